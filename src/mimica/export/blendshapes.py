"""The 52 ARKit blendshapes on any head: ICT-FaceKit's expression shapes (ARKit naming, split
_L/_R) moved onto the user's head by the expression transfer (Song et al.; landmarks found
automatically on other topologies), written as named morph targets.  The head's parts
(correspond.parts) move as their kind does: teeth and tongue with the jaw, eyeballs rigidly,
lashes with the lids."""

from __future__ import annotations

import numpy as np

from .. import facts
from ..errors import MimicaError

ARKIT_52 = list(facts.ARKIT_52)      # Apple's 52, in Live Link Face's order


def ict_sources(arkit: str) -> list[str]:
    """The ICT-FaceKit shapes whose deltas sum to an ARKit shape.  ICT splits browInnerUp and cheekPuff
    into halves and has no tongue (tongueOut stays at rest).

    Parameters
    ----------
    arkit : str

    Returns
    -------
    list of str
    """
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
    """The 52 ARKit shapes of a head: {ARKit name: (m, 3) positions}.

    Attributes
    ----------
    mesh : Mesh
        The head they belong to: the user's, or with its sealed lips or eyes cut (its vertices
        first, the cuts' copies after them).
    mouth : MouthCut or None
        The mouth's cut.
    landmarks : Landmarks
        The head's landmarks (given, or found).
    transfer : ExpressionTransfer
        The transfer that made them (vertex_report, pictures).
    """
    mesh = None
    mouth = None
    landmarks = None              # the head's landmarks (given, or found)
    transfer = None               # the ExpressionTransfer that made them (vertex_report, pictures)


def arkit_blendshapes(head, landmarks=None, progress=None, store=None, cut_mouth=True, match="nicp",
                      relayout=True, cut_eyes=True) -> Blendshapes:
    """The 52 ARKit shapes on a head of any topology: ICT-FaceKit's sculpted shapes moved onto it
    by the expression transfer, the head's parts moving as their kind does.

    Parameters
    ----------
    head : Mesh
        The head (n vertices).
    landmarks : Landmarks or None
        Its 68 landmarks; None: built in for ICT-FaceKit's topology, else found on renders.
    progress : callable, optional
        Called with one line of text at each step.
    store : TemplateStore, optional
        Where ICT-FaceKit's files come from (the data directory, else a pinned download).
    cut_mouth, match, relayout, cut_eyes
        As ExpressionTransfer's.

    Returns
    -------
    Blendshapes
        {ARKit name: (m, 3) positions} on `Blendshapes.mesh` (the head, any cut's m - n vertices
        after its own); tongueOut at rest (ICT-FaceKit has no tongue shape).
    """
    from ..data import ICT_N_VERTICES
    from ..landmarks import ict_landmarks, landmarks_for
    from ..mesh import read_mesh
    from ..transfer import ExpressionTransfer, TransferSettings, static_vertices
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
    how = TransferSettings(method="vtc", match=match, cut_mouth=cut_mouth, cut_eyes=cut_eyes, relayout=relayout)
    xfer = ExpressionTransfer(src, head, ict_landmarks(src), lt, how, static=static_vertices(src.vertices, frames))
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
    """Where a cut (the mouth's, the eyes') changed a head into the mesh the shapes are on -- what a
    DCC applies to its own mesh to cut it as mimica did.

    Parameters
    ----------
    head : Mesh
        As given.
    mesh : Mesh
        The same polygons, the head's vertices first, the cut's copies after them.

    Returns
    -------
    dict
        {"cut_copies": (k,) the head's vertex each added vertex copies, "cut_corners": (m, 3) rows
        (polygon, corner in the polygon, added vertex)}; {} where nothing was cut.
    """
    n = head.n_vertices
    if mesh.n_vertices == n:
        return {}
    moved = np.nonzero(mesh.face_indices != head.face_indices)[0]
    poly = np.searchsorted(head.face_starts, moved, side="right") - 1
    added = mesh.face_indices[moved] - n
    copies = np.full(mesh.n_vertices - n, -1, np.int64)
    copies[added] = head.face_indices[moved]
    return {"cut_copies": copies, "cut_corners": np.stack([poly, moved - head.face_starts[poly], added], 1)}


BLENDSHAPE_SUFFIXES = (".glb", ".gltf", ".usd", ".usda", ".usdc", ".npz", ".fbx")


def check_blendshapes_path(path) -> None:
    """Raise MimicaError where a path's suffix is not a kind of file `write_blendshapes` writes.

    Parameters
    ----------
    path : str or Path
    """
    from pathlib import Path
    if Path(path).suffix.lower() not in BLENDSHAPE_SUFFIXES:
        raise MimicaError(f"{path}: blendshapes are written as glTF (.glb or .gltf), FBX (an FBX head's own file), "
                          "USD (.usd, .usda, .usdc) or NumPy arrays (.npz: the positions of each shape, for the "
                          "Blender add-on)")


def write_blendshapes(path, head, shapes: Blendshapes, units: str = "auto", quantize: bool = False) -> dict:
    """Write a head's 52 ARKit shapes; the kind of file by `path`'s suffix, written whole or not
    at all.

    - .glb / .gltf: a head read from glTF is written back into its own file (its nodes,
      materials and vertex layout; mesh.io.write_gltf_layout), else a new one (mesh.io.write_glb:
      sparse targets, `quantize` for KHR_mesh_quantization); both carry the extras `animate`
      reads (export.extras: where the head turns, its 68 landmarks).
    - .fbx: back into the FBX head it was read from, through Blender (mesh.io.write_fbx_layout).
    - .usd / .usda / .usdc: UsdSkel blend shapes (export.usd).
    - .npz: the rest and each shape's positions, and where a cut added vertices (`cut_corners`):
      what the Blender add-on reads.

    Parameters
    ----------
    path : str or Path
        The file to write.
    head : Mesh
        The head as read (its `layout` says which file it came from).
    shapes : Blendshapes
        `arkit_blendshapes(head, ...)`; `shapes.mesh` is the head with any cut's vertices.
    units : str
        The head's unit where the file does not say it ("auto", "m", "cm", "mm").
    quantize : bool
        glTF written new: targets as 16-bit moves (KHR_mesh_quantization).

    Returns
    -------
    dict
        {"kind": "gltf-layout" | "gltf" | "fbx" | "usd" | "npz", "bytes": the file's size, and
        the writer's own figures: "units", "sparse", "accessors", "appended", "notes", ...}.
    """
    from pathlib import Path

    from ..mesh import atomic_path
    from ..mesh.io import SPARSE_TOLERANCE, UNITS, GltfLayout, glb_units, write_glb
    from .extras import head_extras
    check_blendshapes_path(path)
    path = Path(path)
    suffix = path.suffix.lower()
    targets = {n: shapes[n] for n in ARKIT_52}
    if suffix == ".fbx":
        from ..mesh.io import FbxLayout, write_fbx_layout
        if not isinstance(head.layout, FbxLayout):
            raise MimicaError(f"{path}: FBX is written back into the FBX head it was read from; write .glb for this "
                              "head (Blender, Maya and game engines import it)")
        with atomic_path(path) as tmp:
            info = dict(write_fbx_layout(tmp, head.layout, shapes.mesh, targets), kind="fbx")
    elif suffix == ".npz":
        cut = cut_corners(head, shapes.mesh)
        with atomic_path(path) as tmp:
            with open(tmp, "wb") as fh:
                np.savez(fh, vertices=shapes.mesh.vertices, **targets, **cut)
        info = {"kind": "npz", "appended": len(cut.get("cut_copies", ()))}
    elif suffix in (".usd", ".usda", ".usdc"):
        from .usd import write_usd
        info = dict(write_usd(path, shapes.mesh, targets, units=units), kind="usd")
    else:
        layout = head.layout if isinstance(head.layout, GltfLayout) else None
        k = UNITS[layout.unit] if layout is not None else glb_units(shapes.mesh, units)[1]
        extras = head_extras(shapes.mesh, shapes.landmarks, k)
        binary = suffix == ".glb"
        with atomic_path(path) as tmp:
            if layout is not None:                      # back into the user's own file
                from ..mesh.io import write_gltf_layout
                info = dict(write_gltf_layout(tmp, layout, shapes.mesh, targets, binary=binary, extras=extras),
                            kind="gltf-layout")
            else:
                info = dict(write_glb(tmp, shapes.mesh, targets, binary=binary, units=units, sparse=SPARSE_TOLERANCE,
                                      quantize=quantize, extras=extras), kind="gltf")
    info["bytes"] = path.stat().st_size
    return info
