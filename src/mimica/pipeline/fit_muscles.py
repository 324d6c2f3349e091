"""Fit a rig's muscles to shapes (physics.fit.MuscleFit): the activations that best make target
shapes of the rig's face, a head's ARKit shapes one by one, or a take's frames through the
face's ARKit shapes, written as a timeline `simulate` plays."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import MimicaError


@dataclass
class FitResult:
    """What `fit_muscles` wrote.

    Attributes
    ----------
    out : Path
        The timeline (.json).
    names : list of str
        The rig's muscles, in the activations' column order.
    activations : (T, m) array
        One row per target shape or take frame.
    misfit : (T,) array
        Each row's misfit, relative to its shape.
    labels : list of str
        The shapes' names (targets' file stems or ARKit names).
    frames : int or None
        A take's frames (None for shapes one after another).
    rate : float or None
        A take's frame rate.
    seconds : dict
        {"fields": making the muscles' fields, "fit": the fit}.
    """
    out: Path
    names: list
    activations: np.ndarray
    misfit: np.ndarray
    labels: list
    frames: int | None
    rate: float | None
    seconds: dict


def sequence_timeline(names, activations: np.ndarray, seconds: float = 1.0):
    """A timeline playing fitted activations one after another: each ramps in over 0.3 s, holds, and
    lets go before the next (the i-th from i x seconds).

    Parameters
    ----------
    names : list of str
        The muscles.
    activations : (T, m) float array
    seconds : float
        Each one's turn.

    Returns
    -------
    anim.Timeline
    """
    from ..anim import Channel, Timeline
    ch = {}
    for j, n in enumerate(names):
        keys = []
        for i, a in enumerate(activations[:, j]):
            t0 = i * seconds
            keys += [[t0, 0.0], [t0 + 0.3 * seconds, a], [t0 + 0.8 * seconds, a], [t0 + 0.95 * seconds, 0.0]]
        if np.abs(activations[:, j]).max() > 0:
            ch[n] = Channel(np.array(keys), "linear")
    return Timeline(ch, seconds * len(activations))


def rig_arkit_shapes(path, rig):
    """The ARKit shapes' displacements on a rig's skin, from a head's ARKit GLB of that face.

    Parameters
    ----------
    path : str or Path
        The GLB (`blendshapes`' of the rig's face).
    rig : Rig

    Returns
    -------
    shapes : list of (n, 3) float arrays
    names : list of str
    """
    from ..export import ARKIT_52
    from ..mesh.io import read_morph_targets
    mesh, targets, _ = read_morph_targets(path)
    n = rig.skin.n_vertices
    if mesh.n_vertices < n or np.abs(mesh.vertices[:n] - rig.skin.vertices).max() > 1e-4 * np.ptp(rig.skin.vertices):
        raise MimicaError(f"{path}: not the ARKit shapes of this rig's face (make them with `blendshapes` of the "
                          "face the rig was made from)")
    labels = [k for k in ARKIT_52 if k in targets]
    return [targets[k][:n] - rig.skin.vertices for k in labels], labels


def fit_muscles(rig, out, targets=None, arkit=None, shapes=None, fps: float | None = None,
                progress=None) -> FitResult:
    """The rig's muscle activations that best make the given shapes, as a timeline.

    Parameters
    ----------
    rig : str or Path or Rig
    out : str or Path
        The timeline to write (.json).
    targets : list of str or Path, optional
        Target shapes: the rig's face deformed (its vertices), fitted one after another.
    arkit : str or Path, optional
        Or a head's ARKit GLB of the rig's face (its shapes fitted one by one), or a take (Live
        Link CSV, weights CSV/JSON) fitted frame by frame through the face's ARKit shapes.
    shapes : str or Path, optional
        With a take: the face's ARKit GLB; None: made once here (export.arkit_blendshapes).
    fps : float, optional
        A take's Timecode rate.
    progress : callable, optional
        Called with one line of text while the ARKit shapes are made.

    Returns
    -------
    FitResult
    """
    from ..anim import Channel, Timeline
    from ..mesh import read_vertices
    from ..physics.fit import MuscleFit
    from ..rig import Rig
    if (targets is None or not len(targets)) == (arkit is None):
        raise MimicaError("fit-muscles: give target shapes or an ARKit take or head (one of them)")
    out = Path(out)
    if out.suffix.lower() != ".json":
        raise MimicaError(f"{out}: the activations are written as a timeline .json (simulate plays it)")
    rig = rig if isinstance(rig, Rig) else Rig.load(rig)
    n = rig.skin.n_vertices
    take = None
    if arkit is None:
        disp = []
        for t in map(Path, targets):
            v = read_vertices(t)
            if len(v) != n:
                raise MimicaError(f"{t}: {len(v)} vertices; the rig's skin has {n} (a target is the rig's face, "
                                  "deformed)")
            disp.append(v - rig.skin.vertices)
        labels = [Path(t).stem for t in targets]
    elif Path(arkit).suffix.lower() in (".glb", ".gltf"):
        disp, labels = rig_arkit_shapes(arkit, rig)
    else:
        from ..export.take import read_take
        take = read_take(arkit, fps=fps)
        if shapes is not None:
            disp, labels = rig_arkit_shapes(shapes, rig)
        else:
            from ..export import ARKIT_52, arkit_blendshapes
            bs = arkit_blendshapes(rig.skin, progress=progress, cut_mouth=False)
            disp, labels = [bs[k][:n] - rig.skin.vertices for k in ARKIT_52], list(ARKIT_52)
    t0 = time.perf_counter()
    mf = MuscleFit.of_rig(rig)
    t1 = time.perf_counter()
    if take is None:
        act, mis = mf.fit(np.stack(disp))
        tl = sequence_timeline(mf.names, act)
    else:
        times, weights, rate = take
        W = np.stack([weights.get(k, np.zeros(len(times))) for k in labels], 1)
        act, mis = mf.fit_combinations(np.stack(disp), W)
        tl = Timeline({nm: Channel(np.stack([times, act[:, j]], 1), "linear") for j, nm in enumerate(mf.names)
                       if np.abs(act[:, j]).max() > 0}, float(times[-1]) if times[-1] > 0 else 1.0)
    t2 = time.perf_counter()
    tl.save(out)
    return FitResult(out, list(mf.names), act, np.asarray(mis), labels, None if take is None else len(take[0]),
                     None if take is None else take[2], {"fields": t1 - t0, "fit": t2 - t1})
