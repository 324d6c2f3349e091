"""A target that is the source's own mesh in another vertex layout: a DCC's export of it
(triangulated, vertices split at seams and materials, in another order), found by its uv.

Every face corner of the target must sit on the uv of a corner of the source (within
UV_TOLERANCE), each target vertex on one source vertex, every source vertex reached, and the
target's faces must lie within the source's (a triangulation of them).  Then the target is
the source's topology, and a transfer onto it is solved there, exactly as onto the source's
own file (transfer.ExpressionTransfer), instead of through a correspondence found again (a
registration finds 93.5 % of such a head's skin; Blender's GLB of an ICT identity then moved
0.050 of each shape's largest move away from its OBJ, median over the 52 ARKit shapes).
"""

from __future__ import annotations

from itertools import chain

import numpy as np
from scipy.spatial import cKDTree

from ..mesh import Mesh
from ..mesh.core import unique_rows

UV_TOLERANCE = 2e-5          # of the uv square: a float32 file and a text file agree within it


def same_mesh(source: Mesh, target: Mesh) -> np.ndarray | None:
    """Whether the target is the source's own mesh in another vertex layout (a DCC's export), found by
    its uv.

    Parameters
    ----------
    source, target : Mesh

    Returns
    -------
    (n_target,) int array or None
        The source vertex each target vertex is; None otherwise (another mesh, or no uv).
    """
    if source.uv is None or target.uv is None or source.face_uv_indices is None or target.face_uv_indices is None:
        return None
    if target.n_vertices < source.n_vertices:
        return None
    hi = _vertex_by_uv(source, target)
    if hi is None:
        return None
    reached = np.zeros(source.n_vertices, bool)
    reached[hi] = True
    if not reached.all():                         # only a twin of a reached vertex may be left out
        d, _ = cKDTree(source.vertices[reached]).query(source.vertices[~reached])
        if (d > 1e-9 * float(np.ptp(source.vertices, axis=0).max())).any():
            return None
    # the target's faces within the source's: each target triangle's corners in one source polygon
    import scipy.sparse as sp
    poly_of = np.repeat(np.arange(source.n_faces), source.face_sizes)
    has = sp.csr_matrix((np.ones(len(poly_of)), (source.face_indices, poly_of)),
                        shape=(source.n_vertices, source.n_faces))
    tri = hi[target.triangles]
    common = has[tri[:, 0]].multiply(has[tri[:, 1]]).multiply(has[tri[:, 2]])
    if (np.diff(common.tocsr().indptr) > 0).mean() < 0.999:
        return None
    return hi


def _vertex_by_uv(source: Mesh, target: Mesh) -> np.ndarray | None:
    """The source vertex of each target vertex: the one every corner of it shares a uv with
    (corners whose uv several source vertices share -- a collapsed iris pole -- decided by the
    nearest place once the unambiguous ones have aligned the two)."""
    s_uv = source.uv[source.face_uv_indices]
    corner_uvs = target.uv[target.face_uv_indices]
    uv_first, t_of, _ = unique_rows(corner_uvs)
    near = cKDTree(s_uv).query_ball_point(corner_uvs[uv_first], UV_TOLERANCE)
    lens = np.fromiter((len(c) for c in near), np.int64, len(near))
    if (lens == 0).any():
        return None
    # each distinct uv's source vertices, sorted: (uv, vertex) pairs made one integer each
    n_s = source.n_vertices
    pairs = np.unique(np.repeat(np.arange(len(near)), lens) * n_s
                      + source.face_indices[np.fromiter(chain.from_iterable(near), np.int64, int(lens.sum()))])
    pair_uv, pair_v = np.divmod(pairs, n_s)
    start = np.searchsorted(pair_uv, np.arange(len(near) + 1))
    one = np.diff(start) == 1
    first = pair_v[start[:-1]]
    corner_one = one[t_of]
    out = np.full(target.n_vertices, -1)
    lo = np.full(target.n_vertices, np.iinfo(np.int64).max)
    hi = np.full(target.n_vertices, -1)
    v1 = target.face_indices[corner_one]
    s1 = first[t_of[corner_one]]
    np.minimum.at(lo, v1, s1)
    np.maximum.at(hi, v1, s1)
    two = (hi >= 0) & (lo != hi)
    if two.any():                                 # corners of one vertex on two source vertices:
        size = float(np.ptp(source.vertices, axis=0).max())      # only where those two coincide (a
        if (np.linalg.norm(source.vertices[lo[two]] - source.vertices[hi[two]], axis=1) > 1e-9 * size).any():
            return None                           # split the source kept and the file welded)
    sure = hi >= 0
    out[sure] = hi[sure]
    rest = np.nonzero(~sure)[0]
    if len(rest):
        if sure.sum() < 4:
            return None
        from ..align import fit_similarity
        sim = fit_similarity(target.vertices[sure], source.vertices[out[sure]])
        placed = sim.apply(target.vertices[rest])
        corner_uv = np.full(target.n_vertices, -1)
        corner_uv[target.face_indices] = t_of
        for k, v in enumerate(rest):
            c = pair_v[start[corner_uv[v]]:start[corner_uv[v] + 1]]
            out[v] = c[np.argmin(np.linalg.norm(source.vertices[c] - placed[k], axis=1))]
    return out
