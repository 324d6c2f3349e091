"""The one data store for templates (DESIGN.md, Conventions): every ICT-FaceKit file mimica
reads comes through `TemplateStore.path` -- from the data directory when it holds the file,
else from the user cache, else downloaded once from the public repository at a pinned commit,
each download checked against its sha256 (ict_manifest.json).  The installed wheel needs no
checkout."""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np

from .errors import MimicaError
from .mesh import atomic_path, read_vertices

PROJECT_ROOT = Path(__file__).resolve().parents[2]
MANIFEST = json.loads(Path(__file__).with_name("ict_manifest.json").read_text())


def cache_dir() -> Path:
    """The folder mimica caches downloads and derived files in.

    Returns
    -------
    Path
        $MIMICA_CACHE, else $XDG_CACHE_HOME/mimica, else ~/.cache/mimica.
    """
    env = os.environ.get("MIMICA_CACHE")
    if env:
        return Path(env).expanduser()
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "mimica"


def data_dir() -> Path | None:
    """The configured data directory (ICT-FaceKit, the real heads, the Yale faces).

    Returns
    -------
    Path or None
        $MIMICA_DATA, else `<checkout>/../shared/data` when running from this repository, else None.
    """
    env = os.environ.get("MIMICA_DATA")
    if env:
        return Path(env).expanduser().resolve()
    if (PROJECT_ROOT / "pyproject.toml").is_file() and (PROJECT_ROOT / "src" / "mimica").is_dir():
        return (PROJECT_ROOT.parent / "shared" / "data").resolve()
    return None


class TemplateStore:
    """Where the ICT-FaceKit template files come from: the data directory, else the cache, else a
    download of the pinned commit (checked against the manifest's sha256).

    Parameters
    ----------
    data : str or Path or None
        The folder holding ICT-FaceKit's OBJs (None: data_dir()/ict-facekit/FaceXModel).
    cache : str or Path or None
        Where downloads go (None: cache_dir()/ict-facekit/<commit>).
    url : str or None
        A mirror of the pinned files ({commit} and {name} in it; None: $MIMICA_ICT_URL, else
        GitHub's).
    timeout : float
        Seconds a download may stall.
    """

    def __init__(self, data=None, cache=None, url=None, timeout=30.0):
        base = data_dir()
        self.data = Path(data) if data is not None else (base / "ict-facekit" / "FaceXModel" if base else None)
        self.cache = Path(cache) if cache is not None else cache_dir() / "ict-facekit" / MANIFEST["commit"][:12]
        # MIMICA_ICT_URL: a mirror of the pinned files (same {commit} and {name} pattern)
        self.url = url or os.environ.get("MIMICA_ICT_URL") or MANIFEST["url"]
        self.timeout = timeout

    def path(self, name: str, progress=None) -> Path:
        if name not in MANIFEST["files"]:
            raise MimicaError(f"ICT-FaceKit: {name!r} is not one of its shapes (known: "
                              f"{', '.join(sorted(MANIFEST['files'])[:6])}, ...)")
        if self.data is not None and (self.data / f"{name}.obj").is_file():
            return self.data / f"{name}.obj"
        p = self.cache / f"{name}.obj"
        if p.is_file():
            return p
        return self._download(name, p, progress)

    def _download(self, name, dest: Path, progress=None) -> Path:
        import urllib.error
        import urllib.request
        url = self.url.format(commit=MANIFEST["commit"], name=name)
        if progress:
            progress(f"downloading {url}")
        try:
            with urllib.request.urlopen(url, timeout=self.timeout) as r:
                data = r.read()
        except (urllib.error.URLError, OSError, ValueError) as e:
            reason = getattr(e, "reason", None) or e
            raise MimicaError(f"ICT-FaceKit template {name}.obj: not in the data directory ({self.data or 'MIMICA_DATA not set'}) "
                              f"and the download from {url} failed ({reason}); connect once, or set "
                              f"MIMICA_DATA to a folder holding ict-facekit/FaceXModel") from None
        digest = hashlib.sha256(data).hexdigest()
        if digest != MANIFEST["files"][name]:
            raise MimicaError(f"ICT-FaceKit template {name}.obj from {url}: sha256 {digest[:16]}... does not "
                              f"match the expected {MANIFEST['files'][name][:16]}...; not used")
        with atomic_path(dest) as tmp:
            tmp.write_bytes(data)
        return dest

    def shapes(self, names, n_vertices, progress=None) -> dict:
        """Vertex positions (first n_vertices) of the named shapes, via a compact cache file."""
        key = f"shapes-{n_vertices}-{hashlib.sha1(','.join(sorted(names)).encode()).hexdigest()[:10]}.npz"
        cache = self.cache / key
        if cache.is_file():
            try:
                with np.load(cache) as z:
                    if all(n in z.files for n in names):
                        return {n: z[n].astype(np.float64) for n in names}
            except (OSError, ValueError):
                pass
        out = {}
        for n in names:
            out[n] = read_vertices(self.path(n, progress))[:n_vertices]
        try:
            with atomic_path(cache) as tmp:
                with open(tmp, "wb") as fh:
                    np.savez(fh, **{n: v.astype(np.float32) for n, v in out.items()})
        except MimicaError:                       # atomic_path's one-line write error: a read-only
            pass                                  # home is just slower next time
        return out


_default = None


def default_store() -> TemplateStore:
    """The store for the current MIMICA_DATA, MIMICA_CACHE, XDG_CACHE_HOME and MIMICA_ICT_URL
    (made again when they change).

    Returns
    -------
    TemplateStore
    """
    global _default
    key = tuple(os.environ.get(k) for k in ("MIMICA_DATA", "MIMICA_CACHE", "XDG_CACHE_HOME", "MIMICA_ICT_URL"))
    if _default is None or _default[0] != key:
        _default = (key, TemplateStore())
    return _default[1]


def shape_names() -> list[str]:
    """Every ICT-FaceKit file the store knows.

    Returns
    -------
    list of str
        Their stems, sorted.
    """
    return sorted(MANIFEST["files"])

