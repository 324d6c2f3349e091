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
