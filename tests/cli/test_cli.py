"""The command line: transfer and error end to end; user errors are one line, exit 2, no output."""

from __future__ import annotations

import json

import numpy as np
import pytest

from mimica import read_mesh, write_mesh
from mimica.cli import main
from mimica.data import ICT_LANDMARKS_68, ict_path
from mimica.landmarks import write_landmarks
from mimica.correspond.remesh import resample_face


@pytest.fixture(scope="module")
def files(tmp_path_factory, head_model):
    d = tmp_path_factory.mktemp("cli")
    S = head_model.mesh
    write_mesh(d / "S.obj", S)
    (d / "seq").mkdir()
    for k, e in enumerate(["jawOpen", "mouthSmile_L", "browInnerUp_L"]):
        write_mesh(d / "seq" / f"f{k:03d}_{e}.obj", S.with_vertices(S.vertices + head_model.delta({e: 1.0})))
    tv = head_model.identity("identity015")
    write_mesh(d / "T.obj", S.with_vertices(tv))
    face, _ = S.with_vertices(tv).submesh(np.arange(9230))
    rs = resample_face(face, tv[ICT_LANDMARKS_68], n_vertices=6000, seed=2)
    write_mesh(d / "scan.ply", rs.mesh)
    write_landmarks(d / "scan.json", tv[ICT_LANDMARKS_68])
    return d


def test_transfer_folder_same_topology_keeps_quads(files, tmp_path, capsys):
    out = tmp_path / "o"
    assert main(["transfer", str(files / "S.obj"), str(files / "seq"), "--target", str(files / "T.obj"),
                 "--out", str(out)]) == 0
    names = sorted(p.name for p in out.iterdir() if p.name != ".mimica-run.json")
    assert names == sorted(p.name for p in (files / "seq").iterdir())
    assert (out / ".mimica-run.json").is_file()                 # a complete run, marked
    T = read_mesh(files / "T.obj")
    r = read_mesh(out / names[0])
    assert r.same_topology(T) and (r.face_sizes == 4).sum() > 10000 and r.uv is not None
    assert "frames/s" in capsys.readouterr().err



def test_a_long_sequence_goes_through_its_basis(files, head_model, tmp_path, capsys):
    """130 frames (>= BASIS_FRAMES) of three blended expressions: `transfer` sends them through
    their basis, says so, and writes what frame by frame gives within 1e-3 of the motion."""
    from mimica.transfer import BASIS_FRAMES, ExpressionTransfer, static_vertices
    S = head_model.mesh
    d = np.stack([head_model.delta({e: 1.0}) for e in ["jawOpen", "mouthSmile_L", "browInnerUp_L"]])
    t = np.linspace(0, 2 * np.pi, BASIS_FRAMES + 2)[:, None]
    w = np.clip(np.sin(t * np.array([1.0, 1.7, 0.6]) + np.array([0.0, 1.0, 2.0])), 0, None)
    frames = S.vertices + np.einsum("fk,knd->fnd", w, d)
    seq = tmp_path / "long"
    seq.mkdir()
    for k, v in enumerate(frames):
        write_mesh(seq / f"f{k:03d}.ply", S.with_vertices(v))
    out = tmp_path / "o"
    assert main(["transfer", str(files / "S.obj"), str(seq), "--target", str(files / "T.obj"), "--out", str(out)]) == 0
    assert f"{len(frames)} frames through a basis of their motion" in capsys.readouterr().err
    T = read_mesh(files / "T.obj")
    x = ExpressionTransfer(S, T, None, None, static=static_vertices(S.vertices, frames))   # as the command
    exact = x.apply(frames, basis=False)
    got = np.stack([read_mesh(out / f"f{k:03d}.ply").vertices for k in range(len(frames))])
    motion = np.linalg.norm(exact - T.vertices, axis=2).max()
    assert np.linalg.norm(got - exact, axis=2).max() <= 1e-3 * motion

def test_transfer_onto_other_topology_finds_landmarks(files, tmp_path):
    """No landmark file for a scan-like face: they are found automatically (render, detect,
    cast back) and the result is close to the one with the landmark file."""
    out, out2 = tmp_path / "o", tmp_path / "o2"
    args = ["transfer", str(files / "S.obj"), str(files / "seq" / "f000_jawOpen.obj"),
            "--target", str(files / "scan.ply"), "--method", "dt"]
    assert main(args + ["--out", str(out)]) == 0
    assert main(args + ["--out", str(out2), "--target-landmarks", str(files / "scan.json")]) == 0
    auto, given = read_mesh(out / "f000_jawOpen.obj"), read_mesh(out2 / "f000_jawOpen.obj")
    assert auto.same_topology(read_mesh(files / "scan.ply"))
    rest = read_mesh(files / "scan.ply").vertices
    size = np.ptp(rest, 0).max()
    moved = np.linalg.norm(given.vertices - rest, axis=1).max()
    assert moved > 0.01 * size
    assert np.abs(auto.vertices - given.vertices).max() < 0.25 * moved


def test_landmarks_not_found_is_one_line(tmp_path, capsys):
    """A mesh with no face on it: one line naming the file, exit 2, nothing written."""
    from mimica.mesh import Mesh, write_mesh
    g = np.mgrid[0:20, 0:20].reshape(2, -1).T.astype(float)
    v = np.c_[g, np.zeros(len(g))]
    f = [[i * 20 + j, i * 20 + j + 1, (i + 1) * 20 + j] for i in range(19) for j in range(19)]
    write_mesh(tmp_path / "plane.obj", Mesh.from_faces(v, f))
    out = tmp_path / "o"
    assert main(["transfer", str(tmp_path / "plane.obj"), str(tmp_path / "plane.obj"),
                 "--target", str(tmp_path / "plane.obj"), "--source-landmarks", str(tmp_path / "none.json"),
                 "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and not out.exists()
    assert main(["landmarks", str(tmp_path / "plane.obj"), "--out", str(tmp_path / "p.json")]) == 2
    err = capsys.readouterr().err.strip()
    assert "plane.obj" in err and "no face" in err and not (tmp_path / "p.json").exists()


@pytest.mark.parametrize("case", ["bad_frame", "wrong_count", "missing_target", "bad_landmarks", "dup"])
def test_transfer_bad_input_writes_nothing(files, tmp_path, capsys, case):
    out = tmp_path / "o"
    S, T = str(files / "S.obj"), str(files / "T.obj")
    frames = [str(files / "seq")]
    extra = []
    if case == "bad_frame":
        bad = tmp_path / "bad.obj"
        bad.write_text("v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n")
        frames.append(str(bad))
    elif case == "wrong_count":
        frames.append(str(files / "scan.ply"))
    elif case == "missing_target":
        T = str(tmp_path / "nope.obj")
    elif case == "bad_landmarks":
        lm = tmp_path / "lm.json"
        lm.write_text(json.dumps({"scheme": "ibug68", "points": [[0, 0, 0]]}))
        extra = ["--target-landmarks", str(lm)]
    elif case == "dup":
        frames.append(str(files / "seq" / "f000_jawOpen.obj"))
    rc = main(["transfer", S, *frames, "--target", T, "--out", str(out), *extra])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and err.startswith("mimica: error:") and len(err.splitlines()) == 1
    assert not out.exists()


def test_error_map_png(files, tmp_path, capsys):
    from PIL import Image
    png = tmp_path / "err.png"
    ref = ict_path("jawOpen")
    assert main(["error", str(ref), str(ref), "--reference-neutral", str(ict_path("generic_neutral_mesh")),
                 "--out", str(png)]) == 0
    assert "median 0.00%" in capsys.readouterr().err                # a result against itself
    img = np.asarray(Image.open(png).convert("RGB")).astype(int)
    green = (img[..., 1] > 150) & (img[..., 0] < 100) & (img[..., 2] < 120)
    assert green.sum() > 5000                                       # the moving part, all < 0.1 %


def test_blender_addon_writes_the_addon_to_install(tmp_path, capsys):
    """The zip Blender installs: the package mimica_blender, the add-on and the facts it shares
    with mimica, byte for byte mimica's own files; it imports outside mimica (as in Blender)."""
    import subprocess
    import sys
    import zipfile
    from pathlib import Path
    import mimica.blender_addon as addon
    import mimica.facts as facts
    from mimica.cli import main
    assert main(["blender-addon", "--out", str(tmp_path / "addons")]) == 0
    copy = tmp_path / "addons" / "mimica_blender.zip"
    with zipfile.ZipFile(copy) as z:
        assert sorted(z.namelist()) == ["mimica_blender/__init__.py", "mimica_blender/facts.py"]
        assert z.read("mimica_blender/__init__.py") == Path(addon.__file__).read_bytes()
        assert z.read("mimica_blender/facts.py") == Path(facts.__file__).read_bytes()
        z.extractall(tmp_path / "unzipped")
    probe = "import sys; sys.path.insert(0, '.'); import mimica_blender as a; print(len(a.ARKIT), 'mimica' in sys.modules)"
    got = subprocess.run([sys.executable, "-I", "-c", probe], cwd=tmp_path / "unzipped", capture_output=True, text=True)
    assert got.stdout.split() == ["52", "False"], got.stderr
    assert main(["blender-addon", "--out", str(copy)]) == 2
    assert "name a folder" in capsys.readouterr().err


def test_every_command_that_writes_takes_o_for_out(files, tmp_path):
    """`-o` is `--out` on every command that has one (as in most tools a user knows), and it
    writes where it says."""
    import argparse
    from mimica.cli import build_parser
    commands = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)).choices
    with_out = {name: p for name, p in commands.items() if any(a.dest == "out" for a in p._actions)}
    assert len(with_out) >= 15
    for name, p in with_out.items():
        assert next(a for a in p._actions if a.dest == "out").option_strings == ["-o", "--out"], name
    assert main(["transfer", str(files / "S.obj"), str(files / "seq" / "f000_jawOpen.obj"),
                 "--target", str(files / "T.obj"), "-o", str(tmp_path / "o")]) == 0
    assert (tmp_path / "o").is_dir() and any((tmp_path / "o").iterdir())
