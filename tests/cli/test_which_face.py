"""Photos with several faces: `landmarks --list` numbers them by size,
`--face N` picks one for `landmarks` and `transfer-image`; a face that is not there gives one
line and writes nothing."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from mimica.cli import main

YALE = Path(os.environ["MIMICA_DATA"]) / "yalefaces"


@pytest.fixture(scope="module")
def two(tmp_path_factory):
    """Two Yale portraits side by side, the second two thirds the size: (path, its box)."""
    from PIL import Image
    a = Image.open(YALE / "subject01.noglasses.gif").convert("RGB")
    b = Image.open(YALE / "subject02.noglasses.gif").convert("RGB")
    b = b.resize((b.width * 2 // 3, b.height * 2 // 3))
    w = Image.new("RGB", (a.width + b.width + 20, a.height), (128, 128, 128))
    at = (a.width + 20, (a.height - b.height) // 2)
    w.paste(a, (0, 0))
    w.paste(b, at)
    path = tmp_path_factory.mktemp("two") / "two.png"
    w.save(path)
    return path, (at[0], at[1], at[0] + b.width, at[1] + b.height)


def test_list_and_pick_a_face(two, tmp_path, capsys):
    path, box = two
    capsys.readouterr()
    assert main(["landmarks", str(path), "--list"]) == 0
    said = capsys.readouterr().err
    assert "2 face(s), by size; 0:" in said and "; 1:" in said, said
    assert main(["landmarks", str(path), "--face", "1", "--out", str(tmp_path / "p.json")]) == 0
    pts = np.array(json.loads((tmp_path / "p.json").read_text())["points"])
    assert (pts[:, 0] > box[0]).all() and (pts[:, 0] < box[2]).all()       # on the smaller, right face
    capsys.readouterr()
    assert main(["landmarks", str(path), "--face", "2", "--out", str(tmp_path / "q.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no face 2: 2 found" in err[0] and not (tmp_path / "q.json").exists()


def test_transfer_image_onto_the_asked_face(two, tmp_path, capsys):
    """--face 1: the expression lands on the second face; the first stays within one grey
    level; a face that is not there: one line, nothing written."""
    from mimica.image import read_image
    path, box = two
    out = tmp_path / "out"
    assert main(["transfer-image", str(YALE / "subject03.normal.gif"), str(YALE / "subject03.happy.gif"),
                 "--target", str(path), "--face", "1", "--out", str(out)]) == 0
    before = read_image(path) * 255
    after = read_image(out / "subject03.happy.png") * 255
    if before.ndim == 3 and after.ndim == 2:
        before = before.mean(2)
    diff = np.abs(after.astype(float) - before.astype(float))
    diff = diff.max(-1) if diff.ndim == 3 else diff
    first = diff[:, :box[0] - 20]                          # the first portrait, left of the gap
    assert first.max() <= 1.0 and diff[box[1]:box[3], box[0]:box[2]].max() > 20
    capsys.readouterr()
    assert main(["transfer-image", str(YALE / "subject03.normal.gif"), str(YALE / "subject03.happy.gif"),
                 "--target", str(path), "--face", "3", "--out", str(tmp_path / "bad")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no face 3" in err[0] and "--list" in err[0] and not (tmp_path / "bad").exists()
