"""Files other tools wrote, through the commands: a file that cannot be read is one line;
`blendshapes` hands Blender's GLB and FBX back with their shapes, imported again into every Blender
the tests run; FBX without Blender says how; non-manifold targets transfer; a sealed FBX head gets
its mouth cut; a seam not found says what to do; a take on an FBX head says what to make."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
from helpers import BLENDERS, ROOT, blender_files, validate

from mimica.cli import main
from mimica.mesh import read_mesh
from mimica.errors import MimicaError
from mimica.mesh.io.gltf import write_gltf_layout

DATA = Path(os.environ["MIMICA_DATA"])
SAMPLES = DATA / "gltf-samples"
ICT_HEAD = DATA / "ict-facekit" / "FaceXModel" / "identity001.obj"


def test_files_it_cannot_read_are_refused_in_one_line(tmp_path, capsys):
    data = (SAMPLES / "AnimatedMorphCube" / "AnimatedMorphCube.gltf").read_text()
    squeezed = json.loads(data)
    squeezed["extensionsRequired"] = squeezed["extensionsUsed"] = ["KHR_meshopt_compression"]
    (tmp_path / "meshopt.gltf").write_text(json.dumps(squeezed))
    with pytest.raises(MimicaError, match="meshopt-compressed"):
        read_mesh(tmp_path / "meshopt.gltf")
    tri = read_mesh(SAMPLES / "SimpleMorph" / "SimpleMorph.gltf")
    write_gltf_layout(tmp_path / "whole.glb", tri.layout, tri)
    glb = tmp_path / "cut.glb"
    glb.write_bytes((tmp_path / "whole.glb").read_bytes()[:-20])       # a download cut short
    capsys.readouterr()
    assert main(["render", str(glb), "--out", str(tmp_path / "r.png")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(glb) in err[0] and not (tmp_path / "r.png").exists()


def test_blendshapes_go_back_into_blenders_file(blender_head, tmp_path):
    """`blendshapes` on Blender's GLB writes Blender's file back with 52 morph targets: imported
    into Blender, the same object, node transform, materials and vertices where they stood, the
    shape keys move the head as on the OBJ; the Khronos validator finds no error."""
    out = tmp_path / "arkit.glb"
    assert main(["blendshapes", str(blender_head), "--out", str(out)]) == 0
    [report] = validate([out])
    assert report["errors"] == 0, report["messages"]
    blender_files("import", blender_head, tmp_path / "before.json")
    blender_files("import", out, tmp_path / "after.json")
    before, after = (json.loads((tmp_path / f).read_text())["objects"] for f in ("before.json", "after.json"))
    _imports_in_everyblender_files(out, tmp_path, after)
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


def test_blendshapes_go_back_into_a_draco_compressed_glb(blender_draco_head, tmp_path, capsys):
    """`blendshapes` on Blender's Draco-compressed GLB: said in a line that the file comes back
    uncompressed; its lips cut; written back with 52 morph targets, no validator error; imported
    into Blender, the same object, node transform and materials, every vertex within a step of
    Draco's grid of where Blender's own import of the compressed file puts it."""
    out = tmp_path / "arkit.glb"
    capsys.readouterr()
    assert main(["blendshapes", str(blender_draco_head), "-o", str(out)]) == 0
    said = capsys.readouterr().err
    assert "12 Draco-compressed primitives decoded (a file written back from it holds them uncompressed)" in said
    # the grid moves the found landmarks a little: the path between the lips went out and back
    # around one of them (refused as crossing itself); its loop erased, the lips are cut
    assert "the lips were sealed: cut apart along" in said, said
    [report] = validate([out])
    assert report["errors"] == 0 and report["warnings"] == 0, report["messages"]
    assert "KHR_draco_mesh_compression" not in json.dumps(read_json_chunk(out))
    blender_files("import", blender_draco_head, tmp_path / "before.json")
    blender_files("import", out, tmp_path / "after.json")
    before, after = (json.loads((tmp_path / f).read_text())["objects"] for f in ("before.json", "after.json"))
    _imports_in_everyblender_files(out, tmp_path, after)
    [b], [a] = before, after
    assert a["name"] == b["name"] and a["matrix"] == b["matrix"] and a["materials"] == b["materials"]
    vb = np.load(tmp_path / "before.npz")[b["name"]]
    va = np.load(tmp_path / "after.npz")[a["name"]]
    step = float(np.ptp(vb, axis=0).max()) / (2 ** 14 - 1)
    from scipy.spatial import cKDTree
    assert cKDTree(va).query(vb)[0].max() < 2 * step and cKDTree(vb).query(va)[0].max() < 2 * step
    assert len(a["shape_keys"]) == 53 and a["shape_keys"]["jawOpen"] > 0


def read_json_chunk(glb: Path) -> dict:
    import struct
    data = glb.read_bytes()
    return json.loads(data[20:20 + struct.unpack_from("<I", data, 12)[0]])


def _imports_in_everyblender_files(path, tmp_path, objects) -> None:
    """The other Blenders (5.x) import the file as 4.5 does: the same objects, vertices, keys."""
    for version in list(BLENDERS)[1:]:
        blender_files("import", path, tmp_path / f"b{version}.json", version=version)
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


def test_blendshapes_go_back_into_blenders_fbx(blender_fbx, tmp_path):
    """`blendshapes` on Blender's FBX writes it back with 52 shape keys on the user's object:
    imported into Blender, the same object and materials, the vertices where they stood, and the
    keys move the head as on the OBJ."""
    out = tmp_path / "arkit.fbx"
    assert main(["blendshapes", str(blender_fbx), "--out", str(out)]) == 0
    blender_files("import", blender_fbx, tmp_path / "before.json")
    blender_files("import", out, tmp_path / "after.json")
    before, after = (json.loads((tmp_path / f).read_text())["objects"] for f in ("before.json", "after.json"))
    _imports_in_everyblender_files(out, tmp_path, after)
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


def test_an_fbx_head_with_sealed_lips_gets_its_cut_throughblender_files(tmp_path):
    """The shared real head (sealed lips) as Blender's FBX: the mouth is cut, the cut's vertices
    added to the user's object in Blender after its own, and the 52 shapes equal those of the
    same head's OBJ (the FBX keeps the OBJ's vertices)."""
    from mimica.mesh.io import read_morph_targets
    head = DATA / "real-heads" / "mediapipe-canonical" / "head.obj"
    blender_files("export", head, tmp_path / "head.fbx")
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


def test_a_take_on_an_fbx_head_without_arkit_keys_says_what_to_make(blender_fbx, tmp_path, capsys):
    """A take on an FBX head is written into its FBX: one without ARKit shape keys is told, in one
    line, the command that makes them; a .glb asked of it is refused in one line; nothing written."""
    import numpy as np
    from helpers import live_link_csv
    live_link_csv(tmp_path / "take.csv", np.zeros((3, 52)))
    for out, said in (("t.fbx", "blendshapes"), ("t.glb", "written as .fbx")):
        capsys.readouterr()
        assert main(["animate", str(blender_fbx), "--arkit", str(tmp_path / "take.csv"), "--out",
                     str(tmp_path / out)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and said in err[0] and not (tmp_path / out).exists(), err
