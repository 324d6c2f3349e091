"""The Blender add-on (issue 17, part 5; mimica/blender_addon.py).

Blender's Python needs numpy < 2 and mimica numpy >= 2, so the add-on runs the mimica command
and reads its .npz; its own parts are tested here without Blender.  Its Blender half (the two
operators, driven headless with the bpy 4.5 package in a venv of its own) was checked by hand
(docs/benchmarks.md); a test of it under pytest hung in this session and is not in the suite."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from mimica import blender_addon as addon
from mimica.cli import main
from mimica.export import ARKIT_52
from mimica.export.take import read_take
from test_take import live_link_csv

HEAD = Path(os.environ["MIMICA_DATA"]) / "real-heads" / "mediapipe-canonical" / "head.obj"


def test_the_addon_reads_takes_as_mimica_does(tmp_path):
    assert addon.ARKIT == ARKIT_52                     # its own copy: Blender's Python cannot import mimica
    w = np.random.default_rng(1).uniform(0, 1, (30, 52))
    live_link_csv(tmp_path / "take.csv", w)
    t0, w0, _ = read_take(tmp_path / "take.csv")
    t1, w1 = addon.read_take(tmp_path / "take.csv")
    np.testing.assert_allclose(t1, t0, atol=1e-12)
    for n in ARKIT_52:
        np.testing.assert_allclose(w1[n], w0[n])
    lines = (tmp_path / "take.csv").read_text().splitlines()
    (tmp_path / "back.csv").write_text("\n".join([lines[0]] + lines[1:][::-1]))
    with pytest.raises(addon.AddonError, match="does not increase"):
        addon.read_take(tmp_path / "back.csv")


def test_blendshapes_as_arrays_in_the_heads_order(tmp_path):
    from mimica.mesh import read_mesh
    head = read_mesh(HEAD)
    assert main(["blendshapes", str(HEAD), "--cut-mouth", "off", "--out", str(tmp_path / "s.npz")]) == 0
    with np.load(tmp_path / "s.npz") as z:
        np.testing.assert_allclose(z["vertices"], head.vertices)
        assert all(z[n].shape == head.vertices.shape for n in ARKIT_52)
        assert np.abs(z["jawOpen"] - head.vertices).max() > 0.5
