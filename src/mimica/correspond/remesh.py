"""Resample a face surface with a new, unrelated triangulation (for tests and the demo); the
result is a correspondence to the original (a triangle and barycentric coordinates a vertex).

Samples a jittered grid in the face's cylinder map, triangulates it (Delaunay), lifts every
sample onto the outermost layer of the original surface, and cuts holes where the original
has none of its own (nostrils on request).  Each new vertex keeps the original triangle and
barycentric coordinates it was lifted from, so any shape of the original topology (an
expression, an identity) can be carried over exactly: ``bary-interpolate(shape)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.spatial import Delaunay, cKDTree

from ..align import face_cylinder
from ..mesh.core import Mesh
from ..mesh.query import SurfaceMap


@dataclass
class Resampled:
    """A face remeshed (resample_face) and where each new vertex lies on the original.

    Attributes
    ----------
    mesh : Mesh
        The new mesh.
    triangle : (n,) int array
        The original's triangle (of `original_triangles`) under each new vertex.
    bary : (n, 3) float array
    original_triangles : (m, 3) int array
    """
    mesh: Mesh
    triangle: np.ndarray      # (n,) triangle of the original's `triangles` under each vertex
    bary: np.ndarray          # (n, 3)
    original_triangles: np.ndarray

    def carry(self, vertices: np.ndarray) -> np.ndarray:
        """Positions (n_orig, 3) of any shape of the original topology -> the new vertices."""
        t = self.original_triangles[self.triangle]
        return np.einsum("ij,ijk->ik", self.bary, vertices[t])


# the openings a resampled face can have sealed (iBUG 68 contours: inner lips to the mouth's
# corners, each eye's rim)
SEALS = {"mouth": [list(range(60, 68)) + [48, 54]], "eyes": [list(range(36, 42)), list(range(42, 48))]}


def resample_face(mesh: Mesh, landmarks: np.ndarray, n_vertices: int = 12000, seed: int = 0,
                  nostril_holes: bool = True, rings: int = 6, seal=(), pins=()) -> Resampled:
    """A face remeshed to another topology of about `n_vertices` (for tests and benchmarks with a
    known truth): points spread evenly on its cylinder map, triangulated, lifted onto the surface.

    Parameters
    ----------
    mesh : Mesh
    landmarks : (68, 3) float array
    n_vertices : int
    seed : int
    nostril_holes : bool
        Leave the nostrils open.
    rings : int
        Rings of points kept along the openings' rims.
    seal : tuple of str
        Openings ("mouth", "eyes") bridged by the new triangulation instead of cut, as scans and
        game heads have them: the lips (or lids) joined by a membrane of triangles.
    pins : sequence of int
        Landmarks (indices into `landmarks`, points on the surface) that become vertices, the
        samples within half a step of each giving way: a truth carried to the new mesh then sits
        where the original's does, not up to half an edge beside it.

    Returns
    -------
    Resampled
    """
    rng = np.random.default_rng(seed)
    cyl = face_cylinder(landmarks)
    uv, r = cyl.project(mesh.vertices)
    tri = mesh.triangles
    smap = SurfaceMap(tri, uv, r, mesh.vertices, max_span=np.pi * cyl.radius)
    a = uv[tri[smap.usable]]
    area2d = 0.5 * np.abs((a[:, 1, 0] - a[:, 0, 0]) * (a[:, 2, 1] - a[:, 0, 1])
                          - (a[:, 2, 0] - a[:, 0, 0]) * (a[:, 1, 1] - a[:, 0, 1]))
    h = np.sqrt(area2d.sum() / n_vertices)
    lo, hi = uv.min(0), uv.max(0)
    gx, gy = np.meshgrid(np.arange(lo[0], hi[0], h), np.arange(lo[1], hi[1], h * np.sqrt(3) / 2))
    gx = gx + (np.arange(gx.shape[0])[:, None] % 2) * h / 2          # hexagonal grid
    pts = np.stack([gx.ravel(), gy.ravel()], 1) + rng.uniform(-0.2, 0.2, (gx.size, 2)) * h
    pinned = np.asarray(landmarks, float)[list(pins)]
    if len(pins):
        pin_uv = cyl.project(pinned)[0]
        near = cKDTree(pin_uv).query(pts)[0] < 0.5 * h
        pts = np.vstack([pts[~near], pin_uv])

    def outermost(q):
        """Outermost original triangle under 2D points q: (triangle, bary, found)."""
        return smap.locate(q, k=24)

    t_of, b_of, keep = outermost(pts)
    if len(pins):                           # a pin on its own point, not the outermost surface under it
        from ..mesh.query import TriangleLocator
        at = TriangleLocator(mesh.vertices, tri).closest(pinned)
        t_of[-len(pins):], b_of[-len(pins):], keep[-len(pins):] = at[0], at[1], True
    pts, t_of, b_of = pts[keep], t_of[keep], b_of[keep]
    v3 = np.einsum("ij,ijk->ik", b_of, mesh.vertices[tri[t_of]])
    # triangulate in the cylinder map; a triangle whose centroid or edge midpoints fall where
    # the original has no surface (eyes, mouth, the seam at the back) is a hole
    d = Delaunay(pts).simplices
    probes = [pts[d].mean(1)] + [0.5 * (pts[d[:, i]] + pts[d[:, (i + 1) % 3]]) for i in range(3)]
    ok = np.ones(len(d), bool)
    for q in probes:
        ok &= outermost(q)[2]
    # a triangle must not bridge parts that the original keeps apart (closed lips, lids):
    # the original vertices under its corners must lie within a few rings of each other
    near_v = tri[t_of, np.argmax(b_of, 1)]
    reach = sp.identity(mesh.n_vertices, format="csr") + mesh.adjacency
    ring = reach
    for _ in range(rings - 1):
        ring = (ring @ reach).tocsr()
        ring.data[:] = 1
    for i in range(3):
        ok &= np.asarray(ring[near_v[d[:, i]], near_v[d[:, (i + 1) % 3]]]).ravel() > 0
    lm_uv = cyl.project(np.asarray(landmarks, float))[0]
    for region in seal:
        for contour in SEALS[region]:
            # the rim's hull grown by about a grid step each way: the row of triangles that
            # bridges the opening (a closed mouth's inner rim is nearly a line)
            poly = lm_uv[contour]
            grow = 1.5 * h * np.array([[1, 0], [-1, 0], [0, 1], [0, -1]])
            ok |= Delaunay((poly[:, None] + grow[None]).reshape(-1, 2)).find_simplex(probes[0]) >= 0
    faces = d[ok]
    if nostril_holes:
        lm = np.asarray(landmarks)
        width = np.linalg.norm(lm[35] - lm[31])
        for a_, b_ in ((31, 33), (33, 35)):
            c = 0.5 * (lm[a_] + lm[b_]) + 0.1 * width * cyl.axes[1]
            near = np.linalg.norm(v3 - c, axis=1) < 0.17 * width
            faces = faces[~near[faces].any(1)]
    # orient like the original (normals outward, away from the axis)
    n = np.cross(v3[faces[:, 1]] - v3[faces[:, 0]], v3[faces[:, 2]] - v3[faces[:, 0]])
    out = v3[faces].mean(1) - cyl.origin
    out -= np.outer(out @ cyl.axes[1], cyl.axes[1])
    flip = np.einsum("ij,ij->i", n, out) < 0
    faces[flip] = faces[flip][:, ::-1]
    used = np.unique(faces)
    remap = np.full(len(v3), -1)
    remap[used] = np.arange(len(used))
    new = Mesh.from_faces(v3[used], remap[faces], name=mesh.name + "_remeshed")
    return Resampled(new, t_of[used], b_of[used], tri)

