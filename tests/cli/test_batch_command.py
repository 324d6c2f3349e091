"""`mimica batch` from the command line: the same files as the commands one by one, a corrupt head
fails its own jobs only, a bad manifest runs nothing, a user's folder is never taken for a batch's."""

from __future__ import annotations


import numpy as np
import pytest
from helpers import BATCH_FRAMES as FRAMES, BATCH_HEADS as HEADS, batch_studio
from helpers import batch_manifest as manifest

from mimica.batch import batch_status, run_batch
from mimica.cli import main
from mimica.mesh import read_mesh


@pytest.fixture(scope="module")
def studio(head_model, tmp_path_factory):
    return batch_studio(head_model, tmp_path_factory.mktemp("studio"))


def test_batch_equals_the_commands(studio, tmp_path, head_model):
    """Every job's output equals what the `mimica transfer` command makes of the same inputs;
    a rerun skips them all and says so; --status reads the folder alone."""
    rep = run_batch(manifest(studio, HEADS), tmp_path / "out", workers=2)
    assert rep["counts"] == {"done": 6, "skipped": 0, "failed": 0}, rep
    for head, lm in (("ids/id0", None), ("scan", studio / "heads" / "scan.json")):
        src = head.split("/")[-1]
        args = ["transfer", str(studio / "perf" / "neutral.obj"), str(studio / "perf" / "talk"),
                "--target", str(studio / "heads" / f"{src}.obj"), "--out", str(tmp_path / f"cmd-{src}")]
        assert main(args + (["--target-landmarks", str(lm)] if lm else [])) == 0
        for i in range(len(FRAMES)):
            a = read_mesh(tmp_path / "out" / "talk" / head / "talk" / f"f{i}.obj").vertices
            b = read_mesh(tmp_path / f"cmd-{src}" / f"f{i}.obj").vertices
            np.testing.assert_allclose(a, b, atol=1e-9 * np.ptp(b))
    again = run_batch(manifest(studio, HEADS), tmp_path / "out", workers=2)
    assert again["counts"] == {"done": 0, "skipped": 6, "failed": 0}
    st = batch_status(tmp_path / "out")
    assert len(st["done"]) == 6 and not st["pending"] and not st["failed"]


def test_a_corrupt_head_fails_its_own_jobs(studio, tmp_path, capsys):
    heads = HEADS + '\nbroken = "heads/broken.obj"'
    out = tmp_path / "out"
    assert main(["batch", str(manifest(studio, heads)), "--workers", "2", "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert "6 done" in err and "2 failed" in err
    failed = [ln for ln in err.splitlines() if ln.strip().startswith("failed")]
    assert len(failed) == 2 and "broken.obj" in failed[0] and "non-finite" in failed[0]
    assert "talk/broken/talk, which failed" in failed[1]
    assert not (out / "talk" / "broken").exists()
    assert main(["batch", "--status", "--out", str(out)]) == 0
    said = capsys.readouterr().out
    assert said.startswith(f"{out}: 6 done, 0 pending, 2 failed") and "non-finite" in said


@pytest.mark.parametrize("case, says", [
    ('[heads]\na = "heads/id0.obj"\n[jobs.x]\nrun = "transfer"\nspeed = 3\n', "unknown option 'speed'"),
    ('[heads]\na = "heads/nothere.obj"\n[jobs.x]\nrun = "blendshapes"\n', "no such file"),
    ('[heads]\na = "heads/id0.obj"\n[jobs.x]\nrun = "render"\nfrom = "y"\n[jobs.y]\nrun = "export"\nfrom = "x"\n',
     "circle"),
    ('[heads]\na = "heads/id0.obj"\n[jobs.x]\nrun = "dance"\n', "run = 'dance'"),
    ('[heads]\na = "heads/id0.obj"\n[people]\n[jobs.x]\nrun = "blendshapes"\n', "unknown section 'people'"),
    ('[heads]\na = "heads/id0.obj"\n[jobs.x]\nrun = "transfer"\n', "no performance"),
    ('[heads\n', "not valid TOML"),
    ('[heads]\na = "heads/id0.obj"\n[jobs.x]\nrun = "age"\nages = ["old"]\n', "a list of numbers"),
])
def test_a_bad_manifest_runs_nothing(studio, tmp_path, capsys, case, says):
    p = studio / f"bad-{abs(hash(case)) % 10**8}.toml"
    p.write_text(case)
    out = tmp_path / "out"
    assert main(["batch", str(p), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and says in err and p.name in err, err
    assert not out.exists()


def test_a_users_folder_is_not_a_batch_folder(studio, tmp_path, capsys):
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("mine")
    assert main(["batch", str(manifest(studio, HEADS)), "--out", str(tmp_path / "mine")]) == 2
    assert "holds files of its own" in capsys.readouterr().err
    assert sorted(p.name for p in (tmp_path / "mine").iterdir()) == ["notes.txt"]
