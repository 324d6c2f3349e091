"""Make src/mimica/landmarks/mediapipe68.json: which of MediaPipe's 468 face-mesh points stands
for each of the 68 iBUG points.

Training data: ICT-FaceKit's even identities (identity000, 002, ... 018), neutral and its six
basic expressions, rendered under two lights (image.ictphotos), whose true 2D points are the
projections of ICT's 68 landmark vertices.  For each iBUG point the mesh point with the smallest
mean distance to the truth (over the eyes' distance) is kept.  The odd identities are never
used here: bench/landmarks2d.py measures on them.

Run from the project root with MediaPipe installed (pip install 'mimica[mediapipe]'):
    .venv/bin/python tools/mediapipe68.py
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from mimica.image.ictphotos import LIGHT_LEFT, LIGHT_RIGHT, ICTPhotos  # noqa: E402
from mimica.landmarks.detect2d import mediapipe_faces  # noqa: E402

EXPRESSIONS = [None, "happiness", "surprise", "anger", "sadness", "disgust", "fear"]


def main():
    ph = ICTPhotos(size=(480, 640))
    pts, truth = [], []
    for i in range(0, 20, 2):
        for k, e in enumerate(EXPRESSIONS):
            img, xy = ph.photo(f"identity{i:03d}", e, light=LIGHT_LEFT if k % 2 else LIGHT_RIGHT)
            faces = mediapipe_faces(img)
            if faces:
                pts.append(faces[0])
                truth.append(xy)
    pts, truth = np.array(pts), np.array(truth)
    iod = np.linalg.norm(truth[:, 36] - truth[:, 45], axis=1)
    err = np.linalg.norm(pts[:, None, :, :] - truth[:, :, None, :], axis=3) / iod[:, None, None]   # (n, 68, 468)
    mean = err.mean(0)
    idx = mean.argmin(1)
    out = ROOT / "src" / "mimica" / "landmarks" / "mediapipe68.json"
    out.write_text(json.dumps({
        "about": "for each iBUG 68 point (in order), the MediaPipe face-mesh point nearest the truth on average "
                 "over rendered ICT-FaceKit faces (even identities, neutral and six expressions, two lights); "
                 "made by tools/mediapipe68.py",
        "renders": int(len(pts)),
        "mean_error_over_eye_distance": [round(float(mean[j, i]), 4) for j, i in enumerate(idx)],
        "indices": [int(i) for i in idx]}, indent=1) + "\n")
    print(f"{out}: {len(pts)} renders, mean error {mean[np.arange(68), idx].mean():.4f} of the eyes' distance")


if __name__ == "__main__":
    main()
