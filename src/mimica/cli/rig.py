"""`mimica rig`: place muscles, springs and regions of interest on a face (Kim 2020)."""

from __future__ import annotations

import time

from ._common import _muscle_bar, _landmarks, _say
from ..pipeline import RigOptions as D


def cmd_rig(a):
    """`mimica rig`: muscles, springs and regions of interest placed on a face (pipeline.make_rig).

    Parameters
    ----------
    a : argparse.Namespace
        The command's options (its add_args).

    Returns
    -------
    int
        The exit status (0: done).
    """
    from ..mesh import read_mesh
    from ..pipeline import RigOptions, make_rig
    t0 = time.perf_counter()
    opts = RigOptions(muscles=a.muscles, alpha=a.alpha, modes=a.modes, stretch=a.stretch)
    skin = read_mesh(a.face)
    lm = _landmarks(skin, a.landmarks, "--landmarks", str(a.face))
    with _muscle_bar("muscles") as progress:
        rig = make_rig(skin, lm, opts, out=a.out, progress=progress)
    drives = sum(m.kind == "drive" for m in rig.muscles)
    _say(f"rig: {len(rig.muscles) - drives} muscles" + (f" and {drives} drives (jaw, lids, cheeks)" if drives else "")
         + f" on {rig.skin.n_vertices} skin nodes -> {a.out} ({time.perf_counter() - t0:.1f}s)")
    return 0


def add_args(sub) -> None:
    """Put `mimica rig` and its options on the `mimica` parser.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The parser's commands (ArgumentParser.add_subparsers).
    """
    r = sub.add_parser("rig", help="place muscles, springs and regions of interest on a face (Kim 2020)")
    r.add_argument("face", help="face mesh (OBJ/PLY/glTF)")
    r.add_argument("--landmarks", help="68-point landmark JSON (built in for ICT-FaceKit)")
    r.add_argument("--muscles", default=D.muscles,
                   help="all (the whole library: 44 muscles, and the jaw, the lids and the cheeks as drives, "
                        "about 30 s on an 11k-vertex head), kim (Kim's 8), or a comma list of names")
    r.add_argument("--alpha", type=float, default=D.alpha, help="ROI range (Kim eq. 19) where a muscle has none of its own")
    r.add_argument("--modes", type=int, default=D.modes, help="skin modes per force type")
    r.add_argument("--stretch", choices=["bar", "shell"], default=D.stretch,
                   help="each muscle's stretch: bar (default), its nodes sliding toward the origin by arc "
                        "length, what the library was calibrated with; shell: the stretch mode of the strip's "
                        "own shell eigenproblem (Kim eqs. 11-12), docs/benchmarks.md")
    r.add_argument("-o", "--out", required=True, help="rig file to write")
    r.set_defaults(func=cmd_rig)


run = cmd_rig
