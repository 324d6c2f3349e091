"""ARKit takes on a head: a Live Link Face CSV drives the 52 morph targets of
a head's blendshapes GLB at the take's frame rate; bad takes give one line and write nothing."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mimica.cli import main
from mimica.export import ARKIT_52
from helpers import live_link_csv, validate

def test_live_link_take_plays_on_the_head(head_glb, tmp_path, capsys):
    import pygltflib as gl
    from mimica.mesh.io.gltf import read_accessor
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
    times = read_accessor(g, s.input)
    # Live Link's timecode: frame f at f / 60 s, its sub-frame fraction (.fff) carried along
    sub = ((37 * np.arange(frames)) % 1000) / 1000.0
    np.testing.assert_allclose(times, (np.arange(frames) + sub - sub[0]) / 60.0, atol=1e-6)
    got = read_accessor(g, s.output).reshape(frames, len(names))
    for j, n in enumerate(names):
        np.testing.assert_allclose(got[:, j], w[:, ARKIT_52.index(n)], atol=1e-6)

    r = validate([tmp_path / "t.glb"])[0]
    assert r["errors"] == 0 and r["warnings"] == 0, r["messages"]


def _played(head, tmp_path, capsys) -> str:
    """A random 20-frame take played on `head` into tmp_path/t.glb, which the validator passes;
    what the command said."""
    live_link_csv(tmp_path / "take.csv", np.clip(np.random.default_rng(1).normal(0.3, 0.2, (20, 52)), 0, 1))
    capsys.readouterr()
    assert main(["animate", str(head), "--arkit", str(tmp_path / "take.csv"), "-o", str(tmp_path / "t.glb")]) == 0
    said = capsys.readouterr().err
    assert "drive 52 morph targets" in said, said
    r = validate([tmp_path / "t.glb"])[0]
    assert r["errors"] == 0 and r["warnings"] == 0, r["messages"]
    return said


def test_a_take_plays_on_a_draco_compressed_head(head_glb, tmp_path, capsys):
    """A head Blender wrote with Draco compression (its 52 shape keys uncompressed, the vertex order
    kept): the take drives its 52 morph targets, each moving the head as in Blender's export of
    the same head without compression; the file comes back uncompressed, said in a line, and
    valid."""
    from helpers import blender_files
    from mimica.mesh.io import read_morph_targets
    blender_files("export-draco", head_glb, tmp_path / "draco.glb")
    said = _played(tmp_path / "draco.glb", tmp_path, capsys)
    assert "draco.glb: its 1 Draco-compressed primitive written back uncompressed" in said, said
    blender_files("export", head_glb, tmp_path / "plain.glb")       # the same head, uncompressed
    mesh, targets, _ = read_morph_targets(tmp_path / "plain.glb")
    back, back_targets, _ = read_morph_targets(tmp_path / "t.glb")
    size = float(np.ptp(mesh.vertices, axis=0).max())
    assert np.abs(back.vertices - mesh.vertices).max() < 2 * size / (2 ** 14 - 1)     # Draco's 14-bit grid
    for n, t in targets.items():
        np.testing.assert_allclose(back_targets[n] - back.vertices, t - mesh.vertices, atol=1e-6 * size)


def test_a_take_plays_on_a_meshopt_compressed_head(head_glb, tmp_path, capsys):
    """gltfpack's meshopt-compressed GLB of the head (quantized, KHR_mesh_quantization): the take
    drives its 52 morph targets, each as in gltfpack's uncompressed output; the file comes back
    uncompressed (still quantized), said in a line, and valid."""
    from helpers import gltfpack
    from mimica.mesh.io import read_morph_targets
    gltfpack("-i", head_glb, "-o", tmp_path / "packed.glb", "-cc")
    gltfpack("-i", head_glb, "-o", tmp_path / "plain.glb")
    said = _played(tmp_path / "packed.glb", tmp_path, capsys)
    assert "packed.glb: its 5 meshopt-compressed buffer views written back uncompressed" in said, said
    back, back_targets, _ = read_morph_targets(tmp_path / "t.glb")
    mesh, targets, _ = read_morph_targets(tmp_path / "plain.glb")

    def rows(m, t):                              # each vertex with its moves, in one order (the files' differ)
        r = np.hstack([m.vertices] + [t[n] for n in sorted(t)])
        return r[np.lexsort(r.T[::-1])]
    np.testing.assert_array_equal(rows(back, back_targets), rows(mesh, targets))
    # a turning take through gltfpack: its rotations meshopt's quaternion filter, decoded as the
    # uncompressed output has them (to the filter's precision), unit quaternions
    from mimica.mesh.io.gltf import _load, read_accessor
    _turning_take(tmp_path / "turn.csv")
    assert main(["animate", str(head_glb), "--arkit", str(tmp_path / "turn.csv"), "--head-rotation",
                 "-o", str(tmp_path / "turn.glb")]) == 0
    gltfpack("-i", tmp_path / "turn.glb", "-o", tmp_path / "turn_cc.glb", "-cc")
    gltfpack("-i", tmp_path / "turn.glb", "-o", tmp_path / "turn_plain.glb")

    def rotations(path):
        g = _load(path)
        return [read_accessor(g, a.samplers[c.sampler].output) for a in g.animations for c in a.channels
                if c.target.path == "rotation"]
    [q_cc], [q_plain] = rotations(tmp_path / "turn_cc.glb"), rotations(tmp_path / "turn_plain.glb")
    assert q_cc.shape == q_plain.shape and np.abs(q_cc - q_plain).max() < 5e-4
    assert np.abs(np.linalg.norm(q_cc, axis=1) - 1).max() < 1e-3


def test_a_weights_csv_with_a_time_column(head_glb, tmp_path):
    import pygltflib as gl
    from mimica.mesh.io.gltf import read_accessor
    lines = [",".join(["time"] + ARKIT_52)] + [",".join([f"{t / 30:.5f}"] + ["0.5" if n == "jawOpen" else "0"
                                                                             for n in ARKIT_52]) for t in range(10)]
    (tmp_path / "w.csv").write_text("\n".join(lines))
    assert main(["animate", str(head_glb), "--arkit", str(tmp_path / "w.csv"), "--out", str(tmp_path / "w.glb")]) == 0
    g = gl.GLTF2().load(str(tmp_path / "w.glb"))
    got = read_accessor(g, g.animations[0].samplers[0].output).reshape(10, -1)
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


def _turning_take(path, frames=40):
    """A Live Link take whose head turns: yaw up to 0.5 rad, pitch 0.3, roll 0.2."""
    live_link_csv(path, np.full((frames, 52), 0.1))
    lines = Path(path).read_text().splitlines()
    col = lines[0].split(",").index("HeadYaw")
    out = [lines[0]]
    for f, ln in enumerate(lines[1:]):
        c = ln.split(",")
        c[col:col + 3] = [f"{0.5 * np.sin(f / 7):.6f}", f"{0.3 * np.sin(f / 5):.6f}", f"{0.2 * np.cos(f / 9):.6f}"]
        out.append(",".join(c))
    Path(path).write_text("\n".join(out) + "\n")
    f = np.arange(frames)
    return 0.5 * np.sin(f / 7), 0.3 * np.sin(f / 5), 0.2 * np.cos(f / 9)


def _skinned(g, frame):
    """The file's base positions skinned as a glTF viewer does (joint world matrix x inverse bind,
    blended by WEIGHTS_0) with the head joint's rotation at keyframe `frame`; morphs left out."""
    from scipy.spatial.transform import Rotation
    from mimica.mesh.io.gltf import read_accessor
    prim = g.meshes[0].primitives[0]
    pos = read_accessor(g, prim.attributes.POSITION).astype(float)
    joints = read_accessor(g, prim.attributes.JOINTS_0).astype(int)
    wts = read_accessor(g, prim.attributes.WEIGHTS_0)
    skin = g.skins[0]
    neck, head = (g.nodes[j] for j in skin.joints)
    ibm = read_accessor(g, skin.inverseBindMatrices).reshape(-1, 4, 4).transpose(0, 2, 1)   # column-major
    rot = g.animations[0].channels[1]
    q = read_accessor(g, g.animations[0].samplers[rot.sampler].output)[frame]
    t = np.eye(4)
    t[:3, 3] = neck.translation
    r = np.eye(4)
    r[:3, :3] = Rotation.from_quat(q).as_matrix()
    world = [t, t @ r]
    mats = np.stack([world[j] @ ibm[j] for j in range(2)])
    ph = np.c_[pos, np.ones(len(pos))]
    out = sum(wts[:, k, None] * np.einsum("nij,nj->ni", mats[joints[:, k]], ph) for k in range(4))
    return pos, out[:, :3], wts, q


@pytest.fixture(scope="module")
def ict_head_glb(tmp_path_factory, head_model):
    """ICT's head with its neck and shoulders' start, as `blendshapes` writes it."""
    from mimica.mesh import write_mesh
    d = tmp_path_factory.mktemp("neck")
    write_mesh(d / "ict.obj", head_model.mesh)
    assert main(["blendshapes", str(d / "ict.obj"), "--out", str(d / "ict_arkit.glb"), "--quantize"]) == 0
    return d / "ict_arkit.glb"


def test_head_rotation_turns_the_head_and_bends_the_neck(ict_head_glb, tmp_path, capsys):
    """--head-rotation: a skin of two joints at the stored pivot; its rotation keys are the take's
    yaw, pitch, roll; at rest the skin leaves every vertex where it was; turned, the head above
    the chin moves rigidly about the pivot, the lowest vertices stay, the neck between bends."""
    import pygltflib as gl
    from scipy.spatial.transform import Rotation
    from mimica.export.take import HEAD_KEY, head_quaternions
    yaw, pitch, roll = _turning_take(tmp_path / "take.csv")
    capsys.readouterr()
    out = tmp_path / "turn.glb"
    assert main(["animate", str(ict_head_glb), "--arkit", str(tmp_path / "take.csv"), "--out", str(out),
                 "--head-rotation"]) == 0
    said = capsys.readouterr().err
    assert "the head turns (up to yaw 29, pitch 17, roll 11 degrees)" in said and "bending with the neck" in said, said
    g = gl.GLTF2().load(str(out))
    stored = g.meshes[0].extras[HEAD_KEY]
    assert g.nodes[g.skins[0].joints[0]].translation == pytest.approx(stored["pivot"])
    from mimica.mesh.io.gltf import read_accessor
    keys = read_accessor(g, g.animations[0].samplers[1].output)
    want = head_quaternions(yaw, pitch, roll)
    assert np.allclose(np.abs((keys * want).sum(1)), 1, atol=1e-6)             # the same rotations
    assert (np.sum(keys[1:] * keys[:-1], 1) > 0).all()                          # slerp takes the short way
    pos, moved, wts, q = _skinned(g, int(np.argmax(np.abs(yaw))))
    assert np.allclose(wts.sum(1), 1, atol=1e-6)
    R = Rotation.from_quat(q).as_matrix()
    p = np.asarray(stored["pivot"])
    chin_y = stored["chin"][1]
    head = pos[:, 1] >= chin_y
    assert np.allclose(moved[head], (pos[head] - p) @ R.T + p, atol=1e-6)      # rigid about the pivot
    low = wts[:, 0] == 0
    assert low.any() and np.allclose(moved[low], pos[low], atol=1e-9)           # the shoulders stay
    bend = (wts[:, 0] > 0) & (wts[:, 0] < 1)
    assert bend.sum() > 100 and (pos[bend, 1] < chin_y).all()
    r = validate([out])[0]
    assert r["errors"] == 0 and r["warnings"] == 0, r["messages"]


def test_head_rotation_at_rest_moves_nothing(ict_head_glb, tmp_path):
    """Angles of zero: the skinned head is exactly the head."""
    import pygltflib as gl
    live_link_csv(tmp_path / "still.csv", np.zeros((3, 52)))
    text = (tmp_path / "still.csv").read_text().replace(",0.01", ",0.0")
    (tmp_path / "still.csv").write_text(text)
    out = tmp_path / "still.glb"
    assert main(["animate", str(ict_head_glb), "--arkit", str(tmp_path / "still.csv"), "--out", str(out),
                 "--head-rotation"]) == 0
    pos, moved, _, _ = _skinned(gl.GLTF2().load(str(out)), 1)
    assert np.abs(moved - pos).max() < 1e-7


def test_head_rotation_needs_its_columns_and_a_pivot(head_glb, ict_head_glb, tmp_path, capsys):
    """No head columns, an old GLB without a pivot, a bad --pivot: one line each, nothing written;
    a face without a neck (the 468-vertex head) turns whole; without the flag the head stays."""
    import pygltflib as gl
    lines = [",".join(["time"] + ARKIT_52)] + [",".join([f"{t / 30:.4f}"] + ["0"] * 52) for t in range(4)]
    (tmp_path / "w.csv").write_text("\n".join(lines))
    _turning_take(tmp_path / "take.csv", 6)
    old = tmp_path / "old.glb"
    g = gl.GLTF2().load(str(ict_head_glb))
    g.meshes[0].extras.pop("mimica_head")
    g.save_binary(str(old))
    for args, said in [(["--arkit", str(tmp_path / "w.csv"), "--head-rotation"], "no HeadYaw, HeadPitch and HeadRoll"),
                       (["--arkit", str(tmp_path / "take.csv"), "--head-rotation"], "no head pivot stored"),
                       (["--arkit", str(tmp_path / "take.csv"), "--head-rotation", "--pivot", "0,1"], "--pivot '0,1'")]:
        out = tmp_path / "bad.glb"
        capsys.readouterr()
        assert main(["animate", str(old if "pivot stored" in said else ict_head_glb), *args, "--out", str(out)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and said in err[0], err
        assert not out.exists()
    assert main(["animate", str(old), "--arkit", str(tmp_path / "take.csv"), "--head-rotation",
                 "--pivot", "0,0.02,0", "--out", str(tmp_path / "p.glb")]) == 0
    assert "about (0.000, 0.020, 0.000) m, whole" in capsys.readouterr().err
    assert main(["animate", str(head_glb), "--arkit", str(tmp_path / "take.csv"), "--head-rotation",
                 "--out", str(tmp_path / "face.glb")]) == 0
    said = capsys.readouterr().err
    assert "whole" in said, said
    assert main(["animate", str(head_glb), "--arkit", str(tmp_path / "take.csv"), "--out", str(tmp_path / "s.glb")]) == 0
    assert "the head stays still" in capsys.readouterr().err
    assert gl.GLTF2().load(str(tmp_path / "s.glb")).skins == []


def test_a_json_take_and_a_usd_take(head_glb, tmp_path):
    """A JSON take (columns, or one object a frame) plays as its CSV does; --out take.usda writes
    the head's blend shapes and a SkelAnimation whose weights are the take's, resampled on its
    rate; head rotation there is refused in one line."""
    import json
    from mimica.export.take import read_take
    from mimica.mesh.io import read_morph_targets
    rng = np.random.default_rng(5)
    t = np.arange(12) / 30
    w = rng.uniform(0, 1, (12, 52))
    cols = {"time": t.tolist(), **{n: w[:, j].tolist() for j, n in enumerate(ARKIT_52)}}
    (tmp_path / "cols.json").write_text(json.dumps(cols))
    (tmp_path / "rows.json").write_text(json.dumps([{"time": float(t[i]), **{n: float(w[i, j])
                                                     for j, n in enumerate(ARKIT_52)}} for i in range(12)]))
    for name in ("cols.json", "rows.json"):
        times, weights, rate = read_take(tmp_path / name)
        assert rate == pytest.approx(30) and np.allclose(times, t)
        assert np.allclose(weights["jawOpen"], w[:, ARKIT_52.index("jawOpen")])
    out = tmp_path / "take.usda"
    assert main(["animate", str(head_glb), "--arkit", str(tmp_path / "cols.json"), "--out", str(out)]) == 0
    from pxr import Usd, UsdSkel
    stage = Usd.Stage.Open(str(out))
    anim = UsdSkel.Animation(stage.GetPrimAtPath("/Head/Skel/Anim"))
    names = list(anim.GetBlendShapesAttr().Get())
    assert len(names) == 52 and stage.GetTimeCodesPerSecond() == pytest.approx(30)
    got = np.array(anim.GetBlendShapeWeightsAttr().Get(5))
    np.testing.assert_allclose(got[names.index("jawOpen")], w[5, ARKIT_52.index("jawOpen")], atol=1e-6)
    mesh, targets, unit = read_morph_targets(head_glb)
    assert unit == "cm" and len(targets) == 52 and np.abs(targets["jawOpen"] - mesh.vertices).max() > 0.5
    assert main(["animate", str(head_glb), "--arkit", str(tmp_path / "cols.json"), "--head-rotation",
                 "--out", str(tmp_path / "r.usd")]) == 2
    assert not (tmp_path / "r.usd").exists()
    (tmp_path / "bad.json").write_text(json.dumps({"time": [0, 1], "jawOpen": [0.5]}))
    with pytest.raises(Exception, match="not one value per time"):
        read_take(tmp_path / "bad.json")


def test_a_take_on_an_fbx_head_is_keyed_into_its_fbx(head_glb, tmp_path, capsys):
    """An FBX head with ARKit shape keys (the head's GLB through Blender's FBX exporter):
    `animate --arkit take.csv --out take.fbx` writes the head's FBX with the take keyed on its
    shape keys; imported into Blender, every key's value at every frame is the take's (its start
    at frame 1, where Blender's importer puts the file's time 0), the object and its 52 keys as
    they were; a .glb from an FBX head, and an FBX from a glTF head, are refused in one line."""
    import json
    from helpers import blender_files
    from mimica.export.take import read_take
    blender_files("export", head_glb, tmp_path / "head.fbx")
    frames = 40
    w = np.zeros((frames, 52))
    w[:, ARKIT_52.index("jawOpen")] = np.linspace(0, 1, frames)
    w[:, ARKIT_52.index("eyeBlinkLeft")] = 0.5 - 0.5 * np.cos(np.arange(frames) / 5)
    live_link_csv(tmp_path / "take.csv", w)
    times, written, rate = read_take(tmp_path / "take.csv")
    capsys.readouterr()
    assert main(["animate", str(tmp_path / "head.fbx"), "--arkit", str(tmp_path / "take.csv"),
                 "--out", str(tmp_path / "take.fbx")]) == 0
    assert "drive 52 morph targets" in capsys.readouterr().err
    blender_files("import", tmp_path / "head.fbx", tmp_path / "before.json")
    blender_files("import", tmp_path / "take.fbx", tmp_path / "after.json")
    before, after = (json.loads((tmp_path / f"{n}.json").read_text()) for n in ("before", "after"))
    assert [(o["name"], o["vertices"], sorted(o["shape_keys"])) for o in after["objects"]] == \
        [(o["name"], o["vertices"], sorted(o["shape_keys"])) for o in before["objects"]]
    (name, values), = after["key_values"].items()
    assert len(values) == 52
    for n in ARKIT_52:
        got = np.array(values[n][:frames])                  # frames 1 .. 40: the take's times
        np.testing.assert_allclose(got, np.interp((np.arange(frames)) / rate, times, written[n]), atol=1e-4,
                                   err_msg=n)
    for head, out, said in ((tmp_path / "head.fbx", "t.glb", "written as .fbx"), (head_glb, "t.fbx", "written as .glb")):
        capsys.readouterr()
        assert main(["animate", str(head), "--arkit", str(tmp_path / "take.csv"), "--out", str(tmp_path / out)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and said in err[0] and not (tmp_path / out).exists(), err
