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
from functools import cached_property

import numpy as np
import scipy.sparse as sp

from ..mesh import Mesh


@dataclass(eq=False)
class Elements:
    """The elements of a deformation energy: VTC's vertex one-rings (Song §IV) or DT's triangles.

    Attributes
    ----------
    kind : str
        "vtc" or "dt".
    n_vertices : int
    center : (E,) int array
        Each element's centre vertex.
    nbrs : (E, K) int array
        Its neighbour vertices, -1 = padding.
    triangles : (T, 3) int array
        The triangulation used for normals.
    ring_length : (n,) float array or None
        VTC: the rest mean one-ring edge length per vertex.
    tangent_u, tangent_v : sparse matrix or None
        VTC: linear maps to two tangents per vertex, whose cross product is the vertex normal.
    """
    kind: str
    n_vertices: int
    center: np.ndarray        # (E,) centre vertex
    nbrs: np.ndarray          # (E, K) neighbour vertices, -1 = padding
    triangles: np.ndarray     # (T, 3) triangulation used for normals
    ring_length: np.ndarray | None = None    # VTC: rest mean one-ring edge length per vertex
    tangent_u: sp.csr_matrix | None = None   # VTC: linear maps to two tangents per vertex,
    tangent_v: sp.csr_matrix | None = None   # whose cross product is the vertex normal

    @cached_property
    def _tangents(self) -> sp.csr_matrix:
        return sp.vstack([self.tangent_u, self.tangent_v]).tocsr()

    @property
    def n_elements(self) -> int:
        return int(self.center.shape[0])

    def tips(self, vertices: np.ndarray) -> np.ndarray:
        """Tip vertices for positions (n, 3) or a batch laid out vertex-first, (n, F, 3)."""
        v = vertices
        if self.kind == "vtc":
            # Song §IV: v_{n+1} = v_0 + normal; its length is the rest mean ring edge length
            # so that the frame scales with the mesh (any fixed length keeps self-transfer exact)
            n_ = v.shape[0]
            tt = (self._tangents @ v.reshape(n_, -1)).reshape((2,) + v.shape)
            nrm = _cross(tt[0], tt[1])
            ln = np.sqrt(np.einsum("...k,...k->...", nrm, nrm))
            np.divide(nrm, ln[..., None], out=nrm, where=ln[..., None] > 0)
            h = self.ring_length
            return v + nrm * (h[:, None, None] if v.ndim == 3 else h[:, None])
        # Sumner & Popović 2004, eq. 1: v4 = v1 + (v2-v1)x(v3-v1) / sqrt(|(v2-v1)x(v3-v1)|)
        t = self.triangles
        c = _cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
        ln = np.sqrt(np.maximum(np.sqrt(np.einsum("...k,...k->...", c, c)), 1e-300))
        return v[t[:, 0]] + c / ln[..., None]

    @cached_property
    def tip_operators(self) -> tuple[sp.csr_matrix, sp.csr_matrix, sp.csr_matrix]:
        """Sparse (E x n) maps (base, a, b) of positions with tip = base x + g(a x, b x)
        (`tip_bend`): for VTC the vertex and its two tangents, for DT the first corner and the
        two edges from it.  The nonlinear part g acts element by element, so a batch of frames
        whose positions lie in a few shapes' span gets its tips from a few sparse products."""
        n = self.n_vertices
        if self.kind == "vtc":
            return sp.identity(n, format="csr"), self.tangent_u, self.tangent_v
        t = self.triangles
        e = len(t)

        def pick(col):
            return sp.csr_matrix((np.ones(e), (np.arange(e), t[:, col])), shape=(e, n))
        p0 = pick(0)
        return p0, (pick(1) - p0).tocsr(), (pick(2) - p0).tocsr()

    def tip_bend(self, a, b, at=None):
        """g(a, b) of `tip_operators`, component by component: a and b are (x, y, z) triples of
        arrays whose last axis runs over the elements (any precision), or over the elements
        `at` (indices) only; returns the triple g.  The same tips as `tips` (tested), written
        for the basis path's layout."""
        cx = a[1] * b[2] - a[2] * b[1]
        cy = a[2] * b[0] - a[0] * b[2]
        cz = a[0] * b[1] - a[1] * b[0]
        ln = np.sqrt(cx * cx + cy * cy + cz * cz)
        if self.kind == "vtc":
            h = self.ring_length if at is None else self.ring_length[at]
            f = np.divide(h.astype(ln.dtype), ln, out=np.zeros_like(ln), where=ln > 0)
        else:
            f = 1.0 / np.sqrt(np.maximum(ln, ln.dtype.type(1e-30)))
        return cx * f, cy * f, cz * f

    def frames(self, vertices: np.ndarray, tips: np.ndarray) -> np.ndarray:
        """w = [v_k - v_0 ..., tip - v_0] as (E, 3, K+1); padding columns are zero."""
        v0 = vertices[self.center]
        pad = self.nbrs < 0
        nb = vertices[np.where(pad, 0, self.nbrs)] - v0[:, None, :]
        nb[pad] = 0.0
        w = np.concatenate([nb, (tips - v0)[:, None, :]], axis=1)
        return np.transpose(w, (0, 2, 1))


def _cross(a, b):
    """Cross product over the last axis (faster than np.cross for large batches)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def vtc_elements(mesh: Mesh) -> Elements:
    """One element per vertex: its polygon one-ring (Song §IV, Fig. 2).

    Parameters
    ----------
    mesh : Mesh

    Returns
    -------
    Elements
    """
    a = mesh.adjacency
    deg = np.diff(a.indptr)
    k = max(int(deg.max()), 1) if len(deg) else 1
    nbrs = np.full((mesh.n_vertices, k), -1, dtype=np.int64)
    rows = np.repeat(np.arange(mesh.n_vertices), deg)
    cols = np.arange(a.indices.size) - np.repeat(a.indptr[:-1], deg)
    nbrs[rows, cols] = a.indices
    el = mesh.edges
    ln = np.linalg.norm(mesh.vertices[el[:, 0]] - mesh.vertices[el[:, 1]], axis=1)
    tot = np.bincount(el.reshape(-1), weights=np.repeat(ln, 2), minlength=mesh.n_vertices)
    h = np.where(deg > 0, tot / np.maximum(deg, 1), 1.0)
    tu, tv = _tangent_operators(mesh, nbrs)
    return Elements("vtc", mesh.n_vertices, np.arange(mesh.n_vertices), nbrs, mesh.triangles, h, tu, tv)


def _tangent_operators(mesh: Mesh, nbrs: np.ndarray):
    """Sparse Du, Dv with (Du x) x (Dv x) = the vertex normal direction of positions x.

    At rest, the one-ring vectors are expressed in the tangent plane (basis e1, e2 of the
    area-weighted normal); least-squares weights W = Y (Y^T Y)^-1 make sum_k W_k (v_k - v_0)
    equal e1 and e2.  Being linear in the positions, they give every frame's normals with
    two sparse products and one cross product per vertex.
    """
    v = mesh.vertices
    n = mesh.n_vertices
    n0 = mesh.vertex_normals()
    ref = np.where(np.abs(n0[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
    e1 = np.cross(n0, ref)
    e1 /= np.maximum(np.linalg.norm(e1, axis=1, keepdims=True), 1e-300)
    e2 = np.cross(n0, e1)
    pad = nbrs < 0
    d = v[np.where(pad, 0, nbrs)] - v[:, None, :]
    d[pad] = 0
    y = np.stack([np.einsum("ikc,ic->ik", d, e1), np.einsum("ikc,ic->ik", d, e2)], axis=2)   # (n, K, 2)
    yty = np.transpose(y, (0, 2, 1)) @ y
    tr = np.trace(yty, axis1=1, axis2=2)[:, None, None]
    w = y @ np.linalg.inv(yty + 1e-9 * tr * np.eye(2) + 1e-300 * np.eye(2))              # (n, K, 2)
    rows = np.repeat(np.arange(n), nbrs.shape[1]).reshape(n, -1)
    ops = []
    for j in range(2):
        wj = np.where(pad, 0.0, w[:, :, j])
        data = np.concatenate([wj[~pad], -wj.sum(1)])
        ri = np.concatenate([rows[~pad], np.arange(n)])
        ci = np.concatenate([nbrs[~pad], np.arange(n)])
        ops.append(sp.csr_matrix((data, (ri, ci)), shape=(n, n)))
    return ops[0], ops[1]


def dt_elements(mesh: Mesh) -> Elements:
    """One element per triangle of the (fan) triangulation (Sumner & Popović 2004).

    Parameters
    ----------
    mesh : Mesh

    Returns
    -------
    Elements
    """
    t = mesh.triangles
    return Elements("dt", mesh.n_vertices, t[:, 0].copy(), t[:, 1:].copy(), t)


def gradient_operator(el: Elements, vertices: np.ndarray) -> sp.csr_matrix:
    """The sparse operator stacking each element's transformation from the rest frame.

    A @ [x; tips] stacks Q_e^T row-blocks, Q_e = w'_e G_e, G_e = w_e^T (w_e w_e^T)^{-1} from the
    rest frame (Song eq. 2 / eq. 6), so that Q_e = w'_e w_e^T (w_e w_e^T)^{-1}: row 3e+j holds
    column j of Q_e^T, i.e. Q_e[:, j].

    Parameters
    ----------
    el : Elements
    vertices : (n, 3) float array
        The rest positions.

    Returns
    -------
    (3E, n + E) sparse matrix
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
