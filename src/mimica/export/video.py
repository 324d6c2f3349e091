"""ARKit weights from a video, without an iPhone: the face's 68 points are
tracked frame by frame (MediaPipe's face mesh with attention in its tracking mode, or dlib's
detector: track_video), and the 52 weights fitted to them through the head's own blendshapes.

The model of a frame is a scaled orthographic camera looking at the head's landmarks moved by
its blendshapes:  x = s P R (L + sum_k w_k B_k) + t,  with L the performer's rest landmarks,
B_k the landmarks' motion in ARKit shape k (read from the head's GLB), P the first two rows.
Each frame takes Gauss-Newton steps on the pose jointly with a bounded least squares on the
weights (0 <= w <= 1; linear in them), starting from the last frame's: a ridge first, then an
L1 pull toward few shapes (reweighted), then the chosen shapes refitted without it (a relaxed
lasso), with a pull toward the last frame's weights.  Departure from plain least squares,
measured on dlib's points of rendered ICT takes (other identities and light, bench/export.py's
takes): without the L1 pull the points' noise spreads over shapes that move them alike -- mean
error over the jaw, mouth, brow and blink weights 0.071 against 0.027 on the training take,
0.063 and 0.061 against 0.034 and 0.018 on two others.  The price: a shape that moves the
points little (a brow) is seen only from about 0.3 of its weight.

The performer is not the head: their rest landmarks are the head's plus the offset that the
take's first frame (or the one named) shows, lifted into the head's frame at the head's depth --
the take must start from a rest face, as Live Link Face's calibration also asks -- and then each
point's depth as the take's own turns show it (_depth_offsets), the take fitted again through
them; given the video, each frame's weights are then refined on its pixels (photometric: the
points move less than the face); last, each weight's share that follows the head's turn over
the take is taken out (_turn_share: the tracker's points drift with the turn).  tongueOut is
not fitted (the points do not see it): it stays 0.  The gaze shapes (eyeLook*) are not fitted to
the points; given the video and a head with eyes of its own (photometric.eye_samples), they are
found on the pixels with the other weights, each turning its eye GAZE_FULL_DEG at 1 and moving
the lids as its shape does.  Else they are read from the irises of MediaPipe's attention mesh
(gaze_weights) and joined to the fit's weights by fit_take; through dlib's points without the
video they stay 0.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import MimicaError
from ._solve import box_qp, projection_jacobian
from .blendshapes import ARKIT_52
from .extras import LANDMARKS_KEY, stored_landmarks  # noqa: F401  (the key, for readers of this module)
from .photometric import GAZE_FULL_DEG, eye_samples, face_surface, refine_frames, set_motion

UNSEEN = tuple(n for n in ARKIT_52 if n.startswith("eyeLook") or n == "tongueOut")
# the points a face's expressions move least: the nose bridge and its base, the eyes' corners
RIGID = np.r_[27:31, 31:36, 36, 39, 42, 45]
# tuned on one training take (identity seed 1007, its own expressions, dlib's points); measured
# on others (bench/export.py).  Lengths in face widths (landmarks 0 to 16).
REST_PULL = 1e-4           # weight of sum w^2 against the points' misfit
SPARSE_PULL = 1e-3         # weight of sum w (an L1 pull toward few shapes)
SMOOTH_PULL = 1e-3         # weight of the change from the last frame's weights
RELAX_STAY = 0.02          # ... or above this when it was kept in the frame before
RELAX_KEEP = 0.1           # a weight the L1 pull keeps above this is refitted without it
GAUSS_NEWTON_STEPS = 3     # per frame (and one to refit), from the last frame's pose and weights
SMOOTH_POINTS = 1.5        # frames: the points' Gaussian over time
# the face's outline and the brows' outer ends, where detectors err most, count less: MediaPipe's
# points sit 1.4-4.6 % of the face's width from the true projections there (the brows' ends 3.8 %)
# against 0.9-2.4 % elsewhere (six painted training takes, identities 1011-1016, after each
# frame's similarity); the brows' ends at 1 stood browOuterUp at 0.1-0.2 where it did not act
POINT_WEIGHTS = np.r_[np.full(17, 0.3), 0.3, 0.3, np.ones(6), 0.3, 0.3, np.ones(41)]
CHECK_EVERY = 5            # frames: the face detector confirms the tracked face this often
# degrees of yaw or pitch from the rest frame past which a still face's turn reads as expression:
# neutral takes turning up to 30 degrees (identities 1009, 1010, painted; 300 frames) put a weight
# over 0.3 in 0-8 % of the frames within 15 degrees and in 33-42 % past it through MediaPipe's
# points (the depths found from the turns, the brows' ends counting less, the weights' share
# that follows the turn taken out), in none refined on the pixels (a light fixed in the room
# still shades a turned face otherwise: docs/benchmarks.md); through dlib's in 73-99 % at any
# turn, refined on the pixels 45-76 % within 15 degrees and 39-65 % past it
TURN_TRUSTED = 15.0
# the gaze (gaze_weights, and on the pixels photometric's): an eyeLook weight of 1 turns the eye
# GAZE_FULL_DEG, defined there
EYE_RADIUS = 0.4           # the iris's distance before the eye's centre of turning over the eye's width: ~11 of 28 mm (anatomy)
# MediaPipe's attention mesh: each eye's outer corner, inner corner and iris centre (the subject's right eye, left eye)
EYE_POINTS = ((33, 133, 468), (263, 362, 473))
DEPTH_ROUNDS = 2           # the points' depths found from the take's turns, the take fitted again
DEPTH_RIDGE = 1e-3         # ... the weights' ridge while the depths are found (face widths)
DEPTH_PRIOR = 1e-3         # ... and the pull toward no depth offset, per frame
DEPTH_STRIDE = 3           # ... from every third frame's fit (against every frame's: weights 0.001 apart on average)
# ... where the head turns past this many degrees from the rest frame somewhere in the take: under
# it a frame's depth moves a point by under sin(5 deg) of it, and a 16-frame frontal take's
# misfit (a blink) was read as depths of 0.05-0.08 of the face's width
DEPTH_MIN_TURN = 5.0
# the weights' share that follows the turn (_turn_share): its L1 fit's ridge, a thousandth of the
# frames' weight -- without it, on takes turning 8 degrees, coefficients of 5-46 took smiles and
# blinks away (grey dev takes 0.287 -> 0.347 where weights act)
TURN_SHARE_RIDGE = 1e-3
HELD_WEIGHT = 0.99         # a weight at its bound (1) ...
HELD_SECONDS = 1.0         # ... this long is said


@dataclass
class LandmarkBasis:
    """The head's 68 landmarks at rest and their motion in each ARKit shape, metres in the GLB's
    frame (landmark_basis).

    Attributes
    ----------
    rest : (68, 3) float array
    motion : (52, 68, 3) float array
        In names' order.
    names : list of str
        ARKIT_52.
    landmarks : str
        Where the landmarks came from: "stored" (by `blendshapes`), "given" (a landmark file),
        "ICT-FaceKit's" (built in for its topology) or "found" (on renders of the head).
    surface : photometric.Surface or None
        The head's face surface the weights are refined on, on the frames' pixels (None: the
        landmarks alone); its `eyes` the eyeballs' fronts the gaze is found on (None for a head
        whose eyes are one surface with the lids).
    """
    rest: np.ndarray
    motion: np.ndarray
    names: list
    landmarks: str = "stored"
    surface: object = None


def landmark_basis(head_glb, landmarks=None, read=None) -> LandmarkBasis:
    """Read the head's landmarks and their motion in its ARKit morph targets (named as other
    tools name them too: facts.arkit_targets): the landmarks a GLB written by `blendshapes`
    stores (LANDMARKS_KEY); for a head from another tool, or one a DCC wrote back without
    mimica's extras, those of a landmark file, else found as for any head
    (landmarks.auto.landmarks_for: built in for ICT-FaceKit's topology, else on renders).

    Parameters
    ----------
    head_glb : str or Path
        A glTF/GLB (or FBX) head with the 52 ARKit morph targets.
    landmarks : str or Path or None
        A landmark file for a head that stores none (JSON: landmarks.core.read_landmarks).
    read : tuple or None
        The head as mesh.io.read_morph_targets read it, where the caller has it (an FBX is read
        through Blender: seconds); None: read here.

    Returns
    -------
    LandmarkBasis
        MimicaError for a head without the 52 ARKit targets, or one whose landmarks can be
        neither read nor found.
    """
    from ..mesh.io import UNITS, read_morph_targets
    from ..facts import arkit_targets
    head_glb = Path(head_glb)
    mesh, targets, unit = read_morph_targets(head_glb) if read is None else read
    plays = arkit_targets(targets)
    missing = [n for n in ARKIT_52 if n not in plays]
    if missing:
        raise MimicaError(f"{head_glb}: not a head with the 52 ARKit morph targets (none plays "
                          f"{', '.join(missing[:3])}{' ...' if len(missing) > 3 else ''}; make them with `blendshapes`)")
    stored = stored_landmarks(mesh.layout.extras, mesh.n_vertices, str(head_glb)) if landmarks is None else None
    how = "stored"
    if stored is None:
        from ..landmarks.auto import landmarks_for
        lm = landmarks_for(mesh, landmarks, what=str(head_glb))
        if not lm.present.all():
            raise MimicaError(f"{head_glb}: {int((~lm.present).sum())} of its 68 landmarks missing; give all 68 "
                              "in a landmark file")
        how = "given" if landmarks is not None else "found" if lm.found else "ICT-FaceKit's"
        stored = mesh.triangles[lm.triangle], lm.bary
    tri, bary = stored
    k = UNITS[unit]                                  # metres, as the file holds them

    def at(p):
        return k * np.einsum("ij,ijk->ik", bary, p[tri])
    rest = at(mesh.vertices)
    motion = np.stack([at(targets[plays[n]]) - rest for n in ARKIT_52])
    surface = face_surface(k * mesh.vertices, mesh.triangles, rest)
    set_motion(surface, k * mesh.vertices, mesh.triangles, (k * targets[plays[n]] for n in ARKIT_52))
    eyes = eye_samples(mesh, rest / k)
    if eyes is not None:                                  # metres, as the surface
        eyes.rest, eyes.centres = k * eyes.rest, k * eyes.centres
    surface.eyes = eyes
    return LandmarkBasis(rest, motion, list(ARKIT_52), how, surface)


def _pose(model: np.ndarray, image: np.ndarray, rows=RIGID):
    """Scaled orthographic pose (s, R (3x3), t (2,)) taking 3D points to image points (y up),
    fitted on `rows` (image.warp.orthographic_pose)."""
    from ..image.warp import orthographic_pose
    return orthographic_pose(model[rows], image[rows])


@dataclass
class VideoFit:
    """The ARKit weights fitted to a take's tracked points (fit_weights).

    Attributes
    ----------
    weights : (F, 52) float array
        In ARKIT_52's order.
    rotations : (F, 3, 3) float array
        The head's rotation relative to the rest frame.
    residual : (F,) float array
        RMS misfit of the 68 points, in face widths.
    missing : (F,) bool array
        Frames that showed no face: fitted to points interpolated from their neighbours.
    unseen : tuple of str
        The shapes nothing in the take showed: they stay 0 (the tongue; the gaze too where neither
        the pixels (a head with eyes, the video given) nor the tracker's irises showed it).
    angles : (F, 3) float array
        The head's yaw, pitch and roll from the rest frame, radians (head_angles of the
        rotations; computed from them where not given).
    """
    weights: np.ndarray          # (F, 52) in ARKIT_52's order
    rotations: np.ndarray        # (F, 3, 3): the head's rotation relative to the rest frame
    residual: np.ndarray         # (F,) RMS misfit of the 68 points, in face widths
    missing: np.ndarray = None   # (F,) frames without a face
    unseen: tuple = UNSEEN
    angles: np.ndarray = None    # (F, 3) head_angles(rotations)

    def __post_init__(self):
        if self.angles is None:
            self.angles = head_angles(self.rotations)


def _fill_missing(pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tracked points (F, 68, 2) with NaN rows where a frame showed no face: those frames' points
    interpolated linearly in time from the nearest frames with a face (held at the ends), and
    which they were."""
    missing = ~np.isfinite(pts).all(axis=(1, 2))
    if missing.all():
        raise MimicaError("tracked points: no frame has a face")
    if not missing.any():
        return pts, missing
    have, gone = np.nonzero(~missing)[0], np.nonzero(missing)[0]
    # each missing frame between its nearest seen frames (held at the ends), all coordinates at once
    hi = np.clip(np.searchsorted(have, gone), 1, len(have) - 1) if len(have) > 1 else np.zeros(len(gone), int)
    lo = np.maximum(hi - 1, 0)
    span = np.maximum(have[hi] - have[lo], 1)
    t = np.clip((gone - have[lo]) / span, 0.0, 1.0)[:, None, None]
    out = pts.copy()
    out[gone] = (1 - t) * pts[have[lo]] + t * pts[have[hi]]
    return out, missing


def fit_weights(points: np.ndarray, basis: LandmarkBasis, rest_frame: int = 0, rest_pull: float = REST_PULL,
                smooth_pull: float = SMOOTH_PULL, smooth_points: float = SMOOTH_POINTS,
                sparse_pull: float = SPARSE_PULL, depth_rounds: int = DEPTH_ROUNDS, turn_share: bool = True,
                video=None, progress=None) -> VideoFit:
    """The ARKit weights of each frame of tracked 2D points: the head's pose (scaled orthographic)
    and weights in [0, 1] through its landmark basis, frame by frame (Gauss-Newton on the pose
    joined to a bounded least squares on the weights), pulled toward rest, toward few shapes (a
    reweighted L1, then refitted without it) and toward the last frame's weights.

    Parameters
    ----------
    points : (F, 68, 2) float array
        Pixels (y down); NaN rows where a frame showed no face (fitted to points interpolated
        from their neighbours; `missing` says which).
    basis : LandmarkBasis
    rest_frame : int
        The frame showing the performer's rest: what it shows of their own face is added to the
        head's landmarks (a per-performer neutral), and the rotations are relative to it.
    rest_pull : float
        Weight of sum w^2 against the points' misfit.
    smooth_pull : float
        Weight of the change from the last frame's weights.
    smooth_points : float
        Frames: a Gaussian over time on the points first, against the detector's jitter.
    sparse_pull : float
        Weight of sum w (an L1 pull toward few shapes).
    depth_rounds : int
        Rounds of the points' depths found from the take and the take fitted again (0: the rest
        frame's points lifted at the head's own depth, as one frame shows them).
    turn_share : bool
        Take out of each weight its share that follows the head's turn over the take
        (_turn_share).
    video : str or Path or None
        The take the points were tracked on: each frame's weights are refined on its pixels
        (photometric.refine_frames) where the basis has the head's surface, and the gaze's found
        there where it has the head's eyes.
    progress : callable, optional
        Called with a line of text as frames are refined.

    Returns
    -------
    VideoFit
    """
    pts = np.asarray(points, np.float64)
    if pts.ndim != 3 or pts.shape[1:] != (68, 2) or not len(pts):
        raise MimicaError(f"tracked points: expected (frames, 68, 2), got {pts.shape}")
    if not 0 <= rest_frame < len(pts):
        raise MimicaError(f"rest frame {rest_frame}: the take has frames 0 to {len(pts) - 1}")
    pts, missing = _fill_missing(pts)
    if missing[rest_frame]:
        raise MimicaError(f"rest frame {rest_frame}: it shows no face; name a frame where the performer's face is "
                          "at rest")
    width = float(np.linalg.norm(basis.rest[16] - basis.rest[0]))          # lengths in face widths
    L = basis.rest / width
    B = basis.motion / width
    free = np.array([n not in UNSEEN for n in basis.names])
    Bf = B[free]                                                           # (k, 68, 3)
    img = pts * [1.0, -1.0]                                                # y up, as the head's frame
    if smooth_points and len(img) > 1:                                     # the detector's jitter
        from scipy.ndimage import gaussian_filter1d
        img = gaussian_filter1d(img, smooth_points, axis=0, mode="nearest")
    # the performer's rest: the head's landmarks plus what the rest frame shows of their own face
    s0, R0, t0 = _pose(L, img[rest_frame])
    for _ in range(3):
        off2 = (img[rest_frame] - t0) / s0 - L @ R0[:2].T                   # in the camera's plane
        Ls = L + off2 @ R0[:2]                                             # lifted at the head's depth
        s0, R0, t0 = _pose(Ls, img[rest_frame])
    pulls = (rest_pull, sparse_pull, smooth_pull)
    depth = np.zeros(len(L))
    pick = slice(None, None, DEPTH_STRIDE)
    for r in range(depth_rounds):                    # the depths from every DEPTH_STRIDE-th frame
        X0 = Ls + np.outer(depth, R0[2])             # the rest frame's view of them is unchanged
        w, s, R, t, res = _fit_frames(img[pick], X0, Bf, pulls)
        use = ~missing[pick] & (res < 0.05)
        if r == 0 and not (np.abs(head_angles(R[use] @ R0.T)[:, :2]) > np.radians(DEPTH_MIN_TURN)).any():
            break                                    # a take that never turns shows no depth
        depth = depth + _depth_offsets(img[pick], X0, Bf, s, R, t, R0[2], use=use)
    rest = Ls + np.outer(depth, R0[2])
    w, s, R, t, res = _fit_frames(img, rest, Bf, pulls)
    out = np.zeros((len(pts), len(basis.names)))
    unseen = UNSEEN
    if video is not None and basis.surface is not None:
        out = refine_frames(video, img, L, rest, B, basis.surface, free, width, w, s, R, t,
                            ~missing & (res < 0.05), POINT_WEIGHTS, rest_frame, progress)
        if basis.surface.eyes is not None:           # the gaze found on the pixels, the eyes turning
            unseen = tuple(n for n in UNSEEN if not n.startswith("eyeLook"))
    else:
        out[:, free] = w
    fitted = np.array([n not in unseen for n in basis.names])
    rel = R @ R0.T
    angles = head_angles(rel)
    if turn_share:
        out[:, fitted] = _turn_share(out[:, fitted], angles)
    return VideoFit(out, rel, res, missing, unseen, angles=angles)


def fit_take(tracked: Tracked, basis: LandmarkBasis, rest_frame: int = 0, video=None, progress=None) -> VideoFit:
    """A tracked take's ARKit weights: fit_weights through its points (and its pixels, given the
    video), then, where the pixels did not find the gaze, the eyeLook weights from its irises
    where the tracker gave them (gaze_weights, which reads the head's turn the fit found).

    Parameters
    ----------
    tracked : Tracked
        track_video's.
    basis : LandmarkBasis
    rest_frame : int
        The frame showing the performer at rest (fit_weights).
    video : str or Path or None
        The take itself: the weights refined on its pixels (fit_weights).
    progress : callable, optional
        Called with a line of text as frames are refined.

    Returns
    -------
    VideoFit
        Its `unseen` names what stays 0: the tongue, and the gaze where neither the pixels nor
        the irises showed it.
    """
    fit = fit_weights(tracked.points, basis, rest_frame=rest_frame, video=video, progress=progress)
    if not any(n.startswith("eyeLook") for n in fit.unseen):
        return fit                                   # the gaze found on the pixels
    gaze = gaze_weights(tracked.eyes, fit.angles)
    for n, w in gaze.items():
        fit.weights[:, ARKIT_52.index(n)] = w
    fit.unseen = tuple(n for n in UNSEEN if n not in gaze)
    return fit


def _fit_frames(img, Ls, Bf, pulls):
    """Each frame's pose (s, R, t) and weights (F, k) through the motion Bf (k, 68, 3) from the
    rest Ls (68, 3) (fit_weights; img y up, lengths in face widths), and its RMS misfit."""
    from scipy.spatial.transform import Rotation
    rest_pull, sparse_pull, smooth_pull = pulls
    n = len(img)
    k = len(Bf)
    smo = np.c_[np.zeros((k, 6)), np.sqrt(smooth_pull) * np.eye(k)]
    out = np.zeros((n, k))
    Rs = np.zeros((n, 3, 3))
    ss, ts = np.zeros(n), np.zeros((n, 2))
    res = np.zeros(n)
    w = np.zeros(k)
    kept = np.zeros(k, bool)
    rows = np.repeat(POINT_WEIGHTS, 2)
    lo = np.r_[np.full(6, -np.inf), np.zeros(k)]
    hi = np.r_[np.full(6, np.inf), np.ones(k)]
    P = np.eye(3)[:2]
    for f in range(n):
        if f == 0 or res[f - 1] > 0.05:                 # (re)start the pose from the rigid points
            s_, R, t = _pose(Ls + np.einsum("k,knj->nj", w, Bf), img[f])
        w_prev = w
        for it in range(GAUSS_NEWTON_STEPS + 1):
            # a Gauss-Newton step on the pose (a small rotation d, scale 1 + e, shift s u) joined
            # to a bounded least squares on the weights (linear in them), from the last frame's
            X = Ls + np.einsum("k,knj->nj", w, Bf)          # the current shape (68, 3)
            RX = X @ R.T
            A = projection_jacobian(RX, R, Bf).reshape(136, 6 + k) * rows[:, None]
            b = ((img[f] - t) / s_ - Ls @ (P @ R).T).reshape(-1) * rows
            top = hi
            if it == 0:                                      # a plain ridge to start from
                pull = np.full(k, rest_pull)
            elif it < GAUSS_NEWTON_STEPS:
                # sparsity: an L1 pull (sum w, w >= 0) as a reweighted ridge, lambda / (w + eps):
                # 68 points tell apart poorly shapes that move them alike (a smile, a dimple, a
                # stretch), and the fewest that explain them are the likeliest
                pull = rest_pull + sparse_pull / (w + 0.05)
            else:
                # relaxed lasso: the L1 pull chose the shapes (with hysteresis over time); their
                # weights are refitted without it, as it shrinks every weight it keeps
                kept = (w > RELAX_KEEP) | (kept & (w > RELAX_STAY))
                pull = np.full(k, rest_pull)
                top = np.r_[hi[:6], np.where(kept, 1.0, 1e-12)]
            M = np.vstack([A, np.c_[np.zeros((k, 6)), np.diag(np.sqrt(pull))], smo])
            y = np.r_[b, np.zeros(k), smo[:, 6:] @ w_prev]
            z = box_qp(M.T @ M, M.T @ y, lo, top)
            R = Rotation.from_rotvec(z[:3]).as_matrix() @ R
            t = t + s_ * z[4:6]
            s_ = s_ * (1.0 + z[3])
            w = np.where(z[6:] > 1e-9, z[6:], 0.0)
        out[f] = w
        Rs[f], ss[f], ts[f] = R, s_, t
        res[f] = float(np.sqrt(np.mean((A @ z - b) ** 2)))
    return out, ss, Rs, ts, res


def _depth_offsets(img, rest, motion, s, R, t, axis, use, ridge=DEPTH_RIDGE, prior=DEPTH_PRIOR):
    """How far each point lies before or behind `rest` along the rest frame's view axis, as the
    take's turns show it: one frame shows no depth, so the rest frame's points were lifted at the
    head's, and where the performer's face, or where the tracker's point sits on it, differs in
    depth, every turn moves the point sideways and the fit reads that as an expression (a jaw or
    mouth pulled to one side with the yaw).  Least squares over the take of each frame's misfit
    at rest with the weights' part projected out (variable projection; a ridge `ridge` on the
    weights, so what they explain as well as the depth stays theirs only where they must), and a
    prior `prior` toward no offset per frame (a take that never turns shows none).  Lengths in
    face widths; frames not in `use` are left out."""
    rows = POINT_WEIGHTS[None, :, None]                                 # the fit's own weighting
    s, R, t, img = s[use], R[use], t[use], img[use]
    if not len(s):
        return np.zeros(len(rest))
    PR = R[:, :2, :]                                                    # (F, 2, 3), per face width
    b = ((img - t[:, None]) / s[:, None, None] - np.einsum("nj,fij->fni", rest, PR)) * rows   # (F, 68, 2)
    J = np.einsum("fij,knj->fnik", PR, motion) * rows[..., None]        # (F, 68, 2, k)
    G = (PR @ axis)[:, None, :] * rows                                  # (F, 68, 2): d/d depth
    k = motion.shape[0]
    Jtb = np.einsum("fnik,fni->fk", J, b)
    JtG = np.einsum("fnik,fni->fkn", J, G)                             # (F, k, 68)
    JtJ = np.einsum("fnik,fnil->fkl", J, J) + ridge * np.eye(k)
    S = np.linalg.solve(JtJ, np.concatenate([JtG, Jtb[..., None]], 2))   # (F, k, 69)
    A = np.diag(np.einsum("fni,fni->n", G, G)) - np.einsum("fkn,fkm->nm", JtG, S[..., :-1])
    y = np.einsum("fni,fni->n", G, b) - np.einsum("fkn,fk->n", JtG, S[..., -1])
    return np.linalg.solve(A + prior * len(s) * np.eye(len(rest)), y)


def trackers() -> list[str]:
    """The face trackers installed here, the default first.

    Returns
    -------
    list of str
        "mediapipe" where the photo extra is installed, then "dlib" (always).
    """
    import importlib.util
    return (["mediapipe"] if importlib.util.find_spec("mediapipe") else []) + ["dlib"]


@dataclass
class Tracked:
    """A take's tracked face (track_video).

    Attributes
    ----------
    fps : float
        The video's frame rate.
    points : (F, 68, 2) float array
        Pixels; NaN rows where a frame shows no face.
    eyes : (F, 2, 3, 2) float array
        The subject's right and left eye's outer corner, inner corner and iris centre in pixels
        (MediaPipe's attention mesh: EYE_POINTS); NaN where no face, and throughout for dlib (it
        sees no irises).
    """
    fps: float
    points: np.ndarray
    eyes: np.ndarray


def track_video(path, progress=None, max_frames: int | None = None, tracker: str | None = None) -> Tracked:
    """The face's 68 points and its eyes through a video or a folder of frames.

    "mediapipe" (the default where the photo extra is installed): MediaPipe's face mesh with
    attention in its tracking mode (detect2d.mediapipe_tracker), the 68 of its points that read
    as the iBUG points (detect2d.mediapipe_68).
    "dlib": dlib's detector and shape predictor, each frame's points fitted inside the box of the
    last frame's; the detector confirms the face every CHECK_EVERY frames, and where it finds
    none, the frames since the last confirmation (the last frames too) are checked one by one, so
    that the frames without a face are known exactly; then it looks for the face again on every
    frame.
    dlib's box loses the face on a turn (its points' motion off by 6.5-78 pixels against
    MediaPipe's 2.0-6.8), and a still face's turn reads as expression far less through MediaPipe's
    points; the fit through each: docs/benchmarks.md (bench/video_arkit.py, bench/export.py).

    Parameters
    ----------
    path : str or Path
    progress : callable, optional
        Called with a line of text every 30 frames tracked.
    max_frames : int or None
        Stop after this many.
    tracker : str or None
        "mediapipe" or "dlib" (None: the first of trackers()).

    Returns
    -------
    Tracked
    """
    from ..image.video import frame_source
    from ..landmarks.detect2d import box_of, detect_faces, fit_points
    tracker = tracker or trackers()[0]
    if tracker not in ("mediapipe", "dlib"):
        raise MimicaError(f"unknown face tracker {tracker!r}; use one of mediapipe, dlib")
    n, fps, frames = frame_source(path, raw=True)              # both trackers read uint8
    none = np.full((68, 2), np.nan)
    if tracker == "mediapipe":
        tracked = _tracked_mediapipe(frames, n, progress, max_frames, path)
        pts = _checked(path, n, max_frames, [p for p, _ in tracked])
        return Tracked(fps, pts, np.stack([e for _, e in tracked]))
    out, raw, since = [], None, []          # since: (frame, image) tracked since the detector last saw the face

    def nearest(boxes, c):
        return min(boxes, key=lambda b: np.hypot((b[0] + b[2]) / 2 - c[0], (b[1] + b[3]) / 2 - c[1]))

    def faces(img):
        """The detector's boxes, on the frame at half size where it is 400 pixels or more (a
        quarter of the cost; a tracked face is large), in the frame's pixels."""
        if min(img.shape[:2]) < 400:
            return detect_faces(img)
        return [tuple(2 * c for c in b) for b in detect_faces(img[::2, ::2], upsample=0)]
    try:
        for i, img in _counted(frames, n, progress, max_frames):
            if raw is None:                                     # looking for a face
                boxes = faces(img)
                raw = fit_points(img, boxes[0]) if boxes else None
                since = []
                out.append(none if raw is None else raw)
                continue
            pts = fit_points(img, box_of(raw))
            lost = np.abs(pts - raw).max() > 0.25 * np.ptp(raw[:, 0])
            if lost or i % CHECK_EVERY == 0:
                boxes = faces(img)
                if not boxes:                                   # gone: since when
                    gone = next((j for j, im in since if not faces(im)), i)
                    out[gone:] = [none] * (len(out) - gone)
                    out.append(none)
                    raw, since = None, []
                    continue
                if lost:
                    pts = fit_points(img, nearest(boxes, raw.mean(0)))
                since = []
            else:
                since.append((i, img))
            raw = pts
            out.append(pts)
        # the last frames since the detector's last look: checked too (a face gone at the end)
        gone = next((j for j, im in since if not faces(im)), None)
        if gone is not None:
            out[gone:] = [none] * (len(out) - gone)
    except (RuntimeError, OSError) as e:                        # ffmpeg stopping inside the stream
        raise _broken_off(path, len(out), e) from None
    pts = _checked(path, n, max_frames, out)
    return Tracked(fps, pts, np.full((len(pts), 2, 3, 2), np.nan))


def _tracked_mediapipe(frames, n, progress, max_frames, path) -> list:
    """(the 68 points, the eyes (2, 3, 2): EYE_POINTS) of each frame by MediaPipe's face mesh in
    its tracking mode (track_video)."""
    from ..landmarks.detect2d import mediapipe_68, mediapipe_tracker
    track, pick, out = mediapipe_tracker(), mediapipe_68(), []
    eye = np.array(EYE_POINTS)
    try:
        for _, img in _counted(frames, n, progress, max_frames):
            pts = track(img)
            out.append((np.full((68, 2), np.nan), np.full((2, 3, 2), np.nan)) if pts is None else (pts[pick], pts[eye]))
    except (RuntimeError, OSError) as e:                        # ffmpeg stopping inside the stream
        raise _broken_off(path, len(out), e) from None
    return out


def _counted(frames, n, progress, max_frames):
    """(index, frame) of the first max_frames frames, a line to `progress` every 30."""
    for i, img in enumerate(frames):
        if max_frames is not None and i >= max_frames:
            return
        if progress and i and i % 30 == 0:
            progress(f"tracked {i}" + (f" of {n}" if n else "") + " frames")
        yield i, img


def _broken_off(path, done: int, e: Exception) -> MimicaError:
    """The one line for a video whose decoder stopped after `done` frames."""
    what = str(e).splitlines()[0] if str(e) else type(e).__name__
    return MimicaError(f"{path}: the video breaks off after {done} frames ({what}); re-encode it "
                       "(ffmpeg -i IN -c:v libx264 OUT.mp4) or cut it there")


def _checked(path, n, max_frames, out: list) -> np.ndarray:
    """The tracked frames' points (F, 68, 2), or one line where the video held fewer frames than
    its header said, or no face at all."""
    if not out:
        raise MimicaError(f"{path}: no frames")
    if n and max_frames is None and len(out) < n - max(2, 0.1 * n):    # its header promised more
        raise MimicaError(f"{path}: the video breaks off after {len(out)} of its {n} frames (the file is cut short); "
                          "re-encode what is left (ffmpeg -i IN -c:v libx264 OUT.mp4)")
    pts = np.stack(out)
    if not np.isfinite(pts).any():
        raise MimicaError(f"{path}: no face in any of its {len(pts)} frames")
    return pts


def gaze_weights(eyes: np.ndarray, angles: np.ndarray, smooth_points: float = SMOOTH_POINTS) -> dict:
    """The eyeLook* weights of a take from its irises: each iris's offset from the middle of its
    eye's corners, across and along the eye, over the eye's width, read as the eye's turn
    (asin(offset / EYE_RADIUS)) and the turn as weights (GAZE_FULL_DEG for 1).  The iris lies in
    front of the corners, so the head's turn moves it across them too, by a depth that is the
    performer's own: that share (on the sines of the fitted yaw and pitch, and the rest offset)
    is regressed out over the whole take, whose gaze shifts are brief.  Smoothed over time as the
    points are.

    Parameters
    ----------
    eyes : (F, 2, 3, 2) float array
        track_video's eyes (NaN where unseen: filled from the neighbouring frames).
    angles : (F, 3) float array
        The head's yaw, pitch and roll relative to the rest frame (head_angles of the fit's
        rotations).
    smooth_points : float
        Frames: the Gaussian over time.

    Returns
    -------
    dict
        {eyeLook name: (F,) float array in [0, 1]}, the eight of them; empty where no frame
        shows the irises.
    """
    from scipy.ndimage import gaussian_filter1d
    e = np.asarray(eyes, np.float64).reshape(len(eyes), 6, 2)
    if not np.isfinite(e).any():
        return {}
    e, _ = _fill_missing(e)
    e = e.reshape(-1, 2, 3, 2)
    sines = np.sin(np.asarray(angles)[:, :2])
    # a turn the head never makes shows no share: regressed on a still head's fitted jitter (a
    # thousandth of a degree), a look was read as 0.39 of its 0.5
    X = np.c_[sines[:, np.ptp(sines, axis=0) > np.sin(np.radians(1.0))], np.ones(len(e))]
    out = {}
    for k, side in enumerate(("Right", "Left")):
        outer, inner, iris = e[:, k, 0], e[:, k, 1], e[:, k, 2]
        along = inner - outer
        width = np.maximum(np.linalg.norm(along, axis=1), 1e-9)
        along = along / width[:, None]
        up = np.stack([along[:, 1], -along[:, 0]], 1) * (1.0 if side == "Right" else -1.0)   # the image's up (y down)
        rel = iris - 0.5 * (outer + inner)
        turn = {}
        for name, c in (("out", -(rel * along).sum(1) / width), ("up", (rel * up).sum(1) / width)):
            c = c - X @ _l1_fit(X, c)                                   # the head's share, and the rest
            if smooth_points and len(c) > 1:
                c = gaussian_filter1d(c, smooth_points, mode="nearest")
            turn[name] = np.degrees(np.arcsin(np.clip(c / EYE_RADIUS, -1.0, 1.0))) / GAZE_FULL_DEG
        out[f"eyeLookOut{side}"] = np.clip(turn["out"], 0.0, 1.0)
        out[f"eyeLookIn{side}"] = np.clip(-turn["out"], 0.0, 1.0)
        out[f"eyeLookUp{side}"] = np.clip(turn["up"], 0.0, 1.0)
        out[f"eyeLookDown{side}"] = np.clip(-turn["up"], 0.0, 1.0)
    return out


def _l1_fit(X: np.ndarray, y: np.ndarray, rounds: int = 10, floor: float = 1e-3, ridge: float = 0.0) -> np.ndarray:
    """Coefficients c minimising sum |X c - y| (reweighted least squares): the brief gaze shifts
    of a take are outliers to the head's share, which a least-squares fit would lean toward.
    (A few columns: ten small solves, where scipy's least_squares would only smooth the L1 loss.)
    `ridge` > 0 adds ridge * |c|^2 in units of the frames' weight (from c = 0): where the columns
    vary little, the plain fit's coefficients can grow to fit brief events with them."""
    c = np.zeros(X.shape[1]) if ridge else np.linalg.lstsq(X, y, rcond=None)[0]
    for _ in range(rounds):
        sw = 1.0 / np.sqrt(np.maximum(np.abs(X @ c - y), floor))
        A, b = X * sw[:, None], y * sw
        c = (np.linalg.solve(A.T @ A + ridge * (sw ** 2).sum() * np.eye(X.shape[1]), A.T @ b) if ridge
             else np.linalg.lstsq(A, b, rcond=None)[0])        # lstsq: a still take's sine columns are 0
    return c


def _turn_share(w: np.ndarray, angles: np.ndarray, ridge: float = TURN_SHARE_RIDGE) -> np.ndarray:
    """The weights (F, k) less each one's share that follows the head's turn over the take: an L1
    fit (_l1_fit, a small ridge) on the turn's sines, their squares and product, only a positive
    share taken out.  MediaPipe's points drift with the turn unlike the surface (through the
    exact projections the weights stand at 0.001-0.004 at any turn, through its points at
    0.02-0.07), and the drift reads as weights that rise and fall with the turn; a take's
    expressions are brief against it, outliers to the fit, as the gaze's shifts are in
    gaze_weights.  No constant: the rest frame is 0."""
    sy, sp = np.sin(angles[:, 0]), np.sin(angles[:, 1])
    X = np.stack([sy, sp, sy * sy, sp * sp, sy * sp], 1)
    out = w.copy()
    for j in np.nonzero(w.any(0))[0]:
        out[:, j] = np.clip(w[:, j] - np.maximum(X @ _l1_fit(X, w[:, j], ridge=ridge), 0.0), 0.0, 1.0)
    return out


def head_angles(rotations: np.ndarray) -> np.ndarray:
    """The head's rotations as Euler angles (R = Ry Rx Rz, as animate's head rotation reads them).

    Parameters
    ----------
    rotations : (F, 3, 3) float array

    Returns
    -------
    (F, 3) float array
        Yaw, pitch, roll in radians.
    """
    from scipy.spatial.transform import Rotation
    return Rotation.from_matrix(rotations).as_euler("YXZ")


def write_live_link_csv(path, times: np.ndarray, weights: np.ndarray, fps: float,
                        angles: np.ndarray | None = None) -> Path:
    """Write a Live Link Face-style CSV, whole or not at all.

    Columns: Timecode (HH:MM:SS:FF.fff, FF counting frames at `fps` within each second, so that a
    reader finds the rate from a take of a second or more), BlendShapeCount, the 52 PascalCase
    weights, then HeadYaw, HeadPitch, HeadRoll (radians) and the eyes' (zero).

    Parameters
    ----------
    path : str or Path
    times : (F,) float array
        Seconds.
    weights : (F, 52) float array
        In ARKIT_52's order.
    fps : float
    angles : (F, 3) float array or None
        Yaw, pitch, roll (head_angles); None: zeros.

    Returns
    -------
    Path
    """
    from ..mesh import atomic_path
    rot = ["HeadYaw", "HeadPitch", "HeadRoll", "LeftEyeYaw", "LeftEyePitch", "LeftEyeRoll",
           "RightEyeYaw", "RightEyePitch", "RightEyeRoll"]
    lines = [",".join(["Timecode", "BlendShapeCount"] + [n[0].upper() + n[1:] for n in ARKIT_52] + rot)]
    ang = np.zeros((len(times), 3)) if angles is None else angles
    for t, w, a in zip(times, weights, ang):
        sec = int(np.floor(t + 1e-9))
        ff = round((float(t) - sec) * fps, 3)
        if ff >= fps - 0.0005:                    # rounding reached the next second
            sec, ff = sec + 1, 0.0
        h, rem = divmod(sec, 3600)
        m, s = divmod(rem, 60)
        lines.append(",".join([f"{h:02d}:{m:02d}:{s:02d}:{ff:06.3f}", "61"] + [f"{x:.6f}" for x in w]
                              + [f"{x:.6f}" for x in a] + ["0"] * 6))
    path = Path(path)
    with atomic_path(path) as tmp:
        Path(tmp).write_text("\n".join(lines) + "\n")
    return path


def _spans(mask: np.ndarray) -> list[tuple[int, int]]:
    """The runs of True in a (F,) bool array, as (first, last) frames."""
    d = np.diff(np.r_[0, mask.astype(np.int8), 0])
    return list(zip(np.nonzero(d == 1)[0].tolist(), (np.nonzero(d == -1)[0] - 1).tolist()))


def what_it_saw(fit: VideoFit, fps: float, names=ARKIT_52) -> dict:
    """What a video's fit should tell its user: the frames without a face, the frames turned
    further than the fit can be trusted (TURN_TRUSTED: past it a still face's turn reads as
    expression), and the weights held at their bound for long.

    Parameters
    ----------
    fit : VideoFit
    fps : float
        The video's rate.
    names : list of str
        The weights' names (fit.weights' columns).

    Returns
    -------
    dict
        {"no_face": [(first, last), ...], "turned": [(first, last), ...] where |yaw| or |pitch|
        from the rest frame passes TURN_TRUSTED degrees, "turn_max": the largest (degrees),
        "held": {name: [(first, last), ...]} where a weight stays at or above HELD_WEIGHT for
        HELD_SECONDS or longer}.
    """
    missing = np.zeros(len(fit.weights), bool) if fit.missing is None else fit.missing
    ang = np.degrees(np.abs(fit.angles[:, :2])).max(1)
    ang[missing] = 0.0
    long = max(1, int(round(HELD_SECONDS * fps)))
    held = {}
    for j, n in enumerate(names):
        runs = [r for r in _spans((fit.weights[:, j] >= HELD_WEIGHT) & ~missing) if r[1] - r[0] + 1 >= long]
        if runs:
            held[n] = runs
    return {"no_face": _spans(missing), "turned": _spans(ang > TURN_TRUSTED), "turn_max": float(ang.max()),
            "held": held}


def write_preview(path, video, head_glb, weights: np.ndarray, rotations: np.ndarray, fps: float,
                  missing: np.ndarray | None = None, height: int = 360, progress=None, read=None) -> Path:
    """An MP4 of the video beside the head playing the fitted weights, frame by frame (the head
    turned as the fit found the performer's head; frames without a face marked red).

    Parameters
    ----------
    path : str or Path
        The MP4 to write (whole, or not at all).
    video : str or Path
        The video (or folder of frames) the weights were fitted to.
    head_glb : str or Path
        The head with its ARKit morph targets.
    weights : (F, 52) float array
        In ARKIT_52's order.
    rotations : (F, 3, 3) float array
        The head's rotation relative to the rest frame.
    fps : float
    missing : (F,) bool array or None
        Frames without a face.
    height : int
        The preview's height, pixels.
    progress : callable, optional
        Called with a line of text every 30 frames.
    read : tuple or None
        The head as mesh.io.read_morph_targets read it, where the caller has it; None: read here.

    Returns
    -------
    Path
    """
    from PIL import Image
    from ..image.io import to_uint8
    from ..image.raster import framing, render_mesh
    from ..image.video import VideoWriter, frame_source
    from ..mesh.io import read_morph_targets
    from ..facts import arkit_targets
    mesh, targets, _ = read_morph_targets(head_glb) if read is None else read
    rest = mesh.vertices
    plays = arkit_targets(targets)
    deltas = np.stack([targets[plays[n]] - rest if n in plays else np.zeros_like(rest) for n in ARKIT_52])
    centre = rest.mean(0)
    frame = framing(rest)
    frame = (frame[0], frame[1] * 1.15)                                  # room to turn
    # the video is decoded a second time: keeping the tracking pass's frames would hold the whole
    # take in memory (a 10 s 640x480 take is ~1.1 GB as float32); a decode costs less than that
    _, _, frames = frame_source(video)
    with VideoWriter(path, fps) as out:
        for f, img in enumerate(frames):
            if f >= len(weights):
                break
            v = rest + np.tensordot(weights[f], deltas, 1)
            v = (v - centre) @ rotations[f].T + centre
            head = render_mesh(mesh, v, size=(height, height), frame=frame)
            im = Image.fromarray(to_uint8(img))
            im = im.resize((max(2, round(im.width * height / im.height)), height))
            both = Image.new("RGB", (im.width + height, height), "white")
            both.paste(im, (0, 0))
            both.paste(Image.fromarray(head), (im.width, 0))
            pic = np.asarray(both).copy()
            if missing is not None and missing[f]:
                pic[:6] = (220, 40, 40)                                  # no face: a red band
            out.write(pic)
            if progress and f and f % 30 == 0:
                progress(f"preview: {f} of {len(weights)} frames")
    return Path(path)

