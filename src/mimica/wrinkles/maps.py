"""The wrinkles of one frame baked into texture space for game engines: a 16-bit
displacement map (height along the normal) and a tangent-space normal map.

Every texel is placed on the rest skin through the mesh's texture coordinates, tied to the
wrinkle sections like a vertex, and given the section's exact height, so the maps are as
sharp as their resolution, whatever the mesh's density.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from PIL import Image

from ..errors import MimicaError
from ..mesh import Mesh, atomic_path
from ..image.raster import rasterize


def texel_points(mesh: Mesh, size: int):
    """Rest-surface points under the texels: (rows, cols, points (m, 3))."""
    tuv = mesh.uv_triangles
    if tuv is None:
        raise MimicaError(f"{mesh.name or 'mesh'}: has no texture coordinates, so it cannot carry a map")
    uv = mesh.uv
    xy = np.stack([uv[:, 0] * size, (1.0 - uv[:, 1]) * size], 1)
    tri_id, bary = rasterize(xy, np.zeros(len(uv)), tuv, size, size)
    rows, cols = np.nonzero(tri_id >= 0)
    pts = np.einsum("ij,ijk->ik", bary[rows, cols], mesh.vertices[mesh.triangles[tri_id[rows, cols]]])
    return rows, cols, pts


def world_per_uv(mesh: Mesh) -> float:
    """Average length on the skin of one unit of texture space."""
    t, tuv = mesh.triangles, mesh.uv_triangles
    v, uv = mesh.vertices, mesh.uv
    a3 = 0.5 * np.linalg.norm(np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]]), axis=1).sum()
    e1, e2 = uv[tuv[:, 1]] - uv[tuv[:, 0]], uv[tuv[:, 2]] - uv[tuv[:, 0]]
    a2 = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum()
    return float(np.sqrt(a3 / max(a2, 1e-30)))


def bake(layer, mesh: Mesh, X, age: float, size: int = 1024, emphasis=None):
    """Height image (size, size) in skin units and the tangent-space normal image (size, size, 3)
    of the wrinkles at positions X of the layer's mesh; `mesh` (with uv) lies on the same rest
    surface (the coarse mesh the layer's was refined from, or the same one); emphasis: a factor
    per wrinkle (its muscles', WrinkleLayer.muscle_emphasis)."""
    rows, cols, pts = texel_points(mesh, size)
    b = layer.bind(pts)
    h = np.zeros((size, size))
    h[rows[b.point], cols[b.point]] = layer.heights(b, layer.state(X, age), emphasis)
    texel = world_per_uv(mesh) / size
    gy, gx = np.gradient(h, texel)               # rows run down, v runs up
    n = np.stack([-gx, gy, np.ones_like(h)], -1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return h, n


def save_maps(prefix, h, n) -> list[Path]:
    """<prefix>_displacement.png (16-bit, 0.5 = no displacement), <prefix>_normal.png and
    <prefix>_maps.json (the displacement's scale in skin units)."""
    prefix = Path(prefix)
    scale = float(max(np.abs(h).max(), 1e-12))
    disp = np.round(32767.5 + 32767.0 * h / scale).astype(np.uint16)
    rgb = np.round((n * 0.5 + 0.5) * 255).astype(np.uint8)
    out = [prefix.with_name(prefix.name + s) for s in ("_displacement.png", "_normal.png", "_maps.json")]
    with atomic_path(out[0]) as tmp:
        Image.fromarray(disp).save(tmp, format="PNG")
    with atomic_path(out[1]) as tmp:
        Image.fromarray(rgb).save(tmp, format="PNG")
    with atomic_path(out[2]) as tmp:
        tmp.write_text(json.dumps({"displacement": out[0].name, "normal": out[1].name,
                                   "displacement_scale": scale, "displacement_midlevel": 0.5,
                                   "normal_space": "tangent, OpenGL (+Y up)"}, indent=1) + "\n")
    return out
