"""Benchmark: the files animators take home, against the one-target-per-frame files
of before, measured in the same run.

Run from the project root:  .venv/bin/python bench/export.py
Data: ICT-FaceKit from the data directory ($MIMICA_DATA).  Figures:

- validator_issues: errors + warnings of the Khronos glTF-Validator (tools/gltf) over every
  GLB kind written here (mesh, blendshapes, a compact clip, a per-frame clip, an animated take)
- clip_mb, clip_ratio, clip_err_mm: a 10 s, 60 fps simulated clip (Kim's muscles on ICT's
  face, `mimica simulate`, whose animation.glb is compact: a few basis shapes and weights), its
  size against the same frames as one morph target each (dense, as mimica wrote it before),
  and the largest distance of a vertex from the clip.  Also printed: ICT's expressions blended
  over 600 frames on its whole 26,719-vertex mesh, the same way (rank 6: exact).
- arkit_mb: the 52 ARKit shapes on ICT's own generic mesh (`blendshapes --quantize`:
  KHR_mesh_quantization; the float file's size is printed too)
- video_weights_err, video_fps: ARKit weights fitted from video (`animate --video`): two 10 s,
  30 fps takes of ICT faces of other identities (seeds never tuned on), under another light,
  the head turning, with known ARKit weights, written as H.264 MP4 and fitted through ICT's own
  ARKit GLB; the mean absolute error over the jaw, mouth, brow and blink weights (mean of the
  takes), against the head kept still (all weights 0, measured alike), with the error where a
  weight acts (truth > 0.2) and each main shape's correlation; frames per second of the whole
  command (reading, tracking, fitting, writing)
"""

from __future__ import annotations

import json
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from mimica.data import ICTModel  # noqa: E402
from mimica.export import ARKIT_52  # noqa: E402
from mimica.export.compact import compact_clip  # noqa: E402
from mimica.mesh import write_glb  # noqa: E402
from mimica.mesh.io import glb_units  # noqa: E402


# the takes' expressions: each event a smooth rise and fall of one or a few ARKit shapes
EVENTS = [["jawOpen"], ["mouthSmileLeft", "mouthSmileRight"], ["eyeBlinkLeft", "eyeBlinkRight"], ["browInnerUp"],
          ["browDownLeft", "browDownRight"], ["mouthPucker"], ["mouthFunnel"], ["browOuterUpLeft", "browOuterUpRight"],
          ["mouthFrownLeft", "mouthFrownRight"], ["jawOpen", "mouthFunnel"], ["eyeBlinkLeft"],
          ["mouthStretchLeft", "mouthStretchRight"], ["mouthSmileLeft"], ["jawOpen", "browInnerUp"], ["mouthLeft"],
          ["mouthRollLower", "mouthRollUpper"]]
SCORED = ("jaw", "mouth", "brow", "eyeBlink")


def take_weights(frames, seed):
    """(frames, 52) ARKit weights: events one after another, overlapping, peaks 0.5-1."""
    rng = np.random.default_rng(seed)
    w = np.zeros((frames, 52))
    t = 12
    while t < frames - 30:
        ev = EVENTS[rng.integers(len(EVENTS))]
        dur, peak = int(rng.integers(18, 40)), rng.uniform(0.5, 1.0)
        bump = peak * np.sin(np.linspace(0, np.pi, dur)) ** 2
        for n in ev:
            j = ARKIT_52.index(n)
            w[t:t + dur, j] = np.maximum(w[t:t + dur, j], bump[:frames - t])
        t += int(rng.integers(8, dur))
    return w


PAINT = {"skin": (0.82, 0.64, 0.54), "lips": (0.70, 0.36, 0.36), "brows": (0.28, 0.20, 0.15),
         "sclera": (0.93, 0.91, 0.88), "iris": (0.36, 0.25, 0.16), "pupil": (0.04, 0.04, 0.04),
         "lashes": (0.10, 0.08, 0.07), "mouth": (0.50, 0.24, 0.24), "teeth": (0.95, 0.93, 0.88)}


def painted(model, rest):
    """(the mesh without ICT's tear and occlusion shells, per-vertex colours): skin, lips inside
    the outer lip line, brows along their landmarks, eyeballs with an iris and a pupil about
    their forward axis, dark lashes, mouth and teeth -- what a tracker trained on photographs
    looks for, which a grey render lacks."""
    from mimica.correspond.parts import ICT_PARTS
    from mimica.correspond.eyes import inside_polygon, polyline_distance
    from mimica.data import ICT_LANDMARKS_68
    part = {name: (a, b) for name, a, b in ICT_PARTS}
    col = np.tile(np.asarray(PAINT["skin"]), (len(rest), 1))
    lm = rest[ICT_LANDMARKS_68]
    width = float(np.linalg.norm(lm[16] - lm[0]))
    a, b = part["skin"]
    xy = rest[a:b, :2]
    lips = inside_polygon(xy, lm[48:60, :2]) & (rest[a:b, 2] > lm[48:60, 2].min() - 0.05 * width)
    col[a:b][lips] = PAINT["lips"]
    for brow in (lm[17:22], lm[22:27]):
        near = (polyline_distance(xy, brow[:, :2]) < 0.035 * width) & (rest[a:b, 2] > brow[:, 2].min() - 0.1 * width)
        col[a:b][near] = PAINT["brows"]
    for eye in ("eyeball.left", "eyeball.right"):
        a, b = part[eye]
        c = rest[a:b].mean(0)
        d = rest[a:b] - c
        cos = d[:, 2] / np.linalg.norm(d, axis=1)            # the head looks along +z
        col[a:b] = PAINT["sclera"]
        col[a:b][cos > np.cos(np.radians(38))] = PAINT["iris"]
        col[a:b][cos > np.cos(np.radians(16))] = PAINT["pupil"]
    for name, key in (("lashes", "lashes"), ("mouth socket", "mouth"), ("gums and tongue", "mouth"),
                      ("teeth", "teeth"), ("eye socket", "mouth")):
        a, b = part[name]
        col[a:b] = PAINT[key]
    keep = np.ones(len(rest), bool)
    for name in ("tear shells", "occlusion shells"):
        a, b = part[name]
        keep[a:b] = False
    faces = np.nonzero(np.add.reduceat(~keep[model.mesh.face_indices], model.mesh.face_starts[:-1]) == 0)[0]
    mesh, old = model.mesh.submesh(faces)
    return mesh, old, col[old]


def eyeball_centres(rest):
    """((index range, centre) of ICT's left and right eyeball): each a sphere fitted to it
    (correspond.parts.fit_sphere); the eyeballs do not deform, so once a take."""
    from mimica.correspond.parts import ICT_PARTS, fit_sphere
    part = {name: (a, b) for name, a, b in ICT_PARTS}
    return [(part[key], fit_sphere(rest[slice(*part[key])])[0]) for key in ("eyeball.left", "eyeball.right")]


def turned_eyes(rest, centres, w, degrees):
    """(index range, eyeball's vertices) of ICT's eyeballs turned by the eyeLook weights w (52,):
    `degrees` for a weight of 1, about each eyeball's centre (eyeball_centres).  ICT's eyeLook
    shapes move the lids only, as ARKit's are defined ("the eyelids consistent with a gaze"); a
    performer's eyes turn with them."""
    from scipy.spatial.transform import Rotation
    out = []
    for ((a, b), c), side, away in zip(centres, ("Left", "Right"), (1.0, -1.0)):
        g = {d: w[ARKIT_52.index(f"eyeLook{d}{side}")] for d in ("Out", "In", "Up", "Down")}
        # the subject's left is +x, the head looks along +z: out turns the left eye toward +x
        r = Rotation.from_euler("YX", [degrees * away * (g["Out"] - g["In"]), -degrees * (g["Up"] - g["Down"])],
                                degrees=True).as_matrix()
        out.append(((a, b), (rest[a:b] - c) @ r.T + c))
    return out


def render_take(model, w, seed, path, fps=30, size=(640, 480), turn=(8.0, 4.0), rates=(0.9, 0.6), zoom=1.4,
                paint=False, eye_turn=0.0):
    """The take as an MP4: ICT's identity of `seed` (+1000: never tuned on) with the ARKit
    weights w (ICT's shapes summed as `blendshapes` maps them), lit from the right, the head
    turning (yaw and pitch up to `turn` degrees, at `rates` radians a second), framed at `zoom`
    times the face's half height; grey, or `paint`ed (painted()); the eyes turned `eye_turn`
    degrees at a full eyeLook weight (turned_eyes; 0: they stay still, as ICT's shapes leave them)."""
    from mimica.data import ICT_LANDMARKS_68
    from mimica.export.blendshapes import ict_sources
    from mimica.image.ictphotos import LIGHT_RIGHT
    from mimica.image.raster import face_framing, render_mesh
    from mimica.image.video import VideoWriter
    ident = model.identity(np.random.default_rng(1000 + seed).normal(0, 0.8, 20))
    deltas = np.stack([model.delta({n: 1.0 for n in ict_sources(a)}) if ict_sources(a) else np.zeros_like(ident)
                       for a in ARKIT_52])
    mesh, keep, colors = painted(model, ident) if paint else (model.mesh, slice(None), None)
    c, half = face_framing(model.neutral[ICT_LANDMARKS_68])
    tt = np.arange(len(w)) / fps
    yaw, pitch = turn[0] * np.sin(tt * rates[0] + seed), turn[1] * np.sin(tt * rates[1] + 2 * seed)
    centres = eyeball_centres(ident) if eye_turn else None
    out = VideoWriter(path, fps)
    for f in range(len(w)):
        v = ident + np.einsum("k,knd->nd", w[f], deltas)
        if eye_turn:
            for (a, b), e in turned_eyes(ident, centres, w[f], eye_turn):
                v[a:b] = e
        v = v[keep]
        out.write(render_mesh(mesh, v, size=size, frame=(c, zoom * half), light=LIGHT_RIGHT, colors=colors,
                              background=(90, 90, 90), yaw=yaw[f], pitch=pitch[f]))
    out.close()
    return yaw - yaw[0]


def video_takes(model, head_glb, tmp, seeds=(21, 22), frames=300):
    """(mean error, mean error of the still head, frames per second, lines to print)."""
    from mimica.export.take import read_take
    scored = [j for j, n in enumerate(ARKIT_52) if n.startswith(SCORED)]
    errs, zeros, rates, lines = [], [], [], []
    for seed in seeds:
        w = take_weights(frames, seed)
        yaw = render_take(model, w, seed, tmp / f"take{seed}.mp4")
        t = time.perf_counter()
        cli("animate", head_glb, "--video", tmp / f"take{seed}.mp4", "--out", tmp / f"video{seed}.glb")
        rates.append(frames / (time.perf_counter() - t))
        _, got, _ = read_take(tmp / f"video{seed}.csv")
        fit = np.stack([got[n] for n in ARKIT_52], 1)
        e = np.abs(fit[:, scored] - w[:, scored])
        act = w[:, scored] > 0.2
        errs.append(e.mean())
        zeros.append(np.abs(w[:, scored]).mean())
        corr = {n: np.corrcoef(fit[:, ARKIT_52.index(n)], w[:, ARKIT_52.index(n)])[0, 1]
                for n in ("jawOpen", "mouthSmileLeft", "mouthPucker", "browInnerUp", "eyeBlinkLeft")
                if w[:, ARKIT_52.index(n)].max() > 0.3 and fit[:, ARKIT_52.index(n)].std() > 0}
        yaw_err = np.degrees(np.sqrt(np.mean((got["headYaw"] - np.radians(yaw)) ** 2)))
        lines.append(f"take {seed}: error {e.mean():.3f} (still head {np.abs(w[:, scored]).mean():.3f}); where a "
                     f"weight acts {e[act].mean():.3f}; correlation " +
                     ", ".join(f"{n} {c:.2f}" for n, c in corr.items()) +
                     f"; head yaw rms error {yaw_err:.1f} deg; {rates[-1]:.0f} frames/s end to end")
    return float(np.mean(errs)), float(np.mean(zeros)), float(np.min(rates)), lines


def cli(*args):
    r = subprocess.run([sys.executable, "-c", "import sys; from mimica.cli import main; sys.exit(main())", *map(str, args)],
                       capture_output=True, text=True, env={"PYTHONPATH": str(ROOT / "src"), **__import__("os").environ})
    if r.returncode:
        raise SystemExit(f"mimica {' '.join(map(str, args))} failed: {r.stderr}")
    return r.stderr


def main():
    print(f"machine: {platform.machine()}, {platform.system()}, python {platform.python_version()}")
    model = ICTModel()
    mesh = model.mesh
    tmp = Path(tempfile.mkdtemp(prefix="mimica-bench-export-"))
    frames = model.performance(600)
    names = [f"frame_{i:04d}" for i in range(len(frames))]
    unit, k = glb_units(mesh)
    t = time.perf_counter()
    c = compact_clip(mesh.vertices, frames, 1e-4 / k)
    t_fit = time.perf_counter() - t
    t = time.perf_counter()
    write_glb(tmp / "clip.glb", mesh, {f"basis_{j:02d}": mesh.vertices + b for j, b in enumerate(c.basis)}, fps=60,
              weights=c.weights, sparse=1e-5, extras={"frames": names})
    t_write = time.perf_counter() - t
    write_glb(tmp / "clip_per_frame.glb", mesh, dict(zip(names, frames)), fps=60)     # before: dense, a target a frame
    clip_mb = (tmp / "clip.glb").stat().st_size / 1e6
    per_frame_mb = (tmp / "clip_per_frame.glb").stat().st_size / 1e6
    err_mm = float(np.linalg.norm(c.frames(mesh.vertices) - frames, axis=2).max()) * k * 1e3
    print(f"clip: {len(frames)} frames on {mesh.n_vertices} vertices ({unit}) -> {len(c.basis)} basis shapes, "
          f"fit {t_fit:.1f}s, write {t_write:.1f}s; {clip_mb:.1f} MB against {per_frame_mb:.1f} MB one target a "
          f"frame (x{per_frame_mb / clip_mb:.0f}); largest error {err_mm:.4f} mm")

    neutral = tmp / "ict.obj"
    from mimica.mesh import read_vertices, write_mesh
    write_mesh(neutral, mesh)
    # a simulated clip: Kim's muscles on ICT's face, 10 s at 60 fps (`mimica simulate` writes its
    # animation.glb compact), against its frames as one target each
    cli("rig", neutral, "--out", tmp / "face.rig")
    t = time.perf_counter()
    said = cli("simulate", tmp / "face.rig", "--expression", "happiness", "--duration", "10", "--fps", "60",
               "--out", tmp / "sim")
    sim_frames = sorted((tmp / "sim").glob("frame_*.obj"))
    skin = __import__("mimica.mesh", fromlist=["read_mesh"]).read_mesh(sim_frames[0])
    sim = np.stack([read_vertices(p) for p in sim_frames])
    write_glb(tmp / "sim_per_frame.glb", skin, {p.stem: f for p, f in zip(sim_frames, sim)}, fps=60)
    sim_mb = (tmp / "sim" / "animation.glb").stat().st_size / 1e6
    sim_pf = (tmp / "sim_per_frame.glb").stat().st_size / 1e6
    c_sim = compact_clip(skin.vertices, sim, 1e-4 / glb_units(skin)[1])
    sim_err = 0.0 if c_sim is None else float(np.linalg.norm(c_sim.frames(skin.vertices) - sim, axis=2).max()) \
        * glb_units(skin)[1] * 1e3
    line = next((ln for ln in said.splitlines() if "animation.glb:" in ln), said.strip().splitlines()[-1])
    print(f"simulated clip ({time.perf_counter() - t:.1f}s): {len(sim)} frames on {skin.n_vertices} vertices, "
          f"{sim_mb:.1f} MB against {sim_pf:.1f} MB one target a frame (x{sim_pf / sim_mb:.0f}); largest error "
          f"{sim_err:.4f} mm; simulate said: ...{line[line.index('animation.glb:'):] if 'animation.glb:' in line else line}")
    t = time.perf_counter()
    said = cli("blendshapes", neutral, "--out", tmp / "arkit_float.glb")
    float_mb = (tmp / "arkit_float.glb").stat().st_size / 1e6
    print(f"blendshapes on ICT's generic mesh ({time.perf_counter() - t:.1f}s): {float_mb:.1f} MB "
          f"(before: 17.6 MB, positions only); " + said.strip().splitlines()[-2])
    said = cli("blendshapes", neutral, "--out", tmp / "arkit.glb", "--quantize")
    arkit_mb = (tmp / "arkit.glb").stat().st_size / 1e6
    print(f"  --quantize: {arkit_mb:.1f} MB ({arkit_mb / 17.6:.0%} of before); " + said.strip().splitlines()[-2])
    take = tmp / "take.csv"
    rows = [",".join(["time"] + ARKIT_52)] + [",".join([f"{i / 60:.5f}"] + [f"{0.5 + 0.5 * np.sin(i / 9 + j):.4f}"
                                                                             for j in range(52)]) for i in range(120)]
    take.write_text("\n".join(rows))
    cli("animate", tmp / "arkit.glb", "--arkit", take, "--out", tmp / "take.glb")
    write_glb(tmp / "mesh.glb", mesh)
    kinds = ["mesh.glb", "arkit_float.glb", "arkit.glb", "clip.glb", "clip_per_frame.glb", "take.glb", "sim/animation.glb"]
    node = subprocess.run(["node", str(ROOT / "tools" / "gltf" / "validate.mjs"), *[str(tmp / n) for n in kinds]],
                          capture_output=True, text=True)
    if node.returncode:
        raise SystemExit(f"the glTF-Validator did not run (make test installs it): {node.stderr.strip()}")
    reports = [json.loads(line) for line in node.stdout.splitlines()]
    issues = sum(r["errors"] + r["warnings"] for r in reports)
    print("validator: " + ", ".join(f"{n} {r['errors']} errors {r['warnings']} warnings" for n, r in zip(kinds, reports)))
    verr, vzero, vfps, vlines = video_takes(model, tmp / "arkit.glb", tmp)
    print("weights from video (animate --video, its default tracker): " + "; ".join(vlines))
    print(f"  mean error {verr:.3f} against {vzero:.3f} for the head kept still")
    print(f"validator_issues={issues} clip_mb={sim_mb:.1f} clip_ratio={sim_mb / sim_pf:.3f} "
          f"clip_err_mm={sim_err:.3f} arkit_mb={arkit_mb:.1f} video_weights_err={verr:.3f} video_fps={vfps:.0f}")


if __name__ == "__main__":
    main()
