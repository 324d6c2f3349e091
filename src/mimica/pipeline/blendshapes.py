"""ARKit blendshapes for a head: read it (any format mimica reads), find or read its landmarks,
make the 52 shapes (export.arkit_blendshapes), write them (export.write_blendshapes)."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from ..errors import MimicaError
from ..export.blendshapes import Blendshapes, arkit_blendshapes, check_blendshapes_path, write_blendshapes
from ..mesh import Mesh


@dataclass(frozen=True)
class BlendshapesOptions:
    """How `make_blendshapes` works; each default is the one every user of it gets.

    Attributes
    ----------
    landmarks : str or Path or None
        The head's 68 landmarks in a file (JSON, landmarks.read_landmarks); None: built in for
        ICT-FaceKit's topology, else found on renders of the head (landmarks.detect3d).
    cut_mouth, cut_eyes : bool
        Cut sealed lips apart, and eyes that are one surface with their lids loose from them
        (transfer.ExpressionTransfer).
    match : str
        How the head's vertices find ICT-FaceKit's across topologies: "nicp" or "cylinder".
    units : str
        The head's unit where its file does not say it: "auto", "m", "cm" or "mm".
    quantize : bool
        A new glTF's targets as 16-bit moves (KHR_mesh_quantization).
    """
    landmarks: str | Path | None = None
    cut_mouth: bool = True
    cut_eyes: bool = True
    match: str = "nicp"
    units: str = "auto"
    quantize: bool = False


@dataclass
class BlendshapesResult:
    """What `make_blendshapes` made.

    Attributes
    ----------
    path : Path
        The file written.
    head : Mesh
        The head as read (`head.layout`: the file it came from, and what reading it noted).
    shapes : Blendshapes
        {ARKit name: (n, 3) positions} on `shapes.mesh` (the head with any cut's vertices);
        `shapes.transfer` is the transfer that made them.
    written : dict
        The writer's figures (export.write_blendshapes).
    landmarks_found : bool
        The landmarks were found on renders (neither given nor built in).
    seconds : float
        Wall time, reading to writing.
    """
    path: Path
    head: Mesh
    shapes: Blendshapes
    written: dict
    landmarks_found: bool
    seconds: float


def make_blendshapes(head, out, options: BlendshapesOptions | None = None, progress=None,
                     landmarks=None) -> BlendshapesResult:
    """The 52 ARKit shapes of a head, written to `out`.

    Parameters
    ----------
    head : str or Path or Mesh
        The head: a file (OBJ, PLY, glTF, FBX) or a Mesh.
    out : str or Path
        The file to write; its suffix chooses the kind (export.write_blendshapes): .glb, .gltf,
        .fbx (back into an FBX head), .usd/.usda/.usdc, .npz.
    options : BlendshapesOptions, optional
    progress : callable, optional
        Called with one line of text at each step (and with what reading the head's file noted).
    landmarks : Landmarks, optional
        The head's landmarks already in hand (instead of `options.landmarks`' file).

    Returns
    -------
    BlendshapesResult
    """
    from ..data import is_ict_topology
    from ..landmarks import read_landmarks
    from ..mesh import read_mesh
    o = options or BlendshapesOptions()
    say = progress or (lambda m: None)
    out = Path(out)
    check_blendshapes_path(out)                 # said before the work, not after it
    if out.suffix.lower() == ".fbx" and (isinstance(head, Mesh) or Path(head).suffix.lower() != ".fbx"):
        raise MimicaError(f"{out}: FBX is written back into the FBX head it was read from; write .glb for this "
                          "head (Blender, Maya and game engines import it)")
    t0 = time.perf_counter()
    mesh = head if isinstance(head, Mesh) else read_mesh(head)
    what = (mesh.name or "the head") if isinstance(head, Mesh) else head
    for note in (mesh.layout.notes if mesh.layout is not None else []):
        say(f"{what}: {note}")
    lm = landmarks if landmarks is not None else read_landmarks(o.landmarks, mesh) if o.landmarks else None
    shapes = arkit_blendshapes(mesh, lm, progress=say, cut_mouth=o.cut_mouth, match=o.match, cut_eyes=o.cut_eyes)
    written = write_blendshapes(out, mesh, shapes, units=o.units, quantize=o.quantize)
    return BlendshapesResult(out, mesh, shapes, written, lm is None and not is_ict_topology(mesh),
                             time.perf_counter() - t0)
