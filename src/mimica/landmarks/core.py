"""The landmark types and files (see the package docstring for the format)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..data import ICT_LANDMARKS_68
from ..errors import MimicaError
from ..mesh import Mesh, atomic_path, read_json
from ..mesh.query import TriangleLocator

SCHEME = "ibug68"
N_POINTS = 68
# iBUG 68 groups (0-based): jaw 0-16, brows 17-26, nose 27-35, eyes 36-47, mouth 48-67;
# "right" is the subject's right (image left).
NAMES = ([f"jaw.{i}" for i in range(17)] + [f"brow.right.{i}" for i in range(5)]
         + [f"brow.left.{i}" for i in range(5)] + [f"nose.bridge.{i}" for i in range(4)]
         + [f"nose.base.{i}" for i in range(5)] + [f"eye.right.{i}" for i in range(6)]
         + [f"eye.left.{i}" for i in range(6)] + [f"mouth.outer.{i}" for i in range(12)]
         + [f"mouth.inner.{i}" for i in range(8)])



def _mirror_pairs() -> np.ndarray:
    pair = {i: 16 - i for i in range(17)}                                      # jaw
    pair.update({17 + i: 26 - i for i in range(5)})                            # brows
    pair.update({27: 27, 28: 28, 29: 29, 30: 30, 31: 35, 32: 34, 33: 33})      # nose
    pair.update({36: 45, 37: 44, 38: 43, 39: 42, 40: 47, 41: 46})              # eyes
    pair.update({48: 54, 49: 53, 50: 52, 51: 51, 55: 59, 56: 58, 57: 57,       # mouth
                 60: 64, 61: 63, 62: 62, 65: 67, 66: 66})
    pair.update({v: k for k, v in list(pair.items())})
    return np.array([pair[i] for i in range(68)])


# MIRROR[i]: the landmark that is i's mirror image across the face's mid-plane
MIRROR = _mirror_pairs()


def index(name: str) -> int:
    """The index of a canonical landmark name.

    Parameters
    ----------
    name : str
        'part.side.k' or 'part.k', e.g. 'eye.left.0' (-> 42) or 'jaw.8' (-> 8).

    Returns
    -------
    int
        0 to 67 in the iBUG 68 order; MimicaError for an unknown name.
    """
    try:
        return NAMES.index(name)
    except ValueError:
        raise MimicaError(f"unknown landmark name {name!r}; names look like 'eye.left.0', 'jaw.8'") from None


@dataclass
class Landmarks:
    """The 68 iBUG landmarks on a mesh, as points of its triangles: they follow the mesh through
    any deformation of its vertices.

    Attributes
    ----------
    triangle : (68,) int array
        Each point's triangle (an index into `mesh.triangles`), -1 where missing.
    bary : (68, 3) float array
        Its barycentric coordinates in that triangle.
    scheme : str
        "ibug68".
    found : bool
        Found on renders (landmarks_for's detector), not given: where they sit off a sealed eye's
        margin, correspond.eyes may slide them onto it.
    """

    triangle: np.ndarray      # (68,) int, -1 = missing
    bary: np.ndarray          # (68, 3)
    scheme: str = SCHEME
    found: bool = False

    @property
    def present(self) -> np.ndarray:
        return self.triangle >= 0

    def positions(self, mesh: Mesh, vertices=None) -> np.ndarray:
        """(68, 3) positions on `mesh` (or on `vertices` of the same topology); NaN where missing."""
        return self.positions_in(mesh, np.asarray(mesh.vertices if vertices is None else vertices)[None])[0]

    def positions_in(self, mesh: Mesh, frames: np.ndarray) -> np.ndarray:
        """(F, 68, 3) positions in every frame (F, n, 3) of `mesh`'s topology; NaN where missing."""
        frames = np.asarray(frames)
        out = np.full((len(frames), N_POINTS, 3), np.nan)
        ok = self.present
        t = mesh.triangles[self.triangle[ok]]
        out[:, ok] = np.einsum("ij,fijk->fik", self.bary[ok], frames[:, t])
        return out

    @classmethod
    def from_vertex_indices(cls, mesh: Mesh, indices) -> "Landmarks":
        """Landmarks sitting exactly on given vertices (-1 for missing)."""
        indices = np.asarray(indices, dtype=np.int64)
        tri_of_vertex = np.full(mesh.n_vertices, -1, dtype=np.int64)
        corner = np.full(mesh.n_vertices, -1, dtype=np.int64)
        t = mesh.triangles
        for k in range(3):
            tri_of_vertex[t[:, k]] = np.arange(len(t))
            corner[t[:, k]] = k
        tri = np.where(indices >= 0, tri_of_vertex[np.maximum(indices, 0)], -1)
        bary = np.zeros((len(indices), 3))
        ok = tri >= 0
        bary[np.nonzero(ok)[0], corner[indices[ok]]] = 1.0
        return cls(tri, bary)

    @classmethod
    def snap(cls, mesh: Mesh, points) -> "Landmarks":
        """Snap (68, 3) points (NaN rows = missing) to the closest surface points."""
        return cls.snap_with_distance(mesh, points)[0]

    @classmethod
    def snap_with_distance(cls, mesh: Mesh, points) -> tuple["Landmarks", np.ndarray]:
        """`snap`, and each point's distance to the surface (NaN where missing)."""
        p = np.asarray(points, dtype=np.float64)
        tri = np.full(len(p), -1, dtype=np.int64)
        bary = np.zeros((len(p), 3))
        dist = np.full(len(p), np.nan)
        ok = np.isfinite(p).all(axis=1)
        if ok.any():
            t, b, _, d = TriangleLocator(mesh.vertices, mesh.triangles).closest(p[ok])
            tri[ok], bary[ok], dist[ok] = t, b, d
        return cls(tri, bary), dist


def ict_landmarks(mesh: Mesh) -> Landmarks:
    """The built-in ICT-FaceKit landmarks (its upstream README's vertices).

    Parameters
    ----------
    mesh : Mesh
        A mesh of ICT-FaceKit's topology (any identity or expression).

    Returns
    -------
    Landmarks
    """
    return Landmarks.from_vertex_indices(mesh, ICT_LANDMARKS_68)


def read_point_file(path, scheme: str, dim: int, allow_null: bool, example: str = "...") -> np.ndarray:
    """The 68 points of a landmark JSON file of the given scheme; every problem is one line naming
    the file.

    Parameters
    ----------
    path : str or Path
        {"scheme": scheme, "points": [...68 entries...]}.
    scheme : str
        The scheme expected ("ibug68" for meshes, "ibug68-image" for photos).
    dim : int
        3 for positions, 2 for pixels.
    allow_null : bool
        A null entry (a point not given) is allowed, as a NaN row.
    example : str
        How the message shows the points.

    Returns
    -------
    (68, dim) float array
    """
    path = Path(path)
    doc = read_json(path, "landmark file")
    if not isinstance(doc, dict) or doc.get("scheme") != scheme:
        raise MimicaError(f"{path}: expected {{\"scheme\": \"{scheme}\", \"points\": [{example}]}}")
    pts = doc.get("points")
    if not isinstance(pts, list) or len(pts) != N_POINTS:
        raise MimicaError(f"{path}: 'points' must list {N_POINTS} entries, got "
                          f"{len(pts) if isinstance(pts, list) else type(pts).__name__}")
    out = np.full((N_POINTS, dim), np.nan)
    coords = "[" + ", ".join("xyz"[:dim]) + "]"
    for i, q in enumerate(pts):
        if q is None and allow_null:
            continue
        if (not isinstance(q, list) or len(q) != dim
                or not all(isinstance(c, (int, float)) and not isinstance(c, bool) and np.isfinite(c) for c in q)):
            raise MimicaError(f"{path}: point {i} must be {coords} with finite numbers"
                              + (", or null" if allow_null else ""))
        out[i] = q
    return out


def read_landmarks(path, mesh: Mesh | None = None):
    """Read a landmark JSON file ({"scheme": "ibug68", "points": [[x, y, z] or null, ...]}).

    Parameters
    ----------
    path : str or Path
        At least 4 points given, not all on one spot.
    mesh : Mesh or None
        The mesh they lie on: the points are then snapped onto its surface.

    Returns
    -------
    (68, 3) float array or Landmarks
        The positions (NaN rows: missing) without a mesh; Landmarks on the mesh with one.
    """
    out = read_point_file(path, SCHEME, 3, allow_null=True)
    ok = np.isfinite(out).all(axis=1)
    if ok.sum() < 4:
        raise MimicaError(f"{path}: at least 4 points are needed, {int(ok.sum())} given")
    if mesh is None:
        return out
    size = mesh.bounding_box_diagonal()
    if np.ptp(out[ok], axis=0).max() < 0.05 * size:
        raise MimicaError(f"{path}: the points nearly coincide (they span under 5% of the mesh's size); "
                          "each landmark is its own place on the face")
    lm, dist = Landmarks.snap_with_distance(mesh, out)
    if np.nanmax(dist) > 0.1 * size:
        i = int(np.nanargmax(dist))
        raise MimicaError(f"{path}: point {i} lies {dist[i]:.3g} off the mesh's surface (the mesh is "
                          f"{size:.3g} across); landmarks are in the mesh's own coordinates")
    return lm


def write_landmarks(path, positions) -> Path:
    """Write 68 landmark positions as a landmark JSON file, whole or not at all.

    Parameters
    ----------
    path : str or Path
    positions : (68, 3) float array
        NaN rows are written as null (a point not given).

    Returns
    -------
    Path
    """
    pts = [None if not np.isfinite(p).all() else [float(c) for c in p] for p in np.asarray(positions)]
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps({"scheme": SCHEME, "points": pts}, indent=1) + "\n")
    return path
