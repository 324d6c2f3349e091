"""Lid and lip contours as curves on a face, matched by arc length.

Each contour runs through iBUG 68 landmarks (an eye's rim, the outer and the inner lip line,
all closed).  On a mesh it is traced landmark to landmark as the shortest path over the mesh's
edges, boundary edges counting half their length so that the path keeps to a rim where the
mesh has one (an open eye, an open or cut mouth), and valley edges less (as the mouth's seam,
correspond.mouth) so that it keeps to the crease where closed lids or lips meet.
Between two landmarks the path is sampled at equal shares of its arc length; sample j of a
segment on one face and sample j of the same segment on the other are a pair of points the
registration holds together (correspond.register), so the lids and lips meet landmark to
landmark and evenly between them.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from ..mesh import Mesh
from ..mesh.graph import edge_graph
from ..mesh.query import concave_angles
from .mouth import CREASE

CONTOURS = {"eye.right": [36, 37, 38, 39, 40, 41, 36], "eye.left": [42, 43, 44, 45, 46, 47, 42],
            "lips.outer": list(range(48, 60)) + [48], "lips.inner": list(range(60, 68)) + [60]}
PER_SEGMENT = 4          # samples per landmark-to-landmark segment (its two ends excluded)


def _graph(mesh: Mesh) -> sp.csr_matrix:
    e = mesh.edges
    w = np.linalg.norm(mesh.vertices[e[:, 0]] - mesh.vertices[e[:, 1]], axis=1)
    b = mesh.boundary_vertices()
    w = np.where(b[e[:, 0]] & b[e[:, 1]], 0.5 * w, w)            # keep to rims where there are
    w = w * np.exp(-CREASE * concave_angles(mesh, e))             # and to the creases of sealed ones
    return edge_graph(mesh.n_vertices, e, w)


def _path(g, a: int, b: int, limit: float) -> list[int] | None:
    if a == b:
        return [a]
    _, pred = dijkstra(g, indices=a, return_predecessors=True, limit=limit)
    if pred[b] < 0:
        return None
    out, v = [], b
    while v != a:
        out.append(v)
        v = pred[v]
    return [a] + out[::-1]


def _samples(v: np.ndarray, path: list[int], k: int):
    """k points at equal shares of the path's arc length (ends excluded): (i, j, t) per point,
    the point being (1 - t) v[i] + t v[j]."""
    p = v[path]
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    arc = np.r_[0.0, np.cumsum(seg)]
    if arc[-1] <= 0 or len(path) < 2:
        return [(path[0], path[0], 0.0)] * k
    out = []
    for s in arc[-1] * np.arange(1, k + 1) / (k + 1):
        m = min(int(np.searchsorted(arc, s, side="right")) - 1, len(seg) - 1)
        t = (s - arc[m]) / max(seg[m], 1e-300)
        out.append((path[m], path[m + 1], float(t)))
    return out


def contour_samples(mesh: Mesh, landmarks: np.ndarray, names=None, per_segment: int = PER_SEGMENT):
    """The lid and lip contours traced on a mesh between their landmarks, sampled in the same order on
    every mesh, so the same contour on two faces pairs sample by sample.

    Parameters
    ----------
    mesh : Mesh
    landmarks : (68, 3) float array
    names : list of str or None
        The contours wanted (None: all of CONTOURS).
    per_segment : int
        Samples between two landmarks.

    Returns
    -------
    dict
        {contour name: (k, 3) float array of (i, j, t) rows: a point (1 - t) at vertex i, t at j},
        for every contour whose landmarks are all present and whose segments could be traced.
    """
    lm = np.asarray(landmarks, float)
    g = _graph(mesh)
    tree = cKDTree(mesh.vertices)
    out = {}
    for name in names or CONTOURS:
        ids = CONTOURS[name]
        if not np.isfinite(lm[ids]).all():
            continue
        stops = [int(tree.query(lm[i])[1]) for i in ids]
        rows = []
        for i, (a, b) in enumerate(zip(stops[:-1], stops[1:])):
            span = float(np.linalg.norm(lm[ids[i + 1]] - lm[ids[i]]))
            path = _path(g, a, b, limit=4.0 * span + 1e-9)
            if path is None:
                rows = None
                break
            rows += [(a, a, 0.0)] + _samples(mesh.vertices, path, per_segment)
        if rows:
            out[name] = np.array(rows, dtype=float)
    return out


def rows_matrix(samples: np.ndarray, n: int) -> sp.csr_matrix:
    """Contour samples as rows of vertex weights.

    Parameters
    ----------
    samples : (k, 3) float array
        (i, j, t) rows.
    n : int
        The mesh's vertices.

    Returns
    -------
    (k, n) sparse matrix
        (1 - t) at i, t at j.
    """
    i, j, t = samples[:, 0].astype(int), samples[:, 1].astype(int), samples[:, 2]
    r = np.arange(len(samples))
    return sp.csr_matrix((np.r_[1 - t, t], (np.r_[r, r], np.r_[i, j])), shape=(len(samples), n))


def matched_contours(source: Mesh, source_lm, target: Mesh, target_lm):
    """The contours found on both faces.

    Parameters
    ----------
    source : Mesh
    source_lm : (68, 3) float array
    target : Mesh
    target_lm : (68, 3) float array

    Returns
    -------
    rows : (k, n_s) sparse matrix
        The source's samples.
    points : (k, 3) float array
        The target's samples, in the same order.
    names : list of str
    """
    s = contour_samples(source, source_lm)
    t = contour_samples(target, target_lm)
    names = [c for c in CONTOURS if c in s and c in t]
    if not names:
        return sp.csr_matrix((0, source.n_vertices)), np.zeros((0, 3)), []
    rows = sp.vstack([rows_matrix(s[c], source.n_vertices) for c in names]).tocsr()
    pts = np.vstack([rows_matrix(t[c], target.n_vertices) @ target.vertices for c in names])
    return rows, pts, names
