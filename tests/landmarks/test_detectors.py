"""The photos' two landmark detectors: dlib's 68 points and MediaPipe's face
mesh read at 68 of its points, on rendered ICT-FaceKit faces of identities never used to choose
those points (the odd ones), where the truth is the projection of the landmark vertices, and on
the Yale photos."""

from __future__ import annotations


import numpy as np
import pytest
from helpers import landmark_error

from mimica.image.ictphotos import LIGHT_LEFT, LIGHT_RIGHT, ICTPhotos
from mimica.landmarks import detect2d


@pytest.fixture(scope="module")
def renders():
    ph = ICTPhotos(size=(480, 640))
    out = []
    for k, (i, e) in enumerate([(1, None), (5, "happiness"), (9, "surprise"), (13, "anger"), (17, "fear")]):
        out.append(ph.photo(f"identity{i:03d}", e, light=LIGHT_LEFT if k % 2 else LIGHT_RIGHT))
    return out


def test_mediapipe_points_near_the_truth(mediapipe, renders):
    """Held-out rendered faces: each detector's median point within 6 % of the eyes' distance
    (bench/landmarks2d.py over 70 photos: dlib 3.8 %, MediaPipe 3.2 %), MediaPipe's no worse than
    dlib's on most photos."""
    errs = {d: [landmark_error(detect2d.detect(img, detector=d), xy) for img, xy in renders] for d in detect2d.DETECTORS}
    assert max(errs["mediapipe"]) < 0.06 and max(errs["dlib"]) < 0.06, errs
    assert sum(m <= d for m, d in zip(errs["mediapipe"], errs["dlib"])) >= 3, errs
    assert len(detect2d.mediapipe_68()) == 68 and len(set(detect2d.mediapipe_68().tolist())) == 68


def test_mediapipe_faces_by_size_and_a_missing_one(mediapipe, renders):
    img = renders[0][0]
    small = img[::2, ::2]
    two = np.zeros((img.shape[0], img.shape[1] + small.shape[1], 3), img.dtype)
    two[:, :img.shape[1]] = img
    two[:small.shape[0], img.shape[1]:] = small
    big = detect2d.detect(two, detector="mediapipe", face=0)
    other = detect2d.detect(two, detector="mediapipe", face=1)
    assert big[:, 0].max() < img.shape[1] <= other[:, 0].min()
    with pytest.raises(Exception, match="no face 2: 2 found"):
        detect2d.detect(two, detector="mediapipe", face=2)
    with pytest.raises(Exception, match="no face found"):
        detect2d.detect(np.full((200, 200, 3), 0.5, np.float32), "blank.png", detector="mediapipe")
