"""The bulge of a wrinkle (Viaud & Yahia 1992, §5): a planar, symmetric cubic whose arc
length grows with age, found by inverting a table of arc lengths.

    d_real = dil(d_init, t) = d_init max(1, 1 + (t - AGE_0) DIL_MAX / (AGE_MAX - AGE_0))    (eq. 10)
    P0 = (0, 0), P1 = (d, 0), P0' = (a cos alpha, a sin alpha), P1' = (d - a cos alpha, a sin alpha)  (eqs. 11-12)
    S(d, a, alpha) = integral_0^1 |C'(u)| du                                             (eq. 13)

C is the cubic Bezier segment P0, P0', P1', P1 (its end tangents run along P0P0' and
P1'P1).  S is tabulated over (d, a, alpha) and read by trilinear interpolation (eq. 14);
the inversion holds a and solves for alpha, or, when even alpha_max is too short, holds
alpha_max and solves for a (§5.1).  Lengths are in table units: divide by `unit`.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

AGE_0 = 35.0          # dilation starts (V&Y: about 35 years)
AGE_MAX = 90.0
DIL_MAX = 0.25        # arc-length dilation at AGE_MAX

_GL_X, _GL_W = np.polynomial.legendre.leggauss(48)
_GL_U = 0.5 * (_GL_X + 1.0)
_GL_W = 0.5 * _GL_W


def dilation(d_init, age, age0=AGE_0, age_max=AGE_MAX, dil_max=DIL_MAX):
    """V&Y eq. 10: the arc length a wrinkle's cross-section reaches at an age.

    Parameters
    ----------
    d_init : float or float array
        The arc length at age0.
    age : float or float array
        Years.
    age0, age_max : float
        The age the dilation starts at, and the age it reaches dil_max at.
    dil_max : float
        The relative growth at age_max.

    Returns
    -------
    float array
    """
    return np.asarray(d_init) * np.maximum(1.0, 1.0 + (np.asarray(age) - age0) * dil_max / (age_max - age0))


def control_points(d, a, alpha, skew=1.0):
    """V&Y eqs. 11-12: the Bezier control points of a wrinkle's cross-section.

    skew < 1 gives the asymmetric section (V&Y §5.2, nasolabial folds): the tangent at P1 has
    `skew` times the norm and the angle of the one at P0, so the fuller side is P0's.

    Parameters
    ----------
    d, a, alpha : float arrays
        Half-width, height and the tangents' angle (broadcast together).
    skew : float

    Returns
    -------
    P0, P0p, P1p, P1 : (..., 2) float arrays
    """
    d, a, alpha = np.broadcast_arrays(np.asarray(d, float), np.asarray(a, float), np.asarray(alpha, float))
    z = np.zeros_like(d)
    p0 = np.stack([z, z], -1)
    p0p = np.stack([a * np.cos(alpha), a * np.sin(alpha)], -1)
    p1p = np.stack([d - skew * a * np.cos(skew * alpha), skew * a * np.sin(skew * alpha)], -1)
    p1 = np.stack([d, z], -1)
    return p0, p0p, p1p, p1


def curve(d, a, alpha, u, skew=1.0):
    """Points of the cross-section C(u).

    Parameters
    ----------
    d, a, alpha : float arrays
        As control_points'.
    u : (k,) float array
        Curve parameters in [0, 1].
    skew : float

    Returns
    -------
    (..., k, 2) float array
    """
    p0, p0p, p1p, p1 = (p[..., None, :] for p in control_points(d, a, alpha, skew))
    u = np.asarray(u)[:, None]
    b = [(1 - u) ** 3, 3 * u * (1 - u) ** 2, 3 * u ** 2 * (1 - u), u ** 3]
    return b[0] * p0 + b[1] * p0p + b[2] * p1p + b[3] * p1


def arc_length(d, a, alpha, skew=1.0):
    """V&Y eq. 13 by 48-point Gauss-Legendre quadrature (the reference ArcLengthTable stands in for).

    Parameters
    ----------
    d, a, alpha : float arrays
    skew : float

    Returns
    -------
    float array
        The broadcast shape of d, a, alpha.
    """
    p0, p0p, p1p, p1 = (p[..., None, :] for p in control_points(d, a, alpha, skew))
    u = _GL_U[:, None]
    dc = 3 * ((1 - u) ** 2 * (p0p - p0) + 2 * u * (1 - u) * (p1p - p0p) + u ** 2 * (p1 - p1p))
    return np.einsum("...k,k->...", np.linalg.norm(dc, axis=-1), _GL_W)


@dataclass
class ArcLengthTable:
    """S(d, a, alpha) tabulated, trilinear lookup (eq. 14) and its inversion (§5.1).

    The table's axes are (d, rho = a / d, alpha).  A Bezier segment scales with its control points,
    S(l d, l a, alpha) = l S(d, a, alpha), so S is exactly linear in d at fixed (rho, alpha): along
    d the trilinear interpolation is exact and the grid needs no d resolution; the error is that of
    (rho, alpha) alone.  (V&Y's uniform (d, a) grid with unit steps is 77 % off for short, high
    wrinkles, where a >> d.)

    Attributes
    ----------
    rho : (p,) float array
    alpha : (q,) float array
    s : (p, q) float array
        S(1, rho, alpha).
    skew : float
    """

    rho: np.ndarray
    alpha: np.ndarray
    s: np.ndarray             # (len(rho), len(alpha)): S(1, rho, alpha)
    skew: float = 1.0

    @classmethod
    def build(cls, rho_max=5.0, rho_steps=200, alpha_max=np.pi, alpha_steps=160, skew=1.0):
        rho = np.linspace(0.0, rho_max, rho_steps + 1)
        al = np.linspace(0.0, alpha_max, alpha_steps + 1)
        return cls(rho, al, arc_length(1.0, rho[:, None], al[None, :], skew), skew)

    @staticmethod
    def _cell(grid, x):
        x = np.clip(x, grid[0], grid[-1])
        i = np.clip(((x - grid[0]) / (grid[1] - grid[0])).astype(np.int64), 0, len(grid) - 2)
        return i, (x - grid[i]) / (grid[i + 1] - grid[i])

    def _s(self, rho, alpha):
        (j, fr), (k, fl) = self._cell(self.rho, rho), self._cell(self.alpha, alpha)
        s = self.s
        return ((s[j, k] * (1 - fl) + s[j, k + 1] * fl) * (1 - fr)
                + (s[j + 1, k] * (1 - fl) + s[j + 1, k + 1] * fl) * fr)

    @cached_property
    def _corners(self):
        """Per cell its four corner values [s00, s01 - s00, s10 - s00, s11 - s10 - s01 + s00]
        (bilinear coefficients), one row per cell: a lookup is one gather of four numbers."""
        s = self.s
        c = np.stack([s[:-1, :-1], s[:-1, 1:] - s[:-1, :-1], s[1:, :-1] - s[:-1, :-1],
                      s[1:, 1:] - s[1:, :-1] - s[:-1, 1:] + s[:-1, :-1]], -1)
        return np.ascontiguousarray(c.reshape(-1, 4))

    def lookup(self, d, a, alpha):
        """Eq. 14 (see the class note on the d axis), vectorized over the arguments: the cell
        of (a / d, alpha), its bilinear coefficients in one gather, times d."""
        d = np.asarray(d, float)
        nr, na = len(self.rho) - 1, len(self.alpha) - 1
        r = np.clip(np.asarray(a, float) / d * (nr / (self.rho[-1] - self.rho[0])), 0.0, nr - 1e-9)
        t = np.clip(np.asarray(alpha, float) * (na / (self.alpha[-1] - self.alpha[0])), 0.0, na - 1e-9)
        j = r.astype(np.intp)
        k = t.astype(np.intp)
        fr, fl = r - j, t - k
        c = self._corners.take(j * na + k, axis=0)
        return d * (c[..., 0] + c[..., 1] * fl + fr * (c[..., 2] + c[..., 3] * fl))

    def solve(self, d, d_real, a0, alpha_max=np.pi / 2, iterations=40):
        """§5.1: (a, alpha) with S(d, a, alpha) = d_real; alpha first (a = a0), then a."""
        d, d_real, a0 = np.broadcast_arrays(np.asarray(d, float), np.asarray(d_real, float), np.asarray(a0, float))
        alpha_max = np.broadcast_to(np.asarray(alpha_max, float), d.shape)
        target, rho0 = d_real / d, a0 / d
        enough = self._s(rho0, alpha_max) >= target
        lo, hi = np.zeros(d.shape), alpha_max.copy()              # alpha in [0, alpha_max]
        rlo, rhi = rho0.copy(), np.full(d.shape, self.rho[-1])   # or rho in [rho0, rho_max]
        for _ in range(iterations):                               # bisection, all wrinkles at once
            mid = 0.5 * (lo + hi)
            below = self._s(rho0, mid) < target
            lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
            rmid = 0.5 * (rlo + rhi)
            below = self._s(rmid, alpha_max) < target
            rlo, rhi = np.where(below, rmid, rlo), np.where(below, rhi, rmid)
        a = np.where(enough, a0, 0.5 * (rlo + rhi) * d)
        alpha = np.where(enough, 0.5 * (lo + hi), alpha_max)
        return a, alpha

    def inverse(self, rho0=1.0 / 3.0, alpha_max=np.pi / 2, steps=4096):
        """The inversion for one starting tangent norm a0 = rho0 d, tabulated once: for a length
        ratio q = d_real / d, (alpha(q), rho(q)) with S(d, rho d, alpha) = q d.  Returns
        (q grid, alpha, rho); read it with np.interp (the per-frame path of the wrinkle layer)."""
        q_lo = float(self._s(np.array(rho0), np.array(0.0)))
        q_hi = float(self._s(np.array(self.rho[-1]), np.array(alpha_max)))
        q = q_lo + (q_hi - q_lo) * np.linspace(0.0, 1.0, steps) ** 2   # dense near q = 1 (alpha ~ sqrt)
        a, al = self.solve(np.ones_like(q), q, np.full_like(q, rho0), alpha_max=alpha_max, iterations=50)
        return q, al, a
