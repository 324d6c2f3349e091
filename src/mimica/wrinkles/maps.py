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
    """The rest-surface points under a uv map's texels.

    Parameters
    ----------
    mesh : Mesh
        With texture coordinates (MimicaError otherwise).
    size : int
        The map's side, texels.

    Returns
    -------
    rows, cols : (m,) int arrays
        The texels covered.
    points : (m, 3) float array
        The surface point under each.
    """
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
    """The average length on the skin of one unit of texture space.

    Parameters
    ----------
    mesh : Mesh
        With uv.

    Returns
    -------
    float
    """
    t, tuv = mesh.triangles, mesh.uv_triangles
    v, uv = mesh.vertices, mesh.uv
    a3 = 0.5 * np.linalg.norm(np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]]), axis=1).sum()
    e1, e2 = uv[tuv[:, 1]] - uv[tuv[:, 0]], uv[tuv[:, 2]] - uv[tuv[:, 0]]
    a2 = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum()
    return float(np.sqrt(a3 / max(a2, 1e-30)))


def bake(layer, mesh: Mesh, X, age: float, size: int = 1024, emphasis=None):
    """The wrinkles' height and normal maps at some positions of the layer's mesh.

    Parameters
    ----------
    layer : WrinkleLayer
    mesh : Mesh
        With uv, on the same rest surface as the layer's (the coarse mesh the layer's was refined
        from, or the same one).
    X : (n, 3) float array
        The layer mesh's positions (a frame).
    age : float
        Years.
    size : int
        The maps' side, texels.
    emphasis : (w,) float array or None
        A factor per wrinkle (its muscles', WrinkleLayer.muscle_emphasis).

    Returns
    -------
    height : (size, size) float array
        In skin units.
    normal : (size, size, 3) float array
        Tangent-space normals.
    """
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
    """Write a height and a normal map: <prefix>_displacement.png (16-bit, 0.5 = no displacement),
    <prefix>_normal.png and <prefix>_maps.json (the displacement's scale in skin units).

    Parameters
    ----------
    prefix : str or Path
    h : (size, size) float array
    n : (size, size, 3) float array

    Returns
    -------
    list of Path
        The files written.
    """
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


def wrinkle_regions(names) -> dict:
    """Wrinkles grouped into regions: a wrinkle's name without its number (crows_feet_2_R ->
    crows_feet_R, forehead_3 -> forehead), one region a side.

    Parameters
    ----------
    names : list of str
        The mask's wrinkles.

    Returns
    -------
    dict
        {region: [wrinkle indices]}.
    """
    import re
    out: dict = {}
    for i, n in enumerate(names):
        out.setdefault(re.sub(r"_\d+(?=_|$)", "", n), []).append(i)
    return out


def engine_maps(layer, mesh: Mesh, carried, ages, emphasis, size: int, folder) -> dict:
    """The engine-style set of a clip's wrinkles (as game engines blend them): per region
    (wrinkle_regions) a displacement and a normal map at the frame where that region is deepest,
    a mask of the texels it covers, and per frame a weight in [0, 1] (the region's deepest point
    then, over its deepest in the clip).  An engine shades frame f with each region's normal map
    blended in by weight x mask.

    Parameters
    ----------
    layer : WrinkleLayer
    mesh : Mesh
        With uv (as bake's).
    carried : list of (n, 3) float arrays
        The layer mesh's positions, a frame each.
    ages : (F,) float array
        Years, a frame each.
    emphasis : (F, w) float array or None
        Each wrinkle's factor a frame.
    size : int
        The maps' side.
    folder : str or Path
        Where <region>_displacement.png / _normal.png / _mask.png, weights.csv (time, one column a
        region) and maps.json are written.

    Returns
    -------
    dict
        {region: (peak frame, peak height)}.
    """
    folder = Path(folder)
    regions = wrinkle_regions(layer.mask.names())
    b = layer.vertex_binding
    w_of = layer.sec_wrinkle[b.kn]
    n_w = len(layer.mask.wrinkles)
    depth = np.zeros((len(carried), len(regions)))                  # each region's deepest point a frame
    for f, (X, g) in enumerate(zip(carried, ages)):
        h = np.abs(layer.heights(b, layer.state(X, float(g)), None if emphasis is None else emphasis[f]))
        per = np.zeros(n_w)
        np.maximum.at(per, w_of, h)
        depth[f] = [per[idx].max() for idx in regions.values()]
    peak = depth.argmax(0)
    rows, cols, pts = texel_points(mesh, size)
    tb = layer.bind(pts)
    tw = layer.sec_wrinkle[tb.kn]
    info, entries = {}, []
    for r, (name, idx) in enumerate(regions.items()):
        f = int(peak[r])
        only = np.zeros(n_w)
        only[idx] = 1.0 if emphasis is None else np.asarray(emphasis[f])[idx]
        h, nrm = bake(layer, mesh, carried[f], float(ages[f]), size, only)
        m = np.zeros((size, size), np.uint8)
        m[rows[tb.point[np.isin(tw, idx)]], cols[tb.point[np.isin(tw, idx)]]] = 255
        files = save_maps(folder / name, h, nrm)
        with atomic_path(folder / f"{name}_mask.png") as tmp:
            Image.fromarray(m).save(tmp, format="PNG")
        info[name] = (f, float(depth[f, r]))
        entries.append({"region": name, "wrinkles": [layer.mask.wrinkles[i].name for i in idx], "peak_frame": f,
                        "displacement": files[0].name, "normal": files[1].name, "mask": f"{name}_mask.png",
                        "maps": files[2].name})
    weights = depth / np.maximum(depth.max(0), 1e-30)
    with atomic_path(folder / "weights.csv") as tmp:
        tmp.write_text("\n".join([",".join(["frame"] + list(regions))]
                                 + [",".join([str(f)] + [f"{x:.5f}" for x in row]) for f, row in enumerate(weights)])
                       + "\n")
    with atomic_path(folder / "maps.json") as tmp:
        tmp.write_text(json.dumps({"regions": entries, "weights": "weights.csv",
                                   "blend": "normal = mix(base, region normal, weight[frame] * mask)"}, indent=1)
                       + "\n")
    return info
