"""Lid contacts: the target's lids close as far as the source's do.

A transfer carries the source's deformation gradients, not where its lid rims meet: on a
target of another topology a blink closes the lids part of the way (ICT's own eyeBlink closes
its lid landmarks by 0.865; transferred onto remeshed heads 0.30-0.61, bench/real_heads.py).
Here each open eye of the target has its rim found (the boundary loop of its opening) and
split into the upper and the lower lid at the corners; every upper rim vertex is paired with the
point of the lower rim across from it.  Per frame, the source's lid closure c (1 - lid gap / rest
gap, its landmark pairs 37-41, 38-40, 43-47, 44-46) closes each pair by c x its travel (its rest
gap, or the lid's gap at the target's landmarks where that is wider: a rim cut inside the margin
moves as the margin does), the rims meeting at most; the rim moves along the pair (the upper lid
UPPER_SHARE of the way, as lids do), and the correction spreads over the lid by harmonic
interpolation (zero at the edge of the eye's region), one factorization per target.  Our own
step, not the paper's: Song et al. carry gradients only; measured in bench/real_heads.py.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..align import face_cylinder
from ..mesh import Mesh
from ..mesh.graph import HarmonicFill

EYES = {"right": (slice(36, 42), [(37, 41), (38, 40)], 36, 39),
        "left": (slice(42, 48), [(43, 47), (44, 46)], 42, 45)}
UPPER_SHARE = 0.8            # the upper lid makes most of a blink's travel (ICT's own blink: 0.96 of
# it at the landmarks; that share taken from the source per frame read worse on the made heads with
# found landmarks, e.g. one-surface 34L 0.78 -> 0.74, the remeshed head with holes 0.90 -> 0.87)
REACH = 1.2                  # the correction's region: within REACH x the eye's width of its centre
BAND = 0.2                   # the lid margin that moves with the rim, in eye widths ...
WHOLE = 0.1                  # ... wholly within this of it (the lid's tarsal plate), fading to none at BAND
# (one-surface dev heads 13-16, 20, 24, 30, 42, landmarks found: the cut's rim runs up to 0.1 of the
# width below a lid's landmarks (the crease lies under the margin); blink mean 0.78 -> 0.80, 20L 0.67
# -> 0.73, 14L 0.80 -> 0.87, 15L 0.77 -> 0.73, against a band fading from the rim out to 0.12;
# 0.3 / 0.15 as 0.2 / 0.1)


def closure(lm_rest: np.ndarray, lm: np.ndarray, side: str):
    """How far an eye is closed: 1 - lid gap / rest gap, from the landmark pairs of one eye (37-41,
    38-40 or 43-47, 44-46).

    Parameters
    ----------
    lm_rest : (68, 3) float array
    lm : (68, 3) or (F, 68, 3) float array
        One frame, or every frame at once.
    side : str
        "left" or "right".

    Returns
    -------
    float or (F,) float array
    """
    return 1.0 - _lid_gap(lm, side) / max(float(_lid_gap(lm_rest, side)), 1e-12)


def _lid_gap(lm: np.ndarray, side: str):
    a, b = np.array(EYES[side][1]).T
    return np.linalg.norm(lm[..., a, :] - lm[..., b, :], axis=-1).mean(-1)


class _Eye:
    def __init__(self, mesh: Mesh, lm: np.ndarray, side: str, up: np.ndarray):
        rim_lm, _, c0, c1 = EYES[side]
        self.ok = bool(np.isfinite(lm[rim_lm]).all())
        if not self.ok:
            return
        centre = lm[rim_lm].mean(0)
        width = float(np.linalg.norm(lm[c1] - lm[c0]))
        v = mesh.vertices
        rim = _opening(mesh, centre, 0.8 * width)
        self.ok = len(rim) >= 6
        if not self.ok:
            return
        axis = lm[c1] - lm[c0]
        t = (v[rim] - lm[c0]) @ axis / (axis @ axis)
        h = (v[rim] - (lm[c0] + np.outer(t, axis))) @ up
        is_up = _upper_path(mesh, rim, h, lm[[c0, c1]])
        upper, lower = rim[is_up], rim[~is_up]
        tu, tl = t[is_up], t[~is_up]
        keep = (tu > 0.05) & (tu < 0.95)
        upper, tu = upper[keep], tu[keep]
        self.ok = len(upper) >= 2 and len(lower) >= 2
        if not self.ok:
            return
        order = np.argsort(tl)
        lower, tl = lower[order], tl[order]
        # the lids matched by arc length between the landmarks (corner, the two lid points,
        # corner): the upper rim's point at a share s of the way from 37 to 38 meets the lower
        # rim's point at the same share from 41 to 40, as the source's lids meet
        knots_up, knots_lo = ((c0, c0 + 1, c0 + 2, c1), (c0, c0 + 5, c0 + 4, c1))
        su = _arc_param(v[upper[np.argsort(tu)]], lm[list(knots_up)])
        upper = upper[np.argsort(tu)]
        sl = _arc_param(v[lower], lm[list(knots_lo)])
        tu, tl = su, np.maximum.accumulate(sl)
        j = np.clip(np.searchsorted(tl, tu), 1, len(tl) - 1)       # the lower rim across, interpolated
        w = np.clip((tu - tl[j - 1]) / np.maximum(tl[j] - tl[j - 1], 1e-12), 0, 1)
        self.upper, self.lo0, self.lo1, self.w = upper, lower[j - 1], lower[j], w
        self.rest_gap = self._gap(v[None])[0]
        # how far each pair closes at a closure of 1: its gap, or the lid's gap at its landmarks
        # where that is wider (a cut eye's rim runs along the valley inside the margin, up to 0.1
        # of the width): the rim's gap scaled by the landmarks' gap over the rim's at 37-41 and
        # 38-40, interpolated between them and held out to the corners (one-surface dev heads, found
        # landmarks: mean blink 0.80 -> 0.83, 42R 0.74 -> 0.79, 14R 0.82 -> 0.92; crossing the rims
        # to close the landmarks wholly read worse, 15L 0.76 -> 0.65)
        g = [np.linalg.norm(lm[c0 + k] - lm[c0 + 6 - k]) for k in (1, 2)]
        ratio = np.array(g) / np.maximum(np.interp([1, 2], su, self.rest_gap), 1e-12)
        self.travel = self.rest_gap * np.maximum(np.interp(su, [1, 2], ratio), 1.0)
        # harmonic spread over the eye's region, the rim pairs' corrections as the constraints
        region = np.nonzero(np.linalg.norm(v - centre, axis=1) < REACH * width)[0]
        # the lid margin: skin within BAND x the eye's width of the rim moves with its rim
        # vertex (wholly within WHOLE, fading out beyond), so the lid closes as a band, not as a
        # thread at its edge
        rim_ids = np.unique(np.r_[upper, self.lo0, self.lo1])       # the paired rim (the rest is free)
        near = region[~np.isin(region, rim)]
        dist, k = cKDTree(v[rim_ids]).query(v[near])
        inband = dist < BAND * width
        self.band, self.band_of = near[inband], rim_ids[k[inband]]
        self.band_w = np.minimum((BAND * width - dist[inband]) / ((BAND - WHOLE) * width), 1.0)
        fixed = np.zeros(mesh.n_vertices, bool)
        fixed[np.r_[rim_ids, self.band]] = True
        a = mesh.adjacency.tocsr()
        inside = np.zeros(mesh.n_vertices, bool)
        inside[region] = True
        outer = inside & (np.asarray(a[:, ~inside].sum(1)).ravel() > 0)    # the region's own edge
        free = np.nonzero(inside & ~fixed & ~outer)[0]
        self.cons = np.nonzero(fixed)[0]
        self.free = free
        self.fill = HarmonicFill(a, free, self.cons, screen=0.0) if len(free) else None

    def _partner(self, v):
        """The lower rim's point across each upper rim vertex; v: (..., n, 3)."""
        return (1 - self.w)[:, None] * v[..., self.lo0, :] + self.w[:, None] * v[..., self.lo1, :]

    def _gap(self, v):
        return np.linalg.norm(self._partner(v) - v[..., self.upper, :], axis=-1)

    def correct(self, v: np.ndarray, c: np.ndarray) -> np.ndarray:
        """Frames v (F, n, 3) with this eye's rim gaps closed by c x their travel (c: (F,)
        closures; the rims meet at most), spread smoothly; one back-substitution for all frames."""
        d = self._partner(v) - v[:, self.upper]                      # (F, k, 3)
        gap = np.linalg.norm(d, axis=2)
        want = np.maximum(self.rest_gap[None] - np.asarray(c, float)[:, None] * self.travel[None], 0.0)
        step = ((gap - want) / np.maximum(gap, 1e-12))[..., None] * d   # closes each pair to `want`
        delta = np.zeros_like(v)
        delta[:, self.upper] = UPPER_SHARE * step
        acc, wsum = np.zeros_like(v), np.zeros(v.shape[1])          # a lower vertex: its pairs' mean
        for idx, wt in ((self.lo0, 1 - self.w), (self.lo1, self.w)):
            np.add.at(acc, (slice(None), idx), -(1 - UPPER_SHARE) * step * wt[None, :, None])
            np.add.at(wsum, idx, wt)
        lower = np.unique(np.r_[self.lo0, self.lo1])
        delta[:, lower] = acc[:, lower] / np.maximum(wsum[lower], 1e-12)[None, :, None]
        delta[:, self.band] = self.band_w[None, :, None] * delta[:, self.band_of]
        out = v.copy()
        dc = delta[:, self.cons]                                      # (F, m, 3)
        out[:, self.cons] += dc
        if self.fill is not None:
            out[:, self.free] += self.fill(dc.transpose(1, 0, 2)).transpose(1, 0, 2)
        return out


def _upper_path(mesh: Mesh, rim: np.ndarray, h: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """Which rim vertices are the upper lid's: the loop cut at its vertices nearest the two
    corners into two paths, the upper the one higher above the corners' line (h) on average; where
    the rim is not one simple loop, those above that line.  A cut eye's rim follows the valley
    inside the margin and can pass below the corners' line near a corner (one-surface dev heads:
    16L blink 0.63 -> 0.72; split by the line alone, lower-lid vertices there were paired as upper)."""
    p = mesh.vertices[rim]
    ends = [int(np.argmin(np.linalg.norm(p - k, axis=1))) for k in corners]
    at = np.full(mesh.n_vertices, -1)
    at[rim] = np.arange(len(rim))
    e = at[mesh.boundary_edges()]
    e = e[(e >= 0).all(1)]
    simple = ends[0] != ends[1] and (np.bincount(e.ravel(), minlength=len(rim)) == 2).all()
    e = e[~np.isin(e, ends).any(1)]
    g = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(len(rim), len(rim)))
    _, comp = connected_components(g, directed=False)
    comp[ends] = -1
    paths = [np.nonzero(comp == k)[0] for k in np.unique(comp[comp >= 0])]
    if not simple or len(paths) != 2:
        return h > 0
    out = np.zeros(len(rim), bool)
    out[max(paths, key=lambda q: h[q].mean())] = True
    return out


def _arc_param(chain: np.ndarray, knots: np.ndarray) -> np.ndarray:
    """Each point of a polyline (corner to corner, in order) -> its place along it in landmark
    units: 0 at the first knot, 1 at the second ..., linear in arc length between knots (the
    knots placed where the polyline passes nearest them)."""
    pts = np.vstack([knots[:1], chain, knots[-1:]])
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    arc = np.r_[0.0, np.cumsum(seg)]
    # the arc length of the polyline point nearest each knot
    a, b = pts[:-1], pts[1:]
    at = []
    for k in knots:
        ab = b - a
        t = np.clip(np.einsum("ij,ij->i", k - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-300), 0, 1)
        d = np.linalg.norm(a + t[:, None] * ab - k, axis=1)
        i = int(np.argmin(d))
        at.append(arc[i] + t[i] * seg[i])
    at = np.maximum.accumulate(np.array(at))
    return np.interp(arc[1:-1], at, np.arange(len(knots), dtype=float))


def _opening(mesh: Mesh, centre, radius) -> np.ndarray:
    """The vertices of the boundary loop nearest `centre` (the eye's opening), if it lies
    within `radius`; small holes beside it are other loops."""
    be = mesh.boundary_edges()
    if not len(be):
        return np.zeros(0, np.int64)
    n = mesh.n_vertices
    g = sp.coo_matrix((np.ones(len(be)), (be[:, 0], be[:, 1])), shape=(n, n))
    _, loop = connected_components(g, directed=False)
    b = np.unique(be)
    d = np.linalg.norm(mesh.vertices[b] - centre, axis=1)
    if d.min() > radius:
        return np.zeros(0, np.int64)
    members = b[loop[b] == loop[b[np.argmin(d)]]]
    return members[np.linalg.norm(mesh.vertices[members] - centre, axis=1) < radius]


class LidContacts:
    """A target's open eyes' rims, paired; `apply` closes them as far as the source's close.

    Parameters
    ----------
    target : Mesh
    target_lm : (68, 3) float array
    source_lm_rest : (68, 3) float array
        The source's landmarks at rest.
    """

    def __init__(self, target: Mesh, target_lm: np.ndarray, source_lm_rest: np.ndarray):
        up = face_cylinder(target_lm).axes[1]
        given = [s for s in EYES if np.isfinite(source_lm_rest[np.ravel(EYES[s][1])]).all()]
        self.eyes = {s: e for s in given if (e := _Eye(target, target_lm, s, up)).ok}
        self.source_rest = source_lm_rest

    def apply(self, source_lm_frames, out: np.ndarray) -> np.ndarray:
        """source_lm_frames: (F, 68, 3) the source's landmarks in each frame; out: (F, n, 3)."""
        for side, eye in self.eyes.items():
            out = eye.correct(out, closure(self.source_rest, source_lm_frames, side))
        return out
