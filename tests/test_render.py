"""The software rasterizer: the picture shows the mesh where it is, lit, and nothing else."""

from __future__ import annotations

import numpy as np

from mimica import Mesh
from mimica.render import rasterize, render_mesh


def test_rasterize_square_covers_its_pixels():
    xy = np.array([[10.0, 10], [30, 10], [30, 30], [10, 30]])
    tri, bary = rasterize(xy, np.zeros(4), np.array([[0, 1, 2], [0, 2, 3]]), 40, 40)
    assert (tri >= 0).sum() == 400                              # 20 x 20 pixel centres
    assert (tri[:10] < 0).all() and np.allclose(bary[tri >= 0].sum(1), 1)


def test_nearest_surface_wins():
    xy = np.array([[0.0, 0], [20, 0], [0, 20]] * 2)
    z = np.array([0.0, 0, 0, 1, 1, 1])
    tri, _ = rasterize(xy, z, np.array([[0, 1, 2], [3, 4, 5]]), 20, 20)
    assert set(np.unique(tri[tri >= 0])) == {1}


def test_render_face_not_blank(head_model):
    img = render_mesh(head_model.mesh, size=(128, 128))
    fg = (img != 255).any(axis=2)
    assert 0.2 < fg.mean() < 0.9 and img[fg].std() > 5          # a shaded silhouette
    side = render_mesh(head_model.mesh, size=(128, 128), yaw=90)
    assert not np.array_equal(side, img)


def test_render_quad_mesh_with_colors():
    m = Mesh.from_faces(np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.0]]), [[0, 1, 2, 3]])
    img = render_mesh(m, size=(32, 32), colors=np.array([[1, 0, 0]] * 4))
    centre = img[16, 16]
    assert centre[0] > 100 and centre[1] == 0 and centre[2] == 0
