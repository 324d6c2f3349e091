"""Mesh files, one module a format: `obj` (mimica's own reader and writer), `ply` (plyfile),
`gltf` (glTF and GLB, pygltflib; its JSON decoded by `gltf_decode`), `fbx`.

Every failure a user can cause raises `MimicaError` naming the file and the problem.
Writes are atomic: the file appears complete or not at all.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...errors import MimicaError
from ...outputs import atomic_path  # noqa: F401  (re-exported: mesh.atomic_path)
from ..core import Mesh
from .checks import validate
from .gltf import (QUANTIZATION, QUANTIZE_ERROR, SPARSE_TOLERANCE, UNITS, GltfLayout, glb_units,  # noqa: F401
                   read_gltf, write_glb, write_gltf_layout)
from .gltf import read_morph_targets as _gltf_targets
from .fbx import FbxLayout, read_fbx, read_fbx_shapes, write_fbx_layout
from .obj import read_obj, read_obj_vertices, write_obj
from .ply import read_ply, write_ply

MESH_SUFFIXES = (".obj", ".ply", ".glb", ".gltf", ".fbx")


def natural_order(path: Path):
    """A sort key that puts frame2 before frame10.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    list of tuple
        The file name's runs of digits as numbers, the rest as lower-case text.
    """
    import re
    return [(0, int(t), "") if t.isdigit() else (1, 0, t.lower()) for t in re.split(r"(\d+)", Path(path).name) if t]


def sequence_files(folder) -> tuple[list[Path], list[str]]:
    """The frames of a folder of meshes, in natural order, and the files left out: a sequence is one
    format, so files of another (a previous run's animation.glb beside OBJ frames) are not frames.

    Parameters
    ----------
    folder : str or Path
        A folder holding mesh files (MimicaError where it holds none).

    Returns
    -------
    frames : list of Path
        The files of the folder's most common mesh format, in natural order.
    skipped : list of str
        The names of the others.
    """
    folder = Path(folder)
    files = sorted((f for f in folder.iterdir() if f.suffix.lower() in MESH_SUFFIXES), key=natural_order)
    if not files:
        raise MimicaError(f"{folder}: the folder holds no mesh files ({', '.join(MESH_SUFFIXES)})")
    kinds = [f.suffix.lower() for f in files]
    main = max(sorted(set(kinds)), key=kinds.count)
    return [f for f, k in zip(files, kinds) if k == main], [f.name for f, k in zip(files, kinds) if k != main]


def read_json(path, what="file"):
    """Parse a JSON file; a missing, unreadable or malformed one is a one-line MimicaError.

    Parameters
    ----------
    path : str or Path
    what : str
        How the message names the file ("landmark file", "take", ...).

    Returns
    -------
    object
        The parsed document.
    """
    import json
    path = Path(path)
    try:
        return json.loads(path.read_text())
    except OSError as e:
        raise MimicaError(f"{path}: cannot read the {what} ({e.strerror})") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        where = f" (line {e.lineno}: {e.msg})" if isinstance(e, json.JSONDecodeError) else ""
        raise MimicaError(f"{path}: not valid JSON{where}") from None


# ------------------------------------------------------------------------ API
def _suffix(path: Path) -> str:
    s = path.suffix.lower()
    if s not in MESH_SUFFIXES:
        raise MimicaError(f"{path}: unknown mesh format {s or '(no extension)'!r}; "
                          f"use one of {', '.join(MESH_SUFFIXES)}")
    return s


def read_mesh(path, validate_mesh=True, allow_degenerate=False) -> Mesh:
    """Read a mesh file whole: OBJ, PLY, glTF/GLB (every node's mesh and primitive, in world
    space; the file's layout kept for writing back) or FBX (through Blender).

    Parameters
    ----------
    path : str or Path
        The file; its suffix says the format.
    validate_mesh : bool
        Check it (finite positions, valid indices, no degenerate polygons: mesh.io.checks).
    allow_degenerate : bool
        Accept zero-area polygons.

    Returns
    -------
    Mesh
        Polygons stay polygons (glTF holds triangles only).  A file that cannot be read is a
        one-line MimicaError naming it.
    """
    path = Path(path)
    s = _suffix(path)
    if not path.is_file():
        raise MimicaError(f"{path}: no such file")
    reader = {".obj": read_obj, ".ply": read_ply, ".glb": read_gltf, ".gltf": read_gltf, ".fbx": read_fbx}[s]
    mesh = reader(path)
    mesh.name = path.stem
    if validate_mesh:
        validate(mesh, str(path), allow_degenerate=allow_degenerate)
    return mesh


def write_mesh(path, mesh: Mesh, units: str = "auto") -> Path:
    """Write a mesh, whole or not at all; the format follows the suffix.

    A mesh read from a glTF file (`mesh.layout`) written as glTF goes back into that file
    (gltf.write_gltf_layout: the user's nodes, materials and vertex layout, in its units); one
    read from FBX written as FBX goes back through Blender.

    Parameters
    ----------
    path : str or Path
        .obj, .ply, .glb, .gltf or .fbx.
    mesh : Mesh
    units : str
        glTF only: the mesh's unit ("auto", "m", "cm", "mm"; glTF is in metres).

    Returns
    -------
    Path
    """
    path = Path(path)
    s = _suffix(path)
    with atomic_path(path) as tmp:
        if s in (".glb", ".gltf") and isinstance(mesh.layout, GltfLayout) and mesh.n_faces == mesh.layout.n_faces:
            write_gltf_layout(tmp, mesh.layout, mesh, binary=s == ".glb")
        elif s == ".fbx":
            if not isinstance(mesh.layout, FbxLayout) or mesh.n_faces != mesh.layout.n_faces:
                raise MimicaError(f"{path}: FBX is written back into an FBX file it was read from; write this "
                                  "mesh as OBJ, PLY or glTF")
            write_fbx_layout(tmp, mesh.layout, mesh)
        elif s == ".obj":
            write_obj(mesh, tmp)
        elif s == ".ply":
            write_ply(mesh, tmp)
        else:
            write_glb(tmp, mesh, binary=(s == ".glb"), units=units)
    return path


def read_vertices(path) -> np.ndarray:
    """Only the vertex positions of a mesh file, checked finite: for frame sequences whose
    topology is known already (for OBJ only the 'v' lines are parsed: obj.read_obj_vertices).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    (n, 3) float64 array
    """
    path = Path(path)
    if _suffix(path) != ".obj":
        return read_mesh(path, allow_degenerate=True).vertices
    return read_obj_vertices(path)


def read_morph_targets(path) -> tuple[Mesh, dict, str]:
    """A head's morph targets: a glTF's (gltf.read_morph_targets) or an FBX's shape keys
    (fbx.read_fbx_shapes).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    mesh : Mesh
        The head as solved (its welded work mesh).
    targets : dict
        {name: (n, 3) float array} positions on it.
    unit : str
        The mesh's unit as the file gives it.
    """
    path = Path(path)
    if path.suffix.lower() == ".fbx":
        if not path.is_file():
            raise MimicaError(f"{path}: no such file")
        return read_fbx_shapes(path)
    return _gltf_targets(path)
