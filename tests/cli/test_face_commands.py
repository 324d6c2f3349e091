"""`mimica rig`, `simulate`, `fit-muscles`, `wrinkle-mask` and `age` from the command line: the
files each writes, and one line, exit 2 and nothing written for what they refuse."""

from __future__ import annotations

import json

import numpy as np
import pytest

from mimica.cli import main
from mimica.data import ICT_FACE_AREA_VERTICES, ICT_LANDMARKS_68, ICTModel
from mimica.physics.fit import MuscleFit
from mimica.rig import Rig, build_rig
from mimica.wrinkles import WrinkleMask, reference_mask


MUSCLES = ["zygomaticus_major_L", "zygomaticus_major_R", "depressor_anguli_oris_R"]


@pytest.fixture(scope="module")
def rig(face):
    return build_rig(face.mesh, face.neutral[ICT_LANDMARKS_68], muscles=MUSCLES)


def test_cli_rig_and_simulate(tmp_path, face, capsys):
    from mimica import write_mesh
    obj = write_mesh(tmp_path / "face.obj", face.mesh)
    rig_path = tmp_path / "face.rig"
    assert main(["rig", str(obj), "--muscles", "zygomaticus_major_R", "--out", str(rig_path)]) == 0
    out = tmp_path / "sim"
    assert main(["simulate", str(rig_path), "--expression", "happiness", "--duration", "0.25", "--out", str(out)]) == 0
    frames = sorted(out.glob("frame_*.obj"))
    assert len(frames) == 16 and (out / "strip.png").is_file()
    from pygltflib import GLTF2
    g = GLTF2().load(str(out / "animation.glb"))
    # 16 frames: one morph target each, or a few basis shapes with per-frame weights (compact)
    n_targets = len(g.meshes[0].primitives[0].targets)
    assert len(g.meshes[0].extras.get("frames", g.meshes[0].extras["targetNames"])) == 16 and n_targets <= 16
    assert g.animations[0].channels[0].target.path == "weights"
    assert g.accessors[g.animations[0].samplers[0].input].max == [pytest.approx(0.25)]
    tl = tmp_path / "t.json"
    tl.write_text(json.dumps({"format": "mimica-timeline/1", "channels": {"buccinator_R": {"keys": [[0, 1]]}}}))
    assert main(["simulate", str(rig_path), "--timeline", str(tl), "--out", str(tmp_path / "s2")]) == 2
    assert "not a muscle" in capsys.readouterr().err and not (tmp_path / "s2").exists()
    for extra in (["--solver", "full", "--gravity", "1"], ["--solver", "full", "--engine", "sprung"]):
        assert main(["simulate", str(rig_path), "--out", str(tmp_path / "s3")] + extra) == 2
        assert "full solver" in capsys.readouterr().err and not (tmp_path / "s3").exists()
    assert main(["simulate", str(rig_path), "--solver", "full", "--duration", "0.05", "--fps", "40",
                 "--out", str(tmp_path / "s4")]) == 0
    assert len(list((tmp_path / "s4").glob("frame_*.obj"))) == 3
    assert main(["simulate", str(rig_path), "--springs", "kim", "--expression", "happiness", "--duration", "0.1",
                 "--out", str(tmp_path / "s5")]) == 0
    assert len(list((tmp_path / "s5").glob("frame_*.obj"))) == 7
    assert main(["simulate", str(rig_path), "--springs", "kim", "--solver", "full", "--out", str(tmp_path / "s6")]) == 2
    assert "springs" in capsys.readouterr().err and not (tmp_path / "s6").exists()
    assert main(["rig", str(obj), "--muscles", "zygomaticus_major_R", "--stretch", "shell",
                 "--out", str(tmp_path / "shell.rig")]) == 0
    shell = Rig.load(tmp_path / "shell.rig")
    assert shell.params["stretch"] == "shell"
    assert not np.allclose(shell.muscles[0].stretch, Rig.load(rig_path).muscles[0].stretch)


def test_cli_pull_keyed_on_a_curve(tmp_path, rig, face, capsys):
    rp = rig.save(tmp_path / "f.rig")
    nose = face.neutral[ICT_LANDMARKS_68[30]]
    tl = tmp_path / "t.json"
    tl.write_text(json.dumps({"format": "mimica-timeline/1", "duration": 0.5,
                              "channels": {"pull": {"interp": "linear", "keys": [[0, 0], [0.2, 1]]}}}))
    spec = f"{nose[0]},{nose[1]},{nose[2]}:1.0:0,0,5"
    out = tmp_path / "o"
    assert main(["simulate", str(rp), "--timeline", str(tl), "--pull", spec, "--out", str(out)]) == 0
    from mimica import read_mesh
    last = read_mesh(sorted(out.glob("frame_*.obj"))[-1]).vertices
    assert (last - face.neutral)[np.linalg.norm(face.neutral - nose, axis=1) < 0.5, 2].mean() > 0
    assert main(["simulate", str(rp), "--pull", "1,2:3", "--out", str(tmp_path / "bad")]) == 2
    assert "--pull" in capsys.readouterr().err


def test_cli_wrinkle_mask_simulate_and_age(tmp_path, capsys):
    from mimica import write_mesh
    face = ICTModel(ICT_FACE_AREA_VERTICES)
    obj = write_mesh(tmp_path / "face.obj", face.mesh)
    mask = tmp_path / "face.wrinkles"
    assert main(["wrinkle-mask", str(obj), "--out", str(mask), "--show", str(tmp_path / "m.png")]) == 0
    assert len(WrinkleMask.load(mask)) == len(reference_mask()) and (tmp_path / "m.png").is_file()
    rig = tmp_path / "face.rig"
    assert main(["rig", str(obj), "--muscles", "frontalis_R,frontalis_L", "--modes", "4", "--out", str(rig)]) == 0
    out = tmp_path / "sim"
    assert main(["simulate", str(rig), "--expression", "surprise", "--duration", "0.3", "--wrinkles", str(mask),
                 "--age", "70", "--maps", "128", "--out", str(out)]) == 0
    said = capsys.readouterr().err
    assert "wrinkles: 21" in said and "forehead" in said
    assert len(list(out.glob("frame_*.obj"))) == 19 and list(out.glob("wrinkles_frame_*_normal.png"))
    assert main(["simulate", str(rig), "--expression", "surprise", "--duration", "0.1", "--wrinkles", str(mask),
                 "--maps", "64", "--maps-set", "engine", "--out", str(tmp_path / "eng")]) == 0
    assert "engine maps of 15 regions" in capsys.readouterr().err
    assert (tmp_path / "eng" / "wrinkle_maps" / "weights.csv").is_file()
    assert len(list((tmp_path / "eng" / "wrinkle_maps").glob("*_normal.png"))) == 15
    sheet = tmp_path / "age.png"
    assert main(["age", str(obj), "--rig", str(rig), "--ages", "30,80", "--expression", "surprise",
                 "--size", "96", "--out", str(sheet)]) == 0 and sheet.is_file()
    # a mask of another face, a broken mask, bad ages: one line, exit 2, nothing written
    other = reference_mask()
    for w in other.wrinkles:
        w.points = w.points + 5.0
    other.save(tmp_path / "other.wrinkles")
    (tmp_path / "bad.wrinkles").write_text('{"format": "mimica-wrinkles/1"}')
    for args, word in ((["--wrinkles", str(tmp_path / "other.wrinkles")], "does not lie on"),
                       (["--wrinkles", str(tmp_path / "bad.wrinkles")], "anchors")):
        assert main(["simulate", str(rig), "--duration", "0.1", *args, "--out", str(tmp_path / "x")]) == 2
        assert word in capsys.readouterr().err and not (tmp_path / "x").exists()
    assert main(["age", str(obj), "--rig", str(rig), "--ages", "young", "--out", str(tmp_path / "y.png")]) == 2
    assert "--ages" in capsys.readouterr().err and not (tmp_path / "y.png").exists()


def test_fit_muscles_writes_a_timeline_simulate_plays(rig, face, tmp_path, capsys):
    """`fit-muscles RIG --target` on a shape the rig makes: the timeline holds the activations
    and `simulate --timeline` plays it into that shape."""
    from mimica.anim import Timeline
    from mimica.mesh import write_mesh
    rig.save(tmp_path / "face.rig")
    fit = MuscleFit.of_rig(rig)
    a = np.array([0.8, 0.2, 0.5])
    target = rig.skin.vertices + fit.displacement(a)
    write_mesh(tmp_path / "target.obj", rig.skin.with_vertices(target))
    out = tmp_path / "act.json"
    assert main(["fit-muscles", str(tmp_path / "face.rig"), "--target", str(tmp_path / "target.obj"),
                 "--out", str(out)]) == 0
    said = capsys.readouterr().err
    assert "3 muscles fitted to 1 target" in said and "0% misfit" in said, said
    tl = Timeline.load(out)
    np.testing.assert_allclose(tl.values(0.5, MUSCLES), a, atol=1e-4)
    assert main(["simulate", str(tmp_path / "face.rig"), "--timeline", str(out), "--duration", "0.8",
                 "--out", str(tmp_path / "sim")]) == 0
    from mimica.mesh import read_vertices
    last = read_vertices(sorted((tmp_path / "sim").glob("frame_*.obj"))[-1]) - rig.skin.vertices
    want = target - rig.skin.vertices
    cos = (last * want).sum() / np.linalg.norm(last) / np.linalg.norm(want)
    assert cos > 0.99 and 0.8 < np.linalg.norm(last) / np.linalg.norm(want) < 1.1


def test_fit_muscles_refuses_what_it_cannot_fit(rig, face, tmp_path, capsys):
    from mimica.mesh import write_mesh
    rig.save(tmp_path / "face.rig")
    write_mesh(tmp_path / "other.obj", face.mesh)
    bad = tmp_path / "few.obj"
    bad.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    cases = [(["--out", str(tmp_path / "a.json")], "give --target"),
             (["--target", str(bad), "--out", str(tmp_path / "a.json")], "3 vertices; the rig's skin has"),
             (["--target", str(tmp_path / "other.obj"), "--out", str(tmp_path / "a.txt")], "timeline .json")]
    for args, said in cases:
        capsys.readouterr()
        assert main(["fit-muscles", str(tmp_path / "face.rig"), *args]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and said in err[0], err
        assert not (tmp_path / "a.json").exists() and not (tmp_path / "a.txt").exists()
