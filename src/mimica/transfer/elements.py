"""Local frames whose deformation gradients are transferred.

An element has a centre vertex, neighbour vertices and one extra "tip" vertex off the
surface; its frame w is the 3 x (K+1) matrix of vectors from the centre to the others.

- VTC (Song et al. §IV): one element per vertex, neighbours = the one-ring along polygon
  edges (so quads and mixed polygons are handled as they are), tip along the vertex normal.
- DT (Sumner & Popović 2004): one element per triangle, neighbours = the other two corners,
  tip v4 = v1 + n / sqrt(|n|) (their eq. 1).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..mesh import Mesh


@dataclass
class Elements:
    kind: str
    n_vertices: int
    center: np.ndarray        # (E,) centre vertex
    nbrs: np.ndarray          # (E, K) neighbour vertices, -1 = padding
    triangles: np.ndarray     # (T, 3) triangulation used for normals
    adjacency: sp.csr_matrix | None = None

    @property
    def n_elements(self) -> int:
        return int(self.center.shape[0])

    def tips(self, vertices: np.ndarray) -> np.ndarray:
        """Tip vertices for positions (n, 3) or a batch (F, n, 3)."""
        v = vertices
        if self.kind == "vtc":
            # Song §IV: v_{n+1} in the vertex normal direction; its length is the mean ring
            # edge length so that the frame scales with the mesh.
            nrm = _batched_vertex_normals(v, self.triangles)
            a = self.adjacency
            rows = np.repeat(np.arange(a.shape[0]), np.diff(a.indptr))
            el = np.linalg.norm(v[..., a.indices, :] - v[..., rows, :], axis=-1)
            deg = np.maximum(np.diff(a.indptr), 1)
            h = np.add.reduceat(el, a.indptr[:-1], axis=-1) / deg if el.shape[-1] else np.ones(v.shape[:-1])
            h = np.where(np.diff(a.indptr) > 0, h, 1.0)
            return v + nrm * h[..., None]
        # Sumner & Popović 2004, eq. 1: v4 = v1 + (v2-v1)x(v3-v1) / sqrt(|(v2-v1)x(v3-v1)|)
        t = self.triangles
        c = np.cross(v[..., t[:, 1], :] - v[..., t[:, 0], :], v[..., t[:, 2], :] - v[..., t[:, 0], :])
        ln = np.sqrt(np.maximum(np.linalg.norm(c, axis=-1, keepdims=True), 1e-300))
        return v[..., t[:, 0], :] + c / ln

    def frames(self, vertices: np.ndarray, tips: np.ndarray) -> np.ndarray:
        """w = [v_k - v_0 ..., tip - v_0] as (E, 3, K+1); padding columns are zero."""
        v0 = vertices[self.center]
        pad = self.nbrs < 0
        nb = vertices[np.where(pad, 0, self.nbrs)] - v0[:, None, :]
        nb[pad] = 0.0
        w = np.concatenate([nb, (tips - v0)[:, None, :]], axis=1)
        return np.transpose(w, (0, 2, 1))


def _batched_vertex_normals(v: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Unit area-weighted vertex normals for (n, 3) or (F, n, 3) positions."""
    fn = np.cross(v[..., tri[:, 1], :] - v[..., tri[:, 0], :], v[..., tri[:, 2], :] - v[..., tri[:, 0], :])
    n = v.shape[-2]
    acc = sp.csr_matrix((np.ones(tri.size), (tri.reshape(-1), np.repeat(np.arange(len(tri)), 3))),
                        shape=(n, len(tri)))
    if v.ndim == 2:
        vn = acc @ fn
    else:
        f = fn.shape[0]
        vn = (acc @ np.moveaxis(fn, 0, 1).reshape(len(tri), 3 * f)).reshape(n, f, 3)
        vn = np.moveaxis(vn, 1, 0)
    ln = np.linalg.norm(vn, axis=-1, keepdims=True)
    return np.divide(vn, ln, out=np.zeros_like(vn), where=ln > 0)


def vtc_elements(mesh: Mesh) -> Elements:
    """One element per vertex: its polygon one-ring (Song §IV, Fig. 2)."""
    a = mesh.adjacency
    deg = np.diff(a.indptr)
    k = max(int(deg.max()), 1) if len(deg) else 1
    nbrs = np.full((mesh.n_vertices, k), -1, dtype=np.int64)
    rows = np.repeat(np.arange(mesh.n_vertices), deg)
    cols = np.arange(a.indices.size) - np.repeat(a.indptr[:-1], deg)
    nbrs[rows, cols] = a.indices
    return Elements("vtc", mesh.n_vertices, np.arange(mesh.n_vertices), nbrs, mesh.triangles, a)


def dt_elements(mesh: Mesh) -> Elements:
    """One element per triangle of the (fan) triangulation (Sumner & Popović 2004)."""
    t = mesh.triangles
    return Elements("dt", mesh.n_vertices, t[:, 0].copy(), t[:, 1:].copy(), t)


def gradient_operator(el: Elements, vertices: np.ndarray) -> sp.csr_matrix:
    """Sparse A (3E x (n+E)) with A @ [x; tips] stacking Q_e^T row-blocks, Q_e = w'_e G_e.

    G_e = w_e^T (w_e w_e^T)^{-1} from the rest frame (Song eq. 2 / eq. 6), so that
    Q_e = w'_e w_e^T (w_e w_e^T)^{-1}: row 3e+j holds column j of Q_e^T, i.e. Q_e[:, j].
    """
    n, e = el.n_vertices, el.n_elements
    w = el.frames(vertices, el.tips(vertices))              # (E, 3, K+1)
    wwt = w @ np.transpose(w, (0, 2, 1))
    # a tiny Tikhonov term keeps nearly flat one-rings (e.g. a boundary vertex with two
    # collinear neighbours) invertible without changing well-shaped frames
    tr = np.trace(wwt, axis1=1, axis2=2)[:, None, None]
    g = np.transpose(w, (0, 2, 1)) @ np.linalg.inv(wwt + 1e-12 * tr * np.eye(3))   # (E, K+1, 3)
    k = el.nbrs.shape[1]
    cols = np.concatenate([el.nbrs, (n + np.arange(e))[:, None]], axis=1)           # (E, K+1)
    valid = cols >= 0
    g = np.where(valid[:, :, None], g, 0.0)
    rows_e = np.arange(e)
    data, ri, ci = [], [], []
    for j in range(3):
        r = 3 * rows_e + j
        ri.append(np.repeat(r, k + 1)[valid.reshape(-1)])
        ci.append(cols[valid])
        data.append(g[:, :, j][valid])
        ri.append(r)
        ci.append(el.center)
        data.append(-g[:, :, j].sum(axis=1))
    return sp.csr_matrix((np.concatenate(data), (np.concatenate(ri), np.concatenate(ci))),
                         shape=(3 * e, n + e))
