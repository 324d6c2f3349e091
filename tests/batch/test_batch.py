"""Batches (mimica.batch): a manifest of heads x performances run on a local pool and on a local
Ray cluster with the same outputs; reruns skip what did not change; a killed batch resumes; a
killed worker has its job retried (the command's own tests: tests/cli/test_batch_command.py)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from helpers import BATCH_FRAMES as FRAMES, BATCH_HEADS as HEADS, batch_studio
from helpers import batch_manifest as manifest, batch_outputs as outputs

from mimica.batch import run_batch
from mimica.mesh import read_mesh, write_mesh


@pytest.fixture(scope="module")
def studio(head_model, tmp_path_factory):
    return batch_studio(head_model, tmp_path_factory.mktemp("studio"))




def test_a_changed_head_reruns_its_jobs_only(studio, tmp_path, head_model):
    d = tmp_path / "studio"
    import shutil
    shutil.copytree(studio, d)
    run_batch(manifest(d, HEADS), tmp_path / "out", workers=2)
    before = {p: p.stat().st_mtime_ns for p in (tmp_path / "out").rglob("*.obj")}
    write_mesh(d / "heads" / "id1.obj", head_model.mesh.with_vertices(head_model.identity("identity015")))
    rep = run_batch(manifest(d, HEADS), tmp_path / "out", workers=2)
    ran = {r["id"] for r in rep["jobs"] if r["status"] == "done"}
    assert ran == {"talk/ids/id1/talk", "clip/ids/id1/talk"}, rep
    for p, t in before.items():
        assert (p.stat().st_mtime_ns == t) == ("ids/id1" not in str(p)), p


def _children(pid: int) -> list[int]:
    try:
        return [int(c) for c in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]
    except OSError:
        return []


def _workers(pid: int) -> list[int]:
    """The batch's worker processes (spawned pools), not multiprocessing's resource tracker."""
    out = []
    for c in _children(pid):
        try:
            cmd = Path(f"/proc/{c}/cmdline").read_bytes().replace(b"\0", b" ")
        except OSError:
            continue
        if b"spawn_main" in cmd:
            out.append(c)
    return out


def _batch_process(args) -> subprocess.Popen:
    env = dict(os.environ)
    return subprocess.Popen([sys.executable, "-m", "mimica.cli", "batch", *args], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _wait_for(cond, timeout=120.0):
    t = time.time()
    while time.time() - t < timeout:
        if cond():
            return True
        time.sleep(0.05)
    return False


def test_a_killed_worker_has_its_job_retried(studio, tmp_path):
    out = tmp_path / "out"
    p = _batch_process([str(manifest(studio, HEADS)), "--workers", "2", "--out", str(out)])
    assert _wait_for(lambda: len(_workers(p.pid)) >= 1)
    victim = _workers(p.pid)[0]
    os.kill(victim, signal.SIGKILL)                          # mid-batch: its job is lost with it
    _, err = p.communicate(timeout=300)
    assert p.returncode == 0, err
    rep = json.loads((out / "batch.json").read_text())
    assert rep["counts"] == {"done": 6, "skipped": 0, "failed": 0}, err
    assert any(r.get("retries") for r in rep["jobs"]), rep          # the killed worker's job ran again
    assert len(outputs(out)) == 3 * len(FRAMES) + 3


def test_a_killed_batch_resumes(studio, tmp_path):
    out = tmp_path / "out"
    p = _batch_process([str(manifest(studio, HEADS)), "--workers", "1", "--out", str(out)])
    assert _wait_for(lambda: len(list((out / ".batch" / "done").glob("*.json"))) >= 2)
    workers = _workers(p.pid)
    assert workers
    p.send_signal(signal.SIGKILL)                      # no chance to stop its workers ...
    p.wait()
    assert _wait_for(lambda: not any(Path(f"/proc/{w}").exists() for w in workers), 10)   # ... they leave
    finished = {f.stem for f in (out / ".batch" / "done").glob("*.json")}
    assert 2 <= len(finished) < 6
    rep = run_batch(manifest(studio, HEADS), out, workers=2)
    assert rep["counts"]["skipped"] == len(finished) and rep["counts"]["done"] == 6 - len(finished), rep
    assert rep["counts"]["failed"] == 0
    assert len(outputs(out)) == 3 * len(FRAMES) + 3
    # the resumed folder holds what an uninterrupted batch makes
    fresh = run_batch(manifest(studio, HEADS), tmp_path / "fresh", workers=2)
    assert fresh["counts"]["done"] == 6
    a, b = outputs(out), outputs(tmp_path / "fresh")
    assert a.keys() == b.keys()
    for k in a:
        if k.endswith(".obj"):
            np.testing.assert_array_equal(a[k], b[k])


def test_ray_gives_the_local_pools_outputs(studio, tmp_path):
    """A local Ray cluster (2 CPUs) runs the same plan with the same outputs (to rounding)."""
    if os.environ.get("CI") is None:
        pytest.importorskip("ray")
    import ray
    local = run_batch(manifest(studio, HEADS), tmp_path / "local", workers=2)
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        rem = run_batch(manifest(studio, HEADS), tmp_path / "ray", workers=2, ray="auto")
    finally:
        ray.shutdown()
    assert rem["engine"].startswith("Ray") and rem["counts"] == local["counts"] == {"done": 6, "skipped": 0, "failed": 0}
    a, b = outputs(tmp_path / "local"), outputs(tmp_path / "ray")
    assert a.keys() == b.keys() and len(a) == 3 * len(FRAMES) + 3
    from mimica.mesh.io import read_morph_targets
    for k in a:                          # the same numbers but for rounding: Ray's workers run BLAS
        if k.endswith(".obj"):           # on one thread, the local pool's on all cores
            np.testing.assert_allclose(a[k], b[k], atol=1e-9 * np.ptp(b[k]))
        else:                            # the clips: the same frames
            ma, ta, _ = read_morph_targets(tmp_path / "local" / k)
            mb, tb, _ = read_morph_targets(tmp_path / "ray" / k)
            assert ta.keys() == tb.keys()
            for n in ta:
                np.testing.assert_allclose(ta[n], tb[n], atol=1e-6 * np.ptp(ma.vertices))


def test_every_kind_of_job(studio, tmp_path):
    """blendshapes, animate (from them), simulate, render and export (from a transfer): each
    job's output is the file its command writes, in the folder the manifest says."""
    from mimica.export import ARKIT_52
    from mimica.mesh.io import read_morph_targets
    t = np.arange(6) / 30
    (studio / "take.json").write_text(json.dumps({"time": t.tolist(), **{n: (0.5 * t / t[-1]).tolist()
                                                                          for n in ARKIT_52}}))
    (studio / "smile.json").write_text(json.dumps({"format": "mimica-timeline/1", "channels": {
        "zygomaticus_major_L": {"keys": [[0, 0], [0.2, 1]]}}}))
    p = studio / "kinds.toml"
    p.write_text("""
[heads]
one = "heads/id0.obj"

[performances]
talk = { neutral = "perf/neutral.obj", frames = "perf/talk" }
take = { arkit = "take.json" }
smile = { timeline = "smile.json" }

[jobs.arkit]
run = "blendshapes"
[jobs.play]
run = "animate"
from = "arkit"
[jobs.sim]
run = "simulate"
fps = 10
[jobs.talk]
run = "transfer"
[jobs.look]
run = "render"
from = "talk"
view = "front"
size = 128
[jobs.clip]
run = "export"
from = "talk"
""")
    out = tmp_path / "out"
    rep = run_batch(p, out, workers=2)
    assert rep["counts"] == {"done": 6, "skipped": 0, "failed": 0}, rep
    shapes = read_morph_targets(out / "arkit" / "one" / "arkit.glb")
    assert len(shapes[1]) == 52
    assert (out / "play" / "one" / "take.glb").stat().st_size > 0
    sim = sorted((out / "sim" / "one" / "smile").glob("*.obj"))
    assert len(sim) == 3                                              # 0.2 s at 10 fps: 3 frames
    moved = read_mesh(sim[-1]).vertices - read_mesh(sim[0]).vertices
    assert np.linalg.norm(moved, axis=1).max() > 0.05                # the smile pulls the skin
    from mimica.image import read_image
    assert read_image(out / "look" / "one" / "talk.png").shape[0] > 100
    assert (out / "clip" / "one" / "talk.glb").stat().st_size > 0


def test_a_frames_folder_is_read_as_transfer_reads_it(studio, tmp_path):
    """A performance's folder is one format in natural order, as `mimica transfer` takes a folder:
    a previous run's animation.glb beside the OBJ frames is no frame (mesh.io.sequence_files)."""
    import shutil
    from mimica.batch.manifest import frame_files, plan
    d = tmp_path / "studio"
    shutil.copytree(studio, d)
    (d / "perf" / "talk" / "f10.obj").write_bytes((d / "perf" / "talk" / "f0.obj").read_bytes())
    (d / "perf" / "talk" / "animation.glb").write_bytes(b"glTF")
    jobs = plan(manifest(d, HEADS))
    names = [f.name for f in frame_files(jobs[0].performance)]
    assert names == ["f0.obj", "f1.obj", "f2.obj", "f3.obj", "f10.obj"]
