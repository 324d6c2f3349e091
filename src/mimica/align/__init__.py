"""Similarity alignment from corresponding points (Song §V; Challis 1995; Umeyama 1991)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import MimicaError


@dataclass
class Similarity:
    """x -> scale * R @ x + t; `residual` is the RMS landmark distance after the fit."""

    scale: float
    rotation: np.ndarray
    translation: np.ndarray
    residual: float = 0.0

    def apply(self, x):
        return self.scale * np.asarray(x) @ self.rotation.T + self.translation

    def inverse(self) -> "Similarity":
        r = self.rotation.T
        return Similarity(1 / self.scale, r, -(r @ self.translation) / self.scale, self.residual)

    @classmethod
    def identity(cls) -> "Similarity":
        return cls(1.0, np.eye(3), np.zeros(3))


def fit_similarity(src, dst, what="landmarks") -> Similarity:
    """Least-squares similarity mapping src points onto dst points, (m, 3) each; NaN rows skipped.

    Centroids, cross-covariance SVD for the rotation (reflection excluded), scale from the
    singular values, translation from the centroids (Challis 1995).
    """
    src, dst = np.asarray(src, float), np.asarray(dst, float)
    ok = np.isfinite(src).all(1) & np.isfinite(dst).all(1)
    if ok.sum() < 3:
        raise MimicaError(f"{what}: at least 3 landmarks present on both faces are needed to align them")
    a, b = src[ok], dst[ok]
    ca, cb = a.mean(0), b.mean(0)
    a0, b0 = a - ca, b - cb
    u, s, vt = np.linalg.svd(b0.T @ a0)
    d = np.sign(np.linalg.det(u @ vt)) or 1.0
    dm = np.diag([1.0, 1.0, d])
    r = u @ dm @ vt
    var = (a0 ** 2).sum()
    if var <= 0:
        raise MimicaError(f"{what}: the landmarks all sit on one point")
    scale = float((s * np.diag(dm)).sum() / var)
    t = cb - scale * r @ ca
    res = float(np.sqrt(((scale * a @ r.T + t - b) ** 2).sum(1).mean()))
    return Similarity(scale, r, t, res)
