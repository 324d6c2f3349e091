"""Discrete shell energy (Kim 2020, eqs. 1-4; Grinspun et al. 2003) with exact derivatives.

    E = k_A E_A + k_L E_L + k_B E_B
    E_A = sum_triangles (|A| - |A_rest|)^2 / |A_rest|                        (Kim eq. 1)
    E_L = sum_edges (|e| - |e_rest|)^2 / |e_rest|                            (Kim eq. 2)
    E_B = sum_interior_edges 3 (theta - theta_rest)^2 |e_rest| / h_e         (Kim eq. 3)

theta is the signed dihedral angle across an edge and h_e the mean height of its two
triangles over it.  Each term is written once per element; gradients and Hessians come
from hyper-dual evaluation of that same code (exact), assembled into sparse 3n x 3n form.
E_A carries units of length^2, E_L of length, E_B none; `ShellEnergy.default` divides k_A
and k_L by the matching power of the mean rest edge length, so that the same relative
deformation of a face costs the same in centimetres or metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..mesh import Mesh
from . import hyperdual as hd


def _vec(vs, i):
    return (vs[3 * i], vs[3 * i + 1], vs[3 * i + 2])


def _area_term(vs, rest_area):
    x0, x1, x2 = _vec(vs, 0), _vec(vs, 1), _vec(vs, 2)
    a = 0.5 * hd.norm(hd.cross(hd.sub(x1, x0), hd.sub(x2, x0)))
    d = a - rest_area
    return d * d * (1.0 / rest_area)


def _edge_term(vs, rest_len):
    d = hd.norm(hd.sub(_vec(vs, 1), _vec(vs, 0))) - rest_len
    return d * d * (1.0 / rest_len)


def _dihedral(vs):
    """Signed dihedral angle across edge x0-x1 of triangles (x0, x1, x2) and (x1, x0, x3)."""
    x0, x1, x2, x3 = (_vec(vs, i) for i in range(4))
    e = hd.sub(x1, x0)
    n1 = hd.cross(e, hd.sub(x2, x0))
    n2 = hd.cross(hd.sub(x3, x0), e)
    s = hd.dot(hd.cross(n1, n2), e) / hd.norm(e)
    return hd.atan2(s, hd.dot(n1, n2))


def _bend_term(vs, rest_theta, weight):
    d = _dihedral(vs) - rest_theta
    return 3.0 * d * d * weight


def _numeric_dihedral(x, hinges):
    x0, x1, x2, x3 = (x[hinges[:, i]] for i in range(4))
    e = x1 - x0
    n1 = np.cross(e, x2 - x0)
    n2 = np.cross(x3 - x0, e)
    s = np.einsum("ij,ij->i", np.cross(n1, n2), e) / np.linalg.norm(e, axis=1)
    return np.arctan2(s, np.einsum("ij,ij->i", n1, n2))


def hinges_of(triangles: np.ndarray) -> np.ndarray:
    """(h, 4) interior edges with their two opposite vertices: [x0, x1, x2, x3]."""
    t = triangles
    he = np.concatenate([t[:, [0, 1, 2]], t[:, [1, 2, 0]], t[:, [2, 0, 1]]])   # edge a->b, opposite c
    key = np.sort(he[:, :2], axis=1)
    order = np.lexsort((key[:, 1], key[:, 0]))
    k = key[order]
    same = np.nonzero((k[1:] == k[:-1]).all(1))[0]
    a, b = he[order[same]], he[order[same + 1]]
    ok = (a[:, 0] == b[:, 1]) & (a[:, 1] == b[:, 0])           # consistently oriented pairs
    return np.stack([a[ok, 0], a[ok, 1], a[ok, 2], b[ok, 2]], axis=1)


@dataclass
class ShellEnergy:
    """Kim eq. 4 on a triangle mesh at rest positions `rest`."""

    rest: np.ndarray
    triangles: np.ndarray
    k_area: float
    k_length: float
    k_bend: float

    def __post_init__(self):
        t, x = self.triangles, self.rest
        self.n = len(x)
        self.rest_area = 0.5 * np.linalg.norm(np.cross(x[t[:, 1]] - x[t[:, 0]], x[t[:, 2]] - x[t[:, 0]]), axis=1)
        e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
        self.edges = np.unique(np.sort(e, axis=1), axis=0)
        self.rest_len = np.linalg.norm(x[self.edges[:, 1]] - x[self.edges[:, 0]], axis=1)
        self.hinges = hinges_of(t)
        h = self.hinges
        el = np.linalg.norm(x[h[:, 1]] - x[h[:, 0]], axis=1)
        a1 = 0.5 * np.linalg.norm(np.cross(x[h[:, 1]] - x[h[:, 0]], x[h[:, 2]] - x[h[:, 0]]), axis=1)
        a2 = 0.5 * np.linalg.norm(np.cross(x[h[:, 3]] - x[h[:, 0]], x[h[:, 1]] - x[h[:, 0]]), axis=1)
        h_e = (a1 + a2) / el                       # mean of the two heights 2A/|e|
        self.bend_weight = el / h_e
        self.rest_theta = _numeric_dihedral(x, h)

    @classmethod
    def default(cls, mesh: Mesh, k_area=1.0, k_length=1.0, k_bend=0.05) -> "ShellEnergy":
        """Stiffnesses relative to the mesh's scale (mean edge length l): k_A / l^2, k_L / l, k_B."""
        l = mesh.mean_edge_length()
        return cls(mesh.vertices.copy(), mesh.triangles, k_area / l ** 2, k_length / l, k_bend)

    # ------------------------------------------------------------------ terms
    def _terms(self):
        yield self.k_area, self.triangles, _area_term, (self.rest_area,)
        yield self.k_length, self.edges, _edge_term, (self.rest_len,)
        yield self.k_bend, self.hinges, _bend_term, (self.rest_theta, self.bend_weight)

    @staticmethod
    def _stack(x, idx):
        return x[idx].reshape(len(idx), -1)

    def energy(self, x: np.ndarray) -> float:
        total = 0.0
        for k, idx, fn, par in self._terms():
            if k == 0 or len(idx) == 0:
                continue
            vs = [hd.HD(c) for c in self._stack(x, idx).T]
            total += k * float(np.sum(fn(vs, *par).f))
        return total

    def gradient(self, x: np.ndarray) -> np.ndarray:
        """dE/dx, (n, 3)."""
        g = np.zeros(3 * self.n)
        for k, idx, fn, par in self._terms():
            if k == 0 or len(idx) == 0:
                continue
            _, gl = hd.local_gradient(fn, self._stack(x, idx), par)
            dof = (3 * idx[:, :, None] + np.arange(3)).reshape(len(idx), -1)
            np.add.at(g, dof.ravel(), (k * gl).ravel())
        return g.reshape(-1, 3)

    def hessian(self, x: np.ndarray) -> sp.csr_matrix:
        """d2E/dx2 as a sparse (3n x 3n) matrix (dof order x0, y0, z0, x1, ...)."""
        rows, cols, vals = [], [], []
        for k, idx, fn, par in self._terms():
            if k == 0 or len(idx) == 0:
                continue
            _, _, hl = hd.local_derivatives(fn, self._stack(x, idx), par)
            dof = (3 * idx[:, :, None] + np.arange(3)).reshape(len(idx), -1)
            m = dof.shape[1]
            rows.append(np.repeat(dof, m, axis=1).ravel())
            cols.append(np.tile(dof, (1, m)).ravel())
            vals.append((k * hl).ravel())
        n3 = 3 * self.n
        return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n3, n3))


def lumped_mass(mesh: Mesh, density: float = 1.0) -> np.ndarray:
    """Per-vertex mass: a third of the adjacent triangles' area times the areal density."""
    t = mesh.triangles
    a = mesh.triangle_areas()
    return density * np.bincount(t.ravel(), weights=np.repeat(a / 3, 3), minlength=mesh.n_vertices)


def rayleigh_damping(mass: np.ndarray, stiffness: sp.spmatrix, xi: float, zeta: float) -> sp.csr_matrix:
    """C = xi M + zeta K (Kim, after eq. 6), M lumped (n,) expanded to 3n dofs."""
    return (xi * sp.diags(np.repeat(mass, 3)) + zeta * stiffness).tocsr()
