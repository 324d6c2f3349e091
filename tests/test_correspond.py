"""Transfer across topologies (Song §V.A) onto remeshed scans made here from the shared data."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import held_out_identity

from mimica.data import EXPRESSIONS, ICT_FACE_AREA_FACES, ICT_FACE_AREA_VERTICES, ICT_LANDMARKS_68
from mimica.landmarks import Landmarks, ict_landmarks
from mimica.correspond.remesh import resample_face
from mimica.transfer import ExpressionTransfer, relative_error, static_vertices

FACE = slice(0, ICT_FACE_AREA_VERTICES)


@pytest.fixture(scope="module")
def scans(head_model):
    """Held-out identities, resampled to ~11k vertices with holes at eyes, nostrils, mouth."""
    out = []
    for seed in (100, 101):
        tv = held_out_identity(head_model, seed)
        face, _ = head_model.mesh.with_vertices(tv).submesh(np.arange(ICT_FACE_AREA_FACES))
        rs = resample_face(face, tv[ICT_LANDMARKS_68], n_vertices=11000, seed=seed)
        out.append((tv, rs, Landmarks.snap(rs.mesh, tv[ICT_LANDMARKS_68])))
    return out


def test_remeshed_scan_has_its_own_topology_and_holes(scans):
    from scipy.sparse.csgraph import connected_components
    for _, rs, _ in scans:
        m = rs.mesh
        assert 9000 <= m.n_vertices <= 14000
        assert m.boundary_vertices().sum() > 300             # outline + eye, nostril, mouth holes
        assert connected_components(m.adjacency)[0] == 1


def test_transfer_onto_remeshed_scans(head_model, scans):
    S = head_model.mesh
    frames = np.stack([S.vertices + head_model.delta(EXPRESSIONS[e]) for e in EXPRESSIONS])
    errs = []
    for tv, rs, lt in scans:
        x = ExpressionTransfer(S, rs.mesh, ict_landmarks(S), lt, static=static_vertices(S.vertices, frames))
        out = x.apply(frames)
        assert out.shape == (len(frames), rs.mesh.n_vertices, 3)       # the target's own topology
        assert x.correspondence.matched.mean() > 0.97
        errs.append(np.mean([relative_error(o, rs.carry(tv[FACE] + f[FACE] - S.vertices[FACE]), rs.mesh.vertices)
                             for o, f in zip(out, frames)]))
    assert max(errs) < 0.18 and np.mean(errs) <= 0.15, errs


def test_correspondence_lands_near_the_true_point(head_model, scans):
    from mimica.align import fit_similarity
    from mimica.correspond import correspond
    S = head_model.mesh
    ls = S.vertices[ICT_LANDMARKS_68]
    tv, rs, lt = scans[0]
    T = rs.mesh
    sim = fit_similarity(lt.positions(T), ls)
    cor = correspond(S, ls, T.with_vertices(sim.apply(T.vertices)), sim.apply(lt.positions(T)))
    got = cor.matrix(S.triangles) @ S.vertices
    true = rs.carry(S.vertices[FACE])
    d = np.linalg.norm(got - true, axis=1)[cor.matched]
    width = np.linalg.norm(ls[16] - ls[0])
    assert np.median(d) < 0.02 * width                        # median within 2% of the face width
