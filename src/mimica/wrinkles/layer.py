"""Wrinkles on a moving face (Viaud & Yahia 1992, §5.2-5.3): every frame, the compression
across each wrinkle and the age set the bulge of its cross-section.

Each wrinkle's line is cut into cross-sections a fraction of its width apart.  A section
has a centre C on the line and two ends P0, P1 on the surface, `width` apart across the
line, all three bound to the skin by barycentric coordinates so they move with it.  At a
frame, with d = |P0 P1| now and d0 at rest:

* the rest cross-section spans the arc length S0 = S(d0, d0/3, beta) (eq. 13), beta the
  angle between the chord and the surface at the ends (the 3D case, §5.2: alpha runs from
  alpha_min = beta);
* the skin keeps its length, grown by age: d_real = dil(S0, age) (eq. 10);
* the section over the current chord d must reach d_real: (a, alpha) from the table's
  inversion (eq. 14, §5.1), tabulated once for the starting tangent a0 = d/3;
* the skin near the line is moved along the surface normal by the section's height above
  its rest shape, y(alpha) - y(beta), times the wrinkle's emphasis; "in" folds it inward
  (a furrow), "out" outward.

A young face at rest (age <= AGE_0, d = d0) has alpha = beta and no wrinkle; compression
(d < d0) or age (d_real > S0) raise it.  The heights are exact functions of a point's place
across the line, so the same state also bakes into a displacement map (`maps.py`) at any
resolution.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from ..errors import MimicaError
from ..mesh import Mesh
from ..mesh.query import TriangleLocator
from .bulge import ArcLengthTable, dilation
from .mask import WrinkleMask
from .surface import cardinal_spline, resample_polyline

SKEW = {"symmetric": 1.0, "asymmetric": 0.5}
RHO0 = 1.0 / 3.0             # a0 = d / 3: at alpha = 0 the section is the straight chord
Q_MAX = 4.0                  # sections compressed to a quarter of their length and beyond: capped


@cache
def _inverse(skew):
    return ArcLengthTable.build(skew=skew).inverse(RHO0)


class ProfileTable:
    """The unit-chord section height y(q, t) for the length ratio q = d_real / d and the place t
    across: alpha and a follow from q alone (a0 = d/3), so the whole bulge is a function of two
    variables, tabulated once and read bilinearly per point and frame.

    Parameters
    ----------
    skew : float
        The section's asymmetry (bulge.control_points).
    nq, nt : int
        The table's size along q and t.
    """

    def __init__(self, skew: float, nq: int = 256, nt: int = 65):
        qq, al, rr = _inverse(skew)
        self.nq, self.nt = nq, nt
        x = np.linspace(0.0, 1.0, nq)
        q = 1.0 + (Q_MAX - 1.0) * x * x              # alpha ~ sqrt(q - 1): uniform in x
        t = np.linspace(0.0, 1.0, nt)
        alpha, rho = np.interp(q, qq, al), np.interp(q, qq, rr)
        self.y = profile(t[None, :], rho[:, None], alpha[:, None], skew, 12).ravel()
        self.dy = np.r_[np.diff(self.y), 0.0]         # y[k + 1] - y[k]: the step across, per cell

    def column(self, t):
        """The part of a lookup that depends on t alone (fixed for a point bound to a
        wrinkle): the cell's column and the weight across it."""
        tt = np.asarray(t, float) * (self.nt - 1)
        j = np.minimum(tt.astype(np.intp), self.nt - 2)
        return j, tt - j

    def at(self, q, j, ft):
        """y(q, t) with t given by `column(t)`: bilinear in (sqrt(q - 1), t)."""
        x = q - 1.0
        x *= 1.0 / (Q_MAX - 1.0)
        np.clip(x, 0.0, 1.0, out=x)
        np.sqrt(x, out=x)
        x *= self.nq - 1
        i = np.minimum(x.astype(np.intp), self.nq - 2)
        x -= i                                      # the weight along q
        k = i * self.nt
        k += j
        y, dy = self.y, self.dy
        lo = dy[k]
        lo *= ft
        lo += y[k]
        k += self.nt
        hi = dy[k]
        hi *= ft
        hi += y[k]
        hi -= lo
        hi *= x
        hi += lo
        return hi

    def __call__(self, q, t):
        return self.at(np.array(q, float), *self.column(t))


def _between(v, k0, k1, f):
    """Per point, v of its two sections interpolated: v[k0] + f (v[k1] - v[k0])."""
    out = v[k1]
    out -= v[k0]
    out *= f.reshape(f.shape + (1,) * (v.ndim - 1))
    out += v[k0]
    return out


@cache
def _profiles(skew):
    return ProfileTable(skew)


def profile(t, rho, alpha, skew, iterations=4):
    """The height of the unit-chord section (V&Y eqs. 11-12, d = 1) at a place across it.

    Parameters
    ----------
    t : float array
        Across, in [0, 1].
    rho, alpha : float array
        The section's a / d and its tangents' angle.
    skew : float or float array
    iterations : int
        Newton steps inverting x(u) = t.

    Returns
    -------
    float array
    """
    c0, s0 = rho * np.cos(alpha), rho * np.sin(alpha)
    if np.isscalar(skew) and skew == 1.0:
        c1, s1 = c0, s0
    else:
        sa = skew * alpha
        c1, s1 = skew * rho * np.cos(sa), skew * rho * np.sin(sa)
    # Bezier x(u) = A u^3 + B u^2 + C u (x0 = 0, x3 = 1); Newton on x(u) = t from u = t
    C = 3.0 * c0
    B = 3.0 * (1.0 - c1) - 6.0 * c0
    A = 1.0 - 3.0 * (1.0 - c1) + 3.0 * c0
    u = np.array(np.broadcast_to(t, np.broadcast_shapes(np.shape(t), np.shape(c0))), float)
    for _ in range(iterations):                 # x is monotone (a cos alpha <= d/3)
        x = ((A * u + B) * u + C) * u
        dx = (3.0 * A * u + 2.0 * B) * u + C
        u -= (x - t) / np.maximum(dx, 1e-3)
        np.clip(u, 0.0, 1.0, out=u)
    v = 1.0 - u
    return 3.0 * u * v * (v * s0 + u * s1)


# a wrinkle's depth at its muscle's full contraction, against at rest: a
# mimica choice, not measured (Viaud & Yahia drive the bulge by compression and age alone)
MUSCLE_EMPHASIS = 0.5


@dataclass
class Binding:
    """Points tied to the wrinkle sections: which point, which two sections, where across.

    Attributes
    ----------
    point : (m,) int array
        Index into the bound point set.
    k0, k1 : (m,) int arrays
        The section before and after.
    f : (m,) float array
        The weight of the after.
    t : (m,) float array
        Across the line, 0 at P0 .. 1 at P1.
    gain : (m,) float array
        Emphasis x taper x fold sign.
    rest : (m,) float array
        The rest section's height at t (unit chord), subtracted.
    kn : (m,) int array
        The nearer of the two sections (its normal is used).
    groups : list of tuple
        (skew, slice): points sorted by section profile.
    n_points : int
    """
    point: np.ndarray         # (m,) index into the bound point set
    k0: np.ndarray            # (m,) section before, (m,) after, and the weight of the after
    k1: np.ndarray
    f: np.ndarray
    t: np.ndarray             # across the line, 0 at P0 .. 1 at P1
    gain: np.ndarray          # emphasis x taper x fold sign
    rest: np.ndarray          # the rest section's height at t (unit chord), subtracted
    kn: np.ndarray            # the nearer of the two sections (its normal is used)
    groups: list              # [(skew, slice)]: points sorted by section profile
    n_points: int
    col: np.ndarray = None    # the profile table's column of t and the weight across it
    ft: np.ndarray = None
    span: slice | None = None  # the points as a slice, when they are consecutive

    def __post_init__(self):
        j, ft = [], []
        for sk, sl in self.groups:
            a, b = _profiles(sk).column(self.t[sl])
            j.append(a)
            ft.append(b)
        self.col = np.concatenate(j) if j else np.zeros(0, np.intp)
        self.ft = np.concatenate(ft) if ft else np.zeros(0)
        p = self.point
        if len(p) and p[-1] - p[0] == len(p) - 1 and np.all(np.diff(p) == 1):
            self.span = slice(int(p[0]), int(p[-1]) + 1)


class WrinkleLayer:
    """A mask's wrinkles on one skin mesh; `apply(X, age)` adds the bulges to positions X (V&Y §4-5:
    each wrinkle's sections follow the skin's compression along it, their depth its age).

    Parameters
    ----------
    mesh : Mesh
        The skin.
    mask : WrinkleMask
        On it.
    spacing : float
        The spacing of the sections along a wrinkle, in its widths.
    taper : float
        The share of a wrinkle's length over which its ends fade.
    """

    def __init__(self, mesh: Mesh, mask: WrinkleMask, spacing: float = 0.6, taper: float = 0.3):
        self.mesh = mesh
        X0 = mesh.vertices
        tris = mesh.triangles
        loc = TriangleLocator(X0, tris)
        normals = mesh.vertex_normals(X0)
        self.mask = mask
        sec_tri, sec_bary, wid, starts, n_centre = [], [], [], [0], []
        for i, w in enumerate(mask.wrinkles):
            _, _, pts, _ = loc.closest(cardinal_spline(w.points, 16))
            tc, bc, pts, _ = loc.closest(resample_polyline(pts, spacing * w.width, min_points=4))
            t = np.gradient(pts, axis=0)
            t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-12)
            n = np.einsum("ij,ijk->ik", bc, normals[tris[tc]])
            b = np.cross(n, t)
            b /= np.maximum(np.linalg.norm(b, axis=1, keepdims=True), 1e-12)
            t0, b0, _, _ = loc.closest(pts - 0.5 * w.width * b)
            t1, b1, _, _ = loc.closest(pts + 0.5 * w.width * b)
            sec_tri.append(np.stack([t0, t1, tc], 1))
            sec_bary.append(np.stack([b0, b1, bc], 1))
            wid.append(np.full(len(pts), i))
            starts.append(starts[-1] + len(pts))
            n_centre.append(n)
        self.sec_vid = tris[np.concatenate(sec_tri)]            # (K, 3 points, 3 vertices)
        self.sec_bary = np.concatenate(sec_bary)                 # (K, 3, 3)
        self._relabel_sections(mesh.n_vertices)
        self.sec_wrinkle = np.concatenate(wid)
        self.starts = np.array(starts)
        K = len(self.sec_wrinkle)
        idx = np.arange(K)
        first = self.starts[self.sec_wrinkle]
        last = self.starts[self.sec_wrinkle + 1] - 1
        self.prev, self.next = np.maximum(idx - 1, first), np.minimum(idx + 1, last)
        self.skew = np.array([SKEW[mask.wrinkles[i].profile] for i in self.sec_wrinkle])
        P0, P1, C = self._points(X0)
        chord = P1 - P0
        self.d0 = np.linalg.norm(chord, axis=1)
        if (self.d0 <= 0).any():
            raise MimicaError("wrinkle mask: a cross-section has zero width on this face")
        c = chord / self.d0[:, None]
        n_end = [np.einsum("ij,ijk->ik", self.sec_bary[:, e], normals[self.sec_vid[:, e]]) for e in (0, 1)]
        beta = 0.5 * (np.arcsin(np.clip(-(c * n_end[0]).sum(1), -1, 1)) + np.arcsin(np.clip((c * n_end[1]).sum(1), -1, 1)))
        self.beta = np.clip(np.abs(beta), 0.0, 1.2)
        self.s0 = np.empty(K)                                     # rest arc length ratio S0 / d0
        for sk in np.unique(self.skew):
            q, al, _ = _inverse(sk)
            m = self.skew == sk
            self.s0[m] = np.interp(self.beta[m], al, q)          # invert alpha(q) (monotone)
        self.orient = np.sign((self._normals(P0, P1, C) * np.concatenate(n_centre)).sum(1) + 1e-12)
        self._rest_points = P0, P1, C
        # dense centre lines, for binding points to sections
        sub = 8
        fr = np.linspace(0, 1, sub, endpoint=False)
        ks = np.concatenate([np.arange(self.starts[i], self.starts[i + 1] - 1) for i in range(len(mask.wrinkles))])
        self._dense_k = np.r_[np.repeat(ks, sub), self.starts[1:] - 1]
        self._dense_f = np.r_[np.tile(fr, len(ks)), np.zeros(len(mask.wrinkles))]
        nk = np.minimum(self._dense_k + 1, last[self._dense_k])
        self._tree = cKDTree(C[self._dense_k] * (1 - self._dense_f[:, None]) + C[nk] * self._dense_f[:, None])
        seg = np.linalg.norm(C[self.next] - C[idx], axis=1) * (self.next > idx)
        cs = np.r_[0.0, np.cumsum(seg)][:K]
        self._arc = cs - cs[first]                                 # arc length from the line's start
        self._length = self._arc[self.starts[1:] - 1]
        self.taper = taper
        self.width = np.array([w.width for w in mask.wrinkles])
        self.gain = np.array([w.emphasis * (-1.0 if w.fold == "in" else 1.0) for w in mask.wrinkles])
        self.vertex_binding = self.bind(X0)

    def _relabel_sections(self, n):
        K = len(self.sec_vid)
        rows = np.broadcast_to(np.arange(3 * K).reshape(3, K).T[:, :, None], self.sec_vid.shape)
        self._sec_op = sp.csr_matrix((self.sec_bary.ravel(), (rows.ravel(), self.sec_vid.ravel())),
                                     shape=(3 * K, n))      # rows: every P0, then every P1, every C
        self._sec_op.sort_indices()

    def relabel(self, mesh: Mesh, new_index: np.ndarray) -> None:
        """The same layer on `mesh`, whose vertex i was this mesh's vertex j with new_index[j] = i."""
        self.mesh = mesh
        self.sec_vid = new_index[self.sec_vid]
        self._relabel_sections(mesh.n_vertices)
        b = self.vertex_binding
        self.vertex_binding = Binding(new_index[b.point], b.k0, b.k1, b.f, b.t, b.gain, b.rest, b.kn,
                                      b.groups, b.n_points)

    # ------------------------------------------------------------------ geometry
    def _points(self, X):
        Q = (self._sec_op @ X).reshape(3, -1, 3)
        return Q[0], Q[1], Q[2]

    def _normals(self, P0, P1, C, a=None):
        a = P1 - P0 if a is None else a
        b = np.take(C, self.next, axis=0) - np.take(C, self.prev, axis=0)
        n = np.empty_like(a)                                      # -(a x b), written out
        n[:, 0] = a[:, 2] * b[:, 1] - a[:, 1] * b[:, 2]
        n[:, 1] = a[:, 0] * b[:, 2] - a[:, 2] * b[:, 0]
        n[:, 2] = a[:, 1] * b[:, 0] - a[:, 0] * b[:, 1]
        return n / np.maximum(np.sqrt(np.einsum("ij,ij->i", n, n)), 1e-30)[:, None]

    def bind(self, points) -> Binding:
        """Tie points (m, 3) on the rest surface to the sections whose band holds them."""
        P0, P1, C = self._rest_points
        p = np.asarray(points, float)
        reach = 0.6 * float(self.width.max())
        dist, j = self._tree.query(p, distance_upper_bound=reach)
        cand = np.nonzero(np.isfinite(dist))[0]
        j = j[cand]
        k0, f = self._dense_k[j], self._dense_f[j]
        w = self.sec_wrinkle[k0]
        k1 = np.minimum(k0 + 1, self.starts[w + 1] - 1)
        c, a0, a1 = (_between(v, k0, k1, f) for v in (C, P0, P1))
        across = a1 - a0
        dd = np.linalg.norm(across, axis=1)
        rel = p[cand] - c
        t = 0.5 + (rel * across).sum(1) / np.maximum(dd * dd, 1e-30)
        tang = C[self.next[k0]] - C[self.prev[k0]]
        tang /= np.maximum(np.linalg.norm(tang, axis=1, keepdims=True), 1e-30)
        ta = (rel * tang).sum(1)
        along = np.abs(ta)
        height = np.linalg.norm(rel - ta[:, None] * tang - (t - 0.5)[:, None] * across, axis=1)
        step = np.linalg.norm(C[k1] - C[k0], axis=1) / 8 + 1e-12
        ok = (t > 0) & (t < 1) & (along <= step + 0.05 * self.width[w]) & (height < 0.5 * self.width[w])
        cand, k0, k1, f, t, w = cand[ok], k0[ok], k1[ok], f[ok], t[ok], w[ok]
        # taper the ends of the line (smoothstep over `taper` of its length)
        s = _between(self._arc, k0, k1, f)
        L = self._length[w]
        e = np.clip(np.minimum(s, L - s) / np.maximum(self.taper * L, 1e-12), 0, 1)
        taper = e * e * (3 - 2 * e)
        skew = self.skew[k0]
        o = np.argsort(skew, kind="stable")
        cand, k0, k1, f, t, w, taper, skew = (a[o] for a in (cand, k0, k1, f, t, w, taper, skew))
        s0 = _between(self.s0, k0, k1, f)
        groups, rest = [], np.empty(len(t))
        for sk in np.unique(skew):
            idx = np.nonzero(skew == sk)[0]
            sl = slice(int(idx[0]), int(idx[-1]) + 1)
            groups.append((float(sk), sl))
            rest[sl] = _profiles(float(sk))(s0[sl], t[sl])
        return Binding(cand, k0, k1, f, t, self.gain[w] * taper, rest, np.where(f < 0.5, k0, k1), groups, len(p))

    # ------------------------------------------------------------------ per frame
    def state(self, X, age: float):
        """Per section at positions X: the chord d, the length ratio q = d_real / d the bulge
        must reach (never below the rest section's: a stretched section stays flat), and the
        unit normal."""
        P0, P1, C = self._points(X)
        a = P1 - P0
        d = np.sqrt(np.einsum("ij,ij->i", a, a))
        # eq. 10 on the rest arc length S0 = s0 d0, over the rest section's length s0 d now
        r = float(dilation(1.0, age)) * self.d0 / np.maximum(d, 1e-30)
        for _ in range(2):                  # smooth along the line: a fold is even along its length
            r = 0.5 * r + 0.25 * (r[self.prev] + r[self.next])
        q = np.maximum(r, 1.0) * self.s0
        n = self._normals(P0, P1, C, a)
        n *= self.orient[:, None]
        return d, q, n

    def bulge(self, X, age: float):
        """Per section: (d, a, alpha) of the cubic whose arc length is d_real (eqs. 10-14)."""
        d, q, _ = self.state(X, age)
        a, alpha = np.empty_like(q), np.empty_like(q)
        for sk in np.unique(self.skew):
            m = self.skew == sk
            qq, al, rr = _inverse(sk)
            alpha[m] = np.interp(q[m], qq, al)                     # alpha first, then a (§5.1)
            a[m] = np.interp(q[m], qq, rr) * d[m]
        return d, a, alpha

    def muscle_emphasis(self, activations: dict) -> np.ndarray:
        """(n_wrinkles,) each wrinkle's emphasis from the muscles its mask names: 1 at rest,
        1 + MUSCLE_EMPHASIS x the most active of them (a departure from Viaud & Yahia, whose
        bulge follows the skin's compression and age alone: the folding muscle's
        pull counts for it too; contractions only, relaxations leave it at 1)."""
        return np.array([1.0 + MUSCLE_EMPHASIS * max([0.0] + [max(float(activations.get(m, 0.0)), 0.0)
                                                              for m in w.muscles])
                         for w in self.mask.wrinkles])

    def heights(self, binding: Binding, state, emphasis: np.ndarray | None = None) -> np.ndarray:
        """Signed height (along the normal) of every bound point, (len(binding.point),);
        emphasis: a factor per wrinkle (muscle_emphasis)."""
        d, q, _ = state
        b = binding
        qv = _between(q, b.k0, b.k1, b.f)
        y = np.empty_like(qv)
        for sk, sl in b.groups:
            y[sl] = _profiles(sk).at(qv[sl], b.col[sl], b.ft[sl])
        y -= b.rest
        y *= _between(d, b.k0, b.k1, b.f)
        y *= b.gain
        if emphasis is not None:
            y *= np.asarray(emphasis, float)[self.sec_wrinkle[b.kn]]
        return y

    def _offsets(self, X, age, b, emphasis=None):
        st = self.state(X, age)
        out = np.take(st[2], b.kn, axis=0)
        out *= self.heights(b, st, emphasis)[:, None]
        return out

    def displacement(self, X, age: float, binding: Binding | None = None, emphasis=None) -> np.ndarray:
        """(n, 3) displacement of the bound points at positions X (the mesh's vertices)."""
        b = self.vertex_binding if binding is None else binding
        out = np.zeros((b.n_points, 3))
        out[b.point] = self._offsets(X, age, b, emphasis)
        return out

    def apply(self, X, age: float, inplace: bool = False, emphasis=None) -> np.ndarray:
        """Positions X with the wrinkles' bulges added (into X itself when inplace); emphasis:
        a factor per wrinkle (muscle_emphasis)."""
        b = self.vertex_binding
        Y = X if inplace else X.copy()
        if b.span is not None:
            Y[b.span] += self._offsets(X, age, b, emphasis)
        else:
            Y[b.point] += self._offsets(X, age, b, emphasis)
        return Y

    def compression(self, X) -> np.ndarray:
        """Per wrinkle, the mean of d / d0 over its sections (< 1: compressed)."""
        P0, P1, _ = self._points(X)
        r = np.linalg.norm(P1 - P0, axis=1) / self.d0
        return np.bincount(self.sec_wrinkle, r) / np.bincount(self.sec_wrinkle)


__all__ = ["WrinkleLayer", "Binding", "profile"]
