"""What the video fit and its refinement on the pixels share (export.video, export.photometric):
the projected points' Jacobian and the bounded least squares."""

from __future__ import annotations

import numpy as np

from ..mesh.core import cross_matrices


def projection_jacobian(RX: np.ndarray, R: np.ndarray, motion: np.ndarray) -> np.ndarray:
    """(n, 2, 6 + k): the derivative of P (1 + e) (I + [d]x) RX + u -- points RX (n, 3), already
    rotated by R, moved by k weights through `motion` (k, n, 3) in the head's frame -- in (a small
    rotation d, the scale's change e, the shift u, the weights) at d = e = u = 0; P the first two
    rows (a scaled orthographic camera, lengths as RX's)."""
    P = np.eye(3)[:2]
    return np.concatenate([-np.einsum("ij,njk->nik", P, cross_matrices(RX)), RX[:, :2, None],
                           np.broadcast_to(np.eye(2), (len(RX), 2, 2)), np.einsum("ij,knj->nik", P @ R, motion)], 2)


def gram(A: np.ndarray) -> np.ndarray:
    """A'A through BLAS's symmetric rank-k update (half a product's work: 0.6 ms against 1.0 for
    a frame's 2,450 x 71 rows on the pixels)."""
    from scipy.linalg.blas import dsyrk
    C = dsyrk(1.0, A, trans=1)                      # A (C order) read as A' in Fortran's: the upper triangle of A'A
    return C + np.triu(C, 1).T


def _spd_solve(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """A x = b for A symmetric positive definite, by LAPACK's Cholesky (dposv: a third of
    numpy.linalg.solve's overhead on these small systems), numpy's LU where it is not."""
    from scipy.linalg.lapack import dposv
    _, x, info = dposv(A, b)
    return x if info == 0 else np.linalg.solve(A, b)


def box_qp(H: np.ndarray, g: np.ndarray, lo: np.ndarray, hi: np.ndarray, rounds: int = 30) -> np.ndarray:
    """min z'Hz/2 - g'z with lo <= z <= hi (H positive definite): an active set from the unbounded
    minimum clipped, those past a bound held there several at a time, a held one whose gradient
    points inside freed one at a time.  Written here because scipy's bvls (lsq_linear) moves one
    variable a pass: with most weights resting at 0 its solves were most of a frame's fit (the
    same minimum to 1e-16 on random problems)."""
    z = np.clip(_spd_solve(H, g), lo, hi)
    held = (z <= lo) | (z >= hi)
    for _ in range(rounds):
        fi = np.flatnonzero(~held)
        if len(fi):
            Hf = H[fi]
            zf = _spd_solve(Hf[:, fi], g[fi] - Hf @ np.where(held, z, 0.0))    # the held ones' pull moved over
            lf, hf = lo[fi], hi[fi]
            over = (zf < lf) | (zf > hf)
            z[fi] = np.clip(zf, lf, hf)
            if over.any():
                held[fi[over]] = True
                continue
        grad = H @ z - g
        free_it = held & (((z <= lo) & (grad < -1e-12)) | ((z >= hi) & (grad > 1e-12)))
        if not free_it.any():
            break
        held[np.argmax(np.abs(grad) * free_it)] = False
    return z
