"""Shared fixtures: real data from the configurable data directory ($MIMICA_DATA)."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

# one data setting for the tests, also when they run against an installed wheel (CI): the
# shared data beside this checkout unless MIMICA_DATA says otherwise
os.environ.setdefault("MIMICA_DATA", str(Path(__file__).resolve().parents[2] / "shared" / "data"))
# FBX goes through Blender: the tests' Blender is .venv-blender's bpy (`make blender`; CI makes it)
_BLENDER = Path(__file__).resolve().parents[1] / ".venv-blender" / "bin" / "python"
if _BLENDER.is_file():
    os.environ.setdefault("MIMICA_BLENDER_PYTHON", str(_BLENDER))
# the repository's tools (the viewer's browser harness, tools/viewer_probe.py) for the tests
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))

from mimica.data import ICT_FACE_AREA_VERTICES, ICT_HEAD_VERTICES, ICTModel, data_dir  # noqa: E402


def pytest_report_header(config):
    return f"mimica data directory: {data_dir()}"


@pytest.fixture(scope="session")
def head_model():
    """ICT-FaceKit face + head and neck (11,248 vertices)."""
    return ICTModel(ICT_HEAD_VERTICES)


@pytest.fixture(scope="session")
def full_model():
    return ICTModel()


@pytest.fixture(scope="session")
def face():
    """ICT's face area (its 9,409 vertices), the model the simulation tests drive."""
    return ICTModel(ICT_FACE_AREA_VERTICES)


@pytest.fixture(scope="session")
def head_glb(tmp_path_factory):
    """The shared 468-vertex head's ARKit blendshapes, as `mimica blendshapes` writes them."""
    from mimica.pipeline import make_blendshapes
    d = tmp_path_factory.mktemp("head_arkit")
    data = Path(os.environ["MIMICA_DATA"]) / "real-heads" / "mediapipe-canonical"
    return make_blendshapes(data / "head.obj", d / "head_arkit.glb").path


@pytest.fixture(scope="session")
def mediapipe():
    """MediaPipe's face landmarker is there (the `photo` extra); skipped without it, except in CI."""
    if os.environ.get("CI") is None:
        pytest.importorskip("mediapipe")
    return True


def _blender_export(tmp_path_factory, suffix, mode="export"):
    """ICT-FaceKit's identity001 through Blender's OBJ importer and its glTF or FBX exporter."""
    from helpers import blender_files
    d = tmp_path_factory.mktemp("blender_head")
    blender_files(mode, Path(os.environ["MIMICA_DATA"]) / "ict-facekit" / "FaceXModel" / "identity001.obj",
                  d / f"head{suffix}")
    return d / f"head{suffix}"


@pytest.fixture(scope="session")
def blender_head(tmp_path_factory):
    """Blender's GLB (defaults) of ICT's identity001."""
    return _blender_export(tmp_path_factory, ".glb")


@pytest.fixture(scope="session")
def blender_draco_head(tmp_path_factory):
    """Blender's GLB of ICT's identity001 with its Draco mesh compression on (its defaults else)."""
    return _blender_export(tmp_path_factory, ".glb", "export-draco")


@pytest.fixture(scope="session")
def blender_fbx(tmp_path_factory):
    """Blender's FBX (defaults) of ICT's identity001."""
    return _blender_export(tmp_path_factory, ".fbx")

