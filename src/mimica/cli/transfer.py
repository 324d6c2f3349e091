"""`mimica transfer`: move expressions of a source face onto a target face (Song et al.)."""

from __future__ import annotations

from pathlib import Path

from ..errors import MimicaError
from ._common import _say, _expand_frames
from ._heads import _correspondence_line, _head_options, _say_uncut_mouth, _warn_sealed_eyes
from ..pipeline import TransferOptions as D


def cmd_transfer(a):
    """`mimica transfer`: a source face's expressions moved onto a target face
    (pipeline.transfer_sequence).

    Parameters
    ----------
    a : argparse.Namespace
        The command's options (its add_args).

    Returns
    -------
    int
        The exit status (0: done).
    """
    from ..errors import NeedsLandmarks
    from ..pipeline import TransferOptions, transfer_sequence
    opts = TransferOptions(method=a.method, match=a.match, cut_mouth=a.cut_mouth == "auto",
                           cut_eyes=a.cut_eyes == "auto")
    try:
        r = transfer_sequence(a.source_neutral, _expand_frames(a.source_expr), a.target, a.out, opts,
                              a.source_landmarks, a.target_landmarks, progress=_say)
    except NeedsLandmarks as e:
        raise MimicaError(f"{e}; pass it with --{e.which}-landmarks FILE") from None
    _report(a, r)
    return 0


def _report(a, r) -> None:
    """What a transfer did, said: cuts, the basis, the layout kept, the picture, the timings."""
    from ..mesh.io import GltfLayout
    xfer, sec, n = r.transfer, r.seconds, len(r.files)
    if xfer.mouth is not None:
        _say(f"{a.target}: the lips were sealed; cut apart along {len(xfer.mouth.seam)} vertices, "
             f"{len(xfer.mouth.copies_of)} added after the target's own (--cut-mouth off to keep them sealed)")
    _say_uncut_mouth(xfer, a.target, "--target-landmarks")
    _warn_sealed_eyes(xfer, r.target, r.target_landmarks, a.target,
                      found_flag="--target-landmarks" if r.target_landmarks_found else None)
    rep = xfer.basis_report
    if rep["used"]:
        _say(f"{n} frames through a basis of their motion ({rep['deviation']:.1e} of the motion off on "
             f"{rep['checked']} frames solved one by one)")
    elif "why" in rep and rep["why"] != "frame by frame":
        _say(f"{n} frames one by one: {rep['why']}")
    if isinstance(r.target.layout, GltfLayout):
        _say(f"results written as {Path(a.target).name} with the expression: its nodes, materials and vertex "
             f"layout ({Path(a.target).suffix.lower()})")
    if a.show:                                         # after the results: a failed run leaves none
        from ..render import save_png
        from ..render.diagnose import transfer_picture
        save_png(a.show, transfer_picture(xfer, f"{Path(a.target).name} as the transfer sees it"))
        _say(f"picture -> {a.show}")
    _say(f"aligned target to source: residual {100 * xfer.alignment_residual:.2f}% of the face size"
         + _correspondence_line(xfer))
    if xfer.parts is not None:
        _say(f"parts: source {xfer.parts[0].summary()}; target {xfer.parts[1].summary()} (skin to skin; "
             "eyeballs and teeth rigid, lashes and shells with the skin)")
    _say(f"{n} expression(s) -> {r.out}/ ({a.method}; read {sec['read']:.2f}s, precompute {sec['precompute']:.2f}s, "
         f"transfer {sec['transfer']:.2f}s = {n / max(sec['transfer'], 1e-9):.0f} frames/s)")


def add_args(sub) -> None:
    """Put `mimica transfer` and its options on the `mimica` parser.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The parser's commands (ArgumentParser.add_subparsers).
    """
    t = sub.add_parser("transfer", help="move expressions of a source face onto a target face (Song et al.)",
                       description="Writes, for every SOURCE_EXPR, a file of the same name into --out: the "
                                   "target wearing that expression, in the target's own topology.")
    t.add_argument("source_neutral", help="source face, neutral (OBJ/PLY/glTF)")
    t.add_argument("source_expr", nargs="+", help="source expressions (files or folders), same topology as the source")
    t.add_argument("--target", required=True, help="target face, neutral")
    t.add_argument("--source-landmarks", help="68-point landmark JSON of the source (built in for ICT-FaceKit)")
    t.add_argument("--target-landmarks", help="68-point landmark JSON of the target (built in for ICT-FaceKit)")
    t.add_argument("--method", choices=["vtc", "dt"], default=D.method,
                   help="vtc: vertex-tent coordinates (Song); dt: Sumner-Popovic deformation transfer")
    _head_options(t, "target")
    t.add_argument("-o", "--out", required=True, help="output folder")
    t.set_defaults(func=cmd_transfer)


run = cmd_transfer
