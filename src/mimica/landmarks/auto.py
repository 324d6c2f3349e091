"""Landmarks for any face: from a file, built in for ICT-FaceKit topology, else detected on
renders of the mesh (detect3d)."""

from __future__ import annotations

from ..data import is_ict_topology
from ..errors import MimicaError
from ..mesh import Mesh
from .core import Landmarks, ict_landmarks, read_landmarks
from .detect3d import detect_mesh


def landmarks_for(mesh: Mesh, path=None, what="mesh") -> Landmarks:
    """Landmarks from a file, else built in for ICT-FaceKit topology, else a clear error."""
    if path is not None:
        return read_landmarks(path, mesh)
    if is_ict_topology(mesh):
        return ict_landmarks(mesh)
    import importlib.util
    if importlib.util.find_spec("dlib") is None or importlib.util.find_spec("face_recognition_models") is None:
        raise MimicaError(f"{what}: not an ICT-FaceKit topology, so its 68 landmarks are found on renders of it, "
                          "which needs the photo extra (dlib's face detector): pip install 'mimica[photo]'; "
                          "or give its landmarks in a file (JSON: {\"scheme\": \"ibug68\", \"points\": [[x,y,z], ...]})")
    try:
        pts, _ = detect_mesh(mesh, what=what)    # render, find the 68 points, cast them back
        return Landmarks.snap(mesh, pts)
    except MimicaError:
        pass
    raise MimicaError(f"{what}: not an ICT-FaceKit topology and no face was found in its renders; give its "
                      f"68 landmarks in a file (JSON: {{\"scheme\": \"ibug68\", \"points\": [[x,y,z], ...]}})")
