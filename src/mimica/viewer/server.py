"""`mimica view`: a local page (three.js) bound to 127.0.0.1, the simulation streamed over a
WebSocket.  Only the page's own files are served; faces come in over the socket.

Messages from the page (JSON text):
  {"type": "set", "name": <muscle | facial action | "age">, "value": number}
  {"type": "pose", "values": {name: number, ...}}        (timeline playback)
  {"type": "preset", "name": "happiness"}                (or "neutral")
  {"type": "load", "name": "face.obj", "obj": "<OBJ text>"}   (a second face)
  {"type": "ack"}                                        (a frame was shown: send the next)
Replies: JSON {"type": "init" | "error" | "loaded" | "made", ...} ("made": {"made": k, "of": n,
"name": ...} as the force systems are made beside the page); binary frames: a uint32 kind then
data (0: positions float32 of the face, 1: of the second face, 2: triangles uint32 of the
face, 3: of the second face).  A bad message gets an error reply; the server keeps going.

Only its user reaches it: every request must name the server by Host (127.0.0.1, localhost
or [::1] with its port: no DNS rebinding); the page and the WebSocket need the per-run
token of the URL the command prints (as Jupyter does); a WebSocket from a page of another
Origin is refused (403) before a byte of the face is sent.  Each page has its own bounded
outbox that keeps only the newest frame, so a page that stops reading slows no other.
"""

from __future__ import annotations

import asyncio
import hmac
import json
import mimetypes
import secrets
import struct
import tempfile
import time
from pathlib import Path
from urllib.parse import parse_qs, urlsplit

import numpy as np

from ..errors import MimicaError

STATIC = Path(__file__).with_name("static")
MAX_MESSAGE = 32 << 20           # bytes a page may send in one message (a second face's OBJ text)
MAX_SECOND_VERTICES = 300_000    # a second face larger than this is refused before it is parsed


IN_FLIGHT = 2


def port_in_use(port: int) -> OSError | None:
    """Why 127.0.0.1:`port` cannot be listened on now, asked before minutes of work, so that a busy
    port is said at once (the server still says it should the port be taken in between).

    Parameters
    ----------
    port : int
        0: any free port (always free).

    Returns
    -------
    OSError or None
        The error; None where it is free.
    """
    import socket
    with socket.socket() as s:
        try:
            s.bind(("127.0.0.1", port))
        except OSError as e:
            return e
    return None


def _frame(kind: int, arr) -> bytes:
    return struct.pack("<I", kind) + np.ascontiguousarray(arr).tobytes()


class ViewerServer:
    """The viewer's local server: the page and three.js over HTTP, the simulation's frames over a
    WebSocket, bound to 127.0.0.1 with a token in the page's address.

    Parameters
    ----------
    session : ViewerSession
        What the page plays.
    vendor : Path
        The folder holding three.js (ensure_three).
    title : str
    host : str
    port : int
        0: a free one.
    log : callable, optional
        Called with lines worth logging.
    """
    def __init__(self, session, vendor: Path, title="mimica", host="127.0.0.1", port=0, log=None):
        from .._extras import require
        require("websockets", "viewer", "the viewer")
        self.session, self.vendor, self.title = session, Path(vendor), title
        self.host, self.port = host, port
        self.log = log or (lambda m: None)
        self.routes = {"/": STATIC / "index.html", "/app.js": STATIC / "app.js", "/style.css": STATIC / "style.css",
                       "/vendor/three.module.js": self.vendor / "three.module.js",
                       "/vendor/three.core.js": self.vendor / "three.core.js",
                       "/vendor/OrbitControls.js": self.vendor / "OrbitControls.js"}
        self.token = secrets.token_urlsafe(24)
        self.clients = set()
        self.outbox = {}              # per page: the newest frames not yet sent (kind -> bytes)
        self.wake = {}                # per page: set when its outbox has something
        self.in_flight = {}           # per page: frames sent that it has not shown yet
        self.sent_at = {}
        self.last_input = 0.0
        self.frames_sent = 0

    # -- HTTP -----------------------------------------------------------------------------------
    def _hosts(self):
        return {f"127.0.0.1:{self.port}", f"localhost:{self.port}", f"[::1]:{self.port}"}

    def _token_ok(self, query: str) -> bool:
        given = parse_qs(query).get("token", [""])[0]
        return hmac.compare_digest(given.encode(), self.token.encode())

    def _http(self, connection, request):
        from websockets.datastructures import Headers
        from websockets.http11 import Response

        def refuse(code, reason, text):
            body = text.encode() + b"\n"
            return Response(code, reason, Headers([("Content-Type", "text/plain"),
                                                   ("Content-Length", str(len(body)))]), body)
        parts = urlsplit(request.path)
        path = parts.path
        if request.headers.get("Host", "") not in self._hosts():
            return refuse(403, "Forbidden", "wrong Host")             # DNS rebinding
        if path == "/ws":
            origin = request.headers.get("Origin")
            if origin is not None and origin not in {f"http://{h}" for h in self._hosts()}:
                return refuse(403, "Forbidden", "foreign Origin")
            if not self._token_ok(parts.query):
                return refuse(403, "Forbidden", "token needed")
            return None                                             # the WebSocket handshake
        if path == "/" and not self._token_ok(parts.query):
            return refuse(403, "Forbidden", "open the address mimica printed (it carries a token)")
        f = self.routes.get(path)
        if f is None or not f.is_file():
            return refuse(404, "Not Found", "not found")
        body = f.read_bytes()
        ctype = mimetypes.guess_type(f.name)[0] or "application/octet-stream"
        if f.suffix == ".js":
            ctype = "text/javascript"
        return Response(200, "OK", Headers([("Content-Type", ctype), ("Content-Length", str(len(body))),
                                            ("Cache-Control", "no-store")]), body)

    # -- WebSocket ---------------------------------------------------------------------------------
    async def _client(self, ws):
        from websockets.exceptions import ConnectionClosed
        s = self.session
        self.outbox[ws], self.wake[ws] = {}, asyncio.Event()
        self._post(ws, "init", json.dumps({"type": "init", "title": self.title, **s.controls(),
                                           "timeline_format": _timeline_format()}))
        self._post(ws, 2, _frame(2, s.rig.skin.triangles.astype(np.uint32)))
        self._post(ws, 0, _frame(0, (s._last if s._last is not None else s.positions()).astype(np.float32)))
        writer = asyncio.create_task(self._writer(ws))
        self.clients.add(ws)
        try:
            async for msg in ws:
                try:
                    reply = await self._handle(msg, ws)
                except MimicaError as e:
                    reply = {"type": "error", "message": " ".join(str(e).split())[:300]}
                except Exception as e:                              # never let one message kill the server
                    self.log(f"viewer: a message failed: {type(e).__name__}: {e}")
                    reply = {"type": "error", "message": "that message could not be handled"}
                if reply:
                    self._post(ws, f"reply{time.monotonic_ns()}", json.dumps(reply))
                    if reply.get("type") == "loaded":
                        mesh = s.second[0]
                        self._post(ws, 3, _frame(3, mesh.triangles.astype(np.uint32)))
                        self._post(ws, 1, _frame(1, s.second_positions()))
        except ConnectionClosed:
            pass                                                    # the page went away
        finally:
            self.clients.discard(ws)
            writer.cancel()
            for d in (self.in_flight, self.sent_at, self.outbox, self.wake):
                d.pop(ws, None)

    def _post(self, ws, kind, data):
        """Queue data for one page; a newer frame of the same kind replaces an unsent one."""
        box = self.outbox.get(ws)
        if box is None:
            return
        box.pop(kind, None)
        box[kind] = data
        while len(box) > 64:                          # a page that sends and never reads: drop old replies
            box.pop(next(k for k in box if isinstance(k, str) and k.startswith("reply")), None)
        self.wake[ws].set()

    async def _writer(self, ws):
        """Send one page's outbox in order; only this page waits when it stops reading."""
        from websockets.exceptions import ConnectionClosed
        box, wake = self.outbox[ws], self.wake[ws]
        try:
            while True:
                await wake.wait()
                wake.clear()
                while box:
                    kind = next(iter(box))
                    await ws.send(box.pop(kind))
        except (ConnectionClosed, asyncio.CancelledError):
            pass

    async def _handle(self, msg, ws=None):
        s = self.session
        if isinstance(msg, bytes):
            raise MimicaError("binary messages are not understood")
        try:
            m = json.loads(msg)
        except (ValueError, RecursionError):                       # bad JSON, 5000-digit numbers, deep nesting
            raise MimicaError("not a JSON message this viewer understands") from None
        if not isinstance(m, dict) or not isinstance(m.get("type"), str):
            raise MimicaError("a message is a JSON object with a 'type'")
        t = m["type"]
        if t == "ack":                                             # the page showed a frame
            self.in_flight[ws] = max(0, self.in_flight.get(ws, 0) - 1)
            return None
        self.last_input = time.monotonic()
        if t == "set":
            s.set(m.get("name"), m.get("value"))
        elif t == "pose":
            vals = m.get("values")
            if not isinstance(vals, dict):
                raise MimicaError("pose: 'values' must be an object {name: number}")
            for k, v in vals.items():
                s.set(k, v)
        elif t == "preset":
            s.preset(m.get("name"))
        elif t == "load":
            return await asyncio.get_running_loop().run_in_executor(None, self._load, m)
        else:
            raise MimicaError(f"unknown message type {t!r}")
        return None

    def _load(self, m):
        from ..mesh import read_mesh
        name, text = m.get("name"), m.get("obj")
        if not isinstance(name, str) or not isinstance(text, str):
            raise MimicaError("load: 'name' and 'obj' (the OBJ file's text) are needed")
        n = text.count("\nv ") + text.startswith("v ")
        if n > MAX_SECOND_VERTICES:
            raise MimicaError(f"{Path(name).name}: {n} vertices; the viewer takes a second face of up to "
                              f"{MAX_SECOND_VERTICES} vertices")
        with tempfile.TemporaryDirectory() as d:
            p = Path(d) / "second.obj"
            p.write_text(text)
            try:
                mesh = read_mesh(p)
            except MimicaError as e:
                raise MimicaError(str(e).replace(str(p), Path(name).name)) from None
        self.session.load_second(mesh)
        return {"type": "loaded", "name": Path(name).name, "n_vertices": mesh.n_vertices}

    async def _simulate(self):
        """The simulation advances in real time; a frame is computed and sent only to pages
        with fewer than IN_FLIGHT frames not yet shown ("ack"), so a slow page never queues
        stale frames and the server spends nothing on frames nobody will see; a face that did
        not move is not sent again (the page would redraw it, and keep drawing at its lower
        streaming resolution).  Two in flight, not one, so that a new frame can be waiting
        at the page's next animation frame instead of one server tick after each ack (the
        A/B on this VM was within its noise)."""
        s = self.session
        dt = 1.0 / s.fps
        nxt = time.monotonic()
        while True:
            nxt += dt
            if self.clients:
                s.step()
                ready = [ws for ws in self.clients if self.in_flight.get(ws, 0) < IN_FLIGHT]
                active = time.monotonic() - self.last_input < 3.0
                if ready and (active or s.moved):
                    x = s.positions()                     # sets s.moved
                    if s.moved:                           # a face that did not move is not sent again
                        self._send_frame(ready, x)
                for ws in list(self.in_flight):            # a page that never acks still gets frames
                    if time.monotonic() - self.sent_at.get(ws, 0) > 0.5:
                        self.in_flight[ws] = 0
            await asyncio.sleep(max(0.0, nxt - time.monotonic()))
            if time.monotonic() - nxt > 1.0:                       # fell behind: do not try to catch up
                nxt = time.monotonic()

    def _send_frame(self, pages, x):
        """Post a frame to each ready page's outbox (its writer sends it)."""
        data = _frame(0, x)
        second = self.session.second_positions() if self.session.second is not None else None
        for ws in pages:
            self.in_flight[ws] = self.in_flight.get(ws, 0) + 1   # before sending: the ack may come first
            self.sent_at[ws] = time.monotonic()
            if second is not None:
                self._post(ws, 1, _frame(1, second))
            self._post(ws, 0, data)
        self.frames_sent += 1

    async def run(self, ready=None, progress=None):
        """Serve until cancelled; the session's missing force systems are made beside it
        (ViewerSession.make_systems), each page told how far ("made" messages).

        Parameters
        ----------
        ready : callable, optional
            Called with the server once it listens (its `url` set).
        progress : callable, optional
            Also called as progress(k, n, name) after each system is made.
        """
        from websockets.asyncio.server import serve
        async with serve(self._client, self.host, self.port, process_request=self._http,
                         max_size=MAX_MESSAGE, compression=None) as server:
            self.port = server.sockets[0].getsockname()[1]
            self.url = f"http://{self.host}:{self.port}/?token={self.token}"
            if ready:
                ready(self)
            sim = asyncio.create_task(self._simulate())
            if self.session.pending():
                await self._make_systems(progress)
            await sim

    async def _make_systems(self, progress):
        """The session's make_systems in a thread of its own, each step posted to every page; a
        daemon thread, so that stopping the server does not wait for the last system."""
        import threading
        loop = asyncio.get_running_loop()
        done = loop.create_future()

        def post(f, *args):
            try:
                loop.call_soon_threadsafe(f, *args)
            except RuntimeError:                    # the server stopped meanwhile
                pass

        def tell(k, n, name):
            if progress:
                progress(k, n, name)
            post(self._tell_all, json.dumps({"type": "made", "made": k, "of": n, "name": name}))

        def work():
            try:
                self.session.make_systems(tell)
                post(done.set_result, None)
            except Exception as e:                  # the page says it; the face stays as it is
                post(done.set_result, e)
        threading.Thread(target=work, daemon=True, name="mimica-systems").start()
        e = await done
        if e is not None:
            self.log(f"viewer: the force systems could not be made: {type(e).__name__}: {e}")
            self._tell_all(json.dumps({"type": "error", "message": f"the muscles could not be made: {e}"[:300]}))

    def _tell_all(self, msg):
        for ws in list(self.clients):
            self._post(ws, f"reply{time.monotonic_ns()}", msg)


def _timeline_format():
    from ..anim import FORMAT
    return FORMAT
