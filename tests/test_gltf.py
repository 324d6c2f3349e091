"""Every kind of GLB and glTF mimica writes passes the Khronos glTF-Validator (npm package
gltf-validator, tools/gltf/) with no error and no warning, and carries smooth normals: unit
NORMAL on the base mesh, and on every morph target the change of the normal."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from mimica.mesh import Mesh, write_glb, write_mesh

TOOLS = Path(__file__).resolve().parents[1] / "tools" / "gltf"


def validate(paths) -> list[dict]:
    node = shutil.which("node")
    if node is None or not (TOOLS / "node_modules" / "gltf-validator").is_dir():
        if os.environ.get("CI"):
            pytest.fail("the glTF-Validator is missing in CI: `make test` installs it with npm (tools/gltf)")
        pytest.skip("Node.js or tools/gltf/node_modules missing (make test installs the validator)")
    run = subprocess.run([node, str(TOOLS / "validate.mjs"), *map(str, paths)], capture_output=True, text=True,
                         timeout=300, check=True)
    return [json.loads(line) for line in run.stdout.splitlines()]


def _accessor(g, i):
    from mimica.mesh.io import _gltf_accessor
    return _gltf_accessor(g, i)


@pytest.fixture(scope="module")
def written(head_model, tmp_path_factory):
    """One file of each kind: mesh (.glb, .gltf; quads triangulated; a vertex no face uses),
    morph targets (blendshapes), morph targets with an animation (export, simulate)."""
    from mimica.cli import main
    d = tmp_path_factory.mktemp("gltf")
    m = head_model.mesh
    write_mesh(d / "head.glb", m)
    write_mesh(d / "head.gltf", m)
    loose = Mesh(np.vstack([m.vertices, m.vertices[:1] + 100.0]), m.face_indices, m.face_starts)
    write_glb(d / "loose.glb", loose)
    frames = d / "frames"
    frames.mkdir()
    for i, name in enumerate(("mouthSmile_L", "jawOpen", "eyeBlink_R")):
        write_mesh(frames / f"f{i}.obj", m.with_vertices(head_model.shape(name)))
    assert main(["export", str(frames), "--out", str(d / "clip.glb"), "--fps", "24"]) == 0
    assert main(["export", str(frames), "--out", str(d / "clip.gltf"), "--fps", "24"]) == 0
    data = Path(os.environ["MIMICA_DATA"]) / "real-heads" / "mediapipe-canonical"
    assert main(["blendshapes", str(data / "head.obj"), "--out", str(d / "arkit.glb")]) == 0
    return d


def test_every_kind_passes_the_validator(written):
    files = sorted(p for p in written.iterdir() if p.suffix in (".glb", ".gltf"))
    assert len(files) == 6
    for r in validate(files):
        assert r["errors"] == 0 and r["warnings"] == 0, (r["path"], r["messages"])
        assert r["info"]["maxAttributes"] >= 2                       # POSITION and NORMAL


def test_normals_are_smooth_and_targets_carry_their_change(written, head_model):
    import pygltflib as gl
    g = gl.GLTF2().load(str(written / "clip.glb"))
    prim = g.meshes[0].primitives[0]
    n0 = _accessor(g, prim.attributes.NORMAL)
    np.testing.assert_allclose(np.linalg.norm(n0, axis=1), 1, atol=1e-6)
    m = head_model.mesh
    base = head_model.shape("mouthSmile_L")                       # export's rest: the first frame
    np.testing.assert_allclose(n0, m.vertex_normals(base), atol=1e-6)
    shape = head_model.shape("jawOpen")
    dn = _accessor(g, prim.targets[1]["NORMAL"])
    np.testing.assert_allclose(n0 + dn, m.vertex_normals(shape), atol=1e-5)
    np.testing.assert_allclose(_accessor(g, prim.targets[1]["POSITION"]), shape - base, atol=1e-5)
