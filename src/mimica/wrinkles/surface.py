"""The face's own frame (front view onto its surface) and Cardinal-spline curves through
control points (V&Y §3: the mask is a Cardinal spline surface)."""

from __future__ import annotations

import numpy as np

from ..align import face_cylinder
from ..mesh import Mesh
from ..mesh.query import SurfaceMap


class FaceFrame:
    """The face's own frame from its 68 landmarks: x toward the subject's left, y up, z out of the
    face, origin at the top of the nose bridge (landmark 27), unit = the distance between the outer
    eye corners (36-45).

    Parameters
    ----------
    landmarks : (68, 3) float array
    """

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
        v = mesh.vertices if vertices is None else np.asarray(vertices)
        loc = self.to_local(v)
        return SurfaceMap(mesh.triangles, loc[:, :2], loc[:, 2], v)


def cardinal_spline(points: np.ndarray, samples_per_segment: int = 8, tension: float = 0.0) -> np.ndarray:
    """Points on the Cardinal spline through control points; the ends are clamped.

    Parameters
    ----------
    points : (k, d) float array
    samples_per_segment : int
    tension : float
        0: Catmull-Rom.

    Returns
    -------
    (m, d) float array
    """
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
    """Points at equal arc-length steps (about `spacing`) along a polyline, its ends kept.

    Parameters
    ----------
    points : (k, d) float array
    spacing : float
    min_points : int

    Returns
    -------
    (m, d) float array
    """
    p = np.asarray(points, float)
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    s = np.r_[0.0, np.cumsum(seg)]
    n = max(min_points, int(round(s[-1] / max(spacing, 1e-12))) + 1)
    t = np.linspace(0, s[-1], n)
    return np.stack([np.interp(t, s, p[:, j]) for j in range(p.shape[1])], 1)
