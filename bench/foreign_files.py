"""Benchmark: files other tools wrote, read whole and handed back where they stood.

Run from the project root:  .venv/bin/python bench/foreign_files.py
(Blender's bpy in .venv-blender, `make blender`, makes the DCC's files; MIMICA_BLENDER_PYTHON
names another Python with bpy.)

- vertices_kept / world_err: each file (the Khronos glTF samples in the data directory, and
  Blender's GLB of ICT-FaceKit heads) read and written back with a morph target: the share of
  its vertices whose stored positions come back unchanged, and the largest distance between a
  rest vertex's world position before and after (through the node hierarchy), over the
  head's size (target: 100 %, <= 1e-6).
- shape_dev_median / shape_dev_worst: `blendshapes` on Blender's GLB of a head against
  `blendshapes` on the same head's OBJ: per ARKit shape, the RMS difference of the two
  displacements over the OBJ's largest displacement, median and worst over the shapes
  (targets: <= 0.04, <= 0.10); fbx_shape_dev_median: the same for Blender's FBX, written back
  through Blender.  Baseline in the same run: the GLB with its correspondence found again
  (relayout off: the head not recognized as the source's own mesh in another layout).
"""

from __future__ import annotations

import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from mimica.data import data_dir  # noqa: E402
from mimica.export import ARKIT_52, arkit_blendshapes  # noqa: E402
from mimica.mesh import Mesh, read_mesh  # noqa: E402
from mimica.mesh.io import read_morph_targets, write_fbx_layout  # noqa: E402
from mimica.mesh.io.gltf import _load, read_accessor, write_gltf_layout  # noqa: E402
import mimica  # noqa: E402
mimica.keep_memory()


def blender_python() -> str | None:
    exe = os.environ.get("MIMICA_BLENDER_PYTHON") or str(ROOT / ".venv-blender" / "bin" / "python")
    if Path(exe).is_file():
        os.environ["MIMICA_BLENDER_PYTHON"] = exe            # FBX goes through it too
        return exe
    return None


def blender_export(obj: Path, out: Path) -> None:
    subprocess.run([blender_python(), str(ROOT / "tools" / "blender_files.py"), "export", str(obj), str(out)],
                   check=True, capture_output=True, stdin=subprocess.DEVNULL, timeout=600)


def kept(src: Path, out: Path) -> tuple[int, int, float]:
    """(vertices of src, of them stored unchanged in out, largest world move over the size)."""
    a, b = read_mesh(src), read_mesh(out)
    ga, gb = _load(src), _load(out)
    n = same = 0
    for s in a.layout.sets:
        pa = read_accessor(ga, s.position).reshape(-1, 3)
        pb = read_accessor(gb, gb.meshes[s.mesh].primitives[s.primitives[0]].attributes.POSITION).reshape(-1, 3)
        n += len(pa)
        same += int((pb[:len(pa)] == pa).all(1).sum())
    size = float(np.ptp(a.vertices, axis=0).max())
    return n, same, float(np.abs(b.vertices[:a.n_vertices] - a.vertices).max() / size)


def shape_devs(ref: dict, ref_mesh: Mesh, got: dict, got_mesh: Mesh, match: np.ndarray) -> np.ndarray:
    """Per shape: RMS of (got's displacement - ref's) over ref's largest displacement; got's
    vertex match[i] is ref's vertex i."""
    out = []
    n = ref_mesh.n_vertices
    for name in ARKIT_52:
        d_ref = ref[name][:n] - ref_mesh.vertices[:n]
        big = float(np.linalg.norm(d_ref, axis=1).max())
        if big < 1e-12:
            continue
        d_got = got[name][match] - got_mesh.vertices[match]
        out.append(np.sqrt(((d_got - d_ref) ** 2).sum(1).mean()) / big)
    return np.array(out)


def corner_match(ref: Mesh, got: Mesh) -> np.ndarray:
    """For each vertex of ref, the vertex of got at the same place with the same uv at some corner
    (a DCC's export: the same head in another vertex layout)."""
    def corners(m):
        return np.c_[m.vertices[m.face_indices], m.uv[m.face_uv_indices]], m.face_indices
    kr, vr = corners(ref)
    kg, vg = corners(got)
    scale = np.r_[np.full(3, 1.0 / np.ptp(ref.vertices, axis=0).max()), np.ones(2)]
    d, j = cKDTree(kg * scale).query(kr * scale)
    out = np.full(ref.n_vertices, -1)
    ok = d < 1e-5
    out[vr[ok][::-1]] = vg[j[ok]][::-1]
    if (out < 0).any():                              # by place alone where no corner agrees
        miss = np.nonzero(out < 0)[0]
        out[miss] = cKDTree(got.vertices).query(ref.vertices[miss])[1]
    return out


def main():
    print(f"machine: {platform.machine()}, {platform.system()}, python {platform.python_version()}")
    tmp = Path(tempfile.mkdtemp(prefix="mimica-foreign-"))
    files = sorted((data_dir() / "gltf-samples").glob("*/*.gltf"))
    heads = ["identity001", "identity007"]
    if blender_python() is None:
        print("no Python with Blender's bpy (make blender): the Blender files are left out")
        heads = []
    for h in heads:
        blender_export(data_dir() / "ict-facekit" / "FaceXModel" / f"{h}.obj", tmp / f"{h}.glb")
        files.append(tmp / f"{h}.glb")
    total = same = 0
    worst = 0.0
    for f in files:
        m = read_mesh(f)
        lift = m.vertices + 0.01 * np.ptp(m.vertices, axis=0).max() * np.array([0.0, 1.0, 0.0])
        t0 = time.perf_counter()
        write_gltf_layout(tmp / f"back_{f.stem}.glb", m.layout, m, {"lift": lift})
        t = time.perf_counter() - t0
        n, s, err = kept(f, tmp / f"back_{f.stem}.glb")
        total, same, worst = total + n, same + s, max(worst, err)
        print(f"{f.name}: {len(m.layout.sets)} vertex sets, {n} vertices, {s} kept, world error {err:.1e} of its "
              f"size; written back in {t:.2f}s")
    devs, base, fbx = [], [], []
    for h in heads:
        obj = read_mesh(data_dir() / "ict-facekit" / "FaceXModel" / f"{h}.obj")
        t0 = time.perf_counter()
        ref = arkit_blendshapes(obj)
        t1 = time.perf_counter()
        glb = read_mesh(tmp / f"{h}.glb")
        got = arkit_blendshapes(glb)
        t2 = time.perf_counter()
        match = corner_match(obj, got.mesh)
        d = shape_devs(ref, obj, got, got.mesh, match)
        sh = arkit_blendshapes(glb, relayout=False)
        b = shape_devs(ref, obj, sh, sh.mesh, corner_match(obj, sh.mesh))
        # FBX: read and written back through Blender, read again
        blender_export(data_dir() / "ict-facekit" / "FaceXModel" / f"{h}.obj", tmp / f"{h}.fbx")
        t3 = time.perf_counter()
        head = read_mesh(tmp / f"{h}.fbx")
        shapes = arkit_blendshapes(head)
        write_fbx_layout(tmp / f"{h}_arkit.fbx", head.layout, shapes.mesh, {n: shapes[n] for n in ARKIT_52})
        fm, ft, _ = read_morph_targets(tmp / f"{h}_arkit.fbx")
        t4 = time.perf_counter()
        f = shape_devs(ref, obj, ft, fm, corner_match(obj, fm))
        devs.append(d)
        base.append(b)
        fbx.append(f)
        print(f"{h}: Blender's GLB against the OBJ: shape deviation median {np.median(d):.4f} worst {d.max():.4f}; "
              f"correspondence found again (baseline): median {np.median(b):.3f} worst {b.max():.3f}; FBX through "
              f"Blender: median {np.median(f):.4f} worst {f.max():.4f}; blendshapes {t1 - t0:.1f}s (OBJ) "
              f"{t2 - t1:.1f}s (GLB) {t4 - t3:.1f}s (FBX, read and written through Blender)")
    dev = np.concatenate(devs) if devs else np.array([np.nan])
    fdev = np.concatenate(fbx) if fbx else np.array([np.nan])
    print(f"vertices_kept={same / max(total, 1):.4f} world_err={worst:.1e} shape_dev_median={np.median(dev):.4f} "
          f"shape_dev_worst={np.max(dev):.4f} fbx_shape_dev_median={np.median(fdev):.4f}")


if __name__ == "__main__":
    main()
