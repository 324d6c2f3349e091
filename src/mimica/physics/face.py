"""Muscle-driven skin (Kim 2020 §V-VI): muscles stretch, springs pull the skin, and each
force type moves the skin in its own modal system; the displacement fields are summed.

Per step and per muscle i (all vectorized over the muscle's spring nodes):
  muscle:  q_m'' + 2 w q_m' + w^2 q_m = w^2 a_i(t)     (the stretch mode, Kim eqs. 11-13)
  springs: F = k (u_m - u_s), implicit in the skin's modes: Kim's eq. 15 (relative elongation)
           in the limit of motions large against the layer's thickness, along u_m - u_s (eq. 16's
           S_d - S_ud with the skin's end moving too).  springs="kim": eq. 15's relative elongation
           along the spring's deformation (kim_spring; eq. 16 as printed diverges), linearized
           at every step; measured against the linear law in docs/benchmarks.md, the
           linear one stays the default.
  skin:    the muscle's ROI system driven by R^T F, its displacement warped by the integrated
           rotation (modal warping, eqs. 10, 17-19; warp=False: linear)
  drives:  the jaw, the lids and the cheeks' pressure (rig.drives): anchors moving with their
           part pull the skin through springs that are part of the system's stiffness
  total:   u_s = sum_f u_f                                               (eqs. 20-21)
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..errors import MimicaError
from ..rig.drives import JAW_CLOSERS, LID_MARGIN, jaw_open_factors, jaw_open_parts, lid_pairs, margin_opening
from .engine import run_frames
from .modal import ModalBasis, ModalWarpingSolver, rotation_operator, rotations
from .shell import ShellEnergy, lumped_mass

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


SPRING_LAWS = ("linear", "kim")


def kim_spring(s_init: np.ndarray, u_m: np.ndarray, u_s: np.ndarray, k) -> tuple:
    """The subcutaneous springs of Kim 2020 §V.B, eqs. 14-16, on the skin's end, vectorized over
    springs.

      S_d = s_init + u_m - u_s                                  (the deformed spring)
      |F| = k | |S_d| - |s_init| | / |s_init|                   (eqs. 14-15: relative elongation)
      F / |F| = (S_d - s_init) / |S_d - s_init|                 (eq. 16, S_ud read as the spring at rest)

    Eq. 16 as printed takes S_ud with the skin's end moved and the muscle's not, so S_d - S_ud =
    u_m: the force keeps pushing along the muscle's motion once the skin has passed it, and the
    magnitude grows again there (the springs stand nearly across the muscles' motion: |cos|
    0.07-0.22 on ICT's face), so nothing restores it -- measured, every calibrated muscle's skin
    diverged within a second at 60 fps.  Along the spring's own deformation u_m - u_s it restores.

    Parameters
    ----------
    s_init : (m, 3) float array
        The initial spring vectors (skin node -> muscle node).
    u_m, u_s : (m, 3) float arrays
        The muscle nodes' and the skin nodes' displacements.
    k : float or (m,) float array
        The springs' stiffness.

    Returns
    -------
    F : (m, 3) float array
        The force on the skin's end; 0 where the spring is undeformed.
    dF_du_s, dF_du_m : (m, 3, 3) float arrays
        Its derivatives (F depends on u_m - u_s only, so dF/du_m = -dF/du_s); the magnitude's kink
        at |S_d| = |s_init| takes the derivative of the side the spring is on.
    """
    s_init, u_m, u_s = (np.asarray(x, float) for x in (s_init, u_m, u_s))
    k = np.broadcast_to(np.asarray(k, float), len(s_init))
    l0 = np.linalg.norm(s_init, axis=1)
    w = u_m - u_s
    sd = s_init + w
    ld = np.linalg.norm(sd, axis=1)
    e = (ld - l0) / l0                                            # eq. 15's relative elongation
    lw = np.linalg.norm(w, axis=1)
    moved = lw > 1e-12 * np.maximum(l0, 1e-300)
    d = np.where(moved[:, None], w / np.where(moved, lw, 1.0)[:, None], 0.0)        # eq. 16
    sd_hat = sd / np.maximum(ld, 1e-300)[:, None]
    f = (k * np.abs(e))[:, None] * d
    g = (k * np.sign(e) / l0)[:, None, None] * d[:, :, None] * sd_hat[:, None, :]   # d |F| along d
    g += np.where(moved, k * np.abs(e) / np.where(moved, lw, 1.0), 0.0)[:, None, None] * \
        (np.eye(3)[None] - d[:, :, None] * d[:, None, :])                            # d direction
    return f, -g, g


def _free_rows(basis, nodes) -> tuple:
    """Which of `nodes` the system moves ((k,) bool) and their rows in its free DOFs (3 a node)."""
    pos = np.full(basis.n, -1)
    pos[basis.free] = np.arange(len(basis.free))
    p = pos[np.asarray(nodes)]
    ok = p >= 0
    return ok, (3 * p[ok][:, None] + np.arange(3)).ravel()


class _MuscleSystem:
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


DRIVE_SPRING = 4.0               # a drive's attachments, as stiff as this many `spring`s (at weight 1)


def drive_springs(rig, muscle) -> np.ndarray:
    """A drive's attachment stiffness per skin node: DRIVE_SPRING default springs x its weight
    (part of its system's stiffness, so fixed at precompute).

    Parameters
    ----------
    rig : Rig
    muscle : Muscle
        A drive (kind "drive").

    Returns
    -------
    (n,) float array
        n: the skin's vertices.
    """
    k = np.zeros(rig.skin.n_vertices)
    w = muscle.weight if muscle.weight is not None else np.ones(len(muscle.attach))
    np.add.at(k, muscle.attach, DRIVE_SPRING * spring_stiffness(rig, 4.0) * w)
    return k


def strip_springs(rig, muscle, spring: float = 4.0) -> tuple:
    """A strip muscle's springs on the skin, each strip node's spring fanned out (rig.spring_fan).

    Parameters
    ----------
    rig : Rig
    muscle : Muscle
        A strip muscle.
    spring : float
        Each spring's stiffness in edges' stiffness (spring_stiffness).

    Returns
    -------
    stiffness : (n,) float array
        Per skin node.
    pull : (n, 3) float array
        Their pull at full activation, K_s u_m.
    """
    at, wt, of = muscle.springs()
    k = spring_stiffness(rig, spring) * wt
    f = np.zeros((rig.skin.n_vertices, 3))
    np.add.at(f, at, k[:, None] * muscle.stretch[of])
    return np.bincount(at, k, minlength=rig.skin.n_vertices), f


def strip_loads(rig, muscle) -> np.ndarray:
    """A strip's load patterns: each spring pulling its fan along x, y and z, once for the nodes
    that share a skin node (their fans are the same).

    Parameters
    ----------
    rig : Rig
    muscle : Muscle
        A strip muscle.

    Returns
    -------
    (3n, 3u) float array
        n: the skin's vertices; u: the strip's distinct skin nodes.
    """
    at, wt, of = muscle.springs()
    _, first = np.unique(muscle.attach, return_index=True)
    col = np.full(len(muscle.nodes), -1)
    col[first] = np.arange(len(first))
    keep = col[of] >= 0
    loads = np.zeros((3 * rig.skin.n_vertices, 3 * len(first)))
    for c in range(3):
        np.add.at(loads, (3 * at[keep] + c, 3 * col[of[keep]] + c), wt[keep])
    return loads


def drive_load(rig, muscle, motion=None) -> np.ndarray:
    """The force of a drive's anchors moved by `motion`, K_s u_part.

    Parameters
    ----------
    rig : Rig
    muscle : Muscle
        A drive.
    motion : (k, 3) float array or None
        Its anchors' motion (None: their motion at full activation, muscle.stretch).

    Returns
    -------
    (n, 3) float array
    """
    f = np.zeros((rig.skin.n_vertices, 3))
    k = drive_springs(rig, muscle)
    f[muscle.attach] = k[muscle.attach, None] * (muscle.stretch if motion is None else motion)
    return f


def drive_motions(m) -> list:
    """A drive's anchor motions whose loads its system must hold.

    Parameters
    ----------
    m : Muscle
        A drive.

    Returns
    -------
    list of (k, 3) float arrays
        The jaw's opening as its two parts (exact rotation at any angle, rig.drives.jaw_open_parts);
        any other drive's one motion.
    """
    if m.info.get("part") == "jaw" and m.info.get("motion") == "open" and "pivot" in m.info:
        ms, mc, _ = jaw_open_parts(m.nodes, m.info)
        return [ms, mc]
    return [m.stretch]


CONTACT_SLACK = 1.15            # measured: the lower lid's skin rises 2 % of the opening past its anchors


def _shares(xp, ucp, info, steps: int = 24) -> np.ndarray:
    """Per pair of margin nodes xp (k, 2, 3), the smallest share of the closing field there ucp
    (k, 2, 3) whose removal leaves it open (margin_opening >= 0); 1 where even all of it does
    not.  Bisection, all pairs at once."""
    lo, hi = np.zeros(len(xp)), np.ones(len(xp))
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        ok = margin_opening(xp - mid[:, None, None] * ucp, info) >= 0
        lo, hi = np.where(ok, lo, mid), np.where(ok, mid, hi)
    return hi


def lid_contact(u, uc, rest, info, passes: int = 4):
    """Lid contact, position by position.

    Where the margins would cross, the closing field is taken away there, along the eye, until
    they meet: at each pair of facing margin nodes the share of uc that brings the opening to 0
    (bisection, all pairs at once), interpolated across the eye between the pairs (by the position
    of their upper nodes) for every node the closing drive moves.  The rims then meet wherever the
    closing lid reaches the lower one and are held apart nowhere else -- a share of the whole
    field, the same at every pair, held the ends of a fitted blink 9 % of the opening apart where
    its middle met (docs/benchmarks.md).  Passes repeat it for the lower nodes' own shares; what
    still crosses after them has the rest of the field taken away evenly.

    Parameters
    ----------
    u : (n, 3) float array
        The skin's displacement; changed in place.
    uc : (n, 3) float array
        The closing drive's part of it.
    rest : (n, 3) float array
        The skin at rest.
    info : dict
        The closing drive's (Muscle.info): the eye's centre, up and fwd, and its margins' facing
        pairs (lid_pairs).
    passes : int

    Returns
    -------
    (n, 3) float array
        u.
    """
    p = lid_pairs(info)
    if len(p) == 0:
        return u
    c, up, fwd = (np.asarray(info[k], float) for k in ("centre", "up", "fwd"))
    across = np.cross(fwd, up)
    moving = np.nonzero(np.abs(uc).max(axis=1) > 0)[0]
    if len(moving) == 0:
        return u
    uc = uc[moving]
    t = (rest[moving] - c) @ across
    tp = (rest[p[:, 0]] - c) @ across
    order = np.argsort(tp)
    where = np.minimum(np.searchsorted(moving, p), len(moving) - 1)   # the pairs' nodes among the moving
    inside = moving[where] == p

    def at_pairs(field):                               # (k, 2, 3), zero where it moves no pair node
        return np.where(inside[..., None], field[where], 0.0)
    for _ in range(passes):
        xp = rest[p] + u[p]
        o = margin_opening(xp, info)
        if o.min() >= 0:
            return u
        h = np.where(o < 0, _shares(xp, at_pairs(uc), info), 0.0)
        hn = np.interp(t, tp[order], h[order])
        u[moving] -= hn[:, None] * uc
        uc = uc * (1.0 - hn)[:, None]                   # what is left of the closing field
    xp = rest[p] + u[p]
    o = margin_opening(xp, info)
    if o.min() < 0:                                     # the lower nodes' shares left a crossing:
        u[moving] -= _shares(xp, at_pairs(uc), info)[o < 0].max() * uc      # the same share everywhere
    return u


class ActivationMap:
    """The muscles' activations -> each force system's input.

    A muscle's input is its activation, except for the drives (rig.drives): the jaw opens by the
    digastric's activation less its strongest closer's (masseter, temporalis: the teeth stop it at
    rest, so never below 0).  With `lid_room` (the full-space solver, which has no contact), a lid
    closes at most until its rim meets the other (the closing drive moves the rim by its input x
    the opening, the lower lid's raise by its `raise` part of it, the levator lifts it by its
    `wide` angle; the input is held where they meet); the modal face instead stops the lids where
    they touch, position by position (lid_contact).  Drive inputs stay in 0..1.

    Parameters
    ----------
    muscles : list of Muscle
        The rig's.
    lid_room : bool
        Hold each lid's input where its rim meets the other's.
    """

    def __init__(self, muscles, lid_room: bool = True):
        names = [m.name for m in muscles]
        self.drives = [i for i, m in enumerate(muscles) if m.kind == "drive"]
        self.closers = [i for i, n in enumerate(names) if n.rsplit("_", 1)[0] in JAW_CLOSERS]
        self.jaw_open = [i for i, m in enumerate(muscles) if m.kind == "drive"
                         and m.info.get("part") == "jaw" and m.info.get("motion") == "open"]
        self.lid_close = [i for i in self.drives if muscles[i].info.get("part") == "lid"
                          and muscles[i].info.get("motion") == "close"]
        self.lids = []                               # (close, raise, wide, wide/opening, raise part)
        for i in self.lid_close:
            m = muscles[i]
            same = {muscles[j].info.get("motion"): j for j in self.drives if muscles[j].info.get("eye") == m.info["eye"]}
            w, r = same.get("wide"), same.get("raise")
            ratio = muscles[w].info["wide"] / max(float(m.info.get("gap_max", 1.0)), 1e-9) if w is not None else 0.0
            self.lids.append((i, r, w, ratio, muscles[r].info["raise"] if r is not None else 0.0))
        self.lid_room = lid_room

    def __call__(self, activations) -> np.ndarray:
        if not self.drives:
            return activations
        a = np.array(activations, float)
        if self.closers:
            for j in self.jaw_open:
                a[j] -= max(a[self.closers].max(), 0.0)
        a[self.drives] = np.clip(a[self.drives], 0.0, 1.0)
        for c, r, w, ratio, lift in (self.lids if self.lid_room else []):
            # (the raised lower lid's skin reaches a little past its anchors: CONTACT_SLACK)
            room = 1.0 - (a[r] * lift * CONTACT_SLACK if r is not None else 0.0) + \
                (a[w] * ratio if w is not None else 0.0)
            a[c] = min(a[c], max(room, 0.0) / (1.0 - LID_MARGIN))
        return a


def tether_springs(tether: float, k_length: float, mean_edge: float, mass: np.ndarray) -> np.ndarray:
    """Per-node stiffness of the subcutaneous tethers to the skull: tether x an edge's stiffness
    2 k_L / l, shared out by the nodes' lumped areas.

    Parameters
    ----------
    tether : float
        The tethers' strength in edges' stiffness.
    k_length : float
        The shell's length stiffness k_L.
    mean_edge : float
        The skin's mean edge length l.
    mass : (n,) float array
        The nodes' lumped masses (areas).

    Returns
    -------
    (n,) float array
    """
    return tether * 2 * k_length / mean_edge * mass / mass.mean()


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
    K = (energy.hessian(energy.rest) + sp.diags(np.repeat(k_node, 3))).tocsr()
    W = (rotation_operator(skin.vertices, skin.triangles, smooth=WARP_DIFFUSION, tangent=True, diffuse=True)
         if rotation else None)
    return energy, mass, K, W


def precompute(rig, progress=None, only=None, skin=None):
    """One modal system per force type on the rig (Kim §VI): each muscle's over its ROI (eq. 19),
    loaded at its spring nodes, and gravity's over the skin the skull does not hold; systems the
    rig already carries are kept (those loaded from a file are read back).

    Parameters
    ----------
    rig : Rig
        Changed in place: each muscle's `basis` and the rig's `gravity_basis` made.
    progress : callable, optional
        Called as progress(k, n, name) before each muscle's system.
    only : collection of str, optional
        Make only these systems now (muscle names, "gravity"): a viewer makes each as it is
        first moved.
    skin : tuple, optional
        skin_system(rig), when the caller made it once for several calls (seconds on a whole
        head); None: made here.

    Returns
    -------
    Rig
        The rig.
    """
    if "mean_edge" not in rig.params:
        raise MimicaError("rig: built by an older mimica; rebuild it with `mimica rig`")
    p = rig.params
    gravity = p.get("gravity", True) or rig.gravity_basis is not None
    left = [m for m in rig.muscles if not isinstance(m.basis, ModalBasis)]
    todo = left if only is None else [m for m in left if m.name in only]
    grav = gravity and not isinstance(rig.gravity_basis, ModalBasis) and (only is None or "gravity" in only)
    if not todo and not grav and "k_length" in p:
        return rig
    energy, mass, K, W = skin if skin is not None else skin_system(rig)
    p.update(k_area=energy.k_area, k_length=energy.k_length, k_bend=energy.k_bend)
    modes = int(p.get("modes", 8))
    def system(m):
        if isinstance(m.basis, dict):
            return ModalBasis.from_arrays(m.basis, W)
        if m.kind == "drive":
            # the drive's springs join the stiffness; its loads: the anchors' motion
            Kd = (K + sp.diags(np.repeat(drive_springs(rig, m), 3))).tocsr()
            loads = [drive_load(rig, m, motion) for motion in drive_motions(m)]
            return ModalBasis.compute(energy, mass, ~m.roi, r=modes, stiffness=Kd, rotation=W,
                                      load_shapes=np.stack([f.ravel() for f in loads], 1))
        # its springs' loads, the Ritz vectors solved with the springs in (its static field exact)
        Ks = (K + sp.diags(np.repeat(strip_springs(rig, m)[0], 3))).tocsr()
        return ModalBasis.compute(energy, mass, ~m.roi, r=modes, load_shapes=strip_loads(rig, m),
                                  stiffness=K, rotation=W, span=Ks)
    for k, m in enumerate(todo):                   # (two threads measured slower: BLAS has both cores)
        if progress:
            progress(k, len(todo), m.name)
        m.basis = system(m)
    if isinstance(rig.gravity_basis, dict):
        rig.gravity_basis = ModalBasis.from_arrays(rig.gravity_basis, W)
    elif grav and rig.gravity_basis is None:
        rig.gravity_basis = ModalBasis.compute(energy, mass, rig.held(), r=modes, stiffness=K, rotation=W)
    return rig


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
    K = energy.hessian(energy.rest).toarray()[np.ix_(free, free)]
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


def spring_stiffness(rig, spring: float) -> float:
    """The muscle-to-skin spring's stiffness (Kim eqs. 14-16).

    Parameters
    ----------
    rig : Rig
    spring : float
        In edges' stiffness, 2 k_L / l each.

    Returns
    -------
    float
    """
    return spring * 2.0 * rig.params["k_length"] / rig.params["mean_edge"]


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


class FaceSimulator:
    """Step a rig's muscles (activations in [-1, 1]: contraction > 0, relaxation < 0).

    Parameters
    ----------
    rig : Rig
        Precomputed here if it is not yet (precompute).
    fps : float
        Frames a second; each frame is `substeps` implicit steps.
    substeps : int
    spring : float
        The muscle-to-skin springs' stiffness in edges' stiffness (spring_stiffness).
    frequency : float
        Hz of the softest system's lowest mode (skin_density).
    damping, zeta : float
        Rayleigh damping: the mass term (x 2 pi frequency) and the stiffness term.
    warp : bool or None
        Modal warping (Kim eq. 10); None: on unless `reduced` (see __init__).
    reduced : float or None
        A relative RMS tolerance for the reduced output model (see __init__).
    springs : str
        "linear" or "kim" (Kim's eq. 15, kim_spring).
    reuse : FaceSimulator or None
        Its muscles' systems taken over where this rig shares them (see __init__).
    """

    def __init__(self, rig, fps: float = 60.0, substeps: int = 4, spring: float = 4.0,
                 frequency: float = 4.0, damping: float = 1.6, zeta: float = 0.0005, warp: bool | None = None,
                 reduced: float | None = None, springs: str = "linear", reuse=None):
        """warp: modal warping (Kim eq. 10, Choi & Ko's integrated rotation), on by default
        (None: on unless `reduced`).  Each node's frame turns with the tangent rotation of its
        system's displacement (rotation_operator(tangent=True): the spin of a muscle sliding the
        skin is left out, it creased a full smile), smoothed by diffusion (WARP_DIFFUSION); each
        spring's pull enters its node's frame by R^T and the displacement leaves it by the
        integrated rotation.  On a full smile against --solver full: 0.311 max deviation warped,
        0.333 linear (bench/simulate.py); a bent strip: 3-4x closer than linear modes
        (tests/physics/test_simulate.py).  warp=False: the linear modal face (twice the skin output
        rate), which fit-muscles' fields and the reduced model are made of.

        reduced: a relative RMS tolerance (e.g. 1e-4): the muscles' summed output is then
        drawn from a few shapes per muscle (output_subspace, about 12 each instead of ~116
        modes): one small matrix product per frame instead of one per muscle; advance()
        then steps each muscle's balanced truncation at the same tolerance.  step() and
        `fields()` stay exact.  The reduced model is linear: with it, warp defaults to off.

        springs: "linear" (default), k (u_m - u_s) in the system's stiffness; "kim", Kim's eq.
        15 along the spring's deformation (kim_spring), linearized at each step: no linear model
        then (no `reduced`, no fit), every frame stepped.

        reuse: a simulator made before at the same settings and density on a rig sharing
        Muscle objects with this one (a viewer's, growing as systems are made): those muscles'
        systems are taken over, their states and reduced models with them; the simulator
        handed over must no longer be stepped once this one is (call its `_sync` first)."""
        if springs not in SPRING_LAWS:
            raise MimicaError(f"springs {springs!r}: one of {', '.join(SPRING_LAWS)}")
        if springs == "kim" and reduced:
            raise MimicaError("the reduced model is linear: it needs the linear springs, not Kim's eq. 15")
        self.springs = springs
        warp = (reduced is None) if warp is None else bool(warp)
        self.warp = warp
        self.reduced = reduced
        self._joint = self._fm = self._xr = None
        precompute(rig)
        self.rig, self.fps, self.substeps = rig, fps, substeps
        self.h = 1.0 / (fps * substeps)
        rho = skin_density(rig, frequency)
        xi = damping * 2 * np.pi * frequency                  # Rayleigh mass term: near-critical
        self.rho, self._xi, self._zeta = rho, xi, zeta
        self.pulls = []
        self.pull_scale = 1.0          # scales every user pull (a timeline's "pull" channel)
        self.gravity_scale = 1.0       # scales gravity (a timeline's "gravity" channel)
        key = (self.h, spring, xi, zeta, rho, warp, springs)
        made = {} if reuse is None or reuse._key != key else {id(m): sm for m, sm in zip(reuse.rig.muscles, reuse.systems)}
        self._key = key
        self.systems = [made.get(id(m)) or _MuscleSystem(rig, m, self.h, spring, xi, zeta, rho, warp, springs)
                        for m in rig.muscles]
        self.names = [m.name for m in rig.muscles]
        self.inputs = ActivationMap(rig.muscles, lid_room=False)      # the lids: lid_contact
        self.gravity = None
        if rig.gravity_basis is not None:
            self.gravity = ModalWarpingSolver(rig.gravity_basis, self.h, xi=xi, zeta=zeta, density=rho)
        self._g_fq = None

    def set_gravity(self, g):
        """Constant body acceleration (3,) in the skin's units per s^2, or None."""
        if g is None or self.gravity is None:
            self._g_fq = None
            return
        b = self.gravity.b
        f = (b.mass[b.free, None] * np.asarray(g, float)[None, :]).ravel()
        self._g_fq = b.phi.T @ f / self.gravity.density                # rotation of gravity ignored

    def add_pull(self, center, radius: float, force, reach: float = 3.0):
        """A user pull (Kim §VI): `force` (3,) spread over the skin within `radius` of
        `center`, in its own system whose region of interest is `reach` x radius.

        Its displacement field joins the sum (eq. 21); `pull_scale` scales all pulls.
        """
        basis, nodes, weights = region_system(self.rig, np.asarray(center, float), radius, reach)
        solver = ModalWarpingSolver(basis, self.h, xi=self._xi, zeta=self._zeta, density=self.rho)
        f = np.zeros((self.rig.skin.n_vertices, 3))
        f[nodes] = weights[:, None] * np.asarray(force, float)[None, :]
        self.pulls.append((solver, basis.phi.T @ f[basis.free].ravel() / self.rho))

    def _step_forces(self):
        """One time step of the force types that are not muscles: user pulls and gravity."""
        for solver, fq in self.pulls:
            solver.v = (solver.v + solver.h * (self.pull_scale * fq - solver.lam * solver.q)) / solver.denom
            solver.q = solver.q + solver.h * solver.v
        if self._g_fq is not None:
            g = self.gravity
            g.v = (g.v + g.h * (self.gravity_scale * self._g_fq - g.lam * g.q)) / g.denom
            g.q = g.q + g.h * g.v

    def reset(self) -> "FaceSimulator":
        """Every force system back at rest (the face undeformed), keeping what prepare() built:
        a second clip, or a second timing run, without rebuilding the reduced model."""
        for sm in self.systems:
            sm.set_state(np.zeros_like(sm.state()))
        for sv, _ in self.pulls:
            sv.reset()
        if self.gravity is not None:                   # at rest even while switched off
            self.gravity.reset()
        self._xr = None
        return self

    def _other_solvers(self) -> list:
        """The force systems besides the muscles that are on: user pulls, gravity when set."""
        return [sv for sv, _ in self.pulls] + ([self.gravity] if self._g_fq is not None else [])

    @property
    def reduced_size(self) -> tuple[int, int]:
        """(output shapes, frame-model states) of the reduced model; (modes, states) exactly."""
        if self.reduced and not self.warp:
            return self._joint_output()[0].shape[1], self._frame_model()[0].shape[0]
        return sum(len(s.solver.q) for s in self.systems), sum(len(s.state()) for s in self.systems)

    def prepare(self) -> "FaceSimulator":
        """Build what advance() and displacement() use (the reduced output and frame model,
        or the exact frame transitions) now rather than inside the first frames."""
        if self.reduced and not self.warp:
            self._frame_model()
        elif self.springs == "linear":
            self._frame_transitions()
        return self

    def _sync(self):
        """After reduced frames: the muscles' full states again, from the reduced one (x = Ti xr)."""
        if self._xr is not None:
            _, _, _, Ts, Tis, offs = self._frame_model()
            for sm, Ti, o0, o1 in zip(self.systems, Tis, offs[:-1], offs[1:]):
                sm.set_state(Ti @ self._xr[o0:o1])
            self._xr = None

    def _frame_model(self):
        """The reduced frame model of every muscle, block-diagonal: xr <- Ar xr + Br a,
        z = Cr xr (the reduced output's coordinates); with each muscle's T, Ti and offsets."""
        if self._fm is None:
            U, proj = self._joint_output()
            blocks = [sm.frame_model(self.substeps, p, self.reduced) for sm, p in zip(self.systems, proj)]
            sizes = [b[0].shape[0] for b in blocks]
            offs = np.r_[0, np.cumsum(sizes)]
            kz = np.r_[0, np.cumsum([p.shape[0] for p in proj])]
            n = int(offs[-1])
            Ar, Br, Cr = np.zeros((n, n)), np.zeros((n, len(blocks))), np.zeros((int(kz[-1]), n))
            for i, (a, b, c, _, _) in enumerate(blocks):
                Ar[offs[i]:offs[i + 1], offs[i]:offs[i + 1]] = a
                Br[offs[i]:offs[i + 1], i] = b
                Cr[kz[i]:kz[i + 1], offs[i]:offs[i + 1]] = c
            self._fm = (Ar, Br, Cr, [b[3] for b in blocks], [b[4] for b in blocks], offs)
        return self._fm

    def step(self, activations: np.ndarray):
        """One time step with activations (n_muscles,)."""
        self._sync()
        self._step_forces()
        for s, a in zip(self.systems, self.inputs(activations)):
            s.step(float(a))

    def advance(self, activations: np.ndarray):
        """One displayed frame (all its substeps) with the activations held over it: every
        muscle's state goes through its substep transition raised to the number of substeps,
        x <- A^s x + (A^{s-1} + ... + 1) B a, all muscles in one batched product.  The same
        arithmetic as `substeps` calls of step() up to rounding; pulls and gravity step as usual.
        With `reduced`, the muscles step in their balanced-truncated frame model instead
        (`_MuscleSystem.frame_model`): a few states each, all in one small product; their
        full states come back (x = Ti xr) when step() or fields() needs them."""
        a = np.asarray(activations, float)[:len(self.systems)]
        if self.warp or self.springs != "linear":      # warping, eq. 15: not linear, step by step
            for _ in range(self.substeps):
                self.step(a)
            return
        a = self.inputs(a)
        if self.reduced and not self.warp:
            # the reduced frame model (balanced truncation): one small product for all muscles
            Ar, Br, _, Ts, _, offs = self._frame_model()
            if self._xr is None:
                self._xr = np.concatenate([T @ sm.state() for T, sm in zip(Ts, self.systems)])
            self._xr = Ar @ self._xr + Br @ a
            if self.pulls or self._g_fq is not None:
                for _ in range(self.substeps):
                    self._step_forces()
            return
        for (Ak, Bk), sm, ai in zip(self._frame_transitions(), self.systems, a):
            sv = sm.solver
            r = len(sv.q)
            if sm.resting and ai == 0.0:
                continue
            x = Ak @ np.concatenate(((sm.q, sm.v), sv.q, sv.v)) + Bk * ai
            sm.q, sm.v = float(x[0]), float(x[1])
            sv.q, sv.v = x[2:2 + r], x[2 + r:]
            sm.resting = False
        if self.pulls or self._g_fq is not None:
            for _ in range(self.substeps):
                self._step_forces()

    def _frame_transitions(self):
        """Per muscle, a displayed frame's transition (A^s, (A^{s-1} + ... + 1) B)."""
        fr = self.__dict__.get("_frame_tr")
        if fr is None:
            fr = self._frame_tr = [sm.frame_transition(self.substeps) for sm in self.systems]
        return fr

    def _joint_output(self):
        """[U_1 ... U_m] padded to every node (float32) and the blocks R_m^T Phi_m^T Phi_m."""
        if self._joint is None:
            cols, proj = [], []
            for sm in self.systems:
                U, p = sm.reduced_output(self.reduced)
                cols.append(U)
                proj.append(p)
            self._joint = (np.ascontiguousarray(np.concatenate(cols, 1)), proj)
        return self._joint

    def displacement(self) -> np.ndarray:
        """The skin's displacement: the sum over force types (Kim eq. 21), (n, 3)."""
        if self.reduced and not self.warp:
            U, proj = self._joint_output()
            if self._xr is not None:
                z = (self._frame_model()[2] @ self._xr).astype(np.float32)
            else:
                z = np.concatenate([p @ sm.solver.q for p, sm in zip(proj, self.systems)]).astype(np.float32)
            u = (U @ z).astype(np.float64).reshape(-1, 3)
            for sv in self._other_solvers():
                sv.add_displacement(u, False)
            cols = np.r_[0, np.cumsum([p.shape[0] for p in proj])]

            def closing(i):                                   # the closing drive's own part of u
                return (U[:, cols[i]:cols[i + 1]] @ z[cols[i]:cols[i + 1]]).astype(np.float64).reshape(-1, 3)
            return self._lid_contact(u, closing)
        self._sync()
        u = np.zeros_like(self.rig.skin.vertices)
        for sv in [s.solver for s in self.systems if not s.resting] + self._other_solvers():
            sv.add_displacement(u, self.warp)

        def closing(i):
            uc = np.zeros_like(u)
            self.systems[i].solver.add_displacement(uc, self.warp)
            return uc
        return self._lid_contact(u, closing)

    def _lid_contact(self, u, closing):
        """Lid contact (lid_contact): where the upper and lower margins of an eye would cross,
        the closing drive's field (closing(i), only then made) is taken away there until they
        meet (rig.drives.margin_opening >= 0 at every pair; only the margin nodes are looked at
        otherwise)."""
        rest = self.rig.skin.vertices
        for i in self.inputs.lid_close:
            info = self.rig.muscles[i].info
            p = lid_pairs(info)
            if len(p) == 0 or (self.systems[i].resting and self._xr is None):
                continue
            if margin_opening(rest[p] + u[p], info).min() >= 0:
                continue
            lid_contact(u, closing(i), rest, info)
        return u

    def fields(self) -> dict:
        """Each force type's own displacement field (Kim Fig. 14)."""
        self._sync()

        def field(sv):
            u = np.zeros_like(self.rig.skin.vertices)
            sv.add_displacement(u, self.warp)
            return u
        out = {n: field(s.solver) for n, s in zip(self.names, self.systems)}
        if self._g_fq is not None:
            out["gravity"] = field(self.gravity)
        return out

    def run(self, activation_at, duration: float, progress=None, scales_at=None) -> np.ndarray:
        """Frames (F, n, 3) of skin positions; activation_at(t) -> (n_muscles,).

        scales_at(t) -> (gravity_scale, pull_scale), for forces keyed on curves.
        """
        def scales(t):
            self.gravity_scale, self.pull_scale = scales_at(t)
        return run_frames(self, activation_at, duration, progress, scales if scales_at is not None else None)


def displacement_cosine(u: np.ndarray, reference: np.ndarray, moving: float = 0.05) -> float:
    """The cosine between two displacement fields over the reference's moving region: the anatomy
    check.

    Parameters
    ----------
    u, reference : (n, 3) float arrays
    moving : float
        Nodes moving more than this share of the reference's largest motion count.

    Returns
    -------
    float
    """
    m = np.linalg.norm(reference, axis=1)
    sel = m > moving * m.max()
    a, b = u[sel], reference[sel]
    return float((a * b).sum() / (np.linalg.norm(a) * np.linalg.norm(b) + 1e-300))
