"""`mimica view`: a live viewer in the browser: muscles, facial actions, age, presets, a timeline, a second face."""

from __future__ import annotations

from pathlib import Path

from ..errors import MimicaError
from ._common import _landmarks, _say


def _rig_of(a):
    """The rig the page plays, and its name: --rig's, else one built here (Kim's muscles)."""
    from ..rig import Rig, build_rig
    if a.rig:
        return Rig.load(a.rig), Path(a.rig).stem
    from ..mesh import read_mesh
    face = read_mesh(a.face)
    lm = _landmarks(face, a.landmarks, "--landmarks", str(a.face))
    _say(f"building a rig of {a.face} (Kim's muscles; `mimica rig` once and --rig to skip this)...")
    return build_rig(face, lm.positions(face)), Path(a.face).stem


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
    from ..wrinkles import mask_for
    import asyncio
    import webbrowser
    from ..viewer import ViewerServer, ViewerSession, ensure_three, port_in_use

    if not 0 <= a.port <= 65535:
        raise MimicaError(f"--port {a.port}: a port is 0-65535 (0: a free one)")
    busy = port_in_use(a.port)
    if busy is not None:
        _busy(a.port, busy)
    vendor = ensure_three(progress=_say)
    rig, name = _rig_of(a)
    mask = None
    if not a.no_wrinkles:
        mask, _ = mask_for(rig.skin, rig.landmarks)
    session = ViewerSession(rig, mask)
    server = ViewerServer(session, vendor, title=f"mimica · {name}", port=a.port)

    def ready(srv):
        _say(f"viewer on {srv.url} (Ctrl-C to stop)")
        if not a.no_browser:
            webbrowser.open(srv.url)
    # one BLAS thread: a frame's products are small, and a second thread spinning for work
    # takes the core the browser draws with (measured: 8.7 ms a frame's output with two on a
    # 2-core machine while Chromium draws, ~0.5 ms with one)
    from threadpoolctl import threadpool_limits
    with threadpool_limits(limits=1, user_api="blas"):
        try:
            asyncio.run(server.run(ready))
        except OSError as e:
            _busy(a.port, e)
    return 0


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
    vw.add_argument("--rig", help="a rig from `mimica rig` (else one is built, about 10 s)")
    vw.add_argument("--landmarks", help="68-point landmark JSON (built in for ICT-FaceKit, else found)")
    vw.add_argument("--no-wrinkles", action="store_true", help="no wrinkle layer (and no age slider)")
    vw.add_argument("--port", type=int, default=0, help="port on 127.0.0.1 (default: a free one)")
    vw.add_argument("--no-browser", action="store_true", help="only print the address")
    vw.set_defaults(func=cmd_view)


run = cmd_view
