"""`mimica transfer` onto heads of other topologies from the command line: what it says of the
correspondence and of sealed lips, and the pictures `--show` draws."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import remeshed_scan, sealed_lips

from mimica.cli import main
from mimica.mesh import read_mesh


@pytest.fixture(scope="module")
def scans(head_model):
    return [remeshed_scan(head_model, 100)]


@pytest.fixture(scope="module")
def sealed(head_model):
    return sealed_lips(head_model)


def test_cli_says_how_the_target_was_matched(head_model, scans, tmp_path, capsys):
    """transfer prints the correspondence's method, its matched and low-confidence shares and
    the paired lids; --match cylinder takes Song's map; --show draws the confidence map."""
    from mimica.image import read_image
    from mimica.landmarks import write_landmarks
    from mimica.mesh import read_mesh, write_mesh
    tv, rs, lt = scans[0]
    write_mesh(tmp_path / "S.obj", head_model.mesh)
    write_mesh(tmp_path / "smile.obj", head_model.mesh.with_vertices(head_model.shape("mouthSmile_L")))
    write_mesh(tmp_path / "T.obj", rs.mesh)
    write_landmarks(tmp_path / "T.json", lt.positions(rs.mesh))
    args = ["transfer", str(tmp_path / "S.obj"), str(tmp_path / "smile.obj"), "--target", str(tmp_path / "T.obj"),
            "--target-landmarks", str(tmp_path / "T.json")]
    out = {}
    for match in ("nicp", "cylinder"):
        capsys.readouterr()
        assert main(args + ["--out", str(tmp_path / match), "--match", match, "--show", str(tmp_path / f"{match}.png")]) == 0
        said = [ln for ln in capsys.readouterr().err.splitlines() if "correspondence (" in ln]
        assert len(said) == 1 and f"correspondence ({match})" in said[0], said
        assert ("low confidence" in said[0]) == (match == "nicp")
        assert "lid rims paired by arc length: right and left eye" in said[0]
        out[match] = read_mesh(tmp_path / match / "smile.obj").vertices
        picture = read_image(tmp_path / f"{match}.png")
        assert picture.shape[1] > 1200                        # two views, the confidence map, the legend
    assert not np.allclose(out["nicp"], out["cylinder"])
    with pytest.raises(SystemExit) as bad:                     # argparse: one line, exit 2
        main(args + ["--out", str(tmp_path / "bad"), "--match", "nearest"])
    assert bad.value.code == 2 and not (tmp_path / "bad").exists()


def test_cli_cuts_sealed_lips_in_one_line(head_model, sealed, tmp_path, capsys):
    from mimica.landmarks import write_landmarks
    from mimica.mesh import write_mesh
    mesh, lm = sealed
    write_mesh(tmp_path / "S.obj", head_model.mesh)
    write_mesh(tmp_path / "jaw.obj", head_model.mesh.with_vertices(head_model.shape("jawOpen")))
    write_mesh(tmp_path / "T.obj", mesh)
    write_landmarks(tmp_path / "T.json", lm.positions(mesh))
    args = ["transfer", str(tmp_path / "S.obj"), str(tmp_path / "jaw.obj"), "--target", str(tmp_path / "T.obj"),
            "--target-landmarks", str(tmp_path / "T.json")]
    capsys.readouterr()
    assert main(args + ["--out", str(tmp_path / "cut"), "--show", str(tmp_path / "seen.png")]) == 0
    said = [ln for ln in capsys.readouterr().err.splitlines() if "lips were sealed" in ln]
    assert len(said) == 1 and "cut apart" in said[0]
    from mimica.image import read_image
    seen = read_image(tmp_path / "seen.png")                     # the parts picture: the seam in red
    red = (seen[..., 0] > 0.8) & (seen[..., 1] < 0.25) & (seen[..., 2] < 0.25)
    assert seen.shape[1] > 800 and red.sum() > 20
    cut = read_mesh(tmp_path / "cut" / "jaw.obj")
    assert cut.n_vertices > mesh.n_vertices and cut.n_faces == mesh.n_faces
    assert main(args + ["--out", str(tmp_path / "shut"), "--cut-mouth", "off"]) == 0
    assert read_mesh(tmp_path / "shut" / "jaw.obj").same_topology(mesh)


def test_cli_says_each_sealed_eye_it_leaves_whole(tmp_path, capsys):
    """The shared 468-vertex head with its own landmarks: its left eye reads open-shaped but is too
    coarse to cut, its right one reads shut; each is said (the shut one went unsaid beside the
    other's line)."""
    import json
    import os
    from pathlib import Path
    from mimica.landmarks import Landmarks, write_landmarks
    d = Path(os.environ["MIMICA_DATA"]) / "real-heads" / "mediapipe-canonical"
    mesh = read_mesh(d / "head.obj")
    lm = Landmarks.from_vertex_indices(mesh, json.loads((d / "head.json").read_text())["landmark_vertices"])
    write_landmarks(tmp_path / "lm.json", lm.positions(mesh))
    capsys.readouterr()
    assert main(["blendshapes", str(d / "head.obj"), "--landmarks", str(tmp_path / "lm.json"),
                 "--out", str(tmp_path / "head.glb")]) == 0
    err = capsys.readouterr().err
    assert "the left eye stays one surface with the lids (fewer than 3 vertices inside" in err, err
    assert "the right eye is one closed surface" in err, err
