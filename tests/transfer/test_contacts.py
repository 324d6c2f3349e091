"""The lid contacts' own parts (transfer.contacts): which rim is whose lid, and how far a pair
of rims travels."""

from __future__ import annotations

import numpy as np
import pytest

from mimica.mesh import Mesh
from mimica.transfer.contacts import UPPER_SHARE, _Eye, _upper_path


def _eye_hole(tilt):
    """Rings around an eye-shaped hole (0.5 x 0.15 half-axes, sheared by `tilt`): a clean
    boundary loop, the upper lid where sin(angle) > 0."""
    th = np.linspace(0, 2 * np.pi, 48, endpoint=False)
    r = np.array([1.0, 1.5, 2.0, 3.0])
    x = 0.5 * np.outer(r, np.cos(th))
    v = np.c_[x.ravel(), (0.15 * np.outer(r, np.sin(th)) - tilt * x).ravel(), np.zeros(x.size)]
    i = np.arange(x.size).reshape(x.shape)
    a, b = i[:-1].ravel(), np.roll(i[:-1], -1, axis=1).ravel()
    c, d = np.roll(i[1:], -1, axis=1).ravel(), i[1:].ravel()
    return Mesh.from_faces(v, np.r_[np.c_[a, b, c], np.c_[a, c, d]]), i[0], np.sin(th)


def test_the_rim_is_split_into_its_lids_along_the_loop():
    """The rim cut at its two ends: a lower-lid vertex above the corners' line (a tilted eye, or
    corners found a little low) stays on the lower lid, as the line alone would not have it."""
    mesh, rim, lid = _eye_hole(tilt=0.3)
    p = mesh.vertices[rim]
    t, h = p[:, 0], p[:, 1] + 0.08                       # the corners' line 0.08 low
    ends = [np.argmin(t), np.argmax(t)]
    upper = _upper_path(mesh, rim, h, p[ends] + [[-0.02, 0.01, 0], [0.02, -0.01, 0]])
    ends = np.isin(np.arange(len(rim)), ends)
    assert ((lid > 0) == upper)[~ends].all()
    assert ((h > 0) != (lid > 0))[~ends].any()           # where the line would have put it wrong


def _right_eye(ring):
    """A right eye's landmarks (36-41) on the hole's ring `ring` (1: on its rim)."""
    lm = np.zeros((68, 3))
    th = np.pi - np.arange(6) * np.pi / 3               # 36 the corner at -x, 37 and 38 above, 39, 40 and 41 below
    lm[36:42] = np.c_[0.5 * ring * np.cos(th), 0.15 * ring * np.sin(th), np.zeros(6)]
    return lm


@pytest.mark.parametrize("ring", [1.0, 1.3])
def test_a_rim_inside_its_landmarks_travels_as_they_do(ring):
    """Landmarks on the rim: a closure c leaves (1 - c) of each pair's gap.  Landmarks outside it
    (as a cut eye's rim runs along the valley inside the margin): the rims travel c x the lids'
    gap at the landmarks (1.3 x the rim's, measured at the rim's points nearest them: 1.43 here),
    and meet at most; the upper lid makes UPPER_SHARE of it."""
    mesh, rim, _ = _eye_hole(tilt=0.0)
    eye = _Eye(mesh, _right_eye(ring), "right", np.array([0.0, 1.0, 0.0]))
    assert eye.ok and len(eye.upper) >= 15
    mid = np.abs(mesh.vertices[eye.upper, 0]) < 0.3      # paired one to one (nearer the corners a lower
    #                                                      vertex between two pairs takes their mean)
    for c in (0.5, 0.9):
        out = eye.correct(mesh.vertices[None], np.array([c]))[0]
        gap = eye._gap(out[None])[0][mid]
        closed = 1 - gap / eye.rest_gap[mid]
        if ring == 1.0:
            np.testing.assert_allclose(closed, c, atol=1e-9)
        elif c == 0.5:
            np.testing.assert_allclose(closed, closed[0], atol=1e-9)       # one ratio, the whole lid
            assert 1.3 * c <= closed[0] <= 1.5 * c, closed[0]
        else:
            np.testing.assert_allclose(gap, 0.0, atol=1e-9)               # met, not crossed
        upper_moved = np.linalg.norm(out[eye.upper] - mesh.vertices[eye.upper], axis=1)[mid]
        np.testing.assert_allclose(upper_moved, UPPER_SHARE * (eye.rest_gap[mid] - gap), atol=1e-9)
