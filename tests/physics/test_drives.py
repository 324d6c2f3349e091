"""The jaw and the eyelids: rigid parts that move the skin through its
attachments (rig.drives), as force types of the modal face."""

from __future__ import annotations

import numpy as np
import pytest

from mimica.data import ICT_FACE_AREA_VERTICES, ICT_LANDMARKS_68, ICTModel
from mimica.physics.drives import ActivationMap, lid_contact
from mimica.physics.face import FaceSimulator, displacement_cosine
from mimica.physics.fit import MuscleFit, muscle_fields, skin_stiffness, static_field, static_fields
from mimica.rig import Rig, build_rig
from mimica.rig.drives import jaw_open_factors, jaw_open_parts, lid_opening, open_pairs

EYE = ["orbicularis_oculi_palpebral_R", "orbicularis_oculi_lower_R", "levator_palpebrae_R", "orbicularis_oculi_R",
       "frontalis_R", "corrugator_supercilii_R"]


@pytest.fixture(scope="module")
def face():
    return ICTModel(ICT_FACE_AREA_VERTICES)


@pytest.fixture(scope="module")
def jaw(face):
    return build_rig(face.mesh, face.neutral[ICT_LANDMARKS_68], muscles="digastric,lateral_pterygoid,masseter_R",
                     gravity=False)


@pytest.fixture(scope="module")
def eye(face):
    return build_rig(face.mesh, face.neutral[ICT_LANDMARKS_68], muscles=EYE, gravity=False)


def _rotation(axis, angle):
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def test_the_jaw_bone_turns_rigidly_at_any_opening(jaw):
    m = jaw.muscle("digastric")
    ms, mc, phi = jaw_open_parts(m.nodes, m.info)
    pivot = np.array(m.info["pivot"])
    axis = np.cross(m.info["fwd"], m.info["up"])            # psi turns from forward toward up
    for q in (0.13, 0.5, 0.87, 1.0):
        fs, fc = jaw_open_factors(q, phi)
        moved = m.nodes + fs * ms + fc * mc
        exact = (m.nodes - pivot) @ _rotation(axis, q * phi).T + pivot
        np.testing.assert_allclose(moved, exact, atol=1e-12 * np.abs(m.nodes).max())
    # the chin goes down and back when the jaw opens
    chin = jaw.landmarks[8]
    i = np.argmin(np.linalg.norm(m.nodes - chin, axis=1))
    assert m.stretch[i] @ np.array(m.info["up"]) < 0


def test_the_skin_follows_the_turned_bone_not_its_chord(jaw):
    """Held half open, the jaw's system settles where its anchors turned by half the angle
    pull the skin (one sparse solve), not where the straight chord would."""
    sim = FaceSimulator(jaw, warp=False)
    i = [m.name for m in jaw.muscles].index("digastric")
    sm = sim.systems[i]
    sm.q, sm.v = 0.5, 0.0
    for _ in range(4000):
        sm.step(0.5)
    u = np.zeros_like(jaw.skin.vertices)
    sm.solver.add_displacement(u, False)
    m = jaw.muscles[i]
    ms, mc, phi = jaw_open_parts(m.nodes, m.info)
    fs, fc = jaw_open_factors(0.5, phi)
    K = skin_stiffness(jaw)

    def settle(motion):
        return static_field(jaw, m, K, motion=motion)
    turned, chord = settle(fs * ms + fc * mc), settle(0.5 * (ms + mc))
    scale = np.abs(turned).max()
    assert np.abs(u - turned).max() < 1e-4 * scale
    assert np.abs(u - chord).max() > 1e-2 * scale


def test_the_jaw_opens_like_ict_and_its_closers_hold_it(jaw, face):
    fields = static_fields(jaw)
    names = [m.name for m in jaw.muscles]
    assert displacement_cosine(fields[names.index("digastric")], face.delta({"jawOpen": 1.0})) > 0.85
    assert displacement_cosine(fields[names.index("lateral_pterygoid")], face.delta({"jawForward": 1.0})) > 0.8
    amap = ActivationMap(jaw.muscles)
    np.testing.assert_allclose(amap(np.array([0.8, 0.0, 0.3])), [0.5, 0.0, 0.3])   # masseter closes it
    np.testing.assert_allclose(amap(np.array([0.2, 0.0, 0.9])), [0.0, 0.0, 0.9])   # never past the teeth
    np.testing.assert_allclose(amap(np.array([1.7, -0.5, 0.0])), [1.0, 0.0, 0.0])   # drives within 0..1


def test_the_cheeks_puff_out(face):
    rig = build_rig(face.mesh, face.neutral[ICT_LANDMARKS_68], muscles="cheek_pressure_R,cheek_pressure_L",
                    gravity=False)
    F = static_fields(rig)
    fwd = np.array(rig.muscles[0].info.get("fwd", [0.0, 0.0, 1.0]))
    for f, shape in zip(F, ("cheekPuff_R", "cheekPuff_L")):
        assert displacement_cosine(f, face.delta({shape: 1.0})) > 0.8
        moving = np.linalg.norm(f, axis=1) > 0.2 * np.linalg.norm(f, axis=1).max()
        assert (f[moving] @ fwd > 0).all()                             # the mouth swells out, never in
    beyond = rig.skin.vertices[:, 0] > rig.landmarks[54, 0]          # past the other mouth corner
    assert np.abs(F[0][beyond]).max() < 0.1 * np.abs(F[0]).max()


def test_static_fields_are_the_modal_steady_states(eye):
    """What calibration evaluates (one sparse solve) is what the modal face settles to."""
    a, b = static_fields(eye), muscle_fields(FaceSimulator(eye))
    for i in range(len(a)):
        assert np.abs(a[i] - b[i]).max() < 1e-5 * np.abs(b[i]).max()


def test_a_closed_lid_meets_the_lower_one(eye):
    m = eye.muscle("orbicularis_oculi_palpebral_R")
    F = static_fields(eye)[0]
    rest = lid_opening(eye.skin.vertices, m.info)
    closed = lid_opening(eye.skin.vertices + F, m.info)
    wide = rest >= 0.5 * rest.max()
    assert len(rest) >= 8 and wide.sum() >= 6
    assert closed[wide].max() <= 0.05 * rest.max()          # the rims meet...
    assert closed.min() >= -0.01 * rest.max()               # ...without crossing


def test_lids_never_cross_at_any_activation(eye):
    """Random held activations of the lids and the muscles around the eye, and a moving
    performance: the upper margin never passes the lower one."""
    sim = FaceSimulator(eye)
    info = eye.muscle("orbicularis_oculi_palpebral_R").info
    rest = eye.skin.vertices
    states = [sm.steady_state() for sm in sim.systems]   # each system's steady state at input 1
    rng = np.random.default_rng(5)
    worst = np.inf
    for _ in range(60):
        a = rng.uniform(0, 1, len(EYE)) * (rng.uniform(size=len(EYE)) < 0.7)
        for sm, x, ai in zip(sim.systems, states, sim.inputs(a)):
            sm.set_state(ai * x)
        worst = min(worst, lid_opening(rest + sim.displacement(), info).min())
    assert worst >= -1e-6
    sim.reset()
    frames = sim.run(lambda t: np.clip(np.sin(np.arange(len(EYE)) + 9 * t), 0, 1) * np.r_[1, 1, 1, 1, 1, 1], 1.0)
    assert lid_opening(frames, info).min() >= -1e-6


def _wide_gap(opening, rest):
    """The widest opening left at the pairs open at least half the widest at rest, against it."""
    return opening[open_pairs(rest)].max() / rest.max()


def test_contact_holds_each_position_where_the_rims_meet(eye):
    """The lid closed with the lower one raised (the two together would cross in the middle):
    contact stops the lid where it touches, position by position, so the rims meet all along
    the open eye and never cross; held back evenly instead (a share of the whole closing field:
    passes=0), the middle met while the ends stayed open.  The simulators (warped, linear,
    reduced) playing it held never cross and close within 5 % of the opening."""
    info = eye.muscle("orbicularis_oculi_palpebral_R").info
    rest = eye.skin.vertices
    o0 = lid_opening(rest, info)
    a = np.array([1.0, 0.3, 0, 0, 0, 0.1])
    fields = static_fields(eye)
    assert lid_opening(rest + np.tensordot(a, fields, 1), info).min() < -0.05 * o0.max()   # they would cross
    for passes, gap in ((4, 0.01), (0, None)):
        u = lid_contact(np.tensordot(a, fields, 1), a[0] * fields[0], rest, info, passes=passes)
        o = lid_opening(rest + u, info)
        assert o.min() >= -1e-9
        if gap is None:
            assert _wide_gap(o, o0) > 0.03                 # held back evenly: the ends open (0.048)
        else:
            assert _wide_gap(o, o0) <= gap
    for kw in ({}, {"warp": False}, {"reduced": 1e-4}):
        sim = FaceSimulator(eye, **kw)
        for _ in range(400):                                 # held: settled
            sim.advance(a)
        o = lid_opening(rest + sim.displacement(), info)
        assert o.min() >= -1e-9, kw
        assert _wide_gap(o, o0) <= 0.05, kw


def test_a_fitted_blink_closes_the_eye(eye, face):
    """ICT's eyeBlink fitted: the least squares alone stops the lid short (a crossing in the
    middle counts against it); a closed target's lid is closed until the rims meet, and contact
    holds them there -- in the fit's displacement and in the simulator playing the fitted
    activations.  A squint, not a closed lid, keeps its least-squares activations."""
    fit = MuscleFit.of_rig(eye)
    info = eye.muscle("orbicularis_oculi_palpebral_R").info
    rest = eye.skin.vertices
    o0 = lid_opening(rest, info)
    a, _ = fit.fit(face.delta({"eyeBlink_R": 1.0}))
    shapes = np.stack([face.delta({"eyeBlink_R": 1.0}), face.delta({"eyeSquint_R": 1.0})])
    np.testing.assert_allclose(fit.fit_combinations(shapes, np.array([[1.0, 0.0]]))[0][0], a, atol=1e-9)
    plain = MuscleFit(fit.names, fit.fields, fit.weights, fit.inputs)             # no lid contact
    b, _ = plain.fit(face.delta({"eyeBlink_R": 1.0}))
    assert _wide_gap(lid_opening(rest + plain.displacement(b), info), o0) > 0.05
    assert a[0] > b[0]
    o = lid_opening(rest + fit.displacement(a), info)
    assert _wide_gap(o, o0) <= 0.05 and o.min() >= -1e-9
    sim = FaceSimulator(eye)
    for sm, x, ai in zip(sim.systems, [sm.steady_state() for sm in sim.systems], sim.inputs(a)):
        sm.set_state(ai * x)
    o = lid_opening(rest + sim.displacement(), info)
    assert _wide_gap(o, o0) <= 0.05 and o.min() >= -1e-9
    squint = face.delta({"eyeSquint_R": 1.0})
    np.testing.assert_allclose(fit.fit(squint)[0], plain.fit(squint)[0], atol=1e-12)


def test_rig_round_trip(eye, tmp_path):
    path = eye.save(tmp_path / "eye.rig")
    back = Rig.load(path)
    for a, b in zip(eye.muscles, back.muscles):
        assert (a.kind, a.info.get("motion")) == (b.kind, b.info.get("motion"))
        if a.weight is not None:
            np.testing.assert_array_equal(a.weight, b.weight)
        for x, y in zip(a.springs(), b.springs()):                # a strip's fanned springs too
            np.testing.assert_array_equal(x, y)
    assert any(m.fan is not None for m in back.muscles)
    assert back.muscle("orbicularis_oculi_palpebral_R").info["rims"] == eye.muscle(
        "orbicularis_oculi_palpebral_R").info["rims"]
