"""Discrete shells (Kim 2020, eqs. 1-4): exact derivatives, rigid invariance, rest state."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import skin_patch

from mimica import Mesh
from mimica.physics import ShellEnergy, hinges_of, lumped_mass


@pytest.fixture(scope="module")
def patch(head_model):
    """A real piece of skin: the ICT face polygons within 3 cm of the mouth corner."""
    return skin_patch(head_model, 3.0)[0]


@pytest.fixture(scope="module")
def energy(patch):
    return ShellEnergy.default(patch, k_area=1.0, k_length=2.0, k_bend=0.3)


def _deformed(patch, seed=0, scale=0.05):
    return patch.vertices + np.random.default_rng(seed).normal(scale=scale, size=patch.vertices.shape)


def test_gradient_matches_finite_differences(patch, energy):
    x = _deformed(patch)
    g = energy.gradient(x)
    rng = np.random.default_rng(3)
    h = 1e-6
    for _ in range(3):
        d = rng.normal(size=x.shape)
        fd = (energy.energy(x + h * d) - energy.energy(x - h * d)) / (2 * h)
        assert abs(fd - (g * d).sum()) <= 1e-5 * abs(fd) + 1e-7
    # and entry by entry on a few coordinates
    for i in rng.choice(x.size, 5, replace=False):
        e = np.zeros(x.size)
        e[i] = 1
        e = e.reshape(x.shape)
        fd = (energy.energy(x + h * e) - energy.energy(x - h * e)) / (2 * h)
        assert abs(fd - g.ravel()[i]) <= 1e-5 * np.abs(g).max()


def test_hessian_matches_finite_differences(patch, energy):
    x = _deformed(patch, seed=1)
    H = energy.hessian(x)
    assert abs(H - H.T).max() < 1e-9 * abs(H).max()
    d = np.random.default_rng(4).normal(size=x.shape)
    h = 1e-6
    fd = (energy.gradient(x + h * d) - energy.gradient(x - h * d)).ravel() / (2 * h)
    hd = H @ d.ravel()
    assert np.abs(fd - hd).max() <= 1e-4 * np.abs(hd).max()


def test_rigid_motions_cost_nothing(patch, energy):
    c, s = np.cos(0.7), np.sin(0.7)
    r = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ np.array([[1, 0, 0], [0, c, s], [0, -s, c]])
    moved = patch.vertices @ r.T + [1.0, -2.0, 0.5]
    assert energy.energy(moved) < 1e-20
    assert np.abs(energy.gradient(moved)).max() < 1e-7           # vs ~1e2 for a 0.5 mm jitter
    # at rest the Hessian's null space holds the 6 rigid motions
    H = energy.hessian(patch.vertices)
    x = patch.vertices - patch.vertices.mean(0)
    for w in np.eye(3):
        assert np.abs(H @ np.cross(w, x).ravel()).max() < 1e-8 * abs(H).max()
        assert np.abs(H @ np.tile(w, len(x))).max() < 1e-8 * abs(H).max()
    # and it is positive semi-definite there
    d = np.random.default_rng(5).normal(size=x.size)
    assert d @ (H @ d) > 0


def test_each_term_responds_to_its_own_deformation():
    x = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.0]])
    sq = Mesh.from_faces(x, [[0, 1, 2], [2, 1, 3]])
    (h,) = hinges_of(sq.triangles).tolist()
    assert sorted(h[:2]) == [1, 2] and sorted(h[2:]) == [0, 3]
    only = lambda a, l, b: ShellEnergy(x, sq.triangles, a, l, b)  # noqa: E731
    folded = x.copy()
    folded[3, 2] = 0.5                                  # bend about the diagonal, edges change
    stretched = x * [1.1, 1.0, 1.0]
    assert only(0, 0, 1).energy(folded) > 0 and only(0, 0, 1).energy(stretched) < 1e-20
    assert only(1, 0, 0).energy(stretched) > 0 and only(0, 1, 0).energy(stretched) > 0
    # Kim eq. 2 by hand: edges along x stretch by 10 %
    expect = 2 * 0.1 ** 2 / 1 + (np.sqrt(1.21 + 1) - np.sqrt(2)) ** 2 / np.sqrt(2)
    assert only(0, 1, 0).energy(stretched) == pytest.approx(expect)


def test_default_stiffness_is_scale_free(patch):
    d = _deformed(patch, seed=2) - patch.vertices
    e1 = ShellEnergy.default(patch).energy(patch.vertices + d)
    big = patch.with_vertices(patch.vertices * 100)
    e2 = ShellEnergy.default(big).energy(big.vertices + 100 * d)
    assert e2 == pytest.approx(e1, rel=1e-9)


def test_lumped_mass_is_the_area(patch):
    x, t = patch.vertices, patch.triangles
    area = 0.5 * np.linalg.norm(np.cross(x[t[:, 1]] - x[t[:, 0]], x[t[:, 2]] - x[t[:, 0]]), axis=1).sum()
    m = lumped_mass(patch, density=2.0)
    assert m.sum() == pytest.approx(2 * area) and (m > 0).all()


def test_closed_form_gradients_equal_the_hyperdual_derivatives(patch, energy):
    """gradient() is written in closed form (Bridson et al.'s dihedral gradient); each term
    must equal the hyper-dual derivative of the very energy code, element by element."""
    from mimica.physics import hyperdual as hd
    from mimica.physics.shell import _local_gradient
    x = _deformed(patch, seed=6)
    for k, idx, fn, par in energy._terms():
        xs = energy._stack(x, idx)
        _, want = hd.local_gradient(fn, xs, par)
        np.testing.assert_allclose(_local_gradient(fn, xs, par), want, atol=1e-12 * np.abs(want).max())


def test_projected_hessian_is_psd_and_exact_at_rest(patch, energy):
    """The full solver's Newton matrix: positive semi-definite however the skin is deformed
    (here compressed by 30 % and jittered, where the exact Hessian is indefinite), and the
    exact Hessian at rest, where every term's residual is zero (as is rest_stiffness, its straight
    assembly)."""
    rest = patch.vertices
    np.testing.assert_allclose(energy.hessian(rest, project=True).toarray(), energy.hessian(rest).toarray(),
                               atol=1e-9 * abs(energy.hessian(rest)).max())
    k = energy.rest_stiffness()                          # the systems' stiffness, assembled straight
    np.testing.assert_allclose(k.toarray(), energy.hessian(rest).toarray(), atol=1e-12 * abs(k).max())
    assert abs(k - k.T).max() == 0
    x = _deformed(patch, seed=7, scale=0.1) * [0.7, 1.0, 1.0]
    exact = np.linalg.eigvalsh(energy.hessian(x).toarray())
    psd = np.linalg.eigvalsh(energy.hessian(x, project=True).toarray())
    assert exact.min() < -1e-3 * exact.max()
    assert psd.min() > -1e-9 * psd.max()


def test_bending_is_continuous_through_a_sharp_rest_fold():
    """A hinge folded almost flat onto itself at rest (theta0 = pi - 0.05, as at the lips'
    corners) bent 0.1 further crosses theta = pi: the energy is that of a 0.1 bend, not a
    2 pi jump."""
    def hinge(theta):
        return np.array([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, np.cos(theta), np.sin(theta)]], float)
    tri = np.array([[0, 1, 2], [1, 0, 3]])
    e = ShellEnergy(hinge(0.05), tri, 0.0, 0.0, 1.0)        # dihedral pi - 0.05 between the faces
    assert abs(abs(e.rest_theta[0]) - (np.pi - 0.05)) < 1e-9
    bent = [e.energy(hinge(0.05 + s * 0.1)) for s in (-1, 1)]
    w = e.bend_weight[0]
    np.testing.assert_allclose(bent, 3 * 0.1 ** 2 * w, rtol=1e-6)
