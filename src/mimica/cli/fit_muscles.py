"""`mimica fit-muscles`: the muscle activations that best make target shapes or an ARKit take, as a timeline simulate plays."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import MimicaError
from ._common import _say


def cmd_fit_muscles(a):
    """`mimica fit-muscles`: the muscle activations that best make target shapes or an ARKit take
    (pipeline.fit_muscles).

    Parameters
    ----------
    a : argparse.Namespace
        The command's options (its add_args).

    Returns
    -------
    int
        The exit status (0: done).
    """
    from ..pipeline import fit_muscles
    if bool(a.target) == bool(a.arkit):
        raise MimicaError("fit-muscles: give --target EXPR.obj ... or --arkit (a take CSV/JSON or a head's ARKit GLB)")
    if a.arkit and not a.shapes and Path(a.arkit).suffix.lower() not in (".glb", ".gltf"):
        _say(f"the ARKit shapes of {a.rig}'s face (once; --shapes HEAD_ARKIT.glb gives them)")
    r = fit_muscles(a.rig, a.out, a.target, a.arkit, a.shapes, a.fps, progress=_say)
    if r.frames is None:
        what = (f"{len(r.labels)} target{'s' * (len(r.labels) > 1)} one after another, 1 s each ("
                + ", ".join(f"{lab} {m:.0%}" for lab, m in list(zip(r.labels, r.misfit))[:6])
                + (" ..." if len(r.labels) > 6 else "") + " misfit)")
    else:
        what = f"a take of {r.frames} frames ({r.rate:.3g} fps), median misfit {np.median(r.misfit):.0%}"
    _say(f"{r.out}: {len(r.names)} muscles fitted to {what}; fields {r.seconds['fields']:.1f}s, fit "
         f"{len(r.activations) / max(r.seconds['fit'], 1e-9):.0f} frames/s; `simulate {a.rig} --timeline {r.out}` "
         "plays it")
    return 0


def add_args(sub) -> None:
    """Put `mimica fit-muscles` and its options on the `mimica` parser.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The parser's commands (ArgumentParser.add_subparsers).
    """
    fm = sub.add_parser("fit-muscles", help="the muscle activations that best make target shapes or an ARKit "
                                            "take, as a timeline simulate plays")
    fm.add_argument("rig", help="rig file from `mimica rig`")
    fm.add_argument("--target", nargs="+", help="target shapes: the rig's face deformed (same vertices)")
    fm.add_argument("--arkit", help="a take (Live Link CSV, weights CSV/JSON): its frames fitted through the "
                                    "face's ARKit shapes; or a head's ARKit GLB: its 52 shapes fitted one by one")
    fm.add_argument("--shapes", help="with a take: the face's ARKit shapes (HEAD_ARKIT.glb from `blendshapes`; "
                                     "else made once here)")
    fm.add_argument("--fps", type=float, help="the frame rate of a take's Timecode column")
    fm.add_argument("-o", "--out", required=True, help="activations.json: a timeline of the muscles' activations")
    fm.set_defaults(func=cmd_fit_muscles)


run = cmd_fit_muscles
