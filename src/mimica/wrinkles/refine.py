"""Refining the skin along wrinkle lines where the mesh is too coarse for their bulge
(V&Y §5.2: "one must sufficiently refine ... the more uniform the mesh, the more
symmetrical the tangents").

Red-green refinement of the triangles: every edge near a wrinkle line and longer than a
fraction of the wrinkle's width is split at its midpoint; a triangle with three split edges
becomes four, with one or two, two or three, so the mesh stays conforming.  Passes repeat
until no such edge is left.  Every new vertex is an average of old ones, kept as a sparse
matrix W, so any pose of the coarse mesh (a simulated frame) maps onto the fine one as W @ X;
face-varying texture coordinates are split the same way.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from ..mesh import Mesh
from ..mesh.core import unique_rows
from .surface import cardinal_spline


@dataclass
class Refined:
    """A mesh refined along wrinkle lines (refine_along).

    Attributes
    ----------
    mesh : Mesh
        The fine mesh.
    W : (n_fine, n_coarse) sparse matrix
        Each fine vertex as a combination of coarse ones (`carry`).
    """
    mesh: Mesh
    W: sp.csr_matrix          # (n_fine, n_coarse)

    def carry(self, X: np.ndarray) -> np.ndarray:
        return self.W @ X

    def reordered(self, order: np.ndarray) -> tuple["Refined", np.ndarray]:
        """The same refinement with its vertices in `order` (old indices, new order), and the
        map old index -> new index."""
        new_index = np.empty(len(order), np.intp)
        new_index[order] = np.arange(len(order))
        m = self.mesh
        mesh = Mesh(m.vertices[order], new_index[m.face_indices], m.face_starts, m.uv, m.face_uv_indices, m.name)
        return Refined(mesh, self.W[order].tocsr()), new_index


def _split(tris, marked_edge_of, mid_of):
    """One red-green pass: tris (F, 3); marked_edge_of (F, 3) bool for edges (v_i, v_i+1);
    mid_of (F, 3) index of the midpoint vertex of each marked edge."""
    cnt = marked_edge_of.sum(1)
    out = [tris[cnt == 0]]
    # one split edge: rotate it to e0
    sel = np.nonzero(cnt == 1)[0]
    if len(sel):
        r = np.argmax(marked_edge_of[sel], 1)
        v = np.stack([tris[sel, (r + i) % 3] for i in range(3)], 1)
        m0 = mid_of[sel, r]
        out += [np.stack([v[:, 0], m0, v[:, 2]], 1), np.stack([m0, v[:, 1], v[:, 2]], 1)]
    # two split edges: rotate the unsplit one to e2
    sel = np.nonzero(cnt == 2)[0]
    if len(sel):
        u = np.argmin(marked_edge_of[sel], 1)
        r = (u + 1) % 3
        v = np.stack([tris[sel, (r + i) % 3] for i in range(3)], 1)
        m0, m1 = mid_of[sel, r], mid_of[sel, (r + 1) % 3]
        out += [np.stack([m0, v[:, 1], m1], 1), np.stack([v[:, 0], m0, m1], 1), np.stack([v[:, 0], m1, v[:, 2]], 1)]
    sel = np.nonzero(cnt == 3)[0]
    if len(sel):
        v, m = tris[sel], mid_of[sel]
        out += [np.stack([v[:, 0], m[:, 0], m[:, 2]], 1), np.stack([v[:, 1], m[:, 1], m[:, 0]], 1),
                np.stack([v[:, 2], m[:, 2], m[:, 1]], 1), m]
    return np.concatenate(out)


def refine_along(mesh: Mesh, mask, edge_fraction: float = 0.3, reach: float = 1.0,
                 max_passes: int = 4) -> Refined:
    """Split the edges within `reach` widths of each wrinkle line that are longer than `edge_fraction`
    of its width.  Polygons are triangulated first.

    Parameters
    ----------
    mesh : Mesh
    mask : WrinkleMask
    edge_fraction : float
    reach : float
    max_passes : int

    Returns
    -------
    Refined
    """
    samples, radius, limit = [], [], []
    for w in mask.wrinkles:
        p = cardinal_spline(w.points, 24)
        samples.append(p)
        radius.append(np.full(len(p), reach * w.width))
        limit.append(np.full(len(p), edge_fraction * w.width))
    samples, radius, limit = np.vstack(samples), np.concatenate(radius), np.concatenate(limit)
    tree = cKDTree(samples)
    V = mesh.vertices.copy()
    tris = mesh.triangles.copy()
    tuv = mesh.uv_triangles
    has_uv = tuv is not None
    if has_uv:
        UV = mesh.uv.copy()
    n0 = len(V)
    W = sp.identity(n0, format="csr")
    for _ in range(max_passes):
        e = np.stack([tris, np.roll(tris, -1, 1)], 2).reshape(-1, 2)     # (F*3, 2): v_i -> v_i+1
        key = np.sort(e, 1)
        first, inv, _ = unique_rows(key)
        uniq = key[first]
        inv = inv.reshape(-1)
        mid = 0.5 * (V[uniq[:, 0]] + V[uniq[:, 1]])
        length = np.linalg.norm(V[uniq[:, 0]] - V[uniq[:, 1]], axis=1)
        dist, j = tree.query(mid)
        mark = (dist < radius[j]) & (length > limit[j])
        if not mark.any():
            break
        new_id = np.full(len(uniq), -1)
        new_id[mark] = len(V) + np.arange(mark.sum())
        rows = np.repeat(np.arange(mark.sum()), 2)
        M = sp.csr_matrix((np.full(2 * mark.sum(), 0.5), (rows, uniq[mark].reshape(-1))),
                          shape=(int(mark.sum()), len(V)))
        W = sp.vstack([W, M @ W]).tocsr()
        V = np.vstack([V, mid[mark]])
        marked = mark[inv].reshape(-1, 3)
        mids = new_id[inv].reshape(-1, 3)
        if has_uv:
            ue = np.stack([tuv, np.roll(tuv, -1, 1)], 2).reshape(-1, 2)
            ukey = np.sort(ue, 1)
            sel = marked.reshape(-1)
            picked = ukey[sel]
            first, uinv, _ = unique_rows(picked)
            uu = picked[first]
            umid = np.full(len(ue), -1)
            umid[np.nonzero(sel)[0]] = len(UV) + uinv.reshape(-1)
            UV = np.vstack([UV, 0.5 * (UV[uu[:, 0]] + UV[uu[:, 1]])])
            tuv = _split(tuv, marked, umid.reshape(-1, 3))
        tris = _split(tris, marked, mids)
    fine = Mesh.from_faces(V, tris, uv=UV if has_uv else None, face_uv=tuv if has_uv else None,
                           name=mesh.name + "_refined")
    return Refined(fine, W.tocsr())
