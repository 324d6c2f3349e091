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
