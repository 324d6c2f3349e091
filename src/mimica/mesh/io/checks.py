"""What every reader checks of the mesh it read: a MimicaError naming the file and the problem."""

from __future__ import annotations

import numpy as np

from ...errors import MimicaError
from ..core import Mesh


def validate(mesh: Mesh, source="mesh", allow_degenerate=False) -> Mesh:
    """Check that a mesh can be used: 3D finite vertices, faces in range, no empty mesh, no
    degenerate faces (unless allowed).

    Parameters
    ----------
    mesh : Mesh
    source : str
        How the message names it.
    allow_degenerate : bool

    Returns
    -------
    Mesh
        The mesh; MimicaError naming `source` otherwise.
    """
    v = mesh.vertices
    if v.ndim != 2 or v.shape[1] != 3:
        raise MimicaError(f"{source}: vertices must be 3D points, got shape {v.shape}")
    if len(v) == 0:
        raise MimicaError(f"{source}: the mesh has no vertices")
    if mesh.n_faces == 0:
        raise MimicaError(f"{source}: the mesh has no faces")
    bad = ~np.isfinite(v).all(axis=1)
    if bad.any():
        raise MimicaError(f"{source}: {int(bad.sum())} vertices have non-finite coordinates "
                          f"(first: vertex {int(np.argmax(bad)) + 1})")
    fi = mesh.face_indices
    if fi.size and (fi.min() < 0 or fi.max() >= len(v)):
        k = int(np.argmax((fi < 0) | (fi >= len(v))))
        face = int(np.searchsorted(mesh.face_starts, k, side="right"))
        raise MimicaError(f"{source}: face {face} refers to vertex {int(fi[k]) + 1}, "
                          f"but the mesh has {len(v)} vertices")
    if (mesh.face_sizes < 3).any():
        face = int(np.argmax(mesh.face_sizes < 3)) + 1
        raise MimicaError(f"{source}: face {face} has fewer than 3 corners")
    if not allow_degenerate:
        used = np.zeros(len(v), bool)
        used[fi] = True
        if not used.all():
            raise MimicaError(f"{source}: {int((~used).sum())} vertices belong to no face (first: vertex "
                              f"{int(np.argmin(used)) + 1}); remove the loose vertices first (Blender: "
                              "Mesh > Clean Up > Delete Loose)")
        t = mesh.triangles
        rep = (t[:, 0] == t[:, 1]) | (t[:, 1] == t[:, 2]) | (t[:, 0] == t[:, 2])
        area2 = np.linalg.norm(mesh.face_normals(), axis=1)
        scale = mesh.bounding_box_diagonal()
        deg = rep | (area2 <= (1e-12 * scale) ** 2)
        if deg.any():
            face = int(mesh.tri_face[np.argmax(deg)]) + 1
            raise MimicaError(f"{source}: {int(deg.sum())} degenerate faces (zero area or a repeated "
                              f"corner; first: face {face}); clean the mesh first")
    return mesh
