"""The commands' outputs: no destroyed inputs, a rerun or a killed run never leaves half an
output, one line for every OS error."""

from __future__ import annotations

import os
from pathlib import Path
import signal
import subprocess
import sys
import time

import numpy as np
import pytest


@pytest.fixture(scope="module")
def heads(tmp_path_factory, head_model):
    from mimica.mesh import write_mesh
    d = tmp_path_factory.mktemp("heads")
    head = head_model.mesh
    write_mesh(d / "neutral.obj", head)
    write_mesh(d / "neutral.glb", head)
    for name in ("mouthSmile_L", "jawOpen", "eyeBlink_L", "browDown_R"):
        write_mesh(d / f"{name}.obj", head.with_vertices(head_model.shape(name)))
    from PIL import Image
    Image.fromarray(np.full((64, 64), 90, np.uint8)).save(d / "photo.png")
    return d


def _snapshot(d):
    return {p.name: p.read_bytes() for p in sorted(d.iterdir()) if p.is_file()}


def test_an_output_equal_to_an_input_is_refused_before_any_work(heads, tmp_path, capsys):
    from mimica.cli import main
    import shutil
    S = tmp_path / "S"
    shutil.copytree(heads, S)
    before = _snapshot(S)
    for argv in (["transfer", f"{S}/neutral.obj", f"{S}/mouthSmile_L.obj", "--target", f"{S}/neutral.obj", "--out", str(S)],
                 ["transfer", f"{S}/neutral.obj", str(S), "--target", f"{S}/neutral.obj", "--out", str(tmp_path)],
                 ["rig", f"{S}/neutral.obj", "--out", f"{S}/neutral.obj"],
                 ["landmarks", f"{S}/photo.png", "--out", f"{S}/photo.png"],
                 ["blendshapes", f"{S}/neutral.glb", "--out", f"{S}/neutral.glb"],
                 ["export", f"{S}/jawOpen.obj", "--out", f"{S}/jawOpen.obj"],
                 ["wrinkle-mask", f"{S}/neutral.obj", "--show", f"{S}/neutral.obj", "--out", f"{tmp_path}/m.wrinkles"]):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "is also an input" in err, err
    assert _snapshot(S) == before


def test_a_folder_of_the_users_files_is_never_replaced(heads, tmp_path, capsys):
    from mimica.cli import main
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    assert main(["transfer", f"{heads}/neutral.obj", f"{heads}/jawOpen.obj", "--target", f"{heads}/neutral.obj",
                 "--out", str(out)]) == 2
    assert "did not write" in capsys.readouterr().err
    assert [p.name for p in out.iterdir()] == ["notes.txt"]


def test_a_rerun_replaces_the_earlier_output_whole(heads, tmp_path):
    from mimica.cli import main
    out = tmp_path / "o"
    assert main(["transfer", f"{heads}/neutral.obj", f"{heads}/jawOpen.obj", f"{heads}/eyeBlink_L.obj",
                 "--target", f"{heads}/neutral.obj", "--out", str(out)]) == 0
    assert main(["transfer", f"{heads}/neutral.obj", f"{heads}/mouthSmile_L.obj", "--target",
                 f"{heads}/neutral.obj", "--out", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == [".mimica-run.json", "mouthSmile_L.obj"]
    assert [p.name for p in tmp_path.iterdir()] == ["o"]                 # no stage left beside it


@pytest.mark.parametrize("where", ["parent_is_a_file", "proc", "no_space", "read_only"])
def test_write_errors_are_one_line_naming_the_path(heads, tmp_path, capsys, monkeypatch, where):
    import errno
    from mimica.cli import main
    (tmp_path / "file").write_text("x")
    target = {"parent_is_a_file": tmp_path / "file" / "out", "proc": Path("/proc/mimica-test/out"),
              "no_space": tmp_path / "full", "read_only": tmp_path / "ro"}[where]
    if where in ("no_space", "read_only"):
        code = errno.ENOSPC if where == "no_space" else errno.EROFS

        def fail(*a, **k):
            raise OSError(code, os.strerror(code))
        monkeypatch.setattr("mimica.outputs.os.rename", fail)
        monkeypatch.setattr("mimica.outputs._exchange", lambda a, b: False)
    for argv in (["transfer", f"{heads}/neutral.obj", f"{heads}/jawOpen.obj", "--target", f"{heads}/neutral.obj",
                  "--out", str(target)],
                 ["export", f"{heads}/jawOpen.obj", "--out", str(target), "--format", "ply"]):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and str(target) in err and "Traceback" not in err, err
        assert not target.exists()
    leftovers = [p.name for p in tmp_path.iterdir() if p.name != "file"]
    assert leftovers == [], leftovers


def test_a_busy_port_is_one_line(heads, tmp_path, capsys):
    import socket
    from mimica.cli import main
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    s.listen()
    port = s.getsockname()[1]
    try:
        from mimica.rig import build_rig
        from mimica.mesh import read_mesh
        from mimica.landmarks import ict_landmarks
        face = read_mesh(heads / "neutral.obj")
        build_rig(face, ict_landmarks(face).positions(face), muscles=["frontalis_L"]).save(tmp_path / "f.rig")
        assert main(["view", str(heads / "neutral.obj"), "--rig", str(tmp_path / "f.rig"), "--no-wrinkles",
                     "--no-browser", "--port", str(port)]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and f"--port {port}" in err, err
    finally:
        s.close()


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGKILL])
def test_a_killed_run_leaves_the_old_output_or_the_complete_new_one(heads, tmp_path, sig):
    """Killed at several points of a second run into the same folder: the folder holds the
    first run's files or the second's, whole, and never a mix."""
    import shutil
    out = tmp_path / "o"
    seq = tmp_path / "seq"
    seq.mkdir()
    for i in range(24):
        shutil.copy(heads / ("jawOpen.obj" if i % 2 else "mouthSmile_L.obj"), seq / f"f{i:02d}.obj")
    env = dict(os.environ)
    src = Path(__file__).resolve().parents[2] / "src"
    if os.environ.get("MIMICA_TEST_INSTALLED") != "1":
        env["PYTHONPATH"] = str(src)
    cmd = [sys.executable, "-m", "mimica.cli", "transfer", str(heads / "neutral.obj")]
    first = subprocess.run(cmd + [str(heads / "browDown_R.obj"), "--target", str(heads / "neutral.obj"),
                                  "--out", str(out)], env=env, capture_output=True, text=True)
    assert first.returncode == 0, first.stderr
    old = sorted(p.name for p in out.iterdir())
    new = sorted([".mimica-run.json"] + [f"f{i:02d}.obj" for i in range(24)])
    seen = set()
    for delay in (0.5, 1.5, 2.5, 3.5, 5.0):
        # (a suite started from a background job inherits SIGINT ignored, and so would the run)
        p = subprocess.Popen(cmd + [str(seq), "--target", str(heads / "neutral.obj"), "--out", str(out)],
                             env=env, stderr=subprocess.PIPE, text=True,
                             preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
        time.sleep(delay)
        p.send_signal(sig)
        p.wait(60)
        names = sorted(q.name for q in out.iterdir())
        assert names in (old, new), names
        seen.add("new" if names == new else "old")
        if names == new:                                    # start again from the first run's output
            subprocess.run(cmd + [str(heads / "browDown_R.obj"), "--target", str(heads / "neutral.obj"),
                                  "--out", str(out)], env=env, check=True, capture_output=True)
        if sig != signal.SIGKILL:                          # unwound: its stage is gone
            assert [q.name for q in tmp_path.iterdir() if q.name.startswith(".")] == []
    assert "old" in seen                                   # some kills did land mid-run
