"""Alignment: the similarity between corresponding points (Song §V; Challis 1995; Umeyama 1991),
and the cylinder around a head that its landmarks place (Song §V.A.1)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import MimicaError


@dataclass
class Similarity:
    """A similarity transform x -> scale * R @ x + t.

    Attributes
    ----------
    scale : float
    rotation : (3, 3) float array
        R, a proper rotation.
    translation : (3,) float array
        t.
    residual : float
        The RMS distance of the fitted points after the fit (fit_similarity), in the
        destination's units.
    """

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


def fit_similarity(src, dst, what="landmarks", scale=True) -> Similarity:
    """The least-squares similarity mapping src points onto dst points.

    Centroids, cross-covariance SVD for the rotation (reflection excluded), scale from the
    singular values (1 with scale=False: the best rigid motion), translation from the
    centroids (Challis 1995).

    Parameters
    ----------
    src, dst : (m, 3) float arrays
        Corresponding points; rows with a NaN in either are skipped (at least 3 must remain).
    what : str
        How messages name the points.
    scale : bool
        Fit the scale too (False: the best rigid motion).

    Returns
    -------
    Similarity
        Its `residual` the RMS distance after the fit.
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
    scale = float((s * np.diag(dm)).sum() / var) if scale else 1.0
    t = cb - scale * r @ ca
    res = float(np.sqrt(((scale * a @ r.T + t - b) ** 2).sum(1).mean()))
    return Similarity(scale, r, t, res)


# iBUG 68 indices used to build the face frame
_JAW_CHIN, _EYE_R_OUT, _EYE_L_OUT = 8, 36, 45     # jaw.8, eye.right.0, eye.left.3
_BROWS = slice(17, 27)


@dataclass
class Cylinder:
    """A vertical cylinder in a face frame (Song et al.'s cylinder map).

    Attributes
    ----------
    origin : (3,) float array
        A point on the axis.
    axes : (3, 3) float array
        Rows: right, up (the axis), forward.
    radius : float
        The reference radius: u is arc length at this radius.
    """

    origin: np.ndarray
    axes: np.ndarray          # (3, 3) rows: right, up, forward
    radius: float             # reference radius: u is arc length at this radius

    def project(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Points (m, 3) -> (uv (m, 2), r (m,)); u = radius * angle from forward."""
        loc = (np.asarray(x) - self.origin) @ self.axes.T
        ang = np.arctan2(loc[:, 0], loc[:, 2])
        r = np.hypot(loc[:, 0], loc[:, 2])
        return np.stack([self.radius * ang, loc[:, 1]], axis=1), r


def face_cylinder(landmarks: np.ndarray) -> Cylinder:
    """The face's cylinder: its axis vertical (brows over chin) through the middle of the head.

    Parameters
    ----------
    landmarks : (68, 3) float array
        iBUG 68 positions; the chin (8), the outer eye corners (36, 45) and a brow point
        (17-26) are needed, others may be NaN.

    Returns
    -------
    Cylinder
    """
    lm = np.asarray(landmarks, float)
    ok = np.isfinite(lm).all(1)
    need = [_JAW_CHIN, _EYE_R_OUT, _EYE_L_OUT]
    if not ok[need].all() or not ok[_BROWS].any():
        raise MimicaError("landmarks: the chin (8), outer eye corners (36, 45) and a brow point "
                          "(17-26) are needed to place the face on a cylinder")
    right = lm[_EYE_L_OUT] - lm[_EYE_R_OUT]
    width = float(np.linalg.norm(right))
    right /= width
    up = np.nanmean(lm[_BROWS], axis=0) - lm[_JAW_CHIN]
    up -= right * (up @ right)
    up /= np.linalg.norm(up)
    fwd = np.cross(right, up)
    center = lm[ok].mean(0)
    # the axis sits behind the face, near the middle of the skull (about one eye-to-eye
    # width behind the landmarks' centroid, for adult heads)
    origin = center - fwd * 1.1 * width
    return Cylinder(origin, np.stack([right, up, fwd]), 1.1 * width)
