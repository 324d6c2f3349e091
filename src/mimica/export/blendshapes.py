"""The 52 ARKit blendshapes on any head: ICT-FaceKit's expression shapes (ARKit naming, split
_L/_R) moved onto the user's head by the expression transfer (Song et al.; landmarks found
automatically on other topologies), written as named morph targets.  The head's parts
(correspond.parts) move as their kind does: teeth and tongue with the jaw, eyeballs rigidly,
lashes with the lids."""

from __future__ import annotations

import numpy as np

from ..errors import MimicaError

ARKIT_52 = [
    "eyeBlinkLeft", "eyeLookDownLeft", "eyeLookInLeft", "eyeLookOutLeft", "eyeLookUpLeft", "eyeSquintLeft",
    "eyeWideLeft", "eyeBlinkRight", "eyeLookDownRight", "eyeLookInRight", "eyeLookOutRight", "eyeLookUpRight",
    "eyeSquintRight", "eyeWideRight", "jawForward", "jawLeft", "jawRight", "jawOpen", "mouthClose",
    "mouthFunnel", "mouthPucker", "mouthLeft", "mouthRight", "mouthSmileLeft", "mouthSmileRight",
    "mouthFrownLeft", "mouthFrownRight", "mouthDimpleLeft", "mouthDimpleRight", "mouthStretchLeft",
    "mouthStretchRight", "mouthRollLower", "mouthRollUpper", "mouthShrugLower", "mouthShrugUpper",
    "mouthPressLeft", "mouthPressRight", "mouthLowerDownLeft", "mouthLowerDownRight", "mouthUpperUpLeft",
    "mouthUpperUpRight", "browDownLeft", "browDownRight", "browInnerUp", "browOuterUpLeft",
    "browOuterUpRight", "cheekPuff", "cheekSquintLeft", "cheekSquintRight", "noseSneerLeft",
    "noseSneerRight", "tongueOut",
]


def ict_sources(arkit: str) -> list[str]:
    """ICT-FaceKit shapes whose deltas sum to an ARKit shape.  ICT splits browInnerUp and
    cheekPuff into halves and has no tongue (tongueOut stays at rest)."""
    if arkit in ("browInnerUp", "cheekPuff"):
        return [f"{arkit}_L", f"{arkit}_R"]
    if arkit == "tongueOut":
        return []
    if arkit in ("jawLeft", "jawRight", "mouthLeft", "mouthRight"):      # ICT keeps these names
        return [arkit]
    for side, suf in (("Left", "_L"), ("Right", "_R")):
        if arkit.endswith(side):
            return [arkit[: -len(side)] + suf]
    return [arkit]


class Blendshapes(dict):
    """{ARKit name: (n, 3) positions}; `mesh` is the head they belong to: the user's, or with its
    sealed lips cut apart (its vertices first, the cut's copies after them); `mouth` the cut."""
    mesh = None
    mouth = None
    landmarks = None              # the head's landmarks (given, or found)
    transfer = None               # the ExpressionTransfer that made them (vertex_report, pictures)


def arkit_blendshapes(head, landmarks=None, progress=None, store=None, cut_mouth=True, match="nicp",
                      relayout=True, cut_eyes=True) -> Blendshapes:
    """The 52 ARKit shapes on `head` (a Mesh of any topology; cut_mouth, cut_eyes, relayout: see
    ExpressionTransfer)."""
    from ..data import ICT_N_VERTICES
    from ..landmarks import ict_landmarks, landmarks_for
    from ..mesh import read_mesh
    from ..transfer import ExpressionTransfer, static_vertices
    from ..store import default_store

    store = store or default_store()
    say = progress or (lambda m: None)
    # the whole ICT-FaceKit mesh: its teeth, gums and tongue give the jaw's motion, and a head
    # with the same parts (or ICT's own) gets them moved as ICT moves them
    src = read_mesh(store.path("generic_neutral_mesh", say))
    if src.n_vertices != ICT_N_VERTICES:
        raise MimicaError("ICT-FaceKit neutral: unexpected topology")
    names = sorted({n for a in ARKIT_52 for n in ict_sources(a)})
    say(f"reading {len(names)} ICT-FaceKit shapes")
    shapes = store.shapes(names, ICT_N_VERTICES, say)
    lt = landmarks if landmarks is not None else landmarks_for(head, None, "head")
    frames = np.stack([src.vertices + sum((shapes[n] - src.vertices for n in ict_sources(a)),
                                          np.zeros_like(src.vertices)) for a in ARKIT_52])
    say("transferring 52 shapes")
    xfer = ExpressionTransfer(src, head, ict_landmarks(src), lt, method="vtc",
                              static=static_vertices(src.vertices, frames), cut_mouth=cut_mouth, match=match,
                              relayout=relayout, cut_eyes=cut_eyes)
    if xfer.mouth is not None:
        say(f"the lips were sealed: cut apart along {len(xfer.mouth.seam)} vertices "
            f"({len(xfer.mouth.copies_of)} added after the head's own)")
    if xfer.parts is not None:
        say(f"parts of the head: {xfer.parts[1].summary()}")
    out = xfer.apply(frames)
    res = Blendshapes(zip(ARKIT_52, out))
    res.mesh, res.mouth, res.landmarks, res.transfer = xfer.output_mesh, xfer.mouth, lt, xfer
    res["tongueOut"] = res.mesh.vertices.copy()
    return res


def cut_corners(head, mesh) -> dict:
    """Where a cut (the mouth's, the eyes') changed `head` into `mesh` (the same polygons, its
    vertices first, the cut's copies after them): {"cut_copies": (k,) the head's vertex each added
    vertex copies, "cut_corners": (m, 3) rows (polygon, corner in the polygon, added vertex)} --
    what a DCC applies to its own mesh to cut it as mimica did; {} where nothing was cut."""
    n = head.n_vertices
    if mesh.n_vertices == n:
        return {}
    moved = np.nonzero(mesh.face_indices != head.face_indices)[0]
    poly = np.searchsorted(head.face_starts, moved, side="right") - 1
    added = mesh.face_indices[moved] - n
    copies = np.full(mesh.n_vertices - n, -1, np.int64)
    copies[added] = head.face_indices[moved]
    return {"cut_copies": copies, "cut_corners": np.stack([poly, moved - head.face_starts[poly], added], 1)}
