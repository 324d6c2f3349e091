"""2D facial expression analogy (Song et al. §VI) and expression ratio images (Liu et al. 2001).

For a target photo T (neutral) and a source pair S (neutral), S' (expression):
1. feature points on all three (dlib, or the user's file);
2. S and S' aligned to T by similarities from the points (§VI step 2);
3. S and S' resampled onto the target's pixel grid through the feature points (S' by its
   own points, i.e. back to the material points of the neutral), so all three image grids
   share one topology (§VI.C);
4. each grid a height field (i, j, l = height * Y) (§VI.A); per pixel the VTC transformation
   Q = w' w^T (w w^T)^-1 (eq. 2) from S's to S''s vertex tent, applied to the target's tent;
   the new luminances solve eq. 4 restricted to l (i, j stay on the grid), D^T D l = D^T g,
   with the pixels outside the face held at the target's own (Dirichlet);
5. the result warped by the feature points' motion S -> S' (§VI.B), piecewise affine.
The paper warps first and solves on the warped grid; solving on the target's own grid is the
same correspondence (material points) with a domain that does not change from one
expression to the next, so the sparse system is factored once per target photo (§VI.D: "only
the luminance is solved", one factorization reused for every expression and video frame).
Only a box around the target's face is processed; the rest of the photo is kept.

Step 4 is the paper's appearance step (method "vtc").  The default (method "shading",
image.shading) departs from it: eq. 4 carries the source's shading under the source's light,
which lost to the warp alone on faces lit otherwise (rendered ICT pairs 24.84 vs 25.30 dB); the
expression's shading change is made on a generic 3D face under the target's own fitted light
instead (26.27 dB; docs/benchmarks.md).
"""

from __future__ import annotations

from functools import cached_property

import numpy as np

from ..errors import MimicaError
from .io import luminance, rgb_to_yuv, yuv_to_rgb
from .warp import (FOREHEAD_BROW, Bilinear, FOREHEAD_FOLLOW, PiecewiseAffine, Similarity2D, border_points,
                   forehead_points, head_motion, polygon_mask, sample, triangulate)


def psnr(a, b, mask=None) -> float:
    """Peak signal-to-noise ratio of images in [0, 1].

    Parameters
    ----------
    a, b : (h, w) or (h, w, c) float arrays
    mask : (h, w) bool array or None
        The pixels counted (None: all).

    Returns
    -------
    float
        dB.
    """
    d = (np.asarray(a, float) - np.asarray(b, float)) ** 2
    if d.ndim == 3:
        d = d.mean(-1)
    mse = float(d[mask].mean() if mask is not None else d.mean())
    return float("inf") if mse == 0 else 10 * np.log10(1.0 / mse)


class Result:
    """What ImageAnalogy.transfer made.

    Attributes
    ----------
    image : (H, W, 3) float array
        The target with the expression.
    points : (68, 2) float array
        The target's feature points after the warp.
    warped : (H, W, 3) float array
        The target warped only (shape, no appearance); made on first use.
    mask : (H, W) float array
        The face's weight in [0, 1] where the appearance was solved for; made on first use.
    """

    def __init__(self, image, points, analogy, lookup):
        self.image, self.points, self._an, self._lookup = image, points, analogy, lookup

    def _paste(self, crop):
        an = self._an
        x0, y0, x1, y1 = an.box
        full = np.zeros(an.target.shape[:2] + crop.shape[2:], np.float32) if crop.ndim == 2 else an.target.copy()
        full[y0:y1, x0:x1] = crop
        return full

    @cached_property
    def warped(self) -> np.ndarray:
        an = self._an
        return self._paste(np.clip(yuv_to_rgb(self._lookup(an.crop_yuv).reshape(an.h, an.w, 3)), 0, 1))

    @cached_property
    def mask(self) -> np.ndarray:
        an = self._an
        return self._paste(self._lookup(an.mask_t).reshape(an.h, an.w))


def _face_laplacian(inside):
    """D^T D restricted to the unknown pixels `inside` (h, w) bool: the grid Laplacian whose
    neighbours outside are known (Dirichlet); crop edges have no neighbour (Neumann)."""
    import scipy.sparse as sp
    h, w = inside.shape
    idx = -np.ones(h * w, np.int64)
    flat = inside.ravel()
    idx[flat] = np.arange(flat.sum())
    rows, cols = [], []
    deg = np.zeros(h * w)
    for a, b in ((np.arange(h * w).reshape(h, w)[:, :-1].ravel(), np.arange(h * w).reshape(h, w)[:, 1:].ravel()),
                 (np.arange(h * w).reshape(h, w)[:-1, :].ravel(), np.arange(h * w).reshape(h, w)[1:, :].ravel())):
        touch = flat[a] | flat[b]
        a, b = a[touch], b[touch]
        np.add.at(deg, a, 1.0)
        np.add.at(deg, b, 1.0)
        both = flat[a] & flat[b]
        rows += [idx[a[both]], idx[b[both]]]
        cols += [idx[b[both]], idx[a[both]]]
    n = int(flat.sum())
    r = np.concatenate(rows + [np.arange(n)])
    c = np.concatenate(cols + [np.arange(n)])
    v = np.concatenate([-np.ones(sum(len(x) for x in rows)), deg[flat]])
    return sp.csc_matrix((v, (r, c)), shape=(n, n))


class ImageAnalogy:
    """Expression transfer onto one target photo (Song et al. §VI); per-size tables built once,
    reused for every source pair (and every video frame).

    Parameters
    ----------
    target : (H, W, 3) float array
        The target photo, RGB in [0, 1].
    target_points : (68, 2) float array
        Its feature points (x, y).
    height : float
        The height field's scale (i, j, height * Y), Song's §VI.A.
    margin : float
        The face box grown by this share of its size.
    feather : float or None
        Pixels over which the face mask fades in from its outline (None: 4 % of the face's size,
        at least 2).
    mouth : bool
        Fill an opening mouth from the source's (fill_mouth) when the target's is closed.
    rest_points : (68, 2) float array or None
        The target's own resting face (another photo of the same person, neutral: its points in
        that photo's pixels). Given, the target photo may wear an expression of its own, and the
        results wear the source's expression from that rest instead of added to the target's:
        the target's points go to rest + the source's motion (an absolute neutral, not the target
        photo's expression plus the source's). For the methods "shading" and "warp".
    """

    def __init__(self, target, target_points, height=1.0, margin=0.25, feather=None, mouth=True, rest_points=None):
        t = np.asarray(target, np.float32)
        if t.ndim != 3 or t.shape[2] != 3:
            raise MimicaError("target: expected an RGB image (h, w, 3)")
        p = np.asarray(target_points, float)
        if p.shape != (68, 2) or not np.isfinite(p).all():
            raise MimicaError("target: 68 finite feature points (x, y) are needed")
        self.target, self.points, self.height = t, p, float(height)
        self.rest = None
        if rest_points is not None:
            r = np.asarray(rest_points, float)
            if r.shape != (68, 2) or not np.isfinite(r).all():
                raise MimicaError("target's resting face: 68 finite feature points (x, y) are needed")
            self.rest = head_motion(r, p)(r)          # into the target photo's frame, on the stable points
        H, W = t.shape[:2]
        face = np.concatenate([p, forehead_points(p)])
        lo, hi = face.min(0), face.max(0)
        pad = margin * (hi - lo).max()
        x0, y0 = (np.floor(np.maximum(lo - pad, 0))).astype(int)
        x1, y1 = (np.ceil(np.minimum(hi + pad, [W, H]))).astype(int)
        if x1 - x0 < 16 or y1 - y0 < 16:
            raise MimicaError("target: the face box is smaller than 16 pixels")
        self.box = (x0, y0, x1, y1)
        self.w, self.h = x1 - x0, y1 - y0
        off = np.array([x0, y0], float)
        self.border = border_points(self.w, self.h)                     # crop coordinates
        self.ctrl_t = np.concatenate([face - off, self.border])          # target control points (crop)
        self.n_face = len(face)
        self.tris = triangulate(self.ctrl_t)
        self.face_tri = (self.tris < self.n_face).all(1)
        self.crop = t[y0:y1, x0:x1]
        self.crop_yuv = rgb_to_yuv(self.crop)
        # the mask fades out over this many pixels inside the face outline (§VI.D: keep the
        # source's contour off the target)
        self.feather = feather or max(2.0, 0.04 * (hi - lo).max())
        self.grid = PiecewiseAffine(self.ctrl_t, self.tris, self.w, self.h)   # the target's own grid
        self.mouth = mouth                   # fill_mouth on results when the target's mouth is closed
        self.mask_t = self._neutral_mask()
        from ..solver import SPDSolver
        self.inside = self.mask_t > 0
        self._solver = SPDSolver(_face_laplacian(self.inside))               # factored once

    # -- geometry ----------------------------------------------------------------------------
    def _controls(self, s_pts, x_pts, strength=1.0):
        """Control points (crop coordinates for the target, image coordinates for the sources);
        the target moves by `strength` times the sources' feature motion, the sources are read
        at their own points."""
        s_pts, x_pts = np.asarray(s_pts, float), np.asarray(x_pts, float)
        a = Similarity2D.fit(s_pts, self.points)                         # S -> T (step 2)
        b = head_motion(x_pts, s_pts)                                    # S' -> S
        d68 = b(x_pts) - s_pts                                           # feature motion in S
        d_fh = FOREHEAD_FOLLOW[:, None] * d68[FOREHEAD_BROW]
        d = np.concatenate([d68, d_fh, np.zeros((len(self.border), 2))])
        off = np.array(self.box[:2], float)
        p_s = np.concatenate([s_pts, forehead_points(s_pts), a.inverse()(self.border + off)])
        p_x = b.inverse()(p_s + d)
        k = self._control_strengths(strength)[:, None]
        move = a.linear(d)
        if self.rest is not None:                                        # from the target's own rest
            r68 = self.rest - self.points
            move = move + np.concatenate([r68, FOREHEAD_FOLLOW[:, None] * r68[FOREHEAD_BROW],
                                          np.zeros((len(self.border), 2))])
        p_tw = self.ctrl_t + k * move                                    # step 3: T warped
        return p_s, p_x, p_tw

    def _control_strengths(self, strength) -> np.ndarray:
        """Strength per control point: a number, or (68,) per feature point (the forehead's
        points take their brow's; the border does not move)."""
        s = np.broadcast_to(np.asarray(strength, float), (68,))
        return np.concatenate([s, s[FOREHEAD_BROW], np.zeros(len(self.border))])

    def _strength_map(self, strength):
        """Strength per pixel of the target's grid: the control points' interpolated over the
        triangulation (a number where every point has the same)."""
        s = np.asarray(strength, float)
        if s.ndim == 0 or np.all(s == s.flat[0]):
            return float(s.flat[0])
        c = self._control_strengths(s)
        c[len(c) - len(self.border):] = 0.0
        m, _ = self.grid.map(np.stack([c, c], 1))
        return np.clip(m.reshape(self.h, self.w), 0, 2).astype(np.float32)

    def _neutral_mask(self) -> np.ndarray:
        """Face weight on the target's own grid: 0 outside the face triangles, rising to 1 over
        `feather` pixels inside the outline."""
        from scipy.ndimage import distance_transform_edt
        pa = self.grid
        inside = (self.face_tri[pa.tri_id] & pa.covered).reshape(self.h, self.w)
        return np.clip(distance_transform_edt(inside) / self.feather, 0, 1).astype(np.float32)

    def prepare(self, source, s_pts, expressive, x_pts, strength=1.0, resample=True):
        """Steps 2-3: both sources resampled onto the target's grid (crop; None without
        `resample`, for the appearance steps that do not read them), and the warp of step 5."""
        p_s, p_x, p_tw = self._controls(s_pts, x_pts, strength)
        hw = (self.h, self.w)
        s_r = sample(luminance(source), *self.grid.map(p_s)).reshape(hw) if resample else None
        x_r = sample(luminance(expressive), *self.grid.map(p_x)).reshape(hw) if resample else None
        warp = Bilinear(*PiecewiseAffine(p_tw, self.tris, self.w, self.h).map(self.ctrl_t), self.h, self.w)
        off = np.array(self.box[:2], float)
        return s_r, x_r, warp, p_tw[:68] + off

    # -- appearance ----------------------------------------------------------------------------
    @cached_property
    def _target_terms(self):
        """What the solve needs of the target alone, once: its height field, its tents'
        neighbour differences, and the right-hand side of the held pixels next to the face."""
        t = self.crop_yuv[..., 0] * np.float32(self.height)
        out_ = np.where(self.inside, 0, t)
        known = np.zeros_like(t)
        known[:, 1:] += out_[:, :-1]
        known[:, :-1] += out_[:, 1:]
        known[1:, :] += out_[:-1, :]
        known[:-1, :] += out_[1:, :]
        return t, _diffs(t), known[self.inside]

    def vtc_luminance(self, s_l, x_l, strength=1.0) -> np.ndarray:
        """The target's new luminance from the sources' (both on the target's grid, Y in
        [0, 1]): eq. 2 per pixel, then eq. 4 for the luminance alone (the face's pixels unknown,
        the rest held: one back-substitution of the per-target factor).  With strength a != 1
        each tent's transformation is (1 - a) I + a Q."""
        k = np.float32(self.height)
        strength = self._strength_map(strength)
        mask = self.mask_t if np.isscalar(strength) and strength == 1 else self.mask_t * np.float32(strength)
        t, dt, known = self._target_terms
        s, x = s_l * k, x_l * k
        # neighbour differences right/left/down/up (edge-replicated: zero across the border)
        ds, dx_ = _diffs(s), _diffs(x)
        ns, nx = _tip(s), _tip(x)
        r, l, d, u = ds
        # M = w w^T (symmetric) and the z row of N = w' w^T; columns (1,0,r) (-1,0,l) (0,1,d) (0,-1,u), tip n
        mxx = 2 + ns[0] * ns[0]
        myy = 2 + ns[1] * ns[1]
        mxy = ns[0] * ns[1]
        mxz = r - l + ns[0] * ns[2]
        myz = d - u + ns[1] * ns[2]
        mzz = r * r + l * l + d * d + u * u + ns[2] * ns[2]
        xr, xl, xd, xu = dx_
        nzx = xr - xl + nx[2] * ns[0]
        nzy = xd - xu + nx[2] * ns[1]
        nzz = xr * r + xl * l + xd * d + xu * u + nx[2] * ns[2]
        # q = M^-1 N_z (z row of Q = N M^-1, M symmetric), by cofactors
        c00 = myy * mzz - myz * myz
        c01 = mxz * myz - mxy * mzz
        c02 = mxy * myz - myy * mxz
        c11 = mxx * mzz - mxz * mxz
        c12 = mxy * mxz - mxx * myz
        c22 = mxx * myy - mxy * mxy
        det = mxx * c00 + mxy * c01 + mxz * c02
        qx = (c00 * nzx + c01 * nzy + c02 * nzz) / det
        qy = (c01 * nzx + c11 * nzy + c12 * nzz) / det
        qz = (c02 * nzx + c12 * nzy + c22 * nzz) / det
        # outside the face the target keeps its own tents (Q = I)
        qx *= mask
        qy *= mask
        qz = mask * qz + (1 - mask)
        tr, tl, td, tu = dt
        g_r, g_l = qx + qz * tr, -qx + qz * tl                  # new z differences, eq. 1: w' = Q w
        g_d, g_u = qy + qz * td, -qy + qz * tu
        # one value per grid edge: the two tents that share it, averaged
        eh = 0.5 * (g_r[:, :-1] - g_l[:, 1:])                   # l[:, j+1] - l[:, j]
        ev = 0.5 * (g_d[:-1, :] - g_u[1:, :])                   # l[i+1, :] - l[i, :]
        div = np.zeros_like(t)
        div[:, 1:] += eh
        div[:, :-1] -= eh
        div[1:, :] += ev
        div[:-1, :] -= ev
        # known neighbours (outside the face) are on the right-hand side
        sol = t.copy()
        if np.isscalar(strength):
            sol[self.inside] = self._solver.solve(div[self.inside] + known)
            return sol / k
        # regions at strength 0 are held as the target's own, like the outside (their own
        # factor, once per such pattern): the solve's change then cannot reach into them
        free = self.inside & (strength > 0)
        solver = self._held_solver(free)
        held = np.where(free, 0, t)
        rhs = np.zeros_like(t)
        rhs[:, 1:] += held[:, :-1]
        rhs[:, :-1] += held[:, 1:]
        rhs[1:, :] += held[:-1, :]
        rhs[:-1, :] += held[1:, :]
        sol[free] = solver.solve(div[free] + rhs[free])
        return sol / k

    def _held_solver(self, free: np.ndarray):
        key = free.tobytes()
        cache = self.__dict__.setdefault("_held_solvers", {})
        if key not in cache:
            from ..solver import SPDSolver
            if len(cache) > 8:
                cache.clear()
            cache[key] = SPDSolver(_face_laplacian(free))
        return cache[key]

    def eri_ratio(self, s_l, x_l, mask, small=None, large=None, strength=1.0) -> np.ndarray:
        """Liu, Shan & Zhang 2001: R = A'/A on the aligned sources, filtered by an adaptive
        Gaussian (a small kernel where the ratio carries expression detail, a large one
        elsewhere, to hide misregistration); 1 outside the face; R ** strength."""
        from scipy.ndimage import gaussian_filter
        size = np.ptp(self.points, 0).max()
        small = small or max(0.5, 0.004 * size)
        large = large or max(1.5, 0.02 * size)
        r = (x_l + 0.02) / (s_l + 0.02)
        r_s, r_l = gaussian_filter(r, small), gaussian_filter(r, large)
        detail = gaussian_filter(np.abs(r_s - r_l), large)
        wgt = np.clip(detail / 0.03, 0, 1)
        return self._apply_ratio(wgt * r_s + (1 - wgt) * r_l, mask, strength)

    def _apply_ratio(self, ratio, mask, strength) -> np.ndarray:
        """A ratio image to the power of the strength (a number or per region), 1 outside the
        mask: what ERI and the shading step multiply the target by."""
        strength = self._strength_map(strength)
        if not (np.isscalar(strength) and strength == 1):
            ratio = ratio ** np.asarray(strength, np.float32)
        return (mask * ratio + (1 - mask)).astype(np.float32)

    def setup(self, method: str = "shading") -> "ImageAnalogy":
        """Build now what `method` needs of the target once (for "shading": the generic face and
        the target's light) rather than inside the first transfer."""
        if method == "shading":
            self._shading
        return self

    @cached_property
    def _shading(self):
        from .shading import TargetShading
        return TargetShading(self.crop_yuv[..., 0], self.ctrl_t[:68], self.mask_t > 0.5)

    def shading_ratio(self, s_pts, x_pts, strength=1.0) -> np.ndarray:
        """The expression's shading change under the target's light (image.shading), per pixel of
        the crop: 1 outside the face, to the power `strength` (a number or per region)."""
        from .shading import face_model
        weights = face_model().fit_expression(s_pts, x_pts)
        return self._apply_ratio(self._shading.ratio(weights, self._own_expression), self.mask_t, strength)

    @cached_property
    def _own_expression(self):
        """The target photo's own expression from its resting face (shape weights), or None."""
        from .shading import face_model
        return None if self.rest is None else face_model().fit_expression(self.rest, self.points)

    def transfer(self, source, s_pts, expressive, x_pts, method="shading", strength=1.0, head="still") -> Result:
        """The target with the expression of (source -> expressive).  Images in [0, 1]: RGB, or
        for the sources their luminance (only Y is read from them; a video's fixed source neutral
        can be converted once).  `strength` scales the expression: 0 gives the target back,
        1 the source's expression, up to 2 exaggerates it (the feature motion times strength;
        per pixel the transformation interpolated from the identity, (1 - a) I + a Q, or for
        the shading and ERI the ratio to the power a).  `method`: one of METHODS."""
        if method not in METHODS:
            raise MimicaError(f"unknown method {method!r}; use {', '.join(METHODS)}")
        if head not in ("still", "follow"):
            raise MimicaError(f"head {head!r}: still (the target's head stays) or follow (it moves as the source's)")
        if self.rest is not None:
            check_rest_method(method)
        per = point_strengths(strength)                       # a number, or {region: a}
        strength = float(per[0]) if np.all(per == per[0]) else per
        s_r, x_r, look, pts = self.prepare(source, s_pts, expressive, x_pts, strength,
                                           resample=method in ("vtc", "eri"))
        yuv = self.crop_yuv
        if method == "shading":
            yuv = yuv * self.shading_ratio(s_pts, x_pts, strength)[..., None]
        elif method == "vtc":
            yuv = yuv.copy()
            yuv[..., 0] = self.vtc_luminance(s_r, x_r, strength)
        elif method == "eri":
            yuv = yuv * self.eri_ratio(s_r, x_r, self.mask_t, strength=strength)[..., None]   # Y, U, V all scale with RGB
        x0, y0, x1, y1 = self.box
        out = self.target.copy()
        out[y0:y1, x0:x1] = np.clip(yuv_to_rgb(look(yuv).reshape(self.h, self.w, 3)), 0, 1)
        mouth_a = float(strength) if np.ndim(strength) == 0 else float(np.max(strength[REGIONS["mouth"]]))
        if self.mouth and mouth_a > 0 and self._mouth_closed and mouth_open(pts) and mouth_open(x_pts):
            gain = self._target_lightness / max(_lightness(source, s_pts), 1e-3)
            fill_mouth(out, pts, expressive, x_pts, gain)
        if np.ndim(strength):
            _hold_closed_regions(out, self.target, self.points, strength)
        if head == "follow":
            # the source's head motion (S -> S', on its stable points), carried into the target's
            # frame: M = a b^-1 a^-1, the whole picture resampled by it
            a = Similarity2D.fit(np.asarray(s_pts, float), self.points)
            m = _compose(_compose(a, head_motion(x_pts, s_pts).inverse()), a.inverse())
            h, w = out.shape[:2]
            yy, xx = np.mgrid[0:h, 0:w]
            q = m.inverse()(np.stack([xx.ravel(), yy.ravel()], 1))
            out = sample(out, q[:, 0].reshape(h, w), q[:, 1].reshape(h, w)).astype(np.float32)
            pts = m(pts)
        return Result(out, pts, self, look)

    @cached_property
    def _mouth_closed(self) -> bool:
        """The target shows no mouth interior of its own (else its own teeth are warped open)."""
        return not mouth_open(self.points)

    @cached_property
    def _target_lightness(self) -> float:
        return _lightness(self.target, self.points)


# the appearance steps: the expression's shading under the target's light (image.shading, the
# default), Song's eq. 4 (vtc, the paper's), expression ratio images (eri), none (warp)
METHODS = ("shading", "vtc", "eri", "warp")

# the face's regions by their feature points, for per-region strengths; a side's or a lip's own
# (the subject's left and right, as ARKit names them) after the regions they are part of, so that
# "eyes=0.5,eye_left=0" holds the left eye (the lips' corners stay the mouth's)
REGIONS = {"brows": np.arange(17, 27), "eyes": np.arange(36, 48), "nose": np.arange(27, 36),
           "mouth": np.arange(48, 68), "jaw": np.arange(0, 17),
           "brow_right": np.arange(17, 22), "brow_left": np.arange(22, 27),
           "eye_right": np.arange(36, 42), "eye_left": np.arange(42, 48),
           "lip_upper": np.r_[49:54, 61:64], "lip_lower": np.r_[55:60, 65:68]}


# the regions that are closed outlines of feature points: one held at 0 keeps the target's own
# pixels inside its outline exactly (the warp's triangulation runs across an eye's thin outline
# to the points around it, which would otherwise carry their motion into it)
OUTLINES = {"eye_right": np.arange(36, 42), "eye_left": np.arange(42, 48), "mouth": np.arange(48, 60),
            "lip_upper": np.r_[48:55, 64, 63, 62, 61, 60], "lip_lower": np.r_[48, 60, 67, 66, 65, 64, 54:60]}


def check_rest_method(method: str) -> None:
    """Refuse, in one line, an appearance step that cannot start from the target's resting face.

    Parameters
    ----------
    method : str
        One of METHODS; "vtc" and "eri" carry the source's own appearance change, which would add
        to the one the target photo already wears.
    """
    if method in ("vtc", "eri"):
        raise MimicaError(f"method {method}: from the target's resting face only shading or warp (vtc and eri "
                          "carry the source's own appearance change, which would add to the target photo's own)")


def _hold_closed_regions(out, target, points, strength) -> None:
    """Inside the outline of each closed region whose feature points are all at strength 0,
    the target's own pixels (out changed in place; those points did not move)."""
    for idx in OUTLINES.values():
        if np.all(np.asarray(strength)[idx] == 0):
            inside, (x0, y0, x1, y1) = polygon_mask(points[idx], out.shape[:2])
            out[y0:y1, x0:x1][inside] = target[y0:y1, x0:x1][inside]


def point_strengths(strength) -> np.ndarray:
    """The strength of the expression at each feature point.

    Parameters
    ----------
    strength : float or dict
        A number (every region alike), or {region: a} (REGIONS; regions not named: 1; "all" sets
        the default), each from 0 to 2.

    Returns
    -------
    (68,) float array
    """
    if not isinstance(strength, dict):
        return np.full(68, check_strength(strength))
    bad = sorted(set(strength) - set(REGIONS) - {"all"})
    if bad:
        raise MimicaError(f"strength: unknown region {bad[0]!r} (regions: {', '.join(REGIONS)}, or all)")
    out = np.full(68, check_strength(strength.get("all", 1.0)))
    for name, idx in REGIONS.items():
        if name in strength:
            out[idx] = check_strength(strength[name])
    return out


def _compose(f: Similarity2D, g: Similarity2D) -> Similarity2D:
    """f after g: x -> f(g(x))."""
    return Similarity2D(f.s * g.s, f.r @ g.r, f.s * f.r @ g.t + f.t)


def check_strength(strength) -> float:
    """An expression strength from 0 to 2, else a clear error (NaN included).

    Parameters
    ----------
    strength : float

    Returns
    -------
    float
    """
    a = float(strength)
    if not 0 <= a <= 2:
        raise MimicaError(f"strength {a:g}: expected a number from 0 (no expression) to 2")
    return a


MOUTH = np.arange(60, 68)                  # the inner lip outline


def mouth_open(pts) -> bool:
    """Whether a face's mouth is open: its inner lip outline encloses more than 1 % of the squared
    eye distance.

    Parameters
    ----------
    pts : (68, 2) float array

    Returns
    -------
    bool
    """
    pts = np.asarray(pts, float)
    x, y = pts[MOUTH, 0], pts[MOUTH, 1]
    area = 0.5 * abs(float(x @ np.roll(y, 1) - y @ np.roll(x, 1)))
    eye = np.linalg.norm(pts[36:42].mean(0) - pts[42:48].mean(0))
    return area > 0.01 * eye * eye


def _lightness(img, pts) -> float:
    """Mean luminance of the nose (points 27, 31, 33, 35): skin, no hair, lit like the face."""
    m, (x0, y0, x1, y1) = polygon_mask(np.asarray(pts, float)[[27, 35, 33, 31]], np.shape(img)[:2])
    return float(luminance(np.asarray(img)[y0:y1, x0:x1])[m].mean()) if m.any() else 1.0


def fill_mouth(out, pts, expressive, x_pts, gain: float = 1.0) -> None:
    """Song et al. §VII's remedy for an opening mouth, "a 2D teeth template": inside the result's
    inner lip outline, the expressive source's own mouth interior (teeth, tongue, the dark of the
    mouth), mapped by the affine fit between the two inner lip outlines and scaled by `gain`;
    feathered over 1.5 pixels.  For open outlines (mouth_open); ImageAnalogy calls it only for a
    target whose own mouth is closed.

    Parameters
    ----------
    out : (H, W, 3) float array
        The result, changed in place.
    pts : (68, 2) float array
        The result's points.
    expressive : (H', W', 3) float array
        The expressive source photo.
    x_pts : (68, 2) float array
        Its points.
    gain : float
        The target's lightness over the source's.
    """
    from scipy.ndimage import distance_transform_edt
    poly, src = np.asarray(pts, float)[MOUTH], np.asarray(x_pts, float)[MOUTH]
    inside, (x0, y0, x1, y1) = polygon_mask(poly, out.shape[:2], pad=2)
    if not inside.any():
        return
    alpha = np.clip(distance_transform_edt(inside) / 1.5, 0, 1)[..., None].astype(np.float32)
    a = np.c_[np.r_[poly, poly.mean(0, keepdims=True)], np.ones(len(poly) + 1)]
    m, *_ = np.linalg.lstsq(a, np.r_[src, src.mean(0, keepdims=True)], rcond=None)   # [x y 1] @ m
    yy, xx = np.mgrid[y0:y1, x0:x1].astype(np.float32)
    q = np.stack([xx.ravel(), yy.ravel(), np.ones(xx.size, np.float32)], 1) @ m
    ex = np.asarray(expressive, np.float32)
    if ex.ndim == 2:
        ex = np.repeat(ex[..., None], 3, 2)
    inner = np.clip(sample(ex, q[:, 0], q[:, 1]).reshape(y1 - y0, x1 - x0, 3) * np.float32(gain), 0, 1)
    out[y0:y1, x0:x1] = alpha * inner + (1 - alpha) * out[y0:y1, x0:x1]


def _diffs(a):
    """Differences to the right, left, down and up neighbours (zero across the border)."""
    r = np.zeros_like(a)
    r[:, :-1] = a[:, 1:] - a[:, :-1]
    l = np.zeros_like(a)
    l[:, 1:] = a[:, :-1] - a[:, 1:]
    d = np.zeros_like(a)
    d[:-1] = a[1:] - a[:-1]
    u = np.zeros_like(a)
    u[1:] = a[:-1] - a[1:]
    return r, l, d, u


def _tip(a):
    """Unit normal of the height field at each pixel (the tent's tip, Song §IV), central differences."""
    r, l, d, u = _diffs(a)
    gx, gy = 0.5 * (r - l), 0.5 * (d - u)
    inv = 1 / np.sqrt(gx * gx + gy * gy + 1)
    return -gx * inv, -gy * inv, inv
