"""`mimica blender-addon`: a copy of the Blender add-on to install (Edit > Preferences > Add-ons >
Install from disk...)."""

from __future__ import annotations

from pathlib import Path

from ..errors import MimicaError
from ._common import _say

ADDON = "mimica_blender.py"           # the name Blender lists it by


def cmd_blender_addon(a):
    import importlib.util
    from ..outputs import atomic_path
    spec = importlib.util.find_spec("mimica.blender_addon")      # its file, not its import (it runs in Blender)
    src = Path(spec.origin) if spec is not None and spec.origin else None
    if src is None or not src.is_file():
        raise MimicaError("the Blender add-on is missing from this installation: pip install --force-reinstall mimica")
    out = Path(a.out)
    if out.exists() and not out.is_dir():
        raise MimicaError(f"{out}: name a folder to put the add-on in")
    dest = out / ADDON
    with atomic_path(dest) as tmp:
        Path(tmp).write_bytes(src.read_bytes())
    _say(f"{dest}: the add-on; in Blender: Edit > Preferences > Add-ons > Install from disk..., this file; its "
         "panel is in the 3D view's sidebar, \"mimica\"")
    return 0


def add_args(sub) -> None:
    """The command's options on the `mimica` parser."""
    b = sub.add_parser("blender-addon", help="write the Blender add-on (one file) into a folder, to install in Blender")
    b.add_argument("--out", required=True, help="the folder to put mimica_blender.py in")
    b.set_defaults(func=cmd_blender_addon)


run = cmd_blender_addon
