"""The viewer's session on a rig whose force systems are not made yet: at rest at once, the systems
made beside the page, those moved first, the simulation taking each batch in; the physics stage's
parts of it (precompute of some systems, a simulator taking over another's systems)."""

from __future__ import annotations

import numpy as np
import pytest

from mimica.data import ICT_FACE_AREA_VERTICES, ICT_LANDMARKS_68, ICTModel

MUSCLES = ["zygomaticus_major_L", "zygomaticus_major_R", "frontalis_L", "frontalis_R"]


@pytest.fixture(scope="module")
def face():
    return ICTModel(ICT_FACE_AREA_VERTICES)


def _rig(face):
    from mimica.rig import build_rig
    return build_rig(face.mesh, face.neutral[ICT_LANDMARKS_68], muscles=MUSCLES)


def test_precompute_some_systems_then_the_rest_as_all_at_once(face):
    from mimica.physics import precompute
    from mimica.physics.systems import skin_system
    rig = _rig(face)
    skin = skin_system(rig)                                # the shared matrices, made once by the caller
    precompute(rig, only=["frontalis_L"], skin=skin)
    assert [m.basis is not None for m in rig.muscles] == [False, False, True, False] and rig.gravity_basis is None
    assert set(rig.__dict__) == set(_rig(face).__dict__)   # nothing of them kept on the rig
    precompute(rig, only=["gravity", "zygomaticus_major_R"], skin=skin)
    precompute(rig, skin=skin)
    assert set(rig.__dict__) == set(_rig(face).__dict__)
    whole = precompute(_rig(face))
    for a, b in zip(rig.muscles + [rig], whole.muscles + [whole]):
        pa, pb = (a.basis, b.basis) if a is not rig else (a.gravity_basis, b.gravity_basis)
        np.testing.assert_allclose(pa.lam, pb.lam, rtol=1e-9)
        np.testing.assert_allclose(np.abs(pa.phi), np.abs(pb.phi), atol=1e-8 * np.abs(pb.phi).max())


def test_a_simulator_takes_over_the_systems_of_another_at_the_same_density(face):
    from mimica.physics import precompute
    from mimica.physics.face import FaceSimulator
    from mimica.rig import Rig
    rig = precompute(_rig(face))
    part = Rig(rig.skin, rig.landmarks, rig.muscles[2:], rig.params, rig.gravity_basis)
    first = FaceSimulator(part, reduced=1e-4).prepare()
    grown = FaceSimulator(rig, reduced=1e-4, reuse=first).prepare()
    assert grown.systems[2] is first.systems[0] and grown.systems[3] is first.systems[1]
    assert grown.systems[0] is not None and grown.systems[0] not in first.systems
    other = FaceSimulator(rig, reduced=1e-4, frequency=3.0, reuse=first)      # another density: made anew
    assert not set(map(id, other.systems)) & set(map(id, first.systems))


def test_a_session_opens_at_rest_and_makes_the_moved_systems_first(face, monkeypatch):
    import mimica.physics.systems as pf
    from mimica.physics import precompute
    from mimica.viewer import ViewerSession
    made = []
    real = pf.skin_system
    monkeypatch.setattr(pf, "skin_system", lambda *a, **k: made.append(1) or real(*a, **k))
    s = ViewerSession(_rig(face))
    assert s.pending() == ["gravity"] + MUSCLES and s.sim is None
    np.testing.assert_array_equal(s.positions(), face.mesh.vertices.astype(np.float32))
    assert not s.controls()["ready"]
    s.set("frontalis_R", 1.0)
    s.step()                                               # nothing to step yet: stays at rest
    seen = []

    def progress(k, n, name):
        seen.append((name, [s.muscles[i] for i in s._order] if s.sim is not None else None))
        if k == 4:
            s.set("zygomaticus_major_L", 0.5)             # made (third), not simulated: moved now
    s.make_systems(progress)
    assert len(made) == 1                                  # the skin's matrices made once for the five systems
    assert [x[0] for x in seen] == ["gravity", "frontalis_R", "zygomaticus_major_L", "zygomaticus_major_R",
                                    "frontalis_L"]
    assert seen[2][1] == ["frontalis_R"]                  # taken in once the moved one was made
    assert seen[4][1] == ["zygomaticus_major_L", "zygomaticus_major_R", "frontalis_R"]   # ... and the one moved later
    s.set("zygomaticus_major_L", 0.0)
    assert not s.pending() and s.controls()["ready"] and len(s._order) == 4
    # the same frames as a session on the rig made whole beforehand
    ref = ViewerSession(precompute(_rig(face)))
    ref.set("frontalis_R", 1.0)
    for _ in range(30):
        s.step()
        ref.step()
    x, y = s.positions(), ref.positions()
    assert np.abs(y - face.mesh.vertices).max() > 0.05
    np.testing.assert_allclose(x, y, atol=1e-6)
