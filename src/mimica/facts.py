"""What mimica and its Blender add-on both need to know, in plain Python (the standard library
only): the 52 ARKit names, simulate's preset expressions, a take's rows read into times and
weights, and the turn between mimica's y up and Blender's z up.

The add-on runs inside Blender, whose Python cannot import mimica (numpy < 2 there, >= 2 here),
so `mimica blender-addon` ships this file beside it, and both import it as their sibling
(`from . import facts`).  It imports nothing from mimica; tests/test_layers.py holds it so.
"""

from __future__ import annotations

# Apple's ARFaceAnchor.BlendShapeLocation, in Live Link Face's column order
ARKIT_52 = (
    "eyeBlinkLeft", "eyeLookDownLeft", "eyeLookInLeft", "eyeLookOutLeft", "eyeLookUpLeft", "eyeSquintLeft",
    "eyeWideLeft", "eyeBlinkRight", "eyeLookDownRight", "eyeLookInRight", "eyeLookOutRight", "eyeLookUpRight",
    "eyeSquintRight", "eyeWideRight", "jawForward", "jawLeft", "jawRight", "jawOpen", "mouthClose",
    "mouthFunnel", "mouthPucker", "mouthLeft", "mouthRight", "mouthSmileLeft", "mouthSmileRight",
    "mouthFrownLeft", "mouthFrownRight", "mouthDimpleLeft", "mouthDimpleRight", "mouthStretchLeft",
    "mouthStretchRight", "mouthRollLower", "mouthRollUpper", "mouthShrugLower", "mouthShrugUpper",
    "mouthPressLeft", "mouthPressRight", "mouthLowerDownLeft", "mouthLowerDownRight", "mouthUpperUpLeft",
    "mouthUpperUpRight", "browDownLeft", "browDownRight", "browInnerUp", "browOuterUpLeft", "browOuterUpRight",
    "cheekPuff", "cheekSquintLeft", "cheekSquintRight", "noseSneerLeft", "noseSneerRight", "tongueOut")

_ARKIT_LOWER = {n.lower(): n for n in ARKIT_52}
_SIDES = {"l": "Left", "r": "Right", "left": "Left", "right": "Right"}


def arkit_name(name: str):
    """The ARKit shape a morph target or shape key of another tool's file stands for, or None:
    the name compared without case ("EyeBlinkLeft", as Live Link and Unreal write it), after any
    namespace ("blendShape1.eyeBlinkLeft" from Maya, "head:eyeBlinkLeft", "|head|eyeBlinkLeft"),
    with a side written as a suffix ("eyeBlink_L" as ICT-FaceKit, "eyeBlink.L" as Blender) or a
    copy's number ("eyeBlinkLeft.001") read as the name's own.

    Parameters
    ----------
    name : str

    Returns
    -------
    str or None
        One of ARKIT_52.
    """
    s = name.replace("|", ":").split(":")[-1].strip()
    while len(s) > 4 and s[-4] == "." and s[-3:].isdigit():        # Blender's copies: .001
        s = s[:-4]
    base, sep, side = max(s.rpartition("_"), s.rpartition("."), key=lambda p: len(p[0]))
    if sep and side.lower() in _SIDES:
        s = base.split(".")[-1] + _SIDES[side.lower()]
    else:
        s = s.split(".")[-1]
    return _ARKIT_LOWER.get(s.lower())


def arkit_targets(names) -> dict:
    """Which of a head's morph targets plays each ARKit shape, as other tools name them
    (arkit_name: without case, namespaces, side suffixes); a name that is the ARKit
    name itself wins over one read as it.

    Parameters
    ----------
    names : iterable of str
        The head's morph-target names.

    Returns
    -------
    dict
        {ARKit name: the head's target name}.
    """
    out = {}
    for n in names:
        a = arkit_name(n)
        if a is not None and (a not in out or n == a):
            out[a] = n
    return out


# the head's rotation some takes carry beside the weights (radians)
HEAD_ROTATION = ("headYaw", "headPitch", "headRoll")

# Blender's z up (the face looking along -y) -> mimica's y up (looking along +z): (x, y, z) ->
# (x, z, -y), as Blender's OBJ and glTF exporters turn it; its transpose turns back
Z_UP_TO_Y_UP = ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0), (0.0, -1.0, 0.0))

# simulate's preset expressions (anim.PRESETS but its neutral)
EXPRESSIONS = ("happiness", "sadness", "surprise", "anger", "disgust", "fear")


class TakeError(ValueError):
    """A take that cannot be read; its message names the file and, where it can, the line.

    Parameters
    ----------
    message : str
    """


def _timecode(text: str) -> tuple[int, float]:
    """(whole seconds, frame number) of a Live Link timecode HH:MM:SS:FF(.fff)."""
    p = text.strip().split(":")
    if len(p) != 4:
        raise ValueError(f"{text!r} is not a timecode HH:MM:SS:FF")
    return 3600 * int(p[0]) + 60 * int(p[1]) + int(p[2]), float(p[3])


def take_from_rows(rows: list, path, fps: float | None = None) -> tuple[list, dict, float | None]:
    """A take's times and weights from its rows (a header, then a row a frame).

    Parameters
    ----------
    rows : list of list of str
        The rows as csv.reader gives them; blank rows are skipped.  The header names the 52
        ARKit weights (Live Link Face's PascalCase or camelCase) and a `Timecode` (HH:MM:SS:FF)
        or `time` (seconds) column; headYaw, headPitch and headRoll are read where present.
    path : str or Path
        How messages name the take.
    fps : float or None
        The frame rate of a Timecode column (None: one more than its largest frame number,
        e.g. 60 for frames 0-59).

    Returns
    -------
    times : list of float
        (F,) seconds from the take's first frame, increasing.
    weights : dict
        {name: (F,) list of float}: the 52 ARKit weights and any head rotation.
    rate : float or None
        The Timecode's frame rate; None for a `time` column.

    Raises TakeError (a ValueError) naming the file and the line.
    """
    if len(rows) < 2:
        raise TakeError(f"{path}: no frames (a header line and one line per frame are needed)")
    header = [h.strip() for h in rows[0]]
    by_name = {h[:1].lower() + h[1:]: i for i, h in enumerate(header)}
    missing = [n for n in ARKIT_52 if n not in by_name]
    if missing:
        raise TakeError(f"{path}: no column for {', '.join(missing[:4])}"
                        + (f" and {len(missing) - 4} more" if len(missing) > 4 else "")
                        + " (a take needs the 52 ARKit weights, as Live Link Face writes them)")
    body = [(i, r) for i, r in enumerate(rows[1:], start=2) if any(str(c).strip() for c in r)]
    if not body:
        raise TakeError(f"{path}: no frames (a header line and one line per frame are needed)")
    short = [i for i, r in body if len(r) < len(header)]
    if short:
        raise TakeError(f"{path}: line {short[0]} has fewer values than the header")
    tcol = by_name.get("timecode", by_name.get("time"))
    if tcol is None:
        raise TakeError(f"{path}: no Timecode or time column")
    names = [n for n in ARKIT_52 + HEAD_ROTATION if n in by_name]
    try:
        if header[tcol].lower() == "timecode":
            tc = [_timecode(str(r[tcol])) for _, r in body]
            rate = fps or float(int(max(f for _, f in tc)) + 1)
            times = [s + f / rate for s, f in tc]
        else:
            times, rate = [float(r[tcol]) for _, r in body], None
        weights = {n: [float(r[by_name[n]]) for _, r in body] for n in names}
    except ValueError as e:
        raise TakeError(f"{path}: a value that is not a number or a timecode ({e})") from None
    for what, values in [(header[tcol], times)] + list(weights.items()):
        bad = [k for k, x in enumerate(values) if x != x or abs(x) == float("inf")]
        if bad:
            raise TakeError(f"{path}: line {body[bad[0]][0]}: {what} is not a finite number")
    back = [k for k in range(1, len(times)) if times[k] <= times[k - 1]]
    if back:
        raise TakeError(f"{path}: line {body[back[0]][0]}: the time does not increase (frames must come in order)")
    return [t - times[0] for t in times], weights, rate
