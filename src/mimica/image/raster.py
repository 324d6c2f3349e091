"""A small software rasterizer (numpy, z-buffer), for pictures on machines without a GPU.

Orthographic or weak-perspective views of triangle meshes, Gouraud-shaded or coloured per
vertex.  Triangles are rasterized in groups of equal bounding-box size, each group fully
vectorized; the nearest fragment per pixel wins.
"""

from __future__ import annotations

import numpy as np

from ..mesh import Mesh, vertex_normals


def view_matrix(yaw_deg=0.0, pitch_deg=0.0) -> np.ndarray:
    """The rotation taking model coordinates (y up, z towards the viewer) to camera coordinates.

    Parameters
    ----------
    yaw_deg : float
        Turn about y, degrees.
    pitch_deg : float
        Then about x, degrees.

    Returns
    -------
    (3, 3) float array
    """
    y, p = np.radians(yaw_deg), np.radians(pitch_deg)
    ry = np.array([[np.cos(y), 0, np.sin(y)], [0, 1, 0], [-np.sin(y), 0, np.cos(y)]])
    rx = np.array([[1, 0, 0], [0, np.cos(p), -np.sin(p)], [0, np.sin(p), np.cos(p)]])
    return rx @ ry


def _round_up(n):
    """Bounding-box sizes rounded up (exact to 4, then steps of 2, 4, 16) to share groups."""
    n = np.asarray(n, np.int64)
    return np.where(n <= 4, n, np.where(n <= 16, (n + 1) // 2 * 2, np.where(n <= 64, (n + 3) // 4 * 4,
                                                                              (n + 15) // 16 * 16)))


def rasterize_pixels(xy: np.ndarray, z: np.ndarray, tris: np.ndarray, width: int, height: int):
    """The visible fragments of a triangle mesh in an image (z-buffered).

    Parameters
    ----------
    xy : (n, 2) float array
        Pixel coordinates (x right, y down).
    z : (n,) float array
        Depth, larger = closer.
    tris : (T, 3) int array
    width, height : int

    Returns
    -------
    pix : (k,) int array
        Flat pixel index (y * width + x) of each covered pixel.
    tri : (k,) int array
        Its triangle (row of `tris`).
    l0, l1 : (k,) float32 arrays
        Its barycentrics (l2 = 1 - l0 - l1).
    """
    tris = np.asarray(tris)
    p = xy[tris]                                    # (T, 3, 2)
    lo = np.floor(p.min(1)).astype(np.int64)
    hi = np.ceil(p.max(1)).astype(np.int64)
    lo = np.maximum(lo, 0)
    hi = np.minimum(hi, [width - 1, height - 1])
    keep = (hi >= lo).all(1)
    ids = np.nonzero(keep)[0]
    size = (hi - lo + 1)[ids]
    all_pix, all_tri, all_z, all_l0, all_l1 = [], [], [], [], []
    # group triangles by their bounding box size, rounded up a little so that there are few
    # groups (each group is one vectorized pass); capped rows for big ones
    bw = _round_up(np.minimum(size[:, 0], 4096))
    bh = _round_up(np.minimum(size[:, 1], 4096))
    key = bw * 8192 + bh
    order = np.argsort(key, kind="stable")
    ks, starts = np.unique(key[order], return_index=True)
    bounds = np.r_[starts, len(order)]
    pf = p.astype(np.float32)
    zf = np.asarray(z, np.float32)
    for g in range(len(ks)):
        sel = ids[order[bounds[g]:bounds[g + 1]]]
        w_, h_ = int(ks[g] // 8192), int(ks[g] % 8192)
        chunk = max(1, 2_000_000 // max(w_ * h_, 1))
        ox = np.tile(np.arange(w_, dtype=np.int32), h_)[None]
        oy = np.repeat(np.arange(h_, dtype=np.int32), w_)[None]
        for c0 in range(0, len(sel), chunk):
            s = sel[c0:c0 + chunk]
            px = lo[s, 0, None].astype(np.int32) + ox
            py = lo[s, 1, None].astype(np.int32) + oy
            a, b, c = pf[s, 0], pf[s, 1], pf[s, 2]
            cx = px + np.float32(0.5) - c[:, 0, None]
            cy = py + np.float32(0.5) - c[:, 1, None]
            den = (b[:, 1] - c[:, 1]) * (a[:, 0] - c[:, 0]) + (c[:, 0] - b[:, 0]) * (a[:, 1] - c[:, 1])
            den = np.where(np.abs(den) < 1e-9, np.nan, den)
            inv = (1 / den)[:, None]
            l0 = ((b[:, 1] - c[:, 1])[:, None] * cx + (c[:, 0] - b[:, 0])[:, None] * cy) * inv
            l1 = ((c[:, 1] - a[:, 1])[:, None] * cx + (a[:, 0] - c[:, 0])[:, None] * cy) * inv
            ins = (l0 >= 0) & (l1 >= 0) & (l0 + l1 <= 1) & (px <= hi[s, 0, None]) & (py <= hi[s, 1, None])
            if not ins.any():
                continue
            ti, pi = np.nonzero(ins)
            t3 = tris[s[ti]]
            a0, a1 = l0[ti, pi], l1[ti, pi]
            zz = a0 * zf[t3[:, 0]] + a1 * zf[t3[:, 1]] + (1 - a0 - a1) * zf[t3[:, 2]]
            all_pix.append(py[ti, pi] * np.int64(width) + px[ti, pi])
            all_tri.append(s[ti])
            all_z.append(zz)
            all_l0.append(a0)
            all_l1.append(a1)
    if not all_pix:
        e = np.zeros(0, np.float32)
        return np.zeros(0, np.int64), np.zeros(0, np.int64), e, e
    pix = np.concatenate(all_pix)
    zz = np.concatenate(all_z)
    # per pixel the nearest fragment: one integer sort on (pixel, quantized far-to-near depth)
    zmin, zmax = float(zz.min()), float(zz.max())
    q = ((zmax - zz) * ((2 ** 21 - 1) / max(zmax - zmin, 1e-30))).astype(np.int64)
    o = np.argsort((pix << 21) | q)
    ps = pix[o]
    first = np.r_[True, ps[1:] != ps[:-1]]
    k = o[first]
    return pix[k], np.concatenate(all_tri)[k], np.concatenate(all_l0)[k], np.concatenate(all_l1)[k]


def rasterize(xy: np.ndarray, z: np.ndarray, tris: np.ndarray, width: int, height: int):
    """The visible triangle and barycentrics at every pixel.

    Parameters
    ----------
    xy : (n, 2) float array
        Pixel coordinates (x right, y down).
    z : (n,) float array
        Depth, larger = closer.
    tris : (T, 3) int array
    width, height : int

    Returns
    -------
    tri_id : (height, width) int array
        -1 = background.
    bary : (height, width, 3) float array
    """
    pix, tri, l0, l1 = rasterize_pixels(xy, z, tris, width, height)
    tri_id = np.full(width * height, -1, dtype=np.int64)
    tri_id[pix] = tri
    bary = np.zeros((width * height, 3))
    bary[pix] = np.stack([l0, l1, 1 - l0 - l1], 1)
    return tri_id.reshape(height, width), bary.reshape(height, width, 3)


def facing(xy: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """The triangles of an outward mesh that face the viewer, from their projected corners (pixel
    coordinates, y down: a counter-clockwise triangle on screen has negative area).

    Parameters
    ----------
    xy : (n, 2) float array
    tris : (T, 3) int array

    Returns
    -------
    (T,) bool array
    """
    q = xy[tris]
    return ((q[:, 1, 0] - q[:, 0, 0]) * (q[:, 2, 1] - q[:, 0, 1])
            - (q[:, 2, 0] - q[:, 0, 0]) * (q[:, 1, 1] - q[:, 0, 1])) < 0


def render_mesh(mesh: Mesh, vertices=None, size=(512, 512), yaw=0.0, pitch=0.0, colors=None,
                background=(255, 255, 255), frame=None, base_color=(0.82, 0.72, 0.64), light=None,
                cull=None) -> np.ndarray:
    """A shaded picture of a mesh.

    Parameters
    ----------
    mesh : Mesh
    vertices : (n, 3) float array or None
        Positions to draw (None: the mesh's).
    size : tuple of int
        (w, h) pixels.
    yaw, pitch : float
        The view, degrees (view_matrix).
    colors : (n, 3) float array or None
        Per-vertex RGB in [0, 1] (heat maps); shading still applied.
    background : tuple of int
        RGB 0-255.
    frame : tuple or None
        (center (3,), half extent), so several meshes share one framing (None: framing()).
    base_color : tuple of float
        The skin's RGB in [0, 1] where no colors are given.
    light : (3,) float array or None
        A camera-space direction (x right, y up, z to the viewer) of a single key light with a
        little ambient, instead of the default key + fill.
    cull : bool or None
        Skip back faces; None: when the mesh is consistently oriented and outward
        (`Mesh.outward_oriented`), where they are hidden anyway.

    Returns
    -------
    (h, w, 3) uint8 array
    """
    v = mesh.vertices if vertices is None else np.asarray(vertices)
    w, h = size
    rot = view_matrix(yaw, pitch)
    frame = frame or framing(v, yaw, pitch)
    xy, cam = project(v, frame, size, yaw, pitch)
    tris = mesh.triangles
    if mesh.outward_oriented if cull is None else cull:
        tris = tris[facing(xy, tris)]
    pix, tri, l0, l1 = rasterize_pixels(xy, cam[:, 2], tris, w, h)
    t = tris[tri]
    b = np.stack([l0, l1, 1 - l0 - l1], 1)
    n = (vertex_normals(v, mesh.triangles) @ rot.T).astype(np.float32)
    nn = b[:, 0:1] * n[t[:, 0]] + b[:, 1:2] * n[t[:, 1]] + b[:, 2:3] * n[t[:, 2]]
    nn /= np.maximum(np.linalg.norm(nn, axis=1, keepdims=True), 1e-12)
    # two-sided lighting: a key light from the upper left front and a soft fill
    nn *= np.sign(nn[:, 2:3] + 1e-12)
    if light is None:
        key = np.clip(nn @ (np.array([-0.35, 0.45, 0.82], np.float32) / np.float32(np.linalg.norm([-0.35, 0.45, 0.82]))), 0, 1)
        fill = np.clip(nn @ (np.array([0.5, 0.1, 0.86], np.float32) / np.float32(np.linalg.norm([0.5, 0.1, 0.86]))), 0, 1)
        shade = 0.25 + 0.6 * key + 0.2 * fill
    else:
        shade = 0.15 + 0.85 * np.clip(nn @ (np.asarray(light, np.float32) / np.float32(np.linalg.norm(light))), 0, 1)
    if colors is None:
        col = np.asarray(base_color, np.float32)[None]
    else:
        c = np.asarray(colors, np.float32)
        col = b[:, 0:1] * c[t[:, 0]] + b[:, 1:2] * c[t[:, 1]] + b[:, 2:3] * c[t[:, 2]]
    img = np.empty((h * w, 3), np.uint8)
    img[:] = np.asarray(background, np.uint8)
    img[pix] = (np.clip(col * shade[:, None], 0, 1) * 255 + 0.5).astype(np.uint8)
    return img.reshape(h, w, 3)


def framing(v, yaw=0.0, pitch=0.0, margin=1.05):
    """The framing render_mesh uses for one mesh.

    Parameters
    ----------
    v : (n, 3) float array
    yaw, pitch : float
        The view, degrees.
    margin : float
        Room around it, a factor of its half extent.

    Returns
    -------
    center : (3,) float array
        Its bounding box's centre.
    half_extent : float
        In the view's plane.
    """
    c = 0.5 * (v.min(0) + v.max(0))
    cam = (v - c) @ view_matrix(yaw, pitch).T
    return c, 0.5 * max(np.ptp(cam[:, 0]), np.ptp(cam[:, 1])) * margin


def face_framing(landmarks, margin=0.95):
    """A framing of the face alone, forehead included, from its 68 landmarks (front view).

    Parameters
    ----------
    landmarks : (68, 3) float array
    margin : float

    Returns
    -------
    center : (3,) float array
    half_extent : float
    """
    lm = np.asarray(landmarks)
    c = np.nanmean(lm, 0)
    c = c + 0.45 * (np.nanmean(lm[17:27], 0) - c)                  # toward the brows
    return c, margin * 0.5 * max(np.ptp(lm[:, 0]), np.ptp(lm[:, 1]) * 1.6)


def project(points, frame, size, yaw=0.0, pitch=0.0):
    """Where render_mesh draws 3D points with this framing and image size.

    Parameters
    ----------
    points : (m, 3) float array
    frame : tuple
        (center (3,), half extent).
    size : tuple of int
        (w, h).
    yaw, pitch : float
        The view, degrees.

    Returns
    -------
    xy : (m, 2) float array
        Pixel coordinates.
    cam : (m, 3) float array
        Camera-space points.
    """
    w, h = size
    cam = (np.asarray(points) - frame[0]) @ view_matrix(yaw, pitch).T
    s = 0.5 * min(w, h) / frame[1]
    return np.stack([w / 2 + cam[:, 0] * s, h / 2 - cam[:, 1] * s], 1), cam


def shared_frame(vertex_sets, yaw=0.0, pitch=0.0, margin=1.05):
    """A framing that fits every given set of points in the view.

    Parameters
    ----------
    vertex_sets : list of (n_i, 3) float arrays
    yaw, pitch : float
    margin : float

    Returns
    -------
    center : (3,) float array
    half_extent : float
    """
    return framing(np.concatenate([np.asarray(v) for v in vertex_sets]), yaw, pitch, margin)
