"""Landmarks (JSON, snapping, built-in ICT indices) and similarity alignment."""

from __future__ import annotations

import json

import numpy as np
import pytest

from mimica import MimicaError
from mimica.align import fit_similarity
from mimica.data import ICT_LANDMARKS_68, is_ict_topology
from mimica.landmarks import Landmarks, ict_landmarks, landmarks_for, read_landmarks, write_landmarks
from mimica.correspond.remesh import resample_face


def test_ict_topology_recognised(head_model, full_model):
    assert is_ict_topology(head_model.mesh) and is_ict_topology(full_model.mesh)
    lm = ict_landmarks(head_model.mesh)
    np.testing.assert_allclose(lm.positions(head_model.mesh), head_model.neutral[ICT_LANDMARKS_68])


def test_json_round_trip_and_snapping(head_model, tmp_path):
    m = head_model.mesh
    true = m.vertices[ICT_LANDMARKS_68]
    normals = m.vertex_normals()[ICT_LANDMARKS_68]
    off = true + 0.02 * normals                                  # 0.2 mm off the surface
    off[5] = np.nan                                              # a point not given
    p = write_landmarks(tmp_path / "f.json", off)
    doc = json.loads(p.read_text())
    assert doc["scheme"] == "ibug68" and len(doc["points"]) == 68 and doc["points"][5] is None
    lm = read_landmarks(p, m)
    pos = lm.positions(m)
    assert not lm.present[5] and np.isnan(pos[5]).all()
    # snapped onto the surface: no farther from the given point than the true surface point
    ok = np.arange(68) != 5
    assert (np.linalg.norm(pos[ok] - off[ok], axis=1) <= 0.02 + 1e-9).all()
    assert np.linalg.norm(pos[ok] - true[ok], axis=1).max() <= 0.04 + 1e-9


@pytest.mark.parametrize("doc, needle", [
    ({"scheme": "other", "points": []}, "scheme"),
    ({"scheme": "ibug68", "points": [[0, 0, 0]] * 67}, "68 entries"),
    ({"scheme": "ibug68", "points": [[0, 0]] + [None] * 67}, "point 0"),
    ({"scheme": "ibug68", "points": [[0, 0, 0]] * 3 + [None] * 65}, "at least 4"),
])
def test_bad_landmark_files(tmp_path, head_model, doc, needle):
    p = tmp_path / "bad.json"
    p.write_text(json.dumps(doc))
    with pytest.raises(MimicaError, match=needle):
        read_landmarks(p, head_model.mesh)
    p.write_text("{not json")
    with pytest.raises(MimicaError, match="not valid JSON"):
        read_landmarks(p, head_model.mesh)


def test_other_topology_gets_landmarks_automatically(head_model):
    """A coarse resampled face (3,000 vertices, another topology, jagged holes at the eyes,
    nose and mouth): landmarks found by rendering and detection, median within 3% of the
    face width of the true ones (measured 2.4%; on full ICT identities 0.6%, test_image)."""
    v = head_model.neutral
    rs = resample_face(head_model.mesh.submesh(np.arange(9230))[0], v[ICT_LANDMARKS_68], 3000, seed=1)
    got = landmarks_for(rs.mesh, None, "scan.obj").positions(rs.mesh)
    tru = v[ICT_LANDMARKS_68]
    err = np.linalg.norm(got - tru, axis=1) / np.linalg.norm(tru[0] - tru[16])
    assert np.median(err) < 0.03


def test_no_face_found_says_which_option():
    from mimica.mesh import Mesh
    g = np.mgrid[0:20, 0:20].reshape(2, -1).T.astype(float)
    plane = Mesh.from_faces(np.c_[g, np.zeros(len(g))],
                            [[i * 20 + j, i * 20 + j + 1, (i + 1) * 20 + j] for i in range(19) for j in range(19)])
    with pytest.raises(MimicaError, match="plane.obj: .*68 landmarks in a file") as e:
        landmarks_for(plane, None, "plane.obj")
    assert "--" not in str(e.value)                      # the library names no command-line flag


def test_similarity_recovered_from_landmarks():
    rng = np.random.default_rng(5)
    src = rng.normal(size=(68, 3)) * 5
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.linalg.det(q))
    dst = 1.7 * src @ q.T + [3, -2, 8]
    s = fit_similarity(src, dst)
    assert abs(s.scale - 1.7) < 1e-9 and np.allclose(s.rotation, q) and s.residual < 1e-9
    noisy = dst + rng.normal(scale=0.01, size=dst.shape)
    s2 = fit_similarity(src, noisy)
    assert abs(s2.scale - 1.7) < 1e-3 and 0.005 < s2.residual < 0.03     # residual reported
    np.testing.assert_allclose(s.inverse().apply(s.apply(src)), src, atol=1e-9)


def test_landmarks_follow_the_mesh(head_model):
    lm = Landmarks.snap(head_model.mesh, head_model.neutral[ICT_LANDMARKS_68])
    moved = head_model.neutral + head_model.delta({"jawOpen": 1.0})
    np.testing.assert_allclose(lm.positions(head_model.mesh, moved), moved[ICT_LANDMARKS_68], atol=1e-9)


def test_canonical_names():
    from mimica.landmarks import NAMES, index
    assert len(NAMES) == 68 == len(set(NAMES))
    assert index("jaw.8") == 8 and index("eye.right.0") == 36 and index("mouth.inner.7") == 67
    with pytest.raises(MimicaError, match="unknown landmark"):
        index("nose.tip")
