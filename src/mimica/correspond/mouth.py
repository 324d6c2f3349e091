"""Sealed lips: a head whose mouth is one closed surface cannot open it.

`cut_mouth` finds the seam between the lips -- the shortest path over the mesh's edges from one
inner mouth corner (iBUG 60) through the meeting points of the inner lips (61/67, 62/66,
63/65) to the other corner (64) -- and cuts it: every vertex inside the path is doubled, the
faces below the path take the copies.  The user's vertices keep their order and indices; the
copies are appended.  A mouth that already has an opening (a boundary loop between the lips)
is left alone.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..align import face_cylinder
from ..mesh import Mesh
from ..mesh.graph import edge_graph
from ..mesh.query import concave_angles, shortest_path

WAYPOINTS = [(60,), (61, 67), (62, 66), (63, 65), (64,)]
CREASE = 1.5              # a valley edge costs exp(-CREASE x its concave angle) of its length
VALLEY = np.radians(30)   # a waypoint between the lips moves to a valley vertex this deep ...
SNAP = 0.15               # ... within this share of the mouth's width of its landmarks


@dataclass
class MouthCut:
    """A head's sealed lips cut apart (cut_mouth), or why they were left.

    Attributes
    ----------
    mesh : Mesh
        The cut mesh: the input's vertices first, then the copies.
    copies_of : (k,) int array
        For each appended vertex, the vertex it copies.
    seam : (s,) int array
        The seam's vertices, corner to corner.
    inward : (n + k, 3) float array or None
        Offsets into each seam vertex's own lip (0 elsewhere): where its correspondence is looked up.
    why : str
        Sealed lips left uncut: why (the seam tried is `seam`).
    """
    mesh: Mesh                    # the cut mesh (the input's vertices first, then the copies)
    copies_of: np.ndarray         # (k,) for each appended vertex, the vertex it copies
    seam: np.ndarray              # the seam's vertices, corner to corner
    inward: np.ndarray | None = None   # (n + k, 3) offsets into each seam vertex's own lip (0 elsewhere)
    why: str = ""                 # sealed lips left uncut: why (the seam tried is `seam`)

    @property
    def cut(self) -> bool:
        return len(self.copies_of) > 0


def mouth_is_open(mesh: Mesh, landmarks) -> bool:
    """Whether the mouth already opens: a boundary between the lips at the middle of the mouth (a
    small hole elsewhere, at a corner, does not open it).

    Parameters
    ----------
    mesh : Mesh
    landmarks : (68, 3) float array

    Returns
    -------
    bool
    """
    lm = np.asarray(landmarks, float)
    width = float(np.linalg.norm(lm[64] - lm[60]))
    centre = lm[[62, 66]].mean(0)
    b = mesh.boundary_vertices()
    if not b.any():
        return False
    d = np.linalg.norm(mesh.vertices[b] - centre, axis=1)
    return bool((d < 0.2 * width).any())


def sealed_eyes(mesh: Mesh, landmarks) -> list[str]:
    """The eyes whose lids are one closed surface: no boundary at the eye.

    Parameters
    ----------
    mesh : Mesh
    landmarks : (68, 3) float array

    Returns
    -------
    list of str
        "left", "right".
    """
    lm = np.asarray(landmarks, float)
    b = mesh.boundary_vertices()
    out = []
    for side, rim in (("right", slice(36, 42)), ("left", slice(42, 48))):
        pts = lm[rim]
        if not np.isfinite(pts).all():
            continue
        width = float(np.linalg.norm(pts[3] - pts[0]))
        d = np.linalg.norm(mesh.vertices[b] - pts.mean(0), axis=1) if b.any() else np.zeros(0)
        if not (d < 0.35 * width).any():
            out.append(side)
    return out


def _seam(mesh: Mesh, lm, crease: float = CREASE, valley_corners: bool = False, outer: bool = False) -> np.ndarray:
    """The path of vertices between the lips, corner to corner: from the vertex nearest one
    inner corner (iBUG 60) over the deepest valley vertex near each meeting point of the inner
    lips to the other corner (64), by Dijkstra over edge lengths, an edge in a valley costing
    exp(-crease x its concave angle) of its length: sealed lips meet in a crease, which the
    landmarks (detected ones above all) only come near.  valley_corners: the corners too at the
    deepest valley vertex near them; outer: from the outer corners (48, 54) instead."""
    e = mesh.edges
    v = mesh.vertices
    ang = concave_angles(mesh, e) if crease > 0 else np.zeros(len(e))
    w = np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1) * np.exp(-crease * ang)
    depth = np.zeros(mesh.n_vertices)                 # a vertex's deepest valley edge
    np.maximum.at(depth, e[:, 0], ang)
    np.maximum.at(depth, e[:, 1], ang)
    tree = cKDTree(v)
    reach = SNAP * float(np.linalg.norm(lm[64] - lm[60]))
    stops = []
    waypoints = [(48,)] + WAYPOINTS[1:-1] + [(54,)] if outer else WAYPOINTS
    for k, wp in enumerate(waypoints):
        p = lm[list(wp)].mean(0)
        near = np.array(tree.query_ball_point(p, reach), np.int64)
        near = near[depth[near] > VALLEY] if len(near) else near
        if (k in (0, len(waypoints) - 1) and not valley_corners) or not len(near):
            stops.append(int(tree.query(p)[1]))           # the corners where the landmarks say
        else:
            # between the lips: the deepest valley vertex, the nearer of equally deep ones
            d = np.linalg.norm(v[near] - p, axis=1)
            stops.append(int(near[np.argmax(depth[near] - 1e-3 * d / reach)]))
    g = edge_graph(mesh.n_vertices, e, w)
    path = [stops[0]]
    for a, b in zip(stops[:-1], stops[1:]):
        if a == b:
            continue
        seg = shortest_path(g, a, b)
        if seg is None:
            return np.zeros(0, np.int64)
        path += seg[1:]
    # no vertex twice: waypoints can coincide, and one a little off the valley (landmarks found
    # on a head whose positions a compressed file quantized) sends the path out and back the same
    # way -- the loop is erased, the path kept simple (it was refused as crossing itself)
    out, at = [], {}
    for x in path:
        if x in at:
            for y in out[at[x] + 1:]:
                del at[y]
            del out[at[x] + 1:]
        else:
            at[x] = len(out)
            out.append(x)
    return np.array(out, np.int64)


def cut_mouth(mesh: Mesh, landmarks) -> MouthCut:
    """A head with its lips cut apart along the seam between them (the valley from one inner corner
    to the other); unchanged when the mouth is open.

    Parameters
    ----------
    mesh : Mesh
    landmarks : (68, 3) float array
        The inner lips' (60-67) are needed.

    Returns
    -------
    MouthCut
        `why` says why sealed lips were left uncut.
    """
    lm = np.asarray(landmarks, float)
    none = MouthCut(mesh, np.zeros(0, np.int64), np.zeros(0, np.int64))
    if not np.isfinite(lm[60:68]).all() or mouth_is_open(mesh, lm):
        return none
    first = None
    # the inner corners where the landmarks say; else in the valley; else from the outer corners
    # (detected landmarks on remeshed and coarse heads: the first found no seam on 2 of 13 heads)
    for valley_corners, outer in ((False, False), (True, False), (False, True)):
        cut = _cut_along(mesh, lm, _seam(mesh, lm, valley_corners=valley_corners, outer=outer))
        if cut.cut:
            return cut
        first = first or cut
    return first


def _cut_along(mesh: Mesh, lm: np.ndarray, seam: np.ndarray) -> MouthCut:
    """The mesh cut along this seam (a simple path: _seam erases its loops), or why not."""
    if len(seam) < 3:
        why = "no path over the mesh between the mouth's corners" if len(seam) == 0 else \
            "the mouth's corners are too close on the mesh"
        return MouthCut(mesh, np.zeros(0, np.int64), seam, why=why)
    inner = seam[1:-1]
    # the faces around the seam, split into the two lips: faces meet across shared edges,
    # except the seam's own edges
    fi, st = mesh.face_indices, mesh.face_starts
    face_of = np.repeat(np.arange(mesh.n_faces), np.diff(st))
    on = np.isin(fi, inner)
    faces = np.unique(face_of[on])
    seam_edges = {frozenset(p) for p in zip(seam[:-1], seam[1:])}
    edge_faces = {}
    for f in faces:
        c = fi[st[f]:st[f + 1]]
        for a, b in zip(c, np.roll(c, -1)):
            key = frozenset((int(a), int(b)))
            if key not in seam_edges:
                edge_faces.setdefault(key, []).append(f)
    pos = {f: k for k, f in enumerate(faces)}
    rows, cols = [], []
    for fs in edge_faces.values():
        for a in fs:
            for b in fs:
                if a != b:
                    rows.append(pos[a])
                    cols.append(pos[b])
    adj = sp.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(len(faces),) * 2).tocsr()
    nc, comp = connected_components(adj, directed=False)
    up = face_cylinder(lm).axes[1]
    cent = mesh.face_centroids()[faces]
    # each face's side: above or below the seam where it touches it
    seam_pos = mesh.vertices[inner]
    near = cKDTree(seam_pos).query(cent)[1]
    below_face = (cent - seam_pos[near]) @ up < 0
    below_comp = np.array([below_face[comp == c].mean() > 0.5 for c in range(nc)])
    if below_comp.all() or not below_comp.any():   # not two lips: leave the mesh alone
        return MouthCut(mesh, np.zeros(0, np.int64), seam,
                        why="the path found between the mouth's corners does not part an upper from a lower lip")
    copy = np.full(mesh.n_vertices, -1, np.int64)
    copy[inner] = mesh.n_vertices + np.arange(len(inner))
    new_fi = fi.copy()
    lower_faces = faces[below_comp[comp]]
    sel = np.isin(face_of, lower_faces) & on
    new_fi[sel] = copy[fi[sel]]
    v = np.vstack([mesh.vertices, mesh.vertices[inner]])
    cut = Mesh(v, new_fi, st, name=mesh.name, groups=mesh.groups, group_names=mesh.group_names, layout=mesh.layout)
    if mesh.uv is not None and mesh.face_uv_indices is not None:
        cut.uv, cut.face_uv_indices = mesh.uv, mesh.face_uv_indices
    # where each side's seam vertex sits inside its own lip: half way to its faces' centroids
    # (a correspondence looks the two copies up there, so each follows its own lip)
    inward = np.zeros_like(v)
    centroids = cut.face_centroids()
    for ids in (inner, copy[inner]):
        hit = np.isin(new_fi, ids)
        sums = np.zeros_like(v)
        cnt = np.zeros(len(v))
        np.add.at(sums, new_fi[hit], centroids[face_of[hit]])
        np.add.at(cnt, new_fi[hit], 1)
        inward[ids] = 0.5 * (sums[ids] / np.maximum(cnt[ids], 1)[:, None] - v[ids])
    return MouthCut(cut, inner.copy(), seam, inward)
