"""`mimica age`: a face with its wrinkles at several ages, neutral and with an expression."""

from __future__ import annotations

import time

from ..errors import MimicaError
from ._common import _muscle_bar, _landmarks, _say
from ..pipeline import AgeOptions as D


def cmd_age(a):
    """`mimica age`: a face with its wrinkles at several ages, neutral and with an expression
    (pipeline.age_sheet).

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
    from ..pipeline import AgeOptions, age_sheet
    try:
        ages = tuple(float(x) for x in a.ages.split(","))
    except ValueError:
        ages = ()
    if not ages or not all(0 <= x <= 150 for x in ages):                 # NaN fails too
        raise MimicaError(f"--ages {a.ages!r}: expected ages in years from 0 to 150, e.g. 25,45,65,85")
    if not str(a.out).lower().endswith(".png"):
        raise MimicaError(f"--out {a.out}: the age sheet is a PNG picture; name it *.png")
    from ..anim import PRESETS
    if a.expression not in PRESETS:
        raise MimicaError(f"--expression {a.expression!r}: one of {', '.join(PRESETS)}")
    face = read_mesh(a.face)
    lm = _landmarks(face, a.landmarks, "--landmarks", str(a.face))
    t0 = time.perf_counter()
    opts = AgeOptions(ages=ages, expression=a.expression, size=a.size, rig=a.rig, wrinkles=a.wrinkles)
    with _muscle_bar("rig (all muscles)") as progress:
        n = age_sheet(face, a.out, lm, opts, progress=progress)
    _say(f"{n} renders -> {a.out} ({time.perf_counter() - t0:.1f}s)")
    return 0


def add_args(sub) -> None:
    """Put `mimica age` and its options on the `mimica` parser.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The parser's commands (ArgumentParser.add_subparsers).
    """
    ag = sub.add_parser("age", help="a face with its wrinkles at several ages, neutral and with an expression")
    ag.add_argument("face", help="face mesh (OBJ/PLY/glTF)")
    ag.add_argument("--ages", default=",".join(f"{x:g}" for x in D.ages), help="ages in years, comma-separated")
    ag.add_argument("--expression", default=D.expression, help="expression preset (see `simulate`)")
    ag.add_argument("--landmarks", help="68-point landmark JSON (built in for ICT-FaceKit)")
    ag.add_argument("--rig", help="a rig of this face (default: built with all muscles, about a minute)")
    ag.add_argument("--wrinkles", metavar="MASK", help="wrinkle mask of this face (default: the reference, carried)")
    ag.add_argument("--size", type=int, default=D.size, help="pixels per picture")
    ag.add_argument("-o", "--out", required=True, help="PNG contact sheet")
    ag.set_defaults(func=cmd_age)


run = cmd_age
