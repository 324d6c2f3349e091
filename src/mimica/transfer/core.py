"""Expression transfer as one sparse least-squares system per target (Song §IV, eqs. 4-7).

    min_x  sum_e || Q_t,e(x) - Q_s,e ||_F^2  +  sum_i w_i || x_i - a_i ||^2

Q_s,e is the source deformation of element e (Song eq. 2), carried to the target's
elements through a correspondence matrix P (identity on the same topology);
Q_t,e(x) = A x is linear in the target unknowns (vertices and tips; Song eq. 5).  Vertices
that never move in the source are fixed to the target's rest positions ("regions that do
not move stay put").  The second term ties every vertex to a_i, its rest position plus the
source's displacement at its partner.  Song's energy has only a vanishing weight there
(1e-6 of the mean stiffness, which removes the translation of parts without a fixed vertex);
mimica's default adds ANCHOR * (the vertex's share of the area) / size^2, the discrete form of
ANCHOR / L^2 * integral |x - a|^2 dA, so that motion longer than about L / sqrt(ANCHOR)
(~1 cm on a head) comes from the source and shorter motion from the deformations.  Departure,
measured (docs/benchmarks.md): with the vanishing weight alone the gradients' small errors add
up over the face -- on a remeshed face a still neck moved and a still forehead drifted by
0.02 of the face's size when the jaw opened; on targets whose proportions were changed (the
mouth 1.35x, the eyes 1.3x; the truth being the change applied to the expression, not the
source's displacement copied) the same-topology error fell 0.213 -> 0.139 (mouth) and
0.071 -> 0.041 (eyes) from ANCHOR 0 to 1000 and rose again beyond it.  Since the source's own
S' satisfies every term exactly, self-transfer stays exact.

Across topologies the VTC energy also holds each target triangle to the source deformation
at its corners (Sumner & Popović's per-triangle term, weight DT_STABILIZER; see there).

`TransferSolver(...)` does everything that depends on the target (the factorization);
`apply(frames)` moves a whole batch of source frames through one back-substitution.
"""

from __future__ import annotations

from functools import cached_property

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from .._memory import prefaulted
from ..parallel import cores, one_blas_thread
from ..errors import MimicaError
from ..mesh import Mesh
from .elements import Elements, dt_elements, gradient_operator, vtc_elements
from ..solver import SPDSolver

METHODS = {"vtc": vtc_elements, "dt": dt_elements}
EPS_ANCHOR = 1e-6
ANCHOR = 1000.0
# Across topologies, VTC's energy gets Sumner & Popović's per-triangle term at this weight
# (area-weighted, both means 1).  A departure from Song et al.: a vertex whose one-ring is
# made of slivers (a coarse lip rolling into the mouth) is barely held by its own tent and by
# its neighbours' least-squares fits, and drifts; a triangle's frame pins its three corners.
# Measured (bench/real_heads.py): the 468-vertex head's damaged shapes 3 -> 0; remeshed error
# of four tuning identities (seeds 201-204) 0.1145 -> 0.1105 / 0.1097 / 0.1096 / 0.1101 at
# weights 0.1 / 0.3 / 1 / 3; the held-out figure of bench/transfer.py 0.0896 -> 0.087.
DT_STABILIZER = 0.5
BASIS_TOL = 1e-5          # a sequence's basis keeps all but this share of its motion (RMS)
BASIS_TOL_TIPS = 1e-4     # ... and of the motion in its tips' nonlinear part
BASIS_MAX = 0.25          # ... and is used only when it has at most this share of its training rows
BASIS_TIPS_MAX = 0.6      # ... (the tips: of their training rows)
BASIS_TRAIN = 64          # frames on which the source's basis and the tips' are found


def _orthonormal(a: np.ndarray) -> np.ndarray:
    """Orthonormal columns spanning a tall (n, p) matrix up to its numerical rank: from the
    eigenvectors of its Gram matrix, twice (as Cholesky QR twice, Fukaya et al. 2014: two GEMMs
    and a p x p eigenproblem, several times faster here than Householder QR); directions whose
    eigenvalue is under 1e-14 of the largest (singular values under 1e-7) are dropped -- at 1e-10
    they dropped a 12-shape take's directions at 1.2e-5, and its basis never reached BASIS_TOL."""
    q = np.asarray(a, np.float64)
    for _ in range(2):
        w, v = np.linalg.eigh(_inner(q.T))
        keep = w > 1e-14 * max(float(w.max()), 1e-300)
        q = _matmul(q, v[:, keep] / np.sqrt(w[keep]))
    return np.ascontiguousarray(q, dtype=a.dtype)


def _basis(samples: np.ndarray, tol: float, scale: float | None = None, start: int = 24) -> np.ndarray | None:
    """An orthonormal basis Q (dim, k) of the rows of `samples` (m, dim), the rows' residual
    outside it within tol of `scale` (default: the rows' own norm), by a randomized range finder
    (Halko, Martinsson & Tropp 2011) with the sketch grown until it holds; None when k would
    exceed BASIS_MAX of the rows (not a low-rank motion)."""
    m = samples.shape[0]
    flat = samples.reshape(-1)
    total = float(flat @ flat)
    ref = total if scale is None else scale * scale
    if total <= (tol * tol) * max(ref, 1e-300):
        return np.zeros((samples.shape[1], 0))
    limit = max(1, int(BASIS_MAX * m))
    rng = np.random.default_rng(0)
    p = min(limit + 8, start, m)
    while True:
        # the products on the cores (_matmul, _inner); the sketch this way round (3.8 against 5.9 ms
        # on one core)
        sketch = _matmul(rng.standard_normal((p, m)), samples, split="columns").T
        q = _orthonormal(sketch)
        b = _inner(q.T, samples.T)                                            # (p, m)
        u, sv, _ = np.linalg.svd(b, full_matrices=False)
        tail = total - np.cumsum(sv * sv)                                     # energy outside the first k
        ok = np.nonzero(tail <= (tol * tol) * ref)[0]
        if len(ok):
            k = int(ok[0]) + 1
            return None if k > limit else q @ u[:, :k]
        if p >= min(m, limit + 8):
            return None
        p = min(2 * p, m, limit + 8)


def _coordinate_rows(frames: np.ndarray, S: np.ndarray, at: np.ndarray) -> np.ndarray:
    """(3F, n) the displacements of the frames `at`, row 3f + c: frame f's coordinate c; frame
    by frame into place (gathering the frames, then transposing them: 4 against 16 ms for
    bench/batch.py's 64 training frames)."""
    out = np.empty((len(at), 3, len(S)))
    st = S.T

    def one(i):
        for j in range(i, min(i + 16, len(at))):
            np.subtract(frames[at[j]].T, st, out=out[j])
    _blocks(one, len(at), 16)
    return out.reshape(3 * len(at), len(S))


_POOL = None


def _blocks(work, n: int, size: int) -> None:
    """work(i) for i = 0, size, 2 size ... < n, on all cores (numpy's loops and single-threaded
    BLAS release the GIL; BLAS's own threads measured slower here, fighting CHOLMOD's).  One
    pool for the process, started on first use (again in a forked child, which has none of its
    threads): a pool a call started 10 threads a basis transfer, 11 of its 183 ms under cProfile
    (bench/batch.py's 300 frames).  Work already on one of its threads runs where it is (a
    task waiting on its own pool could wait forever)."""
    import os
    import threading
    from concurrent.futures import ThreadPoolExecutor
    global _POOL
    starts = range(0, n, size)
    n_cores = cores()
    if min(n_cores, len(starts)) <= 1 or threading.current_thread().name.startswith("mimica-blocks"):
        for i in starts:
            work(i)
        return
    if _POOL is None or _POOL[0] != os.getpid():
        _POOL = (os.getpid(), ThreadPoolExecutor(n_cores, thread_name_prefix="mimica-blocks"))
    list(_POOL[1].map(work, starts))


def _matmul(a: np.ndarray, b: np.ndarray, split: str = "rows") -> np.ndarray:
    """a @ b, a's rows (or b's columns) in two halves on the cores (see _blocks)."""
    out = np.empty((a.shape[0], b.shape[1]), np.result_type(a, b))
    rows = split == "rows"
    n = a.shape[0] if rows else b.shape[1]
    size = max(1, -(-n // 2))

    def one(i):
        if rows:
            np.matmul(a[i:i + size], b, out=out[i:i + size])
        else:
            np.matmul(a, b[:, i:i + size], out=out[:, i:i + size])
    _blocks(one, n, size)
    return out


def _project(frames: np.ndarray, S: np.ndarray, q: np.ndarray, chunk: int = 16):
    """Coefficients (k, 3F) of every frame's displacement on the orthonormal basis q (n, k), in
    the rows' order of _coordinate_rows, the energy outside q and the total, frames a chunk at
    a time (no transposed copy of the whole sequence)."""
    nf, k = len(frames), q.shape[1]
    c = np.empty((nf, k, 3))
    qt = np.ascontiguousarray(q.T)
    totals = np.zeros(-(-nf // chunk))

    def one(i):
        d = frames[i:i + chunk] - S
        totals[i // chunk] = np.vdot(d, d)
        if k <= 24:                                     # a GEMM of 3 columns a frame, over blocks of
            m = len(d)                                  # vertices whose rows of q stay in cache for
            acc, part = c[i:i + m], np.empty((m, k, 3))  # the chunk's frames (17 -> 14 ms)
            acc[:] = 0.0
            for v in range(0, len(S), 2048):
                np.matmul(qt[:, v:v + 2048], d[:, v:v + 2048], out=part)
                acc += part
        else:                                           # one GEMM for the chunk (72 shapes: 137 -> 53 ms;
            m = len(d)                                  # 18: 17 against 59)
            c[i:i + m] = (qt @ d.transpose(1, 0, 2).reshape(len(S), 3 * m)).reshape(k, m, 3).transpose(1, 0, 2)
    _blocks(one, nf, chunk)
    total = float(totals.sum())
    inside = float(np.vdot(c, c))
    return np.ascontiguousarray(c.transpose(1, 0, 2)).reshape(k, 3 * nf), max(total - inside, 0.0), total


def _bend_rows(el: Elements, lin, coef_rows: np.ndarray, at=None, chunk: int = 8) -> np.ndarray:
    """The tips' nonlinear part minus its rest value, (3F, E), for frames given by their
    coefficient rows (3F, k) on the basis whose tip operators' products are lin = (a Q, b Q,
    a S, b S, g(a S, b S)), at the elements `at` (default all), a few frames at a time so that
    the temporaries stay in cache."""
    aq, bq, a0, b0, g0 = lin
    if at is not None:
        aq, bq, a0, b0, g0 = aq[at], bq[at], a0[at], b0[at], tuple(g[at] for g in g0)
    nf, e = len(coef_rows) // 3, len(aq)
    out = np.empty((nf, 3, e))
    aq_t, bq_t = np.ascontiguousarray(aq.T), np.ascontiguousarray(bq.T)

    def one(i):
        rows = coef_rows[3 * i:3 * (i + chunk)]
        m = len(rows) // 3
        A = (rows @ aq_t).reshape(m, 3, e)
        B = (rows @ bq_t).reshape(m, 3, e)
        A += a0.T[None]
        B += b0.T[None]
        g = el.tip_bend((A[:, 0], A[:, 1], A[:, 2]), (B[:, 0], B[:, 1], B[:, 2]), at)
        for c in range(3):
            np.subtract(g[c], g0[c], out=out[i:i + m, c])
    _blocks(one, nf, chunk)
    return out.reshape(3 * nf, e)


def _inner(a: np.ndarray, b: np.ndarray | None = None) -> np.ndarray:
    """a @ b (default a @ a.T, numpy's SYRK) for a wide (m, n) a: the n's in blocks on the cores
    (see _blocks), summed: the 192 x 11,248 tips' rows of bench/batch.py's basis path, a @ a.T
    11.1 -> 5.5 ms."""
    nb = max(1, min(cores(), a.shape[1] // 2048))
    size = -(-a.shape[1] // nb)
    parts = [None] * nb

    def one(j):
        x = a[:, j:j + size]
        parts[j // size] = x @ (x.T if b is None else b[j:j + size])
    _blocks(one, a.shape[1], size)
    return sum(parts)


def _gram_basis(rows: np.ndarray, tol: float, scale: float) -> np.ndarray | None:
    """An orthonormal basis (dim, k) of the rows (m, dim), m small: from the eigenvectors of
    their Gram matrix (31 against the range finder's 127 ms on 300 x 11,248 tips), truncated where the
    energy left outside is within tol of `scale`; None when k would exceed BASIS_TIPS_MAX of
    the rows' count.  (Eigenvalues resolve to 1e-16 of the largest: tol down to 1e-7 holds.)"""
    w, v = np.linalg.eigh(_inner(rows))
    w, v = np.maximum(w[::-1], 0.0), v[:, ::-1]
    tail = w.sum() - np.cumsum(w)
    k = int(np.nonzero(tail <= (tol * tol) * max(scale * scale, 1e-300))[0][0]) + 1 if w.sum() > 0 else 0
    if k > max(1, int(BASIS_TIPS_MAX * len(rows))):
        return None
    scaled = v[:, :k] / np.sqrt(np.maximum(w[:k], 1e-300))
    return _matmul(rows.T, scaled)                                             # orthonormal to 1e-10


def _deim_points(q: np.ndarray, rounds: int = 3) -> np.ndarray:
    """Rows of q (n, k) to interpolate it from: `rounds` rounds of k pivots of a pivoted QR
    of q's transpose (Q-DEIM, Drmač & Gugercin 2016), each round among the rows not yet taken
    (oversampling: the least-squares fit from 3k rows measured 2x closer than from k), the
    candidates restricted to the 10k rows of largest leverage (8x faster, 1.2x the error)."""
    k = q.shape[1]
    if k == 0:
        return np.zeros(0, int)
    cand = np.argsort(-np.einsum("ij,ij->i", q, q))[:10 * k]
    taken = np.zeros(len(cand), bool)
    for _ in range(rounds):
        left = np.nonzero(~taken)[0]
        if len(left) == 0:
            break
        _, piv = sla.qr(q[cand[left]].T, mode="r", pivoting=True)
        taken[left[piv[:k]]] = True
    return np.sort(cand[taken])


def _combine(Z: np.ndarray, coef: np.ndarray, x0: np.ndarray, block: int = 8, out=None) -> np.ndarray:
    """x0 + Z @ coef as frames (F, n, 3), Z (n, k), coef (k, F, 3): single-precision GEMMs
    (rounding 1e-7 of the motion) a few frames at a time, each block transposed into place
    while in cache, blocks on all cores (one double-precision GEMM and a transpose of the
    whole output measured 3.6x slower)."""
    n, k = Z.shape
    nf = coef.shape[1]
    out = np.empty((nf, n, 3)) if out is None else out
    z = Z.astype(np.float32, copy=False)
    c = coef.astype(np.float32)

    def one(i):
        m = min(block, nf - i)
        y = (z @ c[:, i:i + m].reshape(k, 3 * m)).reshape(n, m, 3)
        np.add(y.transpose(1, 0, 2), x0[None], out=out[i:i + block])
    _blocks(one, nf, block)
    return out


def static_vertices(source_neutral: np.ndarray, frames: np.ndarray, rtol=1e-7) -> np.ndarray:
    """The source's vertices that move in none of the frames.

    Parameters
    ----------
    source_neutral : (n, 3) float array
    frames : (F, n, 3) float array
    rtol : float
        A move under this share of the face's size counts as none.

    Returns
    -------
    (n,) bool array
    """
    scale = np.linalg.norm(source_neutral.max(0) - source_neutral.min(0))
    d = np.abs(np.asarray(frames) - source_neutral).max(axis=(0, 2)) if len(frames) else \
        np.zeros(len(source_neutral))
    return d <= rtol * scale


class TransferSolver:
    """The expression transfer's linear system (Song et al. §IV; Sumner and Popović for DT), factored
    once per (source neutral, target neutral, correspondence) and applied to many frames.

    Parameters
    ----------
    source, target : Mesh
        The two neutral meshes, already aligned (same frame and scale).
    method : str
        "vtc" or "dt".
    vertex_map : (n_target, n_source) sparse matrix or None
        Rows of barycentric weights mapping target vertices to source surface points; None for
        the same topology (identity).
    matched : (n_target,) bool array or None
        Target vertices that have a partner; the others keep their rest shape (Q = identity).
    fixed : (n_target,) bool array or None
        Target vertices held at their rest position.
    solver_kind : str or None
        The sparse solver (SPDSolver).
    weighting : str
        How elements weigh in the energy ("area").
    dt_weight : float
        The weight of a per-triangle (DT) term added to a VTC energy (DT_STABILIZER is what
        ExpressionTransfer uses across topologies); 0 for Song's energy alone.
    anchor : float
        The weight of each matched vertex's tie to its rest position plus the source's
        displacement at its partner, at the face's scale (ANCHOR is ExpressionTransfer's
        default; see the module docstring); 0 leaves only the vanishing EPS_ANCHOR tie.
    """

    def __init__(self, source: Mesh, target: Mesh, method="vtc", vertex_map=None,
                 matched=None, fixed=None, solver_kind=None, weighting="area", dt_weight=0.0, anchor=0.0):
        if method not in METHODS:
            raise MimicaError(f"unknown transfer method {method!r}; use one of {', '.join(METHODS)}")
        self.method = method
        self.source, self.target = source, target
        ns, nt = source.n_vertices, target.n_vertices
        self.same_topology = vertex_map is None
        if vertex_map is None:
            if not source.same_topology(target):
                raise MimicaError("source and target have different topologies; "
                                  "a correspondence (vertex_map) is needed")
            vertex_map = sp.identity(ns, format="csr")
        self.vertex_map = sp.csr_matrix(vertex_map)
        matched = np.ones(nt, bool) if matched is None else np.asarray(matched, bool)
        fixed = np.zeros(nt, bool) if fixed is None else np.asarray(fixed, bool)

        kinds = [(method, 1.0)] + ([("dt", dt_weight)] if dt_weight > 0 and method != "dt" else [])
        self.terms_s = [(METHODS[k](source), k) for k, _ in kinds]
        terms_t = [(METHODS[k](target), k, w) for k, w in kinds]
        es_all = [el.n_elements for el, _ in self.terms_s]
        et_all = [el.n_elements for el, _, _ in terms_t]
        es, et = sum(es_all), sum(et_all)

        def place(a, n, offset, total):
            """A term's (3E x (n+E)) operator on the stacked unknowns [x; tips of every term]."""
            a = a.tocsc()
            e = a.shape[1] - n
            return sp.hstack([a[:, :n], sp.csc_matrix((a.shape[0], offset)), a[:, n:],
                              sp.csc_matrix((a.shape[0], total - offset - e))]).tocsr()

        A_s, A_t, P, wts, c_id = [], [], [], [], []
        off_s = off_t = 0
        for (els, _), (elt, kind, w), e_s, e_t in zip(self.terms_s, terms_t, es_all, et_all):
            A_s.append(place(gradient_operator(els, source.vertices), ns, off_s, es))
            A_t.append(place(gradient_operator(elt, target.vertices), nt, off_t, et))
            # P: target element -> source elements (Song §V.A: each target VTC gets the source
            # deformation at its corresponding surface point, barycentric weights)
            p_el = self._element_map(matched, kind, elt)
            P.append(sp.kron(p_el, sp.identity(3), format="csr"))
            # unmatched elements keep Q = I: constant right-hand side rows
            unmatched = np.asarray(p_el.sum(axis=1)).ravel() < 0.5
            c = np.zeros((3 * e_t, 3))
            ue = np.nonzero(unmatched)[0]
            for j in range(3):
                c[3 * ue + j, j] = 1.0
            c_id.append(c)
            # rows weighted by the element's surface area, so that the energy is a surface
            # integral and does not depend on how densely each face is meshed
            wts.append(w * np.repeat(self._element_areas(elt, target) if weighting == "area" else np.ones(e_t), 3))
            off_s += e_s
            off_t += e_t
        self.A_s = sp.vstack(A_s).tocsr()                       # 3Es x (ns+Es)
        A_t = sp.vstack(A_t).tocsr()                            # 3Et x (nt+Et)
        self.P3 = sp.block_diag(P, format="csr")
        c_id = np.vstack(c_id)
        wts = np.concatenate(wts)

        n_unk = nt + et
        is_fixed = np.zeros(n_unk, bool)
        is_fixed[:nt] = fixed
        self.free = np.nonzero(~is_fixed)[0]
        self.fixed = np.nonzero(is_fixed)[0]
        A_f = A_t[:, self.free].tocsc()
        A_c = A_t[:, self.fixed].tocsc()
        AfW = (A_f.T @ sp.diags(wts)).tocsr()
        AtA = (AfW @ A_f).tocsr()
        eps = EPS_ANCHOR * float(AtA.diagonal().mean())
        vfree = self.free < nt                       # free unknowns that are vertices
        # the anchor's weight a vertex: eps everywhere, and where matched (anchor / L^2) times the
        # vertex's share of the surface (L the target's size), the discrete form of
        # anchor * integral |x - a|^2 dA / L^2 beside the elements' integral |Q_t - Q_s|^2 dA
        w_anchor = np.full(nt, eps)
        if anchor > 0:
            size2 = float(np.sum(np.ptp(target.vertices, axis=0) ** 2))
            w_anchor += np.where(matched, anchor * self._vertex_shares(target) / size2, 0.0)
        w_free = np.zeros(len(self.free))                      # the free unknowns' weights (tips: 0)
        w_free[vfree] = w_anchor[self.free[vfree]]
        anchor_sel = sp.csr_matrix((w_free[vfree], (np.nonzero(vfree)[0], self.free[vfree])),
                                   shape=(len(self.free), nt))
        M = (AtA + sp.diags(w_free)).tocsr()

        # rhs = R @ [S'; tips(S')] + k0, linear in the source frame (see module docstring)
        Vm = self.vertex_map
        fixed_v = self.fixed                                   # all fixed unknowns are vertices
        Vm_c = Vm[fixed_v]
        right = (anchor_sel @ Vm - AfW @ (A_c @ Vm_c)).tocsr()
        right.resize((len(self.free), ns + es))
        self.R = (AfW @ (self.P3 @ self.A_s)).tocsr() + right
        S, T = source.vertices, target.vertices
        k0 = (-AfW @ (A_c @ (T[fixed_v] - Vm_c @ S)) + AfW @ c_id
              + anchor_sel @ (T - Vm @ S))
        # Each tip appears only in its own element's rows, so the tip block of M is diagonal
        # and the tips are eliminated exactly (Schur complement): the factored system has
        # the free vertices only, with the sparsity of the two-ring.
        iv, it = np.nonzero(vfree)[0], np.nonzero(~vfree)[0]
        Mvt = M[iv][:, it]
        dinv = sp.diags(1.0 / M[it][:, it].diagonal())
        G = (Mvt @ dinv).tocsr()
        self.solver = SPDSolver((M[iv][:, iv] - G @ Mvt.T).tocsr(), solver_kind)
        self.R = (self.R[iv] - G @ self.R[it]).tocsr()
        self.k0 = k0[iv] - G @ k0[it]
        self.free = self.free[iv]
        self.n_target, self.n_unknowns = nt, n_unk
        # the fixed vertices' map, built here and not on first use: `apply` runs on threads
        self._vm_fixed = Vm_c.tocsr()
        self._fixed_base = T[fixed_v] - self._vm_fixed @ S

    def apply_basis(self, frames: np.ndarray, tol: float = BASIS_TOL, similarity=None, check: int = 0):
        """Frames (F, n_s, 3) through a basis of their motion: None where the
        motion, or its tips' bending, does not lie in few enough shapes, else the target frames
        (F, n_t, 3); `basis_stats` says what was used, or why not.
        check: this many frames are also solved one by one, exactly as `apply` would (in the
        same back-substitution as the basis: 12 columns more there against a solve of their own,
        8.5 ms): the frames off the training ones whose tips the interpolation misses most at its
        points (on seven takes their largest deviation was 0.90-1.0 of the whole sequence's; four
        frames spread evenly saw a quarter of it); `basis_stats["checked"]` their indices and
        `basis_stats["exact"]` their target frames.

        The system is linear in [S'; tips(S')], coordinate by coordinate.  The source's
        displacements (each frame's x, y and z columns) are reduced to an orthonormal basis Q,
        found on BASIS_TRAIN frames spread over the sequence (randomized range finder,
        truncated at `tol` of their energy) and checked on all of them; the tips' linear parts
        follow from Q by a few sparse products.  Their nonlinear part (the normalized normal of
        each tent, Song §IV; DT's scaled normal) is computed exactly on the same BASIS_TRAIN
        frames, reduced to its own basis, and interpolated for every frame from a few elements
        (DEIM, Chaturantabut & Sorensen 2010, points by pivoted QR as Drmač & Gugercin 2016,
        oversampled 3x, least squares; what the fit misses at its points picks the frames
        `check` solves).  The back-substitution then runs once per basis vector, not once per
        frame; frames are combinations of the basis solutions (one GEMM, single precision, frame
        block by frame block in the output's layout), into an output whose pages another thread
        maps while the solve runs.
        Exact but for the truncations, the interpolation and the GEMM's rounding (1e-7)."""
        with one_blas_thread():
            return self._apply_basis(frames, tol, similarity, check)

    def _apply_basis(self, frames, tol, similarity, check):
        frames = np.asarray(frames, dtype=np.float64)
        nf = len(frames)
        S = self.source.vertices
        train = np.unique(np.linspace(0, nf - 1, min(nf, BASIS_TRAIN)).round().astype(int))
        self.basis_stats = {"trained": train}
        # at most BASIS_MAX of the training rows (48): the tips need more shapes than the motion
        # (18 -> 64, 35 -> 90 measured on takes of 6 and 12 ICT shapes) and 72 (24 shapes) found
        # more than the training frames hold after 0.25 s; a richer motion goes frame by frame
        # at once (trying it on every frame's rows cost 2-3x the frame-by-frame time)
        qd = _basis(_coordinate_rows(frames, S, train), tol)
        if qd is None:
            self.basis_stats["why"] = "the motion does not lie in few shapes"
            return None
        cd, outside, total = _project(frames, S, qd)
        # every frame within twice the tolerance of the training frames' basis (its truncation
        # leaves the others a little more: 1.003e-10 of a 12-shape take's energy against 1e-10);
        # motion the training frames do not see (a short event between them) goes frame by frame
        # (finding the basis on every frame instead measured slower than frame by frame)
        if outside > 4 * tol * tol * total:
            self.basis_stats["why"] = "the training frames miss some of the motion"
            return None
        motion = np.sqrt(total)
        rows = (3 * train[:, None] + np.arange(3)).ravel()                    # the training frames' rows
        rb = self._r_blocks
        first = self._r_linear @ qd                                           # R_v Q + R_t (base Q): the
        blocks, coefs = [], [cd]                                              # tips' linear part with it
        self.basis_stats.update(source=qd.shape[1], tips=[])
        missed = np.zeros(nf)                                                 # the tips' fit residual a frame
        for (el, _), r_t, rest in zip(self.terms_s, rb[1:], self._tips_rest):
            _, a, b = el.tip_operators
            lin = (a @ qd, b @ qd) + rest                                     # + the rest's a S, b S, g
            gt = _bend_rows(el, lin, cd[:, rows].T)                          # (3 F_train, E) exact
            qg = _gram_basis(gt, BASIS_TOL_TIPS, motion * np.sqrt(len(train) / nf))
            if qg is None:
                self.basis_stats["why"] = "the tips' motion does not lie in few shapes"
                return None
            if qg.shape[1] == 0:                                              # no bending: at rest
                cg = np.zeros((0, 3 * nf))
            elif len(train) == nf:
                cg = qg.T @ gt.T
            else:
                p = _deim_points(qg)
                gp = _bend_rows(el, lin, cd.T, at=p, chunk=-(-nf // 2))      # (3F, points)
                qp, rp = np.linalg.qr(qg[p])                                  # (kg, 3F), least squares (QR:
                cg = sla.solve_triangular(rp, qp.T @ gp.T)                    # 0.5 against pinv's 2 ms)
                res = gp - (qg[p] @ cg).T                                     # what the fit misses at the points
                missed += np.einsum("fcp,fcp->f", res.reshape(nf, 3, -1), res.reshape(nf, 3, -1))
            self.basis_stats["tips"].append(qg.shape[1])
            blocks.append(r_t @ qg)
            coefs.append(cg)
        blocks.insert(0, first)
        k, kd = sum(blk.shape[1] for blk in blocks), qd.shape[1]
        coef = np.vstack(coefs).reshape(k, nf, 3)                             # (k, F, 3)
        x0 = self._rest_solution
        if similarity is not None:                                            # back to the target's frame, on
            m = similarity.scale * similarity.rotation.T                      # the coefficients and the rest
            coef = coef @ m
            x0 = x0 @ m + similarity.translation
        if check:                                                             # the frames, off the training ones,
            others = np.setdiff1d(np.arange(nf), train)                       # whose tips the fit misses most at its
            others = others if len(others) else np.arange(nf)                 # points (else spread evenly)
            if missed[others].max() > 0:
                pick = np.sort(others[np.argsort(-missed[others], kind="stable")[:check]])
            else:
                pick = others[np.unique(np.linspace(0, len(others) - 1, check).round().astype(int))]
            rhs, ycols = self._rhs(frames[pick])
            blocks.append(rhs)
        # the right-hand sides in CHOLMOD's column-major order (it copies any other: 41 against 47 ms)
        P = np.empty((len(self.free), sum(blk.shape[1] for blk in blocks)), order="F")
        at = 0
        for blk in blocks:
            P[:, at:at + blk.shape[1]] = blk
            at += blk.shape[1]
        # the output's pages mapped on another thread while the solve runs on this one (the
        # solve holds the GIL; 81 MB of fresh memory cost 26-39 ms to map on this VM)
        out, mapped = prefaulted((nf, self.n_target, 3))
        Z = np.zeros((self.n_target, k), np.float32)                          # every vertex's basis solutions
        if P.shape[1]:                                                        # (none: the frames are at rest)
            sol = self.solver.solve(P)
            Z[self.free] = sol[:, :k]
            if check:
                self.basis_stats.update(checked=pick, exact=self._place(sol[:, k:], ycols, len(pick), similarity))
        if len(self.fixed):                                                   # held vertices follow their partners
            Z[self.fixed, :kd] = self._vm_fixed @ qd
        mapped()
        return _combine(Z, coef, x0, out=out)

    @cached_property
    def _tips_rest(self) -> list:
        """Per term: the source at rest's tip operator products (a S, b S), (E, 3) each, and the
        nonlinear part there, g(a S, b S) as an (x, y, z) triple -- what every frame's bending
        is measured from (apply_basis)."""
        S = self.source.vertices
        out = []
        for el, _ in self.terms_s:
            _, a, b = el.tip_operators
            a0, b0 = a @ S, b @ S
            out.append((a0, b0, el.tip_bend(tuple(a0.T), tuple(b0.T))))
        return out

    @cached_property
    def _r_linear(self) -> sp.csr_matrix:
        """R's map of the source's displacements with every term's tips' linear part (base x):
        R_v + sum_t R_t base_t (one sparse product a basis instead of 1 + 2 a term)."""
        rb = self._r_blocks
        out = rb[0]
        for (el, _), r_t in zip(self.terms_s, rb[1:]):
            out = out + r_t @ el.tip_operators[0]
        return out.tocsr()

    @cached_property
    def _r_blocks(self):
        """R's columns for the source vertices, then for each term's tips (CSR each)."""
        c = self.R.tocsc()
        ns = self.source.n_vertices
        out, at = [c[:, :ns].tocsr()], ns
        for el, _ in self.terms_s:
            out.append(c[:, at:at + el.n_elements].tocsr())
            at += el.n_elements
        return out

    @cached_property
    def _rest_solution(self) -> np.ndarray:
        """The target's result for the source at rest, (n_t, 3) (its own rest, up to the solve)."""
        return self.apply(self.source.vertices[None])[0]

    @staticmethod
    def _vertex_shares(mesh: Mesh, triangles=None, n_vertices=None) -> np.ndarray:
        """Each vertex's share of the surface (a third of its triangles' areas), mean 1 (none
        below 1e-6 of the mean)."""
        t = mesh.triangles if triangles is None else triangles
        a = np.bincount(t.reshape(-1), weights=np.repeat(mesh.triangle_areas() / 3, 3),
                        minlength=mesh.n_vertices if n_vertices is None else n_vertices)
        a = np.maximum(a, 1e-6 * a.mean())
        return a / a.mean()

    @staticmethod
    def _element_areas(el: Elements, mesh: Mesh) -> np.ndarray:
        """Area carried by each element (a third of the adjacent triangles for a vertex), mean 1."""
        if el.kind == "vtc":
            return TransferSolver._vertex_shares(mesh, el.triangles, el.n_vertices)
        a = mesh.triangle_areas()
        a = np.maximum(a, 1e-6 * a.mean())
        return a / a.mean()

    def _element_map(self, matched, kind, el_t) -> sp.csr_matrix:
        """(E_t x E_s) weights: which source elements a target element takes its Q from."""
        Vm = self.vertex_map
        rowsum = np.asarray(Vm.sum(axis=1)).ravel()
        ok = matched & (rowsum > 0.5)
        D = sp.diags(ok.astype(float))
        if kind == "vtc":
            P = (D @ Vm).tocsr()                                  # vertex elements on both sides
            if self.same_topology:
                return P
            # across topologies a target vertex's tent spans its one-ring: it takes the mean of
            # the source deformation at its own and its neighbours' partners, not at one point
            # (remeshed error 0.0920 -> 0.0896 in bench/transfer.py, mean of four held-out
            # remeshes 0.106 -> 0.103; two rings: 0.095)
            ring = (sp.identity(Vm.shape[0]) + self.target.adjacency) @ D
            return (sp.diags(ok / np.maximum(np.asarray(ring.sum(1)).ravel(), 1)) @ ring @ P).tocsr()
        tt = el_t.triangles
        corner_ok = ok[tt].all(axis=1).astype(float)
        if self.same_topology:
            return sp.diags(corner_ok).tocsr()                   # triangle e <- triangle e
        # DT: a target triangle takes the mean of the source triangles under its corners
        ts = self.source.triangles
        vt_s = sp.csr_matrix((np.ones(ts.size), (ts.reshape(-1), np.repeat(np.arange(len(ts)), 3))),
                             shape=(self.source.n_vertices, len(ts)))
        deg = np.asarray(vt_s.sum(axis=1)).ravel()
        v2t = sp.diags(1 / np.maximum(deg, 1)) @ vt_s           # source vertex -> its triangles
        t2v = sp.csr_matrix((np.repeat(corner_ok / 3, 3), (np.repeat(np.arange(len(tt)), 3), tt.reshape(-1))),
                            shape=(len(tt), self.target.n_vertices))
        return (t2v @ Vm @ v2t).tocsr()

    def apply(self, frames: np.ndarray, similarity=None, out=None) -> np.ndarray:
        """Source frames (F, n_s, 3) or (n_s, 3) -> target frames, same leading shape.

        similarity: optional transform applied to the results (the way back to the
        target's own frame), fused here to save a pass over the data.
        out: optional (F, n_t, 3) array to write the results into.
        """
        frames = np.asarray(frames, dtype=np.float64)
        single = frames.ndim == 2
        f = frames[None] if single else frames
        if f.shape[1:] != self.source.vertices.shape:
            raise MimicaError(f"source frames have {f.shape[1]} vertices, the source neutral has "
                              f"{self.source.n_vertices}")
        nf = f.shape[0]
        rhs, ycols = self._rhs(f)
        out = self._place(self.solver.solve(rhs), ycols, nf, similarity, out)
        return out[0] if single else out

    def _rhs(self, f: np.ndarray):
        """The right-hand sides (n_free, 3F) of frames f (F, n_s, 3), columns frame-major, and
        the source columns they were made from ([positions; tips of every term], (n_s + E, 3F))."""
        nf, ns = f.shape[0], f.shape[1]
        ycols = np.empty((self.A_s.shape[1], 3 * nf))                      # columns: frame-major
        fv = ycols[:ns].reshape(ns, nf, 3)
        fv[:] = np.moveaxis(f, 0, 1)                                       # vertex-first
        at = ns
        for el, _ in self.terms_s:
            ycols[at:at + el.n_elements] = el.tips(fv).reshape(-1, 3 * nf)
            at += el.n_elements
        rhs = self.R @ ycols
        rhs.reshape(-1, nf, 3)[:] += self.k0[:, None, :]
        return rhs, ycols

    def _place(self, sol, ycols, nf: int, similarity=None, out=None) -> np.ndarray:
        """Target frames (F, n_t, 3) from the free unknowns' solution (n_free, 3F) and the
        source columns (the held vertices follow their partners)."""
        ns = self.source.n_vertices
        x = np.empty((self.n_target, nf, 3))
        x[self.free] = sol.reshape(-1, nf, 3)
        if len(self.fixed):
            x[self.fixed] = (self._vm_fixed @ ycols[:ns]).reshape(-1, nf, 3) + self._fixed_base[:, None, :]
        if similarity is not None:
            flat = x.reshape(-1, 3)
            flat[:] = flat @ (similarity.scale * similarity.rotation.T)
            flat += similarity.translation
        if out is None:
            out = np.empty((nf, self.n_target, 3))
        out[:] = np.moveaxis(x, 1, 0)
        return out
