"""`mimica landmarks --detector` and `transfer-image --detector mediapipe` from the command line."""

from __future__ import annotations

import numpy as np
from helpers import landmark_error

from mimica.cli import main
from mimica.image.ictphotos import LIGHT_LEFT, LIGHT_RIGHT, ICTPhotos
from mimica.landmarks import detect2d


def test_landmarks_command_with_either_detector(mediapipe, tmp_path, capsys):
    from mimica.image import write_image
    img, xy = ICTPhotos(size=(480, 640)).photo("identity005", "happiness", light=LIGHT_LEFT)
    write_image(tmp_path / "face.png", img)
    for d in detect2d.DETECTORS:
        capsys.readouterr()
        assert main(["landmarks", str(tmp_path / "face.png"), "--detector", d, "--out", str(tmp_path / f"{d}.json")]) == 0
        err = capsys.readouterr().err
        assert "W0000" not in err and "INFO" not in err and "deprecated" not in err   # MediaPipe's logs kept quiet
        pts = detect2d.read_points(tmp_path / f"{d}.json")
        assert landmark_error(pts, xy) < 0.06
    assert main(["landmarks", str(tmp_path / "face.png"), "--detector", "mediapipe", "--list"]) == 0
    assert "1 face(s)" in capsys.readouterr().err
    write_image(tmp_path / "blank.png", np.full((200, 200, 3), 0.5, np.float32))
    assert main(["landmarks", str(tmp_path / "blank.png"), "--detector", "mediapipe", "--out", str(tmp_path / "b.json")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "no face found" in err and not (tmp_path / "b.json").exists()


def test_transfer_image_with_mediapipe(mediapipe, tmp_path):
    """The whole photo path runs on MediaPipe's points: the target takes the source's smile."""
    from mimica.image import read_image, write_image
    ph = ICTPhotos(size=(480, 640))
    src, _ = ph.photo("identity003", None, light=LIGHT_LEFT)
    smile, _ = ph.photo("identity003", "happiness", light=LIGHT_LEFT)
    tgt, _ = ph.photo("identity011", None, light=LIGHT_RIGHT)
    truth, _ = ph.photo("identity011", "happiness", light=LIGHT_RIGHT)
    for name, im in (("src.png", src), ("smile.png", smile), ("tgt.png", tgt)):
        write_image(tmp_path / name, im)
    assert main(["transfer-image", str(tmp_path / "src.png"), str(tmp_path / "smile.png"), "--target",
                 str(tmp_path / "tgt.png"), "--detector", "mediapipe", "--out", str(tmp_path / "o")]) == 0
    out = read_image(tmp_path / "o" / "smile.png")[..., :3]

    def psnr(a, b):
        return -10 * np.log10(np.mean((np.asarray(a, float) - np.asarray(b, float)) ** 2))
    assert psnr(out, truth) > psnr(tgt, truth) + 1.0          # closer to the true smile than the neutral
