"""The software rasterizer: the picture shows the mesh where it is, lit, and nothing else."""

from __future__ import annotations

import numpy as np
import pytest

from mimica import Mesh
from mimica.render import rasterize, render_mesh


def test_rasterize_square_covers_its_pixels():
    xy = np.array([[10.0, 10], [30, 10], [30, 30], [10, 30]])
    tri, bary = rasterize(xy, np.zeros(4), np.array([[0, 1, 2], [0, 2, 3]]), 40, 40)
    assert (tri >= 0).sum() == 400                              # 20 x 20 pixel centres
    assert (tri[:10] < 0).all() and np.allclose(bary[tri >= 0].sum(1), 1)


def test_nearest_surface_wins():
    xy = np.array([[0.0, 0], [20, 0], [0, 20]] * 2)
    z = np.array([0.0, 0, 0, 1, 1, 1])
    tri, _ = rasterize(xy, z, np.array([[0, 1, 2], [3, 4, 5]]), 20, 20)
    assert set(np.unique(tri[tri >= 0])) == {1}


def test_render_face_not_blank(head_model):
    img = render_mesh(head_model.mesh, size=(128, 128))
    fg = (img != 255).any(axis=2)
    assert 0.2 < fg.mean() < 0.9 and img[fg].std() > 5          # a shaded silhouette
    side = render_mesh(head_model.mesh, size=(128, 128), yaw=90)
    assert not np.array_equal(side, img)


def test_render_quad_mesh_with_colors():
    m = Mesh.from_faces(np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.0]]), [[0, 1, 2, 3]])
    img = render_mesh(m, size=(32, 32), colors=np.array([[1, 0, 0]] * 4))
    centre = img[16, 16]
    assert centre[0] > 100 and centre[1] == 0 and centre[2] == 0


# --- render / export / blendshapes from the command line -------------------------

def _run(*args):
    import subprocess
    import sys
    return subprocess.run([sys.executable, "-m", "mimica.cli", *map(str, args)], capture_output=True, text=True)


def test_render_views_heatmap_and_turntable(tmp_path, head_model):
    from PIL import Image
    from mimica.mesh import write_mesh
    face = tmp_path / "face.obj"
    write_mesh(face, head_model.mesh)
    r = _run("render", face, "--out", tmp_path / "views.png", "--size", 200)
    assert r.returncode == 0, r.stderr
    im = np.asarray(Image.open(tmp_path / "views.png"))
    assert im.shape[1] >= 3 * 200                                   # front, three-quarter, profile
    vals = tmp_path / "err.txt"
    np.savetxt(vals, np.linspace(0, 2.5, head_model.mesh.n_vertices))
    r = _run("render", face, "--view", "front", "--heatmap", vals, "--out", tmp_path / "heat.png", "--size", 200)
    assert r.returncode == 0, r.stderr
    heat = np.asarray(Image.open(tmp_path / "heat.png")).astype(int)
    assert heat.shape[0] > 200                                      # picture plus the legend under it
    assert (np.abs(heat[:200, :, 0] - heat[:200, :, 2]) > 60).any()  # coloured, not grey
    r = _run("render", face, "--turntable", "--frames", 6, "--size", 96, "--out", tmp_path / "turn.mp4")
    assert r.returncode == 0, r.stderr
    from mimica.image.video import frame_source
    assert len(list(frame_source(tmp_path / "turn.mp4")[2])) == 6
    bad = tmp_path / "bad.txt"
    bad.write_text("1\n2\n")
    out = tmp_path / "never.png"
    r = _run("render", face, "--heatmap", bad, "--out", out)
    assert r.returncode == 2 and "2 values" in r.stderr and not out.exists()


def test_export_sequence_as_gltf_animation(tmp_path, head_model):
    import pygltflib
    from mimica.mesh import read_mesh, write_mesh
    seq = tmp_path / "seq"
    names = ["jawOpen", "mouthSmile_L", "browDown_R"]
    for i, n in enumerate(names):
        write_mesh(seq / f"f{i:02d}.obj", head_model.mesh.with_vertices(head_model.shape(n)))
    out = tmp_path / "anim.glb"
    r = _run("export", seq, "--rest", _write_rest(tmp_path, head_model), "--fps", 24, "--out", out)
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
    r = _run("export", seq, "--out", tmp_path / "objs", "--format", "ply")
    assert r.returncode == 0 and len(list((tmp_path / "objs").glob("*.ply"))) == 3


def _write_rest(tmp_path, head_model):
    from mimica.mesh import write_mesh
    p = tmp_path / "rest.obj"
    write_mesh(p, head_model.mesh)
    return p


def test_arkit_names_and_sources():
    from mimica.export import ARKIT_52, ict_sources
    from mimica.store import MANIFEST
    assert len(ARKIT_52) == 52 and len(set(ARKIT_52)) == 52
    for a in ARKIT_52:
        for n in ict_sources(a):
            assert n in MANIFEST["files"], (a, n)
    assert ict_sources("eyeBlinkLeft") == ["eyeBlink_L"] and ict_sources("browInnerUp") == ["browInnerUp_L", "browInnerUp_R"]
    assert ict_sources("tongueOut") == []


def test_templates_offline_is_one_clear_error(tmp_path):
    from mimica.errors import MimicaError
    from mimica.store import TemplateStore
    store = TemplateStore(data=tmp_path / "nowhere", cache=tmp_path / "cache",
                          url="http://127.0.0.1:9/{commit}/{name}.obj", timeout=2)
    with pytest.raises(MimicaError, match="download from .* failed"):
        store.path("jawOpen")
    assert not any((tmp_path / "cache").glob("*.obj"))


def test_templates_with_an_unwritable_cache_still_read(tmp_path, head_model, monkeypatch):
    """A cache that cannot be written (a read-only home: every file creation refused) only
    makes the next read slower: the shapes still come from the data directory."""
    import errno
    from mimica.store import TemplateStore

    def refuse(*a, **k):
        raise PermissionError(errno.EACCES, "Permission denied")
    monkeypatch.setattr("mimica.outputs.tempfile.mkstemp", refuse)
    store = TemplateStore(cache=tmp_path / "cache")
    shapes = store.shapes(["jawOpen"], head_model.n)
    assert np.array_equal(shapes["jawOpen"], head_model.shape("jawOpen"))


def test_blendshapes_on_another_topology(tmp_path, head_model):
    """52 ARKit shapes on a resampled head (its own triangulation): jawOpen opens the jaw,
    the left smile moves the left mouth corner more than the right, tongueOut stays at rest."""
    from mimica.data import ICT_LANDMARKS_68
    from mimica.export import arkit_blendshapes
    from mimica.store import TemplateStore
    from mimica.correspond.remesh import resample_face
    v = head_model.identity("identity013")
    rs = resample_face(head_model.mesh.with_vertices(v), v[ICT_LANDMARKS_68], 6000, seed=3)
    shapes = arkit_blendshapes(rs.mesh, store=TemplateStore(cache=tmp_path))
    assert len(shapes) == 52
    rest = rs.mesh.vertices
    lm = v[ICT_LANDMARKS_68]
    near = lambda p: np.argmin(np.linalg.norm(rest - p, axis=1))                  # noqa: E731
    chin, lc, rc = near(lm[8]), near(lm[54]), near(lm[48])
    assert shapes["jawOpen"][chin, 1] < rest[chin, 1] - 0.5                     # cm, downward
    d = shapes["mouthSmileLeft"] - rest
    assert np.linalg.norm(d[lc]) > 2 * np.linalg.norm(d[rc])
    assert np.array_equal(shapes["tongueOut"], rest)


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
    r = _run("export", seq, "--out", seq / "animation.glb")
    assert r.returncode == 0, r.stderr
    r = _run("export", seq, "--out", tmp_path / "again.glb")
    assert r.returncode == 0 and "left out animation.glb" in r.stderr, r.stderr
    g = pygltflib.GLTF2().load(str(tmp_path / "again.glb"))
    ex = g.meshes[0].extras                                          # a compact clip keeps its frames' names
    assert ex.get("frames", ex["targetNames"]) == [f"f{i}" for i in range(13)]
    r = _run("render", seq, "--out", tmp_path / "sheet.png", "--size", 64)
    assert r.returncode == 0 and "13 meshes; the sheet shows 12" in r.stderr, r.stderr
