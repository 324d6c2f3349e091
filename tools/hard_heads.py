"""Hard heads made from ICT-FaceKit identities, where the truth is known (tests and benchmarks):
a remeshed head that is one closed surface (lips and lids sealed, nostrils and the open back and
neck capped), and one whose eyes are a surface running on from the lids over where the eyeball
is (as morphable-model heads have them), shaped open.  Each comes with its 68 landmarks."""

from __future__ import annotations

import numpy as np

from mimica.align import face_cylinder
from mimica.correspond.remesh import resample_face
from mimica.data import ICT_HEAD_VERTICES, ICT_LANDMARKS_68, ICTModel
from mimica.landmarks import Landmarks
from mimica.mesh import Mesh


def boundary_loops(mesh: Mesh) -> list[np.ndarray]:
    """The mesh's boundary loops, each as its vertices in order: closed walks over its boundary
    edges (Hierholzer's circuits), split where they pass a vertex twice (two holes touching)."""
    t = mesh.triangles
    e = np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), 1)
    u, cnt = np.unique(e, axis=0, return_counts=True)
    b = u[cnt == 1]
    nbr = {}
    for k, (x, y) in enumerate(b):
        nbr.setdefault(int(x), []).append((int(y), k))
        nbr.setdefault(int(y), []).append((int(x), k))
    used = np.zeros(len(b), bool)
    loops = []
    for k0 in range(len(b)):
        if used[k0]:
            continue
        stack, circuit = [int(b[k0, 0])], []
        while stack:                                       # Hierholzer: an Euler circuit of the component
            x = stack[-1]
            nxt = next(((y, k) for y, k in nbr[x] if not used[k]), None)
            if nxt is None:
                circuit.append(stack.pop())
            else:
                used[nxt[1]] = True
                stack.append(nxt[0])
        path, at = [], {}                                  # split at a vertex passed twice: simple loops
        for x in circuit:
            if x in at:
                loops.append(np.array(path[at[x]:]))
                for y in path[at[x] + 1:]:
                    del at[y]
                path = path[:at[x] + 1]
            else:
                at[x] = len(path)
                path.append(x)
    return [lp for lp in loops if len(lp) >= 3]


def capped(mesh: Mesh) -> Mesh:
    """Every boundary loop closed by a fan from a new vertex at its centre, each triangle wound
    against the face it meets: one closed surface."""
    t = mesh.triangles
    wound = {}
    for a_, b_ in np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]).tolist():
        wound[(a_, b_)] = True
    v, faces = [mesh.vertices], [t]
    n = mesh.n_vertices
    for loop in boundary_loops(mesh):
        if len(loop) < 3:
            continue
        v.append(mesh.vertices[loop].mean(0)[None])
        for a_, b_ in zip(loop.tolist(), np.roll(loop, -1).tolist()):
            faces.append(np.array([[b_, a_, n]]) if (a_, b_) in wound else np.array([[a_, b_, n]]))
        n += 1
    return Mesh.from_faces(np.vstack(v), np.vstack(faces), name=mesh.name + "_watertight")


def carried_landmarks(rs, original) -> Landmarks:
    """The remeshed head's landmarks on the right side of every slit: each ICT landmark vertex
    goes to the nearest new vertex lifted from a triangle around it (closest-point snapping
    puts both inner-lip points of a closed mouth on one lip)."""
    tri = original.triangles
    ids = []
    for v in ICT_LANDMARKS_68:
        around = np.nonzero((tri[rs.triangle] == v).any(1))[0]
        if not len(around):
            ring = np.unique(tri[(tri == v).any(1)])
            around = np.nonzero(np.isin(tri[rs.triangle], ring).any(1))[0]
        ids.append(around[np.argmin(np.linalg.norm(rs.mesh.vertices[around] - original.vertices[v], axis=1))]
                   if len(around) else -1)
    ids = np.array(ids)
    # where none was lifted: the closest point, the inner lips' points a little inside their own
    # lip (on sealed lips both would land on the seam, on either side of a cut)
    pts = original.vertices[ICT_LANDMARKS_68].copy()
    up = face_cylinder(pts).axes[1]
    d = 0.03 * np.linalg.norm(pts[45] - pts[36])
    pts[[61, 62, 63]] += d * up
    pts[[65, 66, 67]] -= d * up
    ids[60:68] = -1
    snapped = Landmarks.snap(rs.mesh, pts)
    exact = Landmarks.from_vertex_indices(rs.mesh, np.maximum(ids, 0))
    # a lid's point on a triangle of its lid, outside the eye (a one-surface eye cut open keeps
    # the lid's vertices; the eye takes copies): the triangle at it farthest from the eye's centre
    tris = rs.mesh.triangles
    cent = rs.mesh.vertices[tris].mean(1)
    for rim in (range(36, 42), range(42, 48)):
        centre = pts[list(rim)].mean(0)
        for k in rim:
            if ids[k] >= 0:
                at = np.nonzero((tris == ids[k]).any(1))[0]
                best = at[np.argmax(np.linalg.norm(cent[at] - centre, axis=1))]
                exact.triangle[k] = best
                exact.bary[k] = (tris[best] == ids[k]).astype(float)
    keep = ids >= 0
    return Landmarks(np.where(keep, exact.triangle, snapped.triangle), np.where(keep[:, None], exact.bary, snapped.bary))


def watertight_head(seed: int, n_vertices: int = 10000):
    """(a head that is one closed surface, its landmarks, the identity's vertices): a held-out
    ICT identity remeshed, lips and lids sealed, nostrils and the back capped."""
    head = ICTModel(ICT_HEAD_VERTICES)
    tv = head.identity(np.random.default_rng(1000 + seed).normal(0, 0.8, 20))
    rs = resample_face(head.mesh.with_vertices(tv), tv[ICT_LANDMARKS_68], n_vertices=n_vertices, seed=seed,
                       nostril_holes=False, seal=("mouth", "eyes"))
    mesh = capped(rs.mesh)                  # rs.mesh's vertices and faces first: its landmarks hold
    return mesh, carried_landmarks(rs, head.mesh.with_vertices(tv)), tv


def one_surface_eyes(seed: int, n_vertices: int = 20000, watertight: bool = False):
    """(a head whose eyes are one surface with its lids, shaped open, its landmarks, the
    identity's vertices): a held-out ICT identity's head and eyeballs remeshed together, the
    triangulation running on from the lids over the eyeball's front (as Basel- or Surrey-style
    morphable models have it); lips sealed; the back capped too where `watertight`.  The eyes'
    twelve landmarks are vertices of the new mesh at the identity's own points (pinned), so the
    blink's truth pairs (37-41, 38-40, ...) lie across each other as on ICT: snapped to the
    nearest remeshed vertex they sat up to 0.13 of the eye's width along the lid from them."""
    from mimica.correspond.parts import ICT_PARTS
    full = ICTModel()
    tv = full.identity(np.random.default_rng(1000 + seed).normal(0, 0.8, 20))
    keep = np.zeros(full.mesh.n_vertices, bool)
    keep[:11248] = True
    for name, a, b in ICT_PARTS:
        if name.startswith("eyeball"):
            keep[a:b] = True
    faces = np.nonzero(np.add.reduceat(~keep[full.mesh.face_indices], full.mesh.face_starts[:-1]) == 0)[0]
    part, old = full.mesh.with_vertices(tv).submesh(faces)
    lm = tv[ICT_LANDMARKS_68]
    rs = resample_face(part, lm, n_vertices=n_vertices, seed=seed, nostril_holes=False, seal=("mouth", "eyes"),
                       pins=range(36, 48))
    mesh = capped(rs.mesh) if watertight else rs.mesh
    return mesh, carried_landmarks(rs, part), tv
