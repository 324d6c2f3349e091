"""Benchmark: 2D landmarks, dlib's 68 points against MediaPipe's face mesh
read at 68 of its points, measured in the same run.

Run from the project root:  .venv/bin/python bench/landmarks2d.py   (needs the extras photo and mediapipe)
Data: ICT-FaceKit's odd identities (never used to choose MediaPipe's 68 points, see
tools/mediapipe68.py), neutral and six expressions, lit from the left or the right, rendered at
480x640, whose true points are the projections of ICT's landmark vertices; and the Yale faces.
Figures:

- error per photo: the median over the 68 points of the distance to the truth, over the eyes'
  distance (outer corners 36-45); its median over the photos, per detector; the jaw line (0-16)
  and the inner points (17-67) apart; photos where no face was found
- Yale: photos where no face was found; consistency: each subject's photos fitted (similarity,
  eye corners and nose) onto its `normal` photo, the mean residual of those stable points over
  the eyes' distance (lower: the points sit on the same places of the face from photo to photo)
- time per photo (detection included)
"""

from __future__ import annotations

import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from mimica.align import fit_similarity  # noqa: E402
from mimica.data import data_dir  # noqa: E402
from mimica.errors import MimicaError  # noqa: E402
from mimica.image.ictphotos import LIGHT_LEFT, LIGHT_RIGHT, ICTPhotos  # noqa: E402
from mimica.image.io import read_image  # noqa: E402
from mimica.landmarks.detect2d import DETECTORS, detect  # noqa: E402

EXPRESSIONS = [None, "happiness", "surprise", "anger", "sadness", "disgust", "fear"]
STABLE = [36, 39, 42, 45, 27, 30, 31, 35]


def run(images, detector):
    pts, t = [], time.perf_counter()
    for img in images:
        try:
            pts.append(detect(img, detector=detector))
        except MimicaError:
            pts.append(None)
    return pts, (time.perf_counter() - t) / len(images)


def ict(photos):
    imgs, truth = [], []
    for i in range(1, 20, 2):
        for k, e in enumerate(EXPRESSIONS):
            img, xy = photos.photo(f"identity{i:03d}", e, light=LIGHT_LEFT if k % 2 else LIGHT_RIGHT)
            imgs.append(img)
            truth.append(xy)
    return imgs, np.array(truth)


def yale():
    files = sorted((data_dir() / "yalefaces").glob("*.gif"))
    return [f.name for f in files], [read_image(f) for f in files]


def consistency(names, pts):
    out = []
    for s in sorted({n.split(".")[0] for n in names}):
        ref = [p for n, p in zip(names, pts) if n == f"{s}.normal.gif" and p is not None]
        if not ref:
            continue
        r = ref[0]
        iod = np.linalg.norm(r[36] - r[45])
        for n, q in zip(names, pts):
            if n.startswith(s + ".") and n != f"{s}.normal.gif" and q is not None:
                a, b = np.c_[q[STABLE], np.zeros(len(STABLE))], np.c_[r[STABLE], np.zeros(len(STABLE))]
                fit = fit_similarity(a, b)
                out.append(np.linalg.norm(fit.apply(a)[:, :2] - r[STABLE], axis=1).mean() / iod)
    return np.array(out)


def main():
    print(f"machine: {platform.machine()}, {platform.system()}, python {platform.python_version()}")
    imgs, truth = ict(ICTPhotos(size=(480, 640)))
    iod = np.linalg.norm(truth[:, 36] - truth[:, 45], axis=1)
    names, yimgs = yale()
    res = {}
    for det in DETECTORS:
        pts, sec = run(imgs, det)
        ok = np.array([p is not None for p in pts])
        e = np.array([np.linalg.norm(p - t, axis=1) / d for p, t, d in zip(pts, truth, iod) if p is not None])
        ypts, ysec = run(yimgs, det)
        c = consistency(names, ypts)
        res[det] = float(np.median(np.median(e, axis=1)))
        print(f"[{det}] rendered ICT, {len(imgs)} photos of 10 held-out identities: error {res[det]:.4f} of the eyes' "
              f"distance (median photo; mean point {e.mean():.4f}; jaw {np.median(e[:, :17]):.4f}, inner points "
              f"{np.median(e[:, 17:]):.4f}), no face in {int((~ok).sum())}; {1000 * sec:.0f} ms a photo")
        print(f"[{det}] Yale, {len(yimgs)} photos: no face in {sum(p is None for p in ypts)}; consistency "
              f"{np.median(c):.4f} (median over {len(c)} photos); {1000 * ysec:.0f} ms a photo")
    print(f"landmarks2d_err={res['dlib']:.4f} landmarks2d_err_dlib={res['dlib']:.4f} "
          f"landmarks2d_err_mediapipe={res['mediapipe']:.4f}")


if __name__ == "__main__":
    main()
