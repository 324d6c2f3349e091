"""Checks of values a user gives (numbers, lists of numbers, forces), written once: each returns
the value parsed or raises MimicaError naming what was given (`what`: the option, the field or
the file a front end took it from) and what is expected."""

from __future__ import annotations

import numpy as np

from .errors import MimicaError


def number_in(value, lo: float, hi: float, what: str, integer: bool = False) -> float:
    """`value` as a finite number from `lo` to `hi`.

    Parameters
    ----------
    value : object
        What the user gave (a number or its text).
    lo, hi : float
        The range, both ends allowed.
    what : str
        How the message names it (the option or field).
    integer : bool
        A whole number is expected (returned as int).

    Returns
    -------
    float or int
        Raises MimicaError naming `what`, the value and the range otherwise.
    """
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = float("nan")
    if not np.isfinite(v) or not lo <= v <= hi or (integer and v != int(v)):
        raise MimicaError(f"{what} {value!r}: expected {'a whole number' if integer else 'a number'} "
                          f"from {lo:g} to {hi:g}")
    return int(v) if integer else v


def floats(text: str, n: int, what: str) -> list[float]:
    """'0,1.5,-0.1' -> [0.0, 1.5, -0.1].

    Parameters
    ----------
    text : str
        Exactly `n` finite numbers separated by commas.
    n : int
        How many.
    what : str
        How the message names it.

    Returns
    -------
    list of float
        (n,) the numbers; MimicaError otherwise.
    """
    try:
        vals = [float(x) for x in str(text).split(",")]
    except ValueError:
        vals = []
    if len(vals) != n or not np.isfinite(vals).all():
        raise MimicaError(f"{what} {text!r}: expected {n} finite numbers separated by commas")
    return vals


def pull(spec: str, what: str) -> tuple[np.ndarray, float, np.ndarray]:
    """A force on the skin within a radius of a point, from its text.

    Parameters
    ----------
    spec : str
        'x,y,z:radius:fx,fy,fz' in the skin's units (finite numbers, radius > 0, |force| <= 1e6).
    what : str
        How the message names it.

    Returns
    -------
    centre : (3,) float array
    radius : float
    force : (3,) float array
    """
    try:
        c, r, f = str(spec).split(":")
        center = np.array([float(v) for v in c.split(",")])
        force = np.array([float(v) for v in f.split(",")])
        radius = float(r)
    except ValueError:
        center = force = np.zeros(0)
        radius = float("nan")
    if not (center.shape == (3,) and force.shape == (3,) and np.isfinite(center).all()
            and np.isfinite(force).all() and np.isfinite(radius) and radius > 0
            and np.abs(force).max() <= 1e6):
        raise MimicaError(f"{what} {spec!r}: expected x,y,z:radius:fx,fy,fz (skin units; finite numbers, "
                          "radius > 0)")
    return center, radius, force


def strengths(text: str, what: str):
    """How much of an expression, overall or per region.

    Parameters
    ----------
    text : str
        '0.5', or regions 'brows=0.5,mouth=1.2', or both '0,mouth=1'.
    what : str
        How the message names it.

    Returns
    -------
    float or dict
        0.5; {"brows": 0.5, "mouth": 1.2}; {"all": 0.0, "mouth": 1.0}.  The regions and the
        range are checked where they are used (image.analogy.point_strengths).
    """
    out, parts = {}, [t.strip() for t in str(text).split(",") if t.strip()]
    try:
        for t in parts:
            if "=" in t:
                k, v = t.split("=", 1)
                out[k.strip()] = float(v)
            else:
                out["all"] = float(t)
    except ValueError:
        parts = []
    if not parts:
        raise MimicaError(f"{what} {text!r}: a number from 0 to 2, or regions as brows=0.5,mouth=1.2")
    return out["all"] if list(out) == ["all"] else out
