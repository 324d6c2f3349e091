"""Closest points on a mesh (mesh.query.TriangleLocator): libigl's AABB tree and the k-d tree
search agree with a brute-force scan over every triangle, near the surface and far from it."""

from __future__ import annotations

import numpy as np
import pytest

from mimica.mesh.query import TriangleLocator, closest_point_on_triangles


def brute(mesh, p):
    t = mesh.triangles
    a, b, c = (np.broadcast_to(mesh.vertices[t[:, j]], (len(t), 3)) for j in range(3))
    q, _ = closest_point_on_triangles(np.broadcast_to(p, (len(t), 3)).copy(), a, b, c)
    return np.linalg.norm(q - p, axis=1).min()


@pytest.mark.parametrize("use_igl", [True, False])
def test_closest_points_are_exact(head_model, use_igl):
    m = head_model.mesh
    rng = np.random.default_rng(0)
    size = np.ptp(m.vertices, axis=0).max()
    near = m.vertices[rng.choice(m.n_vertices, 120, replace=False)] + rng.normal(0, 0.01 * size, (120, 3))
    far = m.vertices.mean(0) + rng.normal(0, size, (40, 3))            # inside the head and far out
    p = np.vstack([near, far])
    loc = TriangleLocator(m.vertices, m.triangles, use_igl=use_igl)
    if use_igl:
        assert loc.use_igl, "libigl is a dependency: its import failed"
    tri, bary, q, d = loc.closest(p)
    assert np.allclose(bary.sum(1), 1) and (bary >= -1e-12).all()
    np.testing.assert_allclose(np.einsum("ij,ijk->ik", bary, m.vertices[m.triangles[tri]]), q, atol=1e-12 * size)
    np.testing.assert_allclose(np.linalg.norm(q - p, axis=1), d, atol=1e-12 * size)
    np.testing.assert_allclose(d, [brute(m, x) for x in p], atol=1e-12 * size)


def test_max_distance_keeps_near_points_exact(head_model):
    m = head_model.mesh
    rng = np.random.default_rng(1)
    p = m.vertices[rng.choice(m.n_vertices, 200, replace=False)] + rng.normal(0, 0.3, (200, 3))
    loc = TriangleLocator(m.vertices, m.triangles, use_igl=False)
    exact = loc.closest(p)[3]
    capped = loc.closest(p, max_distance=0.5)[3]
    inside = exact < 0.5
    np.testing.assert_allclose(capped[inside], exact[inside], atol=1e-12)
    assert (capped >= exact - 1e-12).all()


@pytest.mark.parametrize("fold", [30.0, 90.0, 140.0])
def test_concave_angles_of_a_fold(fold):
    """Two strips of triangles meeting along the x axis, folded by `fold` degrees: the fold is a
    valley seen from the side the faces look to (upward normals, the wings raised), a ridge
    turned over; only the fold's own edges carry the angle, flat and boundary edges 0."""
    from mimica.mesh import Mesh
    from mimica.mesh.query import concave_angles
    a = np.radians(fold) / 2
    xs = np.arange(4.0)
    v = np.array([[x, 0, 0] for x in xs] + [[x, np.cos(a), np.sin(a)] for x in xs]
                 + [[x, -np.cos(a), np.sin(a)] for x in xs])
    tris = []
    for i in range(3):
        m, l, r = i, 4 + i, 8 + i
        tris += [[m, m + 1, l + 1], [m, l + 1, l], [m, r, r + 1], [m, r + 1, m + 1]]
    mesh = Mesh.from_faces(v, np.array(tris))
    assert (mesh.face_normals()[:, 2] > 0).all()
    e = mesh.edges
    on_fold = (e < 4).all(1)
    ang = np.degrees(concave_angles(mesh, e))
    np.testing.assert_allclose(ang[on_fold], fold, atol=1e-9)
    assert np.abs(ang[~on_fold]).max() < 1e-6
    turned = Mesh.from_faces(v, np.array(tris)[:, ::-1])               # the same fold, a ridge now
    assert np.abs(concave_angles(turned, e)).max() < 1e-6


def test_triangles_and_polygons_around_each_vertex(head_model):
    """Mesh.vertex_triangles and vertex_faces list, for each vertex, exactly the triangles and
    polygons that use it (ICT's quads, and a polygon that meets a vertex twice listed twice)."""
    from mimica import Mesh
    m = head_model.mesh
    start, around = m.vertex_triangles
    fstart, faround = m.vertex_faces
    assert len(start) == len(fstart) == m.n_vertices + 1
    corner_face = np.repeat(np.arange(m.n_faces), m.face_sizes)
    for v in np.random.default_rng(0).choice(m.n_vertices, 200, replace=False):
        assert np.array_equal(around[start[v]:start[v + 1]], np.nonzero((m.triangles == v).any(1))[0])
        assert np.array_equal(faround[fstart[v]:fstart[v + 1]], corner_face[m.face_indices == v])
    bow = Mesh(np.random.default_rng(1).normal(size=(5, 3)), np.array([0, 1, 2, 0, 3, 4, 1, 2, 3]),
               np.array([0, 6, 9]))                           # a hexagon through vertex 0 twice, a triangle
    s, a = bow.vertex_faces
    assert a[s[0]:s[1]].tolist() == [0, 0] and a[s[3]:s[4]].tolist() == [0, 1] and s[-1] == 9


def test_closest_facing_keeps_to_the_wall_facing_the_point():
    """Two walls 0.01 apart facing each other (a shut mouth's bag): a point nearer the upper wall
    but facing up lands on the lower one; facing down, on the upper; where no candidate faces its
    way, on the closest."""
    from mimica.mesh.core import plane_grid
    wall = plane_grid(5, 5, 1.0, 1.0)                               # normals +z
    tri, n = wall.triangles, wall.n_vertices
    v = np.vstack([wall.vertices, wall.vertices + [0.0, 0.0, 0.01]])
    tris = np.vstack([tri, tri[:, ::-1] + n])                       # the upper wall faces down
    loc = TriangleLocator(v, tris)
    p = np.array([[0.43, 0.57, 0.006]])
    t, bary = loc.closest_facing(p, np.array([[0.0, 0.0, 1.0]]))
    assert t[0] < len(tri) and abs(np.einsum("k,kd->d", bary[0], v[tris[t[0]]])[2]) < 1e-12
    t, bary = loc.closest_facing(p, np.array([[0.0, 0.0, -1.0]]))
    assert t[0] >= len(tri)
    np.testing.assert_allclose(np.einsum("k,kd->d", bary[0], v[tris[t[0]]]), [0.43, 0.57, 0.01], atol=1e-12)
    t, _ = loc.closest_facing(p, np.array([[1.0, 0.0, 0.0]]))       # neither faces it: the closest
    assert t[0] >= len(tri)
