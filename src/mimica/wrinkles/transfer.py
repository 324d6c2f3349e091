"""Carrying a wrinkle mask onto another face (Viaud & Yahia 1992, §3.2).

1. The new face is placed on the reference by a similarity from the landmarks.
2. Each face gets its own cylinder (§3.1, conjugate gradient on the skin near the mask),
   and the mask's nodes (characteristic points = anchors, and the wrinkles' control points)
   are flattened on the reference's, the new face's anchors on the new face's.
3. A sprung mesh joins the reference's nodes (Delaunay edges of the flattened nodes and the
   wrinkle lines); its anchors are moved onto the new face's and held, and it relaxes by
       m_i a_i = sum_j k_ij (|P_i P_j| - |P0_i P0_j|) P_i P_j / |P_i P_j| - h v_i       (eq. 8)
   with k_ij inversely proportional to the rest length (short springs are stiffer).
4. The relaxed nodes are projected back onto the new face's surface (outermost skin under
   each flattened point), in the new face's own coordinates and topology.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy.spatial import Delaunay, cKDTree

from ..align import fit_similarity
from ..errors import MimicaError
from ..mesh import Mesh
from ..mesh.core import unique_rows
from .cylinder import fit_cylinder, flatten, radial_distance
from .mask import Wrinkle, WrinkleMask, boundary_anchors
from ..mesh.query import SurfaceMap, TriangleLocator
from .surface import FaceFrame


@dataclass
class MaskTransferInfo:
    """How a wrinkle mask's transfer went (transfer_mask).

    Attributes
    ----------
    iterations : int
        Of the spring relaxation (relax).
    residual : float
        The largest spring force left, relative to the mean rest length.
    seconds : float
    cylinder_radius : float
        The radius of the cylinder fitted to the target's face (wrinkles.cylinder).
    """
    iterations: int
    residual: float           # largest spring force left, relative to the mean rest length
    seconds: float
    cylinder_radius: float


def _region(vertices, anchors, reach):
    ok = np.isfinite(anchors).all(1)
    d, _ = cKDTree(anchors[ok]).query(vertices)
    return vertices[d < reach]


def _cylinder(vertices, anchors, frame: FaceFrame):
    cyl0 = frame.cylinder
    pts = _region(vertices, anchors, 0.3 * frame.unit)
    return fit_cylinder(pts, axis_guess=cyl0.axes[1], origin_guess=cyl0.origin, radius_guess=cyl0.radius)


def relax(rest2d, start2d, fixed, edges, damping=0.9, tol=1e-7, max_iter=20000):
    """V&Y eq. 8 by semi-implicit Euler with velocity damping until the nodes stop moving: a spring
    network relaxed with some nodes held.

    Parameters
    ----------
    rest2d : (n, 2) float array
        Reference positions (the springs' rest lengths).
    start2d : (n, 2) float array
        Where the nodes start, the fixed ones already at their new places.
    fixed : (n,) bool array
    edges : (m, 2) int array
        The springs.
    damping : float
        The velocity kept a step.
    tol : float
        Stop when no node moves more than this (relative to the mean rest length).
    max_iter : int

    Returns
    -------
    positions : (n, 2) float array
    iterations : int
    residual : float
        The largest spring force left, relative to the mean rest length.
    """
    i, j = edges[:, 0], edges[:, 1]
    L0 = np.linalg.norm(rest2d[i] - rest2d[j], axis=1)
    if (L0 <= 0).any():
        raise MimicaError("wrinkle mask: two mask nodes coincide on the reference")
    scale = float(L0.mean())
    k = scale / L0                                            # variable stiffness k_ij
    deg = np.bincount(np.r_[i, j], np.r_[k, k], len(rest2d))
    dt = 0.5 / np.sqrt(deg.max())                             # stable for unit masses
    x = start2d.copy()
    v = np.zeros_like(x)
    free = ~fixed
    n = len(x)

    def forces(x):
        e = x[j] - x[i]
        ln = np.maximum(np.linalg.norm(e, axis=1), 1e-12)
        f = (k * (ln - L0) / ln)[:, None] * e                 # pulls i toward j when stretched
        return np.stack([np.bincount(i, f[:, c], n) - np.bincount(j, f[:, c], n) for c in (0, 1)], 1)
    it = 0
    for it in range(1, max_iter + 1):
        F = forces(x) - damping * v                           # - h v
        v[free] += dt * F[free]
        x[free] += dt * v[free]
        if it % 50 == 0 and np.abs(v[free]).max() * dt < tol * scale:
            break
    return x, it, float(np.abs(forces(x)[free]).max() / scale) if free.any() else 0.0


def transfer_mask(mask: WrinkleMask, reference: Mesh, target: Mesh, target_landmarks: np.ndarray,
                  target_anchors: np.ndarray | None = None, name: str = "") -> tuple[WrinkleMask, MaskTransferInfo]:
    """A wrinkle mask carried onto a face of any topology (V&Y §3.2): both faces unrolled on their
    fitted cylinders, the mask's anchors placed at the target's landmarks, the rest of its points
    relaxed as a spring network (relax), then lifted onto the target's surface.

    Parameters
    ----------
    mask : WrinkleMask
        Lying on `reference`.
    reference : Mesh
    target : Mesh
    target_landmarks : (68, 3) float array
    target_anchors : (k, 3) float array or None
        The target's anchors (its 68 landmarks, then the mask's boundary anchors) as a mask
        already on this face placed them, which the transfer keeps; None: made from the
        landmarks (boundary_anchors).
    name : str
        The face's name, recorded in the mask.

    Returns
    -------
    mask : WrinkleMask
        On the target.
    info : MaskTransferInfo
    """
    t0 = time.perf_counter()
    ref_anchors = mask.anchors
    if np.isfinite(ref_anchors[:68]).all(1).sum() < 20:
        raise MimicaError("wrinkle mask: its anchors need at least 20 of the 68 landmarks")
    tl = np.asarray(target_landmarks, float)
    if target_anchors is None:
        target_anchors = np.vstack([tl, boundary_anchors(target, tl)])
    sim = fit_similarity(target_anchors[:68], ref_anchors[:68], "landmarks")
    Vt = sim.apply(target.vertices)
    At = sim.apply(target_anchors)
    frame_r, frame_t = FaceFrame(ref_anchors[:68]), FaceFrame(At[:68])
    cyl_r = _cylinder(reference.vertices, ref_anchors, frame_r)
    cyl_t = _cylinder(Vt, At, frame_t)
    fwd = frame_r.axes[2]
    ctrl = [w.points for w in mask.wrinkles]
    sizes = [len(c) for c in ctrl]
    nodes_r = np.vstack([ref_anchors] + ctrl)
    ok_anchor = np.isfinite(ref_anchors).all(1) & np.isfinite(At).all(1)
    keep = np.r_[ok_anchor, np.ones(sum(sizes), bool)]
    rest2d = flatten(nodes_r[keep], cyl_r, forward=fwd)
    na = int(ok_anchor.sum())
    start = rest2d.copy()
    start[:na] = flatten(At[ok_anchor], cyl_t, forward=fwd)
    # free nodes start where the anchors' piecewise-affine warp puts them, so the relaxation
    # settles in the unfolded equilibrium next to it (a spring net alone may flip a node
    # across a nearby anchor)
    dt_a = Delaunay(rest2d[:na])
    simplex = dt_a.find_simplex(rest2d[na:])
    inside = simplex >= 0
    T = dt_a.transform[simplex[inside]]
    bc = np.einsum("ijk,ik->ij", T[:, :2], rest2d[na:][inside] - T[:, 2])
    bary = np.c_[bc, 1 - bc.sum(1)]
    corners = dt_a.simplices[simplex[inside]]
    moved = np.einsum("ij,ijk->ik", bary, start[:na][corners])
    start[na:][inside] = moved
    fixed = np.zeros(len(rest2d), bool)
    fixed[:na] = True
    tri = Delaunay(rest2d).simplices
    edges = np.vstack([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    off = na
    for s in sizes:                                         # the wrinkle lines themselves
        idx = np.arange(off, off + s)
        edges = np.vstack([edges, np.stack([idx[:-1], idx[1:]], 1)])
        off += s
    edges = np.sort(edges, 1)
    edges = edges[unique_rows(edges)[0]]
    x, iters, resid = relax(rest2d, start, fixed, edges)
    # back onto the new surface: the outermost skin under each flattened point
    flat_t = flatten(Vt, cyl_t, forward=fwd)
    smap = SurfaceMap(target.triangles, flat_t, radial_distance(Vt, cyl_t), target.vertices,
                      max_span=np.pi * cyl_t.radius)
    p3, found = smap.points(x[na:])
    wrinkles, off = [], 0
    for w, s in zip(mask.wrinkles, sizes):
        if not found[off:off + s].any():
            raise MimicaError(f"wrinkle {w.name!r} falls off the target face; give it landmarks that cover the face")
        wrinkles.append(Wrinkle(w.name, p3[off:off + s], w.muscles, w.emphasis, w.width / sim.scale,
                                w.profile, w.fold))
        off += s
    out = WrinkleMask(wrinkles, np.asarray(target_anchors, float), name or target.name)
    return out, MaskTransferInfo(iters, resid, time.perf_counter() - t0, cyl_t.radius / sim.scale)


def _moved(mask: WrinkleMask, move, face="") -> WrinkleMask:
    """The mask with every point (wrinkle control points, anchors) passed through `move`."""
    ws = [Wrinkle(w.name, move(w.points), w.muscles, w.emphasis, w.width, w.profile, w.fold)
          for w in mask.wrinkles]
    A = mask.anchors.copy()
    ok = np.isfinite(A).all(1)
    A[ok] = move(A[ok])
    return WrinkleMask(ws, A, face or mask.face, dict(mask.extra))


def snap_mask(mask: WrinkleMask, mesh: Mesh) -> tuple[WrinkleMask, np.ndarray]:
    """A mask's points moved onto the closest points of a mesh's surface (after edits).

    Parameters
    ----------
    mask : WrinkleMask
    mesh : Mesh

    Returns
    -------
    mask : WrinkleMask
    distance : (k,) float array
        How far each wrinkle control point was from the surface.
    """
    loc = TriangleLocator(mesh.vertices, mesh.triangles)
    dist = loc.closest(np.vstack([w.points for w in mask.wrinkles]))[3]
    return _moved(mask, lambda p: loc.closest(p)[2]), dist


def carry_mask(mask: WrinkleMask, reference: Mesh, vertices: np.ndarray, face="") -> WrinkleMask:
    """A mask on another shape of the reference's own topology (an identity, an expression): each
    point keeps its triangle and barycentric coordinates.

    Parameters
    ----------
    mask : WrinkleMask
        On `reference`.
    reference : Mesh
    vertices : (n, 3) float array
        The other shape.
    face : str
        Its name, recorded in the mask.

    Returns
    -------
    WrinkleMask
    """
    loc = TriangleLocator(reference.vertices, reference.triangles)
    tri = reference.triangles

    def move(p):
        t, b, _, _ = loc.closest(p)
        return np.einsum("ij,ijk->ik", b, vertices[tri[t]])
    return _moved(mask, move, face)


def mask_on(path, skin: Mesh, what: str = "") -> WrinkleMask:
    """A mask file read and snapped onto a skin; an error if it was made for another face.

    Parameters
    ----------
    path : str or Path
    skin : Mesh
    what : str
        How the message names the file.

    Returns
    -------
    WrinkleMask
    """
    mask, d = snap_mask(WrinkleMask.load(path), skin)
    size = float(np.linalg.norm(np.ptp(skin.vertices, axis=0)))
    if np.median(d) > 0.02 * size:
        raise MimicaError(f"{path}: the mask does not lie on {what or skin.name or 'the face'} (median distance "
                          f"{np.median(d):.3g}); make one for this face with `mimica wrinkle-mask`")
    return mask


def mask_for(face: Mesh, landmarks: np.ndarray, anchors=None, reference=None) -> tuple[WrinkleMask, str]:
    """The reference mask (or a mask file) on a face, and how it got there: carried exactly on
    ICT-FaceKit topology, else by V&Y §3.2 (transfer_mask).

    Parameters
    ----------
    face : Mesh
    landmarks : (68, 3) float array
    anchors : str or Path or None
        A mask file on this face whose anchors the transfer keeps.
    reference : str or Path or None
        A mask file to carry instead of the reference mask.

    Returns
    -------
    mask : WrinkleMask
    how : str
        One line saying how it was placed.
    """
    from ..data import ICT_FACE_AREA_VERTICES, ICT_HEAD_VERTICES, ICTModel, is_ict_topology
    from .mask import reference_mask
    mask = reference_mask() if reference is None else WrinkleMask.load(reference)
    target_anchors = mask_on(anchors, face).anchors if anchors else None
    if target_anchors is None and reference is None and is_ict_topology(face):
        # the face area alone, or with head and neck: the reference of the same vertex count
        ref = ICTModel(ICT_FACE_AREA_VERTICES if face.n_vertices < ICT_HEAD_VERTICES else ICT_HEAD_VERTICES)
        return carry_mask(mask, ref.mesh, face.vertices, face.name), "carried on the ICT-FaceKit topology"
    new, info = transfer_mask(mask, ICTModel(ICT_HEAD_VERTICES).mesh, face, landmarks, target_anchors=target_anchors)
    return new, (f"spring mesh relaxed in {info.iterations} steps (residual {info.residual:.1e}), "
                 f"{info.seconds:.2f}s")
