"""A take's ARKit weights refined on its frames' pixels: model-based tracking.

The 68 points a tracker gives move less than the face does (MediaPipe's about 0.5-0.6 of the
true motion on ICT's renders: its model's prior) and tell apart poorly the shapes that move them
alike; the pixels do not.  The head's face surface (face_surface: about SURFACE_POINTS of its
vertices inside the face's outline, facing the view, not hidden) takes its grey levels -- and its
red-green differences, where they change across it: the lips, the brows -- from the performer's
rest frame, placed there by the landmark fit's pose and the performer's rest
landmarks (the offsets between the head's landmarks and the performer's carried to the surface
by a thin-plate spline).  Each frame's pose and weights are then moved from the landmark fit's
so that the surface, shaped by the blendshapes, finds those grey levels again in the frame:
Gauss-Newton on the grey-level misfit (Lucas and Kanade's image alignment, the warp here a
deformable model's projection), from a blurred frame to a sharper one,
with the light's change from the rest frame modelled (a gain varying linearly across the face,
the shading's change as the surface turns and as the expression bends it -- Lambert's law to
first order in its normals' change, each shape's at weight 1 -- and an offset; white light
scales the red-green difference as it scales the grey level, so all but the offset are shared;
the light carried from frame to frame), the landmarks' misfit kept beside it and the weights
bounded (0 <= w <= 1), pulled toward the last frame's and, those the landmark fit left at 0, toward
rest -- no L1 pull as the landmark fit's: on the dev takes it took the gain away.  What it
does not model: a face the rest frame does not show (the teeth, the mouth's inside: its lips'
own grey levels are followed) and shadows.

The gaze: where the head has eyes of its own (eye_samples: the eyeballs' fronts between the
lids), the eyeLook weights are fitted with the others, each turning its eye rigidly about the
eyeball's centre (GAZE_FULL_DEG at 1) besides moving the lids as its shape does; an eye's
samples count where they lie between the frame's lids (the model's lid landmarks, so that a
closing lid hides them), face the camera and are on the eye's side of the nose.  Measured on
rendered takes (bench/video_arkit.py, bench/export.py): docs/benchmarks.md.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..mesh.core import cross_matrices
from ._solve import box_qp, gram, projection_jacobian
from .blendshapes import ARKIT_52

SURFACE_POINTS = 2000      # the face's surface vertices sampled
FACING = 0.3               # a vertex counts where its normal's cosine to the view exceeds this
INSET = 0.9                # the face's region scaled by this about its centre (at its edge the blur sees beyond it)
BROW_MARGIN = 0.1          # face widths above the brows' landmarks the face's region reaches
BLURS = (1 / 80, 1 / 160)  # the frame's Gaussian in face widths: coarse steps, then fine ones
STEPS = (1, 2)             # Gauss-Newton steps at each blur
TRUNCATE = 3.0             # the Gaussians cut at this many standard deviations (4, scipy's default: the same figures)
PIXEL_PULL = 1.0           # weight of the grey levels' mean squared misfit ...
LANDMARK_PULL = 1.0        # ... and of the landmarks' (face widths), weighted as the fit weights them
RIDGE = 1e-4               # weight of sum w^2 over the weights the landmark fit left at 0 (the gaze's too)
SMOOTH = 3e-4              # weight of the change from the last frame's weights
ROBUST = 0.05              # grey levels: a misfit past this counts less (Huber's weights)
LIGHTS = 8                 # the light's terms: a gain, its slopes across the face, the turned normals' three, two offsets
EYE_INSET = 0.9            # the lids' opening scaled by this about its centre: where an eye's samples count
EYE_POINTS = 150           # the eyeball's front vertices sampled, each eye
EYE_FACING = 0.6           # an eye's sample counts where its direction from the eye's centre has this cosine to the view
# an eyeLook weight of 1 turns the eye this far -- ARKit's eyeLook shapes are the lids' movement
# "consistent with" a gaze and state no angle, so this is a convention (export.video's reading of
# the irises and bench/video_arkit.py's takes share it)
GAZE_FULL_DEG = 30.0
# a uint8 frame's channels' mean in [0, 1], in single precision (a product: 0.06 ms a frame against
# ndarray.mean's 1.3; the blurs on it take half the time they take in double)
_GREY = np.full(3, 1 / 765, np.float32)
# the red-green difference in [-1, 1]: a real face's lips (and a painted take's brows and irises)
# differ from its skin more in hue than in grey level
_CHROMA = np.array([1 / 255, -1 / 255, 0.0], np.float32)
_CHANNELS = np.stack([_GREY, _CHROMA], 1)        # (3, 2): a frame's grey level and red-green difference, one product
# the share of the samples the red-green difference counts at: those where it changes most across
# them in the rest frame (on even skin it shows no motion; all of them: the same figures, 1.3 times
# the time -- dev takes 0.214 against 0.215 at a half, 0.217 at 0.3)
CHROMA_SHARE = 0.5
LIDS = (np.arange(36, 42), np.arange(42, 48))    # the subject's right eye's lid landmarks, the left's


@dataclass
class Surface:
    """The head's face surface sampled for the pixels' fit (face_surface).

    Attributes
    ----------
    rest : (m, 3) float array
        Its vertices at rest, metres in the GLB's frame.
    normals : (m, 3) float array
        Unit normals at rest.
    index : (m,) int array
        Which of the head's vertices they are.
    motion : (52, m, 3) float array or None
        Their motion in each ARKit shape (ARKIT_52's order) ...
    normal_motion : (52, m, 3) float array or None
        ... and their normals' (at weight 1): set_motion sets both.
    eyes : Eyes or None
        The eyeballs' fronts (eye_samples), where the head has eyes of its own.
    """
    rest: np.ndarray
    normals: np.ndarray
    index: np.ndarray
    motion: np.ndarray = None
    normal_motion: np.ndarray = None
    eyes: "Eyes" = None


@dataclass
class Eyes:
    """The eyeballs' fronts sampled for the gaze's fit on the pixels (eye_samples).

    Attributes
    ----------
    rest : (m, 3) float array
        Vertices of the eyeballs' fronts seen between the lids at rest, metres in the GLB's frame.
    side : (m,) int array
        0 for the subject's right eye, 1 for the left.
    centres : (2, 3) float array
        The eyeballs' centres of turning (a sphere fitted to each).
    axes : (3, 3) float array
        Rows: the face's right-to-left, up and forward axes (_face_frame).
    index : (m,) int array
        Which of the head's vertices they are.
    """
    rest: np.ndarray
    side: np.ndarray
    centres: np.ndarray
    axes: np.ndarray
    index: np.ndarray


def _face_frame(lm: np.ndarray) -> np.ndarray:
    """(3, 3) rows: the face's right-to-left, up and forward axes from its 68 landmarks (the
    forward one toward the nose's tip), whatever way the file faces."""
    x = lm[16] - lm[0]
    up = lm[19:25].mean(0) - lm[8]
    fwd = np.cross(x, up)
    if fwd @ (lm[30] - lm[:17].mean(0)) < 0:
        fwd = -fwd
    x = x / np.linalg.norm(x)
    fwd = fwd / np.linalg.norm(fwd)
    return np.stack([x, np.cross(fwd, x), fwd])


def face_surface(vertices: np.ndarray, triangles: np.ndarray, landmarks: np.ndarray, count: int | None = None) -> Surface:
    """The vertices of the head's face that a camera before it sees: on the part of the mesh its
    landmarks lie on (not the eyeballs, teeth or lashes), inside the face's outline and up to
    BROW_MARGIN above the brows, facing forward and in front of the rest of that part; about
    `count` of them, as dense as the mesh (where a head's mesh is densest, at the eyes and the
    lips, its motion shows most).

    Parameters
    ----------
    vertices : (n, 3) float array
        The head at rest.
    triangles : (T, 3) int array
    landmarks : (68, 3) float array
        Its landmarks at rest.
    count : int or None
        At most this many (None: SURFACE_POINTS).

    Returns
    -------
    Surface
        Without its motion.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import Delaunay, cKDTree
    from ..image.raster import rasterize_pixels
    from ..mesh.core import vertex_normals
    n = len(vertices)
    frame = _face_frame(landmarks)
    v = vertices @ frame.T                                        # x right-to-left, y up, z toward the view
    lm = landmarks @ frame.T
    width = float(np.linalg.norm(lm[16] - lm[0]))
    # the part the landmarks lie on: the connected component nearest to them
    e = np.r_[triangles[:, :2], triangles[:, 1:], triangles[:, ::2]]
    _, comp = connected_components(coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n)), directed=False)
    near = cKDTree(v).query(lm[17:])[1]
    skin = comp == np.bincount(comp[near]).argmax()
    region = np.r_[lm[:17, :2], lm[17:27, :2] + [0.0, BROW_MARGIN * width]]
    centre = region.mean(0)
    inside = Delaunay(centre + INSET * (region - centre)).find_simplex(v[:, :2]) >= 0
    nrm = vertex_normals(vertices, triangles) @ frame.T
    # in front of the rest of that part (the mouth's and the eyes' sockets behind the lips and the
    # lids; not of the lashes, which move with the lids): a z-buffer of the front view, 400 pixels
    # across the face
    px = 400.0 / width
    xy = (v[:, :2] - v[:, :2].min(0)) * px
    size = np.ceil(xy.max(0)).astype(int) + 2
    own = triangles[skin[triangles].all(1)]
    pix, tri, l0, l1 = rasterize_pixels(xy * [1, -1] + [0, size[1] - 1], v[:, 2], own, int(size[0]), int(size[1]))
    zbuf = np.full(int(size[0] * size[1]), -np.inf)
    tz = v[:, 2][own[tri]]
    zbuf[pix] = l0 * tz[:, 0] + l1 * tz[:, 1] + (1 - l0 - l1) * tz[:, 2]
    q = np.clip(np.round(xy * [1, -1] + [0, size[1] - 1]).astype(int), 0, size - 1)
    front = v[:, 2] >= zbuf[q[:, 1] * size[0] + q[:, 0]] - 0.01 * width
    count = SURFACE_POINTS if count is None else count
    idx = np.nonzero(skin & inside & (nrm[:, 2] > FACING) & front)[0]
    if len(idx) > count:      # a random `count` of them (fixed seed): as dense as the mesh is (at the eyes, the lips)
        idx = np.sort(np.random.default_rng(0).choice(idx, count, replace=False))
    return Surface(vertices[idx], nrm[idx] @ frame, idx)


def set_motion(surface: Surface, vertices: np.ndarray, triangles: np.ndarray, targets) -> None:
    """Set the surface's motion in each ARKit shape and its normals' change (surface.motion,
    surface.normal_motion; the normals' change at weight 1, the shading's first order in the
    weights: the secant read better than the tangent at 0 on the dev takes, 0.236 against 0.241
    where weights act).

    Parameters
    ----------
    surface : Surface
        face_surface's, of the head `vertices` (n, 3), `triangles` (T, 3).
    targets : iterable of (n, 3) float arrays
        The head's vertices in each shape at weight 1, ARKIT_52's order (the surface's units).
    """
    from ..mesh.core import vertex_normals
    i = surface.index
    near = triangles[np.isin(triangles, i).any(1)]          # every triangle a sample's normal is made of
    motion, normals = [], []
    for t in targets:
        motion.append(t[i] - vertices[i])
        normals.append(vertex_normals(t, near)[i] - surface.normals)
    surface.motion, surface.normal_motion = np.stack(motion), np.stack(normals)


def eye_samples(mesh, landmarks: np.ndarray, count: int = EYE_POINTS) -> Eyes | None:
    """The eyeballs' fronts a camera before the head sees between its lids: each eye's vertices
    (correspond.parts.split_parts: the rigid eyes) inside its six lid landmarks' polygon scaled by
    EYE_INSET and on the eyeball's front half; about `count` an eye; the eye's centre of turning
    a sphere fitted to its vertices.  None where the head has no eyes of its own (eyes one surface
    with the lids, or none).

    Parameters
    ----------
    mesh : Mesh
        The head at rest.
    landmarks : (68, 3) float array
    count : int

    Returns
    -------
    Eyes or None
    """
    from ..correspond.eyes import inside_polygon
    from ..correspond.parts import EYE_LEFT, EYE_RIGHT, ROLES, fit_sphere, split_parts
    role = split_parts(mesh, landmarks).role
    frame = _face_frame(landmarks)
    v = mesh.vertices @ frame.T
    lm = landmarks @ frame.T
    index, side, centres = [], [], []
    rng = np.random.default_rng(0)
    for k, name in enumerate((EYE_RIGHT, EYE_LEFT)):
        own = np.nonzero(role == ROLES.index(name))[0]
        if len(own) < 20:
            return None
        centre = fit_sphere(mesh.vertices[own])[0]
        c = centre @ frame.T
        poly = lm[LIDS[k], :2]
        mid = poly.mean(0)
        pick = own[inside_polygon(v[own, :2], mid + EYE_INSET * (poly - mid)) & (v[own, 2] > c[2])]
        if len(pick) < 10:
            return None
        if len(pick) > count:
            pick = np.sort(rng.choice(pick, count, replace=False))
        index.append(pick)
        side.append(np.full(len(pick), k))
        centres.append(centre)
    index = np.concatenate(index)
    return Eyes(mesh.vertices[index], np.concatenate(side), np.array(centres), frame, index)


def refine_frames(video, img: np.ndarray, head_rest: np.ndarray, rest: np.ndarray, motion: np.ndarray,
                  surface: Surface, free: np.ndarray, width: float, weights: np.ndarray, s: np.ndarray,
                  R: np.ndarray, t: np.ndarray, use: np.ndarray, point_weights: np.ndarray, rest_frame: int = 0,
                  progress=None) -> np.ndarray:
    """Each frame's weights refined on its pixels (the module's docstring), from the landmark fit's
    pose and weights (export.video.fit_weights; lengths in face widths, image y up); where the
    surface has the eyes (Surface.eyes), the gaze's weights (eyeLook*) too, from 0: each turns its
    eye GAZE_FULL_DEG at 1 and moves the lids as the head's shape does.

    Parameters
    ----------
    video : str or Path
        The take the points were tracked on.
    img : (F, 68, 2) float array
        The points the landmark fit fitted (y up).
    head_rest, rest : (68, 3) float arrays
        The head's landmarks and the performer's (face widths).
    motion : (52, 68, 3) float array
        The landmarks' motion in every shape (ARKIT_52's order).
    surface : Surface
        face_surface's, its motion set (set_motion), in metres.
    free : (52,) bool array
        The shapes the landmark fit fitted.
    width : float
        The face's width, metres.
    weights : (F, k) float array
        The landmark fit's weights of the `free` shapes.
    s, R, t : (F,), (F, 3, 3), (F, 2) float arrays
        The landmark fit's poses.
    use : (F,) bool array
        The frames to refine (the others keep their weights).
    point_weights : (68,) float array
        How much each landmark counts (the landmark fit's POINT_WEIGHTS).
    rest_frame : int
    progress : callable, optional
        Called with a line of text every 300 frames.

    Returns
    -------
    (F, 52) float array
        The refined weights: the `free` shapes', and the gaze's where the surface has the eyes
        (else 0).
    """
    from itertools import chain, islice
    from scipy.interpolate import RBFInterpolator
    from ..image.video import frame_source
    from ..parallel import one_blas_thread
    # the performer's surface: the head's plus its landmarks' offsets carried by a thin-plate spline
    offset = RBFInterpolator(head_rest, rest - head_rest, kernel="thin_plate_spline", smoothing=1e-3)
    sv = surface.rest / width
    V = sv + offset(sv)
    gaze = np.array([n.startswith("eyeLook") for n in ARKIT_52]) & ~free
    eyes = None
    if surface.eyes is not None and gaze.any():
        e = surface.eyes
        ev, ec = e.rest / width, e.centres / width
        # how each gaze weight turns the eyes: (right out, right up, left out, left up) per unit
        turns = np.zeros((52, 4))
        for j in np.nonzero(gaze)[0]:
            n = ARKIT_52[j]
            k = 0 if n.endswith("Right") else 1
            turns[j, 2 * k + ("Up" in n or "Down" in n)] = -1.0 if ("In" in n or "Down" in n) else 1.0
        cols = free | gaze
        eyes = (ev + offset(ev), e.side, ec + offset(ec), e.axes, turns[cols])
    else:
        cols = free.copy()
    D = surface.motion[cols] / width
    rows = np.repeat(point_weights, 2)
    w0 = np.zeros((len(weights), int(cols.sum())))
    w0[:, free[cols]] = weights
    frames = islice(frame_source(video, raw=True)[2], len(w0))
    if rest_frame == 0:                                          # the take decoded once
        rest_img = next(frames)
        frames = chain([rest_img], frames)
    else:
        rest_img = next(islice(frame_source(video, raw=True)[2], rest_frame, None))
    fit = _Frame(V, D, surface.normals, surface.normal_motion[cols], rest, motion[cols], rows, R[rest_frame], eyes)
    refs = fit.references(rest_img, s[rest_frame], R[rest_frame], t[rest_frame], w0[rest_frame])
    out = w0.copy()
    last = w0[0]
    # one BLAS thread: the frames' products are small, and a second thread cost more than it gave
    # (paired end to end on a 600-frame take: 0.95 of the time, 0.6 of the processor time)
    with one_blas_thread():
        for f, frame in enumerate(frames):
            if progress and f and f % 300 == 0:
                progress(f"refined {f} of {len(w0)} frames on their pixels")
            if use[f]:
                start = w0[f].copy()
                start[~free[cols]] = last[~free[cols]]               # the gaze from the last frame's
                # the pull toward rest holds only the shapes the points did not find: those they found passed
                # the landmark fit's own L1 pull, and pulled again they read short
                ridge = RIDGE * ~(free[cols] & (start > 0))
                out[f] = fit.refine(frame, refs, img[f], s[f], R[f], t[f], start, last, ridge)
            else:
                out[f, ~free[cols]] = last[~free[cols]]
            last = out[f]
    full = np.zeros((len(w0), 52))
    full[:, cols] = out
    return full


def _bilinear(stack: np.ndarray, x: np.ndarray, corner: np.ndarray) -> np.ndarray:
    """The images of `stack` (c, h, w) at the points x (n, 2; column, row up from the corner), each
    bilinearly interpolated, the edge's value past it (map_coordinates' order 1, "nearest", for all
    the images at once: the corners' indices and weights found once)."""
    c, h, w = stack.shape
    row = np.clip(-x[:, 1] - corner[1], 0, h - 1)
    col = np.clip(x[:, 0] - corner[0], 0, w - 1)
    r0 = np.minimum(row.astype(np.intp), h - 2)
    c0 = np.minimum(col.astype(np.intp), w - 2)
    fr, fc = (row - r0)[None], (col - c0)[None]
    flat = stack.reshape(c, -1)
    i = r0 * w + c0
    top = flat[:, i] * (1 - fc) + flat[:, i + 1] * fc
    bottom = flat[:, i + w] * (1 - fc) + flat[:, i + w + 1] * fc
    return top * (1 - fr) + bottom * fr


def _turn(K: np.ndarray, angle: float) -> np.ndarray:
    """The rotation by `angle` about the unit axis whose cross product's matrix is K (Rodrigues':
    scipy's Rotation costs 23 us a call, five calls a Gauss-Newton step)."""
    return np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * (K @ K)


class _Frame:
    """A frame's Gauss-Newton on its grey levels and the landmarks (refine_frames): the surface V
    (m, 3), its motion D (k, m, 3), its normals (m, 3) and their change dN (k, m, 3), the
    performer's landmarks `rest` (68, 3) and their motion (k, 68, 3), in face widths; `rows` the
    landmarks' coordinates' weights; R0 the rest frame's rotation; `eyes` None or (their samples
    (me, 3), each one's side (me,), the eyes' centres (2, 3), the face's axes (3, 3), how each
    weight turns the eyes (k, 4)), the eyes turning rigidly about their centres."""

    def __init__(self, V, D, normals, dN, rest, motion, rows, R0, eyes=None):
        self.V, self.N = V, normals
        self.dN = np.ascontiguousarray(dN.reshape(len(dN), -1))            # (k, m * 3): the normals' change, one matmul
        self.light = np.r_[1.0, np.zeros(LIGHTS - 1)]                      # the last frame's light: the room's stays
        self.N0 = normals @ R0.T                                            # the normals as the rest frame sees them
        self.Dflat = np.ascontiguousarray(D.reshape(len(D), -1))           # (k, m * 3): the shape's motion, one matmul
        # (m, 6, k): each sample's motion and normals' change in every shape, a small matrix each, so that
        # the grey level's change with the weights is one batched product
        self.B = np.ascontiguousarray(np.concatenate([D, dN], axis=2).transpose(1, 2, 0))
        self.rest, self.motion, self.rows = rest, motion, rows
        self.k = len(D)
        self.eyes = eyes is not None
        if self.eyes:                                                       # named once, not by position
            self.Ve, self.eye_side, self.eye_centres, self.eye_axes, self.turns = eyes
            self.eye_on = [self.eye_side == 0, self.eye_side == 1]
            self.eye_skews = cross_matrices(self.eye_axes[:2])                # cross(x, .), cross(up, .)

    def _eye_points(self, look):
        """The eyes' samples turned by `look` (2, 2: each eye's out and up, in GAZE_FULL_DEG), and
        their derivatives (me, 4, 3) in (right out, right up, left out, left up).  The subject's
        left is the face's +x: out turns the left eye about the up axis toward +x, the right toward
        -x; up about the x axis, the front toward +y."""
        Ve, centres = self.Ve, self.eye_centres
        Kx, Kup = self.eye_skews                                            # cross(x, .) and cross(up, .) as matrices
        g = np.radians(GAZE_FULL_DEG)
        out = np.empty_like(Ve)
        J = np.zeros((len(Ve), 4, 3))
        for k, away in ((0, -1.0), (1, 1.0)):
            on = self.eye_on[k]
            Ry, Rx = _turn(Kup, away * look[k, 0] * g), _turn(Kx, -look[k, 1] * g)
            q = (Ve[on] - centres[k]) @ Rx.T                                 # pitched, then turned
            p = q @ Ry.T
            out[on] = centres[k] + p
            J[on, 2 * k] = away * g * (p @ Kup.T)
            J[on, 2 * k + 1] = -g * (q @ Kx.T) @ Ry.T
        return out, J

    def _shape(self, w):
        return self.V + (w @ self.Dflat).reshape(-1, 3)

    def _crop(self, image, x, s):
        """The frame about the surface's points x (y up), a tenth of the face's width around them,
        and the crop's corner (column, row)."""
        pad = 0.1 * s
        h, wd = image.shape[:2]
        r0, r1 = int(max(0, -x[:, 1].max() - pad)), int(min(h, -x[:, 1].min() + pad + 1))
        c0, c1 = int(max(0, x[:, 0].min() - pad)), int(min(wd, x[:, 0].max() + pad + 1))
        return image[r0:r1, c0:c1], np.array([c0, r0])

    def references(self, frame, s, R, t, w) -> list:
        """The surface's grey levels and red-green differences in the rest frame (RGB), at each blur
        (the eyes' samples after the face's, looking ahead); sets which samples each channel counts
        (the red-green difference's where it changes most across them: on the lips, the brows, the
        irises -- on even skin it shows no motion) and their shapes' motion and normals' change."""
        from scipy.ndimage import gaussian_filter
        m = len(self.V)
        x = s * (self._shape(w) @ R.T)[:, :2] + t
        crop, corner = self._crop(frame, x, s)
        if self.eyes:
            x = np.r_[x, s * (self.Ve @ R.T)[:, :2] + t]
        crops = np.moveaxis(crop @ _CHANNELS, 2, 0)                  # grey, red-green
        gy, gx = np.gradient(gaussian_filter(crops[1], BLURS[-1] * s, truncate=TRUNCATE))
        change = np.hypot(*_bilinear(np.stack([gx, gy]), x, corner))
        self.channels = []
        for sel in (np.arange(len(x)), np.sort(np.argsort(-change)[:int(CHROMA_SHARE * len(x))])):
            face = sel[sel < m]
            self.channels.append((sel, face, sel[sel >= m] - m, self.B[face]))
        self.rows_total = sum(len(ch[0]) for ch in self.channels)
        return [[_bilinear(gaussian_filter(img, b * s, truncate=TRUNCATE)[None], x[ch[0]], corner)[0]
                 for img, ch in zip(crops, self.channels)] for b in BLURS]

    def _between_lids(self, xe, xl):
        """Whether each eye sample's projection xe (me, 2) lies between its lids -- inside the
        polygon of its eye's six landmarks (xl: the 68 model landmarks projected, (68, 2)) scaled
        by EYE_INSET about its centre (a closing lid hides the samples it passes) -- and on its
        eye's side of the nose's line (from the bridge to the tip, 27 to 30: a turned head's nose
        hides the far eye's inner part)."""
        from ..correspond.eyes import inside_polygon
        side = self.eye_side
        inside = np.zeros(len(side), bool)
        a, d = xl[27], xl[30] - xl[27]

        def across(q):                                  # which side of the nose's line: the 2D cross product
            return d[0] * (q[..., 1] - a[1]) - d[1] * (q[..., 0] - a[0])
        for k, outer in ((0, 36), (1, 45)):
            poly = xl[LIDS[k]]
            mid = poly.mean(0)
            on = side == k
            own_side = across(xe[on]) * np.sign(across(xl[outer])) > 0
            inside[on] = inside_polygon(xe[on], mid + EYE_INSET * (poly - mid)) & own_side
        return inside

    def refine(self, frame, refs, pts, s, R, t, w, last, ridge):
        """A frame's weights (the frame RGB, (h, w, 3) uint8), from the landmark fit's pose (s, R, t) and
        weights w; `pts` its landmarks (68, 2, y up), `last` the last frame's weights, `ridge` (k,)
        each weight's pull toward rest."""
        from scipy.ndimage import gaussian_filter
        k, m = self.k, len(self.V)
        x = s * (self._shape(w) @ R.T)[:, :2] + t
        crop, corner = self._crop(frame, x, s)
        crops = np.moveaxis(crop @ _CHANNELS, 2, 0)                   # grey, red-green, about the face only
        light = self.light.copy()
        lo = np.r_[np.full(6, -np.inf), np.zeros(k), np.full(LIGHTS, -np.inf)]
        hi = np.r_[np.full(6, np.inf), np.ones(k), np.full(LIGHTS, np.inf)]
        sl = np.sqrt(LANDMARK_PULL / 136) * self.rows
        for blur, steps, cs in zip(BLURS, STEPS, refs):
            # each channel's blurred image and its derivatives down and across, sampled together
            stack = []
            for img in crops:
                img = gaussian_filter(img, blur * s, truncate=TRUNCATE)
                stack += [img, *np.gradient(img)]
            stack = np.stack(stack)
            for _ in range(steps):
                RX = self._shape(w) @ R.T
                if self.eyes:
                    Xe, Je = self._eye_points((w @ self.turns).reshape(2, 2))
                    RX = np.r_[RX, Xe @ R.T]
                mm = len(RX)
                x = s * RX[:, :2] + t
                got = _bilinear(stack, x, corner)
                uv = (x - x[:m].mean(0)) / s                            # across the face, face widths
                NR = (self.N + (w @ self.dN).reshape(-1, 3)) @ R.T                # the normals, bent by the weights
                turned = np.r_[NR - self.N0, np.zeros((mm - m, 3))]
                XL = self.rest + np.einsum("k,knj->nj", w, self.motion)
                RXL = XL @ R.T
                seen = np.r_[NR[:, 2] > FACING, np.zeros(mm - m, bool)]
                if self.eyes:                                           # between the lids, facing the camera
                    outward = Xe - self.eye_centres[self.eye_side]
                    facing = (outward @ R[2]) > EYE_FACING * np.linalg.norm(outward, axis=1)
                    seen[m:] = self._between_lids(x[m:], s * RXL[:, :2] + t) & facing
                # the pixels' rows, each channel's in turn, weighted: the Jacobian in (a small rotation d,
                # scale 1 + e, shift s u, the weights, the light) and the misfit
                Aph = np.empty((self.rows_total, 6 + k + LIGHTS))
                rph = np.empty(self.rows_total)
                at = 0
                for ch, ((sel, face, eye, B), c) in enumerate(zip(self.channels, cs)):
                    A, nf = Aph[at:at + len(sel)], len(face)
                    grey, gy, gx = got[3 * ch:3 * ch + 3, sel]
                    a = np.stack([gx, -gy, np.zeros(len(sel))], 1)     # the gradient (y up)
                    aR = a @ R                                          # ... in the head's frame
                    # as the landmark fit's: x = s (1 + e) P (I + [d]x) R X + t + s u, so g.dx/dd = s RX x a;
                    # the weights move the samples (B's first three rows) and shade them: the turned
                    # normals' term below is c (n R' - n0).l, so d/dw_k = c dn_k.(R' l) (B's last three);
                    # the eyes' samples move with the gaze's weights only, turning the eyes
                    A[:, :3] = np.cross(RX[sel], a)
                    A[:, 3] = (a * RX[sel]).sum(1)
                    A[:, 4:6] = a[:, :2]
                    q = np.c_[aR[:nf], (-c[:nf] / s)[:, None] * (R.T @ light[3:6])]
                    A[:nf, 6:6 + k] = np.matmul(q[:, None, :], B)[:, 0]
                    if self.eyes:
                        A[nf:, 6:6 + k] = (Je[eye] @ aR[nf:, :, None])[:, :, 0] @ self.turns.T
                    A[:, :6 + k] *= s
                    # the light: a gain varying across the face, the shading's change as the surface turns
                    # from the rest frame and bends (Lambert's, to first order: its normals' change), an
                    # offset each channel; the eyes' samples take all but the normals' terms.  White light
                    # scales the red-green difference as it scales the grey level: the gain's terms shared
                    lit = A[:, 6 + k:]
                    lit[:, 0], lit[:, 1], lit[:, 2] = c, c * uv[sel, 0], c * uv[sel, 1]
                    lit[:, 3:6] = c[:, None] * turned[sel]
                    lit[:, 6:] = 0.0
                    lit[:, 6 + ch] = 1.0
                    r = grey - lit @ light
                    huber = seen[sel] / np.maximum(1.0, np.abs(r) / ROBUST)
                    sw = np.sqrt(huber * PIXEL_PULL / max(seen.sum(), 1))
                    lit *= -1.0
                    A *= sw[:, None]
                    rph[at:at + len(sel)] = r * sw
                    at += len(sel)
                AL = np.c_[projection_jacobian(RXL, R, self.motion).reshape(136, -1), np.zeros((136, LIGHTS))] * sl[:, None]
                bL = ((pts - t) / s - RXL[:, :2]).reshape(-1) * sl
                # the normal equations: the pixels' and the landmarks' rows, the pulls on the weights
                # (toward rest, toward the last frame's) and on the light's step on the diagonal
                H = gram(Aph) + AL.T @ AL
                g = Aph.T @ (-rph) + AL.T @ bL
                H[6:6 + k, 6:6 + k] += np.diag(ridge + SMOOTH)
                H[-LIGHTS:, -LIGHTS:] += 1e-6 * np.eye(LIGHTS)
                g[6:6 + k] += SMOOTH * (last - w) - ridge * w
                lo[6:6 + k], hi[6:6 + k] = -w, 1.0 - w           # z holds the weights' step
                z = box_qp(H, g, lo, hi)
                angle = np.linalg.norm(z[:3])
                if angle > 0.0:
                    R = _turn(cross_matrices(z[None, :3] / angle)[0], angle) @ R
                t = t + s * z[4:6]
                s = s * (1.0 + z[3])
                w = np.clip(w + z[6:6 + k], 0.0, 1.0)
                light = light + z[-LIGHTS:]
        self.light = light
        return w
