"""Cylinder fit by conjugate gradient and cylindrical flattening (Viaud & Yahia 1992, §3.1).

    E(x, y, z, alpha, beta, r) = sum_i (|GP_i ^ d|^2 - r^2 |d|^2)^2          (eq. 1)

with G = (x, y, z) a point of the axis and d = (alpha, beta, Z0) its direction, one
coordinate of d fixed by the initial guess (here: its largest one).  The gradient is that
of eqs. 2-7; the fit runs in coordinates centred and scaled to unit spread, so that one
tolerance serves faces in millimetres or metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

from ..errors import MimicaError


@dataclass
class CylinderFit:
    """A cylinder fitted to points (fit_cylinder).

    Attributes
    ----------
    origin : (3,) float array
        A point on the axis.
    axis : (3,) float array
        Unit direction.
    radius : float
    energy : float
        The fit's energy (V&Y eq. 1) at the end.
    """
    origin: np.ndarray        # a point on the axis
    axis: np.ndarray          # unit direction
    radius: float
    energy: float
    iterations: int

    def distance(self, points) -> np.ndarray:
        """Signed distance of points from the cylinder surface (outside > 0)."""
        v = np.asarray(points) - self.origin
        radial = v - np.outer(v @ self.axis, self.axis)
        return np.linalg.norm(radial, axis=1) - self.radius


def _unpack(p, k, z0):
    g = p[:3]
    d = np.insert(p[3:5], k, z0)
    return g, d, p[5]


def energy_and_gradient(p, P, k, z0):
    """V&Y's cylinder energy (eq. 1) and its gradient (eqs. 2-7).

    Parameters
    ----------
    p : (6,) float array
        (x, y, z, a, b, r): a point of the axis, the axis's two free components, the radius.
    P : (n, 3) float array
        The points.
    k : int
        The axis component held fixed.
    z0 : float
        Its value.

    Returns
    -------
    E : float
    gradient : (6,) float array
    """
    g, d, r = _unpack(p, k, z0)
    gp = P - g                                      # GP_i
    c = np.cross(gp, d)                             # GP_i ^ d
    dd = d @ d
    res = np.einsum("ij,ij->i", c, c) - r * r * dd  # |GP_i ^ d|^2 - r^2 |d|^2
    e = float(res @ res)
    eye = np.eye(3)
    grad = np.empty(6)
    for a in range(3):                              # eqs. 2-4: dE/dx, dE/dy, dE/dz
        grad[a] = -4.0 * res @ (c @ np.cross(eye[a], d))
    free = [j for j in range(3) if j != k]
    for slot, j in zip((3, 4), free):               # eqs. 5-6: dE/dalpha, dE/dbeta
        grad[slot] = 4.0 * res @ (np.einsum("ij,ij->i", c, np.cross(gp, eye[j])) - r * r * d[j])
    grad[5] = -4.0 * dd * r * res.sum()            # eq. 7
    return e, grad


def fit_cylinder(points, axis_guess=(0.0, 1.0, 0.0), origin_guess=None, radius_guess=None,
                 tol=1e-10, max_iter=2000) -> CylinderFit:
    """Fit a cylinder to points by conjugate gradient (V&Y §3.1).

    Parameters
    ----------
    points : (n, 3) float array
        At least 6, finite.
    axis_guess : (3,) float array
        Must not be orthogonal to the answer (the paper's condition); its largest component is the
        one held fixed.
    origin_guess : (3,) float array or None
    radius_guess : float or None
    tol : float
    max_iter : int

    Returns
    -------
    CylinderFit
    """
    P = np.asarray(points, float)
    if P.ndim != 2 or P.shape[1] != 3 or len(P) < 6 or not np.isfinite(P).all():
        raise MimicaError("cylinder fit: needs at least 6 finite 3D points")
    center = P.mean(0)
    scale = float(np.sqrt(((P - center) ** 2).sum(1).mean()))
    Q = (P - center) / scale
    d0 = np.asarray(axis_guess, float)
    d0 = d0 / np.linalg.norm(d0)
    k = int(np.argmax(np.abs(d0)))
    z0 = float(d0[k])
    g0 = np.zeros(3) if origin_guess is None else (np.asarray(origin_guess, float) - center) / scale
    if radius_guess is None:
        v = Q - g0
        radial = v - np.outer(v @ d0, d0)
        r0 = float(np.linalg.norm(radial, axis=1).mean())
    else:
        r0 = radius_guess / scale
    p0 = np.concatenate([g0, np.delete(d0, k), [r0]])
    res = minimize(energy_and_gradient, p0, args=(Q, k, z0), jac=True, method="CG",
                   options={"gtol": tol, "maxiter": max_iter})
    g, d, r = _unpack(res.x, k, z0)
    axis = d / np.linalg.norm(d)
    # report the axis point nearest the points' centroid (G slides freely along the axis)
    g = g + axis * ((0 - g) @ axis)
    return CylinderFit(center + scale * g, axis, abs(r) * scale, float(res.fun), int(res.nit))


def flatten(points, cyl: CylinderFit, forward=None) -> np.ndarray:
    """Points projected on a cylinder and unrolled to the plane.

    theta = 0 faces `forward` (default: the points' mean direction from the axis), so two faces
    flattened with the same forward direction line up.

    Parameters
    ----------
    points : (n, 3) float array
    cyl : CylinderFit
    forward : (3,) float array or None

    Returns
    -------
    (n, 2) float array
        (arc length r theta, height).
    """
    v = np.asarray(points) - cyl.origin
    h = v @ cyl.axis
    radial = v - np.outer(h, cyl.axis)
    ref = radial.mean(0) if forward is None else np.asarray(forward, float).copy()
    ref -= cyl.axis * (ref @ cyl.axis)
    if np.linalg.norm(ref) < 1e-12:
        ref = np.cross(cyl.axis, [1.0, 0, 0] if abs(cyl.axis[0]) < 0.9 else [0, 1.0, 0])
    e1 = ref / np.linalg.norm(ref)
    e2 = np.cross(cyl.axis, e1)
    theta = np.arctan2(radial @ e2, radial @ e1)
    return np.stack([cyl.radius * theta, h], axis=1)


def radial_distance(points, cyl: CylinderFit) -> np.ndarray:
    """The points' distances from the cylinder's axis.

    Parameters
    ----------
    points : (n, 3) float array
    cyl : CylinderFit

    Returns
    -------
    (n,) float array
    """
    v = np.asarray(points) - cyl.origin
    return np.linalg.norm(v - np.outer(v @ cyl.axis, cyl.axis), axis=1)
