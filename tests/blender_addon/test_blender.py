"""The Blender add-on (mimica/blender_addon.py).

Blender's Python needs numpy < 2 and mimica numpy >= 2, so the add-on runs the mimica command
and reads its .npz; its own parts are tested here without Blender, and its four operators inside
Blender, headless: the bpy package in a venv of its own (.venv-blender, which `make test` makes
under CI; elsewhere the test is skipped unless MIMICA_BLENDER_PYTHON names a Python with bpy)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mimica import blender_addon as addon
from mimica.cli import main
from mimica.export import ARKIT_52
from mimica.export.take import read_take
from helpers import BLENDERS, blender_python, live_link_csv

HEAD = Path(os.environ["MIMICA_DATA"]) / "real-heads" / "mediapipe-canonical" / "head.obj"


def test_the_addon_reads_takes_as_mimica_does(tmp_path):
    assert addon.ARKIT == ARKIT_52                     # the facts shared with mimica (mimica.facts)
    from mimica.anim import PRESETS
    assert list(addon.EXPRESSIONS) == [e for e in PRESETS if e != "neutral"]    # and simulate's presets
    w = np.random.default_rng(1).uniform(0, 1, (30, 52))
    live_link_csv(tmp_path / "take.csv", w)
    t0, w0, _ = read_take(tmp_path / "take.csv")
    t1, w1 = addon.read_take(tmp_path / "take.csv")
    np.testing.assert_allclose(t1, t0, atol=1e-12)
    for n in ARKIT_52:
        np.testing.assert_allclose(w1[n], w0[n])
    lines = (tmp_path / "take.csv").read_text().splitlines()
    (tmp_path / "back.csv").write_text("\n".join([lines[0]] + lines[1:][::-1]))
    with pytest.raises(addon.AddonError, match="does not increase"):
        addon.read_take(tmp_path / "back.csv")


def test_blendshapes_as_arrays_in_the_heads_order(tmp_path):
    from mimica.mesh import read_mesh
    head = read_mesh(HEAD)
    assert main(["blendshapes", str(HEAD), "--cut-mouth", "off", "--out", str(tmp_path / "s.npz")]) == 0
    with np.load(tmp_path / "s.npz") as z:
        np.testing.assert_allclose(z["vertices"], head.vertices)
        assert all(z[n].shape == head.vertices.shape for n in ARKIT_52)
        assert np.abs(z["jawOpen"] - head.vertices).max() > 0.5


def test_the_cut_comes_with_the_arrays(tmp_path):
    """The sealed head's mouth cut as the add-on applies it: copies of the listed vertices after
    the head's own, the listed polygon corners moved onto them, give the faces mimica solved on."""
    from mimica.mesh import read_mesh
    head = read_mesh(HEAD)
    assert main(["blendshapes", str(HEAD), "--out", str(tmp_path / "s.npz")]) == 0
    with np.load(tmp_path / "s.npz") as z:
        k = len(z["cut_copies"])
        assert k > 0 and z["vertices"].shape[0] == head.n_vertices + k
        np.testing.assert_allclose(z["vertices"][:head.n_vertices], head.vertices)
        np.testing.assert_allclose(z["vertices"][head.n_vertices:], head.vertices[z["cut_copies"]])
        fi = head.face_indices.copy()
        for f, c, a in z["cut_corners"]:
            fi[head.face_starts[f] + c] = head.n_vertices + a
        jaw, copies = z["jawOpen"], z["cut_copies"]
    # the corners moved are the lower lip's: they open away from the upper lip's copies
    lower = np.unique(fi[fi >= head.n_vertices])
    upper = copies[lower - head.n_vertices]
    assert np.linalg.norm(jaw[lower] - jaw[upper], axis=1).mean() > 0.05 * np.ptp(head.vertices[:, 1])




@pytest.mark.parametrize("version", list(BLENDERS))
def test_the_addon_inside_blender(tmp_path, full_model, head_glb, version):
    """Headless Blender (bpy 4.5 and 5.0): ARKit shape keys on an imported head (z up, as Blender has
    it: the jaw opens down Blender's z), a Live Link take keyed onto them (values at sampled
    frames equal the CSV's; keys named as other tools name them too), shape keys moved onto
    another mesh, muscle-simulated shape keys, and an error as a Blender report.  And mimica's
    GLBs imported as a user imports them: ICT's whole mesh smooth, with its uv and 12 materials,
    in metres, whole through FBX and back; quantized morph targets as shape keys; an animated
    take with its head's armature, the shape keys' values at sampled frames the take's."""
    from mimica.mesh import write_glb, write_mesh
    from mimica.mesh.io import SPARSE_TOLERANCE
    exe = blender_python(version)
    cmd = tmp_path / "mimica"                       # the add-on runs this mimica command
    cmd.write_text(f"#!/bin/sh\nexec {sys.executable} -m mimica.cli \"$@\"\n")
    cmd.chmod(0o755)
    frames = 90                                     # over a second: the rate is read from the timecode
    w = np.zeros((frames, 52))
    w[:, ARKIT_52.index("jawOpen")] = 0.5 - 0.5 * np.cos(np.arange(frames) / 9)
    w[:, ARKIT_52.index("eyeBlinkLeft")] = np.linspace(1, 0, frames)
    live_link_csv(tmp_path / "take.csv", w)
    times, written, _ = read_take(tmp_path / "take.csv")       # the CSV keeps 6 decimals
    out = tmp_path / "report.json"
    m = full_model.mesh
    write_mesh(tmp_path / "full.glb", m)
    write_glb(tmp_path / "quantized.glb", m, {"jawOpen": full_model.shape("jawOpen")}, sparse=SPARSE_TOLERANCE,
              quantize=True)
    assert main(["animate", str(head_glb), "--arkit", str(tmp_path / "take.csv"), "--head-rotation",
                 "--out", str(tmp_path / "take.glb")]) == 0
    from mimica.pipeline import write_blender_addon
    addon_zip = write_blender_addon(tmp_path / "addon")            # what `mimica blender-addon` writes
    # Blender installs it under HOME (its user scripts): a home of the test's own
    env = {**os.environ, "MIMICA_COMMAND": str(cmd), "HOME": str(tmp_path / "home")}
    run = subprocess.run([exe, str(Path(__file__).with_name("blender_driver.py")), str(addon_zip), str(HEAD),
                          str(tmp_path / "take.csv"), str(out), str(tmp_path / "full.glb"),
                          str(tmp_path / "quantized.glb"), str(tmp_path / "take.glb")], env=env,
                         stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=900)
    assert run.returncode == 0 and out.is_file(), run.stderr[-3000:] + run.stdout[-2000:]
    r = json.loads(out.read_text())
    assert r["arkit"] == ["FINISHED"] and r["arkit_keys"] == 53
    assert r["vertices_after"] > r["vertices"]          # its sealed lips cut apart, as mimica cut them
    assert r["height_z"] == pytest.approx(17.665, abs=0.01)       # the head stands in Blender's z
    assert r["jaw_moves_down"] < -0.5 and r["jaw_largest"] < 0.5 * r["height_z"]
    assert r["take"] == ["FINISHED"] and r["fps"] == 24
    for f, got in r["take_samples"].items():        # keyed at the take's times, linear between them
        t = (int(f) - 1) / 24
        for n in ("jawOpen", "eyeBlinkLeft"):
            assert got[n] == pytest.approx(np.interp(t, times, written[n]), abs=1e-4), (f, n)
    for f, got in r["named_take_samples"].items():  # keys another tool named (blendShape1.JawOpen, eyeBlink_L)
        t = (int(f) - 1) / 24
        for n, a in (("blendShape1.JawOpen", "jawOpen"), ("eyeBlink_L", "eyeBlinkLeft")):
            assert got[n] == pytest.approx(np.interp(t, times, written[a]), abs=1e-4), (f, n)
    assert r["transfer"] == ["FINISHED"] and r["transfer_keys"] == ["Basis", "jawOpen", "mouthSmileLeft"]
    assert 0.95 < r["transfer_ratio"] < 1.25 and r["transfer_jaw_down"] < -0.5
    assert r["muscles"] == ["FINISHED"] and r["muscle_largest"] > 0.05
    assert "no shape keys" in r.get("cube_take_error", ""), r
    full, quant, take = (r["glb"][n] for n in ("full.glb", "quantized.glb", "take.glb"))
    assert full["smooth"] and full["uv_layers"] == 1 and full["materials"] == 12 and full["vertices"] == 28911
    assert full["height"] == pytest.approx(0.01 * np.ptp(m.vertices[:, 1]), rel=1e-4)      # metres
    assert full["fbx_vertices"] == full["vertices"]             # FBX round trip keeps the vertices whole
    import pygltflib as gl
    g = gl.GLTF2().load(str(tmp_path / "report_roundtrip.glb"))  # glTF -> FBX -> glTF: the same vertices
    positions = {p.attributes.POSITION for mesh in g.meshes for p in mesh.primitives}
    assert sum(g.accessors[i].count for i in positions) == full["vertices"]
    jaw = 0.01 * np.abs(full_model.shape("jawOpen") - m.vertices).max()
    assert quant["shape_keys"] == 2 and quant["first_key_largest"] == pytest.approx(jaw, abs=2e-5)
    assert take["armature"] and take["shape_keys"] == 53
    for f, got in take["animated"].items():          # keyed at t x 24 from frame 0 in Blender's 24 fps
        for n, value in got.items():
            assert value == pytest.approx(np.interp(int(f) / 24, times, written[n]), abs=1e-4), (f, n)
