"""ARKit takes on a head (issue 17, part 4): a Live Link Face CSV drives the 52 morph targets of
a head's blendshapes GLB at the take's frame rate; bad takes give one line and write nothing."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from mimica.cli import main
from mimica.export import ARKIT_52

ROTATIONS = ["HeadYaw", "HeadPitch", "HeadRoll", "LeftEyeYaw", "LeftEyePitch", "LeftEyeRoll",
             "RightEyeYaw", "RightEyePitch", "RightEyeRoll"]


def live_link_csv(path, weights, start="13:32:48:00"):
    """A take as Live Link Face writes it: Timecode at 60 fps, BlendShapeCount, PascalCase names."""
    h, m, s, _ = start.split(":")
    lines = [",".join(["Timecode", "BlendShapeCount"] + [n[0].upper() + n[1:] for n in ARKIT_52] + ROTATIONS)]
    for f, w in enumerate(weights):
        sec, fr = divmod(f, 60)
        tc = f"{h}:{m}:{int(s) + sec:02d}:{fr:02d}.{(37 * f) % 1000:03d}"
        lines.append(",".join([tc, "61"] + [f"{x:.6f}" for x in w] + ["0.01"] * len(ROTATIONS)))
    Path(path).write_text("\n".join(lines) + "\n")


@pytest.fixture(scope="module")
def head_glb(tmp_path_factory):
    d = tmp_path_factory.mktemp("take")
    data = Path(os.environ["MIMICA_DATA"]) / "real-heads" / "mediapipe-canonical"
    assert main(["blendshapes", str(data / "head.obj"), "--out", str(d / "head_arkit.glb")]) == 0
    return d / "head_arkit.glb"


def test_live_link_take_plays_on_the_head(head_glb, tmp_path, capsys):
    import pygltflib as gl
    from mimica.mesh.io import _gltf_accessor
    rng = np.random.default_rng(0)
    frames = 90
    w = np.clip(rng.normal(0.3, 0.2, (frames, 52)), 0, 1)
    live_link_csv(tmp_path / "take.csv", w)
    capsys.readouterr()
    assert main(["animate", str(head_glb), "--arkit", str(tmp_path / "take.csv"), "--out", str(tmp_path / "t.glb")]) == 0
    said = capsys.readouterr().err
    assert "90 frames over" in said and "(60 fps)" in said and "drive 52 morph targets" in said, said
    g = gl.GLTF2().load(str(tmp_path / "t.glb"))
    names = g.meshes[0].extras["targetNames"]
    s = g.animations[0].samplers[0]
    times = _gltf_accessor(g, s.input)
    # Live Link's timecode: frame f at f / 60 s, its sub-frame fraction (.fff) carried along
    sub = ((37 * np.arange(frames)) % 1000) / 1000.0
    np.testing.assert_allclose(times, (np.arange(frames) + sub - sub[0]) / 60.0, atol=1e-6)
    got = _gltf_accessor(g, s.output).reshape(frames, len(names))
    for j, n in enumerate(names):
        np.testing.assert_allclose(got[:, j], w[:, ARKIT_52.index(n)], atol=1e-6)
    from test_gltf import validate
    r = validate([tmp_path / "t.glb"])[0]
    assert r["errors"] == 0 and r["warnings"] == 0, r["messages"]


def test_a_weights_csv_with_a_time_column(head_glb, tmp_path):
    import pygltflib as gl
    from mimica.mesh.io import _gltf_accessor
    lines = [",".join(["time"] + ARKIT_52)] + [",".join([f"{t / 30:.5f}"] + ["0.5" if n == "jawOpen" else "0"
                                                                             for n in ARKIT_52]) for t in range(10)]
    (tmp_path / "w.csv").write_text("\n".join(lines))
    assert main(["animate", str(head_glb), "--arkit", str(tmp_path / "w.csv"), "--out", str(tmp_path / "w.glb")]) == 0
    g = gl.GLTF2().load(str(tmp_path / "w.glb"))
    got = _gltf_accessor(g, g.animations[0].samplers[0].output).reshape(10, -1)
    names = g.meshes[0].extras["targetNames"]
    assert np.allclose(got[:, names.index("jawOpen")], 0.5) and np.allclose(np.delete(got, names.index("jawOpen"), 1), 0)


@pytest.mark.parametrize("damage,said", [
    ("missing", "no column for jawOpen"),
    ("nan", "is not a finite number"),
    ("reversed", "the time does not increase"),
    ("words", "not a number or a timecode"),
])
def test_bad_takes_say_one_line_and_write_nothing(head_glb, tmp_path, capsys, damage, said):
    w = np.full((5, 52), 0.2)
    live_link_csv(tmp_path / "take.csv", w)
    lines = (tmp_path / "take.csv").read_text().splitlines()
    if damage == "missing":
        col = 2 + ARKIT_52.index("jawOpen")
        lines = [",".join(c for i, c in enumerate(ln.split(",")) if i != col) for ln in lines]
    elif damage == "nan":
        lines[3] = lines[3].replace("0.200000", "nan", 1)
    elif damage == "reversed":
        lines = [lines[0]] + lines[1:][::-1]
    else:
        lines[2] = lines[2].replace("0.200000", "high", 1)
    (tmp_path / "take.csv").write_text("\n".join(lines))
    out = tmp_path / "bad.glb"
    capsys.readouterr()
    assert main(["animate", str(head_glb), "--arkit", str(tmp_path / "take.csv"), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and said in err[0] and "take.csv" in err[0], err
    assert not out.exists()
