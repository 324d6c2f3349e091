"""Files other tools wrote, read whole and handed back where they stood (mesh.io.gltf):
the Khronos glTF samples in the data directory, and heads Blender exports (bpy, in .venv-blender
as tests/test_blender.py finds it) imported back into Blender after mimica worked on them."""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

from mimica.cli import main
from mimica.errors import MimicaError
from mimica.mesh import read_mesh
from mimica.mesh.io.gltf import open_for_edit, read_gltf_layout, read_morph_targets, save_edited, write_gltf_layout
from helpers import BLENDERS, ROOT, blender_python, validate

DATA = Path(os.environ["MIMICA_DATA"])
SAMPLES = DATA / "gltf-samples"
ICT_HEAD = DATA / "ict-facekit" / "FaceXModel" / "identity001.obj"


def test_the_khronos_samples_read_whole():
    """Every primitive, in world space; targets without names named by index, and they move."""
    cube, lay = read_gltf_layout(SAMPLES / "AnimatedMorphCube" / "AnimatedMorphCube.gltf")
    # 24 vertices (a cube split at its corners for flat normals) welded to its 8 corners; the
    # node scales the 0.01-unit cube by 100 and turns it
    assert cube.n_vertices == 8 and cube.n_faces == 12
    np.testing.assert_allclose(np.abs(cube.vertices), 1.0, atol=1e-5)
    assert "named by their index" in " ".join(lay.notes)
    _, targets, _ = read_morph_targets(SAMPLES / "AnimatedMorphCube" / "AnimatedMorphCube.gltf")
    assert list(targets) == ["target0", "target1"]
    assert all(np.abs(t - cube.vertices).max() > 1.0 for t in targets.values())

    two, lay = read_gltf_layout(SAMPLES / "MorphPrimitivesTest" / "MorphPrimitivesTest.gltf")
    assert two.group_names == ("red", "green") and two.n_faces == 72 // 3 + 24 // 3   # both primitives
    assert [len(s.vertex) for s in lay.sets] == [21, 9]
    assert "default morph target weights" in " ".join(lay.notes)
    _, t2, _ = read_morph_targets(SAMPLES / "MorphPrimitivesTest" / "MorphPrimitivesTest.gltf")
    moved = np.linalg.norm(t2["target0"] - two.vertices, axis=1)
    assert moved.max() == pytest.approx(0.2, abs=1e-6)
    # the shared target moves vertices of both primitives
    assert all((moved[s.vertex] > 1e-3).any() for s in lay.sets)

    tri = read_mesh(SAMPLES / "SimpleMorph" / "SimpleMorph.gltf")    # geometry in a .bin of its own
    assert tri.n_vertices == 3 and tri.n_faces == 1


def test_a_sample_written_back_keeps_the_file(tmp_path):
    """New morph targets added to the user's own file: its node, its targets and its animation
    kept (the animation's weights given zeros for the new targets); valid glTF; read back the same."""
    src = SAMPLES / "AnimatedMorphCube" / "AnimatedMorphCube.gltf"
    cube = read_mesh(src)
    lift = cube.vertices + [0.0, 0.5, 0.0]
    out = tmp_path / "cube.glb"
    info = write_gltf_layout(out, cube.layout, cube, {"lift": lift})
    assert info["appended"] == 0
    [report] = validate([out])
    assert report["errors"] == 0, report["messages"]
    before, after = json.loads(src.read_text()), open_for_edit(out)[1]
    assert after["nodes"] == before["nodes"]
    assert after["meshes"][0]["extras"]["targetNames"] == ["target0", "target1", "lift"]
    anim = after["animations"][0]["samplers"][0]
    keys = before["accessors"][before["animations"][0]["samplers"][0]["output"]]["count"] // 2
    assert after["accessors"][anim["output"]]["count"] == 3 * keys           # 2 targets a key, now 3
    back, targets, _ = read_morph_targets(out)
    np.testing.assert_allclose(back.vertices, cube.vertices, atol=1e-6)
    np.testing.assert_allclose(targets["lift"], lift, atol=1e-6)
    _, orig, _ = read_morph_targets(src)
    np.testing.assert_allclose(targets["target1"], orig["target1"], atol=1e-6)


def test_points_and_lines_are_kept_as_they_are(tmp_path):
    """A primitive that is no surface is not read, said so, and comes back with zero targets."""
    import numpy as np
    from mimica.mesh.io.gltf import ARRAY_BUFFER, FLOAT, _Buffers
    buf = _Buffers()
    p = buf.add(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32), ARRAY_BUFFER, "VEC3", FLOAT, True)
    q = buf.add(np.array([[0, 0, 1], [1, 1, 1]], np.float32), ARRAY_BUFFER, "VEC3", FLOAT, True)
    doc = {"asset": {"version": "2.0", "generator": "a test"}, "scene": 0, "scenes": [{"nodes": [0]}],
           "nodes": [{"mesh": 0, "translation": [5, 0, 0]}],
           "meshes": [{"primitives": [{"attributes": {"POSITION": p}}, {"attributes": {"POSITION": q}, "mode": 1}]}],
           "accessors": buf.accessors, "bufferViews": buf.views}
    save_edited(doc, buf, tmp_path / "in.glb")
    m = read_mesh(tmp_path / "in.glb")
    assert m.n_vertices == 3 and m.vertices[:, 0].min() == 5.0            # the node's translation
    assert "points or lines kept" in " ".join(m.layout.notes)
    write_gltf_layout(tmp_path / "out.glb", m.layout, m, {"up": m.vertices + [0, 0, 1]})
    [report] = validate([tmp_path / "out.glb"])
    assert report["errors"] == 0, report["messages"]
    out = open_for_edit(tmp_path / "out.glb")[1]
    assert out["meshes"][0]["primitives"][1]["mode"] == 1 and len(out["meshes"][0]["primitives"][1]["targets"]) == 1
    assert out["asset"]["generator"] == "a test" and out["nodes"][0]["translation"] == [5, 0, 0]


def test_files_it_cannot_read_are_refused_in_one_line(tmp_path, capsys):
    data = (SAMPLES / "AnimatedMorphCube" / "AnimatedMorphCube.gltf").read_text()
    squeezed = json.loads(data)
    squeezed["extensionsRequired"] = squeezed["extensionsUsed"] = ["KHR_draco_mesh_compression"]
    (tmp_path / "draco.gltf").write_text(json.dumps(squeezed))
    with pytest.raises(MimicaError, match="Draco-compressed"):
        read_mesh(tmp_path / "draco.gltf")
    tri = read_mesh(SAMPLES / "SimpleMorph" / "SimpleMorph.gltf")
    write_gltf_layout(tmp_path / "whole.glb", tri.layout, tri)
    glb = tmp_path / "cut.glb"
    glb.write_bytes((tmp_path / "whole.glb").read_bytes()[:-20])       # a download cut short
    capsys.readouterr()
    assert main(["render", str(glb), "--out", str(tmp_path / "r.png")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(glb) in err[0] and not (tmp_path / "r.png").exists()


# ------------------------------------------------------------------- Blender's files
def _blender(*args, timeout=600, version="4.5"):
    run = subprocess.run([blender_python(version), str(ROOT / "tools" / "blender_files.py"), *map(str, args)],
                         stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=timeout)
    assert run.returncode == 0, run.stderr[-3000:] + run.stdout[-2000:]


def _exported(tmp_path_factory, suffix):
    """ICT-FaceKit's identity001 through Blender's OBJ importer and its glTF or FBX exporter."""
    d = tmp_path_factory.mktemp("blender_head")
    _blender("export", ICT_HEAD, d / f"head{suffix}")
    return d / f"head{suffix}"


@pytest.fixture(scope="module")
def blender_head(tmp_path_factory):
    """Blender's GLB (defaults)."""
    return _exported(tmp_path_factory, ".glb")


def test_a_blender_glb_is_read_whole_and_standing(blender_head):
    """12 primitives (one a material) under a node turned 90 degrees: every one read, in world
    space (the head stands as the OBJ does), the material and back-of-head seam welded."""
    obj = read_mesh(ICT_HEAD)
    head = read_mesh(blender_head)
    assert set(head.group_names) == set(obj.group_names) and len(head.layout.sets) == 12
    size = float(np.ptp(obj.vertices, axis=0).max())
    from scipy.spatial import cKDTree
    d, _ = cKDTree(head.vertices).query(obj.vertices)
    assert d.max() < 1e-6 * size                      # every vertex of the OBJ, where it stands
    d, _ = cKDTree(obj.vertices).query(head.vertices)
    assert d.max() < 1e-6 * size
    from scipy.sparse.csgraph import connected_components
    face_and_back = np.isin(head.groups, [head.group_names.index("M_Face"), head.group_names.index("M_BackHead")])
    sub, _ = head.submesh(np.nonzero(face_and_back)[0])
    skin_obj, _ = obj.submesh(np.nonzero(np.isin(obj.groups, [0, 1]))[0])
    assert sub.n_vertices == skin_obj.n_vertices      # the seam Blender split at the material is one again
    assert connected_components(sub.adjacency)[0] == connected_components(skin_obj.adjacency)[0]


def test_blendshapes_go_back_into_blenders_file(blender_head, tmp_path):
    """`blendshapes` on Blender's GLB writes Blender's file back with 52 morph targets: imported
    into Blender, the same object, node transform, materials and vertices where they stood, the
    shape keys move the head as on the OBJ; the Khronos validator finds no error."""
    out = tmp_path / "arkit.glb"
    assert main(["blendshapes", str(blender_head), "--out", str(out)]) == 0
    [report] = validate([out])
    assert report["errors"] == 0, report["messages"]
    _blender("import", blender_head, tmp_path / "before.json")
    _blender("import", out, tmp_path / "after.json")
    before, after = (json.loads((tmp_path / f).read_text())["objects"] for f in ("before.json", "after.json"))
    _imports_in_every_blender(out, tmp_path, after)
    assert [o["name"] for o in after] == [o["name"] for o in before]
    [b], [a] = before, after
    assert a["matrix"] == b["matrix"] and a["materials"] == b["materials"]
    assert a["vertices"] >= b["vertices"]           # the mouth's cut may add a few, after Blender's own
    vb = np.load(tmp_path / "before.npz")[b["name"]]
    va = np.load(tmp_path / "after.npz")[a["name"]]
    size = float(np.ptp(vb, axis=0).max())
    from scipy.spatial import cKDTree                # Blender puts a primitive's vertices after the last's:
    assert cKDTree(va).query(vb)[0].max() < 1e-6 * size        # every one where it stood,
    assert cKDTree(vb).query(va)[0].max() < 1e-6 * size        # the cut's copies too
    keys = a["shape_keys"]
    assert len(keys) == 53 and keys["jawOpen"] > 0.05 * size and keys["tongueOut"] == 0.0
    # the shapes move the head as `blendshapes` on the same head's OBJ does
    dev = _shape_deviation(out, tmp_path)
    assert np.median(dev) <= 0.04 and dev.max() <= 0.10, (np.median(dev), dev.max())


def _imports_in_every_blender(path, tmp_path, objects) -> None:
    """The other Blenders (5.x) import the file as 4.5 does: the same objects, vertices, keys."""
    for version in list(BLENDERS)[1:]:
        _blender("import", path, tmp_path / f"b{version}.json", version=version)
        other = json.loads((tmp_path / f"b{version}.json").read_text())["objects"]
        assert [(o["name"], o["vertices"], sorted(o["shape_keys"])) for o in other] == \
            [(o["name"], o["vertices"], sorted(o["shape_keys"])) for o in objects], version


def _shape_deviation(result, tmp_path) -> np.ndarray:
    """Per ARKit shape: the RMS difference between the result's displacement and `blendshapes`
    on ICT_HEAD's OBJ, over the OBJ's largest displacement; vertices matched by place and uv."""
    from mimica.correspond.layout import same_mesh
    from mimica.export import ARKIT_52
    from mimica.mesh.io import read_morph_targets
    if not (tmp_path / "obj.glb").exists():
        assert main(["blendshapes", str(ICT_HEAD), "--out", str(tmp_path / "obj.glb")]) == 0
    om, ot, _ = read_morph_targets(tmp_path / "obj.glb")
    gm, gt, _ = read_morph_targets(result)
    obj = read_mesh(ICT_HEAD)
    of = same_mesh(obj, gm)                          # each result vertex's OBJ vertex
    assert of is not None
    size = float(np.ptp(obj.vertices, axis=0).max())
    assert np.abs(gm.vertices - om.vertices[of]).max() < 1e-6 * size
    out = []
    for n in ARKIT_52:
        d_obj = ot[n][of] - om.vertices[of]
        big = float(np.linalg.norm(ot[n] - om.vertices, axis=1).max())
        if big > 0:
            out.append(np.sqrt(((gt[n] - gm.vertices - d_obj) ** 2).sum(1).mean()) / big)
    return np.array(out)


@pytest.fixture(scope="module")
def blender_fbx(tmp_path_factory):
    """Blender's FBX (defaults)."""
    return _exported(tmp_path_factory, ".fbx")


def test_a_blender_fbx_is_read_whole(blender_fbx):
    """Blender's FBX (in centimetres, its axes converted): every control point, in its place
    (y up, metres), polygons and materials as the OBJ has them."""
    obj = read_mesh(ICT_HEAD)
    head = read_mesh(blender_fbx)
    assert head.same_topology(obj) and set(head.group_names) == set(obj.group_names)
    size = float(np.ptp(obj.vertices, axis=0).max())
    assert np.abs(head.vertices - obj.vertices).max() < 1e-6 * size


def test_blendshapes_go_back_into_blenders_fbx(blender_fbx, tmp_path):
    """`blendshapes` on Blender's FBX writes it back with 52 shape keys on the user's object:
    imported into Blender, the same object and materials, the vertices where they stood, and the
    keys move the head as on the OBJ."""
    out = tmp_path / "arkit.fbx"
    assert main(["blendshapes", str(blender_fbx), "--out", str(out)]) == 0
    _blender("import", blender_fbx, tmp_path / "before.json")
    _blender("import", out, tmp_path / "after.json")
    before, after = (json.loads((tmp_path / f).read_text())["objects"] for f in ("before.json", "after.json"))
    _imports_in_every_blender(out, tmp_path, after)
    [b], [a] = before, after
    assert a["name"] == b["name"] and a["materials"] == b["materials"] and a["vertices"] == b["vertices"]
    vb = np.load(tmp_path / "before.npz")[b["name"]]
    va = np.load(tmp_path / "after.npz")[a["name"]]
    assert np.abs(va - vb).max() < 1e-6 * float(np.ptp(vb, axis=0).max())
    assert len(a["shape_keys"]) == 53
    dev = _shape_deviation(out, tmp_path)
    assert np.median(dev) <= 0.04 and dev.max() <= 0.10, (np.median(dev), dev.max())


def test_fbx_without_blender_says_how(monkeypatch, blender_fbx, tmp_path, capsys):
    monkeypatch.delenv("MIMICA_BLENDER_PYTHON", raising=False)
    monkeypatch.setenv("PATH", str(tmp_path))
    assert main(["render", str(blender_fbx), "--out", str(tmp_path / "r.png")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "MIMICA_BLENDER_PYTHON" in err[0] and not (tmp_path / "r.png").exists()


def test_non_manifold_targets_transfer(tmp_path, head_model):
    """Scans and game heads are often non-manifold: ICT's head with a fin on an edge (an edge of
    three faces, one vertex past the head), and the shared real head with a fin and a triangle
    touching it at one vertex, take the jaw's motion; the extra pieces follow the skin."""
    from mimica.mesh import Mesh, write_mesh
    ict = DATA / "ict-facekit" / "FaceXModel"
    for name, m in (("ict_head", head_model.mesh), ("real_head", read_mesh(DATA / "real-heads" / "mediapipe-canonical"
                                                                            / "head.obj"))):
        e = m.edges[len(m.edges) // 3]
        n = m.n_vertices
        v = np.vstack([m.vertices, m.vertices[e].mean(0) + [0, 0, 0.02 * np.ptp(m.vertices[:, 1])],
                       m.vertices[5] + [0.3, 0, 0.2], m.vertices[5] + [0.3, 0.3, 0.2]])
        target = Mesh.from_faces(v, list(m.faces) + [np.array([e[0], e[1], n]), np.array([5, n + 1, n + 2])])
        write_mesh(tmp_path / f"{name}.obj", target)
        assert main(["transfer", str(ict / "generic_neutral_mesh.obj"), str(ict / "jawOpen.obj"), "--target",
                     str(tmp_path / f"{name}.obj"), "--out", str(tmp_path / name)]) == 0
        out = read_mesh(tmp_path / name / "jawOpen.obj")
        assert out.n_vertices >= target.n_vertices and np.isfinite(out.vertices).all()
        move = np.linalg.norm(out.vertices[:target.n_vertices] - v, axis=1)
        assert move[:n].max() > 0.05 * np.ptp(m.vertices[:, 1])              # the jaw opened
        assert move[n:].max() <= move[:n].max()                             # the pieces went with it


def test_an_fbx_head_with_sealed_lips_gets_its_cut_through_blender(tmp_path):
    """The shared real head (sealed lips) as Blender's FBX: the mouth is cut, the cut's vertices
    added to the user's object in Blender after its own, and the 52 shapes equal those of the
    same head's OBJ (the FBX keeps the OBJ's vertices)."""
    from mimica.mesh.io import read_morph_targets
    head = DATA / "real-heads" / "mediapipe-canonical" / "head.obj"
    _blender("export", head, tmp_path / "head.fbx")
    assert main(["blendshapes", str(head), "--out", str(tmp_path / "obj.glb")]) == 0
    assert main(["blendshapes", str(tmp_path / "head.fbx"), "--out", str(tmp_path / "arkit.fbx")]) == 0
    om, ot, _ = read_morph_targets(tmp_path / "obj.glb")
    fm, ft, _ = read_morph_targets(tmp_path / "arkit.fbx")
    n = read_mesh(head).n_vertices
    assert fm.n_vertices == om.n_vertices > n                     # the cut's copies, after the head's own
    size = float(np.ptp(om.vertices, axis=0).max())
    assert np.abs(fm.vertices - om.vertices).max() < 1e-5 * size
    for name in ("jawOpen", "mouthSmileLeft", "eyeBlinkRight"):
        big = float(np.linalg.norm(ot[name] - om.vertices, axis=1).max())
        assert np.sqrt(((ft[name] - ot[name]) ** 2).sum(1).mean()) < 0.01 * big, name


def test_a_seam_not_found_is_said_with_what_to_do(tmp_path, capsys):
    """Sealed lips whose seam cannot be found (here: landmarks that put both mouth corners on one
    point) stay sealed, and the command says so in one line with what to do; --show draws it."""
    import sys
    sys.path.insert(0, str(ROOT / "tools"))
    from hard_heads import watertight_head
    from mimica.landmarks import write_landmarks
    from mimica.mesh import write_mesh
    mesh, lm, _ = watertight_head(21, n_vertices=6000)
    write_mesh(tmp_path / "head.obj", mesh)
    p = lm.positions(mesh)
    p[48:68] = p[[62, 66]].mean(0)                  # every mouth point on one spot
    write_landmarks(tmp_path / "head.json", p)
    ict = DATA / "ict-facekit" / "FaceXModel"
    capsys.readouterr()
    assert main(["transfer", str(ict / "generic_neutral_mesh.obj"), str(ict / "jawOpen.obj"), "--target",
                 str(tmp_path / "head.obj"), "--target-landmarks", str(tmp_path / "head.json"), "--show",
                 str(tmp_path / "show.png"), "--out", str(tmp_path / "out")]) == 0
    err = capsys.readouterr().err
    line = next(ln for ln in err.splitlines() if "stay so" in ln)
    assert "--target-landmarks" in line and "--cut-mouth off" in line
    assert (tmp_path / "show.png").is_file()


def test_a_take_on_an_fbx_head_says_what_to_make(blender_fbx, tmp_path, capsys):
    """A take plays on a glTF head's morph targets: an FBX head is told, in one line, the command
    that makes one."""
    (tmp_path / "take.csv").write_text("time,jawOpen\n0,0\n")
    capsys.readouterr()
    assert main(["animate", str(blender_fbx), "--arkit", str(tmp_path / "take.csv"), "--out",
                 str(tmp_path / "t.glb")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "blendshapes" in err[0] and not (tmp_path / "t.glb").exists()
