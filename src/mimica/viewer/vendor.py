"""three.js for the viewer page, fetched once from the npm registry (pinned version, sha256
checked) into the user cache; never part of this repository."""

from __future__ import annotations

import hashlib
import io
import tarfile
from pathlib import Path

from ..errors import MimicaError

THREE_VERSION = "0.187.0"
THREE_URL = f"https://registry.npmjs.org/three/-/three-{THREE_VERSION}.tgz"
THREE_SHA256 = "ff540832ded0cfe919764d24a3d88f3e2a05f23303f876423e4f893841e90728"
# served name -> path inside the package tarball
FILES = {
    "three.module.js": "package/build/three.module.js",
    "three.core.js": "package/build/three.core.js",
    "OrbitControls.js": "package/examples/jsm/controls/OrbitControls.js",
    "LICENSE": "package/LICENSE",
}


def vendor_dir() -> Path:
    """Where three.js is cached.

    Returns
    -------
    Path
        cache_dir()/three-<version>.
    """
    from ..store import cache_dir
    return cache_dir() / f"three-{THREE_VERSION}"


def ensure_three(url: str = THREE_URL, timeout: float = 60.0, progress=None) -> Path:
    """The folder holding three.js's files, downloaded from the npm registry and checked (sha256) on
    first use.

    Parameters
    ----------
    url : str
        The pinned tarball.
    timeout : float
        Seconds the download may stall.
    progress : callable, optional
        Called with a line of text when it downloads.

    Returns
    -------
    Path
    """
    from .._extras import require
    require("websockets", "viewer", "the viewer")          # said before anything is fetched or built
    d = vendor_dir()
    if all((d / n).is_file() for n in FILES):
        return d
    import urllib.error
    import urllib.request
    if progress:
        progress(f"fetching three.js {THREE_VERSION} from {url} (once)")
    try:
        with urllib.request.urlopen(url, timeout=timeout) as r:
            data = r.read()
    except (urllib.error.URLError, OSError, ValueError) as e:
        raise MimicaError(f"the viewer needs three.js {THREE_VERSION}: not in {d} and the download from {url} "
                          f"failed ({getattr(e, 'reason', None) or e}); connect once and rerun") from None
    digest = hashlib.sha256(data).hexdigest()
    if digest != THREE_SHA256:
        raise MimicaError(f"three.js from {url}: sha256 {digest[:16]}... is not the expected {THREE_SHA256[:16]}...")
    from ..mesh import atomic_path
    with tarfile.open(fileobj=io.BytesIO(data), mode="r:gz") as tar:
        for name, member in FILES.items():
            with atomic_path(d / name) as tmp:
                tmp.write_bytes(tar.extractfile(member).read())
    return d
