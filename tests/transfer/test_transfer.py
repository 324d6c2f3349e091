"""Expression transfer on one topology (Song §IV) and the DT baseline, on real ICT-FaceKit data.

Targets are held out: no parameter was chosen on them (tuning used identity seeds 0-9 and
the ICT identity files 0-9; these use seeds 100+ and identity files 10-19).
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers import held_out_identity, skin_patch

from mimica.data import EXPRESSIONS, ICT_FACE_AREA_VERTICES
from mimica.landmarks import ict_landmarks
from mimica.transfer import ExpressionTransfer, relative_error, static_vertices

FACE = slice(0, ICT_FACE_AREA_VERTICES)
# expressions nobody tuned on: single ICT shapes outside the six basic expressions
HELD_SHAPES = ["mouthPucker", "mouthFunnel", "cheekPuff_L", "jawForward", "mouthRollLower", "eyeBlink_R"]


@pytest.fixture(scope="module")
def basic(head_model):
    return np.stack([head_model.neutral + head_model.delta(EXPRESSIONS[e]) for e in EXPRESSIONS])


def _transfer(model, target_vertices, frames, method="vtc"):
    S = model.mesh
    T = S.with_vertices(target_vertices)
    x = ExpressionTransfer(S, T, ict_landmarks(S), ict_landmarks(T), method=method,
                           static=static_vertices(S.vertices, frames))
    return x, x.apply(frames, basis=False)


def _errors(model, tv, frames, out):
    return [relative_error(o, tv + f - model.neutral, tv, FACE) for o, f in zip(out, frames)]


@pytest.mark.parametrize("method", ["vtc", "dt"])
def test_self_transfer_gives_the_expression_back(head_model, basic, method):
    _, out = _transfer(head_model, head_model.neutral, basic, method)
    err = np.abs(out - basic).max() / np.ptp(head_model.neutral, axis=0).max()
    assert err < 1e-6
    assert relative_error(out, basic, head_model.neutral) < 1e-6


def test_self_transfer_full_model_with_eyes_and_teeth(full_model):
    """The 26,719-vertex model has many parts (teeth, eyeballs) without fixed vertices."""
    frames = np.stack([full_model.neutral + full_model.delta({"jawOpen": 1.0, "eyeLookUp_L": 1.0})])
    x, out = _transfer(full_model, full_model.neutral, frames)
    assert np.abs(out - frames).max() / np.ptp(full_model.neutral, axis=0).max() < 1e-6


def test_cross_identity_error_on_held_out_identities(head_model, basic):
    errs = []
    for seed in (100, 101):
        tv = held_out_identity(head_model, seed)
        _, out = _transfer(head_model, tv, basic)
        errs.append(np.mean(_errors(head_model, tv, basic, out)))
    assert max(errs) < 0.10 and np.mean(errs) <= 0.08, errs


def test_ict_identity_files_held_out_expressions(head_model):
    frames = np.stack([head_model.neutral + head_model.delta({s: 1.0}) for s in HELD_SHAPES])
    for name in ("identity012", "identity017"):
        tv = head_model.identity(name)
        _, out = _transfer(head_model, tv, frames)
        assert np.mean(_errors(head_model, tv, frames, out)) < 0.08


def test_vtc_no_worse_than_dt(head_model, basic):
    tv = held_out_identity(head_model, 102)
    ev = np.mean(_errors(head_model, tv, basic, _transfer(head_model, tv, basic, "vtc")[1]))
    ed = np.mean(_errors(head_model, tv, basic, _transfer(head_model, tv, basic, "dt")[1]))
    assert ev <= ed * 1.05


def test_static_regions_stay_put(head_model, basic):
    tv = held_out_identity(head_model, 103)
    _, out = _transfer(head_model, tv, basic)
    st = static_vertices(head_model.neutral, basic)
    assert st.sum() > 500                                       # the back of the head
    # they carry the source's (sub-micron) motion exactly, nothing more
    np.testing.assert_allclose(out[:, st], tv[st] + (basic - head_model.neutral)[:, st], atol=1e-6)
    assert np.abs(out[:, st] - tv[st]).max() < 1e-5


def test_batches_equal_single_frames(head_model, basic):
    tv = held_out_identity(head_model, 104)
    x, out = _transfer(head_model, tv, basic)
    for i in (0, 3):
        np.testing.assert_allclose(x.apply(basic[i]), out[i], atol=1e-9)
    np.testing.assert_allclose(x.apply(basic, batch=2, workers=2), out, atol=1e-9)


def test_target_pose_does_not_matter(head_model, basic):
    """A rotated, scaled, moved target gets the same result, moved the same way."""
    from mimica.align import Similarity
    tv = held_out_identity(head_model, 105)
    _, ref = _transfer(head_model, tv, basic[:2])
    c, s_ = np.cos(0.4), np.sin(0.4)
    sim = Similarity(1.7, np.array([[c, 0, s_], [0, 1, 0], [-s_, 0, c]]), np.array([3.0, -1.0, 2.0]))
    _, out = _transfer(head_model, sim.apply(tv), basic[:2])
    np.testing.assert_allclose(out, sim.apply(ref), atol=1e-6)


@pytest.mark.parametrize("kind", ["vtc", "dt"])
def test_tips_from_their_operators(head_model, kind):
    """The basis path's tips (base + g(a x, b x)) are the elements' own tips, on moved frames."""
    from mimica.transfer.elements import dt_elements, vtc_elements
    el = (vtc_elements if kind == "vtc" else dt_elements)(head_model.mesh)
    v = np.stack([head_model.shape("jawOpen"), head_model.shape("mouthSmile_L")], axis=1)   # (n, F, 3)
    base, a, b = el.tip_operators
    parts = [(m @ v.reshape(len(v), -1)).reshape(-1, 2, 3) for m in (base, a, b)]
    g = el.tip_bend(tuple(parts[1][..., c].T for c in range(3)), tuple(parts[2][..., c].T for c in range(3)))
    np.testing.assert_allclose(np.stack(g, -1).transpose(1, 0, 2) + parts[0], el.tips(v), atol=1e-12 * np.ptp(v))


def test_long_sequences_go_through_their_basis(head_model):
    """A 160-frame performance of six expressions goes through its basis by default (one
    back-substitution per basis shape, the tips interpolated from 64 training frames) within
    1e-3 of its motion from frame by frame (measured 2.8e-4 on bench/batch.py's 300 frames),
    its check solving the frames whose tips the fit misses most, which see the largest
    deviation; a shorter one goes frame by frame; a motion of no few shapes, or one the training frames do
    not see (a blink between two of them), goes frame by frame, unchanged; frames at rest stay
    at rest."""
    from mimica.transfer import BASIS_DEVIATION, BASIS_FRAMES
    frames = head_model.performance(160)
    tv = held_out_identity(head_model, 131)
    x, exact = _transfer(head_model, tv, frames)                               # frame by frame
    assert not x.basis_report["used"]
    fast = x.apply(frames)                                                     # by default: 160 >= 128
    assert len(frames) >= BASIS_FRAMES
    assert x.basis_report["used"] and x.basis_report["deviation"] <= BASIS_DEVIATION, x.basis_report
    st = x.solver.basis_stats                                                  # the checked frames, solved in
    assert len(st["checked"]) == 4 and not np.isin(st["checked"], st["trained"]).any()   # the basis's solve,
    np.testing.assert_allclose(st["exact"], exact[st["checked"]], rtol=0, atol=1e-12 * np.ptp(tv))  # as one by one
    motion = np.linalg.norm(exact - tv, axis=2).max()
    worst = np.linalg.norm(fast - exact, axis=2).max() / motion
    assert worst <= 1e-3
    # the check sees the worst of it: the frames the tips' fit misses most (measured 1.0 of the
    # sequence's largest deviation; four frames spread evenly saw a quarter)
    assert x.basis_report["deviation"] >= 0.8 * worst, (x.basis_report, worst)
    x.apply(frames[:BASIS_FRAMES - 1])
    assert not x.basis_report["used"]                                          # shorter: frame by frame
    still = np.repeat(head_model.neutral[None], 70, axis=0)                    # rest stays at rest
    np.testing.assert_allclose(x.apply(still, basis=True), np.broadcast_to(tv, still.shape), atol=1e-9 * np.ptp(tv))
    assert x.basis_report["used"]
    noise = frames + np.random.default_rng(1).normal(0, 1e-3, frames.shape)   # every frame its own shape
    again = x.apply(noise, basis=True)
    assert not x.basis_report["used"] and "few shapes" in x.basis_report["why"]
    np.testing.assert_array_equal(again, x.apply(noise, basis=False))
    from mimica.transfer.core import BASIS_TRAIN
    blink = np.repeat(head_model.neutral[None], 160, axis=0)                   # one frame between the
    trained = np.unique(np.linspace(0, 159, BASIS_TRAIN).round().astype(int))  # training frames moves
    k = int(np.setdiff1d(np.arange(160), trained)[10])
    blink[k] += head_model.delta({"eyeBlink_L": 1.0})
    got = x.apply(blink)
    assert not x.basis_report["used"] and "miss" in x.basis_report["why"], x.basis_report
    np.testing.assert_array_equal(got, x.apply(blink, basis=False))


def test_a_take_of_twelve_shapes_goes_through_its_basis(head_model):
    """130 frames moving 12 ICT shapes independently (35 basis directions: a basis direction at
    1.2e-5 of the largest, which the range finder once dropped) go through the basis within 1e-3
    of the motion; 24 shapes are more than the training frames hold: frame by frame."""
    from mimica.store import shape_names
    names = [n for n in shape_names() if not n.startswith(("eyeLook", "Pupil", "identity", "generic"))]
    S = head_model.mesh
    tv = held_out_identity(head_model, 133)
    T = S.with_vertices(tv)
    for count, through in ((12, True), (24, False)):
        d = np.stack([head_model.delta({n: 1.0}) for n in names[:count]])
        rng = np.random.default_rng(0)
        t = np.linspace(0, 4 * np.pi, 130)[:, None]
        w = 0.6 * np.clip(np.sin(t * rng.uniform(0.5, 3.0, count) + rng.uniform(0, 2 * np.pi, count)), 0, None)
        frames = S.vertices + np.einsum("fk,knd->fnd", w, d)
        x = ExpressionTransfer(S, T, ict_landmarks(S), ict_landmarks(T), static=static_vertices(S.vertices, frames))
        exact, fast = x.apply(frames, basis=False), x.apply(frames)
        assert x.basis_report["used"] == through, (count, x.basis_report)
        motion = np.linalg.norm(exact - tv, axis=2).max()
        assert np.linalg.norm(fast - exact, axis=2).max() <= 1e-3 * motion


def test_basis_across_topologies(head_model):
    """Onto a remeshed head (its own topology; VTC with the per-triangle term, lids, fill), the
    basis path stays within 1e-3 of the motion of frame by frame (measured 4.4e-4 on these 300
    frames, its check 4.5e-4)."""
    from mimica.correspond.remesh import resample_face
    from mimica.data import ICT_FACE_AREA_FACES, ICT_LANDMARKS_68
    from mimica.landmarks import Landmarks
    tv = held_out_identity(head_model, 132)
    face, _ = head_model.mesh.with_vertices(tv).submesh(np.arange(ICT_FACE_AREA_FACES))
    rs = resample_face(face, tv[ICT_LANDMARKS_68], n_vertices=6000, seed=4)
    S = head_model.mesh
    frames = head_model.performance(300, seed=3)
    x = ExpressionTransfer(S, rs.mesh, ict_landmarks(S), Landmarks.snap(rs.mesh, tv[ICT_LANDMARKS_68]),
                           static=static_vertices(S.vertices, frames))
    exact = x.apply(frames, basis=False)
    fast = x.apply(frames)
    assert x.basis_report["used"], x.basis_report
    motion = np.linalg.norm(exact - rs.mesh.vertices, axis=2).max()
    assert np.linalg.norm(fast - exact, axis=2).max() <= 1e-3 * motion


def test_the_shared_thread_pool_works_in_a_forked_child_and_nested():
    """core._blocks keeps one thread pool a process: a forked child (which has none of its
    threads) gets its own instead of waiting forever, and work already on the pool runs in place."""
    import os
    import sys
    import subprocess
    code = """
import os, numpy as np
from mimica.transfer.core import _blocks
out = np.zeros(8)
def inner(i):
    out[i:i + 2] += 1
def outer(i):
    _blocks(inner, 8, 2)                          # on a pool thread: runs in place
_blocks(inner, 8, 2)
pid = os.fork()
if pid == 0:
    _blocks(outer, 4, 2)
    os._exit(0 if out.sum() == 8 + 2 * 8 else 3)
_, status = os.waitpid(pid, 0)
print(os.waitstatus_to_exitcode(status), out.sum())
"""
    if not hasattr(os, "fork"):
        pytest.skip("no fork on this platform")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.split() == ["0", "8.0"]


def test_prefaulted_memory_is_mapped_before_it_is_written():
    """The basis path's output is mapped on another thread while the solve runs: once waited
    for, writing all of it takes (almost) no page faults, where a fresh array takes one a page
    (allocator and numpy set as the command line sets them; Linux, which counts the faults)."""
    import subprocess
    import sys
    if not sys.platform.startswith("linux"):
        pytest.skip("page faults counted through getrusage on Linux")
    code = """
import json, resource, numpy as np
from mimica._memory import keep_memory, prefaulted
keep_memory()
def faults(a):
    f0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    a.fill(1.0)
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt - f0
shape = (300, 11248, 3)                                  # bench/batch.py's output, 81 MB
fresh = faults(np.empty(shape))
a, wait = prefaulted(shape)
wait()
print(json.dumps({"fresh": fresh, "mapped": faults(a), "pages": a.nbytes // 4096, "shape": list(a.shape)}))
"""
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    got = __import__("json").loads(r.stdout.strip().splitlines()[-1])
    assert got["shape"] == [300, 11248, 3]
    assert got["fresh"] >= 0.5 * got["pages"], got                           # the count sees faults
    assert got["mapped"] <= 0.01 * got["pages"], got


def test_settings_object_and_keywords_solve_alike(head_model, basic):
    """TransferSettings holds ExpressionTransfer's choices: a settings object and the same
    choice given as a keyword make the same transfer; a keyword changes one field of the
    object; a wrong name or value is refused, naming it."""
    from dataclasses import replace

    from mimica.errors import MimicaError
    from mimica.transfer import TransferSettings
    S = head_model.mesh
    T = S.with_vertices(held_out_identity(head_model, 101))
    dt = TransferSettings(method="dt", stabilize=False)
    a = ExpressionTransfer(S, T, settings=dt)
    b = ExpressionTransfer(S, T, method="dt", stabilize=False)
    c = ExpressionTransfer(S, T, settings=replace(dt, method="vtc"), method="dt")
    assert a.settings == b.settings == c.settings == dt and a.method == "dt"
    np.testing.assert_array_equal(a.apply(basic[:2]), b.apply(basic[:2]))
    with pytest.raises(TypeError, match="no setting metod"):
        ExpressionTransfer(S, T, metod="dt")
    with pytest.raises(TypeError, match="TransferSettings"):
        ExpressionTransfer(S, T, None, None, "dt")
    with pytest.raises(MimicaError, match="'vt'"):
        TransferSettings(method="vt")
    with pytest.raises(MimicaError, match="'closest'"):
        ExpressionTransfer(S, T, match="closest")


def test_anchor_carries_an_expression_to_other_proportions(head_model):
    """A target whose mouth region is 1.35x the source's (a smooth warp W of ICT's generic
    head): the truth is W applied to each expression, not the source's displacement copied.
    The anchor (core.ANCHOR: long waves of the motion from the source) beats Song's energy
    alone there, and a negative weight is refused."""
    from mimica.data import ICT_LANDMARKS_68
    from mimica.errors import MimicaError
    from mimica.transfer import TransferSettings
    S = head_model.mesh
    lm = S.vertices[ICT_LANDMARKS_68]
    centre, width = lm[48:68].mean(0), np.linalg.norm(lm[16] - lm[0])

    def warp(p):
        d = p - centre
        return p + 0.35 * d * np.exp(-(np.linalg.norm(d, axis=-1, keepdims=True) / (0.3 * width)) ** 2)
    frames = np.stack([head_model.neutral + head_model.delta({a: 0.8, b: 0.6})
                       for a, b in zip(HELD_SHAPES, HELD_SHAPES[1:] + HELD_SHAPES[:1])])
    T = S.with_vertices(warp(S.vertices))
    truth = np.stack([warp(f) for f in frames])
    static = static_vertices(S.vertices, frames)
    err = {c: relative_error(ExpressionTransfer(S, T, static=static, anchor=c).apply(frames), truth, T.vertices, FACE)
           for c in (0.0, TransferSettings().anchor)}
    assert err[TransferSettings().anchor] < 0.85 * err[0.0], err
    with pytest.raises(MimicaError, match="anchor"):
        TransferSettings(anchor=-1.0)


def test_apply_on_threads_never_races(head_model):
    """Song transfer of 300 frames on 4 threads, 50 times, each on a fresh solver (the lazily
    built state of a fresh one is what raced): every result equals the one-thread result."""
    S, _ = skin_patch(head_model, 3.0)
    rng = np.random.default_rng(0)
    moving = np.linalg.norm(S.vertices - S.vertices.mean(0), axis=1) < 1.5     # the rest is static
    frames = S.vertices + rng.normal(0, 0.01, (300, S.n_vertices, 3)) * moving[None, :, None]
    static = static_vertices(S.vertices, frames)
    assert 0 < static.sum() < S.n_vertices
    T = S.with_vertices(S.vertices * 1.1)
    ref = ExpressionTransfer(S, T, static=static).apply(frames, workers=1)
    for _ in range(50):
        out = ExpressionTransfer(S, T, static=static).apply(frames, batch=8, workers=4)
        assert np.array_equal(out, ref)
