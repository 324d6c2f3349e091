"""The skin's and the muscles' systems (Kim 2020 §V-VI): the skin's stiffness and mass, each force
type's region of interest and its modes (eqs. 8, 19), a muscle's stretch mode (eqs. 11-13), and
the system that steps one muscle's modes with its springs implicit (modal warping, eqs. 10, 17-18).
precompute(rig) makes them; the rig carries them (a .rig file keeps them)."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..errors import MimicaError
from ..parallel import cores, one_blas_thread, run_jobs
from ..rig.drives import jaw_open_factors
from .drives import drive_load, drive_motions, strip_loads
from .modal import ModalBasis, ModalWarpingSolver, rotation_operator, rotations
from .shell import ShellEnergy, lumped_mass
from .springs import drive_springs, kim_spring, spring_stiffness, strip_springs, tether_springs


# the modal-warping rotation is smoothed by one implicit diffusion step of this time (in squared
# edges, graph Laplacian): a full smile against --solver full, max deviation 0.311 (0.321 at 4,
# 0.309 at 64; 32 rings of averaging: 0.315, and twice the precompute), docs/benchmarks.md
WARP_DIFFUSION = 16.0
# The face's skin: Kim eq. 4's stiffnesses relative to the mesh's scale (ShellEnergy.default).
# A softer membrane and a stiffer bend (0.25 / 0.2) spread the muscles' fields as ICT's shapes
# spread (the whole library's fit on the training faces: median cosine 0.900 -> 0.910), but the
# nonlinear shell (--solver full) then failed on a full smile (CHOLMOD: not positive definite;
# with a shifted diagonal it blew up to 4x the motion); bend 0.2 alone measured worse (0.888).
# The library's placements were found on that softer skin (tools/calibrate_muscles.py --skin)
# and kept: on this skin they fit better than those found on it before (docs/benchmarks.md).
SKIN_AREA, SKIN_BEND = 1.0, 0.05
# processes precompute makes the systems in at most: on this 2-core machine the library's 57
# systems take 13 s in one process, 8.4 s in two (docs/benchmarks.md)
PRECOMPUTE_WORKERS = 2


def _dlyap(M, Q):
    """X with X = M X M^T + Q, M stable, by Smith's doubling: X = sum_k M^k Q M^kT summed in
    doublings, X <- X + M_j X M_j^T, M_j+1 = M_j^2 (a few dozen n x n products).  An
    eigenvector solution is not safe here: the muscles' critically damped stretch mode makes
    the step matrix defective."""
    X = np.array(Q, float)
    M = np.array(M, float)
    for _ in range(64):
        X += M @ X @ M.T
        M = M @ M
        if np.abs(M).max() < 1e-18:
            return 0.5 * (X + X.T)
    raise MimicaError("simulation: a muscle system is not stable at this time step")


def _free_rows(basis, nodes) -> tuple:
    """Which of `nodes` the system moves ((k,) bool) and their rows in its free DOFs (3 a node)."""
    pos = np.full(basis.n, -1)
    pos[basis.free] = np.arange(len(basis.free))
    p = pos[np.asarray(nodes)]
    ok = p >= 0
    return ok, (3 * p[ok][:, None] + np.arange(3)).ravel()


class MuscleSystem:
    """One muscle's skin system: its ROI's modes, coupled to the muscle by springs.

    The springs are integrated implicitly with the skin: in modal coordinates the spring
    stiffness is the small dense matrix Phi_a^T K_s Phi_a (Phi_a: the mode rows at the
    spring nodes), so a step is one r x r matrix-vector product, stable at any spring
    stiffness.  The spring force is linear in the stretch of the layer, k (u_m - u_s), each
    spring as stiff as `spring` skin edges: Kim's eq. 15 (relative elongation) for motions
    large against the layer's thickness, along eq. 16's S_d - S_ud = u_m - u_s.  The pull
    k u_m is linear in the muscle's stretch amplitude, so its modal force is precomputed.
    """

    def __init__(self, rig, muscle, h, spring, xi, zeta, rho, warp=False, springs="linear"):
        b = muscle.basis
        self.solver = sv = ModalWarpingSolver(b, h, xi=xi, zeta=zeta, density=rho)
        self.h, self.w, self.warp = h, muscle.omega, warp
        self.q = self.v = 0.0
        self._memo = {}          # reduced pieces (output subspace, frame model), kept for a simulator taking over
        self.resting = True           # exactly at rest (never moved since made or set): skipped
        self.fq_parts = None
        at, wt, of = muscle.springs()                                 # a strip's springs fan out over the skin
        uniq, inv = np.unique(at, return_inverse=True)
        phi = sv.rows(uniq)                                           # (u, 3, r)
        # a strip node's spring, seen from the skin: its fan's mode rows by weight (k, 3, r); where
        # one force acts per spring (warping's R^T, eq. 15) it acts at this weighted point, in
        # its attachment node's frame (a fan is a few nodes: one frame each measured 3x slower)
        ends = None
        if muscle.kind != "drive" and (warp or springs == "kim"):
            fan = sp.csr_matrix((wt, (of, inv)), shape=(len(muscle.nodes), len(uniq)))
            ends = (muscle.attach, (fan @ phi.reshape(len(uniq), -1)).reshape(len(muscle.nodes), 3, -1))
        if muscle.kind == "drive":
            # a drive's springs are in its system's stiffness (precompute): its modes are those of
            # the skin held by its anchors, loaded by the anchors' motion K_s u_part
            self.stiff = np.diag(sv.lam)
            loads = [drive_load(rig, muscle, mo)[uniq] / rho for mo in drive_motions(muscle)]
            if len(loads) == 2:                      # the jaw: exact rotation of its anchors at any angle
                self.phi = float(np.radians(muscle.info["angle"]))
        elif springs == "kim":
            # eq. 15 (kim_spring): nonlinear in the skin's displacement, so the springs'
            # stiffness is not in the system's; it is linearized at every step (_step_kim).  Each
            # spring as stiff as the linear one for a stretch along it: k_15 = k |s_init|
            s_init = muscle.nodes - rig.skin.vertices[muscle.attach]
            l0 = np.maximum(np.linalg.norm(s_init, axis=1), 1e-9 * rig.params["mean_edge"])
            self.stiff = np.diag(sv.lam)
            self._kim = (s_init, spring_stiffness(rig, spring) * l0, ends[1], np.asarray(muscle.stretch, float))
            loads = [np.zeros((len(uniq), 3))]
        else:
            k_at, pull = strip_springs(rig, muscle, spring)            # per skin node
            pr = phi.reshape(-1, phi.shape[2])
            ks = pr.T @ (np.repeat(k_at[uniq], 3)[:, None] * pr) / rho     # Phi_a^T K_s Phi_a
            self.stiff = np.diag(sv.lam) + ks
            loads = [pull[uniq] / rho]                                   # K_s u_m per unit stretch
        self.rho = rho
        self.step_inv = np.linalg.inv(np.eye(len(b.lam)) + h * np.diag(sv.c) + h * h * self.stiff)
        parts = [np.einsum("kcr,kc->r", phi, f) for f in loads]
        self.fq_unit = sum(parts)                     # at full activation (the linear model: chord)
        if len(parts) == 2:
            self.fq_parts = parts
        if warp and self._kim is not None:            # each spring's node (a held node's rows are zero)
            self._kim_free, self._kim_rows = _free_rows(b, muscle.attach)
            self._psi_k = None
        elif warp:                                    # Kim eq. 10: the pulls in the nodes' frames, R^T F
            if ends is None:                          # a drive: at its anchors' nodes
                ok, self._rows = _free_rows(b, uniq)
                self._phi_a, self._loads = phi[ok], [f[ok] for f in loads]
            else:                                     # a strip: each spring's pull k u_m at its end
                ok, self._rows = _free_rows(b, ends[0])
                self._phi_a = ends[1][ok]
                self._loads = [spring_stiffness(rig, spring) * np.asarray(muscle.stretch, float)[ok] / rho]
            self._psi_a = None                        # the rotation field there, when first needed

    def state(self) -> np.ndarray:
        sv = self.solver
        return np.r_[self.q, self.v, sv.q, sv.v]

    def set_state(self, x):
        sv = self.solver
        r = len(sv.q)
        self.q, self.v = float(x[0]), float(x[1])
        sv.q, sv.v = np.array(x[2:2 + r]), np.array(x[2 + r:])
        self.resting = not np.any(x)

    _kim = None                      # eq. 15's springs: (s_init, k, Phi rows per spring, stretch)

    def transition(self):
        """The step is linear in (state, activation): x' = A x + B a; A and B, column by column
        (computed once)."""
        if self._kim is not None:
            raise MimicaError("Kim's eq. 15 springs are not linear in the skin's motion: no linear model "
                              "(fields, fit, reduced frames) with them; use the linear springs")
        if self.__dict__.get("_tr") is None:
            self._tr = self._transition()
        return self._tr

    def steady_state(self) -> np.ndarray:
        """The state the linear model settles to with its input held at 1: x* = A x* + B."""
        A, B = self.transition()
        return np.linalg.solve(np.eye(len(B)) - A, B)

    _linear = False                  # the jaw's exact rotation and R^T off: the linear model (transitions)

    def _pull(self) -> np.ndarray:
        """The modal force of the muscle's (or the drive's) pull on the skin at its stretch q:
        q times the pull at full activation; the jaw's turned exactly (rig.drives.jaw_open_parts);
        with warping, each spring's pull taken into its skin node's frame, R_i^T F_i (Kim eq. 10,
        R from the tangent rotation of the skin's present modal displacement).  The springs'
        own stiffness (-K_s u_s) stays in the nodes' frames, in the implicit step."""
        if self._linear or (not self.warp and self.fq_parts is None):
            return self.q * self.fq_unit
        factors = (self.q,) if self.fq_parts is None else jaw_open_factors(self.q, self.phi)
        if not self.warp:
            return factors[0] * self.fq_parts[0] + factors[1] * self.fq_parts[1]
        if self._psi_a is None:
            self._psi_a = self.solver.b.psi[self._rows]                   # (3u, r)
        R, _ = rotations((self._psi_a @ self.solver.q).reshape(-1, 3))
        f = sum(c * load for c, load in zip(factors, self._loads))
        return np.einsum("kcr,kc->r", self._phi_a, np.einsum("kji,kj->ki", R, f))

    def _transition(self):
        self._linear = True
        try:
            return self._transition_linear()
        finally:
            self._linear = False

    def _transition_linear(self):
        saved = self.state()
        n = len(saved)
        A = np.empty((n, n))
        for i in range(n):
            e = np.zeros(n)
            e[i] = 1.0
            self.set_state(e)
            self.step(0.0)
            A[:, i] = self.state()
        self.set_state(np.zeros(n))
        self.step(1.0)
        B = self.state()
        self.set_state(saved)
        return A, B

    def output_subspace(self, tol: float):
        """The few skin shapes this system's output can take (model reduction, §VI speed).

        The system is linear with one input, the activation: x' = A x + B a.  Its reachability
        Gramian W (discrete Lyapunov equation) says which states unit-energy activations
        reach; the output u = Phi q then lives, up to a relative RMS error tol, in the span
        of the leading left singular vectors of Phi L (W_qq = L L^T).  Returns (U (3n_free, k)
        in the output's rows, R (r, k)) with U^T Phi = R^T Phi^T Phi."""
        memo = self._memo
        if ("sub", tol) not in memo:
            memo[("sub", tol)] = self._output_subspace(tol)[1]           # R, small; U = Phi R
        R = memo[("sub", tol)]
        return self.solver.b.phi @ R, R

    def _output_subspace(self, tol: float):
        A, B = self.transition()
        W = _dlyap(A, np.outer(B, B))
        r = len(self.solver.q)
        Wq = 0.5 * (W[2:2 + r, 2:2 + r] + W[2:2 + r, 2:2 + r].T)
        w, V = np.linalg.eigh(Wq)
        L = V * np.sqrt(np.maximum(w, 0.0))
        phi = self.solver.b.phi
        G = phi.T @ phi
        s2, Y = np.linalg.eigh(L.T @ G @ L)             # (Phi L)^T (Phi L): its SVD without the tall matrix
        s2, Y = np.maximum(s2[::-1], 0.0), Y[:, ::-1]
        tail = np.r_[np.cumsum(s2[::-1])[::-1][1:], 0.0] / max(s2.sum(), 1e-300)
        k = int(np.argmax(tail <= tol * tol)) + 1
        R = L @ Y[:, :k] / np.sqrt(s2[:k])              # U = Phi R has orthonormal columns
        return phi @ R, R

    def frame_transition(self, substeps: int):
        """A displayed frame of `substeps` steps with the activation held:
        x <- A^s x + (A^{s-1} + ... + 1) B a; returns (A^s, (A^{s-1} + ... + 1) B)."""
        A, B = self.transition()
        Af, Bf = np.eye(len(B)), np.zeros(len(B))
        for _ in range(substeps):
            Bf = A @ Bf + B
            Af = A @ Af
        return Af, Bf

    def frame_model(self, substeps: int, proj: np.ndarray, tol: float):
        """Balanced truncation (Moore 1981) of one displayed frame of this system,
        x <- A^s x + (A^{s-1} + ... + 1) B a with output z = proj q (the reduced output's
        coordinates): the Gramians P (reachability) and Q (observability) from discrete
        Lyapunov equations, the square-root method, the states whose Hankel singular values
        carry the response kept (2 * the dropped sum <= tol * the largest, the H-infinity
        error bound).  Returns (Ar, Br, Cr, T, Ti): xr = T x, x ~ Ti xr, T Ti = I (kept for
        the next simulator that takes this system over: `proj` is then the same)."""
        memo = self._memo
        if ("frame", substeps, tol) not in memo:
            memo[("frame", substeps, tol)] = self._frame_model(substeps, proj, tol)
        return memo[("frame", substeps, tol)]

    def reduced_output(self, tol: float):
        """output_subspace(tol)'s shapes padded to every node (float32; made again each call,
        not kept: a whole head's are hundreds of MB), and the block R^T Phi^T Phi that takes
        modal coordinates to them (kept)."""
        U, R = self.output_subspace(tol)
        b = self.solver.b
        memo = self._memo
        if ("proj", tol) not in memo:
            memo[("proj", tol)] = R.T @ (b.phi.T @ b.phi)
        return b.padded32(U), memo[("proj", tol)]

    def _frame_model(self, substeps: int, proj: np.ndarray, tol: float):
        Af, Bf = self.frame_transition(substeps)
        r = len(self.solver.q)
        C = np.zeros((proj.shape[0], len(Bf)))
        C[:, 2:2 + r] = proj

        def root(G):                                   # G = L L^T, G symmetric semi-definite
            w, V = np.linalg.eigh(0.5 * (G + G.T))
            return V * np.sqrt(np.maximum(w, 0.0))
        Lp = root(_dlyap(Af, np.outer(Bf, Bf)))
        Lq = root(_dlyap(Af.T, C.T @ C))
        U, hsv, Vt = np.linalg.svd(Lq.T @ Lp)
        tail = np.r_[np.cumsum(hsv[::-1])[::-1][1:], 0.0]
        k = int(np.argmax(2.0 * tail <= tol * hsv[0])) + 1
        si = 1.0 / np.sqrt(hsv[:k])
        T = si[:, None] * (U[:, :k].T @ Lq.T)
        Ti = (Lp @ Vt[:k].T) * si[None, :]
        return T @ Af @ Ti, T @ Bf, C @ Ti, T, Ti

    def step(self, a):
        if self.resting and a == 0.0:             # at rest and not driven: stays exactly at rest
            return
        self.resting = False
        h, w = self.h, self.w
        self.q, self.v = follow_activation(self.q, self.v, a, h, w)
        sv = self.solver
        if self._kim is not None:
            self._step_kim()
            return
        sv.v = self.step_inv @ (sv.v + h * (self._pull() - self.stiff @ sv.q))
        sv.q = sv.q + h * sv.v

    def _step_kim(self):
        """One step of the skin under eq. 15's springs (kim_spring), linearized at the present state
        (one Newton step of implicit Euler): (I + hC + h^2 (Lambda - Phi^T J Phi)) v' = v +
        h (Phi^T F - Lambda q), J = dF/du_s per spring; with warping each pull enters its node's
        frame by R^T (the linearization stays in the rest frame)."""
        sv, h = self.solver, self.h
        s_init, k, phi, stretch = self._kim
        u_s = np.einsum("kcr,r->kc", phi, sv.q)
        f, jac, _ = kim_spring(s_init, self.q * stretch, u_s, k)
        if self.warp:
            if self._psi_k is None:
                self._psi_k = self.solver.b.psi[self._kim_rows]
            R, _ = rotations((self._psi_k @ sv.q).reshape(-1, 3))
            f = f.copy()
            f[self._kim_free] = np.einsum("kji,kj->ki", R, f[self._kim_free])
        fq = np.einsum("kcr,kc->r", phi, f) / self.rho
        pr = phi.reshape(-1, phi.shape[2])                                   # (3k, r)
        jq = pr.T @ np.einsum("kab,kbs->kas", jac, phi).reshape(pr.shape) / self.rho
        a = np.eye(len(sv.q)) + h * np.diag(sv.c) + h * h * (np.diag(sv.lam) - jq)
        sv.v = np.linalg.solve(a, sv.v + h * (fq - sv.lam * sv.q))
        sv.q = sv.q + h * sv.v


def skin_system(rig, rotation: bool = True):
    """The skin's shell and the matrices every force system shares.

    Parameters
    ----------
    rig : Rig
    rotation : bool
        Make the rotation operator too (modal warping).

    Returns
    -------
    energy : ShellEnergy
    mass : (n,) float array
        Lumped masses.
    K : (3n, 3n) sparse matrix
        The shell's stiffness with the tethers.
    W : sparse matrix or None
        The rotation operator (rotation_operator), None without `rotation`.
    """
    skin, p = rig.skin, rig.params
    energy = ShellEnergy.default(skin, k_area=SKIN_AREA, k_bend=SKIN_BEND)
    mass = lumped_mass(skin)
    k_node = tether_springs(p.get("tether", 0.0), energy.k_length, p["mean_edge"], mass)   # K + the tethers
    K = (energy.rest_stiffness() + sp.diags(np.repeat(k_node, 3))).tocsr()
    W = (rotation_operator(skin.vertices, skin.triangles, smooth=WARP_DIFFUSION, tangent=True, diffuse=True)
         if rotation else None)
    return energy, mass, K, W


def precompute(rig, progress=None, only=None, skin=None, workers: int | None = None):
    """One modal system per force type on the rig (Kim §VI): each muscle's over its ROI (eq. 19),
    loaded at its spring nodes, and gravity's over the skin the skull does not hold; systems the
    rig already carries are kept (those loaded from a file are read back).

    Parameters
    ----------
    rig : Rig
        Changed in place: each muscle's `basis` and the rig's `gravity_basis` made.
    progress : callable, optional
        Called as progress(k, n, name) as each system is made: k of the n made, name the
        muscle's or "gravity".
    only : collection of str, optional
        Make only these systems now (muscle names, "gravity"): a viewer makes each as it is
        first moved.
    skin : tuple, optional
        skin_system(rig), when the caller made it once for several calls (seconds on a whole
        head); None: made here.
    workers : int or None
        Processes that make the systems (mimica.parallel), each with one BLAS thread; None: one
        a core, at most PRECOMPUTE_WORKERS; 1: in this process alone.  The systems come out
        the same either way (one BLAS thread in this process too).

    Returns
    -------
    Rig
        The rig.
    """
    if "mean_edge" not in rig.params:
        raise MimicaError("rig: built by an older mimica; rebuild it with `mimica rig`")
    p = rig.params
    gravity = p.get("gravity", True) or rig.gravity_basis is not None
    todo = [k for k, m in enumerate(rig.muscles)
            if not isinstance(m.basis, ModalBasis) and (only is None or m.name in only)]
    grav = gravity and not isinstance(rig.gravity_basis, ModalBasis) and (only is None or "gravity" in only)
    if not todo and not grav and "k_length" in p:
        return rig
    energy, mass, K, W = skin if skin is not None else skin_system(rig)
    p.update(k_area=energy.k_area, k_length=energy.k_length, k_bend=energy.k_bend)
    for k in todo:
        if isinstance(rig.muscles[k].basis, dict):
            rig.muscles[k].basis = ModalBasis.from_arrays(rig.muscles[k].basis, W)
    if isinstance(rig.gravity_basis, dict):
        rig.gravity_basis = ModalBasis.from_arrays(rig.gravity_basis, W)
    jobs = [k for k in todo if rig.muscles[k].basis is None]
    if grav and rig.gravity_basis is None:
        jobs.append(-1)
    if not jobs:
        return rig
    # the costliest first (a factorization grows faster than its region): the workers finish together
    jobs.sort(key=lambda k: -(rig.muscles[k].roi.sum() if k >= 0 else len(mass)))
    shared = (_light(rig), energy, mass, K, int(p.get("modes", 8)))
    workers = min(PRECOMPUTE_WORKERS, cores()) if workers is None else max(1, int(workers))
    with one_blas_thread():
        if workers > 1 and len(jobs) >= 2 * workers:
            made = run_jobs(_system_job, shared, jobs, workers)
        else:
            made = ((i, _system_job(shared, k)) for i, k in enumerate(jobs))
        for n_made, (i, arrays) in enumerate(made, 1):
            k = jobs[i]
            basis = ModalBasis(*arrays[:3], None, mass, energy.n, W)
            if k < 0:
                rig.gravity_basis = basis
            else:
                rig.muscles[k].basis = basis
            if progress:
                progress(n_made, len(jobs), rig.muscles[k].name if k >= 0 else "gravity")
    return rig


def _light(rig):
    """The rig without its systems (what a worker needs to make them)."""
    import copy
    light = copy.copy(rig)
    light.muscles = [copy.copy(m) for m in rig.muscles]
    for m in light.muscles:
        m.basis = None
    light.gravity_basis = None
    return light


def _system_job(shared, k: int) -> tuple:
    """One system's (free, phi, lam): muscle k's over its ROI, or gravity's (k = -1)."""
    rig, energy, mass, K, modes = shared
    if k < 0:
        b = ModalBasis.compute(energy, mass, rig.held(), r=modes, stiffness=K, rotation=False)
        return b.free, b.phi, b.lam
    m = rig.muscles[k]
    if m.kind == "drive":
        # the drive's springs join the stiffness; its loads: the anchors' motion
        Kd = (K + sp.diags(np.repeat(drive_springs(rig, m), 3))).tocsr()
        loads = [drive_load(rig, m, motion) for motion in drive_motions(m)]
        b = ModalBasis.compute(energy, mass, ~m.roi, r=modes, stiffness=Kd, rotation=False,
                               load_shapes=np.stack([f.ravel() for f in loads], 1))
    else:
        # its springs' loads, the Ritz vectors solved with the springs in (its static field exact)
        b = ModalBasis.compute(energy, mass, ~m.roi, r=modes, load_shapes=strip_loads(rig, m),
                               stiffness=K, rotation=False, span_springs=np.repeat(strip_springs(rig, m)[0], 3))
    return b.free, b.phi, b.lam


def shell_stretch_mode(nodes: np.ndarray, bar: np.ndarray, modes: int = 8) -> tuple:
    """Kim eqs. 11-12: a muscle's stretch mode from its own shell eigenproblem.  The strip (its
    ROWS x COLS nodes, rig.strip_triangles) as a shell (Kim eq. 4, ShellEnergy.default), its
    origin row held by the skull; K e = lambda M e (eq. 8, lumped masses) for the lowest `modes`;
    the stretch mode is the one most aligned (mass inner product) with the bar's stretch `bar`
    (k, 3) -- Kim takes the 3rd of 4 on his strips -- signed and scaled to its least-squares fit
    of the bar, so that activation 1 still shortens the muscle by its contraction.  Returns
    (mode (k, 3), alignment in [0, 1], its index among the modes)."""
    from scipy.linalg import eigh
    from ..mesh import Mesh
    from ..rig import COLS, strip_triangles
    nodes = np.asarray(nodes, float)
    tris = strip_triangles()
    p = nodes[tris]
    area = np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    # a strip draped over a crease can fold cells flat (nodes on one skin point): those cells
    # are left out, and nodes in none of the rest keep the bar's motion
    tris = tris[area > 1e-6 * area.max()]
    strip = Mesh.from_faces(nodes, tris)
    energy = ShellEnergy.default(strip)
    mass = np.repeat(lumped_mass(strip), 3)
    used = np.zeros(len(nodes), bool)
    used[tris.ravel()] = True
    used[:COLS] = False                                                   # the origin row is held
    free = (3 * np.nonzero(used)[0][:, None] + np.arange(3)).ravel()
    K = energy.rest_stiffness().toarray()[np.ix_(free, free)]
    lam, e = eigh(K, np.diag(mass[free]), subset_by_index=[0, min(modes, len(free)) - 1])
    b = np.asarray(bar, float).ravel()[free]
    m = mass[free]
    dots = (e * (m * b)[:, None]).sum(0)
    norms = np.sqrt((e * e * m[:, None]).sum(0) * (b * b * m).sum())
    align = np.abs(dots) / np.maximum(norms, 1e-300)
    i = int(np.argmax(align))
    scale = dots[i] / max(float((e[:, i] ** 2 * m).sum()), 1e-300)
    mode = np.asarray(bar, float).copy()
    mode[:COLS] = 0.0
    mode.reshape(-1)[free] = scale * e[:, i]
    return mode, float(align[i]), i


def shell_stretch_modes(rig) -> list:
    """Every strip muscle's stretch (Muscle.stretch, the bar's) replaced by its shell stretch mode
    (shell_stretch_mode; `mimica rig --stretch shell`), before its modal system is made; the rig
    records it (params "stretch").

    Parameters
    ----------
    rig : Rig
        Its muscles' systems not made yet (MimicaError otherwise).

    Returns
    -------
    list of tuple
        (name, alignment in [0, 1], mode index) for each strip muscle.
    """
    if any(m.basis is not None for m in rig.muscles if m.kind != "drive"):
        raise MimicaError("rig: its muscles' systems are already made; choose the stretch modes when building it")
    out = []
    for m in rig.muscles:
        if m.kind == "drive":
            continue
        m.stretch, a, i = shell_stretch_mode(m.nodes, m.stretch)
        out.append((m.name, a, i))
    rig.params["stretch"] = "shell"
    return out


def region_system(rig, center: np.ndarray, radius: float, reach: float = 3.0):
    """A modal system for a force on the skin within `radius` of `center` (a user pull).

    Parameters
    ----------
    rig : Rig
    center : (3,) float array
    radius : float
        The pull's reach on the skin (MimicaError where no skin is within it).
    reach : float
        Its ROI: the skin within reach x radius.

    Returns
    -------
    basis : ModalBasis
    nodes : (k,) int array
        The skin nodes it loads.
    weights : (k,) float array
        Their share of the force, summing to 1.
    """
    skin = rig.skin
    d = np.linalg.norm(skin.vertices - center, axis=1)
    nodes = np.nonzero(d < radius)[0]
    if len(nodes) == 0:
        raise MimicaError(f"pull: no skin within {radius:g} of {np.round(center, 3).tolist()}")
    w = (1 - d[nodes] / radius) ** 2
    energy, mass, K, W = skin_system(rig)
    basis = ModalBasis.compute(energy, mass, d > reach * radius, r=rig.params.get("modes", 8),
                               load_nodes=nodes[:: max(1, len(nodes) // 24)], stiffness=K, rotation=W)
    return basis, nodes, w / w.sum()


def follow_activation(q, v, a, h, w):
    """A muscle's stretch mode following its activation, critically damped (Kim eq. 13), one
    implicit Euler step.

    Parameters
    ----------
    q, v : float or float array
        The mode's coordinate and its velocity.
    a : float or float array
        The activation.
    h : float
        The step, seconds.
    w : float
        The angular frequency.

    Returns
    -------
    q, v : float or float array
        After the step.
    """
    v = (v + h * w * w * (a - q)) / (1 + 2 * h * w + h * h * w * w)
    return q + h * v, v


def skin_density(rig, frequency: float) -> float:
    """The areal density that puts the softest system's lowest mode at `frequency` Hz.

    The shell's stiffness is scale-free (ShellEnergy.default), so the time scale is set here: the
    skin settles in a fraction of a second, as faces do.

    Parameters
    ----------
    rig : Rig
        Precomputed.
    frequency : float
        Hz.

    Returns
    -------
    float
    """
    lam = [m.basis.lam.min() for m in rig.muscles if m.basis is not None]
    if rig.gravity_basis is not None:
        lam.append(rig.gravity_basis.lam.min())
    return max(min(lam), 1e-12) / (2 * np.pi * frequency) ** 2
