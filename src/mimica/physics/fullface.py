"""The face without modes: `mimica simulate --solver full`.

The skin is one nonlinear shell (Kim eq. 4, the rig's stiffnesses), held where no muscle's
region of interest reaches (eq. 19) and tethered to its rest as in the modal rig; every
muscle's stretch mode (eqs. 11-13, critically damped to its activation) pulls the skin
through its springs (eqs. 14-16, k (u_m - u_s)), all muscles at once on the same skin rather
than one system per force (eqs. 20-21).  Each step is implicit Euler with Newton on the full
energy (FullSolver: a PSD Hessian and a line search on implicit Euler's potential, so a
full smile that folds the cheek converges instead of diverging): a few seconds a frame on the
2-core machine, free of the modal truncation, the linearization at rest and the
decomposition, the figure the modal face is checked against.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..errors import MimicaError
from ..rig.drives import jaw_open_factors
from .engine import run_frames
from .drives import ActivationMap, drive_motions
from .springs import DRIVE_SPRING, spring_stiffness, tether_springs
from .systems import follow_activation, precompute, skin_density
from .modal import FullSolver
from .shell import ShellEnergy, lumped_mass


class FullFaceSimulator:
    """Step a rig's muscles on the full nonlinear skin (implicit Euler, projected Newton:
    modal.FullSolver); the Engine interface.

    The physical parameters are FaceSimulator's.  Implicit Euler is stable at any step, so one step
    a frame.

    Parameters
    ----------
    rig : Rig
    fps : float
    substeps : int
    spring, frequency, damping, zeta : float
        As FaceSimulator's.
    newton_iters : int
    tol : float
        Newton's relative residual force.
    xtol : float
        Relative to the rig's mean edge: Newton ends once no node moves further (at 1e-2 the ICT
        face under a full smile took 2-10 iterations a step, and a smaller step did not take
        fewer).
    footprint : float
        The radius, in mean edges, over which each spring's insertion (its fan, rig.spring_fan) is
        spread again (0: on the fan alone, as in the modal face).
    engage : float
        The muscle stretch |q| at which its springs are fully on.
    """

    def __init__(self, rig, fps: float = 60.0, substeps: int = 1, spring: float = 4.0, frequency: float = 4.0,
                 damping: float = 1.6, zeta: float = 0.0005, newton_iters: int = 30, tol: float = 1e-6,
                 xtol: float = 1e-2, footprint: float = 5.0, engage: float = 0.1):
        """The physical parameters are FaceSimulator's.  Implicit Euler is stable at any step,
        so one step a frame (substeps=1); xtol, relative to the rig's mean edge, ends Newton
        once no node moves further (at 1e-2 the ICT face under a full smile took 2-10
        iterations a step, and a smaller step did not take fewer).  footprint: the radius, in
        mean edges, over which each spring's insertion (its fan, rig.spring_fan) is spread
        again (0: on the fan alone, as in the modal face); engage: the muscle stretch |q| at
        which its springs are fully on."""
        precompute(rig)             # the stiffnesses, and the densities of the modal face's systems
        self.rig, self.fps, self.substeps, self.engage = rig, fps, substeps, engage
        self.h = h = 1.0 / (fps * substeps)
        p, skin = rig.params, rig.skin
        n = skin.n_vertices
        free = np.zeros(n, bool)
        for m in rig.muscles:
            free |= m.roi
        # the shell on the free nodes and two rings around them: every energy term that
        # touches a free node, with its held neighbours as boundary
        t = skin.triangles
        near = free.copy()
        for _ in range(2):
            near[t[near[t].any(1)].ravel()] = True
        tris = t[near[t].all(1)]
        self.nodes = np.unique(tris)
        remap = np.full(n, -1)
        remap[self.nodes] = np.arange(len(self.nodes))
        energy = ShellEnergy(skin.vertices[self.nodes], remap[tris], p["k_area"], p["k_length"], p["k_bend"])
        mass = lumped_mass(skin)
        rho = skin_density(rig, frequency)
        self.k = spring_stiffness(rig, spring)
        self.tether = tether_springs(p.get("tether", 0.0), p["k_length"], p["mean_edge"], mass)[self.nodes]
        # each spring's insertion spread over the skin within `footprint` mean edges of its node
        # (weights (1 - (d/R)^2)^2, summing to 1): the same total pull, without the tent that a
        # stiff spring pulls up on a single node of the full-resolution skin
        from scipy.spatial import cKDTree
        x = skin.vertices[self.nodes]
        tree = cKDTree(x)
        R = max(footprint, 1e-9) * p["mean_edge"]
        self.spread = []                               # per muscle: (sim nodes x muscle nodes)
        for m in rig.muscles:
            at = remap[m.attach]
            if (at < 0).any():
                raise MimicaError(f"rig: muscle {m.name} is attached outside every region of interest; "
                                  "rebuild it with `mimica rig`")
            if m.kind == "drive":                      # a drive's anchors hold their own nodes, by weight
                w = DRIVE_SPRING * (m.weight if m.weight is not None else np.ones(len(at)))
                self.spread.append(sp.csr_matrix((w, (at, np.arange(len(at)))), shape=(len(x), len(at))))
                continue
            fj, fw, fi = m.springs()                   # the modal face's fan (rig.spring_fan) ...
            fj = remap[fj]                             # (in its ROI, as its attachments)
            near_at = tree.query_ball_point(x[fj], R)  # ... each member spread again (its node among its own)
            cols = np.repeat(np.arange(len(fj)), [len(js) for js in near_at])
            rows = np.concatenate(near_at).astype(int)
            w = (1 - (np.linalg.norm(x[rows] - x[fj[cols]], axis=1) / R) ** 2) ** 2
            S = sp.csr_matrix((w, (rows, cols)), shape=(len(x), len(fj)))
            S = S @ sp.diags(1.0 / np.asarray(S.sum(axis=0)).ravel())
            self.spread.append(S @ sp.csr_matrix((fw, (np.arange(len(fj)), fi)), shape=(len(fj), len(at))))
        self.spring_sum = [self.k * np.asarray(W.sum(axis=1)).ravel() for W in self.spread]
        self.solver = FullSolver(energy, rho * mass[self.nodes], ~free[self.nodes], h,
                                 xi=damping * 2 * np.pi * frequency, zeta=zeta, newton_iters=newton_iters,
                                 tol=tol, xtol=xtol * p["mean_edge"],
                                 springs=self.tether + sum(self.spring_sum))
        self.stretch = [m.stretch for m in rig.muscles]
        # the anchors' displacement at stretch q: q x the stretch, the jaw's exactly turned
        self.parts = [drive_motions(m) if m.kind == "drive" else None for m in rig.muscles]
        self.phi = [np.radians(m.info["angle"]) if "angle" in m.info else None for m in rig.muscles]
        self.omega = np.array([m.omega for m in rig.muscles])
        self.q = np.zeros(len(rig.muscles))
        self.v = np.zeros(len(rig.muscles))
        self.names = [m.name for m in rig.muscles]
        self.inputs = ActivationMap(rig.muscles)

    def step(self, activations) -> None:
        a = self.inputs(np.asarray(activations, float)[:len(self.q)])
        self.q, self.v = follow_activation(self.q, self.v, a, self.h, self.omega)
        # a muscle's springs engage as it contracts or relaxes (stiffness ramps in with |q| up
        # to `engage`): a muscle at rest exerts nothing and does not hold the skin, as in the
        # modal face, where each muscle's springs are in its own system only (eqs. 20-21)
        e = np.minimum(np.abs(self.q) / self.engage, 1.0)
        f = np.zeros((len(self.nodes), 3))
        for ei, q, W, st, parts, phi in zip(e, self.q, self.spread, self.stretch, self.parts, self.phi):
            if ei > 0:
                um = q * st
                if parts is not None and len(parts) == 2:
                    fs, fc = jaw_open_factors(q, phi)
                    um = fs * parts[0] + fc * parts[1]
                f += W @ (ei * self.k * um)                # k u_m; the -k u_s part is in the springs
        self.solver.set_springs(self.tether + sum(ei * s for ei, s in zip(e, self.spring_sum)))
        self.solver.step(f)

    def displacement(self) -> np.ndarray:
        u = np.zeros_like(self.rig.skin.vertices)
        u[self.nodes] = self.solver.u
        return u

    def run(self, activation_at, duration: float, progress=None) -> np.ndarray:
        """Frames (F, n, 3) of skin positions; activation_at(t) -> (n_muscles,)."""
        return run_frames(self, activation_at, duration, progress)
