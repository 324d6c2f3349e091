"""Fit the per-landmark offsets from dlib's photo markup to ICT-FaceKit's landmark vertices.

Renders the even-numbered ICT identities (000, 002, ... 018) as `mimica landmarks` does, runs
the 2D detector, and averages (true projection - detection) in the eye-line frame, in units of
the eye-to-eye distance.  Writes src/mimica/landmarks/detect3d_offsets.json.  The odd-numbered
identities stay held out: bench/transfer_image.py reports the 3D error on them.
"""

import json

import numpy as np

from mimica.data import ICT_HEAD_VERTICES, ICT_LANDMARKS_68, ICTModel
from mimica.landmarks import detect2d
from mimica.landmarks.detect3d import OFFSETS_FILE, eye_frame, render_for_detection

TRAIN = [f"identity{i:03d}" for i in range(0, 20, 2)]


def main():
    m = ICTModel(ICT_HEAD_VERTICES)
    offs = []
    for name in TRAIN:
        v = m.identity(name)
        img, frame, xy, cam = render_for_detection(m.mesh, v)
        p2 = detect2d.fit_points(img, detect2d.detect_faces(img, upsample=0)[0])
        iod, ex, ey = eye_frame(p2)
        d = xy[ICT_LANDMARKS_68] - p2
        offs.append(np.stack([d @ ex, d @ ey], 1) / iod)
        print(name, "mean |offset| (eye distances):", round(float(np.linalg.norm(offs[-1], axis=1).mean()), 4))
    off = np.mean(offs, 0)
    OFFSETS_FILE.write_text(json.dumps({"about": "tools/calibrate_landmarks3d.py: dlib 68-point markup -> ICT-FaceKit "
                                        "landmark vertices, per landmark (across, down) in eye-to-eye distances; "
                                        "fitted on " + ", ".join(TRAIN),
                                        "offsets": np.round(off, 4).tolist()}, indent=0) + "\n")
    print("wrote", OFFSETS_FILE)


if __name__ == "__main__":
    main()
