"""The parts of a head (DESIGN.md, `Parts`): skin, eyeballs, teeth, gums and tongue, and the
parts that ride on the skin (lashes, tear and occlusion shells, sockets, anything else).

Correspondence is skin to skin only; every other part gets a role saying how it moves when
an expression is transferred:

- `skull`: stays (upper teeth and gums),
- `jaw`: the jaw's rigid motion (lower teeth and gums, tongue),
- `eye.left` / `eye.right`: rigid, rotating about the eyeball's centre,
- `follow`: rides on the skin (lashes, shells, brow cards: transfer.parts),
- `pocket`: the skin's pockets behind the lips and lids (a mouth bag, eye sockets), moving as
  the source's.

How parts are found: ICT-FaceKit's own topology from its table (README.upstream.md, "Face
Model Topology"); any other head from its connected components and OBJ materials/groups:
the skin is the component with the largest area (less the pockets joined to its lips and
lids: what a loop along the inner lips or an eye's rim cuts off behind them); a component
named like an eye, tooth, gum or tongue part or a mouth's inside (material or group names), or
shaped like one where the landmarks say (a sphere behind an eye; a piece inside the mouth; one
whose open edge runs along the inner lips), gets that role; the rest follow.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..align import face_cylinder
from ..mesh import Mesh
from ..mesh.graph import HarmonicFill, edge_graph

SKIN, SKULL, JAW, EYE_LEFT, EYE_RIGHT, FOLLOW = "skin", "skull", "jaw", "eye.left", "eye.right", "follow"
POCKET = "pocket"
ROLES = (SKIN, SKULL, JAW, EYE_LEFT, EYE_RIGHT, FOLLOW, POCKET)

# ICT-FaceKit's geometries (vertex ranges, end exclusive) and what each is
ICT_PARTS = [("skin", 0, 11248), ("mouth socket", 11248, 13294), ("eye socket", 13294, 14062),
             ("gums and tongue", 14062, 17039), ("teeth", 17039, 21451), ("eyeball.left", 21451, 23021),
             ("eyeball.right", 23021, 24591), ("tear shells", 24591, 25047), ("occlusion shells", 25047, 25351),
             ("lashes", 25351, 26719)]
OCCLUSAL_TILT_DEG = 5.0
LINING, SOCKET = "inside of the mouth", "eye socket"
ICT_SKIN_FACES = 11144                       # polygons [0:11144) are the face, head and neck

_NAMED = [(re.compile(r"teeth|tooth|dent", re.I), "teeth"), (re.compile(r"gum|tongue", re.I), "gums and tongue"),
          (re.compile(r"sclera|iris|pupil|cornea|eyeball|eye_?ball", re.I), "eyeball"),
          (re.compile(r"lash", re.I), "lashes"), (re.compile(r"brow", re.I), "brows"),
          (re.compile(r"lacrimal|tear|occlusion|eye_?blend|meniscus", re.I), "eye shells"),
          (re.compile(r"mouth|oral|cavity|throat", re.I), LINING)]


@dataclass
class Parts:
    """A head split into parts: per vertex its part and its role.

    Attributes
    ----------
    label : (n,) int array
        The part of each vertex.
    names : list of str
        The name of each part.
    role : (n,) int array
        Index into ROLES: skin, skull (still with the head), jaw (moves with it), the left and
        right eye (rigid), follow (lashes, shells: ride with the skin), pocket (a mouth bag, eye
        sockets: move as the source's).
    skin_faces : (f,) int array
        The skin's polygons (all their corners skin).
    jaw_weight : (n,) float array or None
        Where a piece spans both arches (gums and tongue as one): how much of the jaw's motion
        each of its vertices takes, 0 to 1 (NaN elsewhere); None where no piece does.
    """

    label: np.ndarray            # (n,) part index of each vertex
    names: list                  # name of each part
    role: np.ndarray             # (n,) index into ROLES
    skin_faces: np.ndarray       # polygon indices of the skin (all their corners skin)
    jaw_weight: np.ndarray | None = None

    @property
    def skin(self) -> np.ndarray:
        return self.role == ROLES.index(SKIN)

    def of(self, role: str) -> np.ndarray:
        """Vertex indices with this role."""
        return np.nonzero(self.role == ROLES.index(role))[0]

    @property
    def only_skin(self) -> bool:
        return bool(self.skin.all())

    def summary(self) -> str:
        """One line: each part and its vertex count."""
        counts = np.bincount(self.label, minlength=len(self.names))
        seen = {}
        for n, c in zip(self.names, counts):
            if c:
                seen[n] = seen.get(n, 0) + int(c)
        return ", ".join(f"{n} {c:,}" for n, c in seen.items())


def _eye_centres(lm):
    """Centres of the left and right eye from the 68 landmarks (eye.left: points 42-47)."""
    lm = np.asarray(lm, float)
    return {EYE_LEFT: np.nanmean(lm[42:48], axis=0), EYE_RIGHT: np.nanmean(lm[36:42], axis=0)}


def fit_sphere(p):
    """The least-squares sphere through points.

    Parameters
    ----------
    p : (m, 3) float array

    Returns
    -------
    centre : (3,) float array
    radius : float
    residual : float
        RMS residual over the radius.
    """
    a = np.c_[2 * p, np.ones(len(p))]
    x, *_ = np.linalg.lstsq(a, (p * p).sum(1), rcond=None)
    c = x[:3]
    r = float(np.sqrt(max(x[3] + c @ c, 0.0)))
    res = float(np.sqrt(((np.linalg.norm(p - c, axis=1) - r) ** 2).mean())) / max(r, 1e-300)
    return c, r, res


def _mouth_frame(lm):
    """Face axes (right, up, forward) from the landmarks, the mouth's centre and the height of
    the line between the lips, and the eye-to-eye width."""
    cyl = face_cylinder(lm)
    right, up, fwd = cyl.axes
    lm = np.asarray(lm, float)
    lips = np.nanmean(lm[[61, 62, 63, 65, 66, 67]], axis=0)       # the inner lip line
    return right, up, fwd, lips, float(np.linalg.norm(lm[45] - lm[36]))


def _ict_parts(mesh: Mesh, lm) -> Parts:
    """ICT's table: its head (the first 11,248 vertices) is the skin; the eyeballs, teeth, gums and
    tongue are its own only on its whole mesh.  Vertices of a head-only mesh past the head
    (a user's own additions) follow the skin."""
    from ..data import ICT_N_VERTICES
    n = mesh.n_vertices
    label = np.zeros(n, np.int64)
    names = [p[0] for p in ICT_PARTS]
    for k, (_, a, b) in enumerate(ICT_PARTS):
        label[a:min(b, n)] = k
    role = np.full(n, ROLES.index(FOLLOW))
    role[:11248] = ROLES.index(SKIN)
    weight = None
    if n < ICT_N_VERTICES and n > 11248:
        label[11248:] = len(names)
        names.append("other")
    if n >= ICT_N_VERTICES:
        role[11248:14062] = ROLES.index(POCKET)      # the mouth and eye sockets
        role[21451:23021] = ROLES.index(EYE_LEFT)
        role[23021:24591] = ROLES.index(EYE_RIGHT)
        weight = _split_mouth(mesh, lm, np.arange(14062, 21451), role)
    return Parts(label, names, role, np.arange(min(ICT_SKIN_FACES, mesh.n_faces)), weight)


def _split_mouth(mesh, lm, idx, role) -> np.ndarray | None:
    """Teeth, gums and tongue: each connected piece above the line between the lips stays with
    the skull, below it moves with the jaw; a piece spanning both (gums and tongue as one
    component) takes the jaw's motion in part, by a weight harmonic over the piece between its
    vertices clearly below the plane (1: the tongue, the lower gums) and clearly above (0), so
    that it stretches where the arches meet instead of tearing there.  Returns the weights
    (Parts.jaw_weight), or None where no piece spans both."""
    if lm is None:
        role[idx] = ROLES.index(SKULL)
        return None
    idx = np.unique(idx)                              # in the order of the submatrix below
    right, up, fwd, lips, width = _mouth_frame(lm)
    q = mesh.vertices[idx] - lips
    # the plane between the arches rises toward the back (measured on ICT-FaceKit's jawOpen: at
    # 5 degrees 4.4% of its mouth vertices land on the wrong side, level 6.2%, 10 degrees 7.0%)
    h = q @ up + (q @ fwd) * np.tan(np.radians(OCCLUSAL_TILT_DEG))
    sub = np.zeros(mesh.n_vertices, bool)
    sub[idx] = True
    a = mesh.adjacency[sub][:, sub]
    nc, comp = connected_components(a, directed=False)
    count = np.bincount(comp, minlength=nc)
    mean_h = np.bincount(comp, h, nc) / count
    below = np.bincount(comp, h < 0, nc) / count
    # a piece spans both arches where a quarter of it lies on each side; a tooth whose tip
    # crosses the plane (ICT's upper incisors: 7-16 % of their vertices, roots included) does
    # not, and is not torn from its root
    spans = np.minimum(below, 1 - below) > 0.25
    lower = np.where(spans[comp], h < 0, mean_h[comp] < 0)
    role[idx] = np.where(lower, ROLES.index(JAW), ROLES.index(SKULL))
    if not spans.any():
        return None
    weight = np.full(mesh.n_vertices, np.nan)
    weight[idx[spans[comp]]] = _jaw_weight(a, h, spans[comp], 0.05 * width)
    return weight


def _jaw_weight(a, h, span, band) -> np.ndarray:
    """The jaw's share for the vertices of spanning pieces (span: mask over the rows of the
    adjacency `a`, heights h over the plane between the arches): 1 below -band, 0 above band,
    harmonic (the graph Laplacian's) in between; a stretch reaching neither keeps its side."""
    v = np.nonzero(span)[0]
    h = h[v]
    w = (h < 0).astype(float)
    free = np.abs(h) <= band
    if free.any():                                    # the small screen: a pull to its side
        fill = HarmonicFill(a[v][:, v], np.nonzero(free)[0], np.nonzero(~free)[0], screen=1e-6)
        w[free] = fill(w[~free], prior=w[free])
    return np.clip(w, 0.0, 1.0)


def split_parts(mesh: Mesh, landmarks=None, eyes: dict | None = None) -> Parts:
    """The parts of a head: its connected pieces told apart by their shape and place (eyeballs,
    teeth and tongue, lashes and shells, the skin) and given their roles (ROLES).

    Parameters
    ----------
    mesh : Mesh
    landmarks : (68, 3) float array or None
        Used to place the eyes and the mouth.
    eyes : dict or None
        {"left"/"right": vertices} of eyes cut loose from their lids (correspond.eyes), each the
        eye of its side whatever its shape.

    Returns
    -------
    Parts
    """
    from ..data import ICT_HEAD_VERTICES, is_ict_topology
    lm = None if landmarks is None else np.asarray(landmarks, float)
    if lm is not None and not (np.isfinite(lm[[8, 36, 45]]).all() and np.isfinite(lm[17:27]).any()):
        lm = None
    if mesh.n_vertices >= ICT_HEAD_VERTICES and is_ict_topology(mesh):
        return _ict_parts(mesh, lm)
    nc, comp = connected_components(mesh.adjacency, directed=False)
    tri = mesh.triangles
    area = np.bincount(comp[tri[:, 0]], mesh.triangle_areas(), nc)
    skin_c = int(np.argmax(area))
    if nc == 1:
        return Parts(np.zeros(mesh.n_vertices, np.int64), ["skin"], np.zeros(mesh.n_vertices, np.int64),
                     np.arange(mesh.n_faces))
    group_of = _component_groups(mesh, comp, nc)
    names, role_c = [], np.full(nc, ROLES.index(FOLLOW))
    role = np.full(mesh.n_vertices, ROLES.index(FOLLOW))
    centres = _eye_centres(lm) if lm is not None else {}
    frame = _mouth_frame(lm) if lm is not None else None          # once for every component
    width = frame[4] if frame is not None else None
    mouth = []
    edge = mesh.boundary_vertices()
    cut_eye = {int(comp[v[0]]): side for side, v in (eyes or {}).items() if len(v)}
    for c in range(nc):
        idx = np.nonzero(comp == c)[0]
        kind = group_of[c]
        if c in cut_eye and c != skin_c:
            kind = f"eyeball.{cut_eye[c]} (cut from the lids)"
            role_c[c] = ROLES.index(f"eye.{cut_eye[c]}")
        elif c == skin_c:
            kind = "skin"
            role_c[c] = ROLES.index(SKIN)
        elif kind == "eyeball" or (kind is None and centres and len(idx) >= 8):
            ctr, r, res = fit_sphere(mesh.vertices[idx])
            side = min(centres, key=lambda e: np.linalg.norm(ctr - centres[e])) if centres else None
            near = side is not None and np.linalg.norm(ctr - centres[side]) < 0.5 * width and r < 0.5 * width
            # an eyeball surrounds its centre (ICT's: resultant of the directions 0.28-0.29);
            # lashes and tear or occlusion shells are caps in front of it (0.77-0.95)
            u = mesh.vertices[idx] - ctr
            around = np.linalg.norm((u / np.maximum(np.linalg.norm(u, axis=1, keepdims=True), 1e-300)).mean(0)) < 0.6
            if kind == "eyeball" or (res < 0.08 and near and around):
                kind = "eyeball"
                if side is not None:
                    kind = f"eyeball.{side.split('.')[1]}"
                    role_c[c] = ROLES.index(side)
                else:
                    role_c[c] = ROLES.index(SKULL)
        if kind is None and lm is not None and c != skin_c and _opens_at_the_lips(mesh, idx, edge, lm, width):
            kind = LINING
        if kind == LINING:
            role_c[c] = ROLES.index(POCKET)
        elif kind in ("teeth", "gums and tongue") or (kind is None and lm is not None and
                                                       _inside_mouth(mesh.vertices[idx], lm, frame)):
            kind = kind or "teeth, gums or tongue"
            mouth.append(idx)
            role_c[c] = ROLES.index(SKULL)
        names.append(kind or ("part" if len(idx) > 50 else "piece"))
        role[idx] = role_c[c]
    weight = _split_mouth(mesh, lm, np.concatenate(mouth), role) if mouth else None
    skin_v = comp == skin_c
    label = comp.astype(np.int64)
    for name, v in (pockets(mesh, skin_v, lm) if lm is not None else {}).items():
        skin_v[v] = False
        role[v] = ROLES.index(POCKET)
        label[v] = len(names)
        names.append(name)
    faces = np.nonzero(np.add.reduceat(~skin_v[mesh.face_indices], mesh.face_starts[:-1]) == 0)[0]
    return Parts(label, names, role, faces, weight)


def pockets(mesh: Mesh, skin: np.ndarray, lm) -> dict:
    """The skin's pockets: a mouth bag and eye sockets joined to the lips and lids -- what a loop
    along the inner lips (landmarks 60-67) or an eye's rim (36-41, 42-47), the shortest paths over
    the skin from each point to the next, cuts off from the face behind them.

    Parameters
    ----------
    mesh : Mesh
    skin : (n,) bool array
        The skin's vertices.
    lm : (68, 3) float array

    Returns
    -------
    dict
        {LINING or SOCKET: (k,) int array of the pockets' vertices} (the loops' own vertices stay
        skin); empty where the lips and lids have nothing behind them (holes, sealed or cut).
    """
    lm = np.asarray(lm, float)
    sv = np.nonzero(skin)[0]
    if len(sv) < 100:
        return {}
    e = mesh.edges
    e = e[skin[e[:, 0]] & skin[e[:, 1]]]
    graph = edge_graph(mesh.n_vertices, e, np.linalg.norm(mesh.vertices[e[:, 0]] - mesh.vertices[e[:, 1]], axis=1))
    near = cKDTree(mesh.vertices[sv])
    _, _, fwd, _, width = _mouth_frame(lm)
    out = {}
    # a mouth bag reaches back a third of the eyes' width or more (ICT's), an eye socket 0.3 (its
    # median 0.15); a strip of lip or lid between a loop and an edge a cut made does not
    for name, ring, deep in ((LINING, range(60, 68), 0.15), (SOCKET, range(36, 42), 0.1),
                             (SOCKET, range(42, 48), 0.1)):
        ring = lm[list(ring)]
        if not np.isfinite(ring).all():
            continue
        # a path between neighbouring points is short: the search stops at the ring's length
        length = float(np.linalg.norm(ring - np.roll(ring, 1, axis=0), axis=1).sum())
        v = _cut_off(graph, skin, e, sv[near.query(ring)[1]], (mesh.vertices - ring.mean(0)) @ fwd,
                     deep * width, 0.5 * len(sv), length)
        if v is not None:
            out[name] = v if name not in out else np.r_[out[name], v]
    return out


def _cut_off(graph, skin, e, ends, depth, deep, most, limit) -> np.ndarray | None:
    """The skin a closed loop through `ends` (shortest paths, each no longer than `limit`) cuts
    off from the rest of it, reaching deeper than `deep` behind (depth: per vertex, negative
    behind) and smaller than `most` vertices; None where nothing is."""
    from scipy.sparse.csgraph import dijkstra
    n, k = graph.shape[0], len(ends)
    _, pred = dijkstra(graph, indices=ends, return_predecessors=True, limit=limit)
    loop = np.zeros(n, bool)
    for i in range(k):                                # each point to the next, round the ring
        a, x = ends[i], ends[(i + 1) % k]
        while x != a and x >= 0:
            loop[x] = True
            x = pred[i, x]
        if x < 0:
            return None
        loop[a] = True
    rest = skin & ~loop
    keep = rest[e[:, 0]] & rest[e[:, 1]]
    nc, comp = connected_components(edge_graph(n, e[keep]), directed=False)
    sizes = np.bincount(comp[rest], minlength=nc)
    face = int(np.argmax(sizes))
    out = []
    for c in np.nonzero(sizes)[0]:
        v = np.nonzero(rest & (comp == c))[0]
        if c != face and depth[v].min() < -deep and sizes[c] < most:
            out.append(v)
    return np.concatenate(out) if out else None


def _component_groups(mesh, comp, nc):
    """For each component, the kind its faces' material or group names say (or None)."""
    out = [None] * nc
    if mesh.groups is None or not mesh.group_names:
        return out
    kinds = []
    for name in mesh.group_names:
        kinds.append(next((k for rx, k in _NAMED if rx.search(name)), None))
    face_comp = comp[mesh.face_indices[mesh.face_starts[:-1]]]
    for c in range(nc):
        ks = [kinds[g] for g in np.unique(mesh.groups[face_comp == c])]
        ks = [k for k in ks if k is not None]
        if ks and len(set(ks)) == 1:
            out[c] = ks[0]
    return out


def _opens_at_the_lips(mesh, idx, edge, lm, width) -> bool:
    """A piece whose open edge runs along the inner lips (within 0.12 of the eyes' width of the
    corners and the middles, landmarks 60, 62, 64, 66): a mouth bag of its own.  On ICT's bag
    cut from its lips 0.03-0.08; its gums and tongue 0.25, its teeth 0.68 or more."""
    b = idx[edge[idx]]
    if len(b) < 8 or not np.isfinite(lm[[60, 62, 64, 66]]).all():
        return False
    p = mesh.vertices[b]
    return all(np.linalg.norm(p - lm[k], axis=1).min() < 0.12 * width for k in (60, 62, 64, 66))


def _inside_mouth(p, lm, frame):
    """All points behind the lips, between the mouth corners (with a margin) and between
    halfway up the nose and the chin: a piece inside the mouth (frame: _mouth_frame(lm))."""
    right, up, fwd, lips, width = frame
    q = p - lips
    x, y, z = q @ right, q @ up, q @ fwd
    half = 0.75 * abs(float((lm[54] - lm[48]) @ right))
    top = float((0.5 * (lm[33] + lm[27]) - lips) @ up)       # halfway up the nose: the upper roots
    bottom = float((lm[8] - lips) @ up)
    return bool((np.abs(x) < half).all() and (y < top).all() and (y > bottom).all() and (z < 0.1 * width).all()
                and (z > -1.5 * width).all())
