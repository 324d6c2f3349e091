"""Landmarks for any face: from a file, built in for ICT-FaceKit topology, else detected on
renders of the mesh (detect3d)."""

from __future__ import annotations

from ..data import is_ict_topology
from ..errors import MimicaError, NeedsLandmarks
from ..mesh import Mesh
from .core import Landmarks, ict_landmarks, read_landmarks
from .detect3d import detect_mesh


def landmarks_for(mesh: Mesh, path=None, what="mesh") -> Landmarks:
    """Landmarks from a file, else built in for ICT-FaceKit topology, else a clear error."""
    if path is not None:
        return read_landmarks(path, mesh)
    if is_ict_topology(mesh):
        return ict_landmarks(mesh)
    from .detect2d import _models
    _models()                                    # dlib missing from a broken install: said as such
    try:
        pts, _ = detect_mesh(mesh, what=what)    # render, find the 68 points, cast them back
        return Landmarks.snap(mesh, pts)
    except MimicaError:
        pass
    raise NeedsLandmarks(f"{what}: not an ICT-FaceKit topology and no face was found in its renders; give its "
                      f"68 landmarks in a file (JSON: {{\"scheme\": \"ibug68\", \"points\": [[x,y,z], ...]}})")
