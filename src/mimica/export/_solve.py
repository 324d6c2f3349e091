"""Small solvers the video fit and its refinement on the pixels share (export.video,
export.photometric)."""

from __future__ import annotations

import numpy as np


def cross_matrices(v: np.ndarray) -> np.ndarray:
    """(n, 3, 3): [v]x, so that [v]x a = v x a."""
    z = np.zeros(len(v))
    return np.stack([np.stack([z, -v[:, 2], v[:, 1]], 1), np.stack([v[:, 2], z, -v[:, 0]], 1),
                     np.stack([-v[:, 1], v[:, 0], z], 1)], 1)


def box_qp(H: np.ndarray, g: np.ndarray, lo: np.ndarray, hi: np.ndarray, rounds: int = 30) -> np.ndarray:
    """min z'Hz/2 - g'z with lo <= z <= hi (H positive definite): an active set from the unbounded
    minimum clipped, those past a bound held there several at a time, a held one whose gradient
    points inside freed one at a time.  Written here because scipy's bvls (lsq_linear) moves one
    variable a pass: with most weights resting at 0 its solves were most of a frame's fit (the
    same minimum to 1e-16 on random problems)."""
    z = np.clip(np.linalg.solve(H, g), lo, hi)
    held = (z <= lo) | (z >= hi)
    for _ in range(rounds):
        f = ~held
        zf = np.linalg.solve(H[np.ix_(f, f)], g[f] - H[np.ix_(f, held)] @ z[held]) if f.any() else z[f]
        over = (zf < lo[f]) | (zf > hi[f])
        z[f] = np.clip(zf, lo[f], hi[f])
        if over.any():
            held[np.nonzero(f)[0][over]] = True
            continue
        grad = H @ z - g
        free_it = held & (((z <= lo) & (grad < -1e-12)) | ((z >= hi) & (grad > 1e-12)))
        if not free_it.any():
            break
        held[np.argmax(np.abs(grad) * free_it)] = False
    return z
