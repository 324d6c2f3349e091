"""Performances fitted to muscles: each muscle's rest field, a bounded least
squares over them, a timeline that simulate plays; shapes the muscle face makes itself are
recovered."""

from __future__ import annotations

import numpy as np
import pytest

from mimica.cli import main
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


def test_fit_muscles_writes_a_timeline_simulate_plays(rig, face, tmp_path, capsys):
    """`fit-muscles RIG --target` on a shape the rig makes: the timeline holds the activations
    and `simulate --timeline` plays it into that shape."""
    from mimica.anim import Timeline
    from mimica.mesh import write_mesh
    rig.save(tmp_path / "face.rig")
    fit = MuscleFit.of_rig(rig)
    a = np.array([0.8, 0.2, 0.5])
    target = rig.skin.vertices + fit.displacement(a)
    write_mesh(tmp_path / "target.obj", rig.skin.with_vertices(target))
    out = tmp_path / "act.json"
    assert main(["fit-muscles", str(tmp_path / "face.rig"), "--target", str(tmp_path / "target.obj"),
                 "--out", str(out)]) == 0
    said = capsys.readouterr().err
    assert "3 muscles fitted to 1 target" in said and "0% misfit" in said, said
    tl = Timeline.load(out)
    np.testing.assert_allclose(tl.values(0.5, MUSCLES), a, atol=1e-4)
    assert main(["simulate", str(tmp_path / "face.rig"), "--timeline", str(out), "--duration", "0.8",
                 "--out", str(tmp_path / "sim")]) == 0
    from mimica.mesh import read_vertices
    last = read_vertices(sorted((tmp_path / "sim").glob("frame_*.obj"))[-1]) - rig.skin.vertices
    want = target - rig.skin.vertices
    cos = (last * want).sum() / np.linalg.norm(last) / np.linalg.norm(want)
    assert cos > 0.99 and 0.8 < np.linalg.norm(last) / np.linalg.norm(want) < 1.1


def test_fit_muscles_refuses_what_it_cannot_fit(rig, face, tmp_path, capsys):
    from mimica.mesh import write_mesh
    rig.save(tmp_path / "face.rig")
    write_mesh(tmp_path / "other.obj", face.mesh)
    bad = tmp_path / "few.obj"
    bad.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    cases = [(["--out", str(tmp_path / "a.json")], "give --target"),
             (["--target", str(bad), "--out", str(tmp_path / "a.json")], "3 vertices; the rig's skin has"),
             (["--target", str(tmp_path / "other.obj"), "--out", str(tmp_path / "a.txt")], "timeline .json")]
    for args, said in cases:
        capsys.readouterr()
        assert main(["fit-muscles", str(tmp_path / "face.rig"), *args]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and said in err[0], err
        assert not (tmp_path / "a.json").exists() and not (tmp_path / "a.txt").exists()
