"""The photo transfer's appearance step: the expression's shading, on a 3D face, under the target
photo's own light.

Song et al. §VI carry the source's luminance change onto the target (eq. 2 per pixel, eq. 4 for
the luminances).  That change is made of the expression's shading under the *source's* light:
moved onto a target lit from elsewhere it darkens what should brighten.  Measured on rendered
ICT faces (source lit from the left, target from the right, the truth rendered): eq. 4 after the
warp 24.84 dB, the warp alone 25.30 dB, ERI 23.79 dB; the true shading change of the target's
own geometry under its own light, multiplied into the warped photo, 26.57 dB -- the room that
an appearance step has, and it is the light's.

So this step asks the source only for *what* moved, and makes the shading change where the
target's light is:
1. a generic face with ICT-FaceKit's expression shapes (the face area, gaze and pupils left out)
   is posed on each photo's 68 points by a scaled orthographic camera;
2. the source's expression = non-negative shape weights (0..1) whose landmark motion matches the
   source's feature motion, head motion removed (a bounded ridge least squares);
3. the target's light = a second-order spherical-harmonics fit (Ramamoorthi & Hanrahan 2001) of
   its luminance over the posed face's normals (reweighted against eyebrows, nostrils, hair);
4. each target pixel's shading ratio, light(n') / light(n) for its material point's normal after
   and before the expression, clipped to [1/1.5, 1.5] and smoothed (Gaussian on log, sigma 3 % of
   the face), multiplies the target's colour before the warp (as ERI's ratio does).

The clip and smoothing keep the generic face's misfit on real faces (lips, nostrils, the chin of an
open jaw) from showing: on the Yale pairs, happy and surprised, unclipped and unsmoothed 20.51 /
18.42 dB, clipped 20.78 / 19.11, smoothed 21.0 / 19.6-19.7 against the warp's 20.00 / 19.62; on the
rendered ICT pairs this step gives 26.27 dB against the true shading's 26.57 (bench/transfer_image.py,
docs/benchmarks.md).
Song's eq. 4 stays as method "vtc", the reference.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from ..errors import MimicaError
from .raster import facing, rasterize_pixels
from .warp import head_motion, orthographic_pose

RATIO_CLIP = 1.5          # the shading ratio is kept within [1 / RATIO_CLIP, RATIO_CLIP]
RATIO_BLUR = 0.03         # Gaussian sigma of log ratio, as a fraction of the face's size (points' extent)
EXPRESSION_PULL = 1e-3    # ridge weight on the shape weights (in squared face-model units)
LIGHT_ITERATIONS = 5      # reweighted least squares steps of the light fit
_Y_FLIP = np.array([1.0, -1.0])
_FLOOR = np.float32(0.02)          # shading below this (a face turned from the light) counts as this


class FaceModel:
    """A generic face (ICT-FaceKit's neutral face area) and its expression shapes: what a photo's 68
    points say of a face's 3D pose and expression.

    Attributes
    ----------
    names : list of str
        The expression shapes (ICT's but the gaze and the pupils).
    vertices : (n, 3) float array
        The neutral.
    triangles : (m, 3) int array
    deltas : (K, n, 3) float array
        Each shape's displacement.
    landmarks : (68,) int array
        The landmark vertices.
    """

    def __init__(self):
        from ..data import ICT_FACE_AREA_VERTICES, ICT_LANDMARKS_68, ICTModel, default_store, ict_expression_names
        model = ICTModel(ICT_FACE_AREA_VERTICES)
        self.names = [n for n in ict_expression_names() if not n.startswith(("eyeLook", "Pupil"))]
        shapes = default_store().shapes(self.names, ICT_FACE_AREA_VERTICES)
        self.vertices = model.neutral
        self.triangles = model.mesh.triangles
        self.deltas = np.stack([shapes[n] - model.neutral for n in self.names])      # (K, n, 3)
        self.landmarks = ICT_LANDMARKS_68
        self._lm_deltas = self.deltas[:, ICT_LANDMARKS_68]                              # (K, 68, 3)

    def pose(self, points: np.ndarray):
        """Scaled orthographic camera (s, R, t) putting the neutral's landmarks on the image points
        (x right, y down): p = s * flip(R X)[:2] + t, R a rotation (camera z toward the viewer)."""
        s, rot, t = orthographic_pose(self.vertices[self.landmarks], np.asarray(points, float) * _Y_FLIP)
        return s, rot, t * _Y_FLIP

    def project(self, vertices, s, rot, t):
        """Image positions (n, 2) and depth (n,), larger nearer."""
        c = vertices @ rot.T
        return s * c[:, :2] * _Y_FLIP + t, s * c[:, 2]

    def fit_expression(self, neutral_points, expr_points) -> np.ndarray:
        """(K,) shape weights in [0, 1] whose landmark motion, seen by the neutral's camera,
        matches the feature motion from neutral_points to expr_points (head motion removed)."""
        from scipy.optimize import lsq_linear
        sp, xp = np.asarray(neutral_points, float), np.asarray(expr_points, float)
        s, rot, _ = self.pose(sp)
        d = head_motion(xp, sp)(xp) - sp
        m = (s * (self._lm_deltas @ rot[:2].T) * _Y_FLIP).reshape(len(self.names), -1).T   # (136, K)
        k = m.shape[1]
        a = np.vstack([m, np.sqrt(EXPRESSION_PULL) * s * np.eye(k)])
        return lsq_linear(a, np.r_[d.ravel(), np.zeros(k)], bounds=(0.0, 1.0), method="bvls").x


@lru_cache(maxsize=1)
def face_model() -> FaceModel:
    """The one generic face model of a process (its shapes read once, through the store's cache).

    Returns
    -------
    FaceModel
    """
    return FaceModel()


def _sh9(n: np.ndarray) -> np.ndarray:
    """Real spherical harmonics to order 2 (unnormalized) of unit normals (m, 3) -> (m, 9)."""
    x, y, z = n[:, 0], n[:, 1], n[:, 2]
    return np.stack([np.ones_like(x), x, y, z, x * y, x * z, y * z, x * x - y * y, 3 * z * z - 1], 1)


class TargetShading:
    """The target photo's face as the generic face posed on its points, its light fitted to its
    luminance; `ratio(weights)` the shading change of an expression at each pixel.

    The light is fitted at every pixel (per-pixel normals, once); the ratio, smoothed over several
    pixels anyway, is made per vertex, interpolated on a grid `step` times coarser than the photo,
    smoothed there and resampled (a 430x480 face box of a 640x480 frame: 31 -> 10 ms).

    Parameters
    ----------
    luminance : (h, w) float array
        The target's.
    points : (68, 2) float array
        Its feature points.
    where : (h, w) bool array or None
        The pixels to fit the light on (None: the face).
    model : FaceModel or None
        None: face_model().
    """

    def __init__(self, luminance: np.ndarray, points: np.ndarray, where: np.ndarray | None = None,
                 model: FaceModel | None = None):
        from scipy.interpolate import RBFInterpolator
        from .warp import Bilinear
        y = np.asarray(luminance, np.float32)
        self.model = m = model or face_model()
        self.shape = h, w = y.shape
        p = np.asarray(points, float)
        s, rot, t = m.pose(p)
        xy, z = m.project(m.vertices, s, rot, t)
        # the generic face's 2D shape bent onto the photo's points (a thin-plate spline of the
        # landmarks' residuals), so that its features fall on the photo's
        lm = xy[m.landmarks]
        xy = xy + RBFInterpolator(lm, p - lm, kernel="thin_plate_spline", smoothing=1.0)(xy)
        tris = m.triangles[facing(xy, m.triangles)]
        self.rot = rot
        pix, tri, bary = _raster(xy, z, tris, w, h)
        n0 = _interpolate(self._vertex_normals(m.vertices), tris[tri], bary)
        b = _sh9(n0 / np.maximum(np.linalg.norm(n0, axis=1, keepdims=True), 1e-12))
        fit = np.ones(len(pix), bool) if where is None else np.asarray(where, bool).ravel()[pix]
        if fit.sum() < 50:
            raise MimicaError("target: too little of the face is visible to read its light")
        yy, bb = y.ravel()[pix][fit].astype(np.float64), b[fit].astype(np.float64)
        wt = np.ones(len(yy))
        for _ in range(LIGHT_ITERATIONS):                     # reweighted least squares (Cauchy)
            coef = np.linalg.lstsq(bb * wt[:, None], yy * wt, rcond=None)[0]
            r = yy - bb @ coef
            scale = 1.4826 * np.median(np.abs(r)) + 1e-6
            wt = 1.0 / np.sqrt(1.0 + (r / (2 * scale)) ** 2)
        self.light = coef.astype(np.float32)
        self.pix, self.shade0 = pix, b @ self.light          # the fit's pixels and its shading there
        self._rest = np.maximum(self._vertex_shade(m.vertices), _FLOOR)
        self._before = (None, None)      # (weights' bytes, shading) of the expression the photo wears (ratio's before)
        # the ratio's grid: `step` pixels a cell, the smoothing's sigma at least 2 cells
        sigma = RATIO_BLUR * float(np.ptp(p, 0).max())
        self.step = step = max(1, int(sigma // 2))
        self.sigma = sigma / step
        hc, wc = -(-h // step), -(-w // step)
        self.coarse = (hc, wc)
        self.cpix, ctri, self.cbary = _raster(xy / step, z, tris, wc, hc)
        self.ctri = tris[ctri]
        yy_, xx_ = np.mgrid[0:h, 0:w].astype(np.float32)
        self.up = Bilinear(((xx_ + 0.5) / step - 0.5).ravel(), ((yy_ + 0.5) / step - 0.5).ravel(), hc, wc)

    def _vertex_normals(self, vertices) -> np.ndarray:
        from ..mesh import vertex_normals
        return (vertex_normals(vertices, self.model.triangles) @ self.rot.T).astype(np.float32)

    def _vertex_shade(self, vertices) -> np.ndarray:
        return _sh9(self._vertex_normals(vertices)) @ self.light

    def ratio(self, weights: np.ndarray, before: np.ndarray | None = None) -> np.ndarray:
        """(h, w) float32: the shading after the expression `weights` over the shading before (at
        rest, or at the expression `before` that the photo already wears), 1 off the face."""
        from scipy.ndimage import gaussian_filter
        v = self.model.vertices + np.tensordot(np.asarray(weights, float), self.model.deltas, 1)
        rest = self._rest
        if before is not None:                           # the same for every expression: made once
            key = np.asarray(before, float).tobytes()
            if self._before[0] != key:
                v0 = self.model.vertices + np.tensordot(np.asarray(before, float), self.model.deltas, 1)
                self._before = (key, np.maximum(self._vertex_shade(v0), _FLOOR))
            rest = self._before[1]
        log_v = np.log(np.clip(np.maximum(self._vertex_shade(v), _FLOOR) / rest,
                               1 / RATIO_CLIP, RATIO_CLIP)).astype(np.float32)
        log_r = np.zeros(self.coarse[0] * self.coarse[1], np.float32)
        log_r[self.cpix] = _interpolate(log_v[:, None], self.ctri, self.cbary)[:, 0]
        smooth = gaussian_filter(log_r.reshape(self.coarse), self.sigma)
        return np.exp(self.up(smooth)).reshape(self.shape).astype(np.float32)


def _raster(xy, z, tris, w, h):
    """Covered pixels of a w x h grid: flat index, triangle (row of tris), barycentrics (m, 3)."""
    pix, tri, l0, l1 = rasterize_pixels(xy, z, tris, w, h)
    return pix, tri, np.stack([l0, l1, 1 - l0 - l1], 1).astype(np.float32)


def _interpolate(values, corners, bary):
    """Per-vertex values (n, c) at points given by their triangle's corners (m, 3) and barycentrics."""
    return (bary[:, 0:1] * values[corners[:, 0]] + bary[:, 1:2] * values[corners[:, 1]]
            + bary[:, 2:3] * values[corners[:, 2]])
