"""Eyes that are one surface with the lids (Basel- or Surrey-style morphable models, scans): the
skin runs on from each lid over the eyeball's front, so a blink can only crease the lid.

`cut_eyes` finds each sealed eye's inside -- the faces that, seen from the front, lie within
the polygon of the eye's six landmarks (iBUG 36-41, 42-47), the one piece around its centre --
and cuts it loose from the lids: the vertices where it meets them (the lid margin) are doubled,
the faces inside take the copies.  (A shortest path through the landmarks along the fold of
the lid was tried first: on remeshed heads it ran below the upper lid's landmarks, which then
rode with the eye; the blink closed 0.07-0.84 of the gap.)  That inside is then the eye, a rigid part the lids close
over (correspond.parts: `eyes`).  The user's vertices keep their order; copies are appended.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.sparse.csgraph import connected_components

from ..mesh import Mesh
from scipy.spatial import cKDTree

RIMS = {"right": list(range(36, 42)), "left": list(range(42, 48))}
CAP_SHARE = 0.1           # an eye's inside is under this share of the mesh's faces
OPEN = 0.18               # an eye shaped open: its lids' gap (37-41, 38-40) over its width at least this
INSIDE = 3                # ... and resolved: at least this many vertices inside its margin
# (ICT's identities remeshed at 20k vertices: gap 0.27-0.31 of the width, 4-9 vertices inside;
# the shared 468-vertex head's sealed eyes: one vertex inside, a fan in front of the lids which,
# cut loose, stood out of every blink with the void behind it showing)


@dataclass
class EyeCut:
    """A head's one-surface eyes cut loose from their lids (cut_eyes), or why not.

    Attributes
    ----------
    mesh : Mesh
        The cut mesh: the input's vertices first, then the copies.
    copies_of : (k,) int array
        For each appended vertex, the vertex it copies.
    eyes : dict
        Side -> the vertices of its eye (the copies included).
    rims : dict
        Side -> the lid margin's loop (the lids' vertices).
    why : dict
        Side -> why a sealed eye was left whole.
    """
    mesh: Mesh                         # the cut mesh: the input's vertices first, then the copies
    copies_of: np.ndarray              # (k,) for each appended vertex, the vertex it copies
    eyes: dict = field(default_factory=dict)      # side -> vertices of its eye (the copies included)
    rims: dict = field(default_factory=dict)      # side -> the lid margin's loop (the lids' vertices)
    why: dict = field(default_factory=dict)       # side -> why a sealed eye was left whole

    @property
    def cut(self) -> bool:
        return len(self.copies_of) > 0


def inside_polygon(q: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Whether 2D points lie inside a closed polygon: the even-odd rule, one ray to +x a point (a few
    lines, not a plotting library's).

    Parameters
    ----------
    q : (m, 2) float array
    poly : (k, 2) float array

    Returns
    -------
    (m,) bool array
    """
    x, y = q[:, :1], q[:, 1:]
    a, b = poly, np.roll(poly, -1, axis=0)
    cross = (a[:, 1] > y) != (b[:, 1] > y)
    xt = a[:, 0] + (y - a[:, 1]) * (b[:, 0] - a[:, 0]) / np.where(b[:, 1] == a[:, 1], 1e-300, b[:, 1] - a[:, 1])
    return (cross & (x < xt)).sum(1) % 2 == 1


def _eye_faces(mesh: Mesh, pts: np.ndarray, fwd: np.ndarray) -> np.ndarray | None:
    """The faces of the eye: those whose centre, seen from the front, lies inside the polygon of
    the eye's six landmarks, on the front of the face near them (the one piece around the
    eye's centre).  None when they are not one piece of the surface."""
    centre = pts.mean(0)
    across = pts[3] - pts[0]
    width = float(np.linalg.norm(across))
    ex = across / width
    ey = np.cross(fwd, ex)
    cent = mesh.face_centroids()
    rel = cent - centre
    nrm = np.zeros((mesh.n_faces, 3))
    np.add.at(nrm, mesh.tri_face, mesh.face_normals())
    depth = rel @ fwd
    # on the front near the landmarks: not a socket behind an eyeball, nor the back of the head
    near = (np.linalg.norm(rel, axis=1) < 0.8 * width) & (nrm @ fwd > 0) & (depth > -0.15 * width) \
        & (depth < 0.4 * width)
    q = np.stack([rel @ ex, rel @ ey], 1)
    poly = np.stack([(pts - centre) @ ex, (pts - centre) @ ey], 1)
    inside = near & inside_polygon(q, poly)
    # the landmarks mark the lids' margin: the faces under them are the lids'
    from ..mesh.query import TriangleLocator
    under, _, _, _ = TriangleLocator(mesh.vertices, mesh.triangles).closest(pts)
    lid_faces = mesh.tri_face[under]
    inside[lid_faces] = False
    # ... and the margin runs through them: a landmark's nearest vertex gets the face at it
    # nearest the eye's centre, where none of its faces is the eye's
    face_of = np.repeat(np.arange(mesh.n_faces), mesh.face_sizes)
    for p in pts:
        v = int(np.argmin(np.linalg.norm(mesh.vertices - p, axis=1)))
        fan = np.unique(face_of[mesh.face_indices == v])
        fan = fan[near[fan] & ~np.isin(fan, lid_faces)]
        if len(fan) and not inside[fan].any():
            inside[fan[np.argmin(np.linalg.norm(cent[fan] - centre, axis=1))]] = True
    # the eye runs on from the lids, one piece of surface with them; a head with an eyeball of
    # its own in the opening (behind which the lids run on into a socket) has nothing to cut
    piece = _pieces(mesh)
    own = np.isin(piece, piece[lid_faces])
    if (inside & ~own).any():
        return None
    inside &= own
    if not inside.any():
        return None
    # the one piece: faces inside that share edges with each other, around the centre
    faces = np.nonzero(inside)[0]
    comp = _pieces(mesh.submesh(faces)[0])
    middle = int(np.argmin(np.linalg.norm(cent[faces] - centre, axis=1)))
    return faces[comp == comp[middle]]


def _pieces(mesh: Mesh) -> np.ndarray:
    """(n_faces,) the connected piece of the surface each face is in."""
    _, comp = connected_components(mesh.adjacency, directed=False)
    return comp[mesh.face_indices[mesh.face_starts[:-1]]]


def _closed_over(mesh: Mesh, lm: np.ndarray) -> list[str]:
    """The eyes no boundary runs along: a boundary near fewer than 4 of its 6 landmarks (a small
    hole at a corner does not open an eye)."""
    b = mesh.boundary_vertices()
    tree = cKDTree(mesh.vertices[b]) if b.any() else None
    out = []
    for side, rim in RIMS.items():
        pts = lm[rim]
        if not np.isfinite(pts).all():
            continue
        width = float(np.linalg.norm(pts[3] - pts[0]))
        d = tree.query(pts)[0] if tree is not None else np.full(len(pts), np.inf)
        if (d < 0.25 * width).sum() < 4:
            out.append(side)
    return out


def cut_eyes(mesh: Mesh, landmarks) -> EyeCut:
    """A head with each sealed eye's inside cut loose from its lids along their margin; unchanged
    where the eyes open already (a boundary at the lids) or the landmarks are missing.

    Parameters
    ----------
    mesh : Mesh
    landmarks : (68, 3) float array

    Returns
    -------
    EyeCut
    """
    from ..align import face_cylinder
    lm = np.asarray(landmarks, float)
    out = EyeCut(mesh, np.zeros(0, np.int64))
    shut = _closed_over(mesh, lm)
    if not shut:
        return out
    fwd = face_cylinder(lm).axes[2]
    fi, st = mesh.face_indices.copy(), mesh.face_starts
    face_of = np.repeat(np.arange(mesh.n_faces), np.diff(st))
    verts = [mesh.vertices]
    copies, n = [], mesh.n_vertices
    for side in shut:
        pts = lm[RIMS[side]]
        gap = 0.5 * (np.linalg.norm(pts[1] - pts[5]) + np.linalg.norm(pts[2] - pts[4]))
        if gap < OPEN * np.linalg.norm(pts[3] - pts[0]):
            continue                               # a shut eye: nothing to open
        inside = _eye_faces(Mesh(np.vstack(verts), fi, st), pts, fwd)
        if inside is None or len(inside) > CAP_SHARE * mesh.n_faces:
            out.why[side] = "no piece of the surface inside the eye's landmarks"
            continue
        is_in = np.zeros(mesh.n_faces, bool)
        is_in[inside] = True
        corner_in = is_in[face_of]
        on_both = np.intersect1d(np.unique(fi[corner_in]), np.unique(fi[~corner_in]))   # the margin
        if len(on_both) < 6:
            out.why[side] = "the eye's inside meets its lids at too few vertices"
            continue
        if len(np.unique(fi[corner_in])) - len(on_both) < INSIDE:
            out.why[side] = f"fewer than {INSIDE} vertices inside its lids' margin: too coarse to be an eye of its own"
            continue
        copy = np.full(len(np.vstack(verts)), -1)
        copy[on_both] = n + np.arange(len(on_both))
        sel = corner_in & np.isin(fi, on_both)
        fi[sel] = copy[fi[sel]]
        verts.append(mesh.vertices[on_both])
        copies.append(on_both)
        out.eyes[side] = np.unique(fi[corner_in])
        out.rims[side] = on_both
        n += len(on_both)
    if not copies:
        return out
    cut = Mesh(np.vstack(verts), fi, st, name=mesh.name, groups=mesh.groups, group_names=mesh.group_names,
               layout=mesh.layout)
    if mesh.uv is not None and mesh.face_uv_indices is not None:
        cut.uv, cut.face_uv_indices = mesh.uv, mesh.face_uv_indices
    out.mesh, out.copies_of = cut, np.concatenate(copies)
    return out
