"""Performances fitted to muscles: the non-negative activations whose
simulated skin best matches target shapes.

Kim's force decomposition (eq. 21) makes the modal face linear in the activations: each
muscle's system is linear with one input, so its skin field at rest under a held activation
a is a U_m, with U_m its steady state at a = 1, x* = (I - A)^-1 B of its step x' = A x + B a.
A target displacement d is then fitted by a bounded least squares,

    min_a  || W^1/2 (sum_m a_m U_m - d) ||^2 + ridge ||a||^2,   0 <= a <= 1,

over the skin that muscles move (W: one per vertex, zero where no muscle reaches).  The
normal equations G = U^T W U (m x m) are formed once: a frame costs one small bounded solve
on the Cholesky factor of G, independent of the mesh size.  The jaw and the lids are drives of
the rig (rig.drives: the jaw's pose is the digastric's and the lateral pterygoids' activations),
fitted with the muscles; a lid closed in the target is then closed until the rims meet, and
held there (lid contact, as the simulator holds it), and the jaw's closers are left at 0.  The fields are the linear modal face's (warp off); the gaze is not
a muscle and stays unfitted.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import MimicaError
from ..rig.drives import lid_pairs, margin_opening, open_pairs

RIDGE = 1e-6        # relative to the Gram matrix's mean diagonal: keeps twin muscles apart
# A target lid open at most this part of its rest opening is a closed one (the fit closes it
# until the rims meet): ICT's eyeBlink, sculpted on the generic face, leaves 0.06-0.23 of the
# opening at the facing margin nodes of six identities (0.14 on the generic face itself, the
# nodes at different depths where its lids meet); its squints and cheek raisers 0.69 or more.
LID_CLOSED = 1 / 3


def muscle_fields(sim) -> np.ndarray:
    """Each muscle's skin displacement held at activation 1, at rest (steady state), for a modal,
    unwarped FaceSimulator.  The simulator is left at rest.

    Parameters
    ----------
    sim : FaceSimulator

    Returns
    -------
    (m, n, 3) float array
        m muscles, n skin nodes.
    """
    out = np.zeros((len(sim.systems), sim.rig.skin.n_vertices, 3))
    sim.reset()
    for i, sm in enumerate(sim.systems):
        sm.set_state(sm.steady_state())
        sm.solver.add_displacement(out[i], False)
        sm.set_state(np.zeros_like(sm.state()))
    sim.reset()
    return out


def skin_stiffness(rig):
    """The rig's skin stiffness with its tethers, the shell's stiffnesses recorded in rig.params as
    precompute does (the springs are scaled by them).

    Parameters
    ----------
    rig : Rig

    Returns
    -------
    (3n, 3n) sparse matrix
    """
    from .systems import skin_system
    energy, _, K, _ = skin_system(rig, rotation=False)
    rig.params.update(k_area=energy.k_area, k_length=energy.k_length, k_bend=energy.k_bend)
    return K


def static_field(rig, m, K, spring: float = 4.0, motion=None) -> np.ndarray:
    """One muscle's (or drive's) steady state at activation 1 by one sparse solve in full space,
    (K + K_s) u = K_s u_m over its region of interest -- what its modal system settles to (its
    static load shapes make that exact, tests/physics/test_drives.py), without the modes.

    Parameters
    ----------
    rig : Rig
    m : Muscle
    K : (3n, 3n) sparse matrix
        skin_stiffness's.
    spring : float
        The springs' stiffness in edges' stiffness.
    motion : (k, 3) float array or None
        A drive's anchors moved otherwise than at full activation.

    Returns
    -------
    (n, 3) float array
    """
    import scipy.sparse as sp
    from ..solver import SPDSolver
    from .drives import drive_load
    from .springs import drive_springs, strip_springs
    n = rig.skin.n_vertices
    if m.kind == "drive":
        ks, f = drive_springs(rig, m), drive_load(rig, m, motion)     # fixed at precompute
    else:
        ks, f = strip_springs(rig, m, spring)
    dof = (3 * np.nonzero(m.roi)[0][:, None] + np.arange(3)).ravel()
    A = (K + sp.diags(np.repeat(ks, 3))).tocsr()[dof][:, dof]
    u = np.zeros(3 * n)
    u[dof] = SPDSolver(A.tocsc()).solve(f.reshape(-1)[dof])
    return u.reshape(-1, 3)


def static_fields(rig, spring: float = 4.0) -> np.ndarray:
    """static_field of every muscle of the rig: the same steady states as muscle_fields, what
    calibration (tools/calibrate_muscles.py) evaluates hundreds of times.

    Parameters
    ----------
    rig : Rig
    spring : float

    Returns
    -------
    (m, n, 3) float array
    """
    K = skin_stiffness(rig)
    return np.stack([static_field(rig, m, K, spring) for m in rig.muscles])


def _box_ls(M: np.ndarray, y: np.ndarray, upper: float) -> np.ndarray:
    """argmin ||M a - y||, 0 <= a <= upper: Lawson-Hanson NNLS (fast, in C) on the activations
    not held at `upper`; those that overshoot are then held there, those held whose gradient asks
    to come down are let go, until the Karush-Kuhn-Tucker conditions hold (bounded-variable least
    squares where they still fail).  24 us a frame instead of 580 us for BVLS alone (8 muscles);
    with 56 channels, letting held ones go (it only held before) took BVLS from 3 frames in 4 to
    none."""
    from scipy.optimize import lsq_linear, nnls
    m = M.shape[1]
    top = np.zeros(m, bool)
    tol = 1e-9 * max(float(np.abs(M.T @ y).max()), 1e-300)
    a = np.zeros(m)
    for _ in range(2 * m + 2):
        free = ~top
        r = y - M[:, top].sum(1) * upper
        a = np.full(m, upper)
        a[free] = nnls(M[:, free], r)[0] if free.any() else []
        over = free & (a > upper)
        if over.any():
            top |= over
            continue
        g = M.T @ (M @ a - y)                                # the gradient of 1/2 ||M a - y||^2
        down = top & (g > tol)                               # held, but better lower
        if not down.any():
            break
        top &= ~down
    g = M.T @ (M @ a - y)
    ok = np.where(a <= 0, g >= -tol, np.where(a >= upper, g <= tol, np.abs(g) <= 1e3 * tol))
    if ok.all():
        return a
    return lsq_linear(M, y, bounds=(0.0, upper), method="bvls").x


@dataclass
class MuscleFit:
    """Fit activations to displacements of a rig's skin, many frames at a time (a ridge-regularized
    least squares on the muscles' fields, factored once; lid contact where the rig has lids).

    Attributes
    ----------
    names : list of str
        The muscles.
    fields : (m, n, 3) float array
        Their steady states at activation 1 (muscle_fields, static_fields).
    weights : (n,) float array
        Vertex weights of the misfit (1 on the muscles' reach, else 0).
    inputs : ActivationMap or None
        The rig's (the jaw's closers, the drives' range).
    rest : (n, 3) float array or None
        The rig's skin at rest, for lid contact (None: no lids).
    lids : list of tuple
        (closing drive's index, its info) for lid contact.
    """
    names: list
    fields: np.ndarray           # (m, n, 3)
    weights: np.ndarray          # (n,) vertex weights of the misfit (1 on the muscles' reach, else 0)
    inputs: object = None        # the rig's ActivationMap (the jaw's closers, the drives' range)
    rest: np.ndarray = None      # (n, 3) the rig's skin at rest: lid contact (None: no lids)
    lids: list = field(default_factory=list)   # (closing drive's index, its info): lid contact

    def __post_init__(self):
        U = self.fields.reshape(len(self.names), -1)                 # (m, 3n)
        w3 = np.repeat(self.weights, 3)
        self._UW = U * w3                                             # U^T W, once
        G = self._UW @ U.T
        self._G = G.copy()                                            # without the ridge: the misfit's
        G += RIDGE * max(float(np.mean(np.diag(G))), 1e-300) * np.eye(len(G))
        self._U, self._w3 = U, w3
        self._L = np.linalg.cholesky(G)
        self._lid = []                                   # per lid: what _contact looks at, once
        for c, info in self.lids:
            p = lid_pairs(info)
            x0 = self.rest[p]
            o0 = margin_opening(x0, info)
            up = self.fields[:, p]                                           # (m, k, 2, 3)
            self._lid.append((c, info, p, x0, open_pairs(o0), float(o0.max()), up))

    @classmethod
    def of_rig(cls, rig, sim=None) -> "MuscleFit":
        """The fit for a rig: its muscles' fields, the misfit summed over the vertices some
        muscle's region of interest covers, each vertex alike -- the measure of a match as
        the benchmark states it (the cosine over a shape's vertices); weighted by the vertices' area instead, the
        fit of ICT's shapes on the held-out identities read min 0.682 (mouthDimple: the dense
        lips count less by area) / median 0.888 against 0.797 / 0.895 (docs/benchmarks.md)."""
        from .face import FaceSimulator
        sim = sim or FaceSimulator(rig, warp=False)                  # the fields are the linear face's
        return cls.of_fields(rig, muscle_fields(sim), sim.inputs)

    @classmethod
    def of_fields(cls, rig, fields: np.ndarray, inputs=None) -> "MuscleFit":
        """The fit for a rig from its muscles' fields (m, n, 3) made otherwise (static_fields:
        what calibration evaluates); inputs: the rig's ActivationMap (made when None)."""
        from .drives import ActivationMap
        inputs = ActivationMap(rig.muscles, lid_room=False) if inputs is None else inputs
        fields = np.array(fields, float)
        # the jaw's closers are left out (at 0): they only hold the jaw that the digastric opens
        # (ActivationMap), so the fitted opening is the digastric's own activation
        fields[inputs.closers] = 0.0
        reach = np.zeros(rig.skin.n_vertices, bool)
        for m in rig.muscles:
            reach |= np.asarray(m.roi, bool)
        lids = [(i, rig.muscles[i].info) for i in inputs.lid_close if len(lid_pairs(rig.muscles[i].info))]
        return cls([m.name for m in rig.muscles], fields, reach.astype(float), inputs,
                   np.array(rig.skin.vertices, float), lids)

    def fit(self, displacements: np.ndarray, upper: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
        """((F, m) activations in [0, upper], (F,) relative misfit) of displacements (F, n, 3)
        (or one (n, 3)).  The misfit: ||W^1/2 (U a - d)|| / ||W^1/2 d||."""
        from scipy.linalg import solve_triangular
        d = np.asarray(displacements, float)
        one = d.ndim == 2
        d = d.reshape(1 if one else len(d), -1)
        if d.shape[1] != self._U.shape[1]:
            raise MimicaError(f"targets of {d.shape[1] // 3} vertices for a rig of {self._U.shape[1] // 3}")
        h = self._UW @ d.T                                            # (m, F): U^T W d
        y = solve_triangular(self._L, h, lower=True)                  # L^-1 U^T W d
        Lt = self._L.T
        act = np.empty((len(d), len(self.names)))
        at = [d.reshape(len(d), -1, 3)[:, lid[2]] for lid in self._lid]            # (F, k, 2, 3) each
        for f in range(len(d)):
            act[f] = self._inputs(_box_ls(Lt, y[:, f], upper))
        act = self._close_lids(act, at)
        dd = (d * d * self._w3).sum(1)
        res = act @ self._U - d
        for f in self._touching(act):                                # the lids held where they meet
            res[f] = self.displacement(act[f]).reshape(-1) - d[f]
        mis = np.sqrt((res * res * self._w3).sum(1) / np.maximum(dd, 1e-300))
        return (act[0], mis[0]) if one else (act, mis)

    def fit_combinations(self, shapes: np.ndarray, weights: np.ndarray, upper: float = 1.0):
        """((F, m) activations, (F,) relative misfit) for frames that are combinations of a few
        shapes' displacements (K, n, 3) with weights (F, K) -- an ARKit take: U^T W d and the
        misfit's norms come from K projections made once, so a frame never touches the mesh
        (the misfit from these norms loses digits where it is under about 1e-3, and is the linear
        face's: where lid contact holds a lid, fit() measures the held one)."""
        from scipy.linalg import solve_triangular
        S = np.asarray(shapes, float).reshape(len(shapes), -1)
        if S.shape[1] != self._U.shape[1]:
            raise MimicaError(f"shapes of {S.shape[1] // 3} vertices for a rig of {self._U.shape[1] // 3}")
        w = np.asarray(weights, float)
        H = self._UW @ S.T                                            # (m, K): U^T W s_k
        D = (S * self._w3) @ S.T                                     # (K, K): s_j^T W s_k
        h = H @ w.T                                                   # (m, F): U^T W d_f
        y = solve_triangular(self._L, h, lower=True)                  # (m, F)
        Lt = self._L.T
        at = [np.tensordot(w, S.reshape(len(S), -1, 3)[:, lid[2]], 1) for lid in self._lid]
        act = np.array([self._inputs(_box_ls(Lt, y[:, f], upper)) for f in range(len(w))]).reshape(len(w), -1)
        act = self._close_lids(act, at)
        G = self._G
        dd = np.einsum("fj,jk,fk->f", w, D, w)
        err = np.einsum("fi,ij,fj->f", act, G, act) - 2 * np.einsum("fi,if->f", act, h) + dd
        return act, np.sqrt(np.maximum(err, 0.0) / np.maximum(dd, 1e-300))

    def _inputs(self, a):
        """The drives' inputs of fitted activations (the rig's ActivationMap: the jaw, 0..1)."""
        return a if self.inputs is None or not self.inputs.drives else self.inputs(a)

    def _close_lids(self, act, targets):
        """Fitted activations (F, m) with each closing lid closed as far as its target's:
        targets, per lid, the target's displacement at the lid's margin pairs (F, k, 2, 3).  Lid
        contact makes a lid nonlinear in its activation: past the point where the rims first
        touch, more activation closes the rest of the eye while contact holds the rest
        (FaceSimulator, lid_contact); the least squares, linear, sees only the crossing it would
        make, and stopped a fitted blink 8-9 % of the opening short at the ends of the eye.  So
        where the fitted lid is left more open than the target at its widest (the pairs open at
        least half the widest at rest; a target within LID_CLOSED of closed: not at all), its
        closing activation is raised, up to 1, until it is not: the smallest such activation,
        on a grid of 32 and then 32 within it, all frames at once."""
        for (c, info, p, x0, wide, o0max, Up), dp in zip(self._lid, targets):
            goal = np.maximum(margin_opening(x0 + dp, info)[:, wide].max(1), 0.0)      # (F,)
            goal[goal <= LID_CLOSED * o0max] = 0.0
            x = x0 + np.tensordot(act, Up, 1)                                          # (F, k, 2, 3)
            f = np.nonzero((margin_opening(x, info)[:, wide].max(1) > goal) & (act[:, c] < 1.0))[0]
            if len(f) == 0:
                continue
            base = x[f] - act[f, c][:, None, None, None] * Up[c]                       # without the lid
            lo, hi, rows = act[f, c], np.ones(len(f)), np.arange(len(f))
            for _ in range(2):
                grid = lo[:, None] + (hi - lo)[:, None] * np.linspace(0.0, 1.0, 33)    # (F', 33)
                o = margin_opening(base[:, None] + grid[..., None, None, None] * Up[c], info)[..., wide].max(-1)
                ok = o <= goal[f, None]
                i = np.maximum(ok.argmax(1), 1)                    # the first that holds (lo never does)
                hit = ok.any(1)                                    # none: as far as it goes, 1
                lo = np.where(hit, grid[rows, i - 1], hi)
                hi = np.where(hit, grid[rows, i], hi)
            act[f, c] = hi
        return act

    def _touching(self, act):
        """The frames (indices) whose fitted lids would cross, linearly: lid contact holds them."""
        out = set()
        for c, info, p, x0, _, _, Up in self._lid:
            o = margin_opening(x0 + np.tensordot(act, Up, 1), info)
            out.update(np.nonzero(o.min(1) < 0)[0].tolist())
        return sorted(out)

    def displacement(self, activations: np.ndarray) -> np.ndarray:
        """The rest displacement (n, 3) of the fitted activations (m,): the fields' sum, the lids
        held where they meet (lid contact, as the modal face holds them)."""
        from .drives import lid_contact
        a = np.asarray(activations, float)
        u = (a @ self._U).reshape(-1, 3)
        for c, info in self.lids:
            if a[c] > 0:
                lid_contact(u, a[c] * self._U[c].reshape(-1, 3), self.rest, info)
        return u
