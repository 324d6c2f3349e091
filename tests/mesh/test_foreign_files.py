"""Files other tools wrote, read whole and handed back where they stood (mesh.io.gltf, mesh.io.fbx):
the Khronos glTF samples in the data directory, and heads Blender exports (bpy, in .venv-blender
as tests/helpers.py finds it); the commands on them: tests/cli/test_foreign_files_command.py."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from mimica.errors import MimicaError
from mimica.mesh import read_mesh
from mimica.mesh.io.gltf import open_for_edit, read_gltf_layout, read_morph_targets, save_edited, write_gltf_layout
from helpers import same_objects, validate

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


def test_the_json_is_decoded_as_pygltflib_decodes_it(blender_head):
    """mesh.io.gltf_decode makes the objects pygltflib's own decoding makes, on files other tools
    wrote (and tests/mesh/test_gltf.py on mimica's own)."""
    import pygltflib as gl
    from mimica.mesh.io.gltf_decode import fast_gltf_class
    files = sorted(SAMPLES.glob("*/*.gltf")) + [blender_head]
    for f in files:
        assert same_objects(fast_gltf_class()().load(str(f)), gl.GLTF2().load(str(f))) is None, f
    # pygltflib's own: a list's floats as floats, morph targets as dicts, attributes as objects
    g = fast_gltf_class()().load(str(SAMPLES / "AnimatedMorphCube" / "AnimatedMorphCube.gltf"))
    assert isinstance(g.meshes[0].primitives[0].targets[0], dict)
    assert isinstance(g.meshes[0].primitives[0].attributes, gl.Attributes)
    assert all(isinstance(x, float) for x in g.accessors[0].max)


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


def test_a_draco_compressed_blender_glb_is_read_whole(blender_head, blender_draco_head, tmp_path):
    """Blender's GLB with Draco mesh compression (every primitive a Draco stream, quantized on a
    grid of its own box) reads as the same file without it: every primitive, each vertex within a
    step of Draco's grid of where it stands, and the seams between the materials one again (the two
    sides quantized apart are put back together: each material's vertex count the same as the
    uncompressed file's but the lashes', whose thin strands the grid merges or parts in places, and
whose copies left touching at a point only are not welded); said in a
    note.  A stream that does not decode is one line."""
    import json
    import struct
    from scipy.spatial import cKDTree
    plain, draco = read_mesh(blender_head), read_mesh(blender_draco_head)
    assert len(draco.layout.sets) == 12 and draco.n_faces == plain.n_faces
    assert "12 Draco-compressed primitives decoded" in " ".join(draco.layout.notes)
    size = float(np.ptp(plain.vertices, axis=0).max())
    step = size / (2 ** 14 - 1)                       # Blender's default: 14 bits over the largest box
    assert cKDTree(plain.vertices).query(draco.vertices)[0].max() < 2 * step
    assert cKDTree(draco.vertices).query(plain.vertices)[0].max() < 2 * step
    lashes = []
    for k, name in enumerate(plain.group_names):
        n_plain = len(np.unique(plain.faces[plain.groups == k]))
        n_draco = len(np.unique(draco.faces[draco.groups == draco.group_names.index(name)]))
        if name == "M_EyeLashes":                     # 1,602 against 1,568: strands' points moved
            assert abs(n_draco - n_plain) <= 0.03 * n_plain, (name, n_draco, n_plain)   # apart or merged
            lashes = [n_draco - n_plain]
        else:
            assert n_draco == n_plain, (name, n_draco, n_plain)
    assert [draco.n_vertices - plain.n_vertices] == lashes     # every seam between the materials welded
    # the same file with a stream cut short: one line naming the file and the primitive
    data = bytearray(blender_draco_head.read_bytes())
    size_json = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(data[20:20 + size_json])
    view = doc["bufferViews"][doc["meshes"][0]["primitives"][0]["extensions"]["KHR_draco_mesh_compression"]["bufferView"]]
    start = 20 + size_json + 8 + view.get("byteOffset", 0)
    data[start + 16:start + view["byteLength"]] = bytes(view["byteLength"] - 16)
    bad = tmp_path / "bad.glb"
    bad.write_bytes(bytes(data))
    with pytest.raises(MimicaError, match=r"bad.glb: mesh 0, primitive 0: its Draco stream does not decode"):
        read_mesh(bad)


def _rotated(tris: np.ndarray) -> set:
    """A triangle list as a set, each triangle from its smallest index (the winding kept): the
    meshopt codec may rotate triangles."""
    r = np.argmin(tris, 1)
    return set(map(tuple, np.stack([tris[np.arange(len(tris)), (r + k) % 3] for k in range(3)], 1)))


def test_a_meshopt_compressed_gltfpack_glb_is_read_whole(blender_head, head_glb, tmp_path):
    """gltfpack's output (meshoptimizer's tool for the web: quantized, reordered, primitives merged)
    compressed with EXT_meshopt_compression reads as the same output uncompressed: vertices, their
    triangles (each maybe rotated) and morph targets exactly; with its higher compression (the
    octahedral filter on normals, the exponential one on float positions) the same again or within
    its quantization of the original; said in a note.  A stream cut short is one line."""
    import json
    import struct
    from mimica.mesh.io import read_morph_targets
    from helpers import gltfpack
    for src, name in ((blender_head, "ict"), (head_glb, "arkit")):
        gltfpack("-i", src, "-o", tmp_path / f"{name}.glb")
        gltfpack("-i", src, "-o", tmp_path / f"{name}_c.glb", "-c")
        plain, packed = read_mesh(tmp_path / f"{name}.glb"), read_mesh(tmp_path / f"{name}_c.glb")
        assert "meshopt-compressed buffer views decoded" in " ".join(packed.layout.notes)
        np.testing.assert_array_equal(packed.vertices, plain.vertices)
        assert _rotated(packed.triangles) == _rotated(plain.triangles)
    _, t_plain, _ = read_morph_targets(tmp_path / "arkit.glb")
    mesh, t_packed, _ = read_morph_targets(tmp_path / "arkit_c.glb")
    assert len(t_packed) == 52 and all(np.array_equal(t_packed[n], t_plain[n]) for n in t_plain)
    gltfpack("-i", head_glb, "-o", tmp_path / "arkit_cc.glb", "-cc")            # normals octahedral
    cc, t_cc, _ = read_morph_targets(tmp_path / "arkit_cc.glb")

    def rows(m, t):                              # each vertex with its moves, in one order (the files' differ)
        r = np.hstack([m.vertices] + [t[n] for n in sorted(t)])
        return r[np.lexsort(r.T[::-1])]
    np.testing.assert_array_equal(rows(cc, t_cc), rows(mesh, t_packed))
    from mimica.mesh.io.gltf import _load, read_accessor

    def normals(path):                           # each file vertex's normal, in the order of its place and moves
        g = _load(path)
        p = g.meshes[0].primitives[0]
        key = np.hstack([read_accessor(g, p.attributes.POSITION)] + [read_accessor(g, t["POSITION"]) for t in p.targets])
        return read_accessor(g, p.attributes.NORMAL)[np.lexsort(key.T[::-1])]
    n_c, n_cc = normals(tmp_path / "arkit_c.glb"), normals(tmp_path / "arkit_cc.glb")
    assert np.abs(n_cc - n_c).max() < 0.05 and np.abs(np.linalg.norm(n_cc, axis=1) - 1).max() < 0.02
    gltfpack("-i", blender_head, "-o", tmp_path / "ict_cc.glb", "-cc", "-vpf")  # float positions exponential
    from scipy.spatial import cKDTree
    obj = read_mesh(blender_head)
    size = float(np.ptp(obj.vertices, axis=0).max())
    got = read_mesh(tmp_path / "ict_cc.glb")
    assert cKDTree(obj.vertices).query(got.vertices)[0].max() < 1e-4 * size
    assert cKDTree(got.vertices).query(obj.vertices)[0].max() < 1e-4 * size
    data = bytearray((tmp_path / "arkit_c.glb").read_bytes())
    n = struct.unpack_from("<I", data, 12)[0]

    def rewritten(name, edit):                   # the GLB with its JSON edited
        doc = json.loads(data[20:20 + n])
        edit(doc)
        j = json.dumps(doc).encode()
        j += b" " * ((-len(j)) % 4)
        body = struct.pack("<II", len(j), 0x4E4F534A) + j + bytes(data[20 + n:])
        (tmp_path / name).write_bytes(struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body)
        return tmp_path / name
    # the views' own buffer the GLB's chunk, which holds the compressed bytes too: not a placeholder
    one = rewritten("one.glb", lambda d: ([v.update(buffer=0) for v in d["bufferViews"]], d["buffers"].pop()))
    np.testing.assert_array_equal(read_mesh(one).vertices, read_mesh(tmp_path / "arkit.glb").vertices)
    # a compressed view's bytes cut short: one line naming the file and the view
    i = next(i for i, v in enumerate(json.loads(data[20:20 + n])["bufferViews"]) if "extensions" in v)
    bad = rewritten("bad.glb", lambda d: d["bufferViews"][i]["extensions"]["EXT_meshopt_compression"].update(
        byteLength=d["bufferViews"][i]["extensions"]["EXT_meshopt_compression"]["byteLength"] - 7))
    with pytest.raises(MimicaError, match=rf"bad.glb: buffer view {i}: its meshopt-compressed data does not decode"):
        read_mesh(bad)


def test_the_meshopt_bitstream_as_its_specification_gives_it():
    """EXT_meshopt_compression's Appendix A on its own examples: varints (LEB128); the 4-bit sentinel
    group (10 bytes -> -1 -4 -3 26 -91 0 -6 6 -4 -4 5 -5 1 -1 0 0, deltas from the baseline element
    kept at the end of the tail); mode 2's indices, each a zigzag delta from one of two baselines."""
    from mimica.mesh.io.meshopt import _attributes, _indices, _varint
    assert _varint(b"\x7f", 0) == (0x7F, 1) and _varint(b"\x81\x04", 0) == (0x201, 2)
    assert _varint(b"\xff\xa0\x05", 0) == (0x7F | 0x20 << 7 | 0x05 << 14, 3)   # LEB128 (the text's 0x1fd005
    #                                            reads the groups the other way; gltfpack's files decode as LEB128)
    group = bytes([0x17, 0x5F, 0xF0, 0xBC, 0x77, 0xA9, 0x21, 0x00, 0x34, 0xB5])
    baseline = bytes([10, 20, 30, 40])
    stream = bytes([0xA0, 0b10]) + group + bytes([0, 0, 0]) + bytes(28) + baseline   # bytes 1-3 of each: no change
    got = _attributes(stream, 16, 4)
    deltas = np.array([-1, -4, -3, 26, -91, 0, -6, 6, -4, -4, 5, -5, 1, -1, 0, 0])
    np.testing.assert_array_equal(got[:, 0], (10 + np.cumsum(deltas)) % 256)
    assert (got[:, 1:] == [20, 30, 40]).all()
    want = [5, 3, 100, 4, 101, 101, 2]
    which = [0, 1, 0, 1, 0, 0, 1]
    last, data = [0, 0], bytearray([0xD1])
    for i, b in zip(want, which):                  # the encoding Appendix A describes
        d = i - last[b]
        last[b] = i
        v = ((((d << 1) ^ (d >> 31)) & 0x7FFFFFFF) << 1) | b
        while v >= 0x80:
            data += bytes([(v & 0x7F) | 0x80])
            v >>= 7
        data += bytes([v])
    np.testing.assert_array_equal(_indices(bytes(data) + bytes(4), len(want), 4), want)


def test_a_blender_fbx_is_read_whole(blender_fbx):
    """Blender's FBX (in centimetres, its axes converted): every control point, in its place
    (y up, metres), polygons and materials as the OBJ has them."""
    obj = read_mesh(ICT_HEAD)
    head = read_mesh(blender_fbx)
    assert head.same_topology(obj) and set(head.group_names) == set(obj.group_names)
    size = float(np.ptp(obj.vertices, axis=0).max())
    assert np.abs(head.vertices - obj.vertices).max() < 1e-6 * size
