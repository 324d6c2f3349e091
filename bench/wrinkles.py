"""Benchmark: wrinkles — cylinder fit, bulge table, mask transfer, and the
animated face with its wrinkles (simulation + wrinkle layer per frame, against the
simulation alone in the same process).  Also writes the pictures in docs/figures/.

Run from the project root: .venv/bin/python bench/wrinkles.py
"""

from __future__ import annotations

import platform
import sys
import time
from pathlib import Path

import numpy as np
from scipy.integrate import quad

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))

from mimica.data import ICT_HEAD_VERTICES, ICTModel  # noqa: E402
from mimica.wrinkles import ArcLengthTable, arc_length, dilation, fit_cylinder  # noqa: E402
from mimica.wrinkles.bulge import control_points  # noqa: E402
import mimica  # noqa: E402
mimica.keep_memory()                   # as the command line does (mimica/_memory.py)


def main():
    print(f"machine: {platform.machine()}, python {platform.python_version()}")
    face = ICTModel(ICT_HEAD_VERTICES).neutral[:9409]
    times = []
    for _ in range(5):
        t = time.perf_counter()
        cyl = fit_cylinder(face)
        times.append(time.perf_counter() - t)
    fit_s = min(times)
    print(f"cylinder fit on the ICT face area (9,409 points): {fit_s:.3f}s, radius {cyl.radius:.2f}, "
          f"{cyl.iterations} CG iterations")

    table = ArcLengthTable.build()
    rng = np.random.default_rng(0)
    n = 100000
    d = rng.uniform(0.1, 20.1, n)
    a = d * rng.uniform(0, 5, n)
    al = rng.uniform(0, np.pi, n)
    exact = arc_length(d, a, al)
    looked = table.lookup(d, a, al)
    lookup_err = float(np.max(np.abs(looked - exact) / exact))

    def per_query(f, k=5):                                  # best of k, per wrinkle section
        ts = []
        for _ in range(k):
            t = time.perf_counter()
            f()
            ts.append(time.perf_counter() - t)
        return min(ts) / n
    t_table = per_query(lambda: table.lookup(d, a, al))
    t_gauss = per_query(lambda: arc_length(d, a, al))

    def by_quad(i):
        p0, p0p, p1p, p1 = control_points(d[i], a[i], al[i])
        return quad(lambda u: np.linalg.norm(3 * ((1 - u) ** 2 * (p0p - p0) + 2 * u * (1 - u) * (p1p - p0p)
                                                  + u ** 2 * (p1 - p1p))), 0, 1)[0]
    m = 300
    t = time.perf_counter()
    for i in range(m):
        by_quad(i)
    t_quad = (time.perf_counter() - t) / m
    d_real = dilation(d, rng.uniform(20, 90, n))
    aa, alf = table.solve(d, d_real, 0.1 * d)
    err = float(np.max(np.abs(arc_length(d, aa, alf) - d_real) / d_real))
    print(f"arc-length table: lookup max error {lookup_err:.5f}; bulge arc length vs dil(d_init, t) "
          f"max error {err:.5f} over d in [0.1, 20.1], a/d in [0, 5], alpha in [0, pi], ages 20-90")
    print(f"per wrinkle: table {t_table * 1e9:.0f} ns, vectorized 48-point Gauss {t_gauss * 1e9:.0f} ns "
          f"(x{t_gauss / t_table:.0f}), adaptive quadrature {t_quad * 1e6:.0f} us (x{t_quad / t_table:.0f})")
    mask_transfer()
    fps = animate()
    pictures()
    print(f"frames_per_s={fps:.0f} cylinder_fit_s={fit_s:.3f} arclength_err_max={err:.5f}")


def mask_transfer():
    """V&Y §3.2 onto held-out identities resampled with their own triangulation, against the
    truth (ICT-FaceKit's correspondence) and against no relaxation (similarity + closest point)."""
    from mimica.align import fit_similarity
    from mimica.data import ICT_LANDMARKS_68
    from mimica.mesh.query import TriangleLocator
    from mimica.correspond.remesh import resample_face
    from mimica.wrinkles import carry_mask, reference_mask, transfer_mask
    m = ICTModel(ICT_HEAD_VERTICES)
    ref, mask = m.mesh, reference_mask()
    ours, base, secs = [], [], []
    for seed in (1001, 1002, 1003, 1004):
        V = m.identity(np.random.default_rng(seed).normal(0, 0.8, 20))
        lm = V[ICT_LANDMARKS_68]
        scan = resample_face(ref.with_vertices(V), lm, 12000, seed=seed).mesh
        new, info = transfer_mask(mask, ref, scan, lm)
        secs.append(info.seconds)
        eye = np.linalg.norm(lm[45] - lm[36])
        sim = fit_similarity(ref.vertices[ICT_LANDMARKS_68], lm)
        ls = TriangleLocator(scan.vertices, scan.triangles)
        true = carry_mask(mask, ref, V)
        for w, nw, tw in zip(mask.wrinkles, new.wrinkles, true.wrinkles):
            truth = tw.points
            ours.append(np.linalg.norm(nw.points - truth, axis=1) / eye)
            base.append(np.linalg.norm(ls.closest(sim.apply(w.points))[2] - truth, axis=1) / eye)
    ours, base = np.concatenate(ours), np.concatenate(base)
    print(f"mask transfer onto 4 held-out remeshed identities ({len(mask)} wrinkles): {np.mean(secs):.2f}s each; "
          f"control-point error / eye width: relaxed springs mean {ours.mean():.4f} max {ours.max():.4f}; "
          f"similarity + closest point mean {base.mean():.4f} max {base.max():.4f}")


def animate():
    """Frames per second of the ICT face animated by its muscles with 21 wrinkles (refined
    skin), against the simulation alone; the same frames, same process."""
    from mimica.anim import Timeline
    from mimica.data import ICT_LANDMARKS_68
    from mimica.physics.face import FaceSimulator
    from mimica.rig import build_rig
    from mimica.wrinkles import WrinkledSkin, reference_mask
    m = ICTModel(ICT_HEAD_VERTICES)
    muscles = ["frontalis_R", "frontalis_L", "corrugator_supercilii_R", "corrugator_supercilii_L",
               "zygomaticus_major_R", "zygomaticus_major_L", "orbicularis_oculi_R", "orbicularis_oculi_L"]
    rig = build_rig(m.mesh, m.neutral[ICT_LANDMARKS_68], muscles=muscles)
    names = [x.name for x in rig.muscles]
    t = time.perf_counter()
    ws = WrinkledSkin.build(rig.skin, reference_mask())
    build_s = time.perf_counter() - t
    tl = Timeline.preset("surprise", names, duration=2.0)
    n = 240
    acts = [tl.values(i / 60, names) for i in range(n)]

    t = time.perf_counter()
    reduced = FaceSimulator(rig, fps=60, reduced=1e-4).prepare()
    reduce_s = time.perf_counter() - t

    coarse = WrinkledSkin.build(rig.skin, reference_mask(), refine=False)

    def run(layer):
        sim = reduced.reset()                                # the reduced model, computed once
        out = np.empty((layer.mesh.n_vertices if layer else rig.skin.n_vertices, 3))
        t0 = time.perf_counter()
        for i in range(n):
            sim.advance(acts[i])                             # a frame of the reduced model
            X = rig.skin.vertices + sim.displacement()
            out[:] = layer.frame(X, 60.0) if layer else X
        return n / (time.perf_counter() - t0)
    best = {True: 0.0, False: 0.0, "coarse": 0.0}
    for _ in range(3):
        for w, layer in ((False, None), (True, ws), ("coarse", coarse)):
            best[w] = max(best[w], run(layer))
    per = 1000 / best[True] - 1000 / best[False]
    X = rig.skin.vertices + 0.0
    for name, w in (("refined", ws), ("unrefined", coarse)):
        t0 = time.perf_counter()
        for _ in range(300):
            w.frame(X, 60.0)
        el = (time.perf_counter() - t0) / 300
        print(f"wrinkle layer alone, {name} skin ({w.mesh.n_vertices} nodes, "
              f"{len(w.layer.vertex_binding.point)} in bands): {1000 * el:.2f} ms/frame = {1 / el:.0f} frames/s")
    full = FaceSimulator(rig, fps=60, warp=False)     # the exact model the reduction is of: linear, as it is
    reduced.reset()
    err = peak = 0.0
    rng = np.random.default_rng(5)
    for i in range(2 * n):              # the reduced model against the exact one: the clip, then random
        a = acts[i] if i < n else rng.uniform(-1, 1, len(names))
        for sim in (full, reduced):
            sim.advance(a)
        uf = full.displacement()
        err = max(err, float(np.abs(reduced.displacement() - uf).max()))
        peak = max(peak, float(np.abs(uf).max()))
    err /= peak
    t0 = time.perf_counter()
    for i in range(n):
        full.advance(acts[i])
    exact_ms = 1000 * (time.perf_counter() - t0) / n
    t0 = time.perf_counter()
    for i in range(n):
        reduced.advance(acts[i])
    red_ms = 1000 * (time.perf_counter() - t0) / n
    (shapes, states), (modes, full_states) = reduced.reduced_size, full.reduced_size
    print(f"reduced simulator (tolerance 1e-4, built in {reduce_s:.1f}s): output from {shapes} "
          f"shapes instead of {modes} modes, muscles stepped in "
          f"{states} balanced-truncation states instead of "
          f"{full_states} ({red_ms:.3f} vs {exact_ms:.3f} ms a frame); "
          f"max error {100 * err:.4f}% of the largest displacement over the clip and 240 random frames "
          "(against the exact linear model, modal warping off in both)")
    print(f"animated ICT face (11,248 skin nodes, 8 muscles, 4 substeps/frame): simulation alone "
          f"{best[False]:.0f} frames/s; with 21 wrinkles on the refined skin ({ws.mesh.n_vertices} nodes, "
          f"{len(ws.layer.vertex_binding.point)} in wrinkle bands, built in {build_s:.1f}s) {best[True]:.0f} frames/s "
          f"(wrinkles {per:.2f} ms/frame); with the wrinkles on the rig's own mesh (--no-refine) "
          f"{best['coarse']:.0f} frames/s")
    return best[True]


def pictures():
    """docs/figures: the reference mask, an age sweep and the paper's expressions (Figs. 10-16)."""
    from mimica.data import ICT_LANDMARKS_68
    from mimica.render import contact_sheet, face_framing, render_mesh, save_png
    from mimica.wrinkles import WrinkledSkin, reference_mask
    from mimica.wrinkles.show import mask_image
    out = Path(__file__).resolve().parents[1] / "docs" / "figures"
    m = ICTModel(ICT_HEAD_VERTICES)
    mask = reference_mask()
    save_png(out / "wrinkle_mask.png", contact_sheet([mask_image(m.mesh, mask, size=520),
                                                      mask_image(m.mesh, mask, size=520, yaw=35)],
                                                     title="reference wrinkle mask (21 wrinkles, 76 anchors)"))
    ws = WrinkledSkin.build(m.mesh, mask)
    frame = face_framing(m.neutral[ICT_LANDMARKS_68])
    ages = (25, 45, 65, 85)
    tiles, labels = [], []
    for name in ("neutral", "surprise", "happiness"):
        X = m.neutral + (m.delta(m.expression(name)) if name != "neutral" else 0)
        for g in ages:
            tiles.append(render_mesh(ws.mesh, ws.frame(X, g), size=(300, 300), frame=frame))
            labels.append(f"{name}, {g}")
    save_png(out / "wrinkles_age.png", contact_sheet(tiles, labels, columns=len(ages),
                                                     title="age sweep 25 -> 85 (ICT-FaceKit expressions, 21 wrinkles)"))
    tiles, labels = [], []
    for name in ("surprise", "disgust", "happiness"):
        X = m.neutral + m.delta(m.expression(name))
        tiles += [render_mesh(m.mesh, X, size=(340, 340), frame=frame),
                  render_mesh(ws.mesh, ws.frame(X, 65), size=(340, 340), frame=frame)]
        labels += [f"{name}, no wrinkles", f"{name}, age 65"]
    save_png(out / "wrinkles_expressions.png", contact_sheet(tiles, labels, columns=2,
                                                             title="expressive wrinkles (after V&Y Figs. 10-16)"))
    print(f"pictures -> {out}/wrinkle_mask.png, wrinkles_age.png, wrinkles_expressions.png")


if __name__ == "__main__":
    main()
