"""The engines a rig is simulated by, behind one interface (`Engine`), chosen by name
(physics.make_engine): "modal" (Kim 2020's shells in modal coordinates, one system per force type:
face.FaceSimulator), "full" (the whole skin as one nonlinear shell, implicit Euler and projected
Newton: fullface.FullFaceSimulator) and "sprung" (Viaud and Yahia 1992's force fields:
sprung.SprungFace); and the frame loop they share (`run_frames`)."""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

from ..errors import MimicaError

ENGINES = ("modal", "full", "sprung")


@runtime_checkable
class Engine(Protocol):
    """What every engine is: made from a rig, stepped with the muscles' activations, its skin's
    displacement read after each step, a whole run handed back as frames.

    Attributes
    ----------
    rig : Rig
        The rig it simulates (its skin: n nodes).
    fps : float
        Displayed frames a second.
    substeps : int
        Steps a displayed frame.
    """
    rig: object
    fps: float
    substeps: int

    def step(self, activations: np.ndarray) -> None:
        """One step of 1 / (fps x substeps) seconds with these activations, (n_muscles,)."""

    def displacement(self) -> np.ndarray:
        """The skin's displacement from rest now, (n, 3)."""

    def run(self, activation_at, duration: float, progress=None) -> np.ndarray:
        """Frames (F, n, 3) of skin positions over `duration` seconds; activation_at(t) ->
        (n_muscles,); progress(frame, n_frames) after each frame."""


def explosion_limit(rest: np.ndarray) -> float:
    """The largest displacement a frame may have: ten times the face's size.

    Parameters
    ----------
    rest : (n, 3) float array

    Returns
    -------
    float
    """
    return 10.0 * float(np.linalg.norm(np.ptp(rest, axis=0)))


def check_frame(u: np.ndarray, limit: float, t: float) -> None:
    """Stop before anything is written when a frame's displacement is not finite or has exploded
    past the limit (an unstable step, or non-finite input).  Two reductions, no temporary: NaN
    propagates through min and max, so one comparison catches both.

    Parameters
    ----------
    u : (n, 3) float array
    limit : float
        explosion_limit's.
    t : float
        The frame's time, for the message.
    """
    lo, hi = float(u.min()), float(u.max())
    if not (-limit <= lo and hi <= limit):
        what = "is not finite" if not (np.isfinite(lo) and np.isfinite(hi)) else "moved beyond ten face sizes"
        raise MimicaError(f"the simulation became unstable at t = {t:.3f} s (the skin {what}); nothing "
                          "was written: use a higher frame rate, or smaller forces")


def run_frames(sim, activation_at, duration: float, progress=None, before_step=None) -> np.ndarray:
    """Frames of skin positions from a simulator; a non-finite activation or an exploded frame stops
    the run (MimicaError) before any frame is handed back.

    Parameters
    ----------
    sim : Engine
        With rig, fps, substeps, step() and displacement().
    activation_at : callable
        activation_at(t) -> (n_muscles,) activations.
    duration : float
        Seconds.
    progress : callable, optional
        Called as progress(done, total) as frames are made.
    before_step : callable, optional
        Called as before_step(t) before each step.

    Returns
    -------
    (F, n, 3) float array
    """
    h = 1.0 / (sim.fps * sim.substeps)
    n_frames = int(round(duration * sim.fps)) + 1
    rest = sim.rig.skin.vertices
    limit = explosion_limit(rest)
    frames = np.empty((n_frames,) + rest.shape)
    frames[0] = rest + sim.displacement()
    for f in range(1, n_frames):
        for k in range(sim.substeps):
            t = ((f - 1) * sim.substeps + k + 1) * h
            if before_step is not None:
                before_step(t)
            a = activation_at(t)
            if not np.isfinite(a).all():
                raise MimicaError(f"the muscle activations at t = {t:.3f} s are not finite; nothing was written")
            sim.step(a)
        u = sim.displacement()
        check_frame(u, limit, f / sim.fps)
        frames[f] = rest + u
        if progress:
            progress(f, n_frames)
    return frames
