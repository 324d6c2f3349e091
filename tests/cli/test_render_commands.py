"""`mimica render` and `mimica export` from the command line: the views, heat map and turntable
it draws, the glTF clip it writes, folders of frames read in natural order, and one line, exit 2
and nothing written for what they refuse."""

from __future__ import annotations

import numpy as np

from helpers import run_mimica


def test_render_views_heatmap_and_turntable(tmp_path, head_model):
    from PIL import Image
    from mimica.mesh import write_mesh
    face = tmp_path / "face.obj"
    write_mesh(face, head_model.mesh)
    r = run_mimica("render", face, "--out", tmp_path / "views.png", "--size", 200)
    assert r.returncode == 0, r.stderr
    im = np.asarray(Image.open(tmp_path / "views.png"))
    assert im.shape[1] >= 3 * 200                                   # front, three-quarter, profile
    vals = tmp_path / "err.txt"
    np.savetxt(vals, np.linspace(0, 2.5, head_model.mesh.n_vertices))
    r = run_mimica("render", face, "--view", "front", "--heatmap", vals, "--out", tmp_path / "heat.png", "--size", 200)
    assert r.returncode == 0, r.stderr
    heat = np.asarray(Image.open(tmp_path / "heat.png")).astype(int)
    assert heat.shape[0] > 200                                      # picture plus the legend under it
    assert (np.abs(heat[:200, :, 0] - heat[:200, :, 2]) > 60).any()  # coloured, not grey
    r = run_mimica("render", face, "--turntable", "--frames", 6, "--size", 96, "--out", tmp_path / "turn.mp4")
    assert r.returncode == 0, r.stderr
    from mimica.image.video import frame_source
    assert len(list(frame_source(tmp_path / "turn.mp4")[2])) == 6
    bad = tmp_path / "bad.txt"
    bad.write_text("1\n2\n")
    out = tmp_path / "never.png"
    r = run_mimica("render", face, "--heatmap", bad, "--out", out)
    assert r.returncode == 2 and "2 values" in r.stderr and not out.exists()


def test_export_sequence_as_gltf_animation(tmp_path, head_model):
    import pygltflib
    from mimica.mesh import read_mesh, write_mesh
    seq = tmp_path / "seq"
    names = ["jawOpen", "mouthSmile_L", "browDown_R"]
    for i, n in enumerate(names):
        write_mesh(seq / f"f{i:02d}.obj", head_model.mesh.with_vertices(head_model.shape(n)))
    out = tmp_path / "anim.glb"
    r = run_mimica("export", seq, "--rest", _write_rest(tmp_path, head_model), "--fps", 24, "--out", out)
    assert r.returncode == 0, r.stderr
    g = pygltflib.GLTF2().load(str(out))
    prim = g.meshes[0].primitives[0]
    assert g.meshes[0].extras["targetNames"] == ["f00", "f01", "f02"] and len(prim.targets) == 3
    assert g.animations and g.animations[0].channels[0].target.path == "weights"
    for t in prim.targets:                                          # glTF requires min/max on POSITION
        acc = g.accessors[t["POSITION"]]
        assert acc.min is not None and acc.max is not None
    back = read_mesh(out)
    np.testing.assert_allclose(back.vertices, head_model.neutral, atol=1e-5)
    r = run_mimica("export", seq, "--out", tmp_path / "objs", "--format", "ply")
    assert r.returncode == 0 and len(list((tmp_path / "objs").glob("*.ply"))) == 3


def _write_rest(tmp_path, head_model):
    from mimica.mesh import write_mesh
    p = tmp_path / "rest.obj"
    write_mesh(p, head_model.mesh)
    return p




def test_folder_inputs_say_what_they_take(tmp_path):
    """A folder of frames is one format: a previous run's animation.glb beside the OBJ frames is
    left out (it used to become frame 0), and said; frames come in natural order (f2 before
    f10); a sheet of more than 12 meshes says that it shows 12 of them."""
    import pygltflib
    from mimica.mesh import plane_grid, write_mesh
    seq = tmp_path / "seq"
    grid = plane_grid(6, 6, 1.0, 1.0)
    for i in range(13):
        v = grid.vertices.copy()
        v[:, 2] = 0.05 * i * np.sin(3 * v[:, 0])
        write_mesh(seq / f"f{i}.obj", grid.with_vertices(v))
    r = run_mimica("export", seq, "--out", seq / "animation.glb")
    assert r.returncode == 0, r.stderr
    r = run_mimica("export", seq, "--out", tmp_path / "again.glb")
    assert r.returncode == 0 and "left out animation.glb" in r.stderr, r.stderr
    g = pygltflib.GLTF2().load(str(tmp_path / "again.glb"))
    ex = g.meshes[0].extras                                          # a compact clip keeps its frames' names
    assert ex.get("frames", ex["targetNames"]) == [f"f{i}" for i in range(13)]
    r = run_mimica("render", seq, "--out", tmp_path / "sheet.png", "--size", 64)
    assert r.returncode == 0 and "13 meshes; the sheet shows 12" in r.stderr, r.stderr
