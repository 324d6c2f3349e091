"""The wrinkle mask (Viaud & Yahia 1992, §3): expressive wrinkles as curves on a face.

File format (JSON, ``.wrinkles``; lengths in the face mesh's own units)::

    {"format": "mimica-wrinkles/1",
     "face": "ict-generic-neutral",              # what the mask lies on (informative)
     "anchors": [[x, y, z], ...],                 # characteristic points (V&Y §3.2):
                                                  # the 68 iBUG landmarks, then the mask's
                                                  # boundary (anchor_names() lists them)
     "wrinkles": [
       {"name": "forehead_1",
        "muscles": ["frontalis_L", "frontalis_R"],  # the muscles that fold it
        "emphasis": 1.0,                           # per-wrinkle depth coefficient (V&Y §5.2)
        "width": 0.45,                             # cross-section P0-P1 across the line
        "profile": "symmetric",                    # or "asymmetric" (nasolabial, marionette)
        "fold": "in",                              # "in": a furrow; "out": a ridge
        "points": [[x, y, z], ...]}]}              # control points of a Cardinal spline
                                                  # on the surface, in order along the line

Edit it by hand or with any tool: move control points (they are snapped back onto the
surface), change widths or emphasis, add or delete wrinkles.  For an asymmetric wrinkle the
fuller side is on the right of the line's direction, seen from in front of the face.

The reference mask on the bundled ICT-FaceKit generic face (`reference_mask()`) places the
expressive wrinkles of Hjortsjö's atlas: forehead lines, glabellar and procerus lines,
crow's feet, lower-eyelid lines, bunny lines, nasolabial folds, marionette lines and the
mentolabial sulcus.  It is generated from the landmarks by `define_reference()` and
`tools/make_reference_mask.py` writes the shipped file.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np

from ..errors import MimicaError
from ..mesh import Mesh, atomic_path, read_json
from .surface import FaceFrame

FORMAT = "mimica-wrinkles/1"
PROFILES = ("symmetric", "asymmetric")
FOLDS = ("in", "out")

# boundary anchors beyond the 68 landmarks: (name, landmark weights, lift in eye widths)
BOUNDARY = [
    ("forehead.top.right.outer", {17: 1.0}, 0.55), ("forehead.top.right", {19: 1.0}, 0.62),
    ("forehead.top.right.inner", {21: 1.0}, 0.62), ("forehead.top.left.inner", {22: 1.0}, 0.62),
    ("forehead.top.left", {24: 1.0}, 0.62), ("forehead.top.left.outer", {26: 1.0}, 0.55),
    ("temple.right", {0: 0.8, 17: 0.2}, 0.35), ("temple.left", {16: 0.8, 26: 0.2}, 0.35),
]


def anchor_names() -> list[str]:
    """The names of a mask's anchors: the 68 landmarks' ('eye.left.0', ...), then the boundary's.

    Returns
    -------
    list of str
    """
    from ..landmarks import NAMES
    return list(NAMES) + [b[0] for b in BOUNDARY]


@dataclass
class Wrinkle:
    """One wrinkle of a mask: a curve of control points on the face (V&Y §3).

    Attributes
    ----------
    name : str
    points : (k, 3) float array
        Its control points on the surface.
    muscles : tuple of str
        The muscles whose contraction deepens it.
    emphasis : float
        A factor on its depth.
    """
    name: str
    points: np.ndarray                  # (k, 3) control points on the surface
    muscles: tuple = ()
    emphasis: float = 1.0
    width: float = 0.4
    profile: str = "symmetric"
    fold: str = "in"

    def to_json(self) -> dict:
        return {"name": self.name, "muscles": list(self.muscles), "emphasis": round(float(self.emphasis), 4),
                "width": round(float(self.width), 5), "profile": self.profile, "fold": self.fold,
                "points": [[round(float(c), 5) for c in p] for p in self.points]}


@dataclass
class WrinkleMask:
    """A face's wrinkles and the anchors that place them (V&Y §3.2); saved as a .wrinkles JSON.

    Attributes
    ----------
    wrinkles : list of Wrinkle
    anchors : (68 + len(BOUNDARY), 3) float array
        The 68 landmarks, then the mask boundary's anchors; NaN = missing.
    face : str
        The face it lies on.
    extra : dict
        More of the file's keys, kept.
    """
    wrinkles: list
    anchors: np.ndarray                 # (68 + len(BOUNDARY), 3), NaN = missing
    face: str = ""
    extra: dict = field(default_factory=dict)

    def __len__(self):
        return len(self.wrinkles)

    def names(self) -> list[str]:
        return [w.name for w in self.wrinkles]

    def save(self, path) -> Path:
        path = Path(path)
        doc = {"format": FORMAT, "face": self.face,
               "anchors": [None if not np.isfinite(p).all() else [round(float(c), 5) for c in p]
                           for p in self.anchors],
               "wrinkles": [w.to_json() for w in self.wrinkles]}
        doc.update(self.extra)
        with atomic_path(path) as tmp:
            text = json.dumps(doc, indent=1)
            # one point per line: [x, y, z] lists printed flat
            text = re.sub(r"\[\s*(-?[\d.e+-]+),\s*(-?[\d.e+-]+),\s*(-?[\d.e+-]+)\s*\]", r"[\1, \2, \3]", text)
            tmp.write_text(text + "\n")
        return path

    @classmethod
    def load(cls, path) -> "WrinkleMask":
        path = Path(path)
        return cls.from_json(read_json(path, "wrinkle mask"), str(path))

    @classmethod
    def from_json(cls, doc, where="wrinkle mask") -> "WrinkleMask":
        def bad(msg):
            return MimicaError(f"{where}: {msg}")
        if not isinstance(doc, dict) or doc.get("format") != FORMAT:
            got = doc.get("format") if isinstance(doc, dict) else type(doc).__name__
            raise bad(f"not a wrinkle mask (format {got!r}, expected {FORMAT!r})")
        n_anchor = 68 + len(BOUNDARY)
        anchors = doc.get("anchors")
        if not isinstance(anchors, list) or len(anchors) != n_anchor:
            raise bad(f"'anchors' must list {n_anchor} points (68 landmarks + {len(BOUNDARY)} boundary points)")
        A = np.full((n_anchor, 3), np.nan)
        for i, p in enumerate(anchors):
            if p is not None:
                A[i] = _point(p, bad, f"anchor {i}")
        ws = doc.get("wrinkles")
        if not isinstance(ws, list) or not ws:
            raise bad("'wrinkles' must be a non-empty list")
        out, seen = [], set()
        for i, w in enumerate(ws):
            if not isinstance(w, dict):
                raise bad(f"wrinkle {i} must be an object")
            name = w.get("name")
            if not isinstance(name, str) or not name:
                raise bad(f"wrinkle {i} needs a 'name'")
            if name in seen:
                raise bad(f"wrinkle name {name!r} appears twice")
            seen.add(name)
            pts = w.get("points")
            if not isinstance(pts, list) or len(pts) < 2:
                raise bad(f"wrinkle {name!r}: 'points' must list at least 2 [x, y, z] points")
            P = np.array([_point(p, bad, f"wrinkle {name!r} point {j}") for j, p in enumerate(pts)])
            width, emph = w.get("width", 0.4), w.get("emphasis", 1.0)
            for key, val in (("width", width), ("emphasis", emph)):
                if not isinstance(val, (int, float)) or isinstance(val, bool) or not np.isfinite(val) or val < 0:
                    raise bad(f"wrinkle {name!r}: '{key}' must be a number >= 0, got {val!r}")
            if width <= 0:
                raise bad(f"wrinkle {name!r}: 'width' must be > 0")
            profile, fold = w.get("profile", "symmetric"), w.get("fold", "in")
            if profile not in PROFILES:
                raise bad(f"wrinkle {name!r}: 'profile' must be one of {', '.join(PROFILES)}, got {profile!r}")
            if fold not in FOLDS:
                raise bad(f"wrinkle {name!r}: 'fold' must be 'in' or 'out', got {fold!r}")
            muscles = w.get("muscles", [])
            if not isinstance(muscles, list) or not all(isinstance(m, str) for m in muscles):
                raise bad(f"wrinkle {name!r}: 'muscles' must be a list of muscle names")
            out.append(Wrinkle(name, P, tuple(muscles), float(emph), float(width), profile, fold))
        extra = {k: v for k, v in doc.items() if k not in ("format", "face", "anchors", "wrinkles")}
        return cls(out, A, str(doc.get("face", "")), extra)


def _point(p, bad, what):
    if (not isinstance(p, list) or len(p) != 3
            or not all(isinstance(c, (int, float)) and not isinstance(c, bool) and np.isfinite(c) for c in p)):
        raise bad(f"{what} must be [x, y, z] with finite numbers, got {p!r}")
    return np.array(p, float)


def reference_mask() -> WrinkleMask:
    """The shipped reference mask on the ICT-FaceKit generic neutral face.

    Returns
    -------
    WrinkleMask
    """
    ref = resources.files("mimica.wrinkles").joinpath("reference.wrinkles")
    return WrinkleMask.from_json(json.loads(ref.read_text()), "reference.wrinkles")


# ----------------------------------------------------------------- the reference mask
# Curves are drawn in the face frame (FaceFrame: x toward the subject's left, y up, eye-width
# units) from the landmarks, then projected onto the surface from the front.  A subject-right
# curve is mirrored for the left by mirroring the landmarks, so asymmetric faces get
# asymmetric masks.

def _anchors_local(L: np.ndarray) -> np.ndarray:
    """Boundary anchors (local 2D) from local landmarks L (68, 2)."""
    return np.array([sum(w * L[i] for i, w in wts.items()) + np.array([0.0, lift]) for _, wts, lift in BOUNDARY])


def _right_side(L):
    """Subject-right wrinkles as (name, [points (k, 2)], muscles, emphasis, width, profile)."""
    out_ = -1.0                    # away from the mid-line on the subject's right: -x
    P = lambda i, dx=0.0, dy=0.0: L[i] + np.array([out_ * dx, dy])  # noqa: E731
    mix = lambda *iw: sum(w * L[i] for i, w in iw)  # noqa: E731
    ws = []
    # glabellar (vertical frown) line: above the inner brow end, nearly vertical
    xg = 0.55 * L[21, 0]
    ws.append(("glabellar_R", [np.array([xg, L[21, 1] + 0.13]), np.array([xg * 1.05, L[21, 1] + 0.04]),
                               np.array([xg * 0.95, L[21, 1] - 0.05])],
               ("corrugator_supercilii_R",), 1.0, 0.035, "symmetric"))
    # crow's feet: three lines fanning out beside the outer eye corner
    c = P(36, 0.06, 0.0)
    for k, ang in enumerate((35.0, 5.0, -28.0)):
        d = np.array([out_ * np.cos(np.radians(ang)), np.sin(np.radians(ang))])
        ws.append((f"crows_feet_{k + 1}_R", [c + 0.04 * d, c + 0.11 * d, c + 0.19 * d],
                   ("orbicularis_oculi_R", "zygomaticus_major_R"), 0.9, 0.028, "symmetric"))
    # lower-eyelid line: an arc under the lower lid
    ws.append(("lower_eyelid_R", [P(36, 0.0, -0.07), P(41, 0.0, -0.1), P(40, 0.0, -0.1), P(39, -0.02, -0.08)],
               ("orbicularis_oculi_R",), 0.6, 0.028, "symmetric"))
    # bunny line: down and out across the side of the nose bridge
    ws.append(("bunny_R", [P(28, 0.05, 0.03), P(29, 0.09, 0.0), P(29, 0.13, -0.05)],
               ("nasalis_R", "levator_labii_superioris_alaeque_nasi_R"), 0.6, 0.03, "symmetric"))
    # nasolabial fold: from beside the nose wing, down and out, to beside the mouth corner
    ws.append(("nasolabial_R", [P(31, 0.04, 0.05), P(31, 0.09, -0.03), mix((31, 0.5), (48, 0.5)) + [out_ * 0.115, 0.0],
                                P(48, 0.085, -0.03), P(48, 0.07, -0.12)],
               ("levator_labii_superioris_R", "zygomaticus_major_R", "levator_labii_superioris_alaeque_nasi_R"),
               0.8, 0.09, "asymmetric"))
    # marionette line: from below the mouth corner down toward the jaw
    ws.append(("marionette_R", [P(48, 0.03, -0.07), mix((48, 0.6), (6, 0.4)) + [out_ * 0.05, 0.0],
                                mix((48, 0.3), (6, 0.7)) + [out_ * 0.04, 0.04]],
               ("depressor_anguli_oris_R",), 0.6, 0.06, "asymmetric"))
    return ws


def _centre(L):
    ws = []
    brow = np.vstack([L[17:22], 0.5 * (L[21] + L[22]), L[22:27]])
    for k, lift in enumerate((0.2, 0.33, 0.46)):
        flat = 0.35 + 0.2 * k                          # higher lines follow the brows less
        pts = brow.copy()
        pts[:, 1] = (1 - flat) * brow[:, 1] + flat * brow[:, 1].max() + lift
        pts = pts[1:-1]                                # from above brow point 18 to 25
        ws.append((f"forehead_{k + 1}", list(pts), ("frontalis_L", "frontalis_R"), 1.0, 0.045, "symmetric"))
    y = 0.5 * (L[21, 1] + L[22, 1]) - 0.02
    ws.append(("procerus", [np.array([L[21, 0] * 0.45, y - 0.08]), np.array([0.0, y - 0.1]),
                            np.array([L[22, 0] * 0.45, y - 0.08])],
               ("procerus", "corrugator_supercilii_L", "corrugator_supercilii_R"), 0.7, 0.03, "symmetric"))
    chin_y = L[57, 1] + 0.4 * (L[8, 1] - L[57, 1])
    xs = np.array([-0.13, -0.065, 0.0, 0.065, 0.13])
    ws.append(("mentolabial", [np.array([x, chin_y + 0.9 * x * x]) + [L[57, 0], 0] for x in xs],
               ("mentalis_L", "mentalis_R", "depressor_labii_inferioris_L", "depressor_labii_inferioris_R"),
               0.7, 0.06, "symmetric"))
    return ws


def _mirror_landmarks(L):
    """Local 2D landmarks of the face's mirror image (left and right swapped)."""
    from ..landmarks import MIRROR
    M = L[MIRROR].copy()
    M[:, 0] *= -1
    return M


def define_reference(mesh: Mesh, landmarks: np.ndarray, face: str = "") -> WrinkleMask:
    """Draw the reference wrinkles on a face from its 68 landmarks (V&Y §3, after Hjortsjö).

    Parameters
    ----------
    mesh : Mesh
    landmarks : (68, 3) float array
    face : str
        Its name, recorded.

    Returns
    -------
    WrinkleMask
    """
    frame = FaceFrame(landmarks)
    L = frame.to_local(landmarks)[:, :2]
    specs = _centre(L) + _right_side(L)
    Lm = _mirror_landmarks(L)
    for name, pts, muscles, emph, width, prof in _right_side(Lm):
        pts = [np.array([-p[0], p[1]]) for p in pts]
        muscles = tuple(m[:-2] + "_L" if m.endswith("_R") else m for m in muscles)
        specs.append((name[:-2] + "_L", pts, muscles, emph, width, prof))
    fmap = frame.front_map(mesh)
    wrinkles = []
    for name, pts, muscles, emph, width, prof in specs:
        pts = np.array(pts)
        if prof == "asymmetric" and name.endswith("_L"):
            pts = pts[::-1]                            # keep the fuller side lateral on both sides
        p3, found = fmap.points(pts)
        if not found.all():
            raise MimicaError(f"reference wrinkle {name!r} falls off the face surface")
        wrinkles.append(Wrinkle(name, p3, muscles, emph, width * frame.unit, prof, "in"))
    anchors2d = _anchors_local(L)
    b3, _ = fmap.points(anchors2d)
    anchors = np.vstack([landmarks, b3])
    return WrinkleMask(wrinkles, anchors, face)


def boundary_anchors(mesh: Mesh, landmarks: np.ndarray, vertices=None) -> np.ndarray:
    """The mask boundary's anchors on a face, by the same rule as the reference's.

    Parameters
    ----------
    mesh : Mesh
    landmarks : (68, 3) float array
    vertices : (n, 3) float array or None
        Positions to use (None: the mesh's).

    Returns
    -------
    (len(BOUNDARY), 3) float array
    """
    frame = FaceFrame(landmarks)
    L = frame.to_local(landmarks)[:, :2]
    b3, _ = frame.front_map(mesh, vertices).points(_anchors_local(L))
    return b3
