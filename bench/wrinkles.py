"""Benchmark: wrinkles (issue 4) — what exists so far: the cylinder fit and the bulge table.

Run from the project root: .venv/bin/python bench/wrinkles.py
The animated-wrinkles figure (frames_per_s) needs the wrinkle mask and its animation, not
written yet; the final line prints nan for it until then.
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
    t = time.perf_counter()
    looked = table.lookup(d, a, al)
    t_table = (time.perf_counter() - t) / n
    lookup_err = float(np.max(np.abs(looked - exact) / exact))
    t = time.perf_counter()
    arc_length(d, a, al)
    t_gauss = (time.perf_counter() - t) / n

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
    print("frames_per_s: not measured yet (the animated wrinkle mask is still to come)")
    print(f"frames_per_s=nan cylinder_fit_s={fit_s:.3f} arclength_err_max={err:.5f}")


if __name__ == "__main__":
    main()
