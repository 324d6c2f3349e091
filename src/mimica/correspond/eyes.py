"""Eyes that are one surface with the lids (Basel- or Surrey-style morphable models, scans): the
skin runs on from each lid over the eyeball's front, so a blink can only crease the lid.

`cut_eyes` finds each sealed eye's inside -- the faces that, seen from the front, lie within
the polygon of the eye's six landmarks (iBUG 36-41, 42-47), the one piece around its centre --
and cuts it loose from the lids: the vertices where it meets them (the lid margin) are doubled,
the faces inside take the copies.  (A shortest path through the landmarks along the fold of
the lid was tried first: on remeshed heads it ran below the upper lid's landmarks, which then
rode with the eye; the blink closed 0.07-0.84 of the gap.)  That inside is then the eye, a rigid part the lids close
over (correspond.parts: `eyes`).  The user's vertices keep their order; copies are appended.

Landmarks found on renders sit off such an eye: the detector reads a sealed eye's shading, not
its margin, and puts the whole eye 0.1-0.3 of its width high (corners too; the rest of the face
within 0.03 of the eyes' distance).  So where they were found, not given, each sealed eye's six
points come from the source face's eye as a template (`fit_margin`): the template face put on
this one by the landmarks off the eyes, its skin and eye near the eye moved and turned about the
eye's line to where this surface lies closest to them (the turn takes up a brow that stands out
more or less than the template's) and its lower lid shifted across on its own (a rigid eye cannot
fit both lids of every face), its six points carried along -- within 0.03 of the width of the
true margin across on average, 0.13 at worst, on 28 dev eyes remeshed at 12k, 20k and 30k
vertices.  The inside is then
cut along a loop of valley edges within BAND of that outline and drawn to it (`_loop_faces`),
not at the polygon: at 20k vertices the eye is three edges tall, and a polygon a twentieth of
the width off puts a lid's last ring on the eye.  (Before, found points were slid to the valley
between lid and eyeball deepest along the upper lid's arc: the fold above the lid runs deeper on
some heads, the lower lid's on others; worst held-out blink 0.40, against 0.78 through the
template: bench/real_heads.py.)
Given landmarks are kept; where their polygon holds fewer than INSIDE vertices (a coarse
remesh: a dev head at 12k vertices, held-out seed 47's left eye at 20k), the eye is cut along
that loop near them instead (given, the polygon reads better where it holds: dev eyes 0.85-0.87
against the loop's 0.76-0.87).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.sparse.csgraph import connected_components

from ..mesh import Mesh
from ..mesh.core import unique_rows
from ..mesh.query import TriangleLocator
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

RIMS = {"right": list(range(36, 42)), "left": list(range(42, 48))}
CAP_SHARE = 0.1           # an eye's inside is under this share of the mesh's faces
OPEN = 0.18               # an eye shaped open: its lids' gap (37-41, 38-40) over its width at least this
INSIDE = 3                # ... and resolved: at least this many vertices inside its margin
# (ICT's identities remeshed at 20k vertices: gap 0.27-0.31 of the width, 4-9 vertices inside;
# the shared 468-vertex head's sealed eyes: one vertex inside, a fan in front of the lids which,
# cut loose, stood out of every blink with the void behind it showing)
NOT_EYES = np.r_[0:36, 48:68]      # the landmarks that put a template face on this one
TEMPLATE_REACH = 1.3      # a template eye: its face's front within this (of the eye's width) of it
TEMPLATE_SAMPLES = 4      # ... sampled this many steps along each triangle's edge
FIT_REACH = 0.9           # fit_margin fits the vertices within this of where the template's eye lands
FIT_CAP = 0.1             # ... each one's distance counted up to this (the rest of the face differs)
SEARCH = [(0.1, 4, 2), (0.025, 2, 2), (0.00625, 2, 2)]   # (step of the width, half-spans in steps: in the eye's plane, in depth)
# (these four set once on dev heads 14-16 and 20, not swept; a scale across the eye searched as well,
# 0.7-1.3, took the fit's mean error across from 0.052 to 0.033 of the width on 16 dev eyes, their
# blinks as they were)
TILT = [(5.0, 1), (2.0, 1), (1.0, 1)]   # ... and a turn about the eye's line with each (step in degrees, half-span in steps)
# (moved only, the template slid down the slope of a brow that stands out more than its own: seed
# 34's eyes sat 0.08-0.16 of the width low)
LOWER_REACH = 0.2         # then the lower lid's own shift across: the template's part below the eye's
                          # line moves by its whole from this far (of the width) down to twice it,
                          # fading to none at the line and at three times it (the cheek's slope below
                          # does not pull the lid)
LOWER_SEARCH = [(0.03, 3), (0.01, 3), (0.0025, 4)]       # (step of the width, half-span in steps: 0.13 at most)
LOWER_PRIOR = 0.03        # ... a shift of 0.1 of the width kept only where it fits this share better
# (the lid's points move as the warp moves the template there, 0.59-0.76 of the shift: moved by the
# whole shift they overshot it 1.3-2.3x.  With that and the prior, the dev eyes below remeshed at
# 12k, 20k and 30k vertices: the lower lid's mean error across 0.034 / 0.035 / 0.039 -> 0.028 /
# 0.026 / 0.027 of the width, any point's largest 0.13 / 0.16 / 0.18 -> 0.13 / 0.09 / 0.10 (the
# prior's effect flat from 0.02 to 0.05); blink mean 0.76 / 0.84 / 0.79 -> 0.79 / 0.85 / 0.83)
SEEN = 0.05               # ... fitted to the surface seen from the front: the front-most within this
                          # (of the width) in cells this wide
# (dev heads 13-16, 20, 24, 30, 42 and 50-55, 28 eyes, landmarks found; blink mean / worst, the fit's
# mean / largest error across in widths: moved only, with the lower lid's shift reaching the cheek
# (whole from 0.3 down) and 0.3 at most: 0.80 / 0.13, 0.038 / 0.21; turned, that shift as it was:
# 0.82 / 0.51, 0.030 / 0.25 (two lower lids 0.26 low); turned, no shift of the lower lid: 0.82 / 0.56,
# 0.029 / 0.11 (42R 0.64, its lower lid 0.11 high); turned, this shift: 0.84 / 0.62, 0.027 / 0.16)
BAND = 0.1                # the margin's loop runs within this (of the width) of the fitted outline
LOOP_PULL = 0.05          # ... an edge costing (1 + (its distance from the outline / this)^2) times more
# (dev heads as above, landmarks found: blink mean 0.74 -> 0.76 alone, 13R 0.71 -> 0.77, 15R 0.69 -> 0.79,
# 30R 0.71 -> 0.88; 0.08 as none; the band narrowed to 0.06 instead left eyes with no loop)
# (dev heads 13-16, landmarks found and slid to a valley: blink 0.51-0.72 at 0.1, 0.16-0.77 at 0.25; the
# loop's crease weight, the mouth's CREASE or twice it, made no difference)


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
    landmarks : (68, 3) float array or None
        The landmarks given, those of each cut eye put on its margin where they were found.
    """
    mesh: Mesh                         # the cut mesh: the input's vertices first, then the copies
    copies_of: np.ndarray              # (k,) for each appended vertex, the vertex it copies
    eyes: dict = field(default_factory=dict)      # side -> vertices of its eye (the copies included)
    rims: dict = field(default_factory=dict)      # side -> the lid margin's loop (the lids' vertices)
    why: dict = field(default_factory=dict)       # side -> why a sealed eye was left whole
    landmarks: np.ndarray | None = None           # (68, 3) as given, found ones put on the margins

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


def _eye_frame(pts: np.ndarray, fwd: np.ndarray):
    """An eye's frame from its six landmarks (6, 3): (centre (3,), width, ex (3,) along the eye
    from its first corner to its second, ey (3,) across it, up).  ex keeps the corners' depth
    (the outer corner lies further back), so it is not square to fwd; made square, the one-surface
    dev heads' blinks with found landmarks read mixed (13R 0.71 -> 0.64, 14R 0.92 -> 0.84, 30R
    0.80 -> 0.86): kept as the fits were chosen with it."""
    centre = pts.mean(0)
    width = float(np.linalg.norm(pts[3] - pts[0]))
    ex = (pts[3] - pts[0]) / width
    return centre, width, ex, np.cross(fwd, ex)


def _front_faces(mesh: Mesh, centre: np.ndarray, width: float, fwd: np.ndarray):
    """(face centroids (n_faces, 3), their offsets from the eye's centre, whether each is near
    the eye (within 0.8 of its width) and faces the front)."""
    cent = mesh.face_centroids()
    rel = cent - centre
    nrm = np.zeros((mesh.n_faces, 3))
    np.add.at(nrm, mesh.tri_face, mesh.face_normals())
    return cent, rel, (np.linalg.norm(rel, axis=1) < 0.8 * width) & (nrm @ fwd > 0)


def _eye_faces(mesh: Mesh, pts: np.ndarray, fwd: np.ndarray) -> np.ndarray | None:
    """The faces of the eye: those whose centre, seen from the front, lies inside the polygon of
    the eye's six landmarks, on the front of the face near them (the one piece around the
    eye's centre).  None when they are not one piece of the surface."""
    centre, width, ex, ey = _eye_frame(pts, fwd)
    cent, rel, near = _front_faces(mesh, centre, width, fwd)
    depth = rel @ fwd
    # on the front near the landmarks: not a socket behind an eyeball, nor the back of the head
    near &= (depth > -0.15 * width) & (depth < 0.4 * width)
    q = np.stack([rel @ ex, rel @ ey], 1)
    poly = np.stack([(pts - centre) @ ex, (pts - centre) @ ey], 1)
    inside = near & inside_polygon(q, poly)
    # the landmarks mark the lids' margin: the faces under them are the lids'
    under, _, _, _ = TriangleLocator(mesh.vertices, mesh.triangles).closest(pts)
    lid_faces = mesh.tri_face[under]
    inside[lid_faces] = False
    # ... and the margin runs through them: a landmark's nearest vertex gets the face at it
    # nearest the eye's centre, where none of its faces is the eye's
    start, around = mesh.vertex_faces
    for p in pts:
        v = int(np.argmin(np.linalg.norm(mesh.vertices - p, axis=1)))
        fan = np.unique(around[start[v]:start[v + 1]])
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
    return _piece_around(mesh, inside, cent, centre)     # the one piece around the centre


@dataclass
class EyeTemplate:
    """A face's eyes as templates for a sealed eye's margin (fit_margin): per side, dense samples
    of the front of its skin near the eye and of its eye's part showing between the lids.

    Attributes
    ----------
    landmarks : (68, 3) float array
        The template face's landmarks.
    samples : dict
        Side -> a cKDTree of the samples.
    """
    landmarks: np.ndarray
    samples: dict = field(default_factory=dict)


def eye_template(mesh: Mesh, landmarks: np.ndarray, skin: np.ndarray, eyes: dict) -> EyeTemplate:
    """A face's eyes as templates: its skin's front within TEMPLATE_REACH of each eye's width,
    and the faces of its eye (`eyes[side]`, where it has one) seen within the eye's landmarks.

    Parameters
    ----------
    mesh : Mesh
    landmarks : (68, 3) float array
    skin : (n,) bool array
        Its skin's vertices.
    eyes : dict
        Side -> its eye's vertices ((n,) bool), where the face has eyes of their own.

    Returns
    -------
    EyeTemplate
    """
    from ..align import face_cylinder
    lm = np.asarray(landmarks, float)
    fwd = face_cylinder(lm).axes[2]
    tri, v = mesh.triangles, mesh.vertices
    cen = v[tri].mean(1)
    front = np.cross(v[tri[:, 1]] - v[tri[:, 0]], v[tri[:, 2]] - v[tri[:, 0]]) @ fwd > 0
    uu, vv = np.meshgrid(np.arange(TEMPLATE_SAMPLES + 1), np.arange(TEMPLATE_SAMPLES + 1))
    on = uu + vv <= TEMPLATE_SAMPLES                   # barycentric samples over each triangle
    bu, bv = uu[on] / TEMPLATE_SAMPLES, vv[on] / TEMPLATE_SAMPLES
    out = EyeTemplate(lm)
    for side, rim in RIMS.items():
        pts = lm[rim]
        centre, width, ex, ey = _eye_frame(pts, fwd)
        rel = cen - centre
        eye = np.zeros(len(tri), bool)
        if side in eyes:                               # the eye between the lids
            poly = np.stack([(pts - centre) @ ex, (pts - centre) @ ey], 1)
            eye = eyes[side][tri].all(1) & inside_polygon(np.stack([rel @ ex, rel @ ey], 1), poly)
        keep = (skin[tri].all(1) | eye) & front & (np.linalg.norm(rel, axis=1) < TEMPLATE_REACH * width)
        t = tri[keep]
        if len(t):
            p = (v[t[:, 0], None] * (1 - bu - bv)[None, :, None] + v[t[:, 1], None] * bu[None, :, None]
                 + v[t[:, 2], None] * bv[None, :, None])
            out.samples[side] = cKDTree(p.reshape(-1, 3))
    return out


def fit_margin(mesh: Mesh, landmarks: np.ndarray, side: str, template: EyeTemplate,
               locator=None) -> np.ndarray:
    """A sealed eye's six landmarks from a template eye fitted to its surface: the template face
    put on this one by their other landmarks (a similarity), then its eye moved and turned about
    the eye's line (coarse to fine: SEARCH, TILT) to where this face's vertices near it lie
    closest to it (each distance counted up to FIT_CAP of the eye's width), its lower lid then
    shifted across on its own the same way (LOWER_SEARCH), and its six landmarks carried along.

    Parameters
    ----------
    mesh : Mesh
    landmarks : (68, 3) float array
        This face's landmarks (the eye's own are not used: found ones sit off a sealed eye).
    side : str
        "left" or "right"; the template has that eye.
    template : EyeTemplate
    locator : TriangleLocator or None
        Of the mesh, where already made.

    Returns
    -------
    (6, 3) float array
        On the surface.
    """
    from ..align import face_cylinder, fit_similarity
    lm, ls = np.asarray(landmarks, float), template.landmarks
    to_t = fit_similarity(lm[NOT_EYES], ls[NOT_EYES], what="landmarks")
    fwd = face_cylinder(ls).axes[2]
    centre, width, ex, ey = _eye_frame(ls[RIMS[side]], fwd)
    v = to_t.apply(mesh.vertices)
    near = (np.linalg.norm(v - centre, axis=1) < FIT_REACH * width) & (mesh.vertex_normals() @ to_t.rotation.T @ fwd > 0)
    p = v[near]
    tree, best, tilt = template.samples[side], np.zeros(3), 0.0
    for (step, span, deep), (turn, turns) in zip(SEARCH, TILT):
        g, d = np.arange(-span, span + 1) * step, np.arange(-deep, deep + 1) * step
        a, b, c = (x.reshape(-1, 1) for x in np.meshgrid(g, g, d, indexing="ij"))
        shifts = best + width * (a * ex + b * ey + c * fwd)
        tilts = tilt + turn * np.arange(-turns, turns + 1)
        # the vertices turned by t about the template's eye: the template turned by -t (and moved back)
        q = np.stack([(p - centre) @ _rotation(ex, t).T + centre for t in tilts])[:, None] - shifts[None, :, None]
        k = int(np.argmin(_capped_fit(tree, q.reshape(-1, *p.shape), FIT_CAP * width)))
        tilt, best = tilts[k // len(shifts)], shifts[k % len(shifts)]
    # the lower lid's own shift across (a rigid eye cannot fit both lids of every face): the
    # template's lower part warped by `lower` x its weight `fall` (the vertices moved back instead),
    # fitted to what is seen from the front only (an open eye's eyeball under the lids pulled the
    # warp: ICT's own face fitted its lower lid 0.09 of the width low)
    turned = _rotation(ex, tilt)
    p = (p - centre) @ turned.T + centre
    ps = p[_front_layer(p - centre, ex, ey, fwd, SEEN * width)]
    fall = _fall(ps - centre - best, width, ey)
    lower, m0 = 0.0, None
    for step, span in LOWER_SEARCH:
        tries = lower + step * np.arange(-span, span + 1)
        q = ps[None] - best - width * tries[:, None, None] * fall[None, :, None] * ey
        m = _capped_fit(tree, q, FIT_CAP * width)
        m0 = m[span] if m0 is None else m0                  # unshifted (the first stage's middle try)
        lower = tries[np.argmin(m + LOWER_PRIOR * m0 * (tries / 0.1) ** 2)]
    shift = np.zeros((6, 3))
    shift[4:] = width * lower * _fall(ls[RIMS[side]][4:] - centre, width, ey)[:, None] * ey   # 40, 41 (46, 47)
    moved = to_t.inverse().apply((ls[RIMS[side]] + best + shift - centre) @ turned + centre)
    if locator is None:
        locator = TriangleLocator(mesh.vertices, mesh.triangles)
    return locator.closest(moved)[2]


def _fall(rel: np.ndarray, width: float, ey: np.ndarray) -> np.ndarray:
    """(m,) how much of the lower lid's shift the points rel (m, 3) from the eye's centre take:
    whole from LOWER_REACH to twice it below the eye's line, none at the line and at three times it."""
    below = -(rel @ ey) / (LOWER_REACH * width)
    return np.clip(np.minimum(below, 3 - below), 0, 1)


def _rotation(axis: np.ndarray, degrees: float) -> np.ndarray:
    """(3, 3) the turn by `degrees` about the unit `axis`."""
    return Rotation.from_rotvec(np.radians(degrees) * np.asarray(axis, float)).as_matrix()


def _capped_fit(tree, q: np.ndarray, cap: float) -> np.ndarray:
    """(k,) each try's misfit: q (k, m, 3) the vertices as each of k tries moves them, their
    squared distances to the template's samples (`tree`) capped at `cap`, averaged."""
    dist = tree.query(q.reshape(-1, 3), distance_upper_bound=cap, workers=-1)[0].reshape(len(q), -1)
    return (np.minimum(dist, cap) ** 2).mean(1)


def _front_layer(rel: np.ndarray, ex, ey, fwd, cell: float) -> np.ndarray:
    """(m,) bool: the points (rel: (m, 3) from the eye's centre) within `cell` of the front-most
    in their cell of the eye's plane (`cell` square): what is seen from the front."""
    _, key, _ = unique_rows(np.floor(np.stack([rel @ ex, rel @ ey], 1) / cell).astype(np.int64))
    depth = rel @ fwd
    front = np.full(key.max() + 1, -np.inf)
    np.maximum.at(front, key, depth)
    return depth >= front[key] - cell


def polyline_distance(q: np.ndarray, line: np.ndarray) -> np.ndarray:
    """Each 2D point's distance to a 2D polyline.

    Parameters
    ----------
    q : (m, 2) float array
    line : (k, 2) float array
        Its vertices in order.

    Returns
    -------
    (m,) float array
    """
    a, b = line[:-1], line[1:]
    ab = b - a
    t = np.clip(np.einsum("mkj,kj->mk", q[:, None] - a[None], ab) / np.maximum((ab * ab).sum(1), 1e-300), 0, 1)
    return np.linalg.norm(q[:, None] - (a[None] + t[..., None] * ab[None]), axis=2).min(1)


def _loop_faces(mesh: Mesh, pts: np.ndarray, fwd: np.ndarray) -> np.ndarray | None:
    """The faces of the eye inside the lids' margin, found as a loop of valley edges near the
    landmarks' outline: corner to corner over the upper lid and back under the lower, each by
    Dijkstra within BAND of its arc, an edge costing exp(-CREASE x its concave angle) of its
    length (correspond.mouth's seam) times 1 + (its distance from the arc / LOOP_PULL)^2.  None
    where no loop closes."""
    from scipy.sparse import coo_matrix
    from ..mesh.query import concave_angles, shortest_path
    from .mouth import CREASE
    centre, width, ex, ey = _eye_frame(pts, fwd)
    v = mesh.vertices
    rel = v - centre
    q = np.stack([rel @ ex, rel @ ey], 1) / width
    front = (np.linalg.norm(rel, axis=1) < 1.2 * width) & (mesh.vertex_normals() @ fwd > 0.0)
    poly = np.stack([(pts - centre) @ ex, (pts - centre) @ ey], 1) / width
    e = mesh.edges
    cost = np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1) * np.exp(-CREASE * concave_angles(mesh, e))
    cand = np.nonzero(front)[0]
    c0 = int(cand[np.argmin(np.linalg.norm(v[cand] - pts[0], axis=1))])
    c3 = int(cand[np.argmin(np.linalg.norm(v[cand] - pts[3], axis=1))])
    loop = []
    for a, b, arc in ((c0, c3, poly[[0, 1, 2, 3]]), (c3, c0, poly[[3, 4, 5, 0]])):
        off = polyline_distance(q, arc)
        ok = front & (off < BAND)
        ok[[c0, c3]] = True
        keep = ok[e].all(1)
        pulled = cost * (1 + (off[e].mean(1) / LOOP_PULL) ** 2)         # the valley nearest the outline
        g = coo_matrix((np.r_[pulled[keep], pulled[keep]], (np.r_[e[keep, 0], e[keep, 1]], np.r_[e[keep, 1], e[keep, 0]])),
                       shape=(mesh.n_vertices,) * 2).tocsr()
        seg = shortest_path(g, a, b)
        if seg is None:
            return None
        loop += seg[1:]
    cent, relc, near = _front_faces(mesh, centre, width, fwd)
    inside = near & inside_polygon(np.stack([relc @ ex, relc @ ey], 1) / width, q[np.array(loop)])
    return _piece_around(mesh, inside, cent, centre)


def _piece_around(mesh: Mesh, inside: np.ndarray, cent: np.ndarray, centre: np.ndarray) -> np.ndarray | None:
    """Of the faces `inside` (n_faces,) bool, the one piece that shares edges around the face
    nearest `centre` (cent: the faces' centroids); None where none is inside."""
    if not inside.any():
        return None
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


def _inside(inside, n_faces: int, fi: np.ndarray, face_of: np.ndarray):
    """(why not, each face corner's face inside, the margin's vertices) for the faces `inside`
    taken as an eye: why not is None where they make one."""
    if inside is None or len(inside) > CAP_SHARE * n_faces:
        return "no piece of the surface inside the eye's landmarks", None, None
    is_in = np.zeros(n_faces, bool)
    is_in[inside] = True
    corner_in = is_in[face_of]
    eye = np.unique(fi[corner_in])
    on_both = np.intersect1d(eye, np.unique(fi[~corner_in]))   # the margin
    if len(on_both) < 6:
        return "the eye's inside meets its lids at too few vertices", None, None
    if len(eye) - len(on_both) < INSIDE:
        return (f"fewer than {INSIDE} vertices inside its lids' margin: too coarse to be an eye of its own (a head "
                "subdivided around its eyes is cut)"), None, None
    return None, corner_in, on_both


def cut_eyes(mesh: Mesh, landmarks, found: bool = False, template=None) -> EyeCut:
    """A head with each sealed eye's inside cut loose from its lids along their margin; unchanged
    where the eyes open already (a boundary at the lids) or the landmarks are missing.

    Parameters
    ----------
    mesh : Mesh
    landmarks : (68, 3) float array
    found : bool
        Found on renders, not given: each sealed eye's put on its margin first by `template`
        (fit_margin), where one is given.
    template : EyeTemplate, a function making one, or None
        The eyes of the face the shapes come from (eye_template); a function is called only
        where a sealed eye's found landmarks need it.

    Returns
    -------
    EyeCut
    """
    from ..align import face_cylinder
    lm = np.asarray(landmarks, float)
    out = EyeCut(mesh, np.zeros(0, np.int64), landmarks=lm)
    shut = _closed_over(mesh, lm)
    if not shut:
        return out
    fwd = face_cylinder(lm).axes[2]
    if found and callable(template):
        template = template()
    locator = TriangleLocator(mesh.vertices, mesh.triangles) if found and template is not None else None
    slid = lm.copy()
    fi, st = mesh.face_indices.copy(), mesh.face_starts
    face_of = np.repeat(np.arange(mesh.n_faces), np.diff(st))
    verts = [mesh.vertices]
    copies, n = [], mesh.n_vertices
    for side in shut:
        pts = lm[RIMS[side]]
        fit = found and template is not None and side in template.samples
        gap = 0.5 * (np.linalg.norm(pts[1] - pts[5]) + np.linalg.norm(pts[2] - pts[4]))
        # a shut eye: nothing to open.  Found points read a sealed eye's shading, not its lids (a
        # shut sealed eye's read 0.34 open, an open-shaped one's 0.16 at 12k vertices): the
        # surface decides where they are fitted (a shut eye holds no loop around an inside)
        if not fit and gap < OPEN * np.linalg.norm(pts[3] - pts[0]):
            continue
        moved = fit_margin(mesh, lm, side, template, locator) if fit else pts
        now = Mesh(np.vstack(verts), fi, st)
        # found: along the margin's valley near the fitted points; given: inside their polygon,
        # else (a polygon holding too few vertices) along the valley near them
        ways = [_loop_faces] if fit else [_eye_faces, _loop_faces]
        whys = []
        for way in ways:
            why, corner_in, on_both = _inside(way(now, moved, fwd), mesh.n_faces, fi, face_of)
            if why is None:
                break
            whys.append(why)
        if why is not None:
            out.why[side] = whys[0]
            continue
        pts = moved
        copy = np.full(now.n_vertices, -1)
        copy[on_both] = n + np.arange(len(on_both))
        sel = corner_in & np.isin(fi, on_both)
        fi[sel] = copy[fi[sel]]
        verts.append(mesh.vertices[on_both])
        copies.append(on_both)
        out.eyes[side] = np.unique(fi[corner_in])
        out.rims[side] = on_both
        slid[RIMS[side]] = pts
        n += len(on_both)
    if not copies:
        return out
    cut = Mesh(np.vstack(verts), fi, st, name=mesh.name, groups=mesh.groups, group_names=mesh.group_names,
               layout=mesh.layout)
    if mesh.uv is not None and mesh.face_uv_indices is not None:
        cut.uv, cut.face_uv_indices = mesh.uv, mesh.face_uv_indices
    out.mesh, out.copies_of, out.landmarks = cut, np.concatenate(copies), slid
    return out
