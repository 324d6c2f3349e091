"""`mimica wrinkle-mask`: carry the reference wrinkle mask onto a face (Viaud & Yahia §3.2)."""

from __future__ import annotations

from pathlib import Path

from ._common import _landmarks, _say


def cmd_wrinkle_mask(a):
    """`mimica wrinkle-mask`: the reference wrinkle mask carried onto a face.

    Parameters
    ----------
    a : argparse.Namespace
        The command's options (its add_args).

    Returns
    -------
    int
        The exit status (0: done).
    """
    from ..wrinkles import mask_for
    from ..mesh import read_mesh
    face = read_mesh(a.face)
    lm = _landmarks(face, a.landmarks, "--landmarks", str(a.face)).positions(face)
    mask, how = mask_for(face, lm, a.anchors, a.reference)
    mask.face = Path(a.face).name
    if a.show:
        from ..render import contact_sheet, save_png
        from ..wrinkles.show import mask_image
        save_png(a.show, contact_sheet([mask_image(face, mask, size=560), mask_image(face, mask, size=560, yaw=35)],
                                       title=f"wrinkle mask on {Path(a.face).name}"))
    mask.save(a.out)
    _say(f"{len(mask)} wrinkles -> {a.out} ({how})" + (f"; picture -> {a.show}" if a.show else ""))
    return 0


def add_args(sub) -> None:
    """Put `mimica wrinkle-mask` and its options on the `mimica` parser.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The parser's commands (ArgumentParser.add_subparsers).
    """
    w = sub.add_parser("wrinkle-mask", help="carry the reference wrinkle mask onto a face (Viaud & Yahia §3.2)")
    w.add_argument("face", help="face mesh (OBJ/PLY/glTF), any topology")
    w.add_argument("--landmarks", help="68-point landmark JSON (built in for ICT-FaceKit)")
    w.add_argument("--anchors", metavar="MASK", help="a mask of this face whose anchors you moved: relax again "
                   "with those characteristic points")
    w.add_argument("--reference", metavar="MASK", help="another reference mask on the ICT-FaceKit generic face")
    w.add_argument("--show", metavar="PNG", help="also draw the mask on the face")
    w.add_argument("-o", "--out", required=True, help="mask file to write (.wrinkles, JSON)")
    w.set_defaults(func=cmd_wrinkle_mask)


run = cmd_wrinkle_mask
