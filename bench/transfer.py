"""Benchmark: 3D expression transfer (issue 2), ours (VTC) against Sumner-Popović DT in the same run.

Run from the project root with the project's interpreter:  .venv/bin/python bench/transfer.py
Data: ICT-FaceKit from the data directory ($MIMICA_DATA, default ../shared/data).  The model
is linear, so the truth of expression e on target T is T + (E_e - N); relative error =
mean |result - truth| / mean |truth - T| over the face area (vertices 0-9408).
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))

from mimica.data import (EXPRESSIONS, ICT_FACE_AREA_FACES, ICT_FACE_AREA_VERTICES,  # noqa: E402
                         ICT_HEAD_VERTICES, ICT_LANDMARKS_68, ICTModel)
from mimica.landmarks import Landmarks, ict_landmarks  # noqa: E402
from mimica.correspond.remesh import resample_face  # noqa: E402
from mimica.transfer import ExpressionTransfer, relative_error, static_vertices  # noqa: E402
from mimica.solver import available, backend  # noqa: E402
import mimica  # noqa: E402
mimica.keep_memory()                   # as the command line does (mimica/_memory.py)

FACE = slice(0, ICT_FACE_AREA_VERTICES)


def best_of(fn, repeat):
    best, out = np.inf, None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


def held_out_identity(model, seed):
    """A target identity no parameter was tuned on: random weights on the 20 identity shapes."""
    rng = np.random.default_rng(1000 + seed)
    return model.identity(rng.normal(0, 0.8, 20))


def sequence(model, n_frames, seed=0):
    """A smooth performance: the six basic expressions blended with slowly varying weights."""
    names = list(EXPRESSIONS)
    d = np.stack([model.delta(EXPRESSIONS[e]) for e in names])
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 2 * np.pi, n_frames)[:, None]
    w = np.clip(np.sin(t * rng.uniform(0.5, 2.0, len(names)) + rng.uniform(0, 2 * np.pi, len(names))), 0, None)
    return model.neutral + np.einsum("fk,knd->fnd", w, d), w @ d.reshape(len(names), -1)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--targets", type=int, default=3)
    a = ap.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, {platform.system()}, "
          f"python {platform.python_version()}, sparse solver: {backend()}")

    model = ICTModel(ICT_HEAD_VERTICES)
    S = model.mesh
    frames, _ = sequence(model, a.frames)
    deltas = frames - S.vertices
    static = static_vertices(S.vertices, frames)
    basic = np.stack([S.vertices + model.delta(EXPRESSIONS[e]) for e in EXPRESSIONS])
    ls = ict_landmarks(S)

    # self-transfer: S' onto S gives S' back
    x = ExpressionTransfer(S, S, ls, ls, static=static)
    self_err = np.abs(x.apply(basic) - basic).max() / np.ptp(S.vertices, axis=0).max()
    print(f"self-transfer (S' onto S), max |error| / head size: {self_err:.2e}")

    res = {}
    for method in ("vtc", "dt"):
        pre, fps, err_seq, err_basic = [], [], [], []
        for k in range(a.targets):
            tv = held_out_identity(model, k)
            T = S.with_vertices(tv)
            tp, xf = best_of(lambda: ExpressionTransfer(S, T, ls, ict_landmarks(T), method, static), a.repeat)
            ta, out = best_of(lambda: xf.apply(frames, basis=False), a.repeat)   # frame by frame
            pre.append(tp)
            fps.append(len(frames) / ta)
            err_seq.append(np.mean([relative_error(o, tv + d, tv, FACE) for o, d in zip(out, deltas)]))
            ob = xf.apply(basic)
            err_basic.append([relative_error(o, tv + b - S.vertices, tv, FACE) for o, b in zip(ob, basic)])
        res[method] = dict(precompute=np.median(pre), fps=np.median(fps), err_seq=np.mean(err_seq),
                           err_basic=np.mean(err_basic, axis=0))
        print(f"[{method}] 11,248-vertex head, {a.targets} held-out identities: precompute "
              f"{res[method]['precompute']:.3f}s, {a.frames}-frame sequence {res[method]['fps']:.0f} frames/s, "
              f"relative error {res[method]['err_seq']:.4f} (sequence), per expression: "
              + ", ".join(f"{e} {v:.3f}" for e, v in zip(EXPRESSIONS, res[method]["err_basic"])))

    # the full 26,719-vertex model (eyes, teeth, mouth socket included)
    full = ICTModel()
    ff, _ = sequence(full, a.frames)
    Tf = full.mesh.with_vertices(held_out_identity(full, 0))
    xf = ExpressionTransfer(full.mesh, Tf, ict_landmarks(full.mesh), ict_landmarks(Tf), "vtc",
                            static_vertices(full.neutral, ff))
    tfull, _ = best_of(lambda: xf.apply(ff, basis=False), a.repeat)
    print(f"[vtc] full 26,719-vertex model: {a.frames / tfull:.0f} frames/s")
    # what `transfer` does by default on a sequence this long: through its basis (bench/batch.py)
    tb, _ = best_of(lambda: xf.apply(ff), a.repeat)
    print(f"[vtc] full 26,719-vertex model, by default ({xf.basis_report['why']}): {a.frames / tb:.0f} frames/s")

    # a remeshed target: a scan-like face of its own topology with holes
    rem = {}
    tv = held_out_identity(model, 7)
    face, _ = S.with_vertices(tv).submesh(np.arange(ICT_FACE_AREA_FACES))
    rs = resample_face(face, tv[ICT_LANDMARKS_68], n_vertices=12000, seed=7)
    T = rs.mesh
    lt = Landmarks.snap(T, tv[ICT_LANDMARKS_68])
    from mimica.correspond import correspond
    from mimica.align import fit_similarity
    sim = fit_similarity(lt.positions(T), ls.positions(S))
    Ta = T.with_vertices(sim.apply(T.vertices))
    tc, _ = best_of(lambda: correspond(S, ls.positions(S), Ta, sim.apply(lt.positions(T))), a.repeat)
    for method in ("vtc", "dt"):
        xr = ExpressionTransfer(S, T, ls, lt, method, static)
        ob = xr.apply(basic)
        rem[method] = [relative_error(o, rs.carry(tv[FACE] + b[FACE] - S.vertices[FACE]), T.vertices)
                       for o, b in zip(ob, basic)]
        print(f"[{method}] remeshed target ({T.n_vertices} vertices, holes at eyes, nostrils, mouth): "
              f"relative error {np.mean(rem[method]):.4f}; per expression: "
              + ", ".join(f"{e} {v:.3f}" for e, v in zip(EXPRESSIONS, rem[method])))
    print(f"correspondence for the remeshed target: {tc:.3f}s")
    # across topologies VTC carries a small per-triangle term (transfer.core.DT_STABILIZER):
    # Song's energy alone, and the sequence's speed with and without the term
    for stabilize in (True, False):
        tp, xr = best_of(lambda: ExpressionTransfer(S, T, ls, lt, "vtc", static, stabilize=stabilize), a.repeat)
        ta, _ = best_of(lambda: xr.apply(frames, basis=False), a.repeat)
        err = np.mean([relative_error(o, rs.carry(tv[FACE] + b[FACE] - S.vertices[FACE]), T.vertices)
                       for o, b in zip(xr.apply(basic), basic)])
        print(f"[vtc{'' if stabilize else ', no per-triangle term'}] remeshed target: relative error {err:.4f}, "
              f"precompute {tp:.3f}s, {a.frames / ta:.0f} frames/s")

    # every installed sparse solver on the same system (scikit-sparse's CHOLMOD, cholespy's, SuperLU)
    T = S.with_vertices(held_out_identity(model, 0))
    for kind in available():
        tp, xk = best_of(lambda: ExpressionTransfer(S, T, ls, ict_landmarks(T), "vtc", static, solver_kind=kind), a.repeat)
        ta, _ = best_of(lambda: xk.apply(frames, basis=False), a.repeat)
        print(f"solver {kind}: precompute {tp:.3f}s, {a.frames / ta:.0f} frames/s")

    v, d = res["vtc"], res["dt"]
    print(f"ours vs dt: speed x{v['fps'] / d['fps']:.2f}, error {v['err_seq']:.4f} vs {d['err_seq']:.4f} "
          f"(same topology), {np.mean(rem['vtc']):.4f} vs {np.mean(rem['dt']):.4f} (remeshed)")
    print(f"frames_per_s={v['fps']:.0f} precompute_s={v['precompute']:.3f} correspondence_s={tc:.3f} "
          f"rel_err_same={v['err_seq']:.4f} rel_err_remeshed={np.mean(rem['vtc']):.4f}")


if __name__ == "__main__":
    main()
