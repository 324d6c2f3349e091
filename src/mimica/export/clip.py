"""A sequence of frames of one mesh as one animation file: glTF (a few basis shapes and
per-frame weights where that keeps every vertex within `CLIP_MAX_ERROR_M`, export.compact;
else one morph target a frame) or USD (UsdSkel blend shapes and a SkelAnimation)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

CLIP_MAX_ERROR_M = 1e-4          # a compact clip's bound: 0.1 mm, in metres


def write_clip(path, rest, names, frames: np.ndarray, fps: float, units: str = "auto", compact: bool = True,
               binary: bool = True, quantize: bool = False) -> dict:
    """Write frames as one glTF clip.

    Parameters
    ----------
    path : str or Path
        The .glb (binary) or .gltf file.
    rest : Mesh
        The mesh the frames move (n vertices).
    names : list of str
        One name per frame.
    frames : (F, n, 3) array
        The frames' positions, in the mesh's unit.
    fps : float
        The animation's rate.
    units : str
        The mesh's unit ("auto", "m", "cm", "mm"; mesh.io.glb_units).
    compact : bool
        Try a basis of the frames' motion within CLIP_MAX_ERROR_M first.
    binary, quantize : bool
        GLB rather than glTF; targets as 16-bit moves (KHR_mesh_quantization).

    Returns
    -------
    dict
        The writer's figures ("units", "quantized", ...) and "format" ("gltf"), "frames", "shapes" (morph targets
        written), "basis" (whether they are a basis with weights), "max_error_m" (a basis's largest
        error, metres), "bytes" and "height" (the rest mesh's, in its unit).
    """
    from ..mesh import write_glb
    from ..mesh.io import SPARSE_TOLERANCE, glb_units
    from .compact import compact_clip
    _, k = glb_units(rest, units)
    frames = np.asarray(frames)
    c = compact_clip(rest.vertices, frames, CLIP_MAX_ERROR_M / k) if compact else None
    if c is None:
        info = write_glb(path, rest, dict(zip(names, frames)), binary=binary, fps=fps, units=units,
                         sparse=SPARSE_TOLERANCE, quantize=quantize)
        info.update(shapes=len(frames), basis=False, max_error_m=0.0)
    else:
        shapes = {f"basis_{j:02d}": rest.vertices + b for j, b in enumerate(c.basis)}
        info = write_glb(path, rest, shapes, binary=binary, fps=fps, units=units, weights=c.weights,
                         extras={"frames": list(names), "maxErrorMetres": c.max_error * k}, quantize=quantize)
        info.update(shapes=len(shapes), basis=True, max_error_m=c.max_error * k)
    info.update(format="gltf", frames=len(frames), compact=compact, bytes=Path(path).stat().st_size,
                height=float(np.ptp(rest.vertices[:, 1])))
    return info


def write_clip_usd(path, rest, names, frames: np.ndarray, fps: float, units: str = "auto",
                   compact: bool = True) -> dict:
    """Write frames as one USD clip (UsdSkel): the basis shapes and weights `write_clip` makes,
    or a blend shape a frame with one weight at 1 in each.  Parameters as `write_clip`.

    Returns
    -------
    dict
        {"format": "usd", "unit", "metres_per_unit", "frames", "shapes", "basis", "max_error_m", "bytes"}.
    """
    from ..mesh.io import glb_units
    from .compact import compact_clip
    from .usd import write_usd
    unit, k = glb_units(rest, units)
    frames = np.asarray(frames)
    c = compact_clip(rest.vertices, frames, CLIP_MAX_ERROR_M / k) if compact else None
    if c is None:
        info = write_usd(path, rest, dict(zip(names, frames)), np.eye(len(frames)), fps, units)
        out = {"shapes": len(frames), "basis": False, "max_error_m": 0.0}
    else:
        info = write_usd(path, rest, {f"basis_{j:02d}": rest.vertices + b for j, b in enumerate(c.basis)},
                         c.weights, fps, units)
        out = {"shapes": info["shapes"], "basis": True, "max_error_m": c.max_error * k}
    return {**out, "format": "usd", "unit": unit, "metres_per_unit": k, "frames": len(frames),
            "bytes": Path(path).stat().st_size}
