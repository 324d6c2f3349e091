"""A small software rasterizer (numpy, z-buffer), for pictures on machines without a GPU.

Orthographic or weak-perspective views of triangle meshes, Gouraud-shaded or coloured per
vertex.  Triangles are rasterized in groups of equal bounding-box size, each group fully
vectorized; the nearest fragment per pixel wins.
"""

from __future__ import annotations

import numpy as np

from ..mesh import Mesh, vertex_normals


def view_matrix(yaw_deg=0.0, pitch_deg=0.0) -> np.ndarray:
    """Rotation taking model coordinates (y up, z towards the viewer) to camera coordinates."""
    y, p = np.radians(yaw_deg), np.radians(pitch_deg)
    ry = np.array([[np.cos(y), 0, np.sin(y)], [0, 1, 0], [-np.sin(y), 0, np.cos(y)]])
    rx = np.array([[1, 0, 0], [0, np.cos(p), -np.sin(p)], [0, np.sin(p), np.cos(p)]])
    return rx @ ry


def rasterize(xy: np.ndarray, z: np.ndarray, tris: np.ndarray, width: int, height: int):
    """Visible triangle and barycentrics per pixel.

    xy: (n, 2) pixel coordinates (x right, y down); z: (n,) depth, larger = closer.
    Returns tri_id (h, w) int (-1 = background) and bary (h, w, 3).
    """
    p = xy[tris]                                    # (T, 3, 2)
    lo = np.floor(p.min(1)).astype(np.int64)
    hi = np.ceil(p.max(1)).astype(np.int64)
    lo = np.maximum(lo, 0)
    hi = np.minimum(hi, [width - 1, height - 1])
    keep = (hi >= lo).all(1)
    ids = np.nonzero(keep)[0]
    size = (hi - lo + 1)[ids]
    zbuf = np.full(width * height, -np.inf)
    pix_tri = np.full(width * height, -1, dtype=np.int64)
    all_pix, all_tri, all_z = [], [], []
    # group triangles by their bounding box size (capped rows for big ones)
    bw = np.minimum(size[:, 0], 4096)
    bh = np.minimum(size[:, 1], 4096)
    key = bw * 8192 + bh
    order = np.argsort(key, kind="stable")
    ks, starts = np.unique(key[order], return_index=True)
    bounds = np.r_[starts, len(order)]
    for g in range(len(ks)):
        sel = ids[order[bounds[g]:bounds[g + 1]]]
        w_, h_ = int(ks[g] // 8192), int(ks[g] % 8192)
        chunk = max(1, 2_000_000 // max(w_ * h_, 1))
        for c0 in range(0, len(sel), chunk):
            s = sel[c0:c0 + chunk]
            ox, oy = np.meshgrid(np.arange(w_), np.arange(h_))
            px = lo[s, 0][:, None] + ox.ravel()[None]
            py = lo[s, 1][:, None] + oy.ravel()[None]
            a, b, c = p[s, 0], p[s, 1], p[s, 2]
            cx, cy = px + 0.5, py + 0.5
            den = (b[:, 1] - c[:, 1]) * (a[:, 0] - c[:, 0]) + (c[:, 0] - b[:, 0]) * (a[:, 1] - c[:, 1])
            den = np.where(np.abs(den) < 1e-12, np.nan, den)[:, None]
            l0 = ((b[:, 1] - c[:, 1])[:, None] * (cx - c[:, 0][:, None])
                  + (c[:, 0] - b[:, 0])[:, None] * (cy - c[:, 1][:, None])) / den
            l1 = ((c[:, 1] - a[:, 1])[:, None] * (cx - c[:, 0][:, None])
                  + (a[:, 0] - c[:, 0])[:, None] * (cy - c[:, 1][:, None])) / den
            l2 = 1 - l0 - l1
            ins = (l0 >= 0) & (l1 >= 0) & (l2 >= 0) & (px <= hi[s, 0][:, None]) & (py <= hi[s, 1][:, None])
            if not ins.any():
                continue
            ti, pi = np.nonzero(ins)
            zz = (l0[ti, pi] * z[tris[s[ti], 0]] + l1[ti, pi] * z[tris[s[ti], 1]]
                  + l2[ti, pi] * z[tris[s[ti], 2]])
            all_pix.append(py[ti, pi] * width + px[ti, pi])
            all_tri.append(s[ti])
            all_z.append(zz)
    if all_pix:
        pix = np.concatenate(all_pix)
        tri = np.concatenate(all_tri)
        zz = np.concatenate(all_z)
        o = np.lexsort((-zz, pix))                    # per pixel, nearest first
        pix, tri, zz = pix[o], tri[o], zz[o]
        first = np.r_[True, pix[1:] != pix[:-1]]
        pix_tri[pix[first]] = tri[first]
        zbuf[pix[first]] = zz[first]
    tri_id = pix_tri.reshape(height, width)
    # barycentrics of the visible triangle at pixel centres
    yy, xx = np.nonzero(tri_id >= 0)
    t = tri_id[yy, xx]
    a, b, c = p[t, 0], p[t, 1], p[t, 2]
    cx, cy = xx + 0.5, yy + 0.5
    den = (b[:, 1] - c[:, 1]) * (a[:, 0] - c[:, 0]) + (c[:, 0] - b[:, 0]) * (a[:, 1] - c[:, 1])
    l0 = ((b[:, 1] - c[:, 1]) * (cx - c[:, 0]) + (c[:, 0] - b[:, 0]) * (cy - c[:, 1])) / den
    l1 = ((c[:, 1] - a[:, 1]) * (cx - c[:, 0]) + (a[:, 0] - c[:, 0]) * (cy - c[:, 1])) / den
    bary = np.zeros((height, width, 3))
    bary[yy, xx] = np.stack([l0, l1, 1 - l0 - l1], 1)
    return tri_id, bary


def render_mesh(mesh: Mesh, vertices=None, size=(512, 512), yaw=0.0, pitch=0.0, colors=None,
                background=(255, 255, 255), frame=None, base_color=(0.82, 0.72, 0.64), light=None) -> np.ndarray:
    """Shaded picture of a mesh, (h, w, 3) uint8.

    colors: optional (n, 3) per-vertex RGB in [0, 1] (heat maps); shading still applied.
    frame: optional (center (3,), half_extent) so several meshes share one framing.
    light: optional camera-space direction (x right, y up, z to the viewer) of a single key
    light with a little ambient, instead of the default key + fill.
    """
    v = mesh.vertices if vertices is None else np.asarray(vertices)
    w, h = size
    rot = view_matrix(yaw, pitch)
    frame = frame or framing(v, yaw, pitch)
    xy, cam = project(v, frame, size, yaw, pitch)
    tris = mesh.triangles
    tri_id, bary = rasterize(xy, cam[:, 2], tris, w, h)
    img = np.empty((h, w, 3))
    img[:] = np.asarray(background) / 255.0
    yy, xx = np.nonzero(tri_id >= 0)
    t = tris[tri_id[yy, xx]]
    b = bary[yy, xx]
    n = vertex_normals(v, tris) @ rot.T
    nn = np.einsum("ij,ijk->ik", b, n[t])
    nn /= np.maximum(np.linalg.norm(nn, axis=1, keepdims=True), 1e-12)
    # two-sided lighting: a key light from the upper left front and a soft fill
    nn *= np.sign(nn[:, 2:3] + 1e-12)
    if light is None:
        key = np.clip(nn @ np.array([-0.35, 0.45, 0.82]) / np.linalg.norm([-0.35, 0.45, 0.82]), 0, 1)
        fill = np.clip(nn @ np.array([0.5, 0.1, 0.86]) / np.linalg.norm([0.5, 0.1, 0.86]), 0, 1)
        shade = 0.25 + 0.6 * key + 0.2 * fill
    else:
        shade = 0.15 + 0.85 * np.clip(nn @ (np.asarray(light, float) / np.linalg.norm(light)), 0, 1)
    if colors is None:
        col = np.broadcast_to(np.asarray(base_color), (len(t), 3))
    else:
        col = np.einsum("ij,ijk->ik", b, np.asarray(colors)[t])
    img[yy, xx] = np.clip(col * shade[:, None], 0, 1)
    return (img * 255 + 0.5).astype(np.uint8)


def framing(v, yaw=0.0, pitch=0.0, margin=1.05):
    """The framing render_mesh uses for one mesh: its bounding box centre, half extent."""
    c = 0.5 * (v.min(0) + v.max(0))
    cam = (v - c) @ view_matrix(yaw, pitch).T
    return c, 0.5 * max(np.ptp(cam[:, 0]), np.ptp(cam[:, 1])) * margin


def face_framing(landmarks, margin=0.95):
    """A framing of the face alone, forehead included, from its 68 landmarks (front view)."""
    lm = np.asarray(landmarks)
    c = np.nanmean(lm, 0)
    c = c + 0.45 * (np.nanmean(lm[17:27], 0) - c)                  # toward the brows
    return c, margin * 0.5 * max(np.ptp(lm[:, 0]), np.ptp(lm[:, 1]) * 1.6)


def project(points, frame, size, yaw=0.0, pitch=0.0):
    """Pixel coordinates (m, 2) and camera-space points (m, 3) of 3D points, as render_mesh
    draws them with this framing (center, half extent) and image size (w, h)."""
    w, h = size
    cam = (np.asarray(points) - frame[0]) @ view_matrix(yaw, pitch).T
    s = 0.5 * min(w, h) / frame[1]
    return np.stack([w / 2 + cam[:, 0] * s, h / 2 - cam[:, 1] * s], 1), cam


def shared_frame(vertex_sets, yaw=0.0, pitch=0.0, margin=1.05):
    """A framing (center, half extent) that fits every given (n, 3) array in the view."""
    return framing(np.concatenate([np.asarray(v) for v in vertex_sets]), yaw, pitch, margin)
