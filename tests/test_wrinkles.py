"""Viaud & Yahia §3.1: cylinder fit by conjugate gradient, flattening."""

from __future__ import annotations

import time

import numpy as np
import pytest

from mimica import MimicaError
from mimica.wrinkles import fit_cylinder, flatten
from mimica.wrinkles.cylinder import energy_and_gradient


def _samples(rng, n=800, radius=7.0, noise=0.01):
    axis = np.array([0.2, 1.0, -0.1])
    axis /= np.linalg.norm(axis)
    origin = np.array([1.0, -2.0, 3.0])
    e1 = np.cross(axis, [1.0, 0, 0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    th = rng.uniform(-1.2, 1.2, n)                     # a face-like patch, not the whole round
    h = rng.uniform(-6, 6, n)
    P = origin + np.outer(h, axis) + radius * (np.outer(np.cos(th), e1) + np.outer(np.sin(th), e2))
    return P + rng.normal(scale=noise * radius, size=P.shape), origin, axis, radius


def test_recovers_a_known_cylinder_from_noisy_samples():
    """Noise of 1 % of the radius (0.7 mm on a 7 cm head cylinder), a 140-degree arc."""
    P, origin, axis, radius = _samples(np.random.default_rng(0))
    fit = fit_cylinder(P, axis_guess=(0.3, 1.0, 0.3))
    assert abs(fit.radius - radius) < 0.01 * radius
    assert np.degrees(np.arccos(abs(fit.axis @ axis))) < 1.0
    off = (fit.origin - origin) - axis * ((fit.origin - origin) @ axis)   # axis-to-axis distance
    assert np.linalg.norm(off) < 0.01 * radius


def test_gradient_matches_finite_differences():
    P, *_ = _samples(np.random.default_rng(1), n=200)
    Q = (P - P.mean(0)) / 5.0
    p = np.array([0.1, -0.2, 0.3, 0.2, -0.1, 1.3])
    _, g = energy_and_gradient(p, Q, 1, 0.9)
    h = 1e-6
    for i in range(6):
        e = np.zeros(6)
        e[i] = h
        fd = (energy_and_gradient(p + e, Q, 1, 0.9)[0] - energy_and_gradient(p - e, Q, 1, 0.9)[0]) / (2 * h)
        assert fd == pytest.approx(g[i], rel=1e-5, abs=1e-6)


def test_ict_face_fits_fast_and_flattens(head_model):
    face = head_model.neutral[:9409]
    t = time.perf_counter()
    fit = fit_cylinder(face)
    took = time.perf_counter() - t
    assert took < 0.5                                  # ~0.05 s here; issue 4 asks < 0.2 s (noisy CI: margin)
    assert 5.0 < fit.radius < 15.0 and abs(fit.axis[1]) > 0.9   # a head-sized, upright cylinder
    flat = flatten(face, fit)
    assert flat.shape == (9409, 2) and np.ptp(flat[:, 1]) > 10


def test_bad_points():
    with pytest.raises(MimicaError, match="at least 6"):
        fit_cylinder(np.zeros((3, 3)))


def test_dilation_law():
    from mimica.wrinkles.bulge import AGE_0, AGE_MAX, DIL_MAX, dilation
    assert dilation(2.0, 20) == 2.0 and dilation(2.0, AGE_0) == 2.0              # none before AGE_0
    assert dilation(2.0, AGE_MAX) == pytest.approx(2.0 * (1 + DIL_MAX))          # eq. 10 at AGE_MAX
    ages = np.linspace(AGE_0, AGE_MAX, 5)
    assert np.allclose(np.diff(dilation(1.0, ages), 2), 0)                      # linear after AGE_0


def test_bulge_curve_is_symmetric_and_exact_at_rest():
    from mimica.wrinkles.bulge import arc_length, curve
    u = np.linspace(0, 1, 11)
    c = curve(3.0, 1.2, 0.8, u)
    np.testing.assert_allclose(c[::-1, 0], 3.0 - c[:, 0], atol=1e-12)           # mirror about d/2
    np.testing.assert_allclose(c[::-1, 1], c[:, 1], atol=1e-12)
    assert arc_length(3.0, 0.0, 0.0) == pytest.approx(3.0)                      # flat: the chord


def test_table_lookup_and_inversion_within_one_percent():
    from mimica.wrinkles.bulge import ArcLengthTable, arc_length, dilation
    T = ArcLengthTable.build()
    rng = np.random.default_rng(7)
    d = rng.uniform(0.1, 20.1, 5000)
    a = d * rng.uniform(0, 5, 5000)
    al = rng.uniform(0, np.pi, 5000)
    exact = arc_length(d, a, al)
    assert np.max(np.abs(T.lookup(d, a, al) - exact) / exact) < 0.01
    d_real = dilation(d, rng.uniform(20, 90, 5000))
    aa, alf = T.solve(d, d_real, 0.1 * d)
    assert np.max(np.abs(arc_length(d, aa, alf) - d_real) / d_real) < 0.01
    assert ((alf < np.pi / 2) & np.isclose(aa, 0.1 * d)).any()                  # alpha first ...
    assert ((alf == np.pi / 2) & (aa > 0.1 * d)).any()                          # ... then a
