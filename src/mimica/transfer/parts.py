"""How the parts of a head that are not skin move in a transfer.

The skin is transferred skin to skin (Song et al.); the other target parts take their role's
motion (correspond.parts): rigid bodies take the rigid motion that best fits the source's
part of the same role in each frame (Challis 1995 without scale) -- the jaw's from the
source's lower teeth, gums and tongue, or, where the source has none, from its chin; an eye's
rotation about the target eyeball's own centre; the skull stays; a piece spanning both
arches takes its vertices' shares of the jaw's motion (Parts.jaw_weight) -- `follow` parts ride
on the skin (_Riders: near points with their closest skin point, far ones carried by their
piece's root and turned with the skin there), and the pockets (a
mouth bag, eye sockets) as the source's: each vertex takes the displacement of its closest point
on the source's pockets and skin, and the difference this leaves to the transferred skin where
the two meet (the loops along the inner lips and the lids' rims) is spread over the pocket
harmonically, so the bag joins the lips and a socket the lids.
"""

from __future__ import annotations

import numpy as np

from ..align import Similarity, fit_similarity
from ..correspond.parts import EYE_LEFT, EYE_RIGHT, FOLLOW, JAW, POCKET, ROLES, SKIN, Parts, fit_sphere
from ..mesh import Mesh, vertex_normals
from ..mesh.graph import HarmonicFill, edge_graph
from ..mesh.query import TriangleLocator


class PartMotion:
    """The motion of a split head's other parts, precomputed for one (source, target) pair; `apply`
    fills the non-skin target vertices of each frame from the source frames and the transferred
    skin (eyeballs and teeth rigid, lashes and shells riding the skin).

    Parameters
    ----------
    source : Mesh
    ps : Parts
        The source's.
    target : Mesh
    pt : Parts
        The target's.
    skin : Mesh
        The target's skin.
    skin_index : (k,) int array
        The skin's vertices in the target.
    similarity : Similarity
        The target's alignment onto the source.
    source_landmarks : (68, 3) float array
    match : ((k, 3) int array, (k, 3) float array) or None
        The skin's correspondence: each skin vertex's source triangle (its corners, source
        vertices; -1 where unmatched) and barycentric coordinates there.
    """

    def __init__(self, source: Mesh, ps: Parts, target: Mesh, pt: Parts, skin: Mesh, skin_index: np.ndarray,
                 similarity: Similarity, source_landmarks: np.ndarray, match=None):
        self.similarity, self._back = similarity, similarity.inverse()
        self.rest = source.vertices
        self.target = target.vertices
        self.bodies = []                          # (target vertices, source vertices, eye centres or None)
        for role in (JAW, EYE_LEFT, EYE_RIGHT):
            tv = pt.of(role)
            if not len(tv):
                continue
            sv = ps.of(role)
            if role == JAW and not len(sv):
                sv = _chin(source, ps, source_landmarks)
            if not len(sv):                       # no counterpart: stays with the head
                continue
            centres = None
            if role != JAW:                       # rotate about each eyeball's own centre
                cs, rs, _ = fit_sphere(source.vertices[sv])
                ct, rt, res = fit_sphere(similarity.apply(target.vertices[tv]))
                if not (0.5 * rs < rt < 2 * rs) or res > 0.1:      # an eye's front only (cut from its lids):
                    ct = cs                                        # about where the source's turns
                centres = (ct, cs)
            self.bodies.append((tv, sv, centres))
        # a piece spanning both arches: each vertex takes its share of the jaw's motion
        w = pt.jaw_weight if pt.jaw_weight is not None else np.zeros(0)
        part = np.nonzero(np.isfinite(w) & (w > 0) & (w < 1))[0]
        self._shared = (part, w[part], similarity.apply(target.vertices[part]))
        self.follow = pt.of(FOLLOW)
        self.skin_index = skin_index
        self.pockets = _Pockets(source, ps, target, pt, similarity, skin_index, match) if len(pt.of(POCKET)) else None
        if len(self.follow):
            width = np.linalg.norm(source_landmarks[45] - source_landmarks[36]) / similarity.scale
            # riders ride the surface: the skin and its pockets (a lash's root sits on the lid's
            # margin, which may fall on the socket's side of the loop round the eye)
            ride = np.r_[pt.skin_faces, _faces_of(target, pt.role == ROLES.index(POCKET))]
            surface, self._surface = target.submesh(np.unique(ride)) if self.pockets is not None else (skin, skin_index)
            self._follow = _Riders(target, self.follow, surface, ROOT * width, AROUND * width)

    def rigid(self, frame: np.ndarray, sv: np.ndarray) -> Similarity:
        """The source part's best rigid motion from rest to `frame` (in the source's frame)."""
        return fit_similarity(self.rest[sv], frame[sv], what="a rigid part", scale=False)

    def apply(self, frames: np.ndarray, skin_out: np.ndarray) -> np.ndarray:
        """Source frames (F, n_S, 3) and the transferred skin (F, n_skin, 3) -> (F, n_T, 3)."""
        out = np.repeat(self.target[None], len(frames), axis=0)
        out[:, self.skin_index] = skin_out
        for tv, sv, centres in self.bodies:
            a = self.similarity.apply(self.target[tv])           # the target part in the source's frame
            for f, frame in enumerate(frames):
                m = self.rigid(frame, sv)
                if centres is None:
                    moved = m.apply(a)
                else:                                              # about the target eye's centre
                    ct, cs = centres
                    moved = ct + (m.apply(cs) - cs) + (a - ct) @ m.rotation.T
                out[f, tv] = self._back.apply(moved)
                if centres is None and len(self._shared[0]):               # the jaw: its shares
                    v, share, at = self._shared
                    out[f, v] = self.target[v] + share[:, None] * (self._back.apply(m.apply(at)) - self.target[v])
        if self.pockets is not None:
            out[:, self.pockets.vertices] = self.pockets.apply(frames, out)
        if len(self.follow):
            out[:, self.follow] = self._follow.apply(out[:, self._surface])
        return out


SLACK_DEG = 10.0  # a root's turn less this: small turns of the skin leave a lash as it is
AROUND = 0.03     # of the eyes' width: the skin whose turn a root's riders take
ROOT = 0.005      # of the eyes' width: a riding vertex this close to the skin rides on its own


class _Riders:
    """Parts riding on the skin (lashes, shells, brow cards): a vertex within `root` of the skin
    (with its pockets: the surface given) moves with its closest point there; one farther out
    (a lash's tip) is carried by the skin point of the nearest vertex of its piece that lies on
    the skin (its root, along the piece), turned
    as the skin's mean normal within `around` of that point turns, less SLACK_DEG -- so a lash
    turns with the closing lid instead of each of its points following whatever skin is nearest
    it, and stays as it is when the skin round its root only bends a little.  On ICT's lashes and
    shells on its whole head as another topology, the 95th percentile of their error over a
    socket's size, median / worst of the 52 shapes: each point on its nearest skin 0.0066 /
    0.210; carried and turned 0.0079 / 0.126 (eyeLookDown 0.044 -> 0.096: ICT's sculpted lashes
    turn in a blink, hardly elsewhere), less 10 degrees 0.0019 / 0.138 (0.136 riding the pockets
    too), less 20 0.0019 / 0.160; the turn by Kabsch over the same skin 0.0080 / 0.158."""

    def __init__(self, target: Mesh, vertices: np.ndarray, skin: Mesh, root: float, around: float):
        from scipy.sparse.csgraph import connected_components, dijkstra
        from scipy.spatial import cKDTree
        p = target.vertices[vertices]
        tri, bary, near, dist = TriangleLocator(skin.vertices, skin.triangles).closest(p)
        at = np.full(target.n_vertices, -1)
        at[vertices] = np.arange(len(vertices))
        e = target.edges
        e = at[e[(at[e[:, 0]] >= 0) & (at[e[:, 1]] >= 0)]]
        n = len(vertices)
        graph = edge_graph(n, e, np.linalg.norm(p[e[:, 0]] - p[e[:, 1]], axis=1))
        nc, comp = connected_components(graph, directed=False)
        low = np.full(nc, np.inf)
        np.minimum.at(low, comp, dist)
        # roots: on the skin, or a piece's closest points where none of it is
        roots = np.nonzero(dist <= np.maximum(root, low[comp] + 0.1 * root))[0]
        _, _, src = dijkstra(graph, indices=roots, min_only=True, return_predecessors=True)
        anchor = np.where(dist <= root, np.arange(n), np.where(src >= 0, src, np.arange(n)))
        self._tri = skin.triangles[tri[anchor]]
        self._bary = bary[anchor]
        self._offset = p - near[anchor]                 # from the root's skin point, in the rest frame
        self._turns = anchor != np.arange(n)
        # each root's turn: that of the skin's mean normal around it (within `around`)
        used, self._which = np.unique(anchor[self._turns], return_inverse=True)
        balls = cKDTree(skin.vertices).query_ball_point(near[used], around)
        # too few skin points around (a coarse mesh): the root's own triangle's corners with them
        balls = [b if len(b) >= 3 else sorted(set(b) | set(skin.triangles[tri[r]].tolist()))
                 for b, r in zip(balls, used)]
        size = max((len(b) for b in balls), default=3)
        self._ball = np.zeros((len(used), size), np.int64)
        self._ball_w = np.zeros((len(used), size))
        for i, b in enumerate(balls):
            self._ball[i, :len(b)], self._ball_w[i, :len(b)] = b, 1.0
        # the ball's normals need only the triangles round its vertices
        touch = np.zeros(skin.n_vertices, bool)
        touch[self._ball[self._ball_w > 0]] = True
        self._near_tri = skin.triangles[touch[skin.triangles].any(1)]
        self._rest_normal = _mean_normal(vertex_normals(skin.vertices, self._near_tri)[self._ball],
                                         self._ball_w[..., None])

    def apply(self, skin_out: np.ndarray) -> np.ndarray:
        """The riders' positions (F, k, 3) on the transferred skin (F, n_skin, 3)."""
        at = np.einsum("kc,fkcd->fkd", self._bary, skin_out[:, self._tri])
        out = at + self._offset
        if self._turns.any():
            w = self._ball_w[..., None]
            for f in range(len(skin_out)):
                b = _mean_normal(vertex_normals(skin_out[f], self._near_tri)[self._ball], w)
                rot = _turn(self._rest_normal, b, np.radians(SLACK_DEG))
                out[f, self._turns] = at[f, self._turns] + np.einsum("kij,kj->ki", rot[self._which],
                                                                       self._offset[self._turns])
        return out


def _mean_normal(n, w):
    """(k, 3) unit mean of the normals n (k, m, 3) weighted by w (k, m, 1)."""
    m = (w * n).sum(1)
    return m / np.maximum(np.linalg.norm(m, axis=1, keepdims=True), 1e-300)


def _turn(a, b, slack: float = 0.0):
    """(k, 3, 3) the least rotations taking unit vectors a to b (Rodrigues), each less `slack`
    radians of its angle (none under it)."""
    v = np.cross(a, b)
    angle = np.maximum(np.arctan2(np.linalg.norm(v, axis=1), np.einsum("ki,ki->k", a, b)) - slack, 0.0)
    v = v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-300) * np.sin(angle)[:, None]
    c = np.cos(angle)
    x = np.zeros((len(a), 3, 3))
    x[:, 0, 1], x[:, 0, 2], x[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    x[:, 1, 0], x[:, 2, 0], x[:, 2, 1] = v[:, 2], -v[:, 1], v[:, 0]
    return np.eye(3) + x + (x @ x) / np.maximum(1 + c, 1e-9)[:, None, None]


SCREEN = 0.05     # the pockets' screened Laplacian: the rim's say fades over about 1/sqrt(SCREEN) rings


class _Pockets:
    """The target's pockets (mouth bag, eye sockets) moved as the source's (see the module's
    docstring).  Where the skin has a correspondence, a pocket is first carried onto the
    source's by it: the rim's offsets to their corresponding source points, spread over the
    pocket harmonically, bring the target's lips and lids onto the source's before each pocket
    point looks for its closest source point on a face turned its way
    (TriangleLocator.closest_facing); and the rim's source motion is read at its corresponding
    points."""

    def __init__(self, source: Mesh, ps: Parts, target: Mesh, pt: Parts, similarity: Similarity,
                 skin_index=None, match=None):
        self.similarity, self._back = similarity, similarity.inverse()
        self.rest = source.vertices
        pocket = pt.role == ROLES.index(POCKET)
        self.vertices = np.nonzero(pocket)[0]
        on = (ps.role == ROLES.index(POCKET)) | (ps.role == ROLES.index(SKIN))
        tri = source.triangles
        tri = tri[on[tri].all(1)]
        self._at = similarity.apply(target.vertices[self.vertices])     # in the source's frame
        looked = self._at
        # where a pocket meets the skin: those skin vertices' transferred motion is the boundary
        e = target.edges
        cross = pocket[e[:, 0]] != pocket[e[:, 1]]
        self.rim = rim = np.unique(np.where(pocket[e[cross, 0]], e[cross, 1], e[cross, 0]))
        if len(rim):
            self._rim_at = similarity.apply(target.vertices[rim])
            # screened: what the rim says fades over a few rings into the pocket, whose depths
            # keep the source's motion (a few rim points where the lips' transfer and the
            # source part ways no longer shift a whole bag: see SCREEN)
            self._join = HarmonicFill(target.adjacency, self.vertices, rim, SCREEN)
            # the rim's source points: where the skin's correspondence puts them, else closest
            corners, bary = np.full((len(rim), 3), -1), np.zeros((len(rim), 3))
            if match is not None and skin_index is not None:
                local = np.full(target.n_vertices, -1)
                local[skin_index] = np.arange(len(skin_index))
                k = local[rim]
                corners[k >= 0], bary[k >= 0] = match[0][k[k >= 0]], match[1][k[k >= 0]]
            ok = (corners >= 0).all(1)
            if not ok.all():
                ta, ba, _, _ = TriangleLocator(source.vertices, tri).closest(self._rim_at[~ok])
                corners[~ok], bary[~ok] = tri[ta], ba
            self._rim_corners, self._rim_bary = corners, bary
            if ok.any():
                # the rim's place on the source carried over the whole pocket (a harmonic warp;
                # a pocket that meets no skin keeps its place)
                put = np.einsum("kc,kcd->kd", bary, source.vertices[corners])
                looked = looked + HarmonicFill(target.adjacency, self.vertices, rim)(
                    np.where(ok[:, None], put - self._rim_at, 0.0))
        normals = target.vertex_normals()[self.vertices] @ similarity.rotation.T
        t, bary = TriangleLocator(source.vertices, tri).closest_facing(looked, normals)
        self._corners, self._bary = tri[t], bary

    def _source_motion(self, frames, corners, bary, at):
        """The source's displacement at the given points (`at`, in the source's frame), carried
        into the target's frame."""
        d = np.einsum("kc,fkcd->fkd", bary, frames[:, corners] - self.rest[corners])
        return self._back.apply((at[None] + d).reshape(-1, 3)).reshape(d.shape)

    def apply(self, frames: np.ndarray, out: np.ndarray) -> np.ndarray:
        """The pockets' positions (F, k, 3) for source frames (F, n_S, 3) and the target's other
        vertices already placed in `out`."""
        moved = self._source_motion(frames, self._corners, self._bary, self._at)
        if not len(self.rim):
            return moved
        gap = out[:, self.rim] - self._source_motion(frames, self._rim_corners, self._rim_bary, self._rim_at)
        return moved + self._join(gap.transpose(1, 0, 2)).transpose(1, 0, 2)   # the skin's motion less the source's


def _faces_of(mesh: Mesh, on: np.ndarray) -> np.ndarray:
    """The polygons with a corner among the vertices `on`."""
    return np.nonzero(np.add.reduceat(on[mesh.face_indices].astype(int), mesh.face_starts[:-1]) > 0)[0]


def _chin(source: Mesh, ps: Parts, lm) -> np.ndarray:
    """Source skin vertices near the chin (landmarks 6-10): the jaw's motion where the source
    has no lower teeth."""
    lm = np.asarray(lm, float)
    width = float(np.linalg.norm(lm[45] - lm[36]))
    skin = ps.skin
    near = np.zeros(source.n_vertices, bool)
    for k in range(6, 11):
        if np.isfinite(lm[k]).all():
            near |= np.linalg.norm(source.vertices - lm[k], axis=1) < 0.25 * width
    return np.nonzero(near & skin)[0]
