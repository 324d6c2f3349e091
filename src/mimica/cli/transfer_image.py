"""`mimica transfer-image`: move the expression of one photo pair onto another photo (Song §VI)."""

from __future__ import annotations

from pathlib import Path

from ..errors import MimicaError
from ..pipeline.photos import METHODS, PhotoOptions as D
from ..validate import strengths
from ._common import _bar, DETECTOR_HELP, _say


def _strength(text: str):
    """--strength: a number, or regions: '0.5', 'brows=0.5,mouth=1.2', '0,mouth=1'; its regions
    and range checked before the work."""
    from ..image.analogy import point_strengths
    out = strengths(text, "--strength")
    try:
        point_strengths(out)
    except MimicaError as e:
        raise MimicaError(f"--{e}") from None
    return out


def cmd_transfer_image(a):
    """`mimica transfer-image`: a photo pair's expression moved onto other photos
    (pipeline.transfer_photos).

    Parameters
    ----------
    a : argparse.Namespace
        The command's options (its add_args).

    Returns
    -------
    int
        The exit status (0: done).
    """
    from ..pipeline import PhotoOptions, transfer_photos
    if a.driving and a.source_expr:
        raise MimicaError("give either source expression photos or --driving VIDEO, not both")
    if not a.driving and not a.source_expr:
        raise MimicaError("give source expression photos, or --driving VIDEO")
    if a.driving and Path(a.out).suffix.lower() != ".mp4":
        raise MimicaError(f"{a.out}: with --driving the output is a video; name it .mp4")
    opts = PhotoOptions(method=a.method, strength=_strength(a.strength), mouth=not a.no_mouth, head=a.head,
                        detector=a.detector, face=a.face, source_face=a.source_face)
    with _bar("frames") as progress:
        r = transfer_photos(a.source_neutral, a.target, a.out, a.source_expr, a.driving, opts, progress=progress,
                            from_neutral=a.from_neutral)
    if r["kind"] == "video":
        _say(f"{r['count']} frames -> {a.out} ({r['count'] / max(r['transfer_s'], 1e-9):.1f} frames/s, landmarks tracked)")
    else:
        _say(f"{r['count']} expression(s) -> {a.out}/ ({a.method}; points and setup {r['setup_s']:.2f}s, "
             f"transfer {1000 * r['transfer_s'] / r['count']:.0f} ms each); sheet: {r['sheet']}")
    return 0


def add_args(sub) -> None:
    """Put `mimica transfer-image` and its options on the `mimica` parser.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The parser's commands (ArgumentParser.add_subparsers).
    """
    ti = sub.add_parser("transfer-image", help="move the expression of one photo pair onto another photo (Song §VI)",
                        description="Feature points come from PHOTO.landmarks.json beside a photo when present "
                                    "(see `mimica landmarks`), else they are found automatically.")
    ti.add_argument("source_neutral", help="photo of the source person, neutral")
    ti.add_argument("source_expr", nargs="*", help="photos of the same person with expressions")
    ti.add_argument("--driving", metavar="VIDEO", help="a video (MP4) or folder of frames of the source person")
    ti.add_argument("--target", required=True, help="photo of the target person, neutral (or any expression, "
                    "with --from-neutral)")
    ti.add_argument("--from-neutral", metavar="PHOTO",
                    help="a photo of the target person at rest: the target photo may then wear an expression of its "
                         "own, and the result wears the source's expression from that rest instead of added to the "
                         "target's (--method shading or warp)")
    ti.add_argument("--method", choices=list(METHODS), default=D.method,
                    help="shading (default): the expression's shading on a 3D face under the target's own light; "
                         "vtc: Song's vertex-tent luminance transfer (eq. 4); eri: expression ratio images "
                         "(Liu 2001); warp: feature-point warp only")
    ti.add_argument("--strength", default="1", metavar="A",
                    help="how much of the expression: 0 none, 1 the source's (default), up to 2 exaggerated; "
                         "or per region, e.g. brows=0.5,mouth=1.2 (regions: brows, eyes, nose, mouth, jaw, and "
                         "brow_left/_right, eye_left/_right, lip_upper/_lower; "
                         "a leading number sets the others: 0,mouth=1)")
    ti.add_argument("--no-mouth", action="store_true", help="keep the target's own mouth when the source opens "
                    "its mouth (default: the source's teeth and mouth interior, Song's teeth template)")
    ti.add_argument("--head", choices=["still", "follow"], default=D.head,
                    help="still: the target's head stays where it is; follow: it moves as the source's head "
                         "moves between its neutral and each expression (or frame of --driving)")
    ti.add_argument("--face", type=int, default=0, help="the target photo's face (0: the largest; "
                                                        "`mimica landmarks PHOTO --list` numbers them)")
    ti.add_argument("--source-face", type=int, default=0, help="the source photos' (or video's) face, as --face")
    ti.add_argument("--detector", choices=["dlib", "mediapipe"], default=D.detector, help=DETECTOR_HELP)
    ti.add_argument("-o", "--out", required=True, help="output folder (photos), or an .mp4 with --driving")
    ti.set_defaults(func=cmd_transfer_image)


run = cmd_transfer_image
