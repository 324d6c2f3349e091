"""PLY through plyfile: polygons, uv per vertex or per face corner (MeshLab's `texcoord`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...errors import MimicaError
from ..core import Mesh


def read_ply(path: Path) -> Mesh:
    """Read a PLY (plyfile): its vertices and polygons.

    Parameters
    ----------
    path : Path

    Returns
    -------
    Mesh
        A broken file is one MimicaError naming it.
    """
    from plyfile import PlyData
    try:
        ply = PlyData.read(str(path))
        vx = ply["vertex"]
        v = np.stack([vx["x"], vx["y"], vx["z"]], axis=1).astype(np.float64)
        fe = ply["face"] if "face" in ply else None
        if fe is None:
            faces = np.zeros((0, 3), np.int64)
        else:
            name = "vertex_indices" if "vertex_indices" in fe.data.dtype.names else "vertex_index"
            faces = [np.asarray(f, dtype=np.int64) for f in fe[name]]
        # uv: per face corner ("texcoord" lists, as MeshLab writes them), else per vertex
        # ("s"/"t", "u"/"v" or "texture_u"/"texture_v")
        fuv = [np.asarray(t, dtype=np.float64).reshape(-1, 2) for t in fe["texcoord"]] \
            if fe is not None and "texcoord" in fe.data.dtype.names else None
        names = vx.data.dtype.names
        pair = next((p for p in (("s", "t"), ("u", "v"), ("texture_u", "texture_v")) if set(p) <= set(names)), None)
        vuv = np.stack([vx[pair[0]], vx[pair[1]]], 1).astype(np.float64) if pair else None
    except MimicaError:
        raise
    except Exception as e:  # plyfile raises several types for malformed input
        raise MimicaError(f"{path}: not a readable PLY file ({e})") from None
    mesh = Mesh.from_faces(v, faces)
    if fuv is not None and all(len(t) == len(f) for t, f in zip(fuv, faces)) and len(fuv):
        mesh.uv = np.vstack(fuv)
        mesh.face_uv_indices = np.arange(len(mesh.uv))
    elif vuv is not None:
        mesh.uv, mesh.face_uv_indices = vuv, mesh.face_indices.copy()
    return mesh


def write_ply(mesh: Mesh, path: Path) -> None:
    """Write a mesh as a binary PLY (plyfile).

    Parameters
    ----------
    mesh : Mesh
    path : Path
    """
    from plyfile import PlyData, PlyElement
    v = np.empty(mesh.n_vertices, dtype=[("x", "f8"), ("y", "f8"), ("z", "f8")])
    v["x"], v["y"], v["z"] = mesh.vertices.T
    corners = np.split(np.arange(len(mesh.face_indices)), mesh.face_starts[1:-1])
    has_uv = mesh.uv is not None and mesh.face_uv_indices is not None
    f = np.empty(mesh.n_faces, dtype=[("vertex_indices", "O")] + ([("texcoord", "O")] if has_uv else []))
    f["vertex_indices"] = [mesh.face_indices[c].astype(np.int32) for c in corners]
    if has_uv:         # per face corner (MeshLab's "texcoord" list): the vertices keep their order
        f["texcoord"] = [mesh.uv[mesh.face_uv_indices[c]].astype(np.float32).reshape(-1) for c in corners]
    PlyData([PlyElement.describe(v, "vertex"),
             PlyElement.describe(f, "face", val_types={"texcoord": "f4"} if has_uv else {})],
            text=False).write(str(path))
