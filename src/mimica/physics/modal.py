"""Modal warping for shells (Kim 2020 §III.B; Choi & Ko 2005), and the full-space reference.

Linearize the shell at rest (K = Hessian of Kim eq. 4 at rest, M lumped), remove the fixed
nodes, and solve K Phi = M Phi Lambda for the r lowest modes (Kim eq. 8).  Each mode is
then an independent damped oscillator (Kim eq. 10 with Rayleigh damping,
C_q = xi I + zeta Lambda), integrated semi-implicitly (implicit Euler per mode, stable at
any step).  The displacement is warped node by node, u_i = R~_i (Phi q)_i, with R~_i
Choi & Ko's rotation integrated along the path of the linearized rotation field w = Psi q
(Psi = W Phi, W the per-node curl); forces enter the nodes' frames by R_i^T (Kim eq. 10).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.linalg
import scipy.sparse as sp

from ..errors import MimicaError
from ..mesh.core import cross_matrices
from ..solver import SPDSolver
from .shell import ShellEnergy


def rotation_operator(rest: np.ndarray, triangles: np.ndarray, smooth: float = 0, tangent: bool = False,
                      diffuse: bool = False):
    """The linear map from displacements to per-node infinitesimal rotation vectors.

    Per triangle, the displacement gradient on the tangent plane is completed by the linearized
    normal change; the axial vector of its skew part is the rotation; nodes take the area-weighted
    mean of their triangles.  Exact for infinitesimal rotations.

    Parameters
    ----------
    rest : (n, 3) float array
        The shell at rest.
    triangles : (m, 3) int array
    smooth : float
        Average over this many rings; with diffuse, one implicit diffusion step of that time
        instead, (I + smooth L)^-1 (one factorization, then a solve per use).
    tangent : bool
        Keep only the rotation about axes in the skin's tangent plane (its normal tilting, as the
        skin bends) and drop the spin about the normal, the "drilling" rotation a shell does not
        carry: a muscle sliding the skin along itself shears it, and the curl of that shear is
        spin, not a turn of the material's frame (with it, a full smile warped folds into itself:
        deviation from --solver full 0.522 against 0.367 without, the linear modes' 0.333, at 4
        rings; docs/benchmarks.md).
    diffuse : bool
        Smooth by diffusion rather than ring averages.

    Returns
    -------
    sparse matrix or SmoothedRotation
        W (3n x 3n), or the operator that applies it with its smoothing (`W @ X`).
    """
    x, t = rest, triangles
    e1, e2 = x[t[:, 1]] - x[t[:, 0]], x[t[:, 2]] - x[t[:, 0]]
    nrm = np.cross(e1, e2)
    area = 0.5 * np.linalg.norm(nrm, axis=1)
    n = nrm / (2 * area[:, None])
    t1 = e1 / np.linalg.norm(e1, axis=1, keepdims=True)
    t2 = np.cross(n, t1)
    T = np.stack([t1, t2], axis=2)                                   # (m, 3, 2)
    P = np.einsum("mck,mcj->mkj", T, np.stack([e1, e2], axis=2))     # local 2D edge coords
    Pinv = np.linalg.inv(P)

    def rot_of(d1, d2):
        D = np.stack([d1, d2], axis=2)                               # (m, 3, 2)
        gs = D @ Pinv                                                # du/ds in the tangent basis
        dn = -np.einsum("mck,mk->mc", T, np.einsum("mck,mc->mk", gs, n))
        G = np.einsum("mck,mdk->mcd", gs, T) + dn[:, :, None] * n[:, None, :]
        return 0.5 * np.stack([G[:, 2, 1] - G[:, 1, 2], G[:, 0, 2] - G[:, 2, 0], G[:, 1, 0] - G[:, 0, 1]], 1)

    m = len(t)
    local = np.zeros((m, 3, 9))
    z = np.zeros((m, 3))
    for c in range(3):                                               # probe each corner dof
        for k in range(3):
            u = [z.copy(), z.copy(), z.copy()]
            u[c][:, k] = 1.0
            local[:, :, 3 * c + k] = rot_of(u[1] - u[0], u[2] - u[0])
    nv = len(x)
    wsum = np.bincount(t.ravel(), weights=np.repeat(area, 3), minlength=nv)
    rows, cols, vals = [], [], []
    dof = (3 * t[:, :, None] + np.arange(3)).reshape(m, 9)
    for c in range(3):                                               # scatter to each corner node
        node = t[:, c]
        wgt = area / np.maximum(wsum[node], 1e-300)
        r = 3 * node[:, None] + np.arange(3)                         # (m, 3)
        rows.append(np.repeat(r[:, :, None], 9, axis=2).ravel())
        cols.append(np.repeat(dof[:, None, :], 3, axis=1).ravel())
        vals.append((local * wgt[:, None, None]).ravel())
    W = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(3 * nv, 3 * nv))
    P = None
    if tangent:                                                      # I - n n^T at every node
        vn = np.zeros((nv, 3))
        np.add.at(vn, t.ravel(), np.repeat(nrm, 3, axis=0))
        vn /= np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-300)
        blocks = np.eye(3)[None] - vn[:, :, None] * vn[:, None, :]
        i, j = np.meshgrid(np.arange(3), np.arange(3), indexing="ij")
        base = 3 * np.arange(nv)[:, None, None]
        P = sp.csr_matrix((blocks.ravel(), ((base + i).ravel(), (base + j).ravel())), shape=(3 * nv, 3 * nv))
    if not smooth:
        return W if P is None else (P @ W).tocsr()
    # average the rotation field over `smooth` rings: a node's frame turns with its
    # neighbourhood, not with the spikes that point loads make in the strain field.  The
    # average is kept as a separate operator (applied to the few mode columns, not
    # multiplied into W, whose fill-in would grow with every ring)
    e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    adj = sp.csr_matrix((np.ones(2 * len(e)), (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])), shape=(nv, nv))
    adj = (adj + sp.identity(nv)).tocsr()
    adj.data[:] = 1.0
    if diffuse:
        # one implicit diffusion step instead of many ring averages: (I + t L)^-1, L the graph
        # Laplacian, factored once for the skin; a solve per system instead of `smooth` products
        L = sp.diags(np.asarray(adj.sum(1)).ravel()) - adj
        return SmoothedRotation(W, None, 0, P, SPDSolver((sp.identity(nv) + smooth * L).tocsc()))
    avg = sp.diags(1.0 / np.asarray(adj.sum(1)).ravel()) @ adj
    return SmoothedRotation(W, sp.kron(avg, sp.identity(3), format="csr"), smooth, P)


class SmoothedRotation:
    """W followed by `rings` ring averages (or one diffusion solve) and the tangent projection P, if
    any, as an operator: (P S^rings W) @ X.

    Parameters
    ----------
    W : (3n, 3n) sparse matrix
        The raw rotation operator.
    S : (3n, 3n) sparse matrix
        One ring average.
    rings : int
    P : (3n, 3n) sparse matrix or None
        The projection onto the tangent axes.
    diffusion : SPDSolver or None
        (I + smooth L) factored, used instead of the ring averages.
    """

    def __init__(self, W, S, rings, P=None, diffusion=None):
        self.W, self.S, self.rings, self.P, self.diffusion = W, S, rings, P, diffusion

    def __matmul__(self, x):
        y = self.W @ x
        for _ in range(self.rings):
            y = self.S @ y
        if self.diffusion is not None:                 # node by node: (n, 3 k) right-hand sides
            shape = y.shape
            y = self.diffusion.solve(y.reshape(self.diffusion.n, -1)).reshape(shape)
        return y if self.P is None else self.P @ y


def rotations(w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation matrices of rotation vectors, and Choi and Ko's warp.

    The warp is the rotation integrated along the path, int_0^1 R(s w) ds = I + (1 - cos t)/t^2
    [w]x + (t - sin t)/t^3 [w]x^2 (t = |w|): the displacement of a node whose rotation grew with its
    modal amplitudes, u = R~ Phi q (Choi & Ko 2005 §4, closed form for a fixed axis).

    Parameters
    ----------
    w : (k, 3) float array

    Returns
    -------
    R : (k, 3, 3) float array
        Rodrigues.
    R_warp : (k, 3, 3) float array
        R~(w).
    """
    th = np.linalg.norm(w, axis=1)
    small = th < 1e-4
    t = np.where(small, 1.0, th)
    t2 = th * th
    sin_t, cos_t = np.sin(t), np.cos(t)
    a = np.where(small, 1.0 - t2 / 6, sin_t / t)                   # sin t / t
    b = np.where(small, 0.5 - t2 / 24, (1 - cos_t) / (t * t))       # (1 - cos t) / t^2
    c = np.where(small, 1.0 / 6 - t2 / 120, (t - sin_t) / (t * t * t))
    K = cross_matrices(w)
    K2 = K @ K
    eye = np.eye(3)
    R = eye + a[:, None, None] * K + b[:, None, None] * K2
    Rt = eye + b[:, None, None] * K + c[:, None, None] * K2
    return R, Rt


def _stiffness_products(V, G, loads, prevs, shift, extra) -> np.ndarray:
    """V^T K V for Ritz vectors V solved from (K + E - shift M) V = [loads, M V_prev...], read
    off the right-hand sides instead of a sparse product over every dof (2.6 of the library's
    25 s): K V = R + shift M V - E V, so V^T K V = V^T R + shift G - (E V)^T V, with G = V^T M V,
    V^T M V_prev G's columns, and R's loads (a few nodes' patterns) and E (the span's springs,
    diagonal) nonzero on a few rows.

    Parameters
    ----------
    V : (d, c) float array
        The solves' results, the load block's columns first.
    G : (c, c) float array
        V^T M V.
    loads : (d, k) float array
        The first block's right-hand sides.
    prevs : list of int arrays
        For each later block, the columns of V it multiplied by M.
    shift : float
    extra : (d,) float array or None
        E's diagonal.

    Returns
    -------
    (c, c) float array
    """
    rows = np.flatnonzero(np.any(loads != 0, axis=1))
    kr = np.empty((V.shape[1], V.shape[1]))
    kr[:, : loads.shape[1]] = V[rows].T @ loads[rows]
    at = loads.shape[1]
    for cols in prevs:
        kr[:, at: at + len(cols)] = G[:, cols]
        at += len(cols)
    kr += shift * G
    if extra is not None:
        rows = np.flatnonzero(extra)
        kr -= V[rows].T @ (extra[rows, None] * V[rows])
    return kr


@dataclass
class ModalBasis:
    """Precomputed modes of one shell with fixed nodes (Kim eq. 8).

    Attributes
    ----------
    free : (n_free,) int array
        The free nodes.
    phi : (3 n_free, r) float array
        Mass-normalized mode shapes.
    lam : (r,) float array
        Their eigenvalues.
    mass : (n,) float array
        Lumped masses.
    n : int
        The shell's nodes.
    rotation : object
        The skin's rotation operator, for psi (the modes' rotation fields, made on first use).
    """

    free: np.ndarray          # (n_free,) free node indices
    phi: np.ndarray           # (3 n_free, r) mass-normalized mode shapes
    lam: np.ndarray           # (r,) eigenvalues
    _psi: np.ndarray | None   # (3 n_free, r) rotation field of each mode (None: made when first used)
    mass: np.ndarray          # (n,) lumped masses
    n: int
    rotation: object = None   # the skin's rotation operator, for psi

    @property
    def psi(self) -> np.ndarray:
        """The rotation field of each mode, W Phi, made the first time warping needs it: most
        of a library's systems are never warped in a given performance, and smoothing the
        field was 0.2 s a system (12 of 29 s for the whole library on the 11k head)."""
        if self._psi is None:
            dof = (3 * self.free[:, None] + np.arange(3)).ravel()
            full = np.zeros((3 * self.n, self.phi.shape[1]))
            full[dof] = self.phi
            self._psi = (self.rotation @ full)[dof]
        return self._psi

    @cached_property
    def output32(self) -> tuple[np.ndarray, bool]:
        """Phi in single precision for the skin output, and whether it is padded with zero rows
        to every node (when the free nodes are most of the skin: no scatter needed)."""
        if len(self.free) > 0.4 * self.n:
            return self.padded32(self.phi), True
        return np.ascontiguousarray(self.phi, dtype=np.float32), False

    def padded32(self, rows: np.ndarray) -> np.ndarray:
        """Rows over the free nodes' dofs (3 n_free, k) -> (3 n, k) float32, zero at fixed nodes."""
        full = np.zeros((3 * self.n, rows.shape[1]), np.float32)
        full[(3 * self.free[:, None] + np.arange(3)).ravel()] = rows
        return full

    @classmethod
    def compute(cls, energy: ShellEnergy, mass: np.ndarray, fixed: np.ndarray, r: int = 20,
                load_nodes=None, stiffness=None, rotation=None, load_shapes=None,
                span_springs=None) -> "ModalBasis":
        """Modes of the shell with `fixed` nodes removed, for forces on `load_nodes`, or of the
        given force patterns `load_shapes` (3n, k) (a drive's anchors moving, a muscle's fanned
        springs pulling).

        Without either, the loads are uniform body forces (gravity); r sets how many
        Krylov vectors are added beyond the static load shapes.  span_springs: per-dof
        stiffness (3n,) added to `stiffness` in the solves that make the Ritz vectors (a
        muscle's springs), so that its static response lies in the span exactly, while the
        modes' eigenvalues stay the skin's alone (the springs are the muscle system's own).
        """
        n = energy.n
        fixed = np.asarray(fixed, bool)
        free = np.nonzero(~fixed)[0]
        if len(free) == 0:
            raise MimicaError("modal basis: every node is fixed")
        K = energy.rest_stiffness() if stiffness is None else stiffness
        dof = (3 * free[:, None] + np.arange(3)).ravel()
        Kff = K[dof][:, dof].tocsc()
        m = np.repeat(mass[free], 3)
        r = max(1, min(r, len(dof) - 2))
        # Load-dependent Ritz vectors (Wilson, Yuan & Dickens 1982) stand in for ARPACK: the
        # static shapes of the loads, K^-1 F, then Krylov blocks K^-1 M (...), all with one
        # sparse Cholesky and block solves; the eigenproblem of eq. 8 is then solved exactly
        # on that subspace (Rayleigh-Ritz).  The load shapes make the static response to any
        # force on the load nodes exact, which the lowest (bending) modes alone cannot give
        # for forces along the skin.
        shift = -1e-9 * float(np.abs(Kff.diagonal()).mean() / m.mean())   # keeps drifting parts solvable
        extra = None if span_springs is None else np.asarray(span_springs, float)[dof]   # diagonal E
        Ks = Kff if extra is None else Kff + sp.diags(extra)
        fac = SPDSolver((Ks - shift * sp.diags(m)).tocsc())
        if load_shapes is not None:
            loads = np.asarray(load_shapes, float).reshape(3 * n, -1)[dof]
        elif load_nodes is not None and len(load_nodes):
            pos = np.full(n, -1)
            pos[free] = np.arange(len(free))
            ln = pos[np.asarray(load_nodes)]
            ln = ln[ln >= 0]
            loads = np.zeros((len(dof), 3 * len(ln)))
            cols = (3 * ln[:, None] + np.arange(3)).ravel()
            loads[cols, np.arange(len(cols))] = 1.0
        else:
            loads = np.zeros((len(dof), 3))                                # uniform body loads
            for c in range(3):
                loads[c::3, c] = m[c::3]
        blocks = [fac.solve(loads)]
        width, at, prevs = 0, 0, []                        # at: the last block's first column in V
        while width < r:                                   # r Krylov vectors beyond the loads
            prev = blocks[-1][:, : min(blocks[-1].shape[1], r - width)]
            prevs.append(at + np.arange(prev.shape[1]))
            at += blocks[-1].shape[1]
            blocks.append(fac.solve(m[:, None] * prev))
            width += prev.shape[1]
        V = np.hstack(blocks)
        # M-orthonormal basis of the span, then the reduced eigenproblem (Rayleigh-Ritz)
        S = np.sqrt(m)[:, None] * V
        G = S.T @ S                                        # V^T M V
        g, U = np.linalg.eigh(G)
        if g[0] > 1e-8 * g[-1]:
            # well conditioned: orthonormal through the Gram matrix (orthonormal to about
            # 1e-8, a third of Householder's time on the whole library), V C with C = U g^-1/2
            # kept folded into the small matrices: one product over the dofs fewer
            C = U / np.sqrt(g)
            kr = C.T @ _stiffness_products(V, G, loads, prevs, shift, extra) @ C
        else:
            # rank-revealing (pivoted) QR: dependent columns (two strip nodes sharing a skin
            # node load it alike) go last and are dropped without taking the others' parts along
            q, rr, _ = scipy.linalg.qr(S, mode="economic", pivoting=True)
            keep = np.abs(np.diag(rr)) > 1e-10 * np.abs(rr[0, 0])
            V, C = q[:, keep] / np.sqrt(m)[:, None], np.eye(int(keep.sum()))
            kr = V.T @ (Kff @ V)
        lam, y = np.linalg.eigh(0.5 * (kr + kr.T))
        return cls._ritz(free, V, C @ y, lam, m, mass, n, energy, rotation)

    @classmethod
    def _ritz(cls, free, V, y, lam, m, mass, n, energy, rotation) -> "ModalBasis":
        """The basis of Ritz vectors V y (lowest first, mass-normalized)."""
        order = np.argsort(lam)
        phi = V @ y[:, order]
        lam = np.maximum(lam[order], 0.0)
        phi /= np.sqrt(np.einsum("ij,i,ij->j", phi, m, phi))[None, :]      # Phi^T M Phi = I
        W = rotation_operator(energy.rest, energy.triangles) if rotation is None else rotation
        return cls(free, phi, lam, None, mass, n, W)

    def to_arrays(self) -> dict:
        """Plain arrays for a file (the rig's); mode shapes in single precision, the rotation
        field is derived again on load."""
        return {"free": self.free, "phi": self.phi.astype(np.float32), "lam": self.lam, "mass": self.mass,
                "n": np.array(self.n)}

    @classmethod
    def from_arrays(cls, d: dict, rotation) -> "ModalBasis":
        """The basis of to_arrays(); `rotation` is the skin's rotation operator (rotation_operator)."""
        free, phi, n = np.asarray(d["free"]), np.asarray(d["phi"], np.float64), int(d["n"])
        return cls(free, phi, np.asarray(d["lam"], np.float64), None, np.asarray(d["mass"]), n, rotation)


class ModalWarpingSolver:
    """Kim eq. 10 integrated per mode; `step(force)` advances one time step h.

    Parameters
    ----------
    basis : ModalBasis
    h : float
        The time step, seconds.
    xi, zeta : float
        Rayleigh damping: c = xi + zeta lambda per mode.
    density : float
        Scales the mass (the basis was computed for density 1): eigenvalues and modal forces divide
        by it, displacements are unchanged.
    """

    def __init__(self, basis: ModalBasis, h: float, xi: float = 2.0, zeta: float = 0.01, density: float = 1.0):
        """density scales the mass (the basis was computed for density 1): eigenvalues and
        modal forces divide by it, displacements are unchanged."""
        self.b, self.h, self.density = basis, h, density
        self.lam = basis.lam / density
        self.c = xi + zeta * self.lam                          # Rayleigh damping per mode
        self.q = np.zeros(len(basis.lam))
        self.v = np.zeros_like(self.q)
        self.denom = 1.0 + h * self.c + h * h * self.lam
        self.rot = np.tile(np.eye(3), (len(basis.free), 1, 1))

    def reset(self):
        self.q[:] = 0
        self.v[:] = 0
        self.rot[:] = np.eye(3)

    def step(self, force: np.ndarray, warp: bool = True) -> np.ndarray:
        """force: (n, 3) external nodal forces in world space; returns displacements (n, 3).
        warp=False: plain linear modal analysis (forces not rotated, u = Phi q)."""
        b = self.b
        f = force[b.free]
        if warp:
            f = np.einsum("kji,kj->ki", self.rot, f)                    # R^T F per node
        fq = b.phi.T @ f.ravel() / self.density                         # Phi^T R^T F
        # implicit Euler per mode: v' = (v + h (f - lam q)) / (1 + h c + h^2 lam)
        self.v = (self.v + self.h * (fq - self.lam * self.q)) / self.denom
        self.q = self.q + self.h * self.v
        return self.displacement(warp)

    def rows(self, nodes: np.ndarray) -> np.ndarray:
        """Mode shapes at some nodes, (k, 3, r); zero at fixed nodes."""
        b = self.b
        pos = np.full(b.n, -1)
        pos[b.free] = np.arange(len(b.free))
        p = pos[np.asarray(nodes)]
        ok = p >= 0
        dof = (3 * np.maximum(p, 0)[:, None] + np.arange(3))
        return b.phi[dof] * ok[:, None, None]

    def add_displacement(self, u: np.ndarray, warp: bool = False):
        """u += this system's displacement, u (n, 3) C-contiguous.  The linear one (Phi q) is
        computed in single precision, the output being for display (the state stays double):
        half the memory traffic of the dense modes."""
        if warp:
            u += self.displacement(True)
            return
        phi, padded = self.b.output32
        y = phi @ self.q.astype(np.float32)
        if padded:                       # a plain add beats a scatter over most of the skin
            flat = u.reshape(-1)
            flat += y
        else:
            u[self.b.free] += y.reshape(-1, 3)

    def displacement(self, warp: bool = True) -> np.ndarray:
        """u = R (Phi q) node by node (modal warping), or the linear Phi q."""
        b = self.b
        local = (b.phi @ self.q).reshape(-1, 3)
        u = np.zeros((b.n, 3))
        if warp:
            # forces go into the nodes' frames by R^T (Kim eq. 10); the displacement is the
            # integrated rotation applied to the local one.  self.rot keeps R(q) for the next
            # step's forces: a function of q alone, so calling this again changes nothing
            self.rot, warp_m = rotations((b.psi @ self.q).reshape(-1, 3))
            u[b.free] = np.einsum("kij,kj->ki", warp_m, local)
        else:
            u[b.free] = local
        return u


class FullSolver:
    """Reference: implicit Euler on the full nonlinear shell, projected Newton at every step.

    M (v' - v) / h = F - grad E(x + h v') - C v',  C = xi M + zeta K_rest.
    The step is the minimum over v' of implicit Euler's incremental potential
        Phi(v') = 1/2 |v' - v|_M^2 - h F.v' + E(x + h v') + h/2 v'^T C v'
    (its gradient is h times the residual above), found by Newton on a positive semi-definite
    Hessian (ShellEnergy.hessian(project=True)) with a backtracking (Armijo) line search on Phi:
    every iterate lowers the potential, so a strong activation that folds the skin slows the solve
    down instead of making it diverge.  Converged when the residual force is under tol (relative
    to the largest applied force) or when an iterate moves no node by more than xtol (a length);
    `stats` counts the steps, the Newton iterations and the steps that ran out of iterations.

    Parameters
    ----------
    energy : ShellEnergy
    mass : (n,) float array
        Lumped masses.
    fixed : (n,) bool array
        Nodes held.
    h : float
        The time step.
    xi, zeta : float
        Rayleigh damping.
    newton_iters : int
        Newton iterations a step at most.
    tol : float
        The relative residual force that counts as converged.
    springs : (n,) float array or None
        Per-node stiffness of linear springs to the rest position (the face's tethers and
        subcutaneous springs), added to E.
    xtol : float
        A step that moves no node by more than this has converged.
    """

    def __init__(self, energy: ShellEnergy, mass: np.ndarray, fixed: np.ndarray, h: float,
                 xi: float = 2.0, zeta: float = 0.01, newton_iters: int = 8, tol: float = 1e-9,
                 springs: np.ndarray | None = None, xtol: float = 0.0):
        self.E, self.h = energy, h
        self.fixed = np.asarray(fixed, bool)
        self.free = np.nonzero(~self.fixed)[0]
        self.dof = (3 * self.free[:, None] + np.arange(3)).ravel()
        self.m = np.repeat(mass, 3)
        self.ks = np.zeros(3 * energy.n) if springs is None else np.repeat(np.asarray(springs, float), 3)
        self.K0 = (energy.hessian(energy.rest) + sp.diags(self.ks)).tocsr()
        self.C = (xi * sp.diags(self.m) + zeta * self.K0).tocsr()       # Rayleigh damping
        self.iters, self.tol, self.xtol = newton_iters, tol, xtol
        self._spd = None
        self.stats = {"steps": 0, "iterations": 0, "unconverged": 0}
        self.u = np.zeros((energy.n, 3))
        self.v = np.zeros((energy.n, 3))

    def set_springs(self, springs: np.ndarray) -> None:
        """New per-node spring stiffnesses from the next step on (the damping keeps its own)."""
        self.ks = np.repeat(np.asarray(springs, float), 3)

    def _direction(self, x, res):
        """The Newton direction for v: (M/h + C + h (H+ + K_springs)) dv = -res on the free dofs,
        H+ the PSD Hessian at x; factored by CHOLMOD, its ordering kept from the first step."""
        d, h = self.dof, self.h
        J = (sp.diags(self.m / h + h * self.ks) + self.C
             + h * self.E.hessian(x.reshape(-1, 3), project=True))[d][:, d].tocsc()
        if self._spd is None:
            self._spd = SPDSolver(J)
        else:
            self._spd.refactor(J)
        return self._spd.solve(-res[d])

    def _potential(self, v, x0, f) -> float:
        """Phi(v) of the class docstring; inf where the shell is degenerate."""
        h, x = self.h, x0 + self.h * v
        dv = v - self.v.ravel()
        with np.errstate(all="ignore"):
            e = self.E.energy(x.reshape(-1, 3))
        r = x - self.E.rest.ravel()
        phi = 0.5 * dv @ (self.m * dv) - h * f @ v + e + 0.5 * r @ (self.ks * r) + 0.5 * h * v @ (self.C @ v)
        return phi if np.isfinite(phi) else np.inf

    def _residual(self, v, x0, f):
        x = x0 + self.h * v
        g = self.E.gradient(x.reshape(-1, 3)).ravel() + self.ks * (x - self.E.rest.ravel())
        return self.m * (v - self.v.ravel()) / self.h - f + g + self.C @ v, x

    def step(self, force: np.ndarray) -> np.ndarray:
        d, h = self.dof, self.h
        x0 = (self.E.rest + self.u).ravel()
        v = self.v.ravel().copy()
        f = force.ravel()
        tol = self.tol * max(1.0, np.abs(f).max())
        res, x = self._residual(v, x0, f)
        phi = self._potential(v, x0, f)
        converged = False
        for _ in range(self.iters):
            if np.abs(res[d]).max() < tol:
                converged = True
                break
            dv = self._direction(x, res)
            slope = h * (res[d] @ dv)                  # dPhi/dalpha at 0, < 0 (SPD matrix)
            self.stats["iterations"] += 1
            alpha = 1.0
            while alpha > 1e-10:
                vt = v.copy()
                vt[d] += alpha * dv
                pt = self._potential(vt, x0, f)
                if pt <= phi + 1e-4 * alpha * slope:   # Armijo
                    break
                alpha *= 0.5
            else:                                      # Phi no longer resolves a decrease
                converged = True
                break
            v, phi = vt, pt
            res, x = self._residual(v, x0, f)
            if alpha * h * np.abs(dv).max() < self.xtol:
                converged = True
                break
        self.stats["steps"] += 1
        if not converged and np.abs(res[d]).max() >= tol:
            self.stats["unconverged"] += 1
        self.v = v.reshape(-1, 3)
        self.v[self.fixed] = 0
        self.u = self.u + h * self.v
        return self.u.copy()


def against_full(energy: ShellEnergy, mass: np.ndarray, fixed: np.ndarray, force: np.ndarray, h: float,
                 steps: int, r: int = 20, load_nodes=None, **damping) -> dict:
    """Run the full Newton solver and the modal solver side by side under a constant force.

    Parameters
    ----------
    energy : ShellEnergy
    mass : (n,) float array
    fixed : (n,) bool array
    force : (n, 3) float array
    h : float
    steps : int
    r : int
        Krylov vectors of the modal basis beyond its loads.
    load_nodes : array or None
        Where the force acts (the basis's loads).
    **damping
        xi, zeta.

    Returns
    -------
    dict
        {'full': u, 'linear': dev, 'warped': dev, 'full_steps_per_s', 'modal_steps_per_s'}, dev
        the largest nodal distance from the full solver's displacement over its largest
        displacement.
    """
    full = FullSolver(energy, mass, fixed, h, **damping)
    t = time.perf_counter()
    for _ in range(steps):
        uf = full.step(force)
    out = {"full": uf, "full_steps_per_s": steps / (time.perf_counter() - t)}
    basis = ModalBasis.compute(energy, mass, fixed, r=r, load_nodes=load_nodes)
    scale = np.linalg.norm(uf, axis=1).max()
    for name, warp in (("linear", False), ("warped", True)):
        ms = ModalWarpingSolver(basis, h, **damping)
        t = time.perf_counter()
        for _ in range(steps):
            um = ms.step(force, warp)
        if warp:
            out["modal_steps_per_s"] = steps / (time.perf_counter() - t)
        out[name] = float(np.linalg.norm(um - uf, axis=1).max() / scale)
    return out
