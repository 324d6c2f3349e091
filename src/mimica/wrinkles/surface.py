"""Placing points on a face surface through a 2D map of it (a front view or a flattened
cylinder), and Cardinal-spline curves through control points (V&Y §3: the mask is a
Cardinal spline surface)."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..correspond import face_cylinder
from ..mesh import Mesh
from ..mesh.query import barycentric_2d


class SurfaceMap:
    """A mesh seen through a 2D map of its vertices; 2D points -> surface points.

    Where several layers of the surface lie under a point (nostrils, lips, ears), the one
    with the largest `score` (depth toward the viewer, or distance from the cylinder axis)
    wins: the outermost skin, as a ray from outside would hit it.
    """

    def __init__(self, mesh: Mesh, uv: np.ndarray, score: np.ndarray, vertices=None, max_span=None):
        self.mesh = mesh
        self.v = mesh.vertices if vertices is None else np.asarray(vertices)
        self.uv = np.asarray(uv, float)
        self.score = np.asarray(score, float)
        tri = mesh.triangles
        tuv = self.uv[tri]
        ok = np.isfinite(tuv).all((1, 2))
        if max_span is not None:                          # triangles across a cylinder seam
            ok &= np.ptp(tuv[:, :, 0], axis=1) < max_span
        self.usable = np.nonzero(ok)[0]
        self.tree = cKDTree(tuv[self.usable].mean(1))

    def locate(self, q, k=32):
        """(triangle, barycentric, found) of the outermost surface under each 2D point."""
        q = np.atleast_2d(np.asarray(q, float))
        k = min(k, len(self.usable))
        _, cand = self.tree.query(q, k=k)
        cand = self.usable[cand.reshape(len(q), k)]
        ct = self.mesh.triangles[cand.reshape(-1)]
        uv = self.uv
        bc = barycentric_2d(np.repeat(q, k, 0), uv[ct[:, 0]], uv[ct[:, 1]], uv[ct[:, 2]]).reshape(len(q), k, 3)
        bc = np.nan_to_num(bc, nan=-1.0)
        depth = np.einsum("ijk,ijk->ij", bc, self.score[self.mesh.triangles[cand]])
        inside = (bc >= -1e-9).all(2)
        rows = np.arange(len(q))
        best = np.argmax(np.where(inside, depth, -np.inf), 1)
        found = inside[rows, best]
        # a point just off the surface's edge: the nearest candidate, clamped onto it
        cl = np.clip(bc, 0, None)
        cl /= np.maximum(cl.sum(2, keepdims=True), 1e-12)
        pc = np.einsum("ijk,ijkl->ijl", cl, uv[self.mesh.triangles[cand]])
        near = np.argmin(np.linalg.norm(pc - q[:, None], axis=2), 1)
        pick = np.where(found, best, near)
        b = np.where(found[:, None], bc[rows, pick], cl[rows, pick])
        return cand[rows, pick], b, found

    def points(self, q):
        """3D surface points under 2D points, and whether each was inside the surface."""
        t, b, found = self.locate(q)
        return np.einsum("ij,ijk->ik", b, self.v[self.mesh.triangles[t]]), found


class FaceFrame:
    """The face's own frame from its 68 landmarks: x toward the subject's left, y up, z out of
    the face, origin at the top of the nose bridge (landmark 27), unit = the distance between
    the outer eye corners (36-45)."""

    def __init__(self, landmarks: np.ndarray):
        lm = np.asarray(landmarks, float)
        cyl = face_cylinder(lm)
        self.axes = cyl.axes                                      # rows: right, up, forward
        self.origin = lm[27] if np.isfinite(lm[27]).all() else np.nanmean(lm, 0)
        self.unit = float(np.linalg.norm(lm[45] - lm[36]))
        self.cylinder = cyl

    def to_local(self, x):
        return (np.asarray(x) - self.origin) @ self.axes.T / self.unit

    def to_world(self, p):
        return self.origin + self.unit * np.asarray(p) @ self.axes

    def front_map(self, mesh: Mesh, vertices=None) -> SurfaceMap:
        loc = self.to_local(mesh.vertices if vertices is None else vertices)
        return SurfaceMap(mesh, loc[:, :2], loc[:, 2], vertices)


def cardinal_spline(points: np.ndarray, samples_per_segment: int = 8, tension: float = 0.0) -> np.ndarray:
    """Points on the Cardinal spline through control points (k, d); ends are clamped."""
    p = np.asarray(points, float)
    if len(p) < 2:
        return p.copy()
    ext = np.vstack([2 * p[0] - p[1], p, 2 * p[-1] - p[-2]])
    s = (1 - tension) / 2
    u = np.linspace(0, 1, samples_per_segment, endpoint=False)[:, None]
    h00, h10, h01, h11 = 2 * u ** 3 - 3 * u ** 2 + 1, u ** 3 - 2 * u ** 2 + u, -2 * u ** 3 + 3 * u ** 2, u ** 3 - u ** 2
    out = []
    for i in range(1, len(p)):
        p0, p1 = ext[i], ext[i + 1]
        m0, m1 = s * (ext[i + 1] - ext[i - 1]), s * (ext[i + 2] - ext[i])
        out.append(h00 * p0 + h10 * m0 + h01 * p1 + h11 * m1)
    out.append(p[-1:])
    return np.vstack(out)


def resample_polyline(points: np.ndarray, spacing: float, min_points: int = 2) -> np.ndarray:
    """Points at equal arc-length steps (about `spacing`) along a polyline, ends kept."""
    p = np.asarray(points, float)
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    s = np.r_[0.0, np.cumsum(seg)]
    n = max(min_points, int(round(s[-1] / max(spacing, 1e-12))) + 1)
    t = np.linspace(0, s[-1], n)
    return np.stack([np.interp(t, s, p[:, j]) for j in range(p.shape[1])], 1)
