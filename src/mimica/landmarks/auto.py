"""Landmarks for any face: from a file, built in for ICT-FaceKit topology, else detected on
renders of the mesh (detect3d)."""

from __future__ import annotations

from ..data import is_ict_topology
from ..errors import MimicaError, NeedsLandmarks
from ..mesh import Mesh
from .core import Landmarks, ict_landmarks, read_landmarks
from .detect3d import detect_mesh


def landmarks_for(mesh: Mesh, path=None, what="mesh") -> Landmarks:
    """A face's 68 landmarks: from a file, else built in for ICT-FaceKit's topology, else found
    on renders of the mesh (landmarks.detect3d: dlib's detector, cast back onto the surface).

    Parameters
    ----------
    mesh : Mesh
        The face.
    path : str or Path or None
        A landmark file (JSON: {"scheme": "ibug68", "points": [[x, y, z], ...]}).
    what : str
        How errors name the mesh.

    Returns
    -------
    Landmarks
        Raises NeedsLandmarks (a MimicaError) where none are given and no face is found.
    """
    if path is not None:
        return read_landmarks(path, mesh)
    if is_ict_topology(mesh):
        return ict_landmarks(mesh)
    from .detect2d import dlib_models
    dlib_models()                                    # dlib missing from a broken install: said as such
    try:
        pts, _ = detect_mesh(mesh, what=what)    # render, find the 68 points, cast them back
        found = Landmarks.snap(mesh, pts)
        found.found = True
        return found
    except MimicaError:
        pass
    raise NeedsLandmarks(f"{what}: not an ICT-FaceKit topology and no face was found in its renders; give its "
                      f"68 landmarks in a file (JSON: {{\"scheme\": \"ibug68\", \"points\": [[x,y,z], ...]}})")
