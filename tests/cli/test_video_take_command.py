"""`mimica animate --video` from the command line: a rendered take written as the animation and
a Live Link-style CSV that `animate --arkit` reads back; frames with no face found, said and
previewed; requests that cannot be met and takes that cannot be read give one line and write
nothing."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import jaw_frames, ramp, validate

from mimica.cli import main
from mimica.export import ARKIT_52


@pytest.mark.parametrize("tracker", [None, "dlib"])
def test_video_to_animation_and_live_link_csv(head_glb, tmp_path, capsys, tracker, mediapipe):
    """A folder of rendered frames (ICT's face opening its jaw) -> take.glb and take.csv: the
    GLB passes the validator, the CSV reads back as a take with the GLB's weights, and jawOpen
    rises and falls with the rendered jaw; with either tracker (MediaPipe's face mesh, the
    default, or dlib's)."""
    import pygltflib as gl
    from mimica.export.take import read_take
    from mimica.image.ictphotos import ICTPhotos
    from mimica.image.io import write_image
    from mimica.mesh.io.gltf import read_accessor
    photos = ICTPhotos(size=(320, 400))
    jaw = ramp(14, 2, 10, 1.0)
    frames = tmp_path / "frames"
    frames.mkdir()
    ident = np.zeros(20)
    for f, a in enumerate(jaw):
        img, _ = photos.photo(ident, "jawOpen" if a > 0 else None, amount=max(a, 1e-9))
        write_image(frames / f"f{f:03d}.png", img)
    out = tmp_path / "take.glb"
    capsys.readouterr()
    assert main(["animate", str(head_glb), "--video", str(frames), "--out", str(out)]
                + (["--tracker", tracker] if tracker else [])) == 0
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


def test_video_requests_that_cannot_be_met_say_one_line(head_glb, tmp_path, capsys):
    import pygltflib as gl
    frames = tmp_path / "empty"
    frames.mkdir()
    other = tmp_path / "other.glb"                   # morph targets, none of them ARKit's
    g = gl.GLTF2().load(str(head_glb))
    g.meshes[0].extras["targetNames"] = [f"shape{j}" for j in range(len(g.meshes[0].extras["targetNames"]))]
    g.save_binary(str(other))
    (tmp_path / "w.csv").write_text(",".join(["time"] + ARKIT_52) + "\n0," + ",".join(["0"] * 52) + "\n")
    cases = [([str(head_glb), "--video", str(frames), "--arkit", str(tmp_path / "w.csv")], "one of them"),
             ([str(head_glb)], "one of them"),
             ([str(other), "--video", str(frames)], "not a head with the 52 ARKit morph targets"),
             ([str(head_glb), "--arkit", str(tmp_path / "w.csv"), "--landmarks", str(tmp_path / "w.csv")],
              "give a video"),
             ([str(head_glb), "--video", str(frames), "--landmarks", str(tmp_path / "none.json")], "none.json"),
             ([str(head_glb), "--arkit", str(tmp_path / "w.csv"), "--tracker", "mediapipe"], "give a video"),
             ([str(head_glb), "--video", str(frames)], "holds no image frames"),
             ([str(head_glb), "--video", str(tmp_path / "none.mp4")], "no such video")]
    for args, said in cases:
        out = tmp_path / "bad.glb"
        capsys.readouterr()
        assert main(["animate", *args, "--out", str(out)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and said in err[0], (args, err)
        assert not out.exists() and not out.with_suffix(".csv").exists()


def test_frames_without_a_face_are_found_said_and_previewed(head_glb, tmp_path, capsys):
    """A take whose face leaves the picture for frames 7-10: exactly those frames are said to
    show no face, fitted to points filled in from their neighbours (the jaw still follows the
    rest), and the preview (the video beside the head) marks them with a red band; the preview
    and the take are readable as any new file here is (the umask's mode, not a temporary file's
    0600)."""
    from mimica.image.video import frame_source
    from mimica.outputs import file_mode
    from mimica.pipeline import animate
    jaw = ramp(20, 2, 16, 1.0)
    frames = jaw_frames(tmp_path / "frames", jaw, blank=range(7, 11), size=(480, 600))    # checked at half size
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
    for f in (r.preview, tmp_path / "take.glb", tmp_path / "take.csv"):
        assert f.stat().st_mode & 0o777 == file_mode(), (f.name, oct(f.stat().st_mode))
    capsys.readouterr()
    assert main(["animate", str(head_glb), "--video", str(frames), "--out", str(tmp_path / "again.glb")]) == 0
    said = capsys.readouterr().err
    assert "what it saw: no face in 4 frames (7-10)" in said, said


def test_takes_that_cannot_be_read_say_one_line(head_glb, tmp_path, capsys):
    """A video with no face, a video cut short (its index first, so ffmpeg decodes what is
    there), a preview without a video or not an MP4: one line each, nothing written."""
    import subprocess
    import imageio_ffmpeg
    from mimica.image.io import read_image
    from mimica.image.video import VideoWriter
    blank = jaw_frames(tmp_path / "blank", np.zeros(6), blank=range(6))
    frames = jaw_frames(tmp_path / "frames", ramp(30, 2, 26, 1.0))
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


def test_a_head_written_back_by_blender_plays_a_video(head_glb, tmp_path, capsys):
    """The head through Blender's glTF importer and exporter (mimica's extras dropped, as a
    user's round trip drops them), its targets then named as Live Link names them
    (EyeBlinkLeft): `animate --video` finds its landmarks on renders, says so in a line, drives
    all 52 targets, and jawOpen follows the jaw as it does on the head itself; the head's own
    landmarks given as a file are taken instead (the same basis as the stored one)."""
    from helpers import blender_files
    from mimica.export.take import read_take
    from mimica.export.video import landmark_basis
    from mimica.landmarks import write_landmarks
    from mimica.mesh.io.gltf import open_for_edit, save_edited
    back = tmp_path / "back.glb"
    blender_files("export", head_glb, back)
    _, doc, buf, _ = open_for_edit(back)          # renamed as the file stands (pygltflib adds offsets)
    extras = doc["meshes"][0]["extras"]
    assert "mimica_landmarks" not in extras
    extras["targetNames"] = [n[0].upper() + n[1:] for n in extras["targetNames"]]
    save_edited(doc, buf, back)
    jaw = ramp(14, 2, 10, 1.0)
    frames = jaw_frames(tmp_path / "frames", jaw)
    got = {}
    for name, extra in (("own", []), ("found", []), ("given", ["--landmarks", str(tmp_path / "lm.json")])):
        head = head_glb if name == "own" else back
        if name == "given":
            write_landmarks(tmp_path / "lm.json", landmark_basis(head_glb).rest)     # metres, as Blender wrote it
        out = tmp_path / f"{name}.glb"
        capsys.readouterr()
        assert main(["animate", str(head), "--video", str(frames), "--out", str(out), *extra]) == 0
        said = capsys.readouterr().err
        assert ("found on renders of it" in said) == (name == "found"), said
        assert "drive 52 morph targets" in said, said
        got[name] = read_take(out.with_suffix(".csv"), fps=25)[1]["jawOpen"]
        if name != "own":
            r = validate([out])[0]
            assert r["errors"] == 0, r["messages"]
    for name in ("found", "given"):
        assert np.corrcoef(got[name], jaw)[0, 1] > 0.9 and np.abs(got[name] - got["own"]).max() < 0.15, (name, got)
    own, given = landmark_basis(head_glb), landmark_basis(back, tmp_path / "lm.json")
    width = np.linalg.norm(own.rest[16] - own.rest[0])
    assert given.landmarks == "given" and np.abs(given.rest - own.rest).max() < 1e-3 * width
    assert np.abs(given.motion - own.motion).max() < 0.02 * width
