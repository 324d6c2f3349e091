"""Non-rigid registration of the source surface onto the target.

After Amberg, Romdhani and Vetter, "Optimal Step Nonrigid ICP Algorithms for Surface
Registration" (CVPR 2007): the source is deformed onto the target by a sequence of linear
solves with decreasing stiffness; at each step every source vertex is pulled to its closest
point on the target, dropped where that point lies on the target's boundary (a hole, the edge
of a scan) or where the two surfaces face different ways (Amberg §3.2), and a set of point
pairs (the landmarks, the lid and lip contours) is held with a fixed weight:

    min_d  alpha * sum_edges |d_i - d_j|^2 + sum_i w_i |v_i + d_i - c_i|^2
           + beta * sum_k |B_k (v + d) - p_k|^2                      (Amberg eq. 8, 3-9)

Departure from Amberg: in the stiff first steps a source vertex is pulled to the target point
nearest to it in position and normal together, (x, lambda n) in R^6 (the target vertex nearest in
R^6, then the point of its triangles nearest in R^6), not to the closest point: closest points
hold a surface only along its normal, so where no landmark is near (the neck, the cheeks) the
source slides along the target as far as the landmarks drag it, and a source with more neck than
the target slides its neck up over the target's.  Matching normals too ties the slide to the shape (the chin's turn
under the jaw, the cheekbones).  Measured on 40 remeshed ICT identities (seeds 200-239, three
random mixes each; not bench/transfer.py's held-out seeds): the transfer's mean relative error
0.0714 -> 0.0659, the neck's share 0.0227 -> 0.0190, 36 of 40 cases better, none worse by more
than 0.0022; lambda = half the landmarks' RMS spread, in the first 3 of the 6 steps (on seeds
200-219, matching the vertex alone: lambda = 10 target edges 0.0635 against 0.0636; 5 edges in
all six steps 0.0660 against 0.0652 in four; the vertex alone, without its triangles, on all 40:
0.0661 against 0.0659, and a coarse head's lips tore).  Amberg's rule stays: no data where the closest point
lies on the target's edge (with the normal-space match's own edge alone, the source's extra neck
found matches inside the target: 0.0759).  Only where the target resolves lambda (at least
NORMAL_MIN_EDGES of its edges across it): on a coarser one closest points throughout.

Departure from Amberg: the unknowns are per-vertex displacements d, not per-vertex affine
transforms (X_i, 12 unknowns).  The faces are already aligned (a similarity fit on the
landmarks), the stiffness term is the same unit-weight edge (node-arc) term, and x, y, z then
share one matrix: one factorization of an n x n system per step instead of 4n x 4n, the
symbolic analysis reused (CHOLMOD).  Measured on bench/transfer.py's remeshed target: the
transfer's relative error 0.132 (cylinder map) -> 0.092 with this registration (0.090 with the
exact correspondence the remesh was made with); cotangent weights instead of unit ones: 0.236.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from ..mesh import Mesh
from ..mesh.query import TriangleLocator, closest_point_on_triangles
from ..solver import SPDSolver

STIFFNESS = (50.0, 20.0, 8.0, 3.0, 1.0, 0.5)   # alpha per step, unit-weight edges (Amberg §4)
ITERATIONS = 2                                 # closest-point updates per stiffness
POINT_WEIGHT = 10.0                            # beta: landmarks and contour points
MAX_ANGLE = 60.0                               # degrees between normals beyond which no data
REACH = 10.0                                  # no data farther than this x the target's edge
NORMAL_STEPS = 3                               # stiffness steps matched in (position, normal) space
NORMAL_MIN_EDGES = 6.0                         # ... where lambda spans at least this many target edges
K = 8                                          # without libigl: closest-point candidates, first round
EXACT = 1.0                                    # without libigl: exact within this x the edge


@dataclass
class Registration:
    """The source deformed onto the target (register).

    Attributes
    ----------
    vertices : (n_source, 3) float array
    edge : float
        The target's median edge length.
    """
    vertices: np.ndarray      # (n_source, 3) the source deformed onto the target
    edge: float               # the target's median edge length


def rows_of(mesh: Mesh, triangle: np.ndarray, bary: np.ndarray) -> sp.csr_matrix:
    """Points on a mesh's surface as combinations of its vertices.

    Parameters
    ----------
    mesh : Mesh
    triangle : (k,) int array
    bary : (k, 3) float array

    Returns
    -------
    (k, n) sparse matrix
        Barycentric rows.
    """
    t = mesh.triangles[np.asarray(triangle)]
    r = np.repeat(np.arange(len(t)), 3)
    return sp.csr_matrix((np.asarray(bary, float).ravel(), (r, t.ravel())), shape=(len(t), mesh.n_vertices))


def median_edge(mesh: Mesh) -> float:
    """The median length of a mesh's edges.

    Parameters
    ----------
    mesh : Mesh

    Returns
    -------
    float
    """
    e = mesh.edges
    return float(np.median(np.linalg.norm(mesh.vertices[e[:, 0]] - mesh.vertices[e[:, 1]], axis=1)))


def on_boundary(mesh: Mesh, triangle: np.ndarray, bary: np.ndarray, boundary=None, eps: float = 1e-9) -> np.ndarray:
    """Which surface points lie on the mesh's boundary: every vertex they depend on is a boundary
    vertex (a point on a boundary edge, or a boundary vertex itself).

    Parameters
    ----------
    mesh : Mesh
    triangle : (k,) int array
    bary : (k, 3) float array
    boundary : (n,) bool array or None
        The mesh's boundary_vertices(), when the caller has them.
    eps : float
        Barycentrics at most this count as zero.

    Returns
    -------
    (k,) bool array
    """
    b = mesh.boundary_vertices() if boundary is None else boundary
    nz = np.asarray(bary) > eps
    return (nz & b[mesh.triangles[triangle]]).sum(1) == nz.sum(1)


def _normal_at(normals: np.ndarray, corners: np.ndarray, bary: np.ndarray) -> np.ndarray:
    """Unit normals (k, 3) at surface points: the vertex normals (n, 3) of their triangles'
    corners (k, 3) blended by the barycentrics (k, 3)."""
    nt = np.einsum("ij,ijk->ik", bary, normals[corners])
    return nt / np.maximum(np.linalg.norm(nt, axis=1, keepdims=True), 1e-300)


class _NormalSpace:
    """The target's surface searched in (position, lambda normal) space, R^6: the target vertex
    nearest in R^6, then the point of its triangles nearest in R^6 (the vertex alone snaps a
    coarse target's matches to its vertices)."""

    def __init__(self, target: Mesh, normals: np.ndarray, lam: float):
        self.start, self.around = target.vertex_triangles    # triangles by vertex, CSR
        self.used = np.nonzero(np.diff(self.start) > 0)[0]
        self.tree = cKDTree(np.hstack([target.vertices[self.used], lam * normals[self.used]]))
        self.target, self.normals, self.lam = target, normals, lam

    def match(self, x: np.ndarray, nx: np.ndarray):
        """(triangles, barycentrics, points, unit normals) matched to points x with normals nx."""
        j = self.used[self.tree.query(np.hstack([x, self.lam * nx]), workers=-1)[1]]
        count = self.start[j + 1] - self.start[j]
        row = np.repeat(np.arange(len(x)), count)
        tri = self.around[np.repeat(self.start[j] - np.cumsum(count) + count, count) + np.arange(len(row))]
        v, tt = self.target.vertices, self.target.triangles[tri]
        p, b = closest_point_on_triangles(x[row], v[tt[:, 0]], v[tt[:, 1]], v[tt[:, 2]])
        n = _normal_at(self.normals, tt, b)
        cost = ((p - x[row]) ** 2).sum(1) + self.lam ** 2 * ((n - nx[row]) ** 2).sum(1)
        order = np.lexsort((cost, row))
        best = order[np.searchsorted(row[order], np.arange(len(x)))]   # the cheapest of each row
        return tri[best], b[best], p[best], n[best]


def register(source: Mesh, points: sp.spmatrix, target: Mesh, targets: np.ndarray,
             stiffness=STIFFNESS, iterations: int = ITERATIONS, point_weight: float = POINT_WEIGHT,
             max_angle: float = MAX_ANGLE, normal_length: float = 0.0,
             normal_steps: int = NORMAL_STEPS) -> Registration:
    """Deform the source onto the target, both aligned: a non-rigid ICP after Amberg et al. 2007
    (closest points, none taken on the target's holes and edges or where the surfaces face apart;
    decreasing stiffness), with some source surface points held at given targets.

    Parameters
    ----------
    source, target : Mesh
    points : (k, n_source) sparse matrix
        Rows of source surface points (rows_of) held at `targets`: landmarks, contour samples.
    targets : (k, 3) float array
    stiffness : tuple of float
        Amberg's alpha per step, for unit-weight edges.
    iterations : int
        Closest-point updates per stiffness.
    point_weight : float
        Beta: the held points' weight.
    max_angle : float
        Degrees between normals beyond which a closest point is no data.
    normal_length : float
        Lambda, in the meshes' units: in the first `normal_steps` steps each source vertex is
        pulled to the target point nearest in (x, lambda n) rather than to its closest point
        (0, or under NORMAL_MIN_EDGES of the target's edges: closest points throughout, Amberg's
        rule).
    normal_steps : int
        How many of the stiffness steps match in normal space.

    Returns
    -------
    Registration
    """
    v0 = source.vertices
    adj = source.adjacency
    lap = (sp.diags(np.asarray(adj.sum(1)).ravel()) - adj).tocsr()    # sum over edges |d_i - d_j|^2
    B = sp.csr_matrix(points)
    BtB = (B.T @ B).tocsr()
    Bt_rhs = B.T @ (np.asarray(targets, float) - B @ v0)
    loc = TriangleLocator(target.vertices, target.triangles)
    t_normals = target.vertex_normals()
    h = median_edge(target)
    edge_of_target = target.boundary_vertices()
    cos_max = np.cos(np.radians(max_angle))
    # a target coarser than that has too few vertex normals across lambda to match on (the shared
    # 468-vertex head, lambda 3.8 edges: a coarse lip's edges stretched, 6 against 4 without)
    six = _NormalSpace(target, t_normals, normal_length) if normal_length >= NORMAL_MIN_EDGES * h else None
    d = np.zeros_like(v0)
    w = np.zeros(len(v0))
    tie = 1e-8 * sp.identity(len(v0))            # keeps a vertex no term reaches (unused) in place
    solver = None
    for step, alpha in enumerate(stiffness):
        for _ in range(iterations):
            x = v0 + d
            tri, bary, cp, dist = loc.closest(x, k=K, max_distance=EXACT * h)
            nt = _normal_at(t_normals, target.triangles[tri], bary)
            ns = source.vertex_normals(x)
            facing = np.einsum("ij,ij->i", ns, nt) > cos_max
            # no data where the closest point is on the target's edge (a part the target lacks)
            w = (~on_boundary(target, tri, bary, edge_of_target) & facing & (dist < REACH * h)).astype(float)
            if six is not None and step < normal_steps:
                tri, bary, cp, nt = six.match(x, ns)
                w *= ~on_boundary(target, tri, bary, edge_of_target) & (np.einsum("ij,ij->i", ns, nt) > cos_max)
            m = (alpha * lap + sp.diags(w) + point_weight * BtB + tie).tocsc()
            solver = SPDSolver(m) if solver is None else solver.refactor(m)
            d = solver.solve(w[:, None] * (cp - v0) + point_weight * Bt_rhs)
    return Registration(v0 + d, h)
