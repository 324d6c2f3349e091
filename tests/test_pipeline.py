"""The pipeline layer (mimica.pipeline): each job callable from Python, with the same result and
the same defaults as the command line that calls it."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from mimica.errors import MimicaError
from mimica.pipeline import BlendshapesOptions, make_blendshapes

HEAD = Path(os.environ["MIMICA_DATA"]) / "real-heads" / "mediapipe-canonical" / "head.obj"


def test_blendshapes_from_python_is_the_command_lines(head_glb, tmp_path):
    """A GLB written from Python carries what `animate` reads (the landmarks `--video` fits, the
    pivot the head turns about), and its shapes are the command line's."""
    from mimica.export.extras import stored_head
    from mimica.export.video import landmark_basis
    from mimica.mesh.io import read_morph_targets
    progress = []
    r = make_blendshapes(HEAD, tmp_path / "py.glb", progress=progress.append)
    assert r.path.is_file() and r.landmarks_found and r.written["kind"] == "gltf"
    assert any("transferring 52 shapes" in p for p in progress)
    a, b = landmark_basis(r.path), landmark_basis(head_glb)
    assert np.array_equal(a.rest, b.rest) and np.array_equal(a.motion, b.motion)
    mesh, targets, _ = read_morph_targets(r.path)
    _, cli_targets, _ = read_morph_targets(head_glb)
    assert set(targets) == set(cli_targets) and all(np.array_equal(targets[n], cli_targets[n]) for n in targets)
    assert len(stored_head(mesh.layout.extras)["pivot"]) == 3


def test_blendshapes_refuses_an_unknown_file_kind_before_the_work(tmp_path):
    calls = []
    with pytest.raises(MimicaError, match="glTF"):
        make_blendshapes(HEAD, tmp_path / "head.stl", progress=calls.append)
    assert not calls and not (tmp_path / "head.stl").exists()
    with pytest.raises(MimicaError, match="FBX is written back"):
        make_blendshapes(HEAD, tmp_path / "head.fbx")


def test_the_command_line_takes_its_blendshapes_defaults_from_the_pipeline():
    from dataclasses import fields
    from mimica.cli import build_parser
    a = build_parser().parse_args(["blendshapes", "head.obj", "--out", "x.glb"])
    d = BlendshapesOptions()
    given = {"landmarks": a.landmarks, "cut_mouth": a.cut_mouth == "auto", "cut_eyes": a.cut_eyes == "auto",
             "match": a.match, "units": a.units, "quantize": a.quantize}
    assert given == {f.name: getattr(d, f.name) for f in fields(d)}
