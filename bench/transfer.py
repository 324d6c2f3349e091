"""Benchmark: 3D expression transfer, ours (VTC) against Sumner-Popović DT in the same run.

Run from the project root with the project's interpreter:  .venv/bin/python bench/transfer.py
Data: ICT-FaceKit from the data directory ($MIMICA_DATA, default ../shared/data).  The model
is linear, so the truth of expression e on target T is T + (E_e - N); relative error =
mean |result - truth| / mean |truth - T| over the face area (vertices 0-9408).

Remeshed mixes (remeshed_mix_median / remeshed_mix_worst): 20 held-out identities (seeds
300-319, none tuned on) remeshed at 6k-15k vertices, each with three random mixes of 2-4 of
ICT's shapes at weights 0.5-1 (the first of each mouth-heavy: two or more jaw and mouth shapes);
a case's error is its three mixes' pooled (relative_error over all of them at once: a
mix that barely moves the face does not weigh as much as one that opens the jaw).  In the same run: the same identities and mixes on
ICT's own topology, and (on the first `--peer` cases) trimesh's `registration.nricp_amberg`,
the same Amberg et al. method in a well-kept library, in place of mimica's registration.
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
from mimica.transfer.core import ANCHOR  # noqa: E402
from mimica.solver import available, backend  # noqa: E402
import mimica  # noqa: E402
mimica.keep_memory()                   # as the command line does (mimica/_memory.py)

FACE = slice(0, ICT_FACE_AREA_VERTICES)


def paper(method):
    """The baseline as its paper has it: Sumner and Popovic's DT without mimica's anchor."""
    return {"anchor": 0.0} if method == "dt" else {}


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


MOUTH_SHAPES = ("jaw", "mouth")


def mixes(model, rng, n=3):
    """n random mixes of 2-4 of ICT's shapes at weights 0.5-1, the first mouth-heavy: (n, V, 3)."""
    from mimica.data import ict_expression_names
    names = ict_expression_names()
    mouth = [s for s in names if s.startswith(MOUTH_SHAPES)]
    out = []
    for k in range(n):
        m = int(rng.integers(2, 5))
        pick = list(rng.choice(mouth, 2, replace=False)) if k == 0 else []
        pick += list(rng.choice([s for s in names if s not in pick], m - len(pick), replace=False))
        out.append(model.neutral + model.delta({s: float(rng.uniform(0.5, 1.0)) for s in pick}))
    return np.stack(out)


def trimesh_registered(source, source_lm, target, target_lm, lookup, contours=False):
    """mimica.correspond._registered with trimesh's nricp_amberg as the registration (the peer)."""
    import trimesh
    from trimesh.registration import nricp_amberg
    from mimica.correspond import Correspondence
    from mimica.correspond.register import on_boundary
    from mimica.mesh.query import TriangleLocator
    both = np.isfinite(source_lm).all(1) & np.isfinite(target_lm).all(1)
    tri, bary, _, _ = TriangleLocator(source.vertices, source.triangles).closest(source_lm[both])
    src = trimesh.Trimesh(source.vertices, source.triangles, process=False)
    tgt = trimesh.Trimesh(target.vertices, target.triangles, process=False)
    reg = nricp_amberg(src, tgt, source_landmarks=(tri, bary), target_positions=target_lm[both])
    t2, b2, _, dist = TriangleLocator(reg, source.triangles).closest(lookup)
    h = float(np.median(np.linalg.norm(reg[source.edges[:, 0]] - reg[source.edges[:, 1]], axis=1)))
    beyond = on_boundary(source, t2, b2) & (dist > h)
    conf = np.exp(-0.5 * (dist / h) ** 2)
    conf[beyond] = 0.0
    return Correspondence(np.where(beyond, -1, t2), np.where(beyond[:, None], 0.0, b2), source.n_vertices, conf)


def remeshed_mixes(model, peer_cases: int):
    """(ours per case, same topology per case, peer per case on the first peer_cases, ours without
    the anchor per case, seconds)."""
    import mimica.correspond as corr
    S = model.mesh
    ls = ict_landmarks(S)
    ours, same, peer, song = [], [], [], []
    t0 = time.perf_counter()
    for k in range(20):
        seed = 300 + k
        rng = np.random.default_rng(seed)
        tv = held_out_identity(model, seed)
        mx = mixes(model, rng)
        static = static_vertices(S.vertices, mx)
        face, _ = S.with_vertices(tv).submesh(np.arange(ICT_FACE_AREA_FACES))
        rs = resample_face(face, tv[ICT_LANDMARKS_68], n_vertices=(6000, 9000, 12000, 15000)[k % 4], seed=seed)
        lt = Landmarks.snap(rs.mesh, tv[ICT_LANDMARKS_68])
        truth = [rs.carry(tv[FACE] + m[FACE] - S.vertices[FACE]) for m in mx]
        out = ExpressionTransfer(S, rs.mesh, ls, lt, method="vtc", static=static).apply(mx)
        ours.append(relative_error(out, np.stack(truth), rs.mesh.vertices))            # the case's mixes pooled
        o0 = ExpressionTransfer(S, rs.mesh, ls, lt, method="vtc", static=static, anchor=0.0).apply(mx)
        song.append(relative_error(o0, np.stack(truth), rs.mesh.vertices))           # without the anchor
        T = S.with_vertices(tv)
        o2 = ExpressionTransfer(S, T, ls, ict_landmarks(T), method="vtc", static=static).apply(mx)
        same.append(relative_error(o2, tv + mx - S.vertices, tv, FACE))
        if k < peer_cases:
            saved, corr._registered = corr._registered, trimesh_registered
            try:
                o3 = ExpressionTransfer(S, rs.mesh, ls, lt, method="vtc", static=static).apply(mx)
            finally:
                corr._registered = saved
            peer.append(relative_error(o3, np.stack(truth), rs.mesh.vertices))
    return np.array(ours), np.array(same), np.array(peer), np.array(song), time.perf_counter() - t0


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--targets", type=int, default=3)
    ap.add_argument("--peer", type=int, default=5, help="remeshed cases also run with trimesh's nricp_amberg")
    ap.add_argument("--only-mixes", action="store_true", help="only the remeshed mixes")
    a = ap.parse_args()
    if a.only_mixes:
        mix, mix_same, mix_peer, mix_song, secs = remeshed_mixes(ICTModel(ICT_HEAD_VERTICES), a.peer)
        _print_mixes(mix, mix_same, mix_peer, mix_song, secs)
        return
    print(f"machine: {platform.processor() or platform.machine()}, {platform.system()}, "
          f"python {platform.python_version()}, sparse solver: {backend()}")

    model = ICTModel(ICT_HEAD_VERTICES)
    S = model.mesh
    frames = model.performance(a.frames)
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
            tp, xf = best_of(lambda: ExpressionTransfer(S, T, ls, ict_landmarks(T), method=method, static=static,
                                                        **paper(method)), a.repeat)
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
    ff = full.performance(a.frames)
    Tf = full.mesh.with_vertices(held_out_identity(full, 0))
    xf = ExpressionTransfer(full.mesh, Tf, ict_landmarks(full.mesh), ict_landmarks(Tf), method="vtc",
                            static=static_vertices(full.neutral, ff))
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
        xr = ExpressionTransfer(S, T, ls, lt, method=method, static=static, **paper(method))
        ob = xr.apply(basic)
        rem[method] = [relative_error(o, rs.carry(tv[FACE] + b[FACE] - S.vertices[FACE]), T.vertices)
                       for o, b in zip(ob, basic)]
        print(f"[{method}] remeshed target ({T.n_vertices} vertices, holes at eyes, nostrils, mouth): "
              f"relative error {np.mean(rem[method]):.4f}; per expression: "
              + ", ".join(f"{e} {v:.3f}" for e, v in zip(EXPRESSIONS, rem[method])))
    print(f"correspondence for the remeshed target: {tc:.3f}s")
    # across topologies VTC carries a small per-triangle term (transfer.core.DT_STABILIZER) and,
    # on every target, the anchor (transfer.core.ANCHOR): each left out, and Song's energy alone
    for stabilize, anchor, what in ((True, ANCHOR, ""), (False, ANCHOR, ", no per-triangle term"),
                                    (True, 0.0, ", no anchor"), (False, 0.0, ", Song's energy alone")):
        tp, xr = best_of(lambda: ExpressionTransfer(S, T, ls, lt, method="vtc", static=static, stabilize=stabilize,
                                                    anchor=anchor), a.repeat)
        ta, _ = best_of(lambda: xr.apply(frames, basis=False), a.repeat)
        err = np.mean([relative_error(o, rs.carry(tv[FACE] + b[FACE] - S.vertices[FACE]), T.vertices)
                       for o, b in zip(xr.apply(basic), basic)])
        print(f"[vtc{what}] remeshed target: relative error {err:.4f}, precompute {tp:.3f}s, {a.frames / ta:.0f} frames/s")

    # every installed sparse solver on the same system (scikit-sparse's CHOLMOD, cholespy's, SuperLU)
    T = S.with_vertices(held_out_identity(model, 0))
    for kind in available():
        tp, xk = best_of(lambda: ExpressionTransfer(S, T, ls, ict_landmarks(T), method="vtc", static=static,
                                                    solver_kind=kind), a.repeat)
        ta, _ = best_of(lambda: xk.apply(frames, basis=False), a.repeat)
        print(f"solver {kind}: precompute {tp:.3f}s, {a.frames / ta:.0f} frames/s")

    mix, mix_same, mix_peer, mix_song, secs = remeshed_mixes(model, a.peer)
    _print_mixes(mix, mix_same, mix_peer, mix_song, secs)
    v, d = res["vtc"], res["dt"]
    print(f"ours vs dt: speed x{v['fps'] / d['fps']:.2f}, error {v['err_seq']:.4f} vs {d['err_seq']:.4f} "
          f"(same topology), {np.mean(rem['vtc']):.4f} vs {np.mean(rem['dt']):.4f} (remeshed)")
    print(f"frames_per_s={v['fps']:.0f} precompute_s={v['precompute']:.3f} correspondence_s={tc:.3f} "
          f"rel_err_same={v['err_seq']:.4f} rel_err_remeshed={np.mean(rem['vtc']):.4f} "
          f"remeshed_mix_median={np.median(mix):.4f} remeshed_mix_worst={mix.max():.4f}")


def _print_mixes(mix, same, peer, song, secs):
    print(f"remeshed mixes, 20 held-out identities at 6k-15k vertices, 3 mixes each ({secs:.0f}s): relative "
          f"error median {np.median(mix):.4f} worst {mix.max():.4f} (case {int(np.argmax(mix))}); same topology "
          f"on the same mixes: median {np.median(same):.4f} worst {same.max():.4f}; without the anchor "
          f"(Song's energy): median {np.median(song):.4f} worst {song.max():.4f}")
    if len(peer):
        print(f"on the first {len(peer)} cases: mimica's registration {np.mean(mix[:len(peer)]):.4f} (mean), "
              f"trimesh's nricp_amberg {np.mean(peer):.4f}; per case ours "
              + " ".join(f"{x:.3f}" for x in mix[:len(peer)]) + ", trimesh " + " ".join(f"{x:.3f}" for x in peer))


if __name__ == "__main__":
    main()
