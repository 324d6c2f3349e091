"""Rigid parts that move the skin through its attachments: the jaw and the eyelids.

A muscle of the library pulls a strip of skin; the jaw and the lids are different: a bone (the
mandible) or a stiff plate (the tarsal plate of each lid) turns about a joint, and the skin
over it follows through its attachments.  Each such motion is a *drive*: the part's rigid
motion at full activation, the skin nodes attached to it, and how strongly each is attached
(its weight, 0..1).  The physics stage treats a drive as one more force type (Kim eq. 21):
its attachments are springs to anchors that ride on the part, so its skin system is the
skin's shell with those springs, loaded by the anchors' motion.

Every placement is relative to the 68 landmarks, so a drive fits any face of any topology.
The numbers below were measured on ICT-FaceKit's generic face (training only: its sculpted
jawOpen, jawForward, jawLeft, eyeBlink, eyeWide and eyeSquint; bench/simulate.py checks the
result on held-out identities):

- the jaw turns 25 degrees about the temporomandibular axis at jawOpen = 1 (the lower teeth's
  rigid fit: residual 0.018 of 4.1 units of motion); the axis runs across the face 0.46 eye
  widths below and 0.235 behind the midpoint of landmarks 0 and 16; protrusion is 0.10 eye
  widths forward; a lateral slide 0.043 eye widths with 1.9 degrees of yaw;
- the eyeball's centre is 0.119 eye-opening widths above and 0.321 behind the midpoint of the
  eye's corners (a sphere fitted to ICT's eyeballs: radius 0.557 widths); a blink turns the
  upper lid about the centre's horizontal axis until its rim reaches the lower rim, eyeWide
  lifts it 12 degrees, eyeSquint lifts the lower rim by a quarter of the opening and draws it
  toward the nose.

Lid contact: the closing drive moves every upper-lid node at most onto the lower rim, never
past it; with the lower lid raised as well they would cross, and the modal face holds the
closing lid where the rims meet, position by position along the eye (physics.drives.lid_contact),
so the rims meet and never cross; the fit closes a closed target's lid until they meet
(physics.fit.MuscleFit).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..align import face_cylinder
from .muscles import CALIBRATION

JAW_OPEN_DEG = 25.0              # ICT jawOpen = 1: the lower teeth turn 25.3 degrees
JAW_PIVOT = (-0.46, -0.235)      # (up, forward) of the TMJ axis from mid(lm 0, lm 16), eye widths
JAW_FORWARD = 0.10               # protrusion at full activation, eye widths (ICT: 0.888 / 8.92)
JAW_SLIDE = 0.043                # lateral slide, eye widths (ICT jawLeft: 0.38 / 8.92)
JAW_YAW_DEG = 1.9                # and its yaw about the vertical axis
EYE_CENTRE = (0.119, -0.321)     # (up, forward) of the eyeball's centre, in eye-opening widths
LID_MARGIN = 0.0                 # a closed lid stops this part of the opening short of the lower rim
# the attachments' shapes: first guesses from the measurements above, refined against ICT's
# shapes on the training identities by tools/calibrate_muscles.py --drives (calibration.json)
PARAMS = {
    "jaw_side": 0.75,            # the chin's attachment fades sideways over this many mouth widths
    "jaw_below": 0.15,           # ... above the lips' line over this part of the mouth-to-chin height
    "jaw_under": 1.1,            # ... under the chin from this many mouth-to-chin heights
    "jaw_under_fade": 0.5,
    "lid_band": [4.0, 30.0],     # upper lid: attached fully up to 4 degrees above its margin, none past 30
    "lower_band": [4.0, 25.0],   # lower lid, below its margin
    "lid_raise": 0.25,           # eyeSquint lifts the lower margin by this part of the opening
    "lid_raise_in": 0.75,        # ... and moves the raised lid toward the nose by this part of its rise
    "lid_wide_deg": 12.0,        # eyeWide lifts the upper margin (ICT: 12.3-12.7 degrees)
    "cheek_centre": [0.15, 0.05],  # cheek pressure: centre between the mouth corner and landmark 3-4
    "cheek_radius": 0.4,         # (in eye widths: across, up) and its reach
    "cheek_push": 0.08,          # outward at full activation, eye widths
    "cheek_cavity": 1.0,         # the air pushes out from a point this many eye widths behind the lips
}
PARAMS.update(CALIBRATION.get("drives", {}))

# name -> (part, motion); the jaw's muscles: the digastric opens it (masseter and temporalis
# close it: the simulator subtracts their activations, jaw_closers), the lateral pterygoids
# protrude it together and each slides it to the other side; the lids: levator palpebrae
# lifts the upper lid, orbicularis oculi's palpebral part closes it and lifts the lower lid
DRIVES = {
    "digastric": ("jaw", "open"),
    "lateral_pterygoid": ("jaw", "forward"),
    "lateral_pterygoid_R": ("jaw", "left"),          # the right muscle pulls the jaw to the left
    "lateral_pterygoid_L": ("jaw", "right"),
    "levator_palpebrae_R": ("lid_R", "wide"),
    "levator_palpebrae_L": ("lid_L", "wide"),
    "orbicularis_oculi_palpebral_R": ("lid_R", "close"),
    "orbicularis_oculi_palpebral_L": ("lid_L", "close"),
    "orbicularis_oculi_lower_R": ("lid_R", "raise"),
    "orbicularis_oculi_lower_L": ("lid_L", "raise"),
    # not a muscle: the air in the mouth pushing the cheeks out (cheekPuff; the buccinator gives
    # way), a force type of its own as Kim's user pulls and gravity are
    "cheek_pressure_R": ("cheek_R", "push"),
    "cheek_pressure_L": ("cheek_L", "push"),
}
JAW_CLOSERS = ("masseter", "temporalis")


@dataclass
class Drive:
    """One drive placed on a face: anchors at the attached skin nodes and their motion at full
    activation.

    Attributes
    ----------
    name : str
        Its name in DRIVES (e.g. "digastric", "levator_palpebrae_R").
    attach : (k,) int array
        The skin nodes attached to the part.
    weight : (k,) float array
        Each attachment's strength, 0 to 1.
    motion : (k, 3) float array
        The anchors' displacement at activation 1.
    info : dict
        What the simulator needs (the jaw's frame, the lid's eye and margin pairs, ...).
    """
    name: str
    attach: np.ndarray           # (k,) skin nodes attached to the part
    weight: np.ndarray           # (k,) attachment strength, 0..1
    motion: np.ndarray           # (k, 3) the anchors' displacement at activation 1
    info: dict                   # what the simulator needs (lid opening angles, ...)


def _frame(lm):
    cyl = face_cylinder(lm)
    right, up = cyl.axes[0], cyl.axes[1]
    fwd = np.cross(right, up)
    return right, up, fwd / np.linalg.norm(fwd)


def _turn(a, up, fwd, dpsi):
    """Vectors a (k, 3) turned about the face's horizontal axis so that their angle in the
    (forward, up) plane grows by dpsi (k,) radians."""
    f, u = a @ fwd, a @ up
    c, s = np.cos(dpsi), np.sin(dpsi)
    return a + ((f * c - u * s) - f)[:, None] * fwd + ((f * s + u * c) - u)[:, None] * up


def _smooth(t):
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3 - 2 * t)


def jaw_weights(x, lm):
    """How firmly each skin node is attached to the mandible: the chin and lower lip, fading sideways
    over about a mouth width and above the lips' inner line, and below the chin.

    Parameters
    ----------
    x : (n, 3) float array
        The skin's positions.
    lm : (68, 3) float array
        Its landmarks.

    Returns
    -------
    (n,) float array
        0 to 1.
    """
    right, up, fwd = _frame(lm)
    mc = 0.5 * (lm[62] + lm[66])
    mw = float(np.linalg.norm(lm[54] - lm[48]))
    chin = max(float((mc - lm[8]) @ up), 1e-9)
    xr = (x - mc) @ right
    yu = (x - mc) @ up
    # the lips' inner line: between the upper and lower inner-lip landmarks, across the mouth
    pts = np.array([lm[60], 0.5 * (lm[61] + lm[67]), 0.5 * (lm[62] + lm[66]), 0.5 * (lm[63] + lm[65]), lm[64]])
    px, py = (pts - mc) @ right, (pts - mc) @ up
    o = np.argsort(px)
    line = np.interp(xr, px[o], py[o])
    P = PARAMS
    below = _smooth((line - yu) / (P["jaw_below"] * chin))          # 0 above the line, 1 below
    under = 1.0 - _smooth((-yu - P["jaw_under"] * chin) / (P["jaw_under_fade"] * chin))   # not under the chin
    side = np.exp(-(xr / (P["jaw_side"] * mw)) ** 2)
    front = (x - jaw_frame(lm)["pivot"]) @ fwd > 0                  # in front of the TMJ axis
    return below * under * side * front


def jaw_frame(lm) -> dict:
    """The jaw's frame from the landmarks.

    Parameters
    ----------
    lm : (68, 3) float array

    Returns
    -------
    dict
        {"pivot": the TMJ pivot (3,), "right", "up", "fwd": the face's axes (3,) each, "angle": the
        full opening in degrees, "ew": the eye-to-eye width}, as lists (a rig's JSON).
    """
    right, up, fwd = _frame(lm)
    ew = float(np.linalg.norm(lm[45] - lm[36]))
    pivot = 0.5 * (lm[0] + lm[16]) + ew * (JAW_PIVOT[0] * up + JAW_PIVOT[1] * fwd)
    return {"pivot": pivot.tolist(), "right": right.tolist(), "up": up.tolist(), "fwd": fwd.tolist(),
            "angle": JAW_OPEN_DEG, "ew": ew}


def jaw_motion(x, lm, what: str):
    """The mandible's displacement at some points for one of its motions at full activation.

    Parameters
    ----------
    x : (n, 3) float array
    lm : (68, 3) float array
    what : str
        'open' (turned about the TMJ axis), 'forward', 'left' or 'right' (slides).

    Returns
    -------
    (n, 3) float array
    """
    j = jaw_frame(lm)
    if what == "open":
        m_s, m_c, _ = jaw_open_parts(x, j)
        return m_s + m_c
    right, fwd, ew = np.array(j["right"]), np.array(j["fwd"]), j["ew"]
    if what == "forward":
        return np.broadcast_to(JAW_FORWARD * ew * fwd, x.shape).copy()
    a = x - np.array(j["pivot"])
    sign = 1.0 if what == "left" else -1.0                          # the subject's left is +x
    yaw = sign * np.radians(JAW_YAW_DEG)                            # the chin swings to that side
    c, s = np.cos(yaw), np.sin(yaw)
    r, f = a @ right, a @ fwd
    return ((r * c + f * s) - r)[:, None] * right + ((-r * s + f * c) - f)[:, None] * fwd + sign * JAW_SLIDE * ew * right


def jaw_open_parts(x, info):
    """The jaw's opening at some points, split so that any angle is exact: the anchors' displacement
    at a fraction q of the full angle phi is sin(q phi)/sin(phi) m_s + (1 - cos(q phi))/(1 - cos(phi))
    m_c, and m_s + m_c at q = 1.

    Parameters
    ----------
    x : (n, 3) float array
    info : dict
        jaw_frame's.

    Returns
    -------
    m_s, m_c : (n, 3) float arrays
    phi : float
        The full angle, radians (negative: opening).
    """
    right, up, fwd = (np.asarray(info[k], float) for k in ("right", "up", "fwd"))
    a = np.asarray(x, float) - np.asarray(info["pivot"], float)
    f, u = a @ fwd, a @ up
    phi = -np.radians(float(info["angle"]))
    m_s = np.sin(phi) * ((-u)[:, None] * fwd + f[:, None] * up)
    m_c = (np.cos(phi) - 1) * (f[:, None] * fwd + u[:, None] * up)
    return m_s, m_c, phi


def jaw_open_factors(q, phi):
    """The weights of (m_s, m_c) (jaw_open_parts) at a fraction of the jaw's full opening.

    Parameters
    ----------
    q : float or float array
        The fraction.
    phi : float
        The full angle, radians.

    Returns
    -------
    tuple of float or float array
        sin(q phi) / sin(phi), (1 - cos(q phi)) / (1 - cos(phi)).
    """
    return np.sin(q * phi) / np.sin(phi), (1 - np.cos(q * phi)) / (1 - np.cos(phi))


def eye_geometry(lm, side: str):
    """An eye's centre, its opening's width, and its rims as angles in the (forward, up) plane about
    the centre against the lateral position.

    Parameters
    ----------
    lm : (68, 3) float array
    side : str
        "R" or "L".

    Returns
    -------
    tuple
        (centre (3,), width, s_of(points) -> lateral position across the eye, psi(points) -> angle
        about the centre, upper_rim(s) -> angle, lower_rim(s) -> angle, (s of the outer corner,
        s of the inner corner)).
    """
    right, up, fwd = _frame(lm)
    outer, top, lower, inner = ((36, (37, 38), (41, 40), 39) if side == "R" else (45, (44, 43), (46, 47), 42))
    mid = 0.5 * (lm[outer] + lm[inner])
    width = float(np.linalg.norm(lm[outer] - lm[inner]))
    c = mid + width * (EYE_CENTRE[0] * up + EYE_CENTRE[1] * fwd)

    def s_of(p):
        return (np.atleast_2d(p) - mid) @ right / width

    def psi(p):
        a = np.atleast_2d(p) - c
        return np.arctan2(a @ up, a @ fwd)

    def rim(ids):
        pts = np.array([lm[outer]] + [lm[i] for i in ids] + [lm[inner]])
        s, ps = s_of(pts), psi(pts)
        o = np.argsort(s)
        return lambda q: np.interp(q, s[o], ps[o])
    return c, width, s_of, psi, rim(top), rim(lower), (float(s_of(lm[outer])[0]), float(s_of(lm[inner])[0]))


def lid_drive(x, lm, side: str, what: str):
    """One lid motion at full activation.

    Parameters
    ----------
    x : (n, 3) float array
        The skin's positions.
    lm : (68, 3) float array
    side : str
        "R" or "L".
    what : str
        'close' turns the upper lid about the eyeball's centre until its rim lies on the lower rim
        (less the margin), never past it; 'wide' lifts the upper lid; 'raise' lifts the lower lid
        (and draws it toward the nose).

    Returns
    -------
    weights : (n,) float array
    motion : (n, 3) float array
    info : dict
        The eye, its centre, up and fwd, the margin pairs ("rims"), the widest opening.
    """
    right, up, fwd = _frame(lm)
    c, width, s_of, psi, upper, lower, (s0, s1) = eye_geometry(lm, side)
    lo_s, hi_s = min(s0, s1), max(s0, s1)
    s = s_of(x)
    p = psi(x)
    a = x - c
    near = (np.linalg.norm(a, axis=1) < 1.6 * width) & (a @ fwd > 0)
    inside = (s > lo_s) & (s < hi_s)
    pu, pl = upper(s), lower(s)
    mid = 0.5 * (pu + pl)
    span = hi_s - lo_s
    # the lids' margins from the skin itself (landmarks lie near them, not on them): across
    # the eye in bins, the lowest upper-lid node and the highest lower-lid node near the eyeball
    band = near & inside & (np.linalg.norm(a, axis=1) > 0.45 * width)
    edges = np.linspace(lo_s, hi_s, 17)
    top, bottom, pairs = [], [], []                        # margin nodes: (s, psi, node)
    for e0, e1 in zip(edges[:-1], edges[1:]):
        b = band & (s >= e0) & (s < e1)
        up_b, lo_b = np.nonzero(b & (p > mid))[0], np.nonzero(b & (p <= mid))[0]
        i = up_b[np.argmin(p[up_b])] if len(up_b) else None
        j = lo_b[np.argmax(p[lo_b])] if len(lo_b) else None
        if i is not None:
            top.append((s[i], p[i]))
        if j is not None:
            bottom.append((s[j], p[j]))
        if i is not None and j is not None:                # the margins' nodes facing each other
            pairs.append([int(i), int(j)])
    if len(top) >= 2 and len(bottom) >= 2:                 # the margins through those nodes
        top, bottom = np.array(top), np.array(bottom)
        pu = np.interp(s, top[:, 0], top[:, 1])
        pl = np.interp(s, bottom[:, 0], bottom[:, 1])
    gap = np.maximum(pu - pl, 0.0)
    # contact is checked where the eye is open, not in the corners' folds
    opened = [p[i] - p[j] for i, j in pairs]
    pairs = [pr for pr, o in zip(pairs, opened) if o > 0.15 * max(opened)] if opened else []
    ends = _smooth(np.minimum(s - lo_s, hi_s - s) / (0.08 * span))        # fades at the corners
    if what in ("close", "wide"):
        d = np.degrees(p - pu)
        b0, b1 = PARAMS["lid_band"]
        w = (1 - _smooth((d - b0) / max(b1 - b0, 1e-6))) * (p > mid)
        w = w * near * inside * ends
        if what == "close":
            # each node turns by its weight x the opening, and a node of the lid's margin (below
            # the rim) at most down to the lower rim
            dpsi = -np.minimum(w * gap, np.maximum(p - pl, 0.0)) * (1 - LID_MARGIN)
        else:
            dpsi = w * np.radians(PARAMS["lid_wide_deg"])
    else:
        d = np.degrees(pl - p)
        b0, b1 = PARAMS["lower_band"]
        w = (1 - _smooth((d - b0) / max(b1 - b0, 1e-6))) * (p <= mid)
        w = w * near * inside * ends
        dpsi = w * PARAMS["lid_raise"] * gap
    motion = _turn(a, up, fwd, dpsi) - a
    if what == "raise":
        # ICT's eyeSquint draws the lower lid toward the nose as it rises (its moving nodes: 0.17
        # up, 0.12 inward on average); lid_raise_in chosen by the whole library's fit of eyeSquint
        # on the training faces (generic, seeds 11, 12: 0.754-0.765 without, 0.856-0.871 at 0.75,
        # 0.5 and 1.0 a little lower), docs/benchmarks.md
        inward = np.sign(s1 - s0) * right                   # s0, s1: the outer and inner corners
        motion = motion + PARAMS["lid_raise_in"] * np.linalg.norm(motion, axis=1)[:, None] * inward[None]
    info = {"eye": side, "centre": c.tolist(), "width": width, "up": up.tolist(), "fwd": fwd.tolist(),
            "raise": PARAMS["lid_raise"], "wide": float(np.radians(PARAMS["lid_wide_deg"])),
            "rims": pairs,                                      # (upper, lower) margin nodes
            "gap_max": float(max(gap[inside].max() if inside.any() else 0.0, 1e-6))}  # the widest opening
    return w, motion, info


def lid_pairs(info) -> np.ndarray:
    """The facing margin nodes of a closing lid drive.

    Parameters
    ----------
    info : dict
        The drive's (lid_drive).

    Returns
    -------
    (k, 2) int array
        (upper, lower) skin nodes.
    """
    return np.asarray(info.get("rims", []), int).reshape(-1, 2)


def margin_opening(xp, info) -> np.ndarray:
    """The lid opening at each pair of facing margin nodes.

    Parameters
    ----------
    xp : (..., k, 2, 3) float array
        The pairs' positions.
    info : dict
        The drive's (its eye's centre, up and fwd).

    Returns
    -------
    (..., k) float array
        Radians about the eyeball's centre, upper minus lower: negative where the lids cross.
    """
    c, up, fwd = (np.asarray(info[k], float) for k in ("centre", "up", "fwd"))
    a = np.asarray(xp, float) - c
    psi = np.arctan2(a @ up, a @ fwd)
    return psi[..., 0] - psi[..., 1]


def open_pairs(rest_opening) -> np.ndarray:
    """The margin pairs where a closed lid's gap is measured (the figure; the corners' folds are left
    out).

    Parameters
    ----------
    rest_opening : (k,) float array
        Each pair's opening at rest (margin_opening).

    Returns
    -------
    (k,) bool array
        Open at least half the widest at rest.
    """
    rest_opening = np.asarray(rest_opening, float)
    return rest_opening >= 0.5 * rest_opening.max()


def lid_opening(x, info) -> np.ndarray:
    """margin_opening of skin positions.

    Parameters
    ----------
    x : (n, 3) or (F, n, 3) float array
    info : dict
        The closing drive's.

    Returns
    -------
    (k,) or (F, k) float array
    """
    return margin_opening(np.asarray(x, float)[..., lid_pairs(info), :], info)


def cheek_drive(x, lm, side: str):
    """The cheek pushed out by the air in the mouth: around a point between the mouth corner and the
    jaw line, fading over cheek_radius eye widths, away from the mouth's cavity (its centre
    cheek_cavity eye widths behind the lips; the skin's own normal measured 0.24-0.32 against ICT's
    cheekPuff, which swells mostly forward: 0.88).

    Parameters
    ----------
    x : (n, 3) float array
    lm : (68, 3) float array
    side : str
        "R" or "L".

    Returns
    -------
    weights : (n,) float array
    motion : (n, 3) float array
    """
    right, up, fwd = _frame(lm)
    ew = float(np.linalg.norm(lm[45] - lm[36]))
    corner, jaw = (lm[48], 0.5 * (lm[3] + lm[4])) if side == "R" else (lm[54], 0.5 * (lm[13] + lm[12]))
    t, lift = PARAMS["cheek_centre"]
    c = corner + t * (jaw - corner) + lift * ew * up
    d = np.linalg.norm(x - c, axis=1) / (PARAMS["cheek_radius"] * ew)
    w = np.exp(-d * d) * ((x - c) @ fwd > -PARAMS["cheek_radius"] * ew)
    cavity = 0.5 * (lm[62] + lm[66]) - PARAMS["cheek_cavity"] * ew * fwd
    out = x - cavity
    out /= np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-300)
    return w, (PARAMS["cheek_push"] * ew) * w[:, None] * out


def place_drive(name: str, x, lm, min_weight: float = 0.02) -> Drive:
    """One drive of DRIVES placed on the skin.

    Parameters
    ----------
    name : str
        A key of DRIVES.
    x : (n, 3) float array
        The skin's positions.
    lm : (68, 3) float array
    min_weight : float
        Skin nodes attached less firmly are left out.

    Returns
    -------
    Drive
    """
    part, what = DRIVES[name]
    if part.startswith("cheek"):
        w, motion = cheek_drive(x, lm, part[-1])
        at = np.nonzero(w > min_weight)[0]
        return Drive(name, at, np.ones(len(at)), motion[at], {"part": "cheek", "motion": what})
    if part == "jaw":
        w = jaw_weights(x, lm)
        at = np.nonzero(w > min_weight)[0]
        info = {"part": "jaw", "motion": what}
        if what == "open":                     # the bone's pose, for an exact rotation at any angle
            info.update(jaw_frame(lm))
        return Drive(name, at, w[at], jaw_motion(x[at], lm, what), info)
    # a lid's skin folds into its crease: the anchors' motion fades with the weight (the plate
    # turns, the fold above it less), and every anchor holds as firmly (the crease is tied to
    # the levator's aponeurosis)
    w, motion, info = lid_drive(x, lm, part[-1], what)
    at = np.nonzero(w > min_weight)[0]
    info.update(part="lid", motion=what)
    return Drive(name, at, np.ones(len(at)), motion[at], info)
