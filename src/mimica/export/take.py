"""ARKit performances on a head (issue 17, part 4): a Live Link Face take played on the 52
morph targets of a head mimica made blendshapes for.

A take is a CSV as Apple's Live Link Face app writes it -- `Timecode` (HH:MM:SS:FF.fff at the
take's frame rate), `BlendShapeCount`, the 52 ARKit weights in PascalCase (`EyeBlinkLeft` ...),
then head and eye rotations -- or any CSV of ARKit weights with a `time` column in seconds
(camelCase or PascalCase names).  `animate_glb` copies the head's GLB and adds an animation of
its morph target weights, one keyframe per row of the take.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from ..errors import MimicaError
from .blendshapes import ARKIT_52


def _timecode(text: str) -> tuple[float, float]:
    """'13:32:48:12.345' -> (seconds to the frame, frame number with its fraction)."""
    parts = text.strip().split(":")
    if len(parts) != 4:
        raise ValueError(text)
    h, m, s = (int(p) for p in parts[:3])
    return 3600.0 * h + 60.0 * m + s, float(parts[3])


def read_take(path, fps: float | None = None) -> tuple[np.ndarray, dict, float]:
    """(times in seconds from the take's start (F,), {ARKit name: weights (F,)}, frame rate)
    of a take CSV (the rate: the Timecode's, or the median of a time column's steps).

    fps: the frame rate of a Timecode column (default: one more than the largest frame number
    in the take, e.g. 60 for frames 0-59)."""
    path = Path(path)
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:
            rows = list(csv.reader(f))
    except OSError as e:
        raise MimicaError(f"{path}: cannot read the take ({e.strerror})") from None
    except (UnicodeDecodeError, csv.Error) as e:
        raise MimicaError(f"{path}: not a CSV file ({e})") from None
    if len(rows) < 2:
        raise MimicaError(f"{path}: no frames (a header line and one line per frame are needed)")
    header = [h.strip() for h in rows[0]]
    by_name = {h[:1].lower() + h[1:]: i for i, h in enumerate(header)}
    missing = [n for n in ARKIT_52 if n not in by_name]
    if missing:
        raise MimicaError(f"{path}: no column for {', '.join(missing[:4])}"
                          + (f" and {len(missing) - 4} more" if len(missing) > 4 else "")
                          + " (a take needs the 52 ARKit weights, as Live Link Face writes them)")
    body = [r for r in rows[1:] if any(c.strip() for c in r)]
    if any(len(r) < len(header) for r in body):
        short = next(i for i, r in enumerate(rows[1:], start=2) if any(c.strip() for c in r) and len(r) < len(header))
        raise MimicaError(f"{path}: line {short} has fewer values than the header")
    tcol = by_name.get("timecode", by_name.get("time"))
    if tcol is None:
        raise MimicaError(f"{path}: no Timecode or time column")
    try:
        if header[tcol].lower() == "timecode":
            tc = [_timecode(r[tcol]) for r in body]
            rate = fps or float(int(max(f for _, f in tc)) + 1)
            times = np.array([s + f / rate for s, f in tc])
        else:
            times = np.array([float(r[tcol]) for r in body])
            rate = None
        weights = {n: np.array([float(r[by_name[n]]) for r in body]) for n in ARKIT_52}
    except ValueError as e:
        raise MimicaError(f"{path}: a value that is not a number or a timecode ({e})") from None
    bad = [n for n, w in weights.items() if not np.isfinite(w).all()]
    if bad or not np.isfinite(times).all():
        what = bad[0] if bad else header[tcol]
        line = 2 + int(np.nonzero(~np.isfinite(weights[what] if bad else times))[0][0])
        raise MimicaError(f"{path}: line {line}: {what} is not a finite number")
    if len(times) > 1 and not (np.diff(times) > 0).all():
        line = 3 + int(np.nonzero(np.diff(times) <= 0)[0][0])
        raise MimicaError(f"{path}: line {line}: the time does not increase (frames must come in order)")
    if rate is None:
        rate = float(1.0 / np.median(np.diff(times))) if len(times) > 1 else 0.0
    return times - times[0], weights, rate


def animate_glb(head_glb, out, times: np.ndarray, weights: dict) -> int:
    """Write `out`: the head's GLB with an animation of its morph targets' weights (one
    keyframe per time; targets the take does not name stay at 0).  Returns how many of the
    head's targets the take drives."""
    import pygltflib as gl
    head_glb = Path(head_glb)
    try:
        g = gl.GLTF2().load(str(head_glb))
        mesh = g.meshes[0]
        names = list((mesh.extras or {}).get("targetNames") or [])
    except Exception as e:
        raise MimicaError(f"{head_glb}: not a readable glTF file ({type(e).__name__}: {e})") from None
    if not names or not mesh.primitives[0].targets:
        raise MimicaError(f"{head_glb}: no named morph targets (make them with `blendshapes`)")
    driven = [n for n in names if n in weights]
    if not driven:
        raise MimicaError(f"{head_glb}: none of its morph targets is an ARKit shape")
    w = np.zeros((len(times), len(names)), np.float32)
    for j, n in enumerate(names):
        if n in weights:
            w[:, j] = weights[n]
    node = next((i for i, nd in enumerate(g.nodes) if nd.mesh == 0), None)
    if node is None:
        raise MimicaError(f"{head_glb}: no node shows its mesh")
    blob = bytearray(g.binary_blob() or b"")
    if len(g.buffers) != 1 or g.buffers[0].uri is not None:
        raise MimicaError(f"{head_glb}: a .glb with one embedded buffer is needed (as `blendshapes` writes)")

    def add(arr, minmax=False):
        arr = np.ascontiguousarray(arr, np.float32)
        blob.extend(b"\0" * ((-len(blob)) % 4))
        g.bufferViews.append(gl.BufferView(buffer=0, byteOffset=len(blob), byteLength=arr.nbytes))
        blob.extend(arr.tobytes())
        a = gl.Accessor(bufferView=len(g.bufferViews) - 1, componentType=gl.FLOAT, count=arr.size, type=gl.SCALAR)
        if minmax:
            a.min, a.max = [float(arr.min())], [float(arr.max())]
        g.accessors.append(a)
        return len(g.accessors) - 1

    it = add(times, True)
    iw = add(w.reshape(-1))
    g.animations = [gl.Animation(name=Path(out).stem, samplers=[gl.AnimationSampler(input=it, output=iw,
                                                                                   interpolation="LINEAR")],
                                 channels=[gl.AnimationChannel(sampler=0, target=gl.AnimationChannelTarget(
                                     node=node, path="weights"))])]
    blob.extend(b"\0" * ((-len(blob)) % 4))
    for a in g.accessors:          # pygltflib reads a missing byteOffset as 0: sparse accessors have none
        if a.bufferView is None:
            a.byteOffset = None
    g.buffers[0].byteLength = len(blob)
    g.set_binary_blob(bytes(blob))
    g.save_binary(str(out))
    return len(driven)
