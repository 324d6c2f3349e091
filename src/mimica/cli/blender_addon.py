"""`mimica blender-addon`: the Blender add-on to install (Edit > Preferences > Add-ons > Install
from disk...), a zip of the add-on and the facts it shares with mimica."""

from __future__ import annotations

from ._common import _say


def cmd_blender_addon(a):
    """`mimica blender-addon`: the Blender add-on written as a zip (pipeline.write_blender_addon).

    Parameters
    ----------
    a : argparse.Namespace
        The command's options (its add_args).

    Returns
    -------
    int
        The exit status (0: done).
    """
    from ..pipeline import write_blender_addon
    dest = write_blender_addon(a.out)
    _say(f"{dest}: the add-on; in Blender: Edit > Preferences > Add-ons > Install from disk..., this file; its "
         "panel is in the 3D view's sidebar, \"mimica\"")
    return 0


def add_args(sub) -> None:
    """Put `mimica blender-addon` and its options on the `mimica` parser.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The parser's commands (ArgumentParser.add_subparsers).
    """
    b = sub.add_parser("blender-addon", help="write the Blender add-on (a zip) into a folder, to install in Blender")
    b.add_argument("-o", "--out", required=True, help="the folder to put mimica_blender.zip in")
    b.set_defaults(func=cmd_blender_addon)


run = cmd_blender_addon
