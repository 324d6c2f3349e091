"""`mimica simulate`: animate a rig by its muscles."""

from __future__ import annotations

import argparse

import numpy as np

from ..errors import MimicaError
from ..validate import pull
from ._common import _bar, _clip_how, _say
from ..pipeline.simulate import SimulateOptions as D, ENGINES, MAPS_SETS, SOLVERS, SPRINGS


def cmd_simulate(a):
    """`mimica simulate`: a rig animated by its muscles (pipeline.simulate).

    Parameters
    ----------
    a : argparse.Namespace
        The command's options (its add_args).

    Returns
    -------
    int
        The exit status (0: done).
    """
    from ..pipeline import SimulateOptions, simulate
    opts = SimulateOptions(expression=a.expression, timeline=a.timeline, action=a.action, duration=a.duration,
                           fps=a.fps, gravity=a.gravity, pulls=tuple(pull(p, "--pull") for p in a.pull or []),
                           engine=a.engine, solver=a.solver, warp=a.warp, springs=a.springs, wrinkles=a.wrinkles,
                           age=a.age, refine=not a.no_refine, maps=a.maps, maps_set=a.maps_set)
    if a.maps and not a.wrinkles:
        raise MimicaError("--maps: the maps are the wrinkles'; give the wrinkle mask (--wrinkles MASK)")
    with _bar("simulating") as progress:
        r = simulate(a.rig, a.out, opts, progress=progress)
    _say(f"{r.frames} frames -> {r.out}/ (frame_*.obj, animation.glb, strip.png); {r.steps} steps in {r.seconds:.2f}s"
         + _note(r, a.fps))
    return 0


def _note(r, fps: float) -> str:
    """The wrinkles, the clip and the Newton steps of a simulation, as the tail of its line."""
    out, note = r.out, ""
    if r.wrinkles is not None:
        w = r.wrinkles
        most = np.argsort(w["compression"])[:3]
        maps = {"engine": f"; engine maps of {w['regions']} regions (normal, displacement, mask, per-frame weights) "
                          f"-> {out}/wrinkle_maps/",
                "frames": f"; maps of every frame -> {out}/wrinkles_frame_*",
                "peak": f"; maps of that frame -> {out}/wrinkles_frame_{w['peak']:04d}_*", None: ""}[w["maps"]]
        note += (f"; wrinkles: {len(w['names'])} on {w['nodes']} nodes (built in {w['build_s']:.1f}s), "
                 f"{1000 * w['frame_s']:.2f} ms/frame; most compressed at t={w['peak'] / fps:.2f}s: "
                 + ", ".join(f"{w['names'][i]} {w['compression'][i]:.2f}" for i in most) + maps)
    note += "; animation.glb: " + _clip_how(r.clip)
    if (st := r.newton) is not None:
        note += f"; Newton: {st['iterations'] / max(st['steps'], 1):.1f} iterations a step"
        if st["unconverged"]:
            note += f", {st['unconverged']} steps stopped at the iteration cap"
    return note


def _wrinkle_args(s) -> None:
    """The wrinkle layer's options."""
    s.add_argument("--wrinkles", metavar="MASK", help="wrinkle mask of this face (`mimica wrinkle-mask`): "
                   "bulges follow the skin's compression and the age")
    s.add_argument("--age", type=float, default=D.age, help="age in years for the wrinkles (a timeline's "
                   "'age' channel overrides it)")
    s.add_argument("--no-refine", action="store_true", help="keep the rig's mesh (no refinement along wrinkles)")
    s.add_argument("--maps", type=int, nargs="?", const=1024, metavar="SIZE",
                   help="also write displacement and normal maps (SIZE px, default 1024) of the most "
                        "compressed frame (or as --maps-set says)")
    s.add_argument("--maps-set", choices=list(MAPS_SETS), default=D.maps_set,
                   help="peak: the most compressed frame's maps; frames: every frame's; engine: per wrinkle "
                        "region a normal and displacement map, a mask and per-frame weights (weights.csv), as "
                        "game engines blend wrinkle maps")


def add_args(sub) -> None:
    """Put `mimica simulate` and its options on the `mimica` parser.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The parser's commands (ArgumentParser.add_subparsers).
    """
    s = sub.add_parser("simulate", help="animate a rig by its muscles")
    s.add_argument("rig", help="rig file from `mimica rig`")
    g = s.add_mutually_exclusive_group()
    g.add_argument("--expression", default=D.expression, help="a preset: neutral, happiness, sadness, "
                   "surprise, anger, disgust, fear")
    g.add_argument("--timeline", help="timeline JSON of muscle activation curves")
    g.add_argument("--action", help="one of the 28 facial actions, e.g. AU12_lip_corner_puller")
    s.add_argument("--duration", type=float, help="seconds (default: the timeline's, or 2)")
    s.add_argument("--fps", type=float, default=D.fps)
    s.add_argument("--gravity", type=float, default=D.gravity, help="downward acceleration on the skin (0: off; "
                   "a timeline's 'gravity' channel scales it)")
    s.add_argument("--pull", action="append", metavar="X,Y,Z:R:FX,FY,FZ",
                   help="pull the skin within R of a point with a force (repeatable; a timeline's "
                        "'pull' channel scales all pulls)")
    s.add_argument("--engine", choices=list(ENGINES), default=D.engine,
                   help="shell: Kim 2020 shells in modal coordinates; sprung: Viaud & Yahia 1992 force fields")
    s.add_argument("--solver", choices=list(SOLVERS), default=D.solver,
                   help="modal: Kim's modal systems, one per force (real time); full: the whole skin as one "
                        "nonlinear shell, implicit Euler + projected Newton (folds where the skin "
                        "compresses; 0.3-3 s a frame)")
    s.add_argument("--warp", action=argparse.BooleanOptionalAction, default=D.warp,
                   help="modal warping (Kim eq. 10: forces into each node's frame, displacements out of "
                        "it), on by default with the modal solver; --no-warp: the linear modal face, "
                        "twice the output rate")
    s.add_argument("--springs", choices=list(SPRINGS), default=D.springs,
                   help="the muscle-to-skin springs: linear, k (u_m - u_s) (default); kim: Kim's eq. 15 "
                        "(relative elongation) along the spring's deformation, linearized each step "
                        "(docs/benchmarks.md)")
    _wrinkle_args(s)
    s.add_argument("-o", "--out", required=True, help="output folder")
    s.set_defaults(func=cmd_simulate)


run = cmd_simulate
