"""Every kind of GLB and glTF mimica writes passes the Khronos glTF-Validator (npm package
gltf-validator, tools/gltf/) with no error and no warning, and carries smooth normals: unit
NORMAL on the base mesh, and on every morph target the change of the normal."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from helpers import same_objects, validate
from mimica.mesh import Mesh, write_glb, write_mesh
from mimica.pipeline import ExportOptions, export_sequence, make_blendshapes

def _accessor(g, i):
    from mimica.mesh.io.gltf import read_accessor
    return read_accessor(g, i)


def _vertex_of(g) -> np.ndarray:
    """The mesh vertex of each of the file's vertices (the uv seams split)."""
    from mimica.mesh.io.gltf import VERTEX_MAP, buffer_bytes
    prim = g.meshes[0].primitives[0]
    n = g.accessors[prim.attributes.POSITION].count
    if not (isinstance(prim.extras, dict) and VERTEX_MAP in prim.extras):
        return np.arange(n)
    view = g.bufferViews[prim.extras[VERTEX_MAP]]
    return np.frombuffer(buffer_bytes(g, view.buffer), np.uint32, n, view.byteOffset or 0).astype(int)


@pytest.fixture(scope="module")
def written(head_model, full_model, tmp_path_factory):
    """One file of each kind: mesh (.glb, .gltf; quads triangulated; a vertex no face uses),
    morph targets (blendshapes), morph targets with an animation (export, simulate)."""
    d = tmp_path_factory.mktemp("gltf")
    m = head_model.mesh
    write_mesh(d / "head.glb", m)
    write_mesh(d / "head.gltf", m)
    loose = Mesh(np.vstack([m.vertices, m.vertices[:1] + 100.0]), m.face_indices, m.face_starts)
    write_glb(d / "loose.glb", loose)
    write_mesh(d / "full.glb", full_model.mesh)                     # 12 materials: teeth, eyes, lashes ...
    from mimica.mesh.io import SPARSE_TOLERANCE
    write_glb(d / "sparse.glb", m, {"rest": m.vertices, "blink": head_model.shape("eyeBlink_R"),
                                    "jaw": head_model.shape("jawOpen")}, sparse=SPARSE_TOLERANCE)
    write_glb(d / "quantized.glb", m, {"rest": m.vertices, "blink": head_model.shape("eyeBlink_R"),
                                       "jaw": head_model.shape("jawOpen")}, sparse=SPARSE_TOLERANCE, quantize=True)
    frames = d / "frames"
    frames.mkdir()
    for i, name in enumerate(("mouthSmile_L", "jawOpen", "eyeBlink_R")):
        write_mesh(frames / f"f{i}.obj", m.with_vertices(head_model.shape(name)))
    paths = sorted(frames.glob("*.obj"))
    for clip in ("clip.glb", "clip.gltf"):
        export_sequence(paths, d / clip, ExportOptions(fps=24))
    data = Path(os.environ["MIMICA_DATA"]) / "real-heads" / "mediapipe-canonical"
    make_blendshapes(data / "head.obj", d / "arkit.glb")
    return d


def test_every_kind_passes_the_validator(written):
    files = sorted(p for p in written.iterdir() if p.suffix in (".glb", ".gltf"))
    assert len(files) == 9
    for r in validate(files):
        assert r["errors"] == 0 and r["warnings"] == 0, (r["path"], r["messages"])
        assert r["info"]["maxAttributes"] >= 2                       # POSITION and NORMAL


def test_the_json_is_decoded_as_pygltflib_decodes_it(written):
    """mimica's own files (sparse, quantized, clips with animations, .gltf beside its .bin): the
    same objects as pygltflib's own decoding (tests/mesh/test_foreign_files.py: other tools')."""
    import pygltflib as gl
    from mimica.mesh.io.gltf_decode import fast_gltf_class
    files = sorted(written.glob("*.gl*"))
    assert len(files) >= 9
    for f in files:
        assert same_objects(fast_gltf_class()().load(str(f)), gl.GLTF2().load(str(f))) is None, f


def test_normals_are_smooth_and_targets_carry_their_change(written, head_model):
    import pygltflib as gl
    g = gl.GLTF2().load(str(written / "clip.glb"))
    prim = g.meshes[0].primitives[0]
    n0 = _accessor(g, prim.attributes.NORMAL)
    np.testing.assert_allclose(np.linalg.norm(n0, axis=1), 1, atol=1e-6)
    m = head_model.mesh
    v = _vertex_of(g)
    base = head_model.shape("mouthSmile_L")                       # export's rest: the first frame
    np.testing.assert_allclose(n0, m.vertex_normals(base)[v], atol=1e-6)
    shape = head_model.shape("jawOpen")
    dn = _accessor(g, prim.targets[1]["NORMAL"])
    from mimica.mesh.io.gltf import SPARSE_NORMAL, SPARSE_TOLERANCE      # export writes sparse targets
    np.testing.assert_allclose(n0 + dn, m.vertex_normals(shape)[v], atol=SPARSE_NORMAL + 1e-6)
    np.testing.assert_allclose(_accessor(g, prim.targets[1]["POSITION"]), 0.01 * (shape - base)[v],  # metres
                               atol=SPARSE_TOLERANCE * 1.001)


def test_uv_seams_split_and_read_back_whole(written, head_model):
    """TEXCOORD_0 from the mesh's uv: a vertex on a uv seam is written once per uv it has, and
    mimica reads the file back onto the mesh's own vertices, in order, with each corner's uv."""
    import pygltflib as gl
    from mimica.mesh import read_mesh
    m = head_model.mesh
    g = gl.GLTF2().load(str(written / "head.glb"))
    prim = g.meshes[0].primitives[0]
    assert prim.attributes.TEXCOORD_0 is not None
    n_file = g.accessors[prim.attributes.POSITION].count
    assert n_file > m.n_vertices                                    # the seams, split
    for name in ("head.glb", "head.gltf"):
        back = read_mesh(written / name)
        assert back.n_vertices == m.n_vertices
        np.testing.assert_allclose(back.vertices, m.vertices, atol=1e-5 * np.ptp(m.vertices))
        np.testing.assert_array_equal(back.face_indices, m.triangles.reshape(-1))
        np.testing.assert_allclose(back.uv[back.face_uv_indices], m.uv[m.uv_triangles.reshape(-1)], atol=1e-6)
    arkit = read_mesh(written / "arkit.glb")                        # the head's uv kept through blendshapes
    assert arkit.uv is not None


def test_files_are_in_metres(written, head_model, tmp_path):
    """glTF is in metres: ICT-FaceKit (centimetres, 33 units tall) is written 0.33 m tall with
    its unit kept, and read back in centimetres; --units m writes the numbers as they are."""
    import pygltflib as gl
    from mimica.errors import MimicaError
    from mimica.mesh import read_mesh
    m = head_model.mesh
    g = gl.GLTF2().load(str(written / "head.glb"))
    prim = g.meshes[0].primitives[0]
    acc = g.accessors[prim.attributes.POSITION]
    height = acc.max[1] - acc.min[1]
    assert prim.extras["mimica_units"] == "cm"
    assert abs(height - 0.01 * np.ptp(m.vertices[:, 1])) < 1e-4 and 0.2 < height < 0.5
    write_mesh(tmp_path / "raw.glb", m, units="m")
    raw = gl.GLTF2().load(str(tmp_path / "raw.glb"))
    acc = raw.accessors[raw.meshes[0].primitives[0].attributes.POSITION]
    assert abs((acc.max[1] - acc.min[1]) - np.ptp(m.vertices[:, 1])) < 1e-3
    np.testing.assert_allclose(read_mesh(tmp_path / "raw.glb").vertices, m.vertices, atol=1e-5 * np.ptp(m.vertices))
    with pytest.raises(MimicaError, match="units 'inch'"):
        write_mesh(tmp_path / "bad.glb", m, units="inch")
    assert not (tmp_path / "bad.glb").exists()


def test_one_primitive_and_material_per_group(written, full_model):
    """ICT-FaceKit's 12 materials (face, teeth, sclera ...) become 12 primitives on one set of
    vertices, each with its material; read back, every triangle is in its own group again."""
    import pygltflib as gl
    from mimica.mesh import read_mesh
    m = full_model.mesh
    g = gl.GLTF2().load(str(written / "full.glb"))
    assert [mat.name for mat in g.materials] == list(m.group_names)
    prims = g.meshes[0].primitives
    assert len(prims) == 12 and len({p.attributes.POSITION for p in prims}) == 1
    assert [p.material for p in prims] == list(range(12))
    back = read_mesh(written / "full.glb", allow_degenerate=True)
    assert back.group_names == m.group_names and back.n_vertices == m.n_vertices
    def tagged(mesh):
        return {tuple(sorted(t)) + (mesh.group_names[k],) for t, k in zip(mesh.triangles, mesh.groups[mesh.tri_face])}
    assert tagged(back) == tagged(m)


def test_sparse_targets_keep_what_moves(written, head_model):
    """Sparse morph targets: a vertex moving less than the tolerance (0.01 mm) is left out, the
    rest stored exactly; a target that does not move at all is still valid (one row)."""
    import pygltflib as gl
    from mimica.mesh.io import SPARSE_TOLERANCE
    m = head_model.mesh
    g = gl.GLTF2().load(str(written / "sparse.glb"))
    prim = g.meshes[0].primitives[0]
    v = _vertex_of(g)
    kinds = []
    for t, shape in zip(prim.targets, (m.vertices, head_model.shape("eyeBlink_R"), head_model.shape("jawOpen"))):
        acc = g.accessors[t["POSITION"]]
        kinds.append(None if acc.sparse is None else acc.sparse.count)
        got = _accessor(g, t["POSITION"])
        true = 0.01 * (shape - m.vertices)[v]                        # metres
        assert np.abs(got - true).max() <= SPARSE_TOLERANCE * 1.001
        moving = np.linalg.norm(true, axis=1) > SPARSE_TOLERANCE
        np.testing.assert_allclose(got[moving], true[moving], atol=1e-7)
    assert kinds[0] == 1 and kinds[1] is not None and kinds[1] < len(v) / 3, kinds


def test_quantized_targets_equal_the_float_ones_within_their_step(written, head_model):
    """KHR_mesh_quantization: moves as 16-bit normalized metres are within half a step
    (QUANTIZE_ERROR, 0.015 mm) of the float ones, normal changes within half an 8-bit step; the
    extension is declared required; mimica's reader gives floats back."""
    import pygltflib as gl
    from mimica.mesh.io.gltf import QUANTIZATION, SPARSE_NORMAL, unit_normals
    m = head_model.mesh
    g = gl.GLTF2().load(str(written / "quantized.glb"))
    assert g.extensionsRequired == [QUANTIZATION] and g.extensionsUsed == [QUANTIZATION]
    prim = g.meshes[0].primitives[0]
    v = _vertex_of(g)
    n0 = unit_normals(m, m.vertices)
    far_counts = []
    for t, name in zip(prim.targets[1:], ("eyeBlink_R", "jawOpen")):
        shape = head_model.shape(name)
        pos, nrm = g.accessors[t["POSITION"]], g.accessors[t["NORMAL"]]
        assert (pos.componentType, pos.normalized) == (gl.SHORT, True)
        assert (nrm.componentType, nrm.normalized) == (gl.BYTE, True)
        n1 = unit_normals(m, shape)[v]
        dn = n1 - n0[v]
        got = _accessor(g, t["NORMAL"])
        turned = np.linalg.norm(dn, axis=1) > SPARSE_NORMAL
        near = turned & (np.abs(dn).max(1) <= 1)               # a change normalized bytes hold
        assert np.abs(got[near] - dn[near]).max() <= 0.5 / 127 + 1e-6
        # a normal turned past their reach: at full weight the viewer's normal still points near n1
        far = np.abs(dn).max(1) > 1
        r = n0[v][far] + got[far]
        cos = (r * n1[far]).sum(1) / np.linalg.norm(r, axis=1)
        far_counts.append(int(far.sum()))
        assert far.sum() < 0.01 * len(v) and (cos > np.cos(np.radians(45))).all() and np.median(cos) > 0.999
    assert max(far_counts) > 0                                   # the blink turns some lid normals over
    # against the same targets in floats (sparse.glb), over the bare mesh (head.glb): the targets' bytes halve
    size = {n: (written / f"{n}.glb").stat().st_size for n in ("quantized", "sparse", "head")}
    assert size["quantized"] - size["head"] < 0.6 * (size["sparse"] - size["head"]), size


def test_a_clip_as_a_few_basis_shapes(head_model, tmp_path):
    """export writes a clip as basis shapes and per-frame weights when every vertex stays
    within 0.1 mm: a 40-frame blend of three expressions becomes 3 basis shapes, the frames
    rebuilt from them within the bound; compact=False keeps one target per frame."""
    import pygltflib as gl
    m = head_model.mesh
    t = np.linspace(0, 1, 40)[:, None, None]
    d = [head_model.shape(n) - m.vertices for n in ("mouthSmile_L", "jawOpen", "browDown_R")]
    frames = m.vertices + np.sin(3 * t) * d[0] + t ** 2 * d[1] + np.cos(5 * t) ** 2 * d[2]
    seq = tmp_path / "seq"
    for i, f in enumerate(frames):
        write_mesh(seq / f"f{i}.obj", m.with_vertices(f))
    paths = [seq / f"f{i}.obj" for i in range(len(frames))]
    info = export_sequence(paths, tmp_path / "c.glb", ExportOptions(rest=seq / "f0.obj"))
    assert info["basis"] and info["shapes"] == 3
    assert not export_sequence(paths, tmp_path / "d.glb", ExportOptions(compact=False))["basis"]
    g = gl.GLTF2().load(str(tmp_path / "c.glb"))
    prim, ex = g.meshes[0].primitives[0], g.meshes[0].extras
    assert len(prim.targets) == 3 and len(ex["frames"]) == 40 and ex["maxErrorMetres"] <= 1e-4
    v = _vertex_of(g)
    basis = np.stack([_accessor(g, tg["POSITION"]) for tg in prim.targets])       # metres
    w = _accessor(g, g.animations[0].samplers[0].output).reshape(40, 3)
    rebuilt = np.einsum("fk,knd->fnd", w, basis)
    true = 0.01 * (frames - frames[0])[:, v]
    assert np.linalg.norm(rebuilt - true, axis=2).max() <= 1e-4 + 2e-5            # 0.1 mm (+ sparse/float32)
    assert (tmp_path / "c.glb").stat().st_size * 5 < (tmp_path / "d.glb").stat().st_size
    r = validate([tmp_path / "c.glb"])[0]
    assert r["errors"] == 0 and r["warnings"] == 0, r["messages"]


def test_a_slit_that_moves_apart_is_not_welded(written, tmp_path):
    """Read as another writer's file (mimica's vertex maps taken out), a head whose mouth
    `blendshapes` cut keeps the cut: the lips' copies coincide at rest but move apart in its
    morph targets, so they stay two vertices, each with its own target (the same rows as mimica's
    own reading); without the targets the same copies are one surface's seam, welded."""
    from mimica.mesh.io import UNITS, read_morph_targets
    from mimica.mesh.io.gltf import UNITS_KEY, VERTEX_MAP, open_for_edit, save_edited
    own, own_t, unit = read_morph_targets(written / "arkit.glb")
    for keep_targets in (True, False):
        _, doc, buf, _ = open_for_edit(written / "arkit.glb")
        for mesh in doc["meshes"]:
            for prim in mesh["primitives"]:
                for key in (VERTEX_MAP, UNITS_KEY):
                    prim.get("extras", {}).pop(key, None)
                if not keep_targets:
                    prim.pop("targets", None)
            if not keep_targets:
                mesh.get("extras", {}).pop("targetNames", None)
                mesh.pop("weights", None)
        save_edited(doc, buf, tmp_path / "other.glb")
        if not keep_targets:
            from mimica.mesh import read_mesh
            assert read_mesh(tmp_path / "other.glb").n_vertices == 468          # the head's own, sealed
            continue
        back, back_t, back_unit = read_morph_targets(tmp_path / "other.glb")   # metres: the file's own
        assert back.n_vertices == own.n_vertices == 479                       # 11 lip vertices cut

        def rows(m, t, k):
            r = k * np.c_[m.vertices, t["jawOpen"] - m.vertices]
            return np.round(r[np.lexsort(r.T[::-1])], 5)
        np.testing.assert_allclose(rows(back, back_t, UNITS[back_unit]), rows(own, own_t, UNITS[unit]), atol=2e-5)
