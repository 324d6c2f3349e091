"""The `Mesh` data type: vertices and polygon faces (triangles, quads, mixed).

Polygons are stored flat: ``face_indices`` holds every face's corners one after the
other and ``face_starts`` (length F+1) where each face begins, as in CSR matrices.
Triangulation, edges and one-rings are derived on demand and cached.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import scipy.sparse as sp


def _flatten_faces(faces):
    """(F,k) array or a sequence of index sequences -> (flat indices, starts)."""
    if isinstance(faces, np.ndarray) and faces.ndim == 2:
        f = np.asarray(faces, dtype=np.int64)
        starts = np.arange(0, f.size + 1, max(f.shape[1], 1), dtype=np.int64)
        if f.shape[0] == 0:
            starts = np.zeros(1, dtype=np.int64)
        return f.reshape(-1), starts
    sizes = np.fromiter((len(p) for p in faces), dtype=np.int64, count=len(faces))
    starts = np.zeros(len(sizes) + 1, dtype=np.int64)
    np.cumsum(sizes, out=starts[1:])
    flat = np.fromiter((i for p in faces for i in p), dtype=np.int64, count=int(starts[-1]))
    return flat, starts


@dataclass(eq=False)
class Mesh:
    """A polygon mesh (triangles, quads and larger polygons, mixed); triangulation, edges and
    adjacency are derived and cached, never stored twice.

    Attributes
    ----------
    vertices : (n, 3) float64 array
        Positions, in the user's units.
    face_indices : (c,) int64 array
        Every polygon's corners, one polygon after another.
    face_starts : (n_faces + 1,) int64 array
        Where each polygon's corners start in `face_indices` (the last entry is c).
    uv : (t, 2) float array or None
        Texture coordinates, with `face_uv_indices` (c,) parallel to `face_indices` (the OBJ
        model: a corner has its own uv index).
    name : str
        The file's stem, or "".
    groups : (n_faces,) int array or None
        Each face's material or group, an index into `group_names` (OBJ `usemtl`, else `g`/`o`),
        kept through submesh, with_vertices and OBJ writing.
    layout : GltfLayout or FbxLayout or None
        Where a file of another tool put these vertices, so that a result can be written back
        into that file; None for OBJ and PLY.  Kept by with_vertices.
    """

    vertices: np.ndarray
    face_indices: np.ndarray
    face_starts: np.ndarray
    uv: np.ndarray | None = None
    face_uv_indices: np.ndarray | None = None
    name: str = ""
    groups: np.ndarray | None = None
    group_names: tuple = ()
    layout: object = field(default=None, repr=False)
    _cache: dict = field(default_factory=dict, repr=False)

    @classmethod
    def from_faces(cls, vertices, faces, uv=None, face_uv=None, name=""):
        flat, starts = _flatten_faces(faces)
        fuv = None
        if face_uv is not None:
            fuv, ustarts = _flatten_faces(face_uv)
            if not np.array_equal(ustarts, starts):
                raise ValueError("face_uv must have the same polygon sizes as faces")
        return cls(np.asarray(vertices, dtype=np.float64), flat, starts,
                   None if uv is None else np.asarray(uv, dtype=np.float64), fuv, name)

    # ------------------------------------------------------------------ basic
    @property
    def n_vertices(self) -> int:
        return int(self.vertices.shape[0])

    @property
    def n_faces(self) -> int:
        return int(self.face_starts.shape[0] - 1)

    @cached_property
    def face_sizes(self) -> np.ndarray:
        return np.diff(self.face_starts)

    @property
    def faces(self):
        """(F, k) array when every face has k corners, else a list of arrays."""
        s = self.face_sizes
        if s.size and np.all(s == s[0]):
            return self.face_indices.reshape(-1, int(s[0]))
        if s.size == 0:
            return np.zeros((0, 3), dtype=np.int64)
        return np.split(self.face_indices, self.face_starts[1:-1])

    def with_vertices(self, vertices, name=None) -> "Mesh":
        """Same topology (and uv), new positions; derived topology caches are shared."""
        v = np.asarray(vertices, dtype=np.float64)
        if v.shape != self.vertices.shape:
            raise ValueError(f"expected vertices of shape {self.vertices.shape}, got {v.shape}")
        m = Mesh(v, self.face_indices, self.face_starts, self.uv, self.face_uv_indices,
                 self.name if name is None else name, self.groups, self.group_names, self.layout)
        for k in ("triangles", "tri_face", "_fan_corners", "uv_triangles", "edges", "_edge_counts", "half_edges",
                  "adjacency", "face_sizes", "outward_oriented"):
            if k in self.__dict__:
                m.__dict__[k] = self.__dict__[k]
        return m

    def welded(self, same: np.ndarray | None = None) -> tuple["Mesh", np.ndarray]:
        """Coincident vertices made one (an unwelded seam: a uv or normal split saved as copies
        of a vertex) and, for each vertex, its index in the welded mesh; (self, arange) when no
        two coincide.  Only exact copies are welded, within one material (OBJ usemtl/group),
        and only where the surface stays a manifold: parts that merely touch (lashes rooted on
        a lid, a shell on the eye's rim) stay apart, along an edge (no third face on it) or at a
        point (a copy that shares no edge with another once welded); a slit meant to open is
        not welded.

        Parameters
        ----------
        same : (n, k) float array or None
            Values the copies must share too (a file's morph-target moves: copies that move
            apart, as the two lips of a cut mouth, are a slit, not a seam).
        """
        key = self.vertices if same is None else np.c_[self.vertices, same]
        if self.groups is not None:               # copies in different materials are different parts
            vg = np.full(self.n_vertices, -1.0)
            vg[self.face_indices[::-1]] = np.repeat(self.groups, np.diff(self.face_starts))[::-1]
            key = np.c_[key, vg]
        first, group, _ = unique_rows(key)
        if len(first) == self.n_vertices:
            return self, np.arange(self.n_vertices)
        nxt = np.roll(self.face_indices, -1)
        nxt[self.face_starts[1:] - 1] = self.face_indices[self.face_starts[:-1]]   # each polygon's closing edge
        pairs = np.sort(np.stack([self.face_indices, nxt], 1), axis=1)
        first, _, uses = unique_rows(pairs)
        raw = pairs[first]                                  # each edge once, and its faces
        for _ in range(8):
            e = np.sort(group[raw], axis=1)
            _, eid, cnt = unique_rows(e)
            sizes = np.bincount(group)
            # un-weld where an edge would get a third face
            faces = np.bincount(eid, uses, len(cnt))
            bad = np.unique(e[faces[eid] > 2])
            undo = np.isin(group, bad[sizes[bad] > 1])          # only welds can be undone
            # and a copy that shares no edge with another once welded: pieces touching at a
            # point (a lash's root on a shell, a shell's corner on the lid), not a split seam
            joined = np.zeros(self.n_vertices, bool)
            joined[raw[cnt[eid] > 1].ravel()] = True
            undo |= (sizes[group] > 1) & ~joined
            if not undo.any():
                break
            group = group.copy()
            group[undo] = group.max() + 1 + np.arange(undo.sum())
        _, first, group = np.unique(group, return_index=True, return_inverse=True)
        if len(first) == self.n_vertices:
            return self, np.arange(self.n_vertices)
        order = np.argsort(first)                 # welded vertices keep the order of first use
        rank = np.empty_like(order)
        rank[order] = np.arange(len(order))
        new = rank[group.ravel()]
        # uv stays per corner (the OBJ model), so the welded mesh keeps its texture seams
        return Mesh(self.vertices[first[order]], new[self.face_indices], self.face_starts, self.uv,
                    self.face_uv_indices, self.name, self.groups, self.group_names), new

    def same_topology(self, other: "Mesh") -> bool:
        return (self.n_vertices == other.n_vertices
                and np.array_equal(self.face_starts, other.face_starts)
                and np.array_equal(self.face_indices, other.face_indices))

    # ---------------------------------------------------------------- derived
    @cached_property
    def _fan_corners(self) -> np.ndarray:
        """(T, 3) positions in face_indices of the corners of the fan triangles."""
        s = self.face_sizes
        ntri = np.maximum(s - 2, 0)
        # corner k of the fan in its face: 1..size-2
        first = np.repeat(self.face_starts[:-1], ntri)
        k = np.arange(ntri.sum()) - np.repeat(np.cumsum(ntri) - ntri, ntri) + 1
        return np.stack([first, first + k, first + k + 1], axis=1)

    @cached_property
    def triangles(self) -> np.ndarray:
        """(T, 3) fan triangulation of the polygons."""
        return self.face_indices[self._fan_corners]

    @cached_property
    def uv_triangles(self) -> np.ndarray | None:
        """(T, 3) texture-coordinate indices of the corners of `triangles` (None without uv)."""
        if self.uv is None or self.face_uv_indices is None:
            return None
        return self.face_uv_indices[self._fan_corners]

    @cached_property
    def tri_face(self) -> np.ndarray:
        """For each triangle of `triangles`, the polygon it came from."""
        return np.repeat(np.arange(self.n_faces), np.maximum(self.face_sizes - 2, 0))

    @cached_property
    def vertex_triangles(self) -> tuple[np.ndarray, np.ndarray]:
        """The triangles (of `triangles`) around each vertex, as CSR arrays.

        Returns
        -------
        start : (n + 1,) int array
        around : (k,) int array
            Vertex i's triangles are around[start[i]:start[i + 1]], in increasing order.
        """
        return _incidence(self.triangles.ravel(), 3, self.n_vertices)

    @cached_property
    def vertex_faces(self) -> tuple[np.ndarray, np.ndarray]:
        """The polygons around each vertex, as CSR arrays.

        Returns
        -------
        start : (n + 1,) int array
        around : (k,) int array
            Vertex i's polygons are around[start[i]:start[i + 1]], in increasing order (a polygon
            that meets it twice, twice).
        """
        corner_face = np.repeat(np.arange(self.n_faces), self.face_sizes)
        start, order = _incidence(self.face_indices, 1, self.n_vertices)
        return start, corner_face[order]

    @cached_property
    def half_edges(self) -> np.ndarray:
        """(k, 2) every polygon's sides in its winding, one row per face corner (its corner and
        the next): the same edge of two faces wound alike is an inconsistent orientation."""
        fi, st = self.face_indices, self.face_starts
        nxt = np.arange(fi.size) + 1
        nxt[st[1:] - 1] = st[:-1]
        return np.stack([fi, fi[nxt]], axis=1)

    def _polygon_edges(self) -> np.ndarray:
        """Every polygon's boundary edges as sorted pairs, one row per polygon side."""
        e = np.sort(self.half_edges, axis=1)
        return e[e[:, 0] != e[:, 1]]

    @cached_property
    def _edge_counts(self) -> tuple[np.ndarray, np.ndarray]:
        """The unique undirected polygon edges (E, 2), i < j, sorted, and how many polygons use each
        (E,): one sort of integer keys i * n + j (np.unique over rows sorts far slower)."""
        e = self._polygon_edges().astype(np.int64)
        n = max(self.n_vertices, 1)
        keys, counts = np.unique(e[:, 0] * n + e[:, 1], return_counts=True)
        pairs = np.stack([keys // n, keys % n], axis=1)
        pairs.flags.writeable = counts.flags.writeable = False
        return pairs, counts

    @cached_property
    def edges(self) -> np.ndarray:
        """(E, 2) unique undirected polygon edges (diagonals of the fan excluded), i < j."""
        return self._edge_counts[0]

    @cached_property
    def adjacency(self) -> sp.csr_matrix:
        """(n, n) symmetric 0/1 vertex adjacency along polygon edges (CSR, sorted)."""
        from .graph import edge_graph
        a = edge_graph(self.n_vertices, self.edges)
        a.sum_duplicates()
        a.sort_indices()
        return a

    def face_normals(self, vertices=None) -> np.ndarray:
        """Area-weighted (unnormalized, length = 2*area) triangle normals, (T, 3)."""
        v = self.vertices if vertices is None else vertices
        t = self.triangles
        return np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])

    def triangle_areas(self, vertices=None) -> np.ndarray:
        """Areas of the fan triangles, (T,)."""
        return 0.5 * np.linalg.norm(self.face_normals(vertices), axis=1)

    def mean_edge_length(self, vertices=None) -> float:
        v = self.vertices if vertices is None else vertices
        e = self.edges
        return float(np.linalg.norm(v[e[:, 1]] - v[e[:, 0]], axis=1).mean())

    def boundary_vertices(self) -> np.ndarray:
        """bool (n,): vertices on an edge that only one polygon uses (outline and holes)."""
        out = np.zeros(self.n_vertices, bool)
        out[self.boundary_edges().ravel()] = True
        return out

    def boundary_edges(self) -> np.ndarray:
        """(B, 2) the edges only one polygon uses."""
        uq, cnt = self._edge_counts
        return uq[cnt == 1]

    def face_centroids(self) -> np.ndarray:
        """Mean of each polygon's corners, (F, 3)."""
        sums = np.add.reduceat(self.vertices[self.face_indices], self.face_starts[:-1], axis=0)
        return sums / self.face_sizes[:, None]

    @cached_property
    def outward_oriented(self) -> bool:
        """True when the polygons are consistently oriented (no directed edge used twice) and
        face outward (the signed volume they enclose about the centroid is positive and more
        than 5% of the bounding box's), so that back faces can be culled when drawing."""
        t = self.triangles
        if len(t) == 0:
            return False
        a = np.concatenate([t[:, 0], t[:, 1], t[:, 2]])
        b = np.concatenate([t[:, 1], t[:, 2], t[:, 0]])
        key = a * np.int64(self.n_vertices) + b
        if len(np.unique(key)) != len(key):
            return False
        v = self.vertices - self.vertices.mean(0)
        vol = np.einsum("ij,ij->i", v[t[:, 0]], np.cross(v[t[:, 1]], v[t[:, 2]])).sum() / 6
        return bool(vol > 0.05 * np.prod(np.ptp(v, 0)))

    def vertex_normals(self, vertices=None) -> np.ndarray:
        """Unit area-weighted vertex normals (n, 3); isolated vertices get (0, 0, 0)."""
        v = self.vertices if vertices is None else vertices
        return vertex_normals(v, self.triangles)

    def submesh(self, face_ids) -> tuple["Mesh", np.ndarray]:
        """The mesh made of the given polygons, and for each new vertex its old index."""
        face_ids = np.asarray(face_ids, dtype=np.int64)
        sizes = self.face_sizes[face_ids]
        starts = np.zeros(len(face_ids) + 1, dtype=np.int64)
        np.cumsum(sizes, out=starts[1:])
        idx = np.concatenate([np.arange(self.face_starts[f], self.face_starts[f + 1]) for f in face_ids]) \
            if len(face_ids) else np.zeros(0, dtype=np.int64)
        old = np.unique(self.face_indices[idx])
        remap = np.full(self.n_vertices, -1, dtype=np.int64)
        remap[old] = np.arange(len(old))
        uv = fuv = None
        if self.uv is not None and self.face_uv_indices is not None:
            uold = np.unique(self.face_uv_indices[idx])
            uremap = np.full(len(self.uv), -1, dtype=np.int64)
            uremap[uold] = np.arange(len(uold))
            uv, fuv = self.uv[uold], uremap[self.face_uv_indices[idx]]
        groups = self.groups[face_ids] if self.groups is not None else None
        m = Mesh(self.vertices[old], remap[self.face_indices[idx]], starts, uv, fuv, self.name, groups,
                 self.group_names)
        return m, old

    def bounding_box_diagonal(self) -> float:
        v = self.vertices
        return float(np.linalg.norm(v.max(0) - v.min(0))) if len(v) else 0.0


def unique_rows(key: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The distinct rows of a 2D array as np.unique(key, axis=0, return_index=True,
    return_inverse=True, return_counts=True) gives them -- the same groups in the same order
    (rows sorted column by column; -0.0 equal to 0.0, NaN rows each their own) -- by one stable
    lexsort: numpy sorts the rows as structured records, 10-20x slower on a head's vertices.

    Parameters
    ----------
    key : (n, k) array

    Returns
    -------
    first : (u,) int array
        Each distinct row's first occurrence.
    inverse : (n,) int array
        Each row's group.
    counts : (u,) int array
    """
    key = np.asarray(key)
    if not len(key):
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64)
    key = key.reshape(len(key), -1)
    order = np.lexsort(key.T[::-1])
    s = key[order]
    new = np.r_[True, (s[1:] != s[:-1]).any(1)]
    inverse = np.empty(len(key), np.int64)
    inverse[order] = np.cumsum(new) - 1
    starts = np.nonzero(new)[0]
    return order[starts], inverse, np.diff(np.r_[starts, len(key)])


def cross_matrices(v: np.ndarray) -> np.ndarray:
    """The cross product's matrices of vectors: [v]x, so that [v]x a = v x a.

    Parameters
    ----------
    v : (n, 3) float array

    Returns
    -------
    (n, 3, 3) float array
    """
    K = np.zeros((len(v), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = v[:, 2], -v[:, 1], v[:, 0]
    return K


def vertex_normals(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Unit area-weighted vertex normals.

    Parameters
    ----------
    vertices : (n, 3) float array
    triangles : (m, 3) int array

    Returns
    -------
    (n, 3) float array
        Isolated vertices get (0, 0, 0).
    """
    v = vertices
    fn = np.cross(v[triangles[:, 1]] - v[triangles[:, 0]], v[triangles[:, 2]] - v[triangles[:, 0]])
    vn = np.zeros_like(v)
    for k in range(3):
        for c in range(3):
            vn[:, c] += np.bincount(triangles[:, k], weights=fn[:, c], minlength=len(v))
    ln = np.linalg.norm(vn, axis=-1, keepdims=True)
    return np.divide(vn, ln, out=np.zeros_like(vn), where=ln > 0)


def plane_grid(nx: int, ny: int, length: float, width: float) -> Mesh:
    """A flat rectangle in the z = 0 plane, each cell cut into two triangles along alternating
    diagonals (no preferred direction).

    Parameters
    ----------
    nx, ny : int
        Cells along x and y.
    length, width : float
        Its size along x and y.

    Returns
    -------
    Mesh
        (nx + 1) * (ny + 1) vertices.
    """
    xs, ys = np.meshgrid(np.linspace(0, length, nx + 1), np.linspace(0, width, ny + 1), indexing="ij")
    v = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], 1)
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    a = (i * (ny + 1) + j).ravel()
    b, c, d = a + ny + 1, a + ny + 2, a + 1
    odd = ((i + j) % 2).ravel().astype(bool)
    t1 = np.where(odd[:, None], np.stack([a, b, c], 1), np.stack([a, b, d], 1))
    t2 = np.where(odd[:, None], np.stack([a, c, d], 1), np.stack([b, c, d], 1))
    return Mesh.from_faces(v, np.stack([t1, t2], 1).reshape(-1, 3))


def _incidence(corners: np.ndarray, per: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Corners (k,) (vertex indices, `per` to an element, in order) grouped by vertex: (start
    (n + 1,), the elements in vertex order); with per=1, the corners' positions instead."""
    order = np.argsort(corners, kind="stable")
    start = np.searchsorted(corners[order], np.arange(n + 1))
    return start, order // per
