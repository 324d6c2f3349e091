"""The Blender add-on as a user installs it: one zip holding the package `mimica_blender` -- the
add-on (mimica/blender_addon.py) and the facts it shares with mimica (mimica/facts.py), which
Blender's Python reads without importing mimica."""

from __future__ import annotations

import zipfile
from importlib import resources
from pathlib import Path

from ..errors import MimicaError
from ..outputs import atomic_path

PACKAGE = "mimica_blender"            # the name Blender lists it by
FILES = {"__init__.py": "blender_addon.py", "facts.py": "facts.py"}


def write_blender_addon(folder) -> Path:
    """Write the add-on's zip into a folder (made if missing), for Blender's Edit > Preferences >
    Add-ons > Install from disk.

    Parameters
    ----------
    folder : str or Path
        Where to put it; an existing file there is refused.

    Returns
    -------
    Path
        The zip written, `folder/mimica_blender.zip` (whole, or not at all).
    """
    out = Path(folder)
    if out.exists() and not out.is_dir():
        raise MimicaError(f"{out}: name a folder to put the add-on in")
    here = resources.files("mimica")
    sources = {name: here / own for name, own in FILES.items()}
    missing = [own for name, own in FILES.items() if not sources[name].is_file()]
    if missing:
        raise MimicaError(f"the Blender add-on's {', '.join(missing)} is missing from this installation: "
                          "pip install --force-reinstall mimica")
    dest = out / f"{PACKAGE}.zip"
    with atomic_path(dest) as tmp:
        with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
            for name, src in sources.items():
                z.writestr(f"{PACKAGE}/{name}", src.read_bytes())
    return dest
