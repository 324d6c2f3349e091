"""USD: export and blendshapes write UsdSkel blend shapes and a SkelAnimation
(usd-core), with metersPerUnit and upAxis set; baked by UsdSkel itself, the animation gives the
clip's frames back."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from mimica.cli import main
from mimica.mesh import plane_grid, write_mesh

try:
    import pxr  # noqa: F401
except ImportError:
    if os.environ.get("CI"):                     # the test extra installs usd-core: CI must have it
        raise
    pytest.skip("usd-core is not installed (pip install 'mimica[usd]')", allow_module_level=True)


def _clip(tmp_path, n=12):
    grid = plane_grid(8, 8, 10.0, 10.0)                          # 10 units: taken as metres
    seq = tmp_path / "seq"
    frames = []
    for i in range(n):
        v = grid.vertices.copy()
        v[:, 2] = 0.3 * np.sin(i / 3) * np.sin(v[:, 0]) + 0.2 * (i / n) ** 2 * np.cos(v[:, 1])
        frames.append(v)
        write_mesh(seq / f"f{i}.obj", grid.with_vertices(v))
    return seq, grid, np.stack(frames)


@pytest.mark.parametrize("compact", ["auto", "off"])
def test_exported_clip_bakes_back_to_its_frames(tmp_path, capsys, compact):
    from pxr import Usd, UsdGeom, UsdSkel
    seq, grid, frames = _clip(tmp_path)
    out = tmp_path / "clip.usda"
    capsys.readouterr()
    assert main(["export", str(seq), "--rest", str(seq / "f0.obj"), "--out", str(out), "--fps", "24",
                 "--units", "cm", "--compact", compact]) == 0
    said = capsys.readouterr().err
    assert ("basis blend shapes" in said) == (compact == "auto") and "metersPerUnit 0.01" in said, said
    stage = Usd.Stage.Open(str(out))
    assert UsdGeom.GetStageMetersPerUnit(stage) == pytest.approx(0.01) and UsdGeom.GetStageUpAxis(stage) == "Y"
    assert stage.GetTimeCodesPerSecond() == 24 and stage.GetEndTimeCode() == len(frames) - 1
    assert UsdSkel.BakeSkinning(stage.Traverse())
    points = UsdGeom.Mesh(stage.GetPrimAtPath("/Head/Mesh")).GetPointsAttr()
    for f in range(len(frames)):
        got = np.array(points.Get(Usd.TimeCode(f)))
        assert np.abs(got - frames[f]).max() < 0.01 + 1e-4, f          # 0.1 mm in cm, and float32


def test_blendshapes_as_usd(tmp_path, capsys):
    from pxr import Usd, UsdGeom, UsdSkel
    from mimica.export import ARKIT_52
    data = Path(os.environ["MIMICA_DATA"]) / "real-heads" / "mediapipe-canonical"
    out = tmp_path / "head.usd"
    assert main(["blendshapes", str(data / "head.obj"), "--out", str(out)]) == 0
    stage = Usd.Stage.Open(str(out))
    assert UsdGeom.GetStageMetersPerUnit(stage) == pytest.approx(0.01)
    bind = UsdSkel.BindingAPI(stage.GetPrimAtPath("/Head/Mesh"))
    assert list(bind.GetBlendShapesAttr().Get()) == ARKIT_52
    assert len(bind.GetBlendShapeTargetsRel().GetTargets()) == 52
    jaw = UsdSkel.BlendShape(stage.GetPrimAtPath("/Head/Mesh/jawOpen"))
    assert len(jaw.GetOffsetsAttr().Get()) == len(jaw.GetPointIndicesAttr().Get()) > 20
    assert not list(tmp_path.glob(".*part*"))                            # written atomically


def test_format_usd_names_the_file(tmp_path, head_model, capsys):
    """`export DIR --format usd --out anim` writes anim.usd (as --out anim.usd does); a suffix and
    a --format that disagree are refused in one line."""
    from mimica.cli import main
    from mimica.mesh import write_mesh
    frames = tmp_path / "frames"
    frames.mkdir()
    for i, name in enumerate(("jawOpen", "mouthSmile_L")):
        write_mesh(frames / f"f{i}.obj", head_model.mesh.with_vertices(head_model.shape(name)))
    assert main(["export", str(frames), "--format", "usd", "--out", str(tmp_path / "anim")]) == 0
    assert (tmp_path / "anim.usd").is_file()
    capsys.readouterr()
    assert main(["export", str(frames), "--format", "usd", "--out", str(tmp_path / "anim.glb")]) == 2
    assert "say the format once" in capsys.readouterr().err and not (tmp_path / "anim.glb").exists()
