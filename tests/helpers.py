"""What several test folders share (a library's tests and the command line's): heads made from ICT
(held-out identities, a patch of skin, a remeshed scan, sealed lips), rendered frames of a jaw
opening, a batch studio and its manifest, the Khronos glTF-Validator, a Live Link Face take, the
Blenders the tests drive, the command run as a child.  tests/ is on the path through its conftest."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mimica.export import ARKIT_52

ROOT = Path(__file__).resolve().parents[1]
TOOLS = ROOT / "tools" / "gltf"

# the Blenders the tests run: 4.5 LTS and the current 5.x, each bpy in a venv of its own
BLENDERS = {"4.5": ".venv-blender", "5.0": ".venv-blender5"}

ROTATIONS = ["HeadYaw", "HeadPitch", "HeadRoll", "LeftEyeYaw", "LeftEyePitch", "LeftEyeRoll",
             "RightEyeYaw", "RightEyePitch", "RightEyeRoll"]


def run_mimica(*args) -> subprocess.CompletedProcess:
    """`python -m mimica.cli ARGS` in a child process, its output captured as text."""
    return subprocess.run([sys.executable, "-m", "mimica.cli", *map(str, args)], capture_output=True, text=True)


def validate(paths) -> list[dict]:
    """The glTF-Validator's report of each file (tools/gltf); fails under CI when it is missing."""
    node = shutil.which("node")
    if node is None or not (TOOLS / "node_modules" / "gltf-validator").is_dir():
        if os.environ.get("CI"):
            pytest.fail("the glTF-Validator is missing in CI: `make test` installs it with npm (tools/gltf)")
        pytest.skip("Node.js or tools/gltf/node_modules missing (make test installs the validator)")
    run = subprocess.run([node, str(TOOLS / "validate.mjs"), *map(str, paths)], capture_output=True, text=True,
                         timeout=300, check=True)
    return [json.loads(line) for line in run.stdout.splitlines()]


def gltfpack(*args) -> None:
    """meshoptimizer's gltfpack (tools/gltf, npm) run on its arguments; fails under CI when it is missing."""
    node = shutil.which("node")
    cli = TOOLS / "node_modules" / "gltfpack" / "cli.js"
    if node is None or not cli.is_file():
        if os.environ.get("CI"):
            pytest.fail("gltfpack is missing in CI: `make test` installs it with npm (tools/gltf)")
        pytest.skip("Node.js or tools/gltf/node_modules/gltfpack missing (make test installs it)")
    run = subprocess.run([node, str(cli), *map(str, args)], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:] + run.stdout[-2000:]


def live_link_csv(path, weights, start="13:32:48:00"):
    """A take as Live Link Face writes it: Timecode at 60 fps, BlendShapeCount, PascalCase names."""
    h, m, s, _ = start.split(":")
    lines = [",".join(["Timecode", "BlendShapeCount"] + [n[0].upper() + n[1:] for n in ARKIT_52] + ROTATIONS)]
    for f, w in enumerate(weights):
        sec, fr = divmod(f, 60)
        tc = f"{h}:{m}:{int(s) + sec:02d}:{fr:02d}.{(37 * f) % 1000:03d}"
        lines.append(",".join([tc, "61"] + [f"{x:.6f}" for x in w] + ["0.01"] * len(ROTATIONS)))
    Path(path).write_text("\n".join(lines) + "\n")


def blender_python(version: str = "4.5") -> str:
    """The Python with Blender `version`'s bpy; fails under CI when it is missing."""
    exe = (os.environ.get("MIMICA_BLENDER_PYTHON") if version == "4.5" else None) or \
        str(ROOT / BLENDERS[version] / "bin" / "python")
    if not Path(exe).is_file():
        if os.environ.get("CI"):
            pytest.fail(f"Blender {version}'s bpy is missing in CI: `make test` installs it into "
                        f"{BLENDERS[version]} under CI")
        pytest.skip(f"no Python with Blender {version}'s bpy ({BLENDERS[version]}; make blender)")
    return exe


def held_out_identity(model, seed):
    """Identities no parameter was tuned on (seeds >= 100; the benchmark uses 1000+)."""
    rng = np.random.default_rng(seed)
    return model.identity(rng.normal(0, 0.8, 20))


def skin_patch(model, radius):
    """A real piece of skin: the ICT face polygons within `radius` cm of the right mouth
    corner, and its border nodes."""
    from mimica.data import ICT_FACE_AREA_FACES, ICT_LANDMARKS_68
    m = model.mesh
    c = m.vertices[ICT_LANDMARKS_68[48]]
    near = np.linalg.norm(m.face_centroids()[:ICT_FACE_AREA_FACES] - c, axis=1) < radius
    sub, _ = m.submesh(np.nonzero(near)[0])
    return sub, sub.boundary_vertices()


def remeshed_scan(model, seed):
    """A held-out identity's face area resampled to ~11k vertices of its own topology, holes at
    the eyes, nostrils and mouth: (identity vertices, the Resampled, its landmarks)."""
    from mimica.correspond.remesh import resample_face
    from mimica.data import ICT_FACE_AREA_FACES, ICT_LANDMARKS_68
    from mimica.landmarks import Landmarks
    tv = held_out_identity(model, seed)
    face, _ = model.mesh.with_vertices(tv).submesh(np.arange(ICT_FACE_AREA_FACES))
    rs = resample_face(face, tv[ICT_LANDMARKS_68], n_vertices=11000, seed=seed)
    return tv, rs, Landmarks.snap(rs.mesh, tv[ICT_LANDMARKS_68])


def sealed_lips(model):
    """ICT's identity014 remeshed with its lips sealed: (mesh, landmarks), the inner lips' points
    a little inside their own lip (on sealed lips the closest point of both is on the seam, on
    either side of a cut)."""
    from mimica.align import face_cylinder
    from mimica.correspond.remesh import resample_face
    from mimica.data import ICT_LANDMARKS_68
    from mimica.landmarks import Landmarks
    tv = model.identity("identity014")
    orig = model.mesh.with_vertices(tv)
    rs = resample_face(orig, tv[ICT_LANDMARKS_68], n_vertices=10000, seed=5, seal=("mouth",))
    pts = tv[ICT_LANDMARKS_68].copy()
    up = face_cylinder(pts).axes[1]
    d = 0.03 * np.linalg.norm(pts[45] - pts[36])
    pts[[61, 62, 63]] += d * up
    pts[[65, 66, 67]] -= d * up
    return rs.mesh, Landmarks.snap(rs.mesh, pts)


def ramp(frames, start, length, peak):
    """A weight rising from 0 to `peak` and back over `length` frames from `start` (sin^2)."""
    w = np.zeros(frames)
    w[start:start + length] = peak * np.sin(np.linspace(0, np.pi, length)) ** 2
    return w


def jaw_frames(folder, jaw, blank=(), size=(320, 400), shape="jawOpen"):
    """Rendered frames of ICT's face opening its jaw by `jaw` (one a frame; or making another of
    ICT's shapes); frames in `blank` show no face (the background alone)."""
    from mimica.image.ictphotos import ICTPhotos
    from mimica.image.io import write_image
    photos = ICTPhotos(size=size)
    folder.mkdir()
    for f, a in enumerate(jaw):
        img = np.full((size[1], size[0], 3), 0.8) if f in blank else \
            photos.photo(np.zeros(20), shape if a > 0 else None, amount=max(a, 1e-9))[0]
        write_image(folder / f"f{f:03d}.png", img)
    return folder


def landmark_error(pts, truth):
    """Median distance of 68 points from the truth, over the eyes' outer corners' distance."""
    return float(np.median(np.linalg.norm(pts - truth, axis=1)) / np.linalg.norm(truth[36] - truth[45]))


BATCH_FRAMES = ("jawOpen", "mouthSmile_L", "eyeBlink_L", "browInnerUp_R")
BATCH_HEADS = 'ids = { glob = "heads/id*.obj" }\nscan = { mesh = "heads/scan.obj", landmarks = "heads/scan.json" }'


def batch_studio(m, d):
    """Two ICT identities, a remeshed head of its own topology with its landmark file, a corrupt
    head; a performance of four expressions of ICT's neutral; an ARKit-free manifest."""
    from mimica.correspond.remesh import resample_face
    from mimica.data import ICT_FACE_AREA_FACES, ICT_LANDMARKS_68
    from mimica.landmarks import write_landmarks
    from mimica.mesh import write_mesh
    (d / "heads").mkdir()
    (d / "perf" / "talk").mkdir(parents=True)
    write_mesh(d / "perf" / "neutral.obj", m.mesh)
    for i, s in enumerate(BATCH_FRAMES):
        write_mesh(d / "perf" / "talk" / f"f{i}.obj", m.mesh.with_vertices(m.shape(s)))
    for k, name in enumerate(("identity003", "identity011")):
        write_mesh(d / "heads" / f"id{k}.obj", m.mesh.with_vertices(m.identity(name)))
    tv = m.identity("identity007")
    face, _ = m.mesh.with_vertices(tv).submesh(np.arange(ICT_FACE_AREA_FACES))
    rs = resample_face(face, tv[ICT_LANDMARKS_68], n_vertices=5000, seed=2)
    write_mesh(d / "heads" / "scan.obj", rs.mesh)
    write_landmarks(d / "heads" / "scan.json", tv[ICT_LANDMARKS_68])
    (d / "heads" / "broken.obj").write_text("v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n")
    return d


def batch_manifest(d: Path, heads: str, extra: str = "") -> Path:
    """A batch manifest of the studio's heads (`heads`, TOML) x its performance: transfer, then export."""
    p = d / f"jobs-{abs(hash((heads, extra))) % 10**8}.toml"
    p.write_text(f"""
[heads]
{heads}

[performances]
talk = {{ neutral = "perf/neutral.obj", frames = "perf/talk" }}

[jobs.talk]
run = "transfer"

[jobs.clip]
run = "export"
from = "talk"
{extra}
""")
    return p


def batch_outputs(out: Path) -> dict:
    """Every output file's vertices (meshes) or bytes (others), by relative path."""
    from mimica.mesh import read_mesh
    got = {}
    for f in sorted(out.rglob("*")):
        rel = f.relative_to(out)
        if f.is_dir() or rel.parts[0] in (".batch", "batch.json") or rel.name.startswith("."):
            continue
        got[str(rel)] = read_mesh(f).vertices if f.suffix == ".obj" else f.read_bytes()
    return got


def blender_files(*args, timeout=600, version="4.5"):
    """tools/blender_files.py run in Blender `version`'s Python (export, import, ...)."""
    run = subprocess.run([blender_python(version), str(ROOT / "tools" / "blender_files.py"), *map(str, args)],
                         stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=timeout)
    assert run.returncode == 0, run.stderr[-3000:] + run.stdout[-2000:]


def same_objects(a, b, path="gltf"):
    """Where two of pygltflib's object trees differ (None: nowhere): dataclasses field by field,
    Attributes by their dicts, everything else by type and value."""
    import dataclasses
    import pygltflib as gl
    if dataclasses.is_dataclass(a) and dataclasses.is_dataclass(b):
        return next((d for f in dataclasses.fields(a)
                     if (d := same_objects(getattr(a, f.name), getattr(b, f.name), f"{path}.{f.name}"))), None)
    if isinstance(a, gl.Attributes) or isinstance(b, gl.Attributes):
        return None if type(a) is type(b) and a.__dict__ == b.__dict__ else f"{path}: {a!r} != {b!r}"
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        return next((d for i, (x, y) in enumerate(zip(a, b)) if (d := same_objects(x, y, f"{path}[{i}]"))), None)
    return None if type(a) is type(b) and a == b else f"{path}: {a!r} != {b!r}"
