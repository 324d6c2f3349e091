"""ARKit weights from a video: the 68 tracked points fitted through the head's
own blendshapes.  A take made by the head's own landmark model is recovered; a rendered take
through `animate --video` writes the animation and a Live Link-style CSV that `animate --arkit`
reads back; bad requests give one line and write nothing."""

from __future__ import annotations

import numpy as np

from mimica.cli import main
from mimica.export import ARKIT_52
from helpers import validate


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


def _frames(folder, jaw, blank=(), size=(320, 400)):
    """Rendered frames of ICT's face opening its jaw by `jaw` (one a frame); frames in `blank`
    show no face (the background alone)."""
    from mimica.image.ictphotos import ICTPhotos
    from mimica.image.io import write_image
    photos = ICTPhotos(size=size)
    folder.mkdir()
    for f, a in enumerate(jaw):
        img = np.full((size[1], size[0], 3), 0.8) if f in blank else \
            photos.photo(np.zeros(20), "jawOpen" if a > 0 else None, amount=max(a, 1e-9))[0]
        write_image(folder / f"f{f:03d}.png", img)
    return folder


def test_frames_without_a_face_are_found_said_and_previewed(head_glb, tmp_path, capsys):
    """A take whose face leaves the picture for frames 7-10: exactly those frames are said to
    show no face, fitted to points filled in from their neighbours (the jaw still follows the
    rest), and the preview (the video beside the head) marks them with a red band."""
    from mimica.image.video import frame_source
    from mimica.pipeline import animate
    jaw = _ramp(20, 2, 16, 1.0)
    frames = _frames(tmp_path / "frames", jaw, blank=range(7, 11), size=(480, 600))    # checked at half size
    r = animate(head_glb, tmp_path / "take.glb", video=frames, preview=tmp_path / "preview.mp4")
    assert r.video["saw"]["no_face"] == [(7, 10)]
    assert r.video["fit"].missing.sum() == 4 and np.isfinite(r.video["fit"].weights).all()
    seen = np.r_[0:7, 11:20]
    assert np.corrcoef(r.weights["jawOpen"][seen], jaw[seen])[0, 1] > 0.9
    n, _, shown = frame_source(r.preview)
    shown = list(shown)
    assert len(shown) == 20 and shown[0].shape[:2] == (360, 288 + 360)    # the video and the head, side by side
    red = [bool((img[:4, :, 0] > 0.7).all() and (img[:4, :, 1] < 0.35).all()) for img in shown]
    assert red == [f in range(7, 11) for f in range(20)]
    capsys.readouterr()
    assert main(["animate", str(head_glb), "--video", str(frames), "--out", str(tmp_path / "again.glb")]) == 0
    said = capsys.readouterr().err
    assert "what it saw: no face in 4 frames (7-10)" in said, said


def test_both_trackers_find_the_same_points(tmp_path):
    """dlib (the default) and MediaPipe's face mesh track the same 68 points on a take: within a
    few hundredths of the face's width of each other, and a faceless last frame alike (dlib's
    frames since its detector last looked are checked at the end too); a tracker not known is
    one line."""
    import pytest
    from mimica.errors import MimicaError
    from mimica.export.video import track_video, trackers
    assert trackers() == ["dlib", "mediapipe"]         # CI installs the photo extra
    frames = _frames(tmp_path / "frames", _ramp(8, 1, 6, 1.0), blank=(7,))
    _, a = track_video(frames, tracker="mediapipe")
    _, b = track_video(frames)
    assert np.isnan(a[7]).all() and np.isnan(b[7]).all() and np.isfinite(a[:7]).all()
    width = np.ptp(b[:7, :, 0], axis=1).mean()
    gap = np.linalg.norm(a[:7] - b[:7], axis=2)
    assert np.median(gap) < 0.04 * width, np.median(gap) / width
    with pytest.raises(MimicaError, match="unknown face tracker 'x'"):
        track_video(frames, tracker="x")


def test_what_it_saw_turns_and_held_weights():
    """The report's turns past what the fit trusts and weights held at 1 for a second or more."""
    from scipy.spatial.transform import Rotation
    from mimica.export.video import TURN_TRUSTED, VideoFit, what_it_saw
    f = 100
    w = np.zeros((f, 52))
    w[10:40, ARKIT_52.index("jawOpen")] = 1.0                   # 30 frames at 25 fps: held
    w[50:70, ARKIT_52.index("mouthPucker")] = 1.0               # 20 frames: not
    yaw = np.zeros(f)
    yaw[60:64] = np.radians(TURN_TRUSTED + 5)
    rot = Rotation.from_euler("YXZ", np.stack([yaw, 0 * yaw, 0 * yaw], 1)).as_matrix()
    saw = what_it_saw(VideoFit(w, rot, np.zeros(f), np.zeros(f, bool)), 25.0)
    assert saw["held"] == {"jawOpen": [(10, 39)]}
    assert saw["turned"] == [(60, 63)] and abs(saw["turn_max"] - TURN_TRUSTED - 5) < 1e-6
    assert saw["no_face"] == []


def test_takes_that_cannot_be_read_say_one_line(head_glb, tmp_path, capsys):
    """A video with no face, a video cut short (its index first, so ffmpeg decodes what is
    there), a preview without a video or not an MP4: one line each, nothing written."""
    import subprocess
    import imageio_ffmpeg
    from mimica.image.io import read_image
    from mimica.image.video import VideoWriter
    blank = _frames(tmp_path / "blank", np.zeros(6), blank=range(6))
    frames = _frames(tmp_path / "frames", _ramp(30, 2, 26, 1.0))
    with VideoWriter(tmp_path / "v.mp4", 25) as w:
        for f in sorted(frames.glob("*.png")):
            w.write(read_image(f))
    subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-y", "-loglevel", "error", "-i", str(tmp_path / "v.mp4"),
                    "-c", "copy", "-movflags", "+faststart", str(tmp_path / "fast.mp4")], check=True)
    whole = (tmp_path / "fast.mp4").read_bytes()
    (tmp_path / "cut.mp4").write_bytes(whole[: len(whole) // 2])
    (tmp_path / "w.csv").write_text(",".join(["time"] + ARKIT_52) + "\n0," + ",".join(["0"] * 52) + "\n")
    cases = [(["--video", str(blank)], "no face in any of its 6 frames"),
             (["--video", str(tmp_path / "cut.mp4")], "breaks off after"),
             (["--arkit", str(tmp_path / "w.csv"), "--preview", str(tmp_path / "p.mp4")], "give --video"),
             (["--video", str(frames), "--preview", str(tmp_path / "p.gif")], "written as .mp4")]
    for args, said in cases:
        out = tmp_path / "bad.glb"
        capsys.readouterr()
        assert main(["animate", str(head_glb), *args, "--out", str(out)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and said in err[0], (args, err)
        assert not out.exists() and not out.with_suffix(".csv").exists()
        assert not any(tmp_path.glob("p.*")) and not any(tmp_path.glob(".p.*"))
