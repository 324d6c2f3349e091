"""Simulate a rig (Kim 2020; Viaud and Yahia 1992): a timeline of its muscles (a preset, one of
the facial actions, or a file), run by an engine, the wrinkle layer on top, written as frames,
one clip, a strip of pictures and, if asked, the wrinkles' maps."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import MimicaError

ENGINES = ("shell", "sprung")
SOLVERS = ("modal", "full")
SPRINGS = ("linear", "kim")
MAPS_SETS = ("peak", "frames", "engine")


@dataclass(frozen=True)
class SimulateOptions:
    """How a rig is simulated; each default is the one every user of it gets.

    Attributes
    ----------
    expression : str
        A preset (neutral, happiness, sadness, surprise, anger, disgust, fear), used where
        neither `timeline` nor `action` is given.
    timeline : str or Path or None
        A timeline file of the muscles' activation curves (and "age", "gravity", "pull").
    action : str or None
        One of the 28 facial actions, e.g. "AU12_lip_corner_puller".
    duration : float or None
        Seconds; None: the timeline's, else 2.
    fps : float
        Frames a second.
    gravity : float
        Downward acceleration on the skin (0: off; a timeline's "gravity" channel scales it).
    pulls : tuple of (centre (3,), radius, force (3,))
        Forces on the skin within a radius of a point (a timeline's "pull" channel scales them).
    engine : str
        "shell" (Kim 2020's shells in modal coordinates) or "sprung" (Viaud and Yahia's force
        fields).
    solver : str
        "modal" (one modal system per force, real time) or "full" (the whole skin as one
        nonlinear shell: implicit Euler and projected Newton).
    warp : bool or None
        Modal warping (Kim eq. 10); None: on with the modal solver.
    springs : str
        The muscle-to-skin springs: "linear" or "kim" (Kim eq. 15, linearized each step).
    wrinkles : str or Path or None
        A wrinkle mask of the rig's face: bulges follow the skin's compression and the age.
    age : float
        Years, for the wrinkles (a timeline's "age" channel overrides it).
    refine : bool
        Refine the mesh along the wrinkles.
    maps : int or None
        Also bake displacement and normal maps of this size (pixels).
    maps_set : str
        "peak" (the most compressed frame's maps), "frames" (every frame's) or "engine" (per
        wrinkle region, as game engines blend wrinkle maps).
    """
    expression: str = "happiness"
    timeline: str | Path | None = None
    action: str | None = None
    duration: float | None = None
    fps: float = 60.0
    gravity: float = 0.0
    pulls: tuple = ()
    engine: str = "shell"
    solver: str = "modal"
    warp: bool | None = None
    springs: str = "linear"
    wrinkles: str | Path | None = None
    age: float = 50.0
    refine: bool = True
    maps: int | None = None
    maps_set: str = "peak"


@dataclass
class SimulateResult:
    """What `simulate` made.

    Attributes
    ----------
    out : Path
        The folder written: frame_*.obj, animation.glb, strip.png (and the wrinkles' maps).
    frames : int
        How many frames.
    steps : int
        Solver steps taken.
    seconds : float
        Wall time of the simulation (writing left out).
    clip : dict
        export.clip.write_clip's figures for animation.glb.
    wrinkles : dict or None
        The wrinkle layer's figures: {"names", "nodes", "build_s", "frame_s", "peak" (frame),
        "compression" (the peak frame's per wrinkle), "maps" ("peak", "frames", "engine" or None),
        "regions" (engine maps)}.
    newton : dict or None
        The full solver's {"iterations", "steps", "unconverged"}.
    """
    out: Path
    frames: int
    steps: int
    seconds: float
    clip: dict = field(default_factory=dict)
    wrinkles: dict | None = None
    newton: dict | None = None


def _check(o: SimulateOptions, tl_channels) -> None:
    for name, value, allowed in (("engine", o.engine, ENGINES), ("solver", o.solver, SOLVERS),
                                 ("springs", o.springs, SPRINGS), ("maps_set", o.maps_set, MAPS_SETS)):
        if value not in allowed:
            raise MimicaError(f"simulate: {name} {value!r}: one of {', '.join(allowed)}")
    if o.timeline is not None and o.action is not None:
        raise MimicaError("simulate: a timeline or an action, not both")
    forces = o.gravity or o.pulls
    if o.engine == "sprung" and (forces or o.solver == "full" or o.springs != "linear"):
        raise MimicaError("gravity, pulls, Kim's springs and the full solver work with the shell engine only")
    if o.solver == "full" and (forces or o.warp is not None or o.springs != "linear"
                               or {"gravity", "pull"} & set(tl_channels)):
        raise MimicaError("the full solver simulates the muscles only; gravity, pulls, warping and Kim's "
                          "springs work with the modal solver")


def timeline_for(rig, o: SimulateOptions):
    """The timeline the options name on this rig: their action, timeline file or preset.

    Parameters
    ----------
    rig : Rig
        The rig it drives (its muscles' names are the channels a file may use).
    o : SimulateOptions

    Returns
    -------
    timeline : anim.Timeline
    duration : float
        Seconds to simulate: the options' duration, else the file's, else 2.
    """
    from ..anim import Timeline
    names = [m.name for m in rig.muscles]
    if o.action:
        duration = o.duration or 2.0
        return Timeline.action(o.action, names, duration), duration
    if o.timeline is not None:
        tl = Timeline.load(o.timeline)
        unknown = sorted(set(tl.channels) - set(names) - {"age", "gravity", "pull"})
        if unknown:
            raise MimicaError(f"{o.timeline}: channel {unknown[0]!r} is not a muscle of this rig "
                              f"(muscles: {', '.join(names)})")
        return tl, o.duration or tl.duration
    return Timeline.preset(o.expression, names, duration=o.duration or 2.0), o.duration or 2.0


def engine_name(o: SimulateOptions) -> str:
    """The physics engine the options choose.

    Parameters
    ----------
    o : SimulateOptions

    Returns
    -------
    str
        "modal", "full" or "sprung" (physics.make_engine's names).
    """
    return "sprung" if o.engine == "sprung" else "full" if o.solver == "full" else "modal"


def engine_for(rig, o: SimulateOptions, tl):
    """The simulator the options name, its forces set (gravity, pulls).

    Parameters
    ----------
    rig : Rig
        The rig, precomputed (physics.precompute).
    o : SimulateOptions
    tl : anim.Timeline
        The timeline it will play (a gravity channel turns gravity on).

    Returns
    -------
    physics.Engine
        From physics.make_engine: step, displacement, run.
    """
    from ..physics import make_engine
    name = engine_name(o)
    if name != "modal":
        return make_engine(name, rig, o.fps)
    sim = make_engine(name, rig, o.fps, warp=o.warp, springs=o.springs)
    if o.gravity or "gravity" in tl.channels:
        sim.set_gravity(np.array([0.0, -(o.gravity or 1.0), 0.0]))
    for center, radius, force in o.pulls:
        sim.add_pull(np.asarray(center, float), float(radius), np.asarray(force, float))
    return sim


def simulate(rig, out, options: SimulateOptions | None = None, progress=None) -> SimulateResult:
    """Simulate a rig and write the result into the folder `out` (whole, or not at all).

    Parameters
    ----------
    rig : str or Path or Rig
        A rig (pipeline.make_rig, `Rig.load`).
    out : str or Path
        The output folder.
    options : SimulateOptions, optional
    progress : callable, optional
        Called as progress(frame, n_frames) while simulating.

    Returns
    -------
    SimulateResult
    """
    from ..outputs import check_output_dir, staged_dir
    from ..rig import Rig
    o = options or SimulateOptions()
    _check(o, ())                                    # the options alone: before anything is read
    check_output_dir(out)
    what = "the rig's face" if isinstance(rig, Rig) else str(rig)
    rig = rig if isinstance(rig, Rig) else Rig.load(rig)
    mask = None
    if o.wrinkles is not None:                       # the mask checked on this face before the work
        from ..wrinkles import mask_on
        if o.maps and rig.skin.uv is None:
            raise MimicaError("wrinkle maps: the rig's skin has no texture coordinates; rebuild the rig from a "
                              "mesh with uv")
        mask = mask_on(o.wrinkles, rig.skin, what)
    tl, duration = timeline_for(rig, o)
    _check(o, tl.channels)
    sim = engine_for(rig, o, tl)
    names = [m.name for m in rig.muscles]
    run_kw = {}
    if o.engine == "shell" and ({"gravity", "pull"} & set(tl.channels)):
        def scales(t):
            g = float(tl.channels["gravity"](t)) if "gravity" in tl.channels else 1.0
            p = float(tl.channels["pull"](t)) if "pull" in tl.channels else 1.0
            return g, p
        run_kw["scales_at"] = scales
    t0 = time.perf_counter()
    frames = sim.run(lambda t: tl.values(t, names), duration, progress=progress, **run_kw)
    el = time.perf_counter() - t0
    res = SimulateResult(Path(out), len(frames), (len(frames) - 1) * sim.substeps, el)
    with staged_dir(out, {"command": "simulate"}) as d:
        _write(o, rig, tl, sim, frames, d, mask, res)
    return res


def _write(o, rig, tl, sim, frames, d: Path, mask, res: SimulateResult) -> None:
    """frame_*.obj, animation.glb, strip.png (and the wrinkle maps) into the stage `d`."""
    from ..export.clip import write_clip
    from ..mesh import write_mesh
    from ..render import contact_sheet, render_mesh, save_png, shared_frame
    skin = rig.skin
    if mask is not None:
        frames, skin, res.wrinkles = _wrinkle_frames(o, rig, tl, frames, d, mask)
    for i, v in enumerate(frames):
        write_mesh(d / f"frame_{i:04d}.obj", skin.with_vertices(v))
    res.clip = write_clip(d / "animation.glb", skin, [f"frame_{i:04d}" for i in range(len(frames))],
                          np.asarray(frames), o.fps)
    title = o.action or (Path(o.timeline).name if o.timeline is not None else o.expression)
    if mask is not None:
        title += f", wrinkles, age {o.age:g}" if "age" not in tl.channels else ", wrinkles, age curve"
    pick = np.linspace(0, len(frames) - 1, min(6, len(frames))).round().astype(int)
    frame = shared_frame([frames[i] for i in pick])
    tiles = [render_mesh(skin, frames[i], size=(320, 320), frame=frame) for i in pick]
    save_png(d / "strip.png", contact_sheet(tiles, [f"t = {i / o.fps:.2f}s" for i in pick],
                                            title=f"{title} ({o.engine}{', full solver' if o.solver == 'full' else ''})"))
    if o.solver == "full":
        res.newton = dict(sim.solver.stats)


def _wrinkle_frames(o, rig, tl, frames, d: Path, mask):
    """The wrinkle layer on the frames and the maps asked for: (frames, mesh, figures)."""
    from ..wrinkles import wrinkle_frames
    ages = tl.channels["age"](np.arange(len(frames)) / o.fps) if "age" in tl.channels else o.age
    names = [m.name for m in rig.muscles]
    # each wrinkle deepened by the muscles its mask names, at their activations frame by frame
    acts = [dict(zip(names, tl.values(f / o.fps, names))) for f in range(len(frames))]
    w = wrinkle_frames(rig.skin, mask, frames, ages, refine=o.refine, activations=acts)
    peak = w.peak
    fig = {"names": w.skin.layer.mask.names(), "nodes": w.skin.mesh.n_vertices, "build_s": w.build_s,
           "frame_s": w.frame_s, "peak": int(peak), "compression": np.asarray(w.compression[peak]),
           "maps": None, "regions": 0}
    if o.maps and o.maps_set == "engine":
        from ..wrinkles.maps import engine_maps
        fig["regions"] = len(engine_maps(w.skin.layer, rig.skin, w.carried, w.ages, w.emphasis, o.maps,
                                         d / "wrinkle_maps"))
        fig["maps"] = "engine"
    elif o.maps:
        from ..wrinkles.maps import bake, save_maps
        for f in range(len(frames)) if o.maps_set == "frames" else [peak]:
            h, n = bake(w.skin.layer, rig.skin, w.carried[f], float(w.ages[f]), o.maps, w.emphasis[f])
            save_maps(d / f"wrinkles_frame_{f:04d}", h, n)
        fig["maps"] = o.maps_set
    return w.frames, w.skin.mesh, fig
