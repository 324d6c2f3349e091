"""Benchmark: the 52 ARKit shapes on heads of other topologies, against ICT-FaceKit's
own sculpted shapes on its own head, measured in the same run.

Run from the project root:  .venv/bin/python bench/real_heads.py
Heads: the shared real head (real-heads/mediapipe-canonical: 468 vertices, eyes and lips
sealed) and heads made here from held-out ICT identities, where the truth is known: remeshed
with holes at eyes and mouth; remeshed with the lips sealed; eyes closed (ICT's blinks in the
neutral) with lids and lips sealed; and ICT's whole mesh (teeth, eyeballs, lashes) with its
vertices shuffled, for the rigid parts.  Figures (the issue's):

- blink: how far eyeBlinkLeft/Right close the lids, 1 - lid gap / rest gap (iBUG pairs 37-41,
  38-40, 43-47, 44-46), on open-eyed heads; ICT's own 0.865 (target >= 0.78)
- jaw: inner-lip gap (62-66) over nose-bridge-to-chin height (27-8) in jawOpen; ICT's own
  0.296 (target >= 0.18)
- damaged shapes: shapes whose share of triangles turned past 90 degrees, or of edges
  stretched past 2.5x or shrunk under 0.4x, exceeds max(0.5%, 1.5x) ICT's own shape's share
- rigid residual: teeth and eyeballs, distance from their best rigid motion / their size
- pocket_err_worst: on the same mesh and on the whole meshes of two ICT identities (other head
  shapes, bags and sockets; shuffled, no material names), the mouth bag and eye sockets (joined
  to the lips and lids) against ICT's own sculpted ones: the worst ARKit shape's median distance
  over the pocket's size, the worse pocket and head
- riders_err_worst: the same heads' lashes and tear and occlusion shells, riding the lids,
  against ICT's own: the worst ARKit shape's 95th percentile of the distance over an eye
  socket's size
- rel_err_remeshed: bench/transfer.py's remeshed figure (held-out identity, 12k vertices)
- watertight_jaw_min: jaw (as above) on heads that are one closed surface (held-out identities
  remeshed, lips and lids sealed, nostrils and the back capped: tools/hard_heads.py), and the
  shared real head capped the same way
- closed_eye_blink_min: blink (as above) on heads whose eyes are one surface with the lids,
  shaped open (held-out identities' heads and eyeballs remeshed together at 20k vertices, seeds
  33-35 and 43-48, 35 also watertight; the eyes' landmarks pinned as vertices at the identity's
  points); none of their seeds was used to develop the eyes' cut (13-16, 20, 24, 30, 42 and 50-55
  were; 34's fitted margin, sitting low, is what the template's turn was looked for, and 33-35's
  fit errors were read while it was tried; 47 and 48 were added fresh with it: docs/benchmarks.md)
- detected_jaw_min, detected_blink_min, detected_closed_eye_blink_min: the same heads, their
  landmarks found on renders by the core detector (what `pip install mimica` does without a
  landmark file), measured at their true landmarks
"""

from __future__ import annotations

import json
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from mimica.align import fit_similarity  # noqa: E402
from mimica.correspond.remesh import resample_face  # noqa: E402
from mimica.data import (EXPRESSIONS, ICT_FACE_AREA_FACES, ICT_FACE_AREA_VERTICES, ICT_HEAD_VERTICES,  # noqa: E402
                         ICT_LANDMARKS_68, ICTModel, data_dir)
from mimica.export import ARKIT_52, arkit_blendshapes  # noqa: E402
from mimica.export.blendshapes import ict_sources  # noqa: E402
from mimica.landmarks import Landmarks, ict_landmarks  # noqa: E402
from mimica.mesh import Mesh, read_mesh  # noqa: E402
from mimica.transfer import ExpressionTransfer, relative_error, static_vertices  # noqa: E402
from mimica.transfer.contacts import closure  # noqa: E402
sys.path.insert(0, str(ROOT / "tools"))
from hard_heads import capped, carried_landmarks, one_surface_eyes, watertight_head  # noqa: E402
import mimica  # noqa: E402
mimica.keep_memory()

def held_out(model, seed):
    rng = np.random.default_rng(1000 + seed)
    return model.identity(rng.normal(0, 0.8, 20))


def jaw_ratio(lm):
    return float(np.linalg.norm(lm[62] - lm[66]) / np.linalg.norm(lm[27] - lm[8]))


def damage(mesh: Mesh, shape: np.ndarray) -> tuple[float, float]:
    """(share of triangles turned past 90 degrees, share of edges stretched > 2.5x or < 0.4x)."""
    n0, n1 = mesh.face_normals(), mesh.face_normals(shape)
    flipped = float((np.einsum("ij,ij->i", n0, n1) < 0).mean())
    e = mesh.edges
    r = np.linalg.norm(shape[e[:, 0]] - shape[e[:, 1]], axis=1) / np.maximum(
        np.linalg.norm(mesh.vertices[e[:, 0]] - mesh.vertices[e[:, 1]], axis=1), 1e-300)
    return flipped, float(((r > 2.5) | (r < 0.4)).mean())


def ict_own(full_model):
    """ICT's own 52 shapes on its head: blink closure, jaw ratio, damage per shape."""
    head = ICTModel(ICT_HEAD_VERTICES)
    n = head.neutral
    own = {a: n + sum((head.shape(s) - n for s in ict_sources(a)), np.zeros_like(n)) for a in ARKIT_52}
    lm = lambda v: v[ICT_LANDMARKS_68]  # noqa: E731
    return {"blink": {"left": closure(lm(n), lm(own["eyeBlinkLeft"]), "left"),
                      "right": closure(lm(n), lm(own["eyeBlinkRight"]), "right")},
            "jaw": jaw_ratio(lm(own["jawOpen"])), "damage": {a: damage(head.mesh, own[a]) for a in ARKIT_52}}


def made_heads(model):
    """Heads of other topologies made from held-out identities, with their landmarks."""
    head = ICTModel(ICT_HEAD_VERTICES)
    blink = head.delta({"eyeBlink_L": 1.0, "eyeBlink_R": 1.0})
    out = []
    for name, seed, seal, closed in (("remeshed, holes", 11, (), False), ("remeshed, lips sealed", 12, ("mouth",), False),
                                     ("eyes closed, lids and lips sealed", 13, ("mouth", "eyes"), True)):
        tv = held_out(head, seed) + (blink if closed else 0)
        orig = head.mesh.with_vertices(tv)
        rs = resample_face(orig, tv[ICT_LANDMARKS_68], n_vertices=10000, seed=seed, seal=seal)
        out.append((name, rs.mesh, carried_landmarks(rs, orig), not closed))
    return out


def shared_head():
    d = data_dir() / "real-heads" / "mediapipe-canonical"
    mesh = read_mesh(d / "head.obj")
    info = json.loads((d / "head.json").read_text())
    return ("shared real head (mediapipe, sealed)", mesh,
            Landmarks.from_vertex_indices(mesh, info["landmark_vertices"]), bool(info.get("eyes_open")))


def rel_err_remeshed(model):
    """bench/transfer.py's remeshed figure: held-out identity 7 on 12k vertices, six expressions."""
    S = model.mesh
    ls = ict_landmarks(S)
    basic = np.stack([model.neutral + model.delta(EXPRESSIONS[e]) for e in EXPRESSIONS])
    tv = held_out(model, 7)
    face, _ = S.with_vertices(tv).submesh(np.arange(ICT_FACE_AREA_FACES))
    rs = resample_face(face, tv[ICT_LANDMARKS_68], n_vertices=12000, seed=7)
    lt = Landmarks.snap(rs.mesh, tv[ICT_LANDMARKS_68])
    xr = ExpressionTransfer(S, rs.mesh, ls, lt, method="vtc", static=static_vertices(S.vertices, basic))
    face_v = slice(0, ICT_FACE_AREA_VERTICES)
    return float(np.mean([relative_error(o, rs.carry(tv[face_v] + b[face_v] - S.vertices[face_v]), rs.mesh.vertices)
                          for o, b in zip(xr.apply(basic), basic)]))


def rigid_residual(full_model):
    """The whole ICT mesh as a head of another topology (vertices shuffled): rigid parts."""
    full = full_model.mesh
    perm = np.random.default_rng(7).permutation(full.n_vertices)
    inv = np.argsort(perm)
    m = Mesh(full.vertices[perm], inv[full.face_indices], full.face_starts, groups=full.groups,
             group_names=full.group_names)
    lt = Landmarks.snap(m, m.vertices[inv[ICT_LANDMARKS_68]])
    shapes = arkit_blendshapes(m, lt)
    parts = shapes.transfer.parts[1]
    worst = 0.0
    shared = parts.jaw_weight if parts.jaw_weight is not None else np.full(len(parts.role), np.nan)
    rigid = ~((shared > 0) & (shared < 1))          # gums and tongue as one piece take a share of the jaw
    for role in ("jaw", "skull", "eye.left", "eye.right"):
        v = np.intersect1d(parts.of(role), np.nonzero(rigid)[0])
        size = float(np.ptp(m.vertices[v]))
        for a in ARKIT_52:
            fit = fit_similarity(m.vertices[v], shapes[a][v], scale=False)
            worst = max(worst, float(np.abs(fit.apply(m.vertices[v]) - shapes[a][v]).max()) / size)
    return worst, parts.summary(), bag_error(full_model, m, perm, shapes)


HELD_OUT_WHOLE = ("identity012", "identity017")       # whole meshes of other head shapes


def held_out_pockets(full_model, identity: str) -> dict:
    """bag_error on a held-out ICT identity's whole mesh (its own head shape, bag, sockets and
    lashes; vertices shuffled, no material names), the truth ICT's linear model: the identity plus
    each shape's offsets."""
    full = full_model.mesh
    idv = full_model.identity(identity)
    perm = np.random.default_rng(7).permutation(full.n_vertices)
    inv = np.argsort(perm)
    m = Mesh(idv[perm], inv[full.face_indices], full.face_starts)
    shapes = arkit_blendshapes(m, Landmarks.snap(m, m.vertices[inv[ICT_LANDMARKS_68]]))
    return bag_error(full_model, m, perm, shapes, idv)


def bag_error(full_model, m, perm, shapes, identity=None) -> dict:
    """The pockets of ICT's whole mesh as a head of another topology (its mouth bag and eye
    sockets, joined to the lips and lids) against ICT's own sculpted ones: per ARKit shape the
    median distance over the pocket's size; and its lashes and shells riding the lids: per shape
    the 95th percentile of their distance over a socket's size.  {set: (median shape's, worst
    shape's)} for ours and, in the same run, the baselines: the pockets transferred as skin, as
    before they were found (their finding switched off here); each rider on the skin nearest it
    (no root's turn)."""
    from mimica.correspond import parts as parts_module
    from mimica.transfer import parts as motion_module
    neutral = full_model.neutral[perm]
    rest = neutral if identity is None else np.asarray(identity)[perm]
    sets = {"mouth bag": (np.nonzero((perm >= 11248) & (perm < 13294))[0], 50),
            "eye sockets": (np.nonzero((perm >= 13294) & (perm < 14062))[0], 50),
            "lashes and shells": (np.nonzero(perm >= 24591)[0], 95)}
    socket = float(np.ptp(rest[np.argsort(perm)[13294:13294 + 384]], axis=0).max())      # one eye's

    def errors(sh, names):
        out = {}
        for name in names:
            v, q = sets[name]
            size = socket if q == 95 else float(np.ptp(rest[v], axis=0).max())
            e = []
            for a in ARKIT_52:
                truth = rest[v] + sum((full_model.shape(n)[perm][v] - neutral[v] for n in ict_sources(a)),
                                      np.zeros((len(v), 3)))
                e.append(np.percentile(np.linalg.norm(sh[a][v] - truth, axis=1), q) / size)
            out[name] = (float(np.median(e)), float(np.max(e)))
        return out

    lm = Landmarks.snap(m, m.vertices[np.argsort(perm)[ICT_LANDMARKS_68]])
    ours = errors(shapes, sets)
    found, root = parts_module.pockets, motion_module.ROOT
    parts_module.pockets = lambda *a: {}
    try:
        base = errors(arkit_blendshapes(m, lm), ["mouth bag", "eye sockets"])
    finally:
        parts_module.pockets = found
    motion_module.ROOT = np.inf
    try:
        base.update(errors(arkit_blendshapes(m, lm), ["lashes and shells"]))
    finally:
        motion_module.ROOT = root
    return {"ours": ours, "baseline": base}


def main():
    print(f"machine: {platform.machine()}, {platform.system()}, python {platform.python_version()}")
    model = ICTModel(ICT_HEAD_VERTICES)
    full_model = ICTModel()
    own = ict_own(full_model)
    print(f"ICT's own shapes on its head: blink closure left {own['blink']['left']:.3f} right "
          f"{own['blink']['right']:.3f}, jaw ratio {own['jaw']:.3f}")
    blinks, jaws, damaged = [], [], 0
    heads = [shared_head()] + made_heads(model)
    for name, mesh, lm, eyes_open in heads:
        t = time.perf_counter()
        shapes = arkit_blendshapes(mesh, lm)
        el = time.perf_counter() - t
        out_mesh = shapes.mesh                     # the head, its lips cut apart where they were sealed
        rest = lm.positions(mesh)
        pos = {a: lm.positions(out_mesh, shapes[a]) for a in ("eyeBlinkLeft", "eyeBlinkRight", "jawOpen")}
        jaw = jaw_ratio(pos["jawOpen"])
        jaws.append(jaw)
        cut = f", lips cut ({out_mesh.n_vertices - mesh.n_vertices} vertices added)" if shapes.mouth is not None else ""
        line = f"[{name}] {mesh.n_vertices} vertices{cut}, {el:.1f}s: jaw ratio {jaw:.3f} (ICT {own['jaw']:.3f})"
        if eyes_open:
            bl = closure(rest, pos["eyeBlinkLeft"], "left")
            br = closure(rest, pos["eyeBlinkRight"], "right")
            blinks += [bl, br]
            line += f", blink closure left {bl:.3f} right {br:.3f} (ICT {own['blink']['left']:.3f})"
        bad = []
        for a in ARKIT_52:
            f, s = damage(out_mesh, shapes[a])
            of, os_ = own["damage"][a]
            if f > max(0.005, 1.5 * of) or s > max(0.005, 1.5 * os_):
                bad.append(f"{a} ({100 * f:.1f}% turned, {100 * s:.1f}% edges)")
        damaged += len(bad)
        print(line + f"; damaged shapes {len(bad)}" + (": " + ", ".join(bad[:6]) + (" ..." if len(bad) > 6 else "")
                                                       if bad else ""))
    # one closed surface; eyes that are one surface with the lids
    wt_jaws, ce_blinks = [], []
    sh = shared_head()
    wt_shared = capped(sh[1])
    hard = [("watertight, seed 31", *watertight_head(31)[:2], False),
            ("watertight, seed 32", *watertight_head(32)[:2], False),
            ("shared real head, capped", wt_shared, Landmarks(sh[2].triangle, sh[2].bary), False),
            ("one-surface eyes, seed 33", *one_surface_eyes(33)[:2], True),
            ("one-surface eyes, seed 34", *one_surface_eyes(34)[:2], True),
            ("one-surface eyes, watertight, seed 35", *one_surface_eyes(35, watertight=True)[:2], True),
            ("one-surface eyes, seed 43", *one_surface_eyes(43)[:2], True),
            ("one-surface eyes, seed 44", *one_surface_eyes(44)[:2], True),
            ("one-surface eyes, seed 45", *one_surface_eyes(45)[:2], True),
            ("one-surface eyes, seed 46", *one_surface_eyes(46)[:2], True),
            ("one-surface eyes, seed 47", *one_surface_eyes(47)[:2], True),
            ("one-surface eyes, seed 48", *one_surface_eyes(48)[:2], True)]
    for name, mesh, lm, eyes in hard:
        t = time.perf_counter()
        shapes = arkit_blendshapes(mesh, lm)
        el = time.perf_counter() - t
        out_mesh = shapes.mesh
        rest = lm.positions(mesh)
        pos = {a: lm.positions(out_mesh, shapes[a]) for a in ("eyeBlinkLeft", "eyeBlinkRight", "jawOpen")}
        jaw = jaw_ratio(pos["jawOpen"])
        line = f"[{name}] {mesh.n_vertices} vertices, {el:.1f}s: jaw ratio {jaw:.3f}"
        if eyes:
            bl, br = closure(rest, pos["eyeBlinkLeft"], "left"), closure(rest, pos["eyeBlinkRight"], "right")
            ce_blinks += [bl, br]
            cut = shapes.transfer.eye_cut
            line += (f", blink closure left {bl:.3f} right {br:.3f} (eyes cut loose: "
                     f"{', '.join(cut.eyes) if cut is not None else 'none'})")
        else:
            wt_jaws.append(jaw)
        bad = []
        for a in ARKIT_52:
            f, s = damage(out_mesh, shapes[a])
            of, os_ = own["damage"][a]
            if f > max(0.005, 1.5 * of) or s > max(0.005, 1.5 * os_):
                bad.append(a)
        damaged += len(bad)
        print(line + f"; damaged shapes {len(bad)}" + (": " + ", ".join(bad[:6]) if bad else ""))
    # the same heads with their landmarks found on renders (the core detector), as `mimica
    # blendshapes HEAD` without a landmark file; measured at the heads' true landmarks
    det_jaws, det_blinks, det_ce = [], [], []
    for name, mesh, lm, eyes in heads + hard:
        shapes = arkit_blendshapes(mesh, None)
        rest = lm.positions(mesh)
        pos = {a: lm.positions(shapes.mesh, shapes[a]) for a in ("eyeBlinkLeft", "eyeBlinkRight", "jawOpen")}
        det_jaws.append(jaw_ratio(pos["jawOpen"]))
        line = f"[{name}, landmarks detected] jaw ratio {det_jaws[-1]:.3f}"
        if eyes:
            b = [closure(rest, pos["eyeBlinkLeft"], "left"), closure(rest, pos["eyeBlinkRight"], "right")]
            (det_ce if shapes.transfer.eye_cut is not None or "one-surface" in name else det_blinks).extend(b)
            line += f", blink closure left {b[0]:.3f} right {b[1]:.3f}"
        print(line)
    big = heads[1][1]
    detect_s = np.inf
    for _ in range(3):                              # best of 3, landmark detection included
        t = time.perf_counter()
        arkit_blendshapes(big, None)
        detect_s = min(detect_s, time.perf_counter() - t)
    print(f"blendshapes on a {big.n_vertices}-vertex head, landmarks detected: {detect_s:.1f}s (best of 3)")
    rigid, parts, pockets = rigid_residual(full_model)
    print(f"whole ICT mesh, shuffled (parts: {parts}): rigid residual {rigid:.1e} of the part's size")
    for name, (med, worst) in pockets["ours"].items():
        b = pockets["baseline"][name]
        how = ("95th percentile of the distance / a socket's size", "each on the skin nearest it") \
            if name == "lashes and shells" else ("median distance / the pocket's size", "transferred as skin")
        print(f"its {name} against ICT's own, {how[0]}: median shape {med:.4f}, worst {worst:.4f} "
              f"(baseline, {how[1]}: {b[0]:.4f}, {b[1]:.4f})")
    for ident in HELD_OUT_WHOLE:
        held = held_out_pockets(full_model, ident)
        print(f"{ident}'s whole mesh (held out, shuffled, no material names), worst shape, ours / baseline: "
              + ", ".join(f"{k} {held['ours'][k][1]:.4f} / {held['baseline'][k][1]:.4f}" for k in held["ours"]))
        for k in held["ours"]:
            pockets["ours"][k] = (pockets["ours"][k][0], max(pockets["ours"][k][1], held["ours"][k][1]))
    pocket_worst = max(pockets["ours"][k][1] for k in ("mouth bag", "eye sockets"))
    riders_worst = pockets["ours"]["lashes and shells"][1]
    rel = rel_err_remeshed(model)
    print(f"blink_min={min(blinks):.3f} jaw_min={min(jaws):.3f} damaged_shapes={damaged} "
          f"rigid_residual={rigid:.1e} rel_err_remeshed={rel:.4f} watertight_jaw_min={min(wt_jaws):.3f} "
          f"closed_eye_blink_min={min(ce_blinks):.3f} detected_jaw_min={min(det_jaws):.3f} "
          f"detected_blink_min={min(det_blinks):.3f} detected_closed_eye_blink_min={min(det_ce):.4f} "
          f"pocket_err_worst={pocket_worst:.4f} riders_err_worst={riders_worst:.4f}")


if __name__ == "__main__":
    main()
