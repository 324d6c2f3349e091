"""ARKit weights from a video (issue 17, part 4): the 68 tracked points fitted through the head's
own blendshapes.  A take made by the head's own landmark model is recovered; a rendered take
through `animate --video` writes the animation and a Live Link-style CSV that `animate --arkit`
reads back; bad requests give one line and write nothing."""

from __future__ import annotations

import numpy as np

from mimica.cli import main
from mimica.export import ARKIT_52
from test_gltf import validate


def _ramp(frames, start, length, peak):
    w = np.zeros(frames)
    w[start:start + length] = peak * np.sin(np.linspace(0, np.pi, length)) ** 2
    return w


def test_a_take_made_by_the_heads_own_points_is_recovered(head_glb):
    """Points projected from the head's landmarks moved by known weights, under a turning head:
    the fit finds the weights (mean error under 0.08 where they act, correlation over 0.95, under
    0.02 elsewhere) and the head's turn."""
    from scipy.spatial.transform import Rotation
    from mimica.export.video import fit_weights, head_angles, landmark_basis
    basis = landmark_basis(head_glb)
    frames = 60
    w = np.zeros((frames, 52))
    w[:, ARKIT_52.index("jawOpen")] = _ramp(frames, 5, 30, 0.8)
    w[:, ARKIT_52.index("mouthSmileLeft")] = _ramp(frames, 25, 30, 0.7)
    w[:, ARKIT_52.index("browInnerUp")] = _ramp(frames, 10, 40, 0.9)
    yaw = np.radians(10) * np.sin(np.arange(frames) / 12)
    pts = np.zeros((frames, 68, 2))
    for f in range(frames):
        R = Rotation.from_euler("YXZ", [yaw[f], 0.05, 0.0]).as_matrix()
        p3 = (basis.rest + np.einsum("k,knj->nj", w[f], basis.motion)) @ R.T
        pts[f] = np.c_[320 + 1800 * p3[:, 0], 240 - 1800 * p3[:, 1]]           # pixels, y down
    fit = fit_weights(pts, basis)
    acting = [ARKIT_52.index(n) for n in ("jawOpen", "mouthSmileLeft", "browInnerUp")]
    on = w[:, acting] > 0.2
    err = np.abs(fit.weights[:, acting] - w[:, acting])
    assert err[on].mean() < 0.08, err[on].mean()
    for j in acting:
        assert np.corrcoef(fit.weights[:, j], w[:, j])[0, 1] > 0.95
    rest = np.delete(np.arange(52), acting)
    assert np.abs(fit.weights[:, rest]).mean() < 0.02
    turn = head_angles(fit.rotations)[:, 0]                       # relative to the rest frame
    assert np.abs(turn - (yaw - yaw[0])).max() < np.radians(1.0)


def test_video_to_animation_and_live_link_csv(head_glb, tmp_path, capsys):
    """A folder of rendered frames (ICT's face opening its jaw) -> take.glb and take.csv: the
    GLB passes the validator, the CSV reads back as a take with the GLB's weights, and jawOpen
    rises and falls with the rendered jaw."""
    import pygltflib as gl
    from mimica.export.take import read_take
    from mimica.image.ictphotos import ICTPhotos
    from mimica.image.io import write_image
    from mimica.mesh.io.gltf import read_accessor
    photos = ICTPhotos(size=(320, 400))
    jaw = _ramp(14, 2, 10, 1.0)
    frames = tmp_path / "frames"
    frames.mkdir()
    ident = np.zeros(20)
    for f, a in enumerate(jaw):
        img, _ = photos.photo(ident, "jawOpen" if a > 0 else None, amount=max(a, 1e-9))
        write_image(frames / f"f{f:03d}.png", img)
    out = tmp_path / "take.glb"
    capsys.readouterr()
    assert main(["animate", str(head_glb), "--video", str(frames), "--out", str(out)]) == 0
    said = capsys.readouterr().err
    assert "14 frames tracked" in said and "frame 0 taken as the performer's rest" in said, said
    assert out.is_file() and out.with_suffix(".csv").is_file()
    # a folder plays at 25 fps; the take is under a second, so its rate is given to the reader
    times, weights, rate = read_take(out.with_suffix(".csv"), fps=25)
    assert len(times) == 14 and {"headYaw", "headPitch", "headRoll"} <= set(weights)
    g = gl.GLTF2().load(str(out))
    np.testing.assert_allclose(read_accessor(g, g.animations[0].samplers[0].input), times, atol=1e-6)
    np.testing.assert_allclose(times, np.arange(14) / 25, atol=1e-6)
    names = g.meshes[0].extras["targetNames"]
    anim = read_accessor(g, g.animations[0].samplers[0].output).reshape(14, len(names))
    for j, n in enumerate(names):
        np.testing.assert_allclose(anim[:, j], weights[n], atol=2e-6)
    got = weights["jawOpen"]
    assert np.corrcoef(got, jaw)[0, 1] > 0.9 and got.max() > 0.5 and got[0] < 0.05, np.round(got, 2)
    r = validate([out])[0]
    assert r["errors"] == 0 and r["warnings"] == 0, r["messages"]


def test_live_link_csv_keeps_the_video_rate(tmp_path):
    """The CSV's timecode counts frames at the video's rate: a 30 fps take of 2.5 s reads back at
    30 fps with its times (a 60 fps count would read as 59)."""
    from mimica.export.take import read_take
    from mimica.export.video import write_live_link_csv
    times = np.arange(75) / 30
    w = np.random.default_rng(3).uniform(0, 1, (75, 52))
    write_live_link_csv(tmp_path / "t.csv", times, w, 30.0)
    back, weights, rate = read_take(tmp_path / "t.csv")
    assert rate == 30 and np.allclose(back, times, atol=1e-6)
    assert np.allclose(weights["jawOpen"], w[:, ARKIT_52.index("jawOpen")], atol=1e-6)


def test_video_requests_that_cannot_be_met_say_one_line(head_glb, tmp_path, capsys):
    import pygltflib as gl
    frames = tmp_path / "empty"
    frames.mkdir()
    old = tmp_path / "old.glb"
    g = gl.GLTF2().load(str(head_glb))
    g.meshes[0].extras.pop("mimica_landmarks")
    g.save_binary(str(old))
    (tmp_path / "w.csv").write_text(",".join(["time"] + ARKIT_52) + "\n0," + ",".join(["0"] * 52) + "\n")
    cases = [([str(head_glb), "--video", str(frames), "--arkit", str(tmp_path / "w.csv")], "one of them"),
             ([str(head_glb)], "one of them"),
             ([str(old), "--video", str(frames)], "no landmarks stored"),
             ([str(head_glb), "--video", str(frames)], "holds no image frames"),
             ([str(head_glb), "--video", str(tmp_path / "none.mp4")], "no such video")]
    for args, said in cases:
        out = tmp_path / "bad.glb"
        capsys.readouterr()
        assert main(["animate", *args, "--out", str(out)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and said in err[0], (args, err)
        assert not out.exists() and not out.with_suffix(".csv").exists()
