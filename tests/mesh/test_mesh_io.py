"""Mesh IO: formats round-trip, polygons stay polygons, bad input gives one clear error."""

from __future__ import annotations

import numpy as np
import pytest

from mimica import Mesh, MimicaError, read_mesh, write_mesh
from mimica.data import ict_path

MIXED_OBJ = """# a quad, a triangle and a pentagon, with uv and normals
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 2 0 0
v 2 1 0.5
v 1.5 2 0.2
vt 0 0
vt 1 0
vt 1 1
vt 0 1
vn 0 0 1
f 1/1/1 2/2/1 3/3/1 4/4/1
f 2/1/1 5/2/1 3/3/1
f 3/1/1 5/2/1 6/3/1 7/4/1 4/1/1
"""


@pytest.fixture
def mixed(tmp_path):
    p = tmp_path / "mixed.obj"
    p.write_text(MIXED_OBJ)
    return read_mesh(p)


def test_obj_mixed_polygons_kept(mixed, tmp_path):
    assert list(mixed.face_sizes) == [4, 3, 5]
    assert mixed.uv.shape == (4, 2)
    assert len(mixed.triangles) == 2 + 1 + 3
    out = write_mesh(tmp_path / "again.obj", mixed)
    back = read_mesh(out)
    assert back.same_topology(mixed)
    np.testing.assert_allclose(back.vertices, mixed.vertices)
    np.testing.assert_array_equal(back.face_uv_indices, mixed.face_uv_indices)


def test_obj_variants_without_uv(tmp_path):
    p = tmp_path / "plain.obj"
    p.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1//1 2//1 4//1 3//1\nf -4 -3 -2\n")
    m = read_mesh(p, allow_degenerate=True)
    assert m.uv is None
    assert list(m.face_sizes) == [4, 3]
    np.testing.assert_array_equal(m.faces[1], [0, 1, 2])          # negative (relative) indices


@pytest.mark.parametrize("suffix", [".ply", ".glb", ".gltf"])
def test_other_formats_round_trip(mixed, tmp_path, suffix):
    back = read_mesh(write_mesh(tmp_path / f"m{suffix}", mixed))
    np.testing.assert_allclose(back.vertices, mixed.vertices, atol=1e-6)
    if suffix == ".ply":
        assert back.same_topology(mixed)                       # PLY keeps polygons
    else:
        assert back.n_faces == len(mixed.triangles)            # glTF holds triangles


def test_ict_obj_quads_and_uv():
    m = read_mesh(ict_path("generic_neutral_mesh"))
    assert m.n_vertices == 26719 and m.n_faces == 26384
    assert (m.face_sizes == 4).sum() == 25836 and (m.face_sizes == 3).sum() == 548
    assert m.uv is not None and len(m.face_uv_indices) == len(m.face_indices)


BAD = {
    "nonfinite.obj": ("v 0 0 0\nv 1 nan 0\nv 0 1 0\nf 1 2 3\n", "non-finite"),
    "badindex.obj": ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n", "refers to vertex 9"),
    "empty.obj": ("# nothing\n", "no vertices"),
    "nofaces.obj": ("v 0 0 0\nv 1 0 0\nv 0 1 0\n", "no faces"),
    "degenerate.obj": ("v 0 0 0\nv 1 0 0\nv 2 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 4\n", "degenerate"),
    "garbage.obj": ("v 0 0 zero\nf 1 2 3\n", "line 1"),
    "garbage.ply": ("this is not a ply file\n", "not a readable PLY"),
    "garbage.glb": ("glTF? no\n", "not a readable glTF"),
    "mesh.stl": ("solid x\n", "unknown mesh format"),
}


@pytest.mark.parametrize("name", sorted(BAD))
def test_bad_input_one_line_error_naming_the_file(tmp_path, name):
    text, needle = BAD[name]
    p = tmp_path / name
    p.write_text(text)
    with pytest.raises(MimicaError) as e:
        read_mesh(p)
    msg = str(e.value)
    assert str(p) in msg and needle in msg and "\n" not in msg


def test_missing_and_unreadable_file(tmp_path):
    with pytest.raises(MimicaError, match="no such file"):
        read_mesh(tmp_path / "absent.obj")
    d = tmp_path / "dir.obj"
    d.mkdir()
    with pytest.raises(MimicaError, match="dir.obj"):
        read_mesh(d)


def test_write_is_atomic(tmp_path, mixed, monkeypatch):
    """A failure while writing leaves no file behind, not even a partial one."""
    import mimica.mesh.io as io

    def boom(mesh, path):
        path.write_text("partial")
        raise RuntimeError("disk full")
    monkeypatch.setattr(io, "write_obj", boom)
    out = tmp_path / "written"
    with pytest.raises(RuntimeError):
        write_mesh(out / "out.obj", mixed)
    assert list(out.iterdir()) == []


def test_mesh_derived_topology():
    sq = Mesh.from_faces(np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.0]]), [[0, 1, 2, 3]])
    assert sq.edges.tolist() == [[0, 1], [0, 3], [1, 2], [2, 3]]     # no fan diagonal
    np.testing.assert_allclose(sq.vertex_normals(), [[0, 0, 1]] * 4)


def test_welded_merges_exact_copies_only():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [1, 0, 0], [0, 1, 0]], float)
    seam = Mesh.from_faces(v, [[0, 1, 2], [4, 3, 5]])          # 4, 5: copies of 1, 2
    w, index = seam.welded()
    assert w.n_vertices == 4 and index.tolist() == [0, 1, 2, 3, 1, 2]
    np.testing.assert_array_equal(w.vertices[index], seam.vertices)
    assert w.triangles.tolist() == [[0, 1, 2], [1, 3, 2]]
    apart = seam.with_vertices(v + np.array([[0, 0, 0]] * 4 + [[1e-12, 0, 0]] * 2))   # a slit: not welded
    assert apart.welded()[0] is apart


def test_pieces_touching_at_a_point_are_not_welded():
    """Two pieces sharing a point but no edge (a lash's root on a shell, a shell's corner on the
    lid: ICT's whole mesh has 10 such points) stay apart: welded, they made one piece of skin,
    lashes and shells (940 of ICT's lash and shell vertices solved as skin).  A fan of copies
    round a point (a split pole) is welded: its copies share edges once welded."""
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 0], [-1, 0, 0], [0, -1, 0]], float)
    touch = Mesh.from_faces(v, [[0, 1, 2], [3, 4, 5]])          # 3 coincides with 0, nothing else
    assert touch.welded()[0] is touch
    ring = np.array([[np.cos(a), np.sin(a), 0] for a in np.linspace(0, 2 * np.pi, 6, endpoint=False)])
    pole = np.r_[ring, np.zeros((6, 3))]                          # 6 copies of the centre, one a face
    fan = Mesh.from_faces(pole, [[6 + i, i, (i + 1) % 6] for i in range(6)])
    w, index = fan.welded()
    assert w.n_vertices == 7 and len(set(index[6:].tolist())) == 1


def test_ply_keeps_the_uv(head_model, tmp_path):
    """PLY with uv: written per face corner (MeshLab's "texcoord" lists), so the
    vertices keep their order across uv seams; read back, every corner has its uv. A PLY with
    per-vertex s/t (as other tools write) is read too."""
    from plyfile import PlyData, PlyElement
    from mimica.mesh import read_mesh, write_mesh
    m = head_model.mesh
    write_mesh(tmp_path / "head.ply", m)
    back = read_mesh(tmp_path / "head.ply")
    assert back.n_vertices == m.n_vertices
    np.testing.assert_array_equal(back.face_indices, m.face_indices)
    np.testing.assert_allclose(back.uv[back.face_uv_indices], m.uv[m.face_uv_indices], atol=1e-6)
    v = np.zeros(3, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("s", "f4"), ("t", "f4")])
    v["x"], v["y"], v["s"], v["t"] = [0, 1, 0], [0, 0, 1], [0.1, 0.9, 0.1], [0.2, 0.2, 0.8]
    f = np.empty(1, dtype=[("vertex_indices", "O")])
    f["vertex_indices"] = [np.array([0, 1, 2], np.int32)]
    PlyData([PlyElement.describe(v, "vertex"), PlyElement.describe(f, "face")]).write(str(tmp_path / "st.ply"))
    tri = read_mesh(tmp_path / "st.ply")
    np.testing.assert_allclose(tri.uv[tri.face_uv_indices], [[0.1, 0.2], [0.9, 0.2], [0.1, 0.8]], atol=1e-6)


def test_unique_rows_groups_as_numpy_does():
    """mesh.core.unique_rows: the groups, first rows and counts of np.unique(axis=0), on floats with
    -0.0 and NaN rows and on integer pairs."""
    from mimica.mesh.core import unique_rows
    rng = np.random.default_rng(0)
    for trial in range(60):
        n, k = int(rng.integers(1, 300)), int(rng.integers(1, 6))
        key = rng.integers(0, 4, (n, k)).astype(float) if trial % 2 else rng.integers(0, 5, (n, k))
        if key.dtype.kind == "f":
            key[rng.integers(0, n, 3)] = -0.0
            key[rng.integers(0, n, 2), 0] = np.nan
        _, first, inverse, counts = np.unique(key, axis=0, return_index=True, return_inverse=True, return_counts=True)
        got = unique_rows(key)
        assert all(np.array_equal(a, b) for a, b in zip((first, inverse.ravel(), counts), got)), trial
    for empty in (np.zeros((0, 2), np.int64), np.zeros((0, 3))):       # no rows: no groups
        assert all(len(a) == 0 for a in unique_rows(empty))
