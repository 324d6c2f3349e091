"""`mimica view`: a live viewer in the browser: muscles, facial actions, age, presets, a timeline, a second face."""

from __future__ import annotations

from pathlib import Path

from ..errors import MimicaError
from ._common import _landmarks, _muscle_bar, _say


def cmd_view(a):
    """`mimica view`: the live viewer in the browser, served until interrupted.

    Parameters
    ----------
    a : argparse.Namespace
        The command's options (its add_args).

    Returns
    -------
    int
        The exit status (0: done).
    """
    from ..mesh import read_mesh
    from ..pipeline import ViewOptions, prepare_view
    from ..viewer import ViewerServer, ViewerSession, ensure_three, port_in_use

    if not 0 <= a.port <= 65535:
        raise MimicaError(f"--port {a.port}: a port is 0-65535 (0: a free one)")
    busy = port_in_use(a.port)
    if busy is not None:
        _busy(a.port, busy)
    vendor = ensure_three(progress=_say)
    skin = lm = None
    if not a.rig:
        skin = read_mesh(a.face)
        lm = _landmarks(skin, a.landmarks, "--landmarks", str(a.face))
        _say(f"placing the muscles on {a.face}; the page opens on it at rest and its muscles are made as "
             "they are moved (`mimica rig` once and --rig to skip this)")
    face = prepare_view(skin, lm, a.rig, ViewOptions(wrinkles=not a.no_wrinkles))
    session = ViewerSession(face.rig, face.mask)
    server = ViewerServer(session, vendor, title=f"mimica · {Path(a.rig or a.face).stem}", port=a.port, log=_say)
    _serve(a, session, server)
    return 0


def _serve(a, session, server) -> None:
    """The page served until interrupted, a browser opened on it, the muscles' bar while they are made."""
    import asyncio
    import contextlib
    import webbrowser

    def ready(srv):
        _say(f"viewer on {srv.url} (Ctrl-C to stop)")
        if not a.no_browser:
            webbrowser.open(srv.url)
    pending = bool(session.pending())
    with _muscle_bar("muscles (those moved first)") if pending else contextlib.nullcontext(None) as bar:
        made = _one_blas_thread_when_made(bar, not pending)
        try:
            asyncio.run(server.run(ready, made))
        except OSError as e:
            _busy(a.port, e)


def _one_blas_thread_when_made(bar, now: bool):
    """The progress callback of the systems made beside the page: the bar, then one BLAS thread
    once they are all made (`now`: at once).  A frame's products are small, and a second thread
    spinning for work takes the core the browser draws with (measured: 8.7 ms a frame's output
    with two on a 2-core machine while Chromium draws, ~0.5 ms with one); the systems are made
    with one BLAS thread each anyway (physics.precompute)."""
    from threadpoolctl import threadpool_limits

    def made(k, n, name):
        bar(k, n, name)
        if k == n:
            threadpool_limits(limits=1, user_api="blas")
    if now:
        threadpool_limits(limits=1, user_api="blas")
    return made


def _busy(port: int, e: OSError):
    raise MimicaError(f"--port {port}: cannot listen on 127.0.0.1 ({e.strerror or e}); "
                      "choose another port, or 0 for a free one") from None


def add_args(sub) -> None:
    """Put `mimica view` and its options on the `mimica` parser.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The parser's commands (ArgumentParser.add_subparsers).
    """
    vw = sub.add_parser("view", help="a live viewer in the browser: muscles, facial actions, age, presets, "
                                     "a timeline, a second face")
    vw.add_argument("face", help="face mesh (OBJ/PLY/glTF); with --rig, the rig's own face is shown")
    vw.add_argument("--rig", help="a rig from `mimica rig` (else one is made as `mimica rig` makes it)")
    vw.add_argument("--landmarks", help="68-point landmark JSON (built in for ICT-FaceKit, else found)")
    vw.add_argument("--no-wrinkles", action="store_true", help="no wrinkle layer (and no age slider)")
    vw.add_argument("--port", type=int, default=0, help="port on 127.0.0.1 (default: a free one)")
    vw.add_argument("--no-browser", action="store_true", help="only print the address")
    vw.set_defaults(func=cmd_view)


run = cmd_view
