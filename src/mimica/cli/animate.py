"""`mimica animate`: play an ARKit take (a Live Link Face CSV) on a head's ARKit blendshapes."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import MimicaError
from ..validate import floats
from ._common import _say
from ..pipeline import AnimateOptions as D


def cmd_animate(a):
    """`mimica animate`: an ARKit take (a Live Link Face CSV, or one fitted to a video) played on a
    head's ARKit blendshapes (pipeline.animate).

    Parameters
    ----------
    a : argparse.Namespace
        The command's options (its add_args).

    Returns
    -------
    int
        The exit status (0: done).
    """
    from ..pipeline import AnimateOptions, animate
    opts = AnimateOptions(head_rotation=a.head_rotation, pivot=tuple(floats(a.pivot, 3, "--pivot")) if a.pivot else None,
                          fps=a.fps, rest_frame=a.rest_frame, landmarks=a.landmarks, tracker=a.tracker)
    if (a.arkit is None) == (a.video is None):
        raise MimicaError("animate: give the take as --arkit take.csv or as --video take.mp4 (one of them)")
    if a.preview and a.video is None:
        raise MimicaError("--preview shows the head beside the video it was fitted to: give --video")
    r = animate(a.head, a.out, a.arkit, a.video, opts, progress=_say, preview=a.preview)
    if r.video:
        v = r.video
        if v["landmarks"] == "found":
            _say(f"{a.head}: no landmarks stored in it (another tool's head, or written back by one): its 68 "
                 "found on renders of it; give them with --landmarks where they miss")
        _say(f"{a.video}: {v['frames']} frames tracked ({v['track_fps']:.0f} frames/s) and fitted "
             f"on its points and pixels ({v['fit_fps']:.0f} frames/s); frame {a.rest_frame} taken as the performer's rest; "
             f"points misfit median {v['misfit_median'] * 100:.1f} % of the face's width; "
             + ("the gaze and the tongue stay 0 (unseen)" if any(n.startswith("eyeLook") for n in v["unseen"])
                else "the tongue stays 0 (unseen)"))
        _say(f"{a.video}: what it saw: {_saw(v['saw'])}")
    head_line = _head_line(r)
    _say("".join(f"{a.head}: {note}\n" for note in r.notes)          # what writing the head back did
         + f"{a.video or a.arkit}: {len(r.times)} frames over {r.times[-1]:.2f}s ({r.rate:.3g} fps) drive {r.driven} "
         f"morph targets of {Path(a.head).name}{head_line} -> {r.out}" + (f" (weights: {r.csv})" if r.csv else "")
         + (f"; preview: {r.preview}" if r.preview else ""))
    return 0


def _head_line(r) -> str:
    """How the head moves in the take, as a part of its line."""
    w = r.weights
    if r.pivot is None:
        how = "--head-rotation turns it" if r.out.suffix.lower() == ".glb" else "its turn is in the take"
        return f"; the head stays still ({how})" if "headYaw" in w else ""
    turn = np.degrees(np.abs([w[n] for n in ("headYaw", "headPitch", "headRoll")]).max(1))
    return (f"; the head turns (up to yaw {turn[0]:.0f}, pitch {turn[1]:.0f}, roll {turn[2]:.0f} degrees) "
            f"about ({', '.join(f'{x:.3f}' for x in r.pivot)}) m, "
            + (f"{r.bending} vertices bending with the neck" if r.bending else "whole"))


def _frames(spans) -> str:
    n = sum(b - a + 1 for a, b in spans)
    shown = ", ".join(f"{a}" if a == b else f"{a}-{b}" for a, b in spans[:6]) + (", ..." if len(spans) > 6 else "")
    return f"{n} frame{'s' if n != 1 else ''} ({shown})"


def _saw(saw: dict) -> str:
    """export.video.what_it_saw's report in one line."""
    from ..export.video import HELD_SECONDS, TURN_TRUSTED
    said = [f"no face in {_frames(saw['no_face'])}, fitted to points filled in from their neighbours"
            if saw["no_face"] else "a face in every frame"]
    said.append(f"turned past {TURN_TRUSTED:g} degrees (a turn past it reads as expression) in {_frames(saw['turned'])}, "
                f"at most {saw['turn_max']:.0f}" if saw["turned"] else f"turned at most {saw['turn_max']:.0f} degrees")
    held = [f"{n} {_frames(s)}" for n, s in saw["held"].items()]
    said.append(f"held at full weight for {HELD_SECONDS:g} s or more: {'; '.join(held)}" if held
                else "no weight held at full")
    return "; ".join(said)


def add_args(sub) -> None:
    """Put `mimica animate` and its options on the `mimica` parser.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The parser's commands (ArgumentParser.add_subparsers).
    """
    an = sub.add_parser("animate", help="play an ARKit take (a Live Link Face CSV) on a head's ARKit blendshapes")
    an.add_argument("head", help="the head's ARKit blendshapes, a .glb or .fbx (as `mimica blendshapes` writes it)")
    an.add_argument("--arkit", help="the take: a Live Link Face CSV (Timecode, BlendShapeCount, the "
                                    "52 weights ...), or a CSV or JSON of the 52 weights with a time column")
    an.add_argument("--video", help="or the take as a video (or a folder of frames) of a face: its 68 points are "
                                    "tracked and the 52 weights fitted through the head's blendshapes, written "
                                    "also as a Live Link-style CSV beside --out")
    an.add_argument("--rest-frame", type=int, default=D.rest_frame,
                    help="with --video: a frame where the performer's face is at rest (default: the first)")
    an.add_argument("--landmarks", help="with --video: the head's 68 landmarks (JSON) where its GLB stores none "
                                        "(a head from another tool; default: found on renders of it)")
    an.add_argument("--tracker", choices=["dlib", "mediapipe"], help="with --video: the face's tracker (default "
                    "mediapipe where the photo extra is installed, else dlib)")
    an.add_argument("--fps", type=float, help="the frame rate of a Timecode column (default: from its frame numbers)")
    an.add_argument("--head-rotation", action="store_true",
                    help="also turn the head by the take's HeadYaw, HeadPitch, HeadRoll (radians)")
    an.add_argument("--pivot", help="x,y,z in metres, in the GLB's frame: the point the head turns about "
                                    "(default: the one `blendshapes` placed from the landmarks, with the neck "
                                    "bending below the chin)")
    an.add_argument("--preview", help="with --video: preview.mp4, the video beside the head playing the fitted weights")
    an.add_argument("-o", "--out", required=True, help="take.glb (take.fbx for an FBX head): the head with the take as "
                    "an animation (or take.usd / .usda / .usdc: its blend shapes and a SkelAnimation)")
    an.set_defaults(func=cmd_animate)


run = cmd_animate
