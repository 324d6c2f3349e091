"""The viewer's state: a rig's muscles (and facial actions, and age when wrinkles are on),
simulated live; a second face the current expression is transferred onto.

A rig whose force systems are not made yet is shown at rest at once; `make_systems` (run beside
the page) then makes them, the ones the page moves first, and the simulation takes in each batch
as it is made: the page opens in the seconds the rig's placement takes, not after the minute the
whole library's systems take on a whole head."""

from __future__ import annotations

import threading

import numpy as np

from ..errors import MimicaError


class ViewerSession:
    """What the viewer's page plays: a rig's reduced simulation driven by muscles, facial actions and
    presets, the wrinkle layer at an age, and a second face the expression is transferred onto.

    Parameters
    ----------
    rig : Rig
    mask : WrinkleMask or None
        The wrinkles (None: none).
    fps : float
    """
    def __init__(self, rig, mask=None, fps: float = 60.0):
        from ..anim import PRESETS
        from ..rig.muscles import FACIAL_ACTIONS
        self.rig, self.fps = rig, fps
        self.muscles = [m.name for m in rig.muscles]
        self._lock = threading.Lock()          # the simulation: stepped here, replaced by make_systems
        self.sim, self._order = None, np.zeros(0, int)
        self.made = (0, len(self.pending()))   # (systems made, of) as make_systems goes
        if not self.made[1]:
            self._take_in()
        self.base = np.array([n.rsplit("_", 1)[0] if n.endswith(("_L", "_R")) else n for n in self.muscles])
        # facial actions that reach at least one muscle of this rig
        from ..rig.muscles import weights_on
        self.actions = {k: weights_on(v, self.muscles) for k, v in FACIAL_ACTIONS.items()
                        if any(b in v for b in self.base)}      # each on this rig's muscles, made once
        self.presets = {k: v for k, v in PRESETS.items()}
        self.values = {n: 0.0 for n in self.muscles}
        self.action_values = {k: 0.0 for k in self.actions}
        from ..pipeline import SimulateOptions
        self.age = SimulateOptions.age          # the wrinkles' age, as `simulate` and the pipeline default it
        self.layer = None
        if mask is not None:
            from ..wrinkles import WrinkledSkin
            self.layer = WrinkledSkin.build(rig.skin, mask, refine=False).layer
        self.rest = rig.skin.vertices
        self.second = None            # (mesh, ExpressionTransfer)
        self._last = None             # the skin of the last frame computed (float64)
        self.moved = True             # whether that frame differs from the one before

    # -- controls ------------------------------------------------------------------------------
    def controls(self) -> dict:
        return {"muscles": self.muscles, "actions": list(self.actions), "presets": list(self.presets),
                "age": self.layer is not None, "age_value": self.age,
                "made": self.made[0], "of": self.made[1], "ready": self.sim is not None and not self.pending()}

    def set(self, name: str, value) -> None:
        if not isinstance(name, str):
            raise MimicaError("set: 'name' must be a string")
        if not isinstance(value, (int, float)) or isinstance(value, bool) or not np.isfinite(value):
            raise MimicaError(f"set {name}: 'value' must be a finite number")
        v = float(value)
        if name == "age":
            if self.layer is None:
                raise MimicaError("age: this face has no wrinkle layer (the viewer was started without wrinkles)")
            self.age = float(np.clip(v, 15.0, 95.0))
        elif name in self.values:
            self.values[name] = float(np.clip(v, -1.0, 1.0))
        elif name in self.action_values:
            self.action_values[name] = float(np.clip(v, 0.0, 1.0))
        else:
            raise MimicaError(f"set: no control named {name!r}")

    def preset(self, name: str) -> None:
        if name not in self.presets and name != "neutral":
            raise MimicaError(f"preset: unknown expression {name!r}")
        from ..rig.muscles import weights_on
        for n, v in zip(self.muscles, weights_on(self.presets.get(name, {}), self.muscles)):
            self.values[n] = float(v)
        for k in self.action_values:
            self.action_values[k] = 0.0

    def activations(self) -> np.ndarray:
        a = np.array([self.values[n] for n in self.muscles])
        for k, w in self.action_values.items():
            if w:
                a += w * self.actions[k]
        return np.clip(a, -1.0, 1.0)

    # -- the force systems -------------------------------------------------------------------------
    def pending(self) -> list[str]:
        """The force systems not made yet (muscle names, "gravity")."""
        from ..physics.modal import ModalBasis
        out = [m.name for m in self.rig.muscles if not isinstance(m.basis, (ModalBasis, dict))]
        if self.rig.params.get("gravity", True) and self.rig.gravity_basis is None:
            out.insert(0, "gravity")
        return out

    def _take_in(self):
        """Simulate every muscle whose system is made, taking over the running simulation's
        systems and states (FaceSimulator's `reuse`)."""
        from ..physics.face import FaceSimulator
        from ..physics.modal import ModalBasis
        from ..rig import Rig
        rig = self.rig
        idx = np.array([i for i, m in enumerate(rig.muscles) if isinstance(m.basis, (ModalBasis, dict))], int)
        part = rig if len(idx) == len(rig.muscles) else Rig(rig.skin, rig.landmarks, [rig.muscles[i] for i in idx],
                                                              rig.params, rig.gravity_basis)
        old = self.sim
        # display: reduced output and frame model (0.007% off), built now, not inside the first frames
        sim = FaceSimulator(part, fps=self.fps, reduced=1e-4, reuse=old).prepare()
        with self._lock:
            if old is not None:
                old._sync()                    # its states into the systems the new one shares
            self.sim, self._order = sim, idx
            self.moved = True                  # a new simulation: its next frame is worth drawing

    def make_systems(self, progress=None) -> None:
        """Make the rig's missing force systems, gravity first (the softest: the skin's density
        is set by it), then those the controls move now before the others; the simulation takes
        them in whenever all those moved are made, and at the end.  Run beside the page (a
        thread); controls set meanwhile are kept.

        Parameters
        ----------
        progress : callable, optional
            Called as progress(k, n, name) after each system is made.
        """
        from ..physics import precompute
        from ..physics.systems import skin_system
        left = self.pending()
        n, k = len(left), 0
        skin = skin_system(self.rig) if left else None      # the skin's matrices, once for every system
        taken = {self.muscles[i] for i in self._order} if self.sim is not None else set()
        while left:
            moved = set(self._moved())
            name = "gravity" if "gravity" in left else next((x for x in left if x in moved), left[0])
            precompute(self.rig, only=[name], skin=skin)
            left.remove(name)
            k += 1
            self.made = (k, n)
            if progress:
                progress(k, n, name)
            moved = set(self._moved())
            # every moved muscle made, and one of them not simulated yet: take them in
            if not left or (moved - taken - set(left) and not moved & set(left)):
                self._take_in()
                taken = {self.muscles[i] for i in self._order}

    def _moved(self) -> list[str]:
        """The muscles the controls move now."""
        a = self.activations()
        return [n for n, v in zip(self.muscles, a) if v != 0.0]

    # -- simulation -----------------------------------------------------------------------------
    def step(self) -> None:
        """Advance the simulation by one displayed frame (its substeps); cheap."""
        if self.sim is None:
            return
        a = self.activations()
        with self._lock:
            self.sim.advance(a[self._order])

    def positions(self, tol=1e-4) -> np.ndarray:
        """The skin now (with wrinkles), float32: the summed fields, the costly part.  Sets
        `moved`: whether any node moved more than tol since the last call."""
        if self.sim is None:
            x = self.rest.copy()
        else:
            with self._lock:
                x = self.rest + self.sim.displacement()
        if self.layer is not None:
            x = self.layer.apply(x, self.age, inplace=True)      # x is this frame's own array
        self.moved = self._last is None or float(np.abs(x - self._last).max()) > tol
        self._last = x
        return x.astype(np.float32)

    # -- a second face ----------------------------------------------------------------------------
    def load_second(self, mesh):
        from ..landmarks import landmarks_for
        from ..transfer import ExpressionTransfer, TransferSettings
        src = self.rig.skin
        ls = self.rig_landmarks()
        lt = landmarks_for(mesh, None, "the second face")
        self.second = (mesh, ExpressionTransfer(src, mesh, ls, lt, TransferSettings(method="vtc")))
        return mesh

    def rig_landmarks(self):
        from ..landmarks import Landmarks
        return Landmarks.snap(self.rig.skin, self.rig.landmarks)

    def second_positions(self) -> np.ndarray | None:
        if self.second is None:
            return None
        x = self._last if self._last is not None else self.rest
        return self.second[1].apply(x[None])[0].astype(np.float32)
