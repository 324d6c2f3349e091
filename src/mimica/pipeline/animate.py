"""Play a take on a head with ARKit blendshapes: the take's weights from a file (Live Link Face
CSV, weights CSV or JSON: export.take) or fitted to a video through the head's own shapes
(export.video), written as an animated GLB or FBX (the head's own file, its weights keyed) or
USD."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import MimicaError

HEAD_ANGLES = ("headYaw", "headPitch", "headRoll")


@dataclass(frozen=True)
class AnimateOptions:
    """How a take is played; each default is the one every user of it gets.

    Attributes
    ----------
    head_rotation : bool
        Also turn the head by the take's head angles (a GLB written from an OBJ head only).
    pivot : tuple of 3 float or None
        Where the head turns, metres in the file's frame; None: the one `blendshapes` stored.
    fps : float or None
        The rate of a take's Timecode column (None: read from the take).
    rest_frame : int
        A video's frame taken as the performer's rest face.
    landmarks : str or Path or None
        With a video: the head's 68 landmarks (a JSON file) where its GLB stores none (a head
        from another tool, or written back by a DCC); None: found as for any head.
    tracker : str or None
        With a video: "dlib" or "mediapipe" (export.video.track_video); None: the default
        (export.video.trackers()).
    """
    head_rotation: bool = False
    pivot: tuple | None = None
    fps: float | None = None
    rest_frame: int = 0
    landmarks: str | Path | None = None
    tracker: str | None = None


@dataclass
class AnimateResult:
    """What `animate` wrote.

    Attributes
    ----------
    out : Path
        The animated file.
    times : (F,) array
        The take's times in seconds.
    rate : float
        Its frame rate.
    weights : dict
        {ARKit name or head angle: (F,) weights}.
    driven : int
        The head's morph targets the take drives.
    pivot : list or None
        Where the head turns (metres), when it does.
    bending : int
        Vertices bending with the neck.
    csv : Path or None
        A video's weights as a Live Link Face CSV, beside `out`.
    video : dict
        A video's figures: {"frames", "track_fps", "fit_fps", "misfit_median" (of the face's width),
        "unseen" (the names of the shapes the tracker cannot see), "saw" (export.video.what_it_saw:
        frames without a face, turned past what the fit trusts, weights held at 1), "fit" (the
        VideoFit), "landmarks" (where the head's came from)}.
    preview : Path or None
        The video beside the head playing its weights, where asked for.
    notes : list of str
        What a user should know of the head as written back (export.take.animate_glb).
    """
    out: Path
    times: np.ndarray
    rate: float
    weights: dict
    driven: int
    pivot: list | None
    bending: int
    csv: Path | None = None
    video: dict = field(default_factory=dict)
    preview: Path | None = None
    notes: list = field(default_factory=list)


def _check(head: Path, out: Path, take, video, o: AnimateOptions) -> str:
    """What `out` is ("glb", "usd" or "fbx"), or one line for a request that cannot be met."""
    from ..export.usd import USD_SUFFIXES
    kind = "usd" if out.suffix.lower() in USD_SUFFIXES else out.suffix.lower().lstrip(".")
    fbx_head = head.suffix.lower() == ".fbx"
    if kind not in ("glb", "usd", "fbx"):
        raise MimicaError(f"{out}: an animated take is written as .glb, .fbx or USD ({', '.join(USD_SUFFIXES)})")
    if kind != "glb" and o.head_rotation:
        raise MimicaError(f"{out}: the head's rotation is written to .glb only (USD and FBX get the blend shapes' "
                          "weights)")
    if not head.is_file():
        raise MimicaError(f"{head}: no such file")
    if head.suffix.lower() not in (".glb", ".gltf", ".fbx"):
        raise MimicaError(f"{head}: a take plays on a glTF or FBX head with ARKit blend shapes; make one with "
                          f"`mimica blendshapes {head.name} --out {head.stem}_arkit.glb`")
    if kind == "glb" and fbx_head:
        raise MimicaError(f"{out}: a take on an FBX head is written as .fbx (the head's own file, its shape keys "
                          "keyed) or USD")
    if kind == "fbx" and not fbx_head:
        raise MimicaError(f"{out}: a take on a glTF head is written as .glb (the head's own file, its morph targets "
                          "keyed) or USD")
    if (take is None) == (video is None):
        raise MimicaError("animate: give the take as a take file or as a video (one of them)")
    if o.landmarks is not None and video is None:
        raise MimicaError(f"{o.landmarks}: the head's landmarks place the points a video is fitted at; give a video")
    if o.tracker is not None and video is None:
        raise MimicaError(f"tracker {o.tracker!r}: a tracker follows the face through a video; give a video")
    return kind


def weights_from_video(head, video, rest_frame: int = 0, progress=None, tracker: str | None = None,
                       landmarks=None, read=None):
    """A video fitted through the head's blendshapes (export.video): the face's 68 points tracked
    (export.video.track_video: dlib's, or MediaPipe's face mesh), the ARKit weights and the
    head's angles fitted a frame, the weights refined on the frames' pixels (export.photometric).

    Parameters
    ----------
    head : str or Path
        A GLB (or FBX) with the 52 ARKit morph targets (`blendshapes` writes one, its landmarks
        stored in a GLB).
    video : str or Path
        A video or a folder of frames.
    rest_frame : int
        The frame showing the performer at rest.
    progress : callable, optional
        Called with a line of text as frames are tracked and refined.
    tracker : str or None
        "dlib" or "mediapipe" (None: the default, export.video.trackers()).
    landmarks : str or Path or None
        The head's landmarks where its GLB stores none (export.video.landmark_basis).
    read : tuple or None
        The head as mesh.io.read_morph_targets read it, where the caller has it.

    Returns
    -------
    times : (F,) float array
    weights : dict
        {ARKit name, headYaw, headPitch, headRoll: (F,) float array}.
    fps : float
    figures : dict
        {"frames", "track_fps", "fit_fps", "misfit_median" (face widths), "unseen": the names of
        the shapes the tracker cannot see (the tongue; the gaze too through dlib's points), "saw":
        export.video.what_it_saw's report, "fit": the VideoFit}.
    """
    from ..export import ARKIT_52
    from ..export.video import fit_take, landmark_basis, track_video, what_it_saw
    basis = landmark_basis(head, landmarks, read)
    t0 = time.perf_counter()
    tracked = track_video(video, progress=progress, tracker=tracker)
    fps, n = tracked.fps, len(tracked.points)
    t1 = time.perf_counter()
    fit = fit_take(tracked, basis, rest_frame=rest_frame, video=video, progress=progress)
    t2 = time.perf_counter()
    weights = {name: fit.weights[:, j] for j, name in enumerate(ARKIT_52)}
    weights.update(zip(HEAD_ANGLES, fit.angles.T))
    figures = {"frames": n, "track_fps": n / max(t1 - t0, 1e-9),
               "fit_fps": n / max(t2 - t1, 1e-9), "misfit_median": float(np.median(fit.residual)),
               "unseen": list(fit.unseen), "saw": what_it_saw(fit, fps), "fit": fit,
               "landmarks": basis.landmarks}
    return np.arange(n) / fps, weights, fps, figures


def take_usd(head: Path, out, times, weights: dict, rate: float, read=None) -> dict:
    """The take as USD: the head's blend shapes (read from its GLB) and a SkelAnimation of their
    weights, resampled on the take's own rate (USD keys whole time codes).

    Parameters
    ----------
    head : Path
        The head's GLB.
    out : str or Path
        The .usd/.usda/.usdc to write.
    times : (F,) float array
    weights : dict
        {ARKit name: (F,) float array}; the head's targets named as other tools name them
        are played too (facts.arkit_targets).
    rate : float
        Frames a second.
    read : tuple or None
        The head as mesh.io.read_morph_targets read it, where the caller has it.

    Returns
    -------
    dict
        {"driven": targets the take drives, "pivot": None, "bending": 0}.
    """
    from ..facts import arkit_targets
    from ..export.usd import write_usd
    from ..mesh.io import read_morph_targets
    mesh, targets, unit = read_morph_targets(head) if read is None else read
    plays = {n: a for a, n in arkit_targets(targets).items() if a in weights}   # the head's names kept
    names = [n for n in targets if n in plays]
    if not names:
        raise MimicaError(f"{head}: none of its morph targets is an ARKit shape")
    rate = rate if rate and rate > 0 else 30.0
    grid = np.arange(int(np.floor(times[-1] * rate + 1e-6)) + 1) / rate
    w = np.stack([np.interp(grid, times, weights[plays[n]]) for n in names], 1)
    write_usd(out, mesh, {n: targets[n] for n in names}, w, rate, unit)
    return {"driven": len(names), "pivot": None, "bending": 0}


def animate(head, out, take=None, video=None, options: AnimateOptions | None = None, progress=None,
            preview=None) -> AnimateResult:
    """Play a take (a file) or a video's performance on a head's ARKit blendshapes.

    Parameters
    ----------
    head : str or Path
        The head's GLB/glTF with ARKit morph targets, or its FBX with ARKit shape keys
        (`blendshapes` writes either; other tools' too).
    out : str or Path
        .glb from a glTF head, .fbx from an FBX head (the head's own file with its weights
        keyed), or USD (.usd, .usda, .usdc) from either.
    take : str or Path, optional
        A Live Link Face CSV, or weights as CSV/JSON (export.take.read_take).
    video : str or Path, optional
        Or a video (or a folder of frames) of a face; its weights also go to a Live Link Face CSV
        beside `out`.
    options : AnimateOptions, optional
    progress : callable, optional
        Called with one line of text while a video is read.
    preview : str or Path, optional
        With a video: an MP4 of the video beside the head playing its fitted weights.

    Returns
    -------
    AnimateResult
    """
    from ..export import ARKIT_52
    from ..export.take import animate_fbx, animate_glb, read_take
    from ..mesh import atomic_path
    o = options or AnimateOptions()
    head, out = Path(head), Path(out)
    kind = _check(head, out, take, video, o)
    if preview is not None:
        preview = Path(preview)
        if video is None:
            raise MimicaError(f"{preview}: a preview shows the head beside the video it was fitted to; give a video")
        if preview.suffix.lower() != ".mp4":
            raise MimicaError(f"{preview}: a preview is written as .mp4")
    csv_out, figures = None, {}
    # the head read once for what reads it (the video's basis, the preview, USD): an FBX is read
    # through Blender, seconds a time
    from ..mesh.io import read_morph_targets
    read = read_morph_targets(head) if video is not None or kind == "usd" else None
    if video is not None:
        times, weights, rate, figures = weights_from_video(head, video, o.rest_frame, progress, o.tracker,
                                                           landmarks=o.landmarks, read=read)
        csv_out = out.with_suffix(".csv")
    else:
        times, weights, rate = read_take(take, fps=o.fps)

    def video_outputs():                        # the CSV and the preview, beside the animation
        if csv_out is not None:
            from ..export.video import write_live_link_csv, write_preview
            write_live_link_csv(csv_out, times, np.stack([weights[n] for n in ARKIT_52], 1), rate,
                                np.stack([weights[n] for n in HEAD_ANGLES], 1))
            if preview is not None:
                try:
                    fit = figures["fit"]
                    write_preview(preview, video, head, fit.weights, fit.rotations, rate, fit.missing,
                                  progress=progress, read=read)
                except BaseException:
                    csv_out.unlink(missing_ok=True)
                    raise
    if kind == "usd":                           # write_usd is atomic by itself (its suffix names its format)
        info = take_usd(head, out, times, weights, rate, read)
        try:
            video_outputs()
        except BaseException:
            out.unlink(missing_ok=True)
            raise
    else:
        with atomic_path(out) as tmp:
            if kind == "fbx":
                info = animate_fbx(head, tmp, times, weights, rate)
            else:
                info = animate_glb(head, tmp, times, weights, head_rotation=o.head_rotation,
                                   pivot=None if o.pivot is None else list(o.pivot))
            video_outputs()                     # inside: a failure leaves none of them
    return AnimateResult(out, times, rate, weights, info["driven"], info["pivot"], info["bending"], csv_out, figures,
                         preview, info.get("notes", []))
