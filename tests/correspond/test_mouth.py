"""Sealed lips cut apart, on ICT heads remeshed with the lips sealed (the truth
known: ICT's own jawOpen) and on the shared real head (mediapipe canonical, sealed)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from helpers import sealed_lips

from mimica.correspond.mouth import cut_mouth, mouth_is_open
from mimica.correspond.remesh import resample_face
from mimica.data import ICT_LANDMARKS_68, data_dir
from mimica.landmarks import Landmarks, ict_landmarks
from mimica.mesh import read_mesh
from mimica.transfer import ExpressionTransfer


def _jaw_ratio(lm):
    return float(np.linalg.norm(lm[62] - lm[66]) / np.linalg.norm(lm[27] - lm[8]))


@pytest.fixture(scope="module")
def sealed(head_model):
    """A held-out ICT identity remeshed with its lips sealed."""
    return sealed_lips(head_model)


def test_cut_keeps_the_vertex_order(sealed):
    mesh, lm = sealed
    assert not mouth_is_open(mesh, lm.positions(mesh))
    mc = cut_mouth(mesh, lm.positions(mesh))
    assert mc.cut and 5 <= len(mc.copies_of) < 60
    n = mesh.n_vertices
    np.testing.assert_array_equal(mc.mesh.vertices[:n], mesh.vertices)             # the user's, in order
    np.testing.assert_array_equal(mc.mesh.vertices[n:], mesh.vertices[mc.copies_of])  # copies appended
    assert mc.mesh.n_faces == mesh.n_faces
    # the seam is now a slit: its inner vertices lie on the boundary, on both sides
    b = mc.mesh.boundary_vertices()
    assert b[mc.copies_of].all() and b[n:].all()


def test_open_mouth_is_not_cut(head_model):
    tv = head_model.identity("identity015")
    rs = resample_face(head_model.mesh.with_vertices(tv), tv[ICT_LANDMARKS_68], n_vertices=8000, seed=5)
    assert mouth_is_open(rs.mesh, tv[ICT_LANDMARKS_68])
    assert not cut_mouth(rs.mesh, tv[ICT_LANDMARKS_68]).cut


def test_jaw_opens_on_a_sealed_head(head_model, sealed):
    """ICT's jawOpen opens the inner lips by 0.267 of the nose-to-chin height on its own head;
    on the sealed head the cut lets it open by at least 0.18 (0.251 measured), where without it
    the membrane across the mouth holds the lips together (0.053; with Song's energy alone, no
    per-triangle term, 0.104 and 29 edges stretched past 2.5x)."""
    mesh, lm = sealed
    S = head_model.mesh
    frame = head_model.shape("jawOpen")
    shut = ExpressionTransfer(S, mesh, ict_landmarks(S), lm, cut_mouth=False).apply(frame)
    x = ExpressionTransfer(S, mesh, ict_landmarks(S), lm)
    out = x.apply(frame)
    assert x.mouth is not None and out.shape == (x.output_mesh.n_vertices, 3)
    assert _jaw_ratio(lm.positions(x.output_mesh, out)) > 0.18
    assert _jaw_ratio(lm.positions(mesh, shut)) < 0.1
    assert _stretched(x.output_mesh, out) <= _stretched(mesh, shut)
    rest = x.apply(S.vertices)                                    # the neutral stays closed
    np.testing.assert_allclose(rest, x.output_mesh.vertices, atol=1e-6 * np.ptp(mesh.vertices))


def _stretched(mesh, v):
    e = mesh.edges
    r = np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1) / np.linalg.norm(mesh.vertices[e[:, 0]] - mesh.vertices[e[:, 1]], axis=1)
    return int((r > 2.5).sum())


def test_shared_real_head_opens_its_mouth(head_model):
    d = data_dir() / "real-heads" / "mediapipe-canonical"
    head = read_mesh(d / "head.obj")
    lm = Landmarks.from_vertex_indices(head, json.loads((d / "head.json").read_text())["landmark_vertices"])
    S = head_model.mesh
    x = ExpressionTransfer(S, head, ict_landmarks(S), lm)
    assert x.mouth is not None
    out = x.apply(head_model.shape("jawOpen"))
    # 0.222 measured (the seam by landmarks alone 0.194; sealed: 0.133)
    assert _jaw_ratio(lm.positions(x.output_mesh, out)) > 0.2


def test_seam_follows_the_lips_crease():
    """The shared head's sealed lips meet in a valley (its triangles fold 90 degrees there);
    its landmarks lie on the lips' front, off that line.  The seam keeps to the valley between
    the corners; by landmarks and edge lengths alone it ran over the upper lip's inner face."""
    from mimica.correspond.mouth import _seam
    from mimica.mesh.query import concave_angles
    d = data_dir() / "real-heads" / "mediapipe-canonical"
    head = read_mesh(d / "head.obj")
    lm = Landmarks.from_vertex_indices(head, json.loads((d / "head.json").read_text())["landmark_vertices"])
    e = head.edges
    ang = dict(zip(map(tuple, e), np.degrees(concave_angles(head, e))))
    def valley(seam):                    # the seam's edges between its first and last two
        inner = seam[2:-2]
        return [ang[tuple(sorted(p))] for p in zip(inner[:-1], inner[1:])]
    pos = lm.positions(head)
    crease, plain = _seam(head, pos), _seam(head, pos, crease=0.0)
    assert len(crease) >= len(plain) and min(valley(crease)) > 80, valley(crease)
    assert np.mean(valley(plain)) < 50, valley(plain)                # 0, 90, 90, 0
    assert crease[0] == plain[0] and crease[-1] == plain[-1]        # the corners the landmarks give


def test_sealed_eyes_are_told(head_model):
    from mimica.correspond.mouth import sealed_eyes
    d = data_dir() / "real-heads" / "mediapipe-canonical"
    head = read_mesh(d / "head.obj")
    lm = Landmarks.from_vertex_indices(head, json.loads((d / "head.json").read_text())["landmark_vertices"])
    assert sorted(sealed_eyes(head, lm.positions(head))) == ["left", "right"]
    assert sealed_eyes(head_model.mesh, head_model.neutral[ICT_LANDMARKS_68]) == []


def test_blinks_close_the_lids(head_model, sealed):
    """ICT's eyeBlink closes its lid landmarks by 0.865; transferred onto the remeshed head the
    lids now close as the source's do (transfer.contacts), where the gradients alone left them
    half open.  The rims' pairs are matched by arc length between the landmarks (0.889 / 0.862;
    paired straight across the corners' axis they closed 0.726 / 0.795)."""
    from mimica.transfer.contacts import closure
    mesh, lm = sealed
    S = head_model.mesh
    frames = np.stack([head_model.shape("eyeBlink_L"), head_model.shape("eyeBlink_R")])
    rest = lm.positions(mesh)
    got = {}
    for lids in (False, True):
        x = ExpressionTransfer(S, mesh, ict_landmarks(S), lm, lids=lids)
        out = x.apply(frames)
        got[lids] = [closure(rest, lm.positions(x.output_mesh, out[k]), side) for k, side in enumerate(("left", "right"))]
    assert min(got[True]) > 0.82 and min(got[True]) > min(got[False]) + 0.15, got
    x = ExpressionTransfer(S, mesh, ict_landmarks(S), lm)
    np.testing.assert_allclose(x.apply(S.vertices), x.output_mesh.vertices, atol=1e-6 * np.ptp(mesh.vertices))


def test_sealed_eyes_do_not_spike(full_model):
    """The shared real head's eyes are closed surfaces; ICT's blinking lid rims, carried onto
    the skin across them, pushed it out (0.82 eye widths at worst before the transfer averaged
    each tent over its one-ring; 0.23 with Song's energy alone now).  That skin has low
    confidence and takes its motion from the skin around it (transfer.fill), and the
    per-triangle term (transfer.core.DT_STABILIZER) holds it too: 0.152 (0.161 without the fill,
    0.17 with the fill alone)."""
    d = data_dir() / "real-heads" / "mediapipe-canonical"
    head = read_mesh(d / "head.obj")
    lm = Landmarks.from_vertex_indices(head, json.loads((d / "head.json").read_text())["landmark_vertices"])
    S = full_model.mesh
    frames = np.stack([full_model.shape("eyeBlink_L"), full_model.shape("eyeBlink_R")])
    pos = lm.positions(head)
    width = np.linalg.norm(pos[45] - pos[42])
    worst = {}
    for fill, stabilize in ((False, False), (False, True), (True, True)):
        x = ExpressionTransfer(S, head, ict_landmarks(S), lm, fill=fill, stabilize=stabilize)
        assert (x.vertex_report()["confidence"] < 0.5).sum() > 5          # the sealed eyes' skin
        out = x.apply(frames)[:, :head.n_vertices]
        worst[fill, stabilize] = np.linalg.norm(out - head.vertices, axis=2).max() / width
    best = worst[True, True]
    assert best < 0.17 and best <= worst[False, True] and best < 0.8 * worst[False, False], worst


def _damage(mesh, rest, shape):
    """(triangles turned past 90 degrees, edges stretched past 2.5x or shrunk under 0.4x): counts."""
    turned = int((np.einsum("ij,ij->i", mesh.face_normals(rest), mesh.face_normals(shape)) < 0).sum())
    e = mesh.edges
    r = np.linalg.norm(shape[e[:, 0]] - shape[e[:, 1]], axis=1) / np.linalg.norm(rest[e[:, 0]] - rest[e[:, 1]], axis=1)
    return turned, int(((r > 2.5) | (r < 0.4)).sum())


def test_coarse_lips_keep_their_triangles(full_model, head_model):
    """The shared head's lips roll into its mouth as a few loops of slivers.  With Song's VTC
    energy alone the vertices of those one-rings, barely held, drifted past each other: jawOpen
    turned 6 of its 898 triangles and mouthRollLower 10 (ICT's own shapes turn 0.14 % and 0.05 %
    of theirs; the benchmark's limit is max(0.5 %, 1.5x ICT's)).  The per-triangle term that
    steadies VTC across topologies (transfer.core.DT_STABILIZER) keeps every triangle, and so
    does the anchor (transfer.core.ANCHOR) without it."""
    d = data_dir() / "real-heads" / "mediapipe-canonical"
    head = read_mesh(d / "head.obj")
    lm = Landmarks.from_vertex_indices(head, json.loads((d / "head.json").read_text())["landmark_vertices"])
    S = full_model.mesh
    names = ("jawOpen", "mouthRollLower")
    frames = np.stack([full_model.shape(n) for n in names])
    hv = head_model.neutral
    for n in names:                       # ICT's own shapes on its own head turn under 0.5 %
        assert _damage(head_model.mesh, hv, head_model.shape(n))[0] < 0.005 * head_model.mesh.n_faces
    got = {}
    for stabilize, anchor in ((False, 0.0), (True, 0.0), (False, None), (True, None)):
        more = {} if anchor is None else {"anchor": anchor}
        x = ExpressionTransfer(S, head, ict_landmarks(S), lm, stabilize=stabilize, **more)
        out = x.apply(frames)
        got[stabilize, anchor] = [_damage(x.output_mesh, x.output_mesh.vertices, o) for o in out]
    limit = 0.005 * len(head.triangles)
    for k in ((True, 0.0), (False, None), (True, None)):
        assert all(t <= limit and s <= limit for t, s in got[k]), got
    assert max(t for t, _ in got[False, 0.0]) > limit, got          # the test sees the drift (Song's energy alone)
    x = ExpressionTransfer(S, head, ict_landmarks(S), lm)
    np.testing.assert_allclose(x.apply(S.vertices), x.output_mesh.vertices, atol=1e-6 * np.ptp(head.vertices))
