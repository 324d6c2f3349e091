"""mesh.graph: the edge graph and the harmonic fill the lid contacts, the low-confidence fill,
the pockets and the jaw's share solve with; mesh.core's cross-product matrices."""

from __future__ import annotations

import numpy as np

from mimica.mesh.graph import HarmonicFill, edge_graph


def _path(n):
    return edge_graph(n, np.c_[np.arange(n - 1), np.arange(1, n)])


def test_a_harmonic_fill_on_a_path_is_a_straight_line():
    """Laplace's equation on a path between two given ends: the values fall on the line between
    them, any trailing shape; an isolated piece keeps its prior."""
    g = _path(11)
    fill = HarmonicFill(g, np.arange(1, 10), np.array([0, 10]))
    got = fill(np.array([[0.0, 5.0], [10.0, -5.0]]))
    np.testing.assert_allclose(got[:, 0], np.arange(1, 10), atol=1e-6)
    np.testing.assert_allclose(got[:, 1], 5 - np.arange(1, 10), atol=1e-6)
    alone = HarmonicFill(edge_graph(3, np.array([[0, 1]])), np.array([2]), np.array([0]), screen=1e-6)
    np.testing.assert_allclose(alone(np.array([4.0]), prior=np.array([7.0])), [7.0])


def test_a_screened_fill_fades_from_the_ring():
    """Screened, what the ring says fades with the distance from it (about 1/sqrt(screen) edges):
    far from a given end the value is near zero, not the end's value."""
    g = _path(41)
    fill = HarmonicFill(g, np.arange(1, 41), np.array([0]), screen=0.05)
    got = fill(np.array([1.0]))
    assert got[0] > 0.7 and got[-1] < 1e-3 and np.all(np.diff(got) < 0)


def test_the_cross_product_s_matrices_are_the_cross_product():
    """mesh.core.cross_matrices (the video fit's Jacobians, the eyes' and the modal warp's
    rotations): [v]x a equals v x a, and [v]x is antisymmetric."""
    from mimica.mesh.core import cross_matrices
    rng = np.random.default_rng(0)
    v, a = rng.normal(size=(20, 3)), rng.normal(size=(20, 3))
    K = cross_matrices(v)
    np.testing.assert_allclose(np.einsum("nij,nj->ni", K, a), np.cross(v, a), atol=1e-14)
    np.testing.assert_array_equal(K, -K.transpose(0, 2, 1))
