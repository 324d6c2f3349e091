"""Performances fitted to muscles: each muscle's rest field, a bounded least
squares over them, a timeline that simulate plays; shapes the muscle face makes itself are
recovered."""

from __future__ import annotations

import numpy as np
import pytest

from mimica.data import ICT_LANDMARKS_68
from mimica.physics.face import FaceSimulator
from mimica.physics.fit import MuscleFit, _box_ls, muscle_fields
from mimica.rig import build_rig

MUSCLES = ["zygomaticus_major_L", "zygomaticus_major_R", "depressor_anguli_oris_R"]


@pytest.fixture(scope="module")
def rig(face):
    return build_rig(face.mesh, face.neutral[ICT_LANDMARKS_68], muscles=MUSCLES)


@pytest.fixture(scope="module")
def fit(rig):
    return MuscleFit.of_rig(rig)


def test_rest_fields_are_where_held_activations_settle(rig, fit):
    """A muscle's field at activation 1 is its steady state: activations held for 4 s settle on
    the fields' weighted sum (force decomposition: the face is linear in them)."""
    sim = FaceSimulator(rig, warp=False)                       # the fields are the linear face's
    a = np.array([0.7, 0.0, 0.4])
    u = sim.run(lambda t: a, 4.0)[-1] - rig.skin.vertices
    np.testing.assert_allclose(u, fit.displacement(a), atol=1e-5 * np.abs(u).max())
    assert np.allclose(muscle_fields(sim), fit.fields)                       # the simulator left at rest


def test_a_shape_the_muscle_face_makes_is_recovered(fit):
    """Displacements made by the fields themselves (activations in [0, 1], some at the bounds)
    give their activations back, frame by frame and through shape combinations alike."""
    rng = np.random.default_rng(4)
    act = np.clip(rng.uniform(-0.3, 1.3, (40, 3)), 0, 1)
    d = np.einsum("fm,mnk->fnk", act, fit.fields)
    got, mis = fit.fit(d)
    assert np.abs(got - act).max() < 1e-4 and mis.max() < 1e-4
    shapes = np.stack([fit.fields[0] + fit.fields[2], fit.fields[1], 0.5 * fit.fields[2]])
    w = rng.uniform(0, 1, (30, 3))
    a2, m2 = fit.fit_combinations(shapes, w)
    a3, m3 = fit.fit(np.einsum("fk,knd->fnd", w, shapes))
    np.testing.assert_allclose(a2, a3, atol=1e-9)
    np.testing.assert_allclose(m2, m3, atol=2e-3)            # the misfit from Gram norms: a few digits


def test_box_least_squares_equals_bvls():
    """The fast box solver (NNLS, held upper bounds, KKT check) finds what BVLS finds."""
    from scipy.optimize import lsq_linear
    rng = np.random.default_rng(9)
    for _ in range(200):
        m = int(rng.integers(2, 12))
        M = np.triu(rng.normal(size=(m, m))) + 2 * np.eye(m)
        y = rng.normal(size=m) * 3
        ref = lsq_linear(M, y, bounds=(0.0, 1.0), method="bvls").x
        np.testing.assert_allclose(_box_ls(M, y, 1.0), ref, atol=1e-7)


def test_box_least_squares_needs_no_fallback_with_many_channels(monkeypatch):
    """With a whole library's worth of channels (56), the active set settles by itself: the
    slow BVLS fallback is not taken, and the result is still BVLS's."""
    import scipy.optimize
    from scipy.optimize import lsq_linear
    calls = []
    monkeypatch.setattr(scipy.optimize, "lsq_linear", lambda *a, **k: calls.append(1) or lsq_linear(*a, **k))
    rng = np.random.default_rng(10)
    for _ in range(40):
        m = 56
        M = np.triu(rng.normal(size=(m, m))) + 3 * np.eye(m)
        y = rng.normal(size=m) * 4
        a = _box_ls(M, y, 1.0)
        np.testing.assert_allclose(a, lsq_linear(M, y, bounds=(0.0, 1.0), method="bvls").x, atol=1e-7)
    assert len(calls) <= 2
