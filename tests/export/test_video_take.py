"""ARKit weights from a video (mimica.export.video): the 68 tracked points fitted through the
head's own blendshapes.  A take made by the head's own landmark model is recovered; the Live Link
CSV keeps the video's rate; both trackers find the same points; what the fit saw is reported
(the command line's own tests: tests/cli/test_video_take_command.py)."""

from __future__ import annotations

import numpy as np

from mimica.export import ARKIT_52
from helpers import jaw_frames, ramp


def _projected(rest, motion, w, yaw, pitch) -> np.ndarray:
    """(F, 68, 2) pixels (y down) of the landmarks `rest` moved by weights w through `motion`,
    the head turned by yaw (F,) and pitch (radians)."""
    from scipy.spatial.transform import Rotation
    pts = np.zeros((len(w), 68, 2))
    for f in range(len(w)):
        R = Rotation.from_euler("YXZ", [yaw[f], pitch, 0.0]).as_matrix()
        p3 = (rest + np.einsum("k,knj->nj", w[f], motion)) @ R.T
        pts[f] = np.c_[320 + 1800 * p3[:, 0], 240 - 1800 * p3[:, 1]]
    return pts


def test_a_take_made_by_the_heads_own_points_is_recovered(head_glb):
    """Points projected from the head's landmarks moved by known weights, under a turning head:
    the fit finds the weights (mean error under 0.08 where they act, correlation over 0.95, under
    0.02 elsewhere) and the head's turn."""
    from mimica.export.video import fit_weights, head_angles, landmark_basis
    basis = landmark_basis(head_glb)
    frames = 60
    w = np.zeros((frames, 52))
    w[:, ARKIT_52.index("jawOpen")] = ramp(frames, 5, 30, 0.8)
    w[:, ARKIT_52.index("mouthSmileLeft")] = ramp(frames, 25, 30, 0.7)
    w[:, ARKIT_52.index("browInnerUp")] = ramp(frames, 10, 40, 0.9)
    yaw = np.radians(10) * np.sin(np.arange(frames) / 12)
    fit = fit_weights(_projected(basis.rest, basis.motion, w, yaw, 0.05), basis)
    acting = [ARKIT_52.index(n) for n in ("jawOpen", "mouthSmileLeft", "browInnerUp")]
    on = w[:, acting] > 0.2
    err = np.abs(fit.weights[:, acting] - w[:, acting])
    assert err[on].mean() < 0.08, err[on].mean()
    for j in acting:
        assert np.corrcoef(fit.weights[:, j], w[:, j])[0, 1] > 0.95
    rest = np.delete(np.arange(52), acting)
    assert np.abs(fit.weights[:, rest]).mean() < 0.02
    turn = head_angles(fit.rotations)[:, 0]                       # relative to the rest frame
    assert np.abs(turn - (yaw - yaw[0])).max() < np.radians(1.0)


def test_the_rest_frame_removes_a_performers_resting_asymmetry(head_glb):
    """A performer whose face at rest is lopsided (its left corner raised, its right brow down,
    another face's proportions): the rest frame is their neutral, so at rest every weight reads
    under 0.05 and the take's own shapes are found on top of the lopsided rest (jawOpen and
    mouthSmileRight within 0.08 where they act).  Read against the head's own rest instead (its
    landmarks as the first frame), the same points show the raised corner as a standing
    mouthSmileLeft (0.38 of its 0.45)."""
    from mimica.export.video import fit_weights, landmark_basis
    basis = landmark_basis(head_glb)
    frames = 50
    lopsided = {"mouthSmileLeft": 0.45, "browDownRight": 0.5}
    rest = basis.rest * [1.04, 0.97, 1.0] + sum(a * basis.motion[ARKIT_52.index(n)] for n, a in lopsided.items())
    w = np.zeros((frames, 52))
    w[:, ARKIT_52.index("jawOpen")] = ramp(frames, 5, 25, 0.7)
    w[:, ARKIT_52.index("mouthSmileRight")] = ramp(frames, 22, 25, 0.6)
    pts = _projected(rest, basis.motion, w, np.radians(6) * np.sin(np.arange(frames) / 10), 0.04)
    fit = fit_weights(pts, basis)
    still = w.max(1) == 0
    assert still.sum() >= 5
    assert fit.weights[still].max() < 0.05, fit.weights[still].max()
    for n in ("jawOpen", "mouthSmileRight"):
        j = ARKIT_52.index(n)
        on = w[:, j] > 0.2
        assert np.abs(fit.weights[on, j] - w[on, j]).mean() < 0.08, (n, np.abs(fit.weights[on, j] - w[on, j]).mean())
    # the same points with the head's own rest as the performer's: the asymmetry is a standing expression
    head_rest = np.c_[320 + 1800 * basis.rest[:, 0], 240 - 1800 * basis.rest[:, 1]]
    fit_head = fit_weights(np.concatenate([head_rest[None], pts]), basis)
    assert fit_head.weights[1:][still, ARKIT_52.index("mouthSmileLeft")].mean() > 0.2


def test_the_takes_turns_place_the_performers_points_in_depth(head_glb):
    """A performer whose jaw line lies deeper and brows further forward than the head's (by 5 and
    3 % of the face's width; a tracker's points sit at depths of their own too), the head turning
    from 25 degrees to -25 and back, the jaw opening once: one rest frame cannot show depth, so
    read through the rest frame alone the turn reads as expression (another shape over 0.1:
    browDownLeft reaches 0.5); with the depths found from the turns, every other weight stays
    under 0.05 and jawOpen is found within 0.05 where it acts."""
    from mimica.export.video import fit_weights, landmark_basis
    basis = landmark_basis(head_glb)
    width = np.linalg.norm(basis.rest[16] - basis.rest[0])
    rest = basis.rest.copy()
    rest[:17, 2] -= 0.05 * width
    rest[17:27, 2] += 0.03 * width
    frames = 120
    w = np.zeros((frames, 52))
    j = ARKIT_52.index("jawOpen")
    w[:, j] = ramp(frames, 50, 30, 0.7)
    pts = _projected(rest, basis.motion, w, np.radians(25) * np.cos(np.arange(frames) * 2 * np.pi / frames), 0.05)
    others = np.delete(np.arange(52), j)
    alone = fit_weights(pts, basis, depth_rounds=0).weights
    assert alone[:, others].max() > 0.1, alone[:, others].max()
    fit = fit_weights(pts, basis).weights
    assert fit[:, others].max() < 0.05, (ARKIT_52[others[np.argmax(fit[:, others].max(0))]], fit[:, others].max())
    on = w[:, j] > 0.2
    assert np.abs(fit[on, j] - w[on, j]).mean() < 0.05, np.abs(fit[on, j] - w[on, j]).mean()


def test_a_take_that_never_turns_keeps_the_rest_frames_lift(head_glb):
    """The head turning under DEPTH_MIN_TURN: no depth is read from the take (its points'
    misfit -- here the tracker's noise -- would be), so the weights are those of the rest frame's
    lift alone; turning past it, the depths are found."""
    from mimica.export.video import DEPTH_MIN_TURN, fit_weights, landmark_basis
    basis = landmark_basis(head_glb)
    frames = 60
    w = np.zeros((frames, 52))
    w[:, ARKIT_52.index("eyeBlinkLeft")] = ramp(frames, 10, 30, 0.9)
    noise = np.random.default_rng(7).normal(0, 0.4, (frames, 68, 2))
    for turn, same in ((0.5 * DEPTH_MIN_TURN, True), (3 * DEPTH_MIN_TURN, False)):
        pts = _projected(basis.rest, basis.motion, w, np.radians(turn) * np.sin(np.arange(frames) / 9), 0.05) + noise
        lifted = fit_weights(pts, basis, depth_rounds=0).weights
        assert np.array_equal(fit_weights(pts, basis).weights, lifted) == same, turn


def test_live_link_csv_keeps_the_video_rate(tmp_path):
    """The CSV's timecode counts frames at the video's rate: a 30 fps take of 2.5 s reads back at
    30 fps with its times (a 60 fps count would read as 59)."""
    from mimica.export.take import read_take
    from mimica.export.video import write_live_link_csv
    times = np.arange(75) / 30
    w = np.random.default_rng(3).uniform(0, 1, (75, 52))
    write_live_link_csv(tmp_path / "t.csv", times, w, 30.0)
    back, weights, rate = read_take(tmp_path / "t.csv")
    assert rate == 30 and np.allclose(back, times, atol=1e-6)
    assert np.allclose(weights["jawOpen"], w[:, ARKIT_52.index("jawOpen")], atol=1e-6)


def test_both_trackers_find_the_same_points(tmp_path):
    """MediaPipe's face mesh (the default where installed) and dlib track the same 68 points on a take: within a
    few hundredths of the face's width of each other, and a faceless last frame alike (dlib's
    frames since its detector last looked are checked at the end too); a tracker not known is
    one line."""
    import pytest
    from mimica.errors import MimicaError
    from mimica.export.video import track_video, trackers
    assert trackers() == ["mediapipe", "dlib"]         # CI installs the photo extra
    frames = jaw_frames(tmp_path / "frames", ramp(8, 1, 6, 1.0), blank=(7,))
    a = track_video(frames).points
    b = track_video(frames, tracker="dlib").points
    assert np.isnan(a[7]).all() and np.isnan(b[7]).all() and np.isfinite(a[:7]).all()
    width = np.ptp(b[:7, :, 0], axis=1).mean()
    gap = np.linalg.norm(a[:7] - b[:7], axis=2)
    assert np.median(gap) < 0.04 * width, np.median(gap) / width
    with pytest.raises(MimicaError, match="unknown face tracker 'x'"):
        track_video(frames, tracker="x")


def test_the_default_tracker_sees_a_blink(head_glb, tmp_path, mediapipe):
    """Rendered frames of ICT's face closing its left eye, tracked by the default tracker
    (MediaPipe's face mesh with attention: its lids refined) and fitted through the head: the
    left eye's blink rises and falls with the rendered one, the right eye stays open.  (Through
    MediaPipe's plain face mesh the fitted blink stays 0 on these frames; through dlib's points it
    rises only as the eye opens again.)"""
    from mimica.export.video import fit_weights, landmark_basis, track_video
    blink = ramp(16, 2, 12, 1.0)
    frames = jaw_frames(tmp_path / "frames", blink, shape="eyeBlink_L")
    pts = track_video(frames).points
    w = fit_weights(pts, landmark_basis(head_glb)).weights
    left, right = w[:, ARKIT_52.index("eyeBlinkLeft")], w[:, ARKIT_52.index("eyeBlinkRight")]
    assert np.corrcoef(left, blink)[0, 1] > 0.75 and left.max() > 0.4, np.round(left, 2)
    assert 3 <= np.argmax(left) <= 11, np.round(left, 2)               # while the eye is closing or shut
    assert right.max() < 0.25, np.round(right, 2)


def test_what_it_saw_turns_and_held_weights():
    """The report's turns past what the fit trusts and weights held at 1 for a second or more."""
    from scipy.spatial.transform import Rotation
    from mimica.export.video import TURN_TRUSTED, VideoFit, what_it_saw
    f = 100
    w = np.zeros((f, 52))
    w[10:40, ARKIT_52.index("jawOpen")] = 1.0                   # 30 frames at 25 fps: held
    w[50:70, ARKIT_52.index("mouthPucker")] = 1.0               # 20 frames: not
    yaw = np.zeros(f)
    yaw[60:64] = np.radians(TURN_TRUSTED + 5)
    rot = Rotation.from_euler("YXZ", np.stack([yaw, 0 * yaw, 0 * yaw], 1)).as_matrix()
    saw = what_it_saw(VideoFit(w, rot, np.zeros(f), np.zeros(f, bool)), 25.0)
    assert saw["held"] == {"jawOpen": [(10, 39)]}
    assert saw["turned"] == [(60, 63)] and abs(saw["turn_max"] - TURN_TRUSTED - 5) < 1e-6
    assert saw["no_face"] == []


def test_other_tools_names_play_the_arkit_shapes(head_glb, tmp_path):
    """Morph targets as other tools name them -- Live Link's PascalCase, a Maya namespace, ICT's
    and Blender's side suffixes, Blender's copies -- are read as the ARKit shapes, an exact name
    winning; names of no ARKit shape are none.  A head whose targets are so named is played
    whole (all 52 driven, each by its own shape's weights)."""
    import pygltflib as gl
    from mimica.export.take import animate_glb
    from mimica.facts import arkit_name, arkit_targets
    from mimica.mesh.io.gltf import read_accessor
    for name, arkit in (("EyeBlinkLeft", "eyeBlinkLeft"), ("blendShape1.jawOpen", "jawOpen"),
                        ("|head|mouthLeft", "mouthLeft"), ("head:cheekPuff", "cheekPuff"),
                        ("mouthSmile_L", "mouthSmileLeft"), ("browDown.R", "browDownRight"),
                        ("eyeWideRight.001", "eyeWideRight"), ("Basis", None), ("browInnerUp_L", None),
                        ("smile", None)):
        assert arkit_name(name) == arkit, name
    assert arkit_targets(["JawOpen", "jawOpen", "Jaw_Open"]) == {"jawOpen": "jawOpen"}
    g = gl.GLTF2().load(str(head_glb))
    names = g.meshes[0].extras["targetNames"]
    g.meshes[0].extras["targetNames"] = ["blendShape1." + n[0].upper() + n[1:] for n in names]
    g.save_binary(str(tmp_path / "maya.glb"))
    rng = np.random.default_rng(5)
    weights = {n: rng.uniform(0, 1, 3) for n in ARKIT_52}
    info = animate_glb(tmp_path / "maya.glb", tmp_path / "take.glb", np.arange(3) / 30, weights)
    assert info["driven"] == 52
    out = gl.GLTF2().load(str(tmp_path / "take.glb"))
    anim = read_accessor(out, out.animations[0].samplers[0].output).reshape(3, len(names))
    for j, n in enumerate(names):
        np.testing.assert_allclose(anim[:, j], weights[n], atol=1e-6)


def _eyes(frames, right_out, yaw, depth=0.1):
    """(F, 2, 3, 2) eyes of a face 40 px an eye, the head turning by yaw (radians; the irises,
    `depth` eye widths before the corners, move across them) and the right eye turning out by
    right_out (degrees)."""
    from mimica.export.video import EYE_RADIUS
    eyes = np.zeros((frames, 2, 3, 2))
    for k, (outer, inner) in enumerate((((100.0, 200.0), (140.0, 200.0)), ((220.0, 200.0), (180.0, 200.0)))):
        eyes[:, k, 0], eyes[:, k, 1] = outer, inner
        eyes[:, k, 2] = ((np.array(outer) + inner) / 2)[None] + np.c_[40 * depth * np.sin(yaw), np.zeros(frames)]
    eyes[:, 0, 2, 0] -= 40 * EYE_RADIUS * np.sin(np.radians(right_out))      # toward its outer corner
    return eyes


def test_gaze_from_the_irises():
    """An iris moving toward its eye's outer corner reads as that eye looking out, by the angle its
    offset gives over GAZE_FULL_DEG; the other shapes stay 0; a head turning alone (the irises
    moving across the corners by their depth) reads as no gaze."""
    from scipy.spatial.transform import Rotation
    from mimica.export.video import GAZE_FULL_DEG, gaze_weights, head_angles
    frames = 90
    turn = ramp(frames, 30, 40, 0.5 * GAZE_FULL_DEG)                  # half a full look out
    still = np.zeros((frames, 3))
    g = gaze_weights(_eyes(frames, turn, np.zeros(frames)), still)
    assert abs(g["eyeLookOutRight"].max() - 0.5) < 0.05, g["eyeLookOutRight"].max()
    assert np.corrcoef(g["eyeLookOutRight"], turn)[0, 1] > 0.98
    assert max(w.max() for n, w in g.items() if n != "eyeLookOutRight") < 0.02
    yaw = np.radians(25) * np.sin(np.arange(frames) / 10)
    rot = Rotation.from_euler("Y", yaw[:, None]).as_matrix()
    g = gaze_weights(_eyes(frames, np.zeros(frames), yaw), head_angles(rot))
    assert max(w.max() for w in g.values()) < 0.02, {n: w.max() for n, w in g.items()}
    assert gaze_weights(np.full((5, 2, 3, 2), np.nan), still[:5]) == {}   # dlib's: no irises


def test_fit_take_joins_the_gaze_to_the_fit(head_glb):
    """fit_take: the points' weights as fit_weights finds them, the eyeLook weights from the irises
    in their columns, and what stays 0 named -- the tongue; the gaze too where the tracker gave no
    irises (dlib's)."""
    from mimica.export.video import UNSEEN, GAZE_FULL_DEG, Tracked, fit_take, fit_weights, landmark_basis
    basis = landmark_basis(head_glb)
    frames = 60
    w = np.zeros((frames, 52))
    w[:, ARKIT_52.index("jawOpen")] = ramp(frames, 5, 30, 0.8)
    pts = _projected(basis.rest, basis.motion, w, np.zeros(frames), 0.0)
    turn = ramp(frames, 20, 30, 0.5 * GAZE_FULL_DEG)
    fit = fit_take(Tracked(30.0, pts, _eyes(frames, turn, np.zeros(frames))), basis)
    alone = fit_weights(pts, basis)
    look = ARKIT_52.index("eyeLookOutRight")
    assert abs(fit.weights[:, look].max() - 0.5) < 0.05, fit.weights[:, look].max()
    others = [j for j, n in enumerate(ARKIT_52) if not n.startswith("eyeLook")]
    np.testing.assert_allclose(fit.weights[:, others], alone.weights[:, others])
    assert fit.unseen == ("tongueOut",)
    blind = fit_take(Tracked(30.0, pts, np.full((frames, 2, 3, 2), np.nan)), basis)
    assert blind.unseen == UNSEEN and not blind.weights[:, look].any()
    np.testing.assert_allclose(blind.angles[:, 0], 0.0, atol=1e-3)


def test_the_share_of_a_weight_that_follows_the_turn_is_taken_out():
    """A weight that rises and falls with the head's turn over the take (a tracker's drift) is
    mostly taken out (the ridge keeps a little: under a third of it stays), a brief expression on
    top of it and in another shape kept; where the head turns only 8 degrees, brief expressions
    that happen to fall with the turn are kept too."""
    from mimica.export.video import _turn_share
    frames = 600
    t = np.arange(frames)
    yaw = np.radians(30) * np.sin(t / 60)
    pitch = np.radians(10) * np.sin(t / 45)
    angles = np.stack([yaw, pitch, 0 * yaw], 1)
    event = np.zeros(frames)
    event[200:225] = 0.8 * np.sin(np.linspace(0, np.pi, 25)) ** 2
    drift = 0.4 * (np.sin(yaw) / np.sin(np.radians(30))) ** 2
    w = np.stack([drift, np.minimum(drift + event, 1.0), np.roll(event, 150)], 1)
    out = _turn_share(w, angles)
    assert out[:, 0].mean() < drift.mean() / 3, (out[:, 0].mean(), drift.mean())     # measured 0.05 of 0.20
    on = event > 0.1
    assert np.abs(out[on, 1] - event[on]).max() < 0.1, np.abs(out[on, 1] - event[on]).max()
    np.testing.assert_allclose(out[:, 2], w[:, 2], atol=0.02)
    small = np.stack([np.radians(8) * np.sin(t / 60), np.radians(4) * np.sin(t / 45), 0 * t], 1)
    events = np.zeros((frames, 2))
    events[90:115, 0] = 0.7                                            # near the turn's peaks
    events[280:300, 1] = 0.5
    np.testing.assert_allclose(_turn_share(events, small), events, atol=0.02)
