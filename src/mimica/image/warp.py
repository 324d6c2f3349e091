"""Piecewise-affine image warps from feature points (Song et al. §VI.B-C; Beier & Neely's
triangulated cousin): the 68 points plus forehead points and a still border are triangulated
once on the target; every map is affine per triangle."""

from __future__ import annotations

import numpy as np

# rigid-ish points for aligning an expressive photo to its neutral: nose bridge, eye corners,
# the jaw outline by the ears (measured: dropping these four makes self-transfer worse)
STABLE = np.array([0, 1, 15, 16, 27, 28, 29, 30, 36, 39, 42, 45])
BROWS = np.arange(17, 27)
JAW = np.arange(0, 17)


class Similarity2D:
    """x -> s R x + t in the image plane (Umeyama 1991 in 2D); `fit` makes one from point pairs.

    Parameters
    ----------
    s : float
        The scale.
    r : (2, 2) float array
        The rotation.
    t : (2,) float array
        The translation.
    """

    def __init__(self, s, r, t):
        self.s, self.r, self.t = float(s), np.asarray(r, float), np.asarray(t, float)

    def __call__(self, x):
        return self.s * np.asarray(x, float) @ self.r.T + self.t

    def linear(self, d):
        return self.s * np.asarray(d, float) @ self.r.T

    def inverse(self) -> "Similarity2D":
        return Similarity2D(1 / self.s, self.r.T, -(self.r.T @ self.t) / self.s)

    @classmethod
    def fit(cls, src, dst) -> "Similarity2D":
        a, b = np.asarray(src, float), np.asarray(dst, float)
        ca, cb = a.mean(0), b.mean(0)
        a0, b0 = a - ca, b - cb
        u, sv, vt = np.linalg.svd(b0.T @ a0)
        d = np.diag([1.0, np.sign(np.linalg.det(u @ vt)) or 1.0])
        r = u @ d @ vt
        s = float((sv * np.diag(d)).sum() / max((a0 ** 2).sum(), 1e-12))
        return cls(s, r, cb - s * r @ ca)


def orthographic_pose(points3d, points2d):
    """The scaled orthographic pose with points2d ~ s R[:2] points3d + t: the affine camera by least
    squares, its rows made orthonormal (Procrustes), R's third row their cross product.  2D axes as
    given (flip y first for image rows that grow downward).

    Parameters
    ----------
    points3d : (m, 3) float array
    points2d : (m, 2) float array

    Returns
    -------
    s : float
    R : (3, 3) float array
    t : (2,) float array
    """
    X, x = np.asarray(points3d, float), np.asarray(points2d, float)
    mx, mi = X.mean(0), x.mean(0)
    M = np.linalg.lstsq(X - mx, x - mi, rcond=None)[0].T        # (2, 3)
    u, sv, vt = np.linalg.svd(M, full_matrices=False)
    r2 = u @ vt
    R = np.vstack([r2, np.cross(r2[0], r2[1])])
    s = float(sv.mean())
    return s, R, mi - s * r2 @ mx


def head_motion(pts, ref_pts) -> Similarity2D:
    """How the analogy removes the head's motion between a neutral and an expressive photo: the
    similarity on the stable points (eye corners, nose) taking one photo's points into the other's
    frame.

    Parameters
    ----------
    pts, ref_pts : (68, 2) float arrays
        The two photos' landmarks.

    Returns
    -------
    Similarity2D
        pts -> ref_pts's frame.
    """
    return Similarity2D.fit(np.asarray(pts, float)[STABLE], np.asarray(ref_pts, float)[STABLE])


def align_to(img, pts, ref_pts) -> np.ndarray:
    """An image resampled into another photo's frame by head_motion (for truths).

    Parameters
    ----------
    img : (h, w) or (h, w, c) array
    pts : (68, 2) float array
        Its landmarks.
    ref_pts : (68, 2) float array
        The other photo's.

    Returns
    -------
    array
        float32, img's shape.
    """
    b = head_motion(pts, ref_pts).inverse()
    h, w = img.shape[:2]
    yy, xx = np.mgrid[0:h, 0:w]
    q = b(np.stack([xx.ravel(), yy.ravel()], 1))
    return sample(img, q[:, 0].reshape(h, w), q[:, 1].reshape(h, w))


def polygon_mask(poly, shape, pad: int = 0) -> tuple[np.ndarray, tuple]:
    """The pixels inside a polygon over its bounding box grown by `pad` and clipped to an image.

    Parameters
    ----------
    poly : (k, 2) float array
        (x, y) points.
    shape : tuple
        The image's (h, w[, c]).
    pad : int
        Pixels added around the box.

    Returns
    -------
    mask : (y1 - y0, x1 - x0) bool array
    box : tuple of int
        (x0, y0, x1, y1).
    """
    from PIL import Image, ImageDraw
    poly = np.asarray(poly, float)
    h, w = shape[:2]
    x0, y0 = np.clip(np.floor(poly.min(0)).astype(int) - pad, 0, [w, h])
    x1, y1 = np.clip(np.ceil(poly.max(0)).astype(int) + 1 + pad, 0, [w, h])
    im = Image.new("L", (max(int(x1 - x0), 0), max(int(y1 - y0), 0)), 0)
    ImageDraw.Draw(im).polygon([(float(x - x0), float(y - y0)) for x, y in poly], fill=1)
    return np.asarray(im) > 0, (int(x0), int(y0), int(x1), int(y1))


def forehead_points(lm) -> np.ndarray:
    """Two rows of points above the brows (the 68-point markup stops at the brows): brow points 17,
    19, 21, 22, 24, 26 moved up along the face's vertical by 0.4 and 0.8 of the brow-to-nose-base
    height.

    Parameters
    ----------
    lm : (68, 2) float array

    Returns
    -------
    (12, 2) float array
    """
    lm = np.asarray(lm, float)
    eye_r, eye_l = lm[36:42].mean(0), lm[42:48].mean(0)
    across = eye_l - eye_r
    up = np.array([across[1], -across[0]]) / max(np.linalg.norm(across), 1e-9)
    if up @ (lm[BROWS].mean(0) - lm[33]) < 0:
        up = -up
    h = np.linalg.norm(lm[BROWS].mean(0) - lm[33])
    base = lm[[17, 19, 21, 22, 24, 26]]
    return np.concatenate([base + 0.4 * h * up, base + 0.8 * h * up])


# each forehead point's brow point (its motion is shared at half strength)
FOREHEAD_BROW = np.array([17, 19, 21, 22, 24, 26] * 2)
FOREHEAD_FOLLOW = np.array([0.6] * 6 + [0.3] * 6)


def border_points(w, h, per_side=4) -> np.ndarray:
    """Still points on a rectangle just outside an image's pixel grid (corners included).

    Parameters
    ----------
    w, h : int
        The image's size.
    per_side : int
        Intervals along each side.

    Returns
    -------
    (4 per_side, 2) float array
    """
    xs = np.linspace(-1.0, w, per_side + 1)
    ys = np.linspace(-1.0, h, per_side + 1)
    top = np.stack([xs, np.full_like(xs, -1.0)], 1)
    bot = np.stack([xs, np.full_like(xs, float(h))], 1)
    left = np.stack([np.full(per_side - 1, -1.0), ys[1:-1]], 1)
    right = np.stack([np.full(per_side - 1, float(w)), ys[1:-1]], 1)
    return np.concatenate([top, bot, left, right])


def triangulate(points) -> np.ndarray:
    """The Delaunay triangulation of 2D points (scipy.spatial.Delaunay).

    Parameters
    ----------
    points : (m, 2) float array

    Returns
    -------
    (k, 3) int32 array
    """
    from scipy.spatial import Delaunay
    return Delaunay(np.asarray(points, float)).simplices.astype(np.int32)


class PiecewiseAffine:
    """Pixels of a w x h grid located in a triangulation of moved control points (one triangle id per
    pixel, rasterized by Pillow); any corresponding point set then gives a dense map (pixel ->
    point in another image) through one affine map per triangle.

    Parameters
    ----------
    points : (m, 2) float array
        The control points where they are in this grid.
    tris : (k, 3) int array
        Their triangles.
    w, h : int
        The grid's size.
    """

    def __init__(self, points, tris, w, h):
        from PIL import Image, ImageDraw
        p = np.asarray(points, float)
        self.points, self.tris, self.w, self.h = p, tris, w, h
        im = Image.new("I", (w, h), 0)
        draw = ImageDraw.Draw(im)
        for k, t in enumerate(tris.tolist()):
            draw.polygon([(p[i, 0] + 0.5, p[i, 1] + 0.5) for i in t], fill=k + 1)   # PIL pixel x covers [x, x+1)
        tid = np.asarray(im, np.int32).ravel() - 1
        self.covered = tid >= 0
        self.tri_id = np.where(self.covered, tid, 0)
        a = p[tris]                                                          # (T, 3, 2)
        m = np.concatenate([a, np.ones((len(tris), 3, 1))], 2)               # rows [x y 1]
        cond = np.abs(np.linalg.det(m)) < 1e-9
        m[cond] = np.eye(3)                                                  # degenerate: never mind
        self._minv = np.linalg.inv(m)                                        # (T, 3, 3)
        self.xx = np.tile(np.arange(w, dtype=np.float32), h)
        self.yy = np.repeat(np.arange(h, dtype=np.float32), w)

    def map(self, points) -> tuple:
        """Where each pixel lands in the image whose control points are `points`: flat (x, y)."""
        q = np.asarray(points, float)[self.tris]                             # (T, 3, 2)
        coef = (self._minv @ q).astype(np.float32)                           # (T, 3, 2): [x y 1] @ coef
        c = np.ascontiguousarray(coef.reshape(len(coef), 6).T)               # (6, T)
        tid = self.tri_id
        x = c[0].take(tid) * self.xx + c[2].take(tid) * self.yy + c[4].take(tid)
        y = c[1].take(tid) * self.xx + c[3].take(tid) * self.yy + c[5].take(tid)
        return x, y


class Bilinear:
    """Bilinear lookup at fixed float pixel positions: the indices and weights are computed once,
    then each channel costs four gathers.

    Parameters
    ----------
    x, y : (m,) float arrays
        Pixel coordinates, clamped to the image.
    h, w : int
        The images' size.
    """

    def __init__(self, x, y, h, w):
        x = np.clip(np.asarray(x, np.float32), 0, np.float32(w - 1.001))
        y = np.clip(np.asarray(y, np.float32), 0, np.float32(h - 1.001))
        xf, yf = np.floor(x), np.floor(y)
        self.fx, self.fy = x - xf, y - yf
        self.i = yf.astype(np.int32) * np.int32(w) + xf.astype(np.int32)
        self.w, self.shape = w, (h, w)

    def __call__(self, img) -> np.ndarray:
        """Samples of a (h, w) image, or of each channel of (h, w, c) -> (m, c)."""
        img = np.asarray(img)
        if img.ndim == 3:
            return np.stack([self(img[..., c]) for c in range(img.shape[2])], -1)
        flat = np.ascontiguousarray(img).reshape(-1)
        i, w = self.i, self.w
        i00 = flat.take(i)
        top = i00 + (flat.take(i + 1) - i00) * self.fx
        i10 = flat.take(i + w)
        bot = i10 + (flat.take(i + (w + 1)) - i10) * self.fx
        return top + (bot - top) * self.fy


def sample(img, x, y) -> np.ndarray:
    """Bilinear samples of an image at float pixel coordinates, clamped at the edges.

    Parameters
    ----------
    img : (h, w) or (h, w, c) array
    x, y : float arrays
        Pixel coordinates, any shape (the same).

    Returns
    -------
    float32 array
        x.shape, or x.shape + (c,).
    """
    shape = np.shape(x)
    out = Bilinear(np.ravel(x), np.ravel(y), *np.shape(img)[:2])(img)
    return out.reshape(shape + out.shape[1:])
