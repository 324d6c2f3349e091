"""Hyper-dual numbers: exact first and second derivatives of code written once.

A hyper-dual number is f + a e1 + b e2 + ab e1e2 with e1^2 = e2^2 = 0 (Fike & Alonso 2011).
Seeding a = d/dx_i and b = d/dx_j, one evaluation yields f, df/dx_i, df/dx_j and the
second derivative d2f/dx_i dx_j exactly (no step size, no truncation error).  Every field
is a numpy array, so one evaluation covers all elements of a mesh at once.
"""

from __future__ import annotations

import numpy as np


class HD:
    """A hyper-dual number f + a e1 + b e2 + ab e1e2 (Fike and Alonso 2011), vectorized: each part an
    array, so one evaluation of a function gives its value, two first derivatives and the mixed
    second derivative exactly (no truncation error).

    Parameters
    ----------
    f : float array
        The value.
    a, b : float array
        The derivatives along the two seeded directions.
    ab : float array
        The mixed second derivative.
    """
    __slots__ = ("f", "a", "b", "ab")

    def __init__(self, f, a=0.0, b=0.0, ab=0.0):
        self.f, self.a, self.b, self.ab = f, a, b, ab

    @staticmethod
    def lift(x):
        return x if isinstance(x, HD) else HD(x)

    def _chain(self, g, d1, d2):
        """g(self) given g, g', g'' evaluated at self.f."""
        return HD(g, d1 * self.a, d1 * self.b, d1 * self.ab + d2 * self.a * self.b)

    def __add__(self, o):
        o = HD.lift(o)
        return HD(self.f + o.f, self.a + o.a, self.b + o.b, self.ab + o.ab)

    __radd__ = __add__

    def __neg__(self):
        return HD(-self.f, -self.a, -self.b, -self.ab)

    def __sub__(self, o):
        return self + (-HD.lift(o))

    def __rsub__(self, o):
        return HD.lift(o) - self

    def __mul__(self, o):
        o = HD.lift(o)
        return HD(self.f * o.f, self.f * o.a + self.a * o.f, self.f * o.b + self.b * o.f,
                  self.f * o.ab + self.a * o.b + self.b * o.a + self.ab * o.f)

    __rmul__ = __mul__

    def reciprocal(self):
        inv = 1.0 / self.f
        return self._chain(inv, -inv * inv, 2.0 * inv * inv * inv)

    def __truediv__(self, o):
        return self * HD.lift(o).reciprocal()

    def __rtruediv__(self, o):
        return HD.lift(o) * self.reciprocal()

    def sqrt(self):
        s = np.sqrt(self.f)
        return self._chain(s, 0.5 / s, -0.25 / (s * self.f))


def atan2(y: HD, x: HD) -> HD:
    """atan2 with exact first and second derivatives.

    Parameters
    ----------
    y, x : HD

    Returns
    -------
    HD
    """
    r2 = x.f * x.f + y.f * y.f
    ta = (x.f * y.a - y.f * x.a) / r2
    tb = (x.f * y.b - y.f * x.b) / r2
    r2b = 2.0 * (x.f * x.b + y.f * y.b)
    tab = ((x.b * y.a + x.f * y.ab - y.b * x.a - y.f * x.ab) * r2 - (x.f * y.a - y.f * x.a) * r2b) / (r2 * r2)
    return HD(np.arctan2(y.f, x.f), ta, tb, tab)


# 3-vectors as tuples of three HD scalars
def sub(u, v):
    """u - v for 3-vectors given as 3-tuples (of HD or arrays).

    Parameters
    ----------
    u, v : tuple of 3

    Returns
    -------
    tuple of 3
    """
    return (u[0] - v[0], u[1] - v[1], u[2] - v[2])


def dot(u, v):
    """u . v for 3-vectors given as 3-tuples.

    Parameters
    ----------
    u, v : tuple of 3

    Returns
    -------
    HD or array
    """
    return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]


def cross(u, v):
    """u x v for 3-vectors given as 3-tuples.

    Parameters
    ----------
    u, v : tuple of 3

    Returns
    -------
    tuple of 3
    """
    return (u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0])


def norm(u):
    """|u| for a 3-vector given as a 3-tuple.

    Parameters
    ----------
    u : tuple of 3

    Returns
    -------
    HD or array
    """
    return dot(u, u).sqrt()


def local_derivatives(fn, x: np.ndarray, params=()):
    """Value, gradient and Hessian of a per-element function of k stacked coordinates (k (k + 1) / 2
    hyper-dual evaluations).

    Parameters
    ----------
    fn : callable
        fn(vars, *params) -> HD per element, vars a list of k HD arrays.
    x : (m, k) float array
        The values.
    params : tuple
        More arguments of fn.

    Returns
    -------
    f : (m,) float array
    g : (m, k) float array
    H : (m, k, k) float array
    """
    m, k = x.shape
    zero = np.zeros(m)
    one = np.ones(m)
    g = np.empty((m, k))
    h = np.empty((m, k, k))
    f = None
    for i in range(k):
        for j in range(i, k):
            vs = [HD(x[:, c], one if c == i else zero, one if c == j else zero, zero) for c in range(k)]
            r = fn(vs, *params)
            if i == j:
                f = r.f
                g[:, i] = r.a
            h[:, i, j] = h[:, j, i] = r.ab
    return f, g, h


def local_gradient(fn, x: np.ndarray, params=()):
    """Value and gradient only (k hyper-dual evaluations).

    Parameters
    ----------
    fn : callable
        As local_derivatives'.
    x : (m, k) float array
    params : tuple

    Returns
    -------
    f : (m,) float array
    g : (m, k) float array
    """
    m, k = x.shape
    zero = np.zeros(m)
    one = np.ones(m)
    g = np.empty((m, k))
    f = None
    for i in range(k):
        vs = [HD(x[:, c], one if c == i else zero, zero, zero) for c in range(k)]
        r = fn(vs, *params)
        f, g[:, i] = r.f, r.a
    return f, g
