"""`mimica transfer-image` and `mimica landmarks` from the command line: the pictures and sheet
written, the strength and --from-neutral options, driving frames into a clip, and one line, exit 2
and nothing written for what they refuse."""

from __future__ import annotations

import json

import numpy as np

from helpers import run_mimica

from mimica.data import data_dir
from mimica.image import read_image

YALE = data_dir() / "yalefaces"


def test_cli_transfer_image_and_errors(tmp_path):
    out = tmp_path / "out"
    r = run_mimica("transfer-image", YALE / "subject01.normal.gif", YALE / "subject01.happy.gif",
             "--target", YALE / "subject03.normal.gif", "--out", out)
    assert r.returncode == 0, r.stderr
    res = read_image(out / "subject01.happy.png")
    assert res.shape == (243, 320, 3)
    assert (out / "sheet.png").is_file()
    # the result differs from the target where the face is, and not far away from it
    tgt = read_image(YALE / "subject03.normal.gif")
    d = np.abs(res - tgt).mean(-1)
    assert d[150:200, 130:190].mean() > 0.02 and d[:, :20].mean() < 1e-3
    junk = tmp_path / "junk.gif"
    junk.write_bytes(b"GIF89a nonsense")
    out2 = tmp_path / "out2"
    r = run_mimica("transfer-image", junk, YALE / "subject01.happy.gif", "--target", YALE / "subject03.normal.gif",
             "--out", out2)
    assert r.returncode == 2 and "junk.gif" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not out2.exists()
    r = run_mimica("transfer-image", YALE / "subject01.normal.gif", YALE / "subject01.happy.gif",
             "--target", YALE / "subject03.normal.gif", "--strength", "3", "--out", out2)
    assert r.returncode == 2 and "strength 3" in r.stderr and not out2.exists()
    r = run_mimica("transfer-image", YALE / "subject01.normal.gif", YALE / "subject01.happy.gif",
             "--target", YALE / "subject03.normal.gif", "--strength", "0.5", "--out", out2)
    half = read_image(out2 / "subject01.happy.png")
    # half the expression: about half the change from the target (warp and tents both halved)
    ratio = np.abs(half - tgt).mean() / np.abs(res - tgt).mean()
    assert r.returncode == 0 and 0.3 < ratio < 0.7, ratio


def test_cli_landmarks_and_driving_frames(tmp_path):
    lm = tmp_path / "s.landmarks.json"
    r = run_mimica("landmarks", YALE / "subject02.normal.gif", "--out", lm, "--show", tmp_path / "s.png")
    assert r.returncode == 0, r.stderr
    assert len(json.loads(lm.read_text())["points"]) == 68 and (tmp_path / "s.png").is_file()
    frames = tmp_path / "frames"
    frames.mkdir()
    import shutil
    for i, e in enumerate(["normal", "happy", "surprised"]):
        shutil.copy(YALE / f"subject02.{e}.gif", frames / f"f{i}.gif")
    clip = tmp_path / "clip.mp4"
    r = run_mimica("transfer-image", YALE / "subject02.normal.gif", "--driving", frames,
             "--target", YALE / "subject05.normal.gif", "--out", clip)
    assert r.returncode == 0, r.stderr
    from mimica.image.io import to_uint8
    from mimica.image.video import frame_source
    n, fps, it = frame_source(clip)
    got = list(it)
    assert len(got) == 3 and got[0].shape[:2] == (242, 320)
    # read raw (as the trackers and the refinement on the pixels read a take): the same pixels, uint8
    for source in (clip, frames):
        raw = list(frame_source(source, raw=True)[2])
        plain = list(frame_source(source)[2])
        assert len(raw) == 3 and all(r.dtype == np.uint8 and r.shape == p.shape for r, p in zip(raw, plain))
        assert all(np.array_equal(r, to_uint8(p)) for r, p in zip(raw, plain))


def test_a_faceless_target_writes_nothing(tmp_path):
    from PIL import Image
    grey = tmp_path / "grey.png"
    Image.new("RGB", (200, 200), (128, 128, 128)).save(grey)
    out = tmp_path / "out"
    r = run_mimica("transfer-image", YALE / "subject01.normal.gif", YALE / "subject01.happy.gif", "--target", grey,
             "--out", out)
    assert r.returncode == 2 and "grey.png" in r.stderr and "no face" in r.stderr
    assert not out.exists()


def test_cli_from_neutral_on_a_target_that_already_smiles(tmp_path):
    """subject03's happy photo as the target, its normal one as its rest, and its own smile as the
    source: from the rest, the smile it already wears is the source's, so the photo comes back
    (mean change under a tenth of the smile added on top of its own); vtc is refused in one line,
    nothing written."""
    args = ("transfer-image", YALE / "subject03.normal.gif", YALE / "subject03.happy.gif",
            "--target", YALE / "subject03.happy.gif")
    r = run_mimica(*args, "--out", tmp_path / "stacked")
    assert r.returncode == 0, r.stderr
    r = run_mimica(*args, "--from-neutral", YALE / "subject03.normal.gif", "--out", tmp_path / "rest")
    assert r.returncode == 0, r.stderr
    tgt = read_image(YALE / "subject03.happy.gif")
    stacked, rest = (np.abs(read_image(tmp_path / d / "subject03.happy.png") - tgt).mean() for d in ("stacked", "rest"))
    assert rest < 0.15 * stacked, (rest, stacked)
    r = run_mimica(*args, "--from-neutral", YALE / "subject03.normal.gif", "--method", "vtc", "--out", tmp_path / "no")
    assert r.returncode == 2 and "method vtc" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "no").exists()
