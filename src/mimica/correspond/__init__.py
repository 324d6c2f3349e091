"""Dense correspondence between two aligned faces of different topologies.

Two methods.  `method="nicp"` (the default): the source is registered onto the target by a
non-rigid ICP held at the landmarks (correspond.register, after Amberg et al. 2007), and every
target vertex takes the closest point of the registered source; a target vertex whose closest
point lies on the source's edge, farther than an edge length, has no partner (the target
reaches beyond the source there).  Each vertex also gets a confidence in [0, 1]: how close and
how parallel the two surfaces came there, exp(-d^2 / 2h^2) x max(0, n_t . n_s), h the target's
median edge length.

`method="cylinder"`: Song et al.'s map (§V.A):

1. Both faces are projected onto a cylinder around the head's vertical axis
   (u = angle, v = height; Song §V.A.1, u = arccos(x/r)).
2. The landmarks and the four corners of each face's (u, v) bounding box are triangulated
   (the "parameterization mesh", Song Fig. 6); every target vertex gets barycentric
   coordinates in its landmark triangle, and the same coordinates in the source's landmark
   triangle give its place in the source's cylinder map (Song eq. 8).
3. That place is looked up in the source's cylindrical mesh by exact point location (a k-d
   tree over triangle centroids and a barycentric test, standing in for the paper's
   rasterized mesh image); where the map folds (nostrils, ears), the layer whose radius is
   closest to the target vertex's wins.
4. Topology correction (Song §V.A.4): a target vertex that lands in no source triangle (a
   hole, or outside the source) is left unmatched; the transfer keeps its rest shape there.

The result is a `Correspondence`: for each target vertex a source triangle and barycentric
coordinates (DESIGN.md), and the sparse matrix of those weights.  Measured (bench/transfer.py,
remeshed held-out identity): the transfer's relative error 0.132 with the cylinder map, 0.092
with the registration (0.090 with the exact correspondence the remesh was made with; 0.0896
with the registration and the transfer's tent average, transfer.core).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.spatial import Delaunay, cKDTree

from ..align import face_cylinder
from ..errors import MimicaError
from ..mesh import Mesh
from ..mesh.query import TriangleLocator, barycentric_2d
from .register import on_boundary, register, rows_of

@dataclass
class Correspondence:
    """A dense map from the target's vertices onto the source's surface.

    Attributes
    ----------
    triangle : (n_target,) int array
        The source triangle each target vertex lies on (-1: unmatched).
    bary : (n_target, 3) float array
        Its barycentric coordinates there.
    n_source : int
        The source's vertex count.
    confidence : (n_target,) float array or None
        0 to 1: how close and parallel the two surfaces came (None for the cylinder map);
        below LOW a vertex counts as low-confidence.
    contours : list or None
        The lid and lip contours matched (correspond.contours), where asked for.
    """

    triangle: np.ndarray
    bary: np.ndarray
    n_source: int
    confidence: np.ndarray | None = None     # (n_target,) in [0, 1]; None for the cylinder map
    contours: list | None = None             # the lid and lip contours matched (correspond.contours)

    LOW = 0.5                                # below it a vertex counts as low-confidence

    @property
    def matched(self) -> np.ndarray:
        return self.triangle >= 0

    def matrix(self, source_triangles: np.ndarray) -> sp.csr_matrix:
        """Sparse (n_target x n_source) interpolation weights (zero rows where unmatched)."""
        ok = self.matched
        rows = np.repeat(np.nonzero(ok)[0], 3)
        cols = source_triangles[self.triangle[ok]].reshape(-1)
        return sp.csr_matrix((self.bary[ok].reshape(-1), (rows, cols)),
                             shape=(len(self.triangle), self.n_source))


def _param_mesh(uv_lm, uv_all):
    """Landmarks + the 4 corners of the (u, v) bounding box (Song Fig. 6)."""
    lo, hi = uv_all.min(0), uv_all.max(0)
    pad = 0.02 * (hi - lo) + 1e-9
    lo, hi = lo - pad, hi + pad
    corners = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])
    return np.vstack([uv_lm, corners])


def _locate(points, pts_mesh, tris):
    """For 2D points, a containing triangle of (pts_mesh, tris) and barycentrics (-1 if none)."""
    tri_out = np.full(len(points), -1, dtype=np.int64)
    bary_out = np.zeros((len(points), 3))
    a, b, c = pts_mesh[tris[:, 0]], pts_mesh[tris[:, 1]], pts_mesh[tris[:, 2]]
    for k in range(len(tris)):  # ~130 triangles: a loop over triangles, vectorized over points
        todo = tri_out < 0
        if not todo.any():
            break
        idx = np.nonzero(todo)[0]
        bc = barycentric_2d(points[idx], np.broadcast_to(a[k], (len(idx), 2)),
                            np.broadcast_to(b[k], (len(idx), 2)), np.broadcast_to(c[k], (len(idx), 2)))
        inside = (bc >= -1e-9).all(1)
        tri_out[idx[inside]] = k
        bary_out[idx[inside]] = bc[inside]
    return tri_out, bary_out


METHODS = ("nicp", "cylinder")
NORMAL_LENGTH = 0.5           # register's normal-space lambda, x the target landmarks' RMS spread
CONTOUR_WEIGHT = 1.0          # of a contour sample, against a landmark's (register.POINT_WEIGHT)


def correspond(source: Mesh, source_lm: np.ndarray, target: Mesh, target_lm: np.ndarray,
               k: int = 24, method: str = "nicp", lookup: np.ndarray | None = None,
               contours: bool = False) -> Correspondence:
    """Correspondence from the target's vertices to the source's surface; both faces already
    aligned (align.fit_similarity on their landmarks).

    Parameters
    ----------
    source, target : Mesh
        The faces.
    source_lm, target_lm : (68, 3) float arrays
        Landmark positions on each (NaN: missing; at least 6 present on both).
    k : int
        Neighbours of the cylinder map's interpolation ("cylinder" only).
    method : str
        "nicp": the source registered onto the target by a non-rigid ICP held at the landmarks
        (correspond.register), each target vertex taking its closest point; "cylinder": Song
        et al.'s cylinder map.
    lookup : (n_target, 3) float array or None
        Where each target vertex looks its partner up (None: where it is; the two sides of a
        cut seam look a little inside their own lip).
    contours : bool
        With "nicp", the lid and lip contours are also held, matched by arc length
        (correspond.contours).  Off by default: on four held-out remeshes the transfer's mean
        relative error was 0.1033 without them, 0.1035 with the eyes' rims, 0.1043 with the
        outer lips, 0.1073 with the inner lips, 0.1068 with all four (the landmarks and closest
        points already place the rims; a scan's ragged holes pull the source's rims off).

    Returns
    -------
    Correspondence
    """
    if method not in METHODS:
        raise MimicaError(f"unknown correspondence method {method!r}; use one of {', '.join(METHODS)}")
    both = np.isfinite(source_lm).all(1) & np.isfinite(target_lm).all(1)
    if both.sum() < 6:
        raise MimicaError("landmarks: at least 6 landmarks present on both faces are needed "
                          "for a dense correspondence")
    if method == "nicp":
        return _registered(source, source_lm, target, target_lm,
                           target.vertices if lookup is None else np.asarray(lookup, float), contours)
    if lookup is not None:
        target = target.with_vertices(np.asarray(lookup, float))
    cyl = face_cylinder(np.where(both[:, None], source_lm, np.nan))
    uv_s, r_s = cyl.project(source.vertices)
    uv_t, r_t = cyl.project(target.vertices)
    lm_s, _ = cyl.project(source_lm[both])
    lm_t, _ = cyl.project(target_lm[both])

    # parameterization mesh (Song Fig. 6), triangulated once on the source side
    # the corners A-D are taken from the box around both faces: the faces are aligned, so
    # outside the landmarks the map stays the identity even when one face is a cropped scan
    both_uv = np.vstack([uv_s, uv_t])
    ps = _param_mesh(lm_s, both_uv)
    pt = _param_mesh(lm_t, both_uv)
    tris = Delaunay(ps).simplices
    # Song eq. 8: same barycentric coordinates in the corresponding landmark triangle
    ptri, pbary = _locate(uv_t, pt, tris)
    inside = ptri >= 0
    q = np.full_like(uv_t, np.nan)
    q[inside] = np.einsum("ij,ijk->ik", pbary[inside], ps[tris[ptri[inside]]])

    # exact point location of q in the source's cylindrical mesh
    st = source.triangles
    tri_uv = uv_s[st]                                              # (T, 3, 2)
    span = tri_uv[:, :, 0].max(1) - tri_uv[:, :, 0].min(1)
    usable = span < np.pi * cyl.radius                             # drop triangles across the seam
    tid = np.nonzero(usable)[0]
    cent = tri_uv[tid].mean(1)
    tree = cKDTree(cent)
    edge = np.median(np.linalg.norm(tri_uv[tid, 1] - tri_uv[tid, 0], axis=1))
    kk = min(k, len(tid))
    qi = np.nonzero(inside)[0]
    _, cand = tree.query(q[qi], k=kk)
    cand = tid[cand.reshape(len(qi), kk)]
    qq = np.repeat(q[qi], kk, axis=0)
    ct = st[cand.reshape(-1)]
    bc = barycentric_2d(qq, uv_s[ct[:, 0]], uv_s[ct[:, 1]], uv_s[ct[:, 2]]).reshape(len(qi), kk, 3)
    bc = np.nan_to_num(bc, nan=-1.0)
    rr = np.einsum("ijk,ijk->ij", bc, r_s[st[cand]])
    contains = (bc >= -1e-7).all(2)
    # where several layers contain the point, the radius closest to the target's wins
    cost = np.where(contains, np.abs(rr - r_t[qi, None]), np.inf)
    best = np.argmin(cost, axis=1)
    hit = np.isfinite(cost[np.arange(len(qi)), best])
    # near misses (a point just outside a boundary): clamp into the nearest candidate when it
    # is within one typical edge length; further out it is a hole, left unmatched
    clamped = np.clip(bc, 0, None)
    clamped /= np.maximum(clamped.sum(2, keepdims=True), 1e-12)
    pc = np.einsum("ijk,ijkl->ijl", clamped, uv_s[st[cand]])
    dist = np.linalg.norm(pc - q[qi, None, :], axis=2)
    near = np.argmin(dist, axis=1)
    ok_near = ~hit & (dist[np.arange(len(qi)), near] < edge)
    pick = np.where(hit, best, near)
    good = hit | ok_near
    rows = np.arange(len(qi))
    triangle = np.full(target.n_vertices, -1, dtype=np.int64)
    bary = np.zeros((target.n_vertices, 3))
    triangle[qi[good]] = cand[rows, pick][good]
    bb = np.where(hit[:, None], bc[rows, pick], clamped[rows, pick])
    bary[qi[good]] = bb[good]
    return Correspondence(triangle, bary, source.n_vertices)


def _registered(source: Mesh, source_lm, target: Mesh, target_lm, lookup, contours=False) -> Correspondence:
    """The correspondence through a non-rigid registration of the source onto the target."""
    both = np.isfinite(source_lm).all(1) & np.isfinite(target_lm).all(1)
    tri, bary, _, _ = TriangleLocator(source.vertices, source.triangles).closest(source_lm[both])
    rows, pts, names = rows_of(source, tri, bary), target_lm[both], []
    if contours:
        from .contours import matched_contours
        c_rows, c_pts, names = matched_contours(source, source_lm, target, target_lm)
        k = np.sqrt(CONTOUR_WEIGHT)
        rows, pts = sp.vstack([rows, k * c_rows]).tocsr(), np.vstack([pts, k * c_pts])
    lm = target_lm[both]
    reg = register(source, rows, target, pts,
                   normal_length=NORMAL_LENGTH * float(np.sqrt(((lm - lm.mean(0)) ** 2).sum(1).mean())))
    tri, bary, _, dist = TriangleLocator(reg.vertices, source.triangles).closest(lookup)
    h = reg.edge
    beyond = on_boundary(source, tri, bary) & (dist > h)
    ns = np.einsum("ij,ijk->ik", bary, source.vertex_normals(reg.vertices)[source.triangles[tri]])
    ns /= np.maximum(np.linalg.norm(ns, axis=1, keepdims=True), 1e-300)
    facing = np.clip(np.einsum("ij,ij->i", ns, target.vertex_normals()), 0, 1)
    confidence = np.exp(-0.5 * (dist / h) ** 2) * facing
    confidence[beyond] = 0.0
    tri = np.where(beyond, -1, tri)
    return Correspondence(tri, np.where(beyond[:, None], 0.0, bary), source.n_vertices, confidence, names)
