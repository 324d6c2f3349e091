"""`mimica demo`: transfer bundled ICT-FaceKit expressions; write meshes and a contact sheet."""

from __future__ import annotations

from pathlib import Path


def cmd_demo(a):
    """`mimica demo`: ICT-FaceKit's bundled expressions transferred; meshes and a contact sheet
    written.

    Parameters
    ----------
    a : argparse.Namespace
        The command's options (its add_args).

    Returns
    -------
    int
        The exit status (0: done).
    """
    from ..demo import run_demo
    from ..outputs import staged_dir
    with staged_dir(a.out, {"command": "demo"}) as d:
        return run_demo(d, quick=a.quick, shown=Path(a.out))


def add_args(sub) -> None:
    """Put `mimica demo` and its options on the `mimica` parser.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The parser's commands (ArgumentParser.add_subparsers).
    """
    d = sub.add_parser("demo", help="transfer bundled ICT-FaceKit expressions; write meshes and a contact sheet")
    d.add_argument("-o", "--out", default="out/demo")
    d.add_argument("--quick", action="store_true", help="fewer faces and expressions")
    d.set_defaults(func=cmd_demo)


run = cmd_demo
