"""The muscle-driven face (Kim 2020 §V-VI), stepped: muscles stretch, springs pull the skin, and each
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

The systems are made by physics.systems (precompute), the springs by physics.springs, the drives'
loads and the lids' contact by physics.drives; FaceSimulator steps them.
"""

from __future__ import annotations

import numpy as np

from ..errors import MimicaError
from ..rig.drives import lid_pairs, margin_opening
from .drives import ActivationMap, lid_contact
from .engine import run_frames
from .modal import ModalWarpingSolver
from .springs import SPRING_LAWS
from .systems import MuscleSystem, precompute, region_system, skin_density


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
        self.systems = [made.get(id(m)) or MuscleSystem(rig, m, self.h, spring, xi, zeta, rho, warp, springs)
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
        (`MuscleSystem.frame_model`): a few states each, all in one small product; their
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
