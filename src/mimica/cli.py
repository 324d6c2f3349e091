"""The `mimica` command line.  User errors print one line and exit 2; nothing half-written."""

from __future__ import annotations

import argparse
import contextlib
import sys
import time
from pathlib import Path

import numpy as np

from .errors import MimicaError


def _progress(iterable, total=None, desc=""):
    from tqdm import tqdm
    return tqdm(iterable, total=total, desc=desc, disable=not sys.stderr.isatty(), leave=False,
                unit="frame")


@contextlib.contextmanager
def _muscle_bar(desc):
    """A progress bar over the muscles' systems: yields progress(k, n, name)."""
    bar = _progress(range(1), 1, desc)

    def progress(k, n, name):
        bar.total = n
        bar.set_postfix_str(name)
        bar.update(1 if k else 0)
    try:
        yield progress
    finally:
        bar.close()


def _landmarks(mesh, path, flag, what):
    """A face's landmarks (landmarks_for); where none are found, the flag that gives them."""
    from .landmarks import landmarks_for
    from .errors import NeedsLandmarks
    try:
        return landmarks_for(mesh, path, what)
    except NeedsLandmarks as e:
        raise MimicaError(f"{e}; pass it with {flag} FILE") from None


QUANTIZE_HELP = ("glTF: morph targets as 16-bit moves and 8-bit normal changes (KHR_mesh_quantization, "
                 "within 0.015 mm; about half the size; the viewer must know the extension: three.js, "
                 "Blender and Babylon.js do)")
UNITS_HELP = ("the unit of the input's coordinates; glTF files are in metres (auto: a head up to 3 units "
              "tall is in metres, up to 100 in cm, taller in mm)")
MATCH_HELP = ("across topologies, how target vertices find their source partners: nicp, a non-rigid "
              "registration of the source onto the target (default); cylinder, Song et al.'s cylinder map")


DETECTOR_HELP = ("photos: the 68 points' detector: mediapipe (default: MediaPipe's face mesh at 68 of its points) "
                 "or dlib (its 68-point predictor); compared in docs/benchmarks.md")
FILE_FORMATS = ("glb", "gltf", "usd", "usda", "usdc")     # --format naming one file's kind


def _clip_how(info: dict) -> str:
    """'120 frames as 9 basis shapes and their weights (largest error ...)'."""
    n = info["frames"]
    if info["basis"]:
        how = (f"{n} frames as {info['shapes']} basis {'blend ' if 'unit' in info else ''}shapes and their weights "
               f"(largest error {info['max_error_m'] * 1e3:.3f} mm, bound 0.1 mm)")
    else:
        how = f"{n} frames as " + ("blend shapes" if "unit" in info else "morph targets" + (
            " (no smaller basis within 0.1 mm)" if info.get("compact") else ""))
    return how


def _clip_line(info: dict, fps: float, units: str) -> str:
    """What export.clip.write_clip / write_clip_usd wrote, in one line."""
    how = _clip_how(info)
    if "unit" in info:                                 # USD
        return (f"{how}, a SkelAnimation at {fps:g} fps; units: {info['unit']} (metersPerUnit "
                f"{info['metres_per_unit']:g}, y up); {info['bytes'] / 1e6:.1f} MB")
    return (f"{how}, one animation at {fps:g} fps; " + _units_line(info["height"], info["units"], units) + "; "
            + _quantized_line(info) + f"{info['bytes'] / 1e6:.1f} MB")


def _floats(text: str, n: int, flag: str) -> list[float]:
    """'0,1.5,-0.1' -> [0.0, 1.5, -0.1]: n finite numbers, or a MimicaError naming the flag."""
    try:
        vals = [float(x) for x in text.split(",")]
    except ValueError:
        vals = []
    if len(vals) != n or not np.isfinite(vals).all():
        raise MimicaError(f"{flag} {text!r}: expected {n} finite numbers separated by commas")
    return vals


def _sparse_line(path, info: dict, n: int) -> str:
    """'34 of 52 morph targets sparse (moves under 0.01 mm left out), 4.2 MB'."""
    from .mesh.io import SPARSE_TOLERANCE
    return (f"{info['sparse']} of {n} morph targets sparse (moves under {SPARSE_TOLERANCE * 1e3:g} mm left out), "
            + _quantized_line(info) + f"{Path(path).stat().st_size / 1e6:.1f} MB")


def _quantized_line(info: dict) -> str:
    """'52 quantized (KHR_mesh_quantization, moves within 0.015 mm), ' or nothing."""
    from .mesh.io import QUANTIZATION, QUANTIZE_ERROR
    return (f"{info['quantized']} quantized ({QUANTIZATION}, moves within {QUANTIZE_ERROR * 1e3:.3f} mm), "
            if info.get("quantized") else "")


def _units_line(height: float, unit: str, asked: str) -> str:
    """'units: cm (the head is 33.4 units tall; --units to say otherwise), written in metres'."""
    how = (f"the head is {height:.3g} units tall; --units to say otherwise"
           if asked == "auto" else "as --units says")
    return f"units: {unit} ({how}), written in metres as glTF wants"


def _head_options(p, what: str) -> None:
    """--show, --match, --cut-mouth and --cut-eyes, the same on transfer and blendshapes."""
    p.add_argument("--show", help=f"PNG: the {what} as the transfer sees it (parts, unmatched skin, the mouth "
                                  "seam, the paired lid rims, the correspondence's confidence)")
    p.add_argument("--match", choices=["nicp", "cylinder"], default="nicp", help=MATCH_HELP)
    p.add_argument("--cut-mouth", choices=["auto", "off"], default="auto",
                   help=f"auto: a {what} whose lips are sealed has them cut apart, so the mouth (jawOpen) can "
                        "open (its vertices keep their order; the cut's copies come after them)")
    p.add_argument("--cut-eyes", choices=["auto", "off"], default="auto",
                   help=f"auto: a {what} whose eyes are one surface with the lids has each eye cut loose along "
                        "the lid margin, so the lids close over it (eyeBlink); copies come after the mouth's")


def _correspondence_line(xfer) -> str:
    """'; correspondence (nicp): 99.8% of the target's skin matched, 2.1% with low confidence'."""
    if xfer.relaid:
        return "; the target is the source's own mesh in another vertex layout (found by its uv): solved on its topology"
    cor = xfer.correspondence                  # the skin's, when the heads have parts
    if cor is None:
        return ""
    line = f"; correspondence ({xfer.match}): {100 * cor.matched.mean():.1f}% of the target's skin matched"
    if cor.confidence is not None:
        low = cor.matched & (cor.confidence < cor.LOW)
        line += f", {100 * low.mean():.1f}% with low confidence (< {cor.LOW}; --show draws where)"
    if xfer.paired_eyes:
        line += f"; lid rims paired by arc length: {' and '.join(xfer.paired_eyes)} eye"
    return line


def _say_uncut_mouth(xfer, what, landmarks_flag: str) -> None:
    """One line where sealed lips were left sealed: why, and what to do."""
    if xfer.mouth_uncut is not None:
        _say(f"{what}: the lips are sealed and stay so: {xfer.mouth_uncut.why}; give the head's 68 landmarks "
             f"({landmarks_flag}) so that the mouth's corners and lips are where they are, or say --cut-mouth off "
             "(--show draws where the seam was looked for)")


def _warn_sealed_eyes(xfer, mesh, lm, what, found_flag=None):
    """One line on eyes that are one surface with the lids: cut open, or why not (blinks then
    move the lids over them); found_flag: the option that gives landmarks, where none were
    given (on a head not of ICT-FaceKit's topology they were then found on renders)."""
    from .data import is_ict_topology
    if found_flag and is_ict_topology(mesh):
        found_flag = None
    if xfer.eye_cut is not None:
        ec = xfer.eye_cut
        _say(f"{what}: the {' and '.join(ec.eyes)} eye{'s were' if len(ec.eyes) > 1 else ' was'} one surface with "
             f"the lids: cut loose along the lid margins, {len(ec.copies_of)} vertices added after the others "
             "(--cut-eyes off to keep them whole)")
        if found_flag:
            _say(f"note: {what}: the eyes were cut where the landmarks found on its renders put them, and a render "
                 "barely shows the lids of an eye that is one surface with them (on made heads the points sat "
                 f"0.1-0.25 of the eye's width above the margin and blinks failed): look with --show, and give the "
                 f"head's 68 landmarks ({found_flag}) if the cut is not at the lids' margin")
    if xfer.eyes_uncut:
        whys = "; ".join(dict.fromkeys(xfer.eyes_uncut.values()))
        sides = " and ".join(xfer.eyes_uncut)
        _say(f"note: {what}: the {sides} eye{'s stay' if len(xfer.eyes_uncut) > 1 else ' stays'} one surface with "
             f"the lids ({whys}); blinks move the lids over {'them' if len(xfer.eyes_uncut) > 1 else 'it'}")
    if lm is None or xfer.eye_cut is not None or xfer.eyes_uncut:
        return
    from .correspond.mouth import sealed_eyes
    shut = sealed_eyes(mesh, lm.positions(mesh))
    if shut:
        _say(f"note: {what}: the {' and '.join(shut)} eye{'s are' if len(shut) > 1 else ' is'} one closed "
             "surface; lids move over it, they do not open or close")


def _read_head(path):
    """read_mesh, and the lines a file of another tool has to say (gltf.GltfLayout.notes)."""
    from .mesh import read_mesh
    mesh = read_mesh(path)
    for n in (mesh.layout.notes if mesh.layout is not None else []):
        _say(f"{path}: {n}")
    return mesh


def _say(msg):
    print(msg, file=sys.stderr)


def _expand_frames(items):
    from .mesh.io import sequence_files
    out = []
    for it in items:
        p = Path(it)
        if p.is_dir():
            files, other = sequence_files(p)
            if other:                                  # said: a previous run's animation.glb ...
                _say(f"{p}: its {len(files)} {files[0].suffix.lower()} files are the frames; left out "
                     + (", ".join(other[:3]) + (f" and {len(other) - 3} more" if len(other) > 3 else "")))
            out += files
        else:
            out.append(p)
    return out


def cmd_transfer(a):
    from .errors import NeedsLandmarks
    from .mesh.io import GltfLayout
    from .pipeline import TransferOptions, transfer_sequence
    opts = TransferOptions(method=a.method, match=a.match, cut_mouth=a.cut_mouth == "auto",
                           cut_eyes=a.cut_eyes == "auto")
    try:
        r = transfer_sequence(a.source_neutral, _expand_frames(a.source_expr), a.target, a.out, opts,
                              a.source_landmarks, a.target_landmarks, progress=_say)
    except NeedsLandmarks as e:
        raise MimicaError(f"{e}; pass it with --{e.which}-landmarks FILE") from None
    xfer, sec, n = r.transfer, r.seconds, len(r.files)
    if xfer.mouth is not None:
        _say(f"{a.target}: the lips were sealed; cut apart along {len(xfer.mouth.seam)} vertices, "
             f"{len(xfer.mouth.copies_of)} added after the target's own (--cut-mouth off to keep them sealed)")
    _say_uncut_mouth(xfer, a.target, "--target-landmarks")
    _warn_sealed_eyes(xfer, r.target, r.target_landmarks, a.target,
                      found_flag="--target-landmarks" if r.target_landmarks_found else None)
    rep = xfer.basis_report
    if rep["used"]:
        _say(f"{n} frames through a basis of their motion ({rep['deviation']:.1e} of the motion off on "
             f"{rep['checked']} frames solved one by one)")
    elif "why" in rep and rep["why"] != "frame by frame":
        _say(f"{n} frames one by one: {rep['why']}")
    if isinstance(r.target.layout, GltfLayout):
        _say(f"results written as {Path(a.target).name} with the expression: its nodes, materials and vertex "
             f"layout ({Path(a.target).suffix.lower()})")
    if a.show:                                         # after the results: a failed run leaves none
        from .render import save_png
        from .render.diagnose import transfer_picture
        save_png(a.show, transfer_picture(xfer, f"{Path(a.target).name} as the transfer sees it"))
        _say(f"picture -> {a.show}")
    _say(f"aligned target to source: residual {100 * xfer.alignment_residual:.2f}% of the face size"
         + _correspondence_line(xfer))
    if xfer.parts is not None:
        _say(f"parts: source {xfer.parts[0].summary()}; target {xfer.parts[1].summary()} (skin to skin; "
             "eyeballs and teeth rigid, lashes and shells with the skin)")
    _say(f"{n} expression(s) -> {r.out}/ ({a.method}; read {sec['read']:.2f}s, precompute {sec['precompute']:.2f}s, "
         f"transfer {sec['transfer']:.2f}s = {n / max(sec['transfer'], 1e-9):.0f} frames/s)")
    return 0


def cmd_error(a):
    from .mesh import read_mesh
    from .render.errormap import error_map_png
    from .transfer import relative_error, song_vertex_error

    res = read_mesh(a.result, allow_degenerate=True)
    ref = read_mesh(a.reference, allow_degenerate=True)
    ref_n = read_mesh(a.reference_neutral, allow_degenerate=True)
    res_n = read_mesh(a.result_neutral, allow_degenerate=True) if a.result_neutral else ref_n
    for m, p in ((ref, a.reference), (ref_n, a.reference_neutral), (res_n, a.result_neutral or a.reference_neutral)):
        if m.n_vertices != res.n_vertices:
            raise MimicaError(f"{p}: has {m.n_vertices} vertices, the result has {res.n_vertices}; "
                              "the error needs meshes of one topology")
    region = None
    if a.region:
        try:
            lo, hi = (int(x) for x in a.region.split(":"))
        except ValueError:
            lo = hi = -1
        if not 0 <= lo < hi <= res.n_vertices:
            raise MimicaError(f"--region {a.region!r}: expected LO:HI vertex indices with 0 <= LO < HI <= "
                              f"{res.n_vertices}, e.g. 0:9409")
        region = slice(lo, hi)
    try:
        bins = tuple(float(x) / 100 for x in a.bins.split(","))
    except ValueError:
        bins = ()
    if len(bins) != 3 or not np.isfinite(bins).all() or min(bins) <= 0 or list(bins) != sorted(bins):
        raise MimicaError(f"--bins {a.bins!r}: expected three increasing positive percentages, e.g. 0.1,0.5,2")
    e = song_vertex_error(res.vertices, res_n.vertices, ref.vertices, ref_n.vertices)
    rel = relative_error(res.vertices, ref.vertices + (res_n.vertices - ref_n.vertices), res_n.vertices, region)
    ee = e if region is None else e[region]
    _say(f"Song per-vertex error: median {100 * np.nanmedian(ee):.2f}%, mean {100 * np.nanmean(ee):.2f}%; "
         f"relative error {rel:.4f}")
    if a.out:
        error_map_png(a.out, res, e, title=f"{Path(a.result).name} vs {Path(a.reference).name}", bins=bins)
        _say(f"error map -> {a.out}")
    return 0


def cmd_rig(a):
    from .mesh import read_mesh
    from .pipeline import RigOptions, make_rig
    t0 = time.perf_counter()
    opts = RigOptions(muscles=a.muscles, alpha=a.alpha, modes=a.modes, stretch=a.stretch)
    skin = read_mesh(a.face)
    lm = _landmarks(skin, a.landmarks, "--landmarks", str(a.face))
    with _muscle_bar("muscles") as progress:
        rig = make_rig(skin, lm, opts, out=a.out, progress=progress)
    drives = sum(m.kind == "drive" for m in rig.muscles)
    _say(f"rig: {len(rig.muscles) - drives} muscles" + (f" and {drives} drives (jaw, lids, cheeks)" if drives else "")
         + f" on {rig.skin.n_vertices} skin nodes -> {a.out} ({time.perf_counter() - t0:.1f}s)")
    return 0


def _sequence_timeline(names, activations, labels, seconds: float = 1.0):
    """A timeline playing fitted activations (T, m) one after another: each ramps in over 0.3 s,
    holds, and lets go before the next (the i-th from i x seconds)."""
    from .anim import Channel, Timeline
    ch = {}
    for j, n in enumerate(names):
        keys = []
        for i, a in enumerate(activations[:, j]):
            t0 = i * seconds
            keys += [[t0, 0.0], [t0 + 0.3 * seconds, a], [t0 + 0.8 * seconds, a], [t0 + 0.95 * seconds, 0.0]]
        if np.abs(activations[:, j]).max() > 0:
            ch[n] = Channel(np.array(keys), "linear")
    return Timeline(ch, seconds * len(activations))


def cmd_fit_muscles(a):
    from .anim import Channel, Timeline
    from .mesh import read_vertices
    from .physics.fit import MuscleFit
    from .rig import Rig
    if bool(a.target) == bool(a.arkit):
        raise MimicaError("fit-muscles: give --target EXPR.obj ... or --arkit (a take CSV/JSON or a head's ARKit GLB)")
    out = Path(a.out)
    if out.suffix.lower() != ".json":
        raise MimicaError(f"{out}: the activations are written as a timeline .json (simulate --timeline plays it)")
    rig = Rig.load(a.rig)
    n = rig.skin.n_vertices
    arkit = Path(a.arkit) if a.arkit else None
    shapes = take = None
    if a.target:
        targets = [Path(t) for t in a.target]
        shapes = []
        for t in targets:
            v = read_vertices(t)
            if len(v) != n:
                raise MimicaError(f"{t}: {len(v)} vertices; the rig's skin has {n} (a target is the rig's face, "
                                  "deformed)")
            shapes.append(v - rig.skin.vertices)
        labels = [t.stem for t in targets]
    elif arkit.suffix.lower() in (".glb", ".gltf"):
        shapes, labels = _rig_arkit_shapes(arkit, rig)
    else:
        from .export.take import read_take
        times, weights, rate = read_take(arkit, fps=a.fps)
        take = (times, weights, rate)
        if a.shapes:
            shapes, labels = _rig_arkit_shapes(Path(a.shapes), rig)
        else:
            from .export import ARKIT_52, arkit_blendshapes
            _say(f"the ARKit shapes of {a.rig}'s face (once; --shapes HEAD_ARKIT.glb gives them)")
            bs = arkit_blendshapes(rig.skin, progress=_say, cut_mouth=False)
            shapes, labels = [bs[k][:n] - rig.skin.vertices for k in ARKIT_52], list(ARKIT_52)
    t0 = time.perf_counter()
    mf = MuscleFit.of_rig(rig)
    t1 = time.perf_counter()
    if take is None:
        act, mis = mf.fit(np.stack(shapes))
        el = time.perf_counter() - t1
        tl = _sequence_timeline(mf.names, act, labels)
        what = (f"{len(labels)} target{'s' * (len(labels) > 1)} one after another, 1 s each ("
                + ", ".join(f"{lab} {m:.0%}" for lab, m in list(zip(labels, mis))[:6])
                + (" ..." if len(labels) > 6 else "") + " misfit)")
    else:
        times, weights, rate = take
        W = np.stack([weights.get(k, np.zeros(len(times))) for k in labels], 1)
        act, mis = mf.fit_combinations(np.stack(shapes), W)
        el = time.perf_counter() - t1
        tl = Timeline({nm: Channel(np.stack([times, act[:, j]], 1), "linear") for j, nm in enumerate(mf.names)
                       if np.abs(act[:, j]).max() > 0}, float(times[-1]) if times[-1] > 0 else 1.0)
        what = f"a take of {len(times)} frames ({rate:.3g} fps), median misfit {np.median(mis):.0%}"
    tl.save(out)
    _say(f"{out}: {len(mf.names)} muscles fitted to {what}; fields {t1 - t0:.1f}s, fit "
         f"{len(act) / max(el, 1e-9):.0f} frames/s; `simulate {a.rig} --timeline {out}` plays it")
    return 0


def _rig_arkit_shapes(path: Path, rig):
    """The ARKit shapes' displacements on the rig's skin, from a head's ARKit GLB of that face."""
    from .export import ARKIT_52
    from .mesh.io import read_morph_targets
    mesh, targets, _ = read_morph_targets(path)
    n = rig.skin.n_vertices
    if mesh.n_vertices < n or np.abs(mesh.vertices[:n] - rig.skin.vertices).max() > 1e-4 * np.ptp(rig.skin.vertices):
        raise MimicaError(f"{path}: not the ARKit shapes of this rig's face (make them with `blendshapes` of the "
                          "face the rig was made from)")
    labels = [k for k in ARKIT_52 if k in targets]
    return [targets[k][:n] - rig.skin.vertices for k in labels], labels


def cmd_simulate(a):
    from .pipeline import SimulateOptions, simulate
    opts = SimulateOptions(expression=a.expression, timeline=a.timeline, action=a.action, duration=a.duration,
                           fps=a.fps, gravity=a.gravity, pulls=tuple(_parse_pull(p) for p in a.pull or []),
                           engine=a.engine, solver=a.solver, warp=a.warp, springs=a.springs, wrinkles=a.wrinkles,
                           age=a.age, refine=not a.no_refine, maps=a.maps, maps_set=a.maps_set)
    if a.maps and not a.wrinkles:
        raise MimicaError("--maps: the maps are the wrinkles'; give the wrinkle mask (--wrinkles MASK)")
    bar = _progress(range(1), None, "simulating")
    r = simulate(a.rig, a.out, opts, progress=lambda f, n: (setattr(bar, "total", n), bar.update(1)))
    bar.close()
    out = r.out
    note = ""
    if r.wrinkles is not None:
        w = r.wrinkles
        most = np.argsort(w["compression"])[:3]
        maps = {"engine": f"; engine maps of {w['regions']} regions (normal, displacement, mask, per-frame weights) "
                          f"-> {out}/wrinkle_maps/",
                "frames": f"; maps of every frame -> {out}/wrinkles_frame_*",
                "peak": f"; maps of that frame -> {out}/wrinkles_frame_{w['peak']:04d}_*", None: ""}[w["maps"]]
        note += (f"; wrinkles: {len(w['names'])} on {w['nodes']} nodes (built in {w['build_s']:.1f}s), "
                 f"{1000 * w['frame_s']:.2f} ms/frame; most compressed at t={w['peak'] / a.fps:.2f}s: "
                 + ", ".join(f"{w['names'][i]} {w['compression'][i]:.2f}" for i in most) + maps)
    note += "; animation.glb: " + _clip_how(r.clip)
    if r.newton is not None:
        st = r.newton
        note += f"; Newton: {st['iterations'] / max(st['steps'], 1):.1f} iterations a step"
        if st["unconverged"]:
            note += f", {st['unconverged']} steps stopped at the iteration cap"
    _say(f"{r.frames} frames -> {out}/ (frame_*.obj, animation.glb, strip.png); {r.steps} steps in {r.seconds:.2f}s"
         + note)
    return 0


def cmd_wrinkle_mask(a):
    from .wrinkles import mask_for
    from .mesh import read_mesh
    face = read_mesh(a.face)
    lm = _landmarks(face, a.landmarks, "--landmarks", str(a.face)).positions(face)
    mask, how = mask_for(face, lm, a.anchors, a.reference)
    mask.face = Path(a.face).name
    if a.show:
        from .render import contact_sheet, save_png
        from .wrinkles.show import mask_image
        save_png(a.show, contact_sheet([mask_image(face, mask, size=560), mask_image(face, mask, size=560, yaw=35)],
                                       title=f"wrinkle mask on {Path(a.face).name}"))
    mask.save(a.out)
    _say(f"{len(mask)} wrinkles -> {a.out} ({how})" + (f"; picture -> {a.show}" if a.show else ""))
    return 0


def cmd_age(a):
    from .mesh import read_mesh
    from .pipeline import AgeOptions, age_sheet
    try:
        ages = tuple(float(x) for x in a.ages.split(","))
    except ValueError:
        ages = ()
    if not ages or not all(0 <= x <= 150 for x in ages):                 # NaN fails too
        raise MimicaError(f"--ages {a.ages!r}: expected ages in years from 0 to 150, e.g. 25,45,65,85")
    if not str(a.out).lower().endswith(".png"):
        raise MimicaError(f"--out {a.out}: the age sheet is a PNG picture; name it *.png")
    from .anim import PRESETS
    if a.expression not in PRESETS:
        raise MimicaError(f"--expression {a.expression!r}: one of {', '.join(PRESETS)}")
    face = read_mesh(a.face)
    lm = _landmarks(face, a.landmarks, "--landmarks", str(a.face))
    t0 = time.perf_counter()
    opts = AgeOptions(ages=ages, expression=a.expression, size=a.size, rig=a.rig, wrinkles=a.wrinkles)
    with _muscle_bar("rig (all muscles)") as progress:
        n = age_sheet(face, a.out, lm, opts, progress=progress)
    _say(f"{n} renders -> {a.out} ({time.perf_counter() - t0:.1f}s)")
    return 0


def _parse_pull(spec):
    """'x,y,z:radius:fx,fy,fz' -> (center (3,), radius, force (3,))."""
    try:
        c, r, f = spec.split(":")
        center = np.array([float(v) for v in c.split(",")])
        force = np.array([float(v) for v in f.split(",")])
        radius = float(r)
    except ValueError:
        center = force = np.zeros(0)
        radius = float("nan")
    if not (center.shape == (3,) and force.shape == (3,) and np.isfinite(center).all()
            and np.isfinite(force).all() and np.isfinite(radius) and radius > 0
            and np.abs(force).max() <= 1e6):
        raise MimicaError(f"--pull {spec!r}: expected x,y,z:radius:fx,fy,fz (skin units; finite numbers, "
                          "radius > 0)")
    return center, radius, force


def _image_points(img, path, what, face: int = 0, detector: str = "mediapipe"):
    """2D feature points: `--landmarks`-style sibling file PHOTO.landmarks.json if present, else
    detected (the photo's face number `face`, by size)."""
    from .landmarks import detect2d
    side = Path(path).with_suffix(".landmarks.json")
    if side.is_file():
        return detect2d.read_points(side, (img.shape[1], img.shape[0]))
    try:
        return detect2d.detect(img, str(path), face, detector)
    except MimicaError as e:
        if "no face found" in str(e):
            raise MimicaError(f"{e}, named {side.name} beside it (`mimica landmarks` writes one to edit)") from None
        raise MimicaError(f"{e}; `mimica landmarks {Path(path).name} --list` shows them") from None


def _strength(text: str):
    """--strength: a number, or regions: '0.5', 'brows=0.5,mouth=1.2', '0,mouth=1'."""
    out, parts = {}, [t.strip() for t in str(text).split(",") if t.strip()]
    try:
        for t in parts:
            if "=" in t:
                k, v = t.split("=", 1)
                out[k.strip()] = float(v)
            else:
                out["all"] = float(t)
    except ValueError:
        raise MimicaError(f"--strength {text!r}: a number from 0 to 2, or regions as brows=0.5,mouth=1.2") from None
    if not parts:
        raise MimicaError(f"--strength {text!r}: a number from 0 to 2, or regions as brows=0.5,mouth=1.2")
    from .image.analogy import point_strengths
    try:
        point_strengths(out)                              # checked before the work
    except MimicaError as e:
        raise MimicaError(f"--{e}") from None
    return out["all"] if list(out) == ["all"] else out


def cmd_transfer_image(a):
    from .image import ImageAnalogy, read_image, write_image
    from .landmarks.detect2d import Tracker
    from .render import contact_sheet, save_png

    if a.driving and a.source_expr:
        raise MimicaError("give either source expression photos or --driving VIDEO, not both")
    if not a.driving and not a.source_expr:
        raise MimicaError("give source expression photos, or --driving VIDEO")
    a.strength = _strength(a.strength)
    t0 = time.perf_counter()
    src = read_image(a.source_neutral)
    tgt = read_image(a.target)
    sp = _image_points(src, a.source_neutral, "source neutral", a.source_face, a.detector)
    tp = _image_points(tgt, a.target, "target", a.face, a.detector)
    an = ImageAnalogy(tgt, tp, mouth=not a.no_mouth).setup(a.method)
    from .image.io import luminance
    src_y = luminance(src)                             # the same source for every expression / frame
    out = Path(a.out)
    if a.driving:
        from .image.video import VideoWriter, frame_source
        if out.suffix.lower() != ".mp4":
            raise MimicaError(f"{out}: with --driving the output is a video; name it .mp4")
        n, fps, frames = frame_source(a.driving)
        track = Tracker(what=str(a.driving), face=a.source_face, detector=a.detector)
        t1 = time.perf_counter()
        with VideoWriter(out, fps) as vw:
            for f in _progress(frames, n, "frames"):
                vw.write(an.transfer(src_y, sp, f, track(f), method=a.method, strength=a.strength, head=a.head).image)
        dt = time.perf_counter() - t1
        _say(f"{vw.n} frames -> {out} ({vw.n / max(dt, 1e-9):.1f} frames/s, landmarks tracked)")
        return 0
    paths = [Path(p) for p in a.source_expr]
    stems = [p.stem for p in paths]
    if len(set(stems)) != len(stems):
        raise MimicaError("two source expressions share a file name; outputs would overwrite each other")
    exprs = [(p, read_image(p)) for p in paths]
    pts = [_image_points(img, p, str(p), a.source_face, a.detector) for p, img in exprs]
    t1 = time.perf_counter()
    results = [an.transfer(src_y, sp, img, xp, method=a.method, strength=a.strength, head=a.head)
               for (_, img), xp in zip(exprs, pts)]
    t2 = time.perf_counter()
    cells = [[_tile(src, tgt), _tile(img, tgt), _tile(tgt, tgt), _tile(r.image, tgt)]
             for (_, img), r in zip(exprs, results)]
    sheet = contact_sheet([c for row in cells for c in row], columns=4,
                          labels=[lab for (p, _) in exprs for lab in ("source", p.stem, "target", f"target: {p.stem}")])
    from .outputs import staged_dir
    with staged_dir(out, {"command": "transfer-image"}) as d:
        for (p, _), r in zip(exprs, results):
            write_image(d / f"{p.stem}.png", r.image)
        save_png(d / "sheet.png", sheet)
    _say(f"{len(results)} expression(s) -> {out}/ ({a.method}; points and setup {t1 - t0:.2f}s, "
         f"transfer {1000 * (t2 - t1) / len(results):.0f} ms each); sheet: {out / 'sheet.png'}")
    return 0


def _tile(img, like):
    """img as uint8 at the size of `like` (for contact sheets of photos of different sizes)."""
    from PIL import Image
    from .image.io import to_uint8
    im = Image.fromarray(to_uint8(img))
    h, w = like.shape[:2]
    return np.asarray(im.resize((w, h), Image.BILINEAR)) if im.size != (w, h) else np.asarray(im)


def cmd_landmarks(a):
    from .image import read_image, write_image
    from .landmarks import detect2d
    from .image.io import to_uint8
    from .mesh import MESH_SUFFIXES
    path = Path(a.face)
    if path.suffix.lower() in MESH_SUFFIXES:
        if a.list or a.out is None:
            raise MimicaError(f"{path}: a mesh has one face; write its landmarks with --out LANDMARKS.json")
        from .landmarks.detect3d import detect_mesh
        from .landmarks import write_landmarks
        from .mesh import read_mesh
        mesh = read_mesh(path)
        pts, view = detect_mesh(mesh, what=str(path))
        if a.show:
            from .render import face_framing, project, render_mesh, save_png
            fr = face_framing(pts)
            img = render_mesh(mesh, size=(640, 640), frame=fr)
            xy, _ = project(pts, fr, (640, 640))
            save_png(Path(a.show), _draw_points(img, xy))
        write_landmarks(a.out, pts)
        _say(f"68 landmarks found from the view yaw {view[0]}, pitch {view[1]} -> {a.out}")
        return 0
    img = read_image(path)
    if a.list:
        boxes = detect2d.face_boxes(img, a.detector)
        _say(f"{path}: {len(boxes)} face(s), by size" + "".join(
            f"; {i}: {r - l}x{b - t} px at ({(l + r) // 2}, {(t + b) // 2})" for i, (l, t, r, b) in enumerate(boxes)))
        return 0
    if a.out is None:
        raise MimicaError("landmarks: --out LANDMARKS.json is needed (or --list)")
    try:
        pts = detect2d.detect(img, str(path), a.face_number, a.detector)
    except MimicaError as e:
        raise MimicaError(f"{e}; --list shows them" if "no face found" not in str(e) else str(e)) from None
    if a.show:
        write_image(Path(a.show), _draw_points(to_uint8(img), pts))
    detect2d.write_points(a.out, pts, image=path.name, size=(img.shape[1], img.shape[0]))
    _say(f"68 points -> {a.out} (pixel coordinates; edit and rerun `transfer-image`, which reads "
         f"PHOTO.landmarks.json beside each photo)")
    return 0


def _draw_points(img, xy):
    from PIL import Image, ImageDraw
    im = Image.fromarray(np.asarray(img, np.uint8)).convert("RGB")
    d = ImageDraw.Draw(im)
    r = max(1.5, im.width / 250)
    for i, (x, y) in enumerate(xy):
        col = (255, 60, 40) if i < 17 else (40, 200, 255) if i < 27 else (255, 220, 0) if i < 36 else (80, 255, 80) if i < 48 else (255, 80, 255)
        d.ellipse([x - r, y - r, x + r, y + r], fill=col)
    return np.asarray(im)


def cmd_render(a):
    from .pipeline import RenderOptions, render_sequence
    src = Path(a.face)
    paths = _expand_frames([src]) if src.is_dir() else [src]
    opts = RenderOptions(view=a.view, turntable=a.turntable, size=a.size, frames=a.frames, fps=a.fps,
                         heatmap=a.heatmap)
    bar = _progress(range(1), None, "rendering")
    r = render_sequence(paths, a.out, opts, progress=lambda k, n: (setattr(bar, "total", n), bar.update(1)))
    bar.close()
    if r["kind"] == "png":
        if r["shown"] < r["frames"] and not a.turntable:
            _say(f"{src}: {r['frames']} meshes; the sheet shows {r['shown']} of them, evenly spaced "
                 "(first and last included; an .mp4 output shows every one)")
        _say(f"{a.out} ({r['size'][0]}x{r['size'][1]}, {r['seconds']:.2f}s)")
    else:
        _say(f"{a.out}: {r['shown']} frames at {a.fps:g} fps in {r['seconds']:.1f}s")
    return 0


def cmd_export(a):
    from .pipeline import ExportOptions, export_sequence
    paths = _expand_frames([Path(p) for p in a.frames])
    out = Path(a.out)
    suf = out.suffix.lower()
    fmt = a.format
    if not suf and a.format in FILE_FORMATS:             # `--format usd --out anim`: anim.usd
        out, suf = out.with_suffix("." + a.format), "." + a.format
    elif suf and a.format in FILE_FORMATS and suf != "." + a.format:
        raise MimicaError(f"--format {a.format} with --out {out}: say the format once (the suffix, or --format)")
    if not suf and fmt not in ("obj", "ply"):
        raise MimicaError(f"--format {a.format}: obj or ply for a folder, or {', '.join(FILE_FORMATS)} for one file")
    opts = ExportOptions(fps=a.fps, format=fmt if fmt in ("obj", "ply") else "obj", units=a.units,
                         compact=a.compact == "auto", quantize=a.quantize, rest=a.rest)
    r = export_sequence(paths, out, opts)
    if r["kind"] == "folder":
        _say(f"{out}/: {r['frames']} {opts.format.upper()} files")
    else:
        _say(f"{out}: " + _clip_line(r, a.fps, a.units))
    return 0


def cmd_animate(a):
    from .pipeline import AnimateOptions, animate
    opts = AnimateOptions(head_rotation=a.head_rotation, pivot=tuple(_floats(a.pivot, 3, "--pivot")) if a.pivot else None,
                          fps=a.fps, rest_frame=a.rest_frame)
    if (a.arkit is None) == (a.video is None):
        raise MimicaError("animate: give the take as --arkit take.csv or as --video take.mp4 (one of them)")
    r = animate(a.head, a.out, a.arkit, a.video, opts, progress=_say)
    if r.video:
        v = r.video
        _say(f"{a.video}: {v['frames']} frames tracked ({v['track_fps']:.0f} frames/s) and fitted "
             f"({v['fit_fps']:.0f} frames/s); frame {a.rest_frame} taken as the performer's rest; "
             f"points misfit median {v['misfit_median'] * 100:.1f} % of the face's width; "
             f"{v['unseen']} shapes the points cannot see (gaze, tongue) stay 0")
    w = r.weights
    if r.pivot is not None:
        turn = np.degrees(np.abs([w[n] for n in ("headYaw", "headPitch", "headRoll")]).max(1))
        head_line = (f"; the head turns (up to yaw {turn[0]:.0f}, pitch {turn[1]:.0f}, roll {turn[2]:.0f} degrees) "
                     f"about ({', '.join(f'{x:.3f}' for x in r.pivot)}) m, "
                     + (f"{r.bending} vertices bending with the neck" if r.bending else "whole"))
    else:
        head_line = "; the head stays still (--head-rotation turns it)" if "headYaw" in w else ""
    _say(f"{a.video or a.arkit}: {len(r.times)} frames over {r.times[-1]:.2f}s ({r.rate:.3g} fps) drive {r.driven} "
         f"morph targets of {Path(a.head).name}{head_line} -> {r.out}" + (f" (weights: {r.csv})" if r.csv else ""))
    return 0


def cmd_blendshapes(a):
    from .export import ARKIT_52
    from .mesh.io import SPARSE_TOLERANCE
    from .pipeline import BlendshapesOptions, make_blendshapes
    out = Path(a.out)
    if a.format and not out.suffix:                       # `--format usd --out head`: head.usd
        out = out.with_suffix("." + a.format)
    elif a.format and out.suffix.lower() != "." + a.format:
        raise MimicaError(f"--format {a.format} with --out {out}: say the format once (the suffix, or --format)")
    opts = BlendshapesOptions(landmarks=a.landmarks, cut_mouth=a.cut_mouth == "auto", cut_eyes=a.cut_eyes == "auto",
                              match=a.match, units=a.units, quantize=a.quantize)
    r = make_blendshapes(a.head, out, opts, progress=_say)
    shapes, info, name = r.shapes, r.written, Path(a.head).name
    if line := _correspondence_line(shapes.transfer).lstrip("; "):
        _say(line)
    _say_uncut_mouth(shapes.transfer, a.head, "--landmarks")
    _warn_sealed_eyes(shapes.transfer, r.head, shapes.landmarks, a.head,
                      found_flag="--landmarks" if r.landmarks_found else None)
    added = f" ({info['appended']} vertices added by the cuts)" if info.get("appended") else ""
    if info["kind"] == "fbx":
        _say(f"written into {name}'s own objects through Blender's FBX exporter{added}, {info['bytes'] / 1e6:.1f} MB")
    elif info["kind"] == "npz":
        _say(f"{out}: the rest and the 52 shapes' positions, {shapes.mesh.n_vertices} vertices in the head's order"
             + (f" ({info['appended']} added by the cuts after the head's own; cut_copies and cut_corners say where)"
                if info["appended"] else ""))
    elif info["kind"] == "usd":
        _say(f"units: {info['units']} (metersPerUnit set, y up); {info['bytes'] / 1e6:.1f} MB")
    elif info["kind"] == "gltf-layout":
        _say(f"written into {name}'s own nodes, materials and vertices{added}; units as the file's; "
             f"{info['sparse']} of {info['accessors']} morph target accessors sparse (moves under "
             f"{SPARSE_TOLERANCE * 1e3:g} mm left out), {info['bytes'] / 1e6:.1f} MB")
        for n in info["notes"]:
            _say(f"{out}: {n}")
    else:
        _say(_units_line(float(np.ptp(shapes.mesh.vertices[:, 1])), info["units"], a.units) + "; " + _sparse_line(out, info, len(ARKIT_52)))
    if a.show:
        from .render import save_png
        from .render.diagnose import transfer_picture
        save_png(a.show, transfer_picture(shapes.transfer, f"{name} as the transfer sees it"))
        _say(f"picture -> {a.show}")
    _say(f"{out}: {len(ARKIT_52)} ARKit morph targets on {shapes.mesh.n_vertices} vertices "
         f"({r.seconds:.1f}s; tongueOut stays at rest: ICT-FaceKit has no tongue shape)")
    return 0


def cmd_batch(a):
    from .batch import batch_status, run_batch
    out = Path(a.out)
    if a.status:
        if a.manifest:
            raise MimicaError("--status reads the batch's folder alone; leave the manifest out")
        st = batch_status(out)
        print(f"{out}: {len(st['done'])} done, {len(st['pending'])} pending, {len(st['failed'])} failed")
        for s in ("failed", "pending", "done"):
            for r in st[s]:
                why = f": {r['error']}" if s == "failed" else (
                    f" ({r['seconds']:.1f}s on {r['machine']})" if s == "done" and r.get("seconds") is not None else "")
                print(f"  {s:8s}{r['id']}{why}")
        return 0
    if not a.manifest:
        raise MimicaError("batch: name the manifest (jobs.toml), or ask --status")
    bar = None
    if sys.stderr.isatty():
        from tqdm import tqdm
        bar = tqdm(total=0, desc="batch", unit="job", leave=False)

    def progress(ev):
        if bar is not None:
            bar.total = ev["total"]
            if ev["status"] == "started":
                bar.refresh()
                return
            bar.set_postfix_str(ev["job"][-40:])
            bar.update(1)
    try:
        rep = run_batch(a.manifest, out, workers=a.workers, ray=a.ray, retry=a.retry, progress=progress)
    finally:
        if bar is not None:
            bar.close()
    c = rep["counts"]
    _say(f"batch: {c['done']} done, {c['skipped']} skipped (finished before, inputs unchanged), {c['failed']} failed "
         f"in {rep['seconds']:.1f}s on {rep['engine']}; report {out / 'batch.json'}")
    for r in rep["jobs"]:
        if r["status"] == "failed":
            _say(f"  failed {r['id']}: {r.get('error', '')}")
    return 1 if c["failed"] else 0


def cmd_view(a):
    from .wrinkles import mask_for
    import asyncio
    import webbrowser
    from .rig import Rig, build_rig
    from .viewer import ViewerServer, ViewerSession, ensure_three

    if not 0 <= a.port <= 65535:
        raise MimicaError(f"--port {a.port}: a port is 0-65535 (0: a free one)")
    vendor = ensure_three(progress=_say)
    if a.rig:
        rig = Rig.load(a.rig)
        name = Path(a.rig).stem
    else:
        from .mesh import read_mesh
        face = read_mesh(a.face)
        lm = _landmarks(face, a.landmarks, "--landmarks", str(a.face))
        _say(f"building a rig of {a.face} (Kim's muscles; `mimica rig` once and --rig to skip this)...")
        rig = build_rig(face, lm.positions(face))
        name = Path(a.face).stem
    mask = None
    if not a.no_wrinkles:
        mask, _ = mask_for(rig.skin, rig.landmarks)
    session = ViewerSession(rig, mask)
    server = ViewerServer(session, vendor, title=f"mimica · {name}", port=a.port)

    def ready(srv):
        _say(f"viewer on {srv.url} (Ctrl-C to stop)")
        if not a.no_browser:
            webbrowser.open(srv.url)
    # one BLAS thread: a frame's products are small, and a second thread spinning for work
    # takes the core the browser draws with (measured: 8.7 ms a frame's output with two on a
    # 2-core machine while Chromium draws, ~0.5 ms with one)
    from threadpoolctl import threadpool_limits
    with threadpool_limits(limits=1, user_api="blas"):
        try:
            asyncio.run(server.run(ready))
        except OSError as e:
            raise MimicaError(f"--port {a.port}: cannot listen on 127.0.0.1 ({e.strerror or e}); "
                              "choose another port, or 0 for a free one") from None
    return 0


def cmd_demo(a):
    from .demo import run_demo
    from .outputs import staged_dir
    with staged_dir(a.out, {"command": "demo"}) as d:
        return run_demo(d, quick=a.quick, shown=Path(a.out))


class _Parser(argparse.ArgumentParser):
    """argparse whose refusals are one line, like every other error of the command line."""

    def error(self, message):
        self.exit(2, f"mimica: error: {' '.join(message.split())} (see `{self.prog} --help`)\n")


def build_parser():
    p = _Parser(prog="mimica", description="Anatomy-aware facial animation toolkit.")
    sub = p.add_subparsers(dest="cmd", required=True)

    t = sub.add_parser("transfer", help="move expressions of a source face onto a target face (Song et al.)",
                       description="Writes, for every SOURCE_EXPR, a file of the same name into --out: the "
                                   "target wearing that expression, in the target's own topology.")
    t.add_argument("source_neutral", help="source face, neutral (OBJ/PLY/glTF)")
    t.add_argument("source_expr", nargs="+", help="source expressions (files or folders), same topology as the source")
    t.add_argument("--target", required=True, help="target face, neutral")
    t.add_argument("--source-landmarks", help="68-point landmark JSON of the source (built in for ICT-FaceKit)")
    t.add_argument("--target-landmarks", help="68-point landmark JSON of the target (built in for ICT-FaceKit)")
    t.add_argument("--method", choices=["vtc", "dt"], default="vtc",
                   help="vtc: vertex-tent coordinates (Song); dt: Sumner-Popovic deformation transfer")
    _head_options(t, "target")
    t.add_argument("--out", required=True, help="output folder")
    t.set_defaults(func=cmd_transfer)

    e = sub.add_parser("error", help="Song's per-vertex error of a result against a reference, as a PNG map")
    e.add_argument("result", help="transferred expression")
    e.add_argument("reference", help="reference expression (same topology)")
    e.add_argument("--reference-neutral", required=True, help="the reference's neutral")
    e.add_argument("--result-neutral", help="the result's neutral (default: the reference neutral)")
    e.add_argument("--region", help="vertex range LO:HI for the summary (e.g. 0:9409, ICT face area)")
    e.add_argument("--bins", default="0.1,0.5,2", help="colour thresholds in percent (Song Fig. 11: 0.1,0.5,2)")
    e.add_argument("--out", help="PNG to write")
    e.set_defaults(func=cmd_error)

    fm = sub.add_parser("fit-muscles", help="the muscle activations that best make target shapes or an ARKit "
                                            "take, as a timeline simulate plays")
    fm.add_argument("rig", help="rig file from `mimica rig`")
    fm.add_argument("--target", nargs="+", help="target shapes: the rig's face deformed (same vertices)")
    fm.add_argument("--arkit", help="a take (Live Link CSV, weights CSV/JSON): its frames fitted through the "
                                    "face's ARKit shapes; or a head's ARKit GLB: its 52 shapes fitted one by one")
    fm.add_argument("--shapes", help="with a take: the face's ARKit shapes (HEAD_ARKIT.glb from `blendshapes`; "
                                     "else made once here)")
    fm.add_argument("--fps", type=float, help="the frame rate of a take's Timecode column")
    fm.add_argument("--out", required=True, help="activations.json: a timeline of the muscles' activations")
    fm.set_defaults(func=cmd_fit_muscles)

    r = sub.add_parser("rig", help="place muscles, springs and regions of interest on a face (Kim 2020)")
    r.add_argument("face", help="face mesh (OBJ/PLY/glTF)")
    r.add_argument("--landmarks", help="68-point landmark JSON (built in for ICT-FaceKit)")
    r.add_argument("--muscles", default="all",
                   help="all (the whole library: 44 muscles, and the jaw, the lids and the cheeks as drives, "
                        "about 30 s on an 11k-vertex head), kim (Kim's 8), or a comma list of names")
    r.add_argument("--alpha", type=float, default=10.0, help="ROI range (Kim eq. 19) where a muscle has none of its own")
    r.add_argument("--modes", type=int, default=8, help="skin modes per force type")
    r.add_argument("--stretch", choices=["bar", "shell"], default="bar",
                   help="each muscle's stretch: bar (default), its nodes sliding toward the origin by arc "
                        "length, what the library was calibrated with; shell: the stretch mode of the strip's "
                        "own shell eigenproblem (Kim eqs. 11-12), docs/benchmarks.md")
    r.add_argument("--out", required=True, help="rig file to write")
    r.set_defaults(func=cmd_rig)

    s = sub.add_parser("simulate", help="animate a rig by its muscles")
    s.add_argument("rig", help="rig file from `mimica rig`")
    g = s.add_mutually_exclusive_group()
    g.add_argument("--expression", default="happiness", help="a preset: neutral, happiness, sadness, "
                   "surprise, anger, disgust, fear")
    g.add_argument("--timeline", help="timeline JSON of muscle activation curves")
    g.add_argument("--action", help="one of the 28 facial actions, e.g. AU12_lip_corner_puller")
    s.add_argument("--duration", type=float, help="seconds (default: the timeline's, or 2)")
    s.add_argument("--fps", type=float, default=60.0)
    s.add_argument("--gravity", type=float, default=0.0, help="downward acceleration on the skin (0: off; "
                   "a timeline's 'gravity' channel scales it)")
    s.add_argument("--pull", action="append", metavar="X,Y,Z:R:FX,FY,FZ",
                   help="pull the skin within R of a point with a force (repeatable; a timeline's "
                        "'pull' channel scales all pulls)")
    s.add_argument("--engine", choices=["shell", "sprung"], default="shell",
                   help="shell: Kim 2020 shells in modal coordinates; sprung: Viaud & Yahia 1992 force fields")
    s.add_argument("--solver", choices=["modal", "full"], default="modal",
                   help="modal: Kim's modal systems, one per force (real time); full: the whole skin as one "
                        "nonlinear shell, implicit Euler + projected Newton (folds where the skin "
                        "compresses; 0.3-3 s a frame)")
    s.add_argument("--warp", action=argparse.BooleanOptionalAction, default=None,
                   help="modal warping (Kim eq. 10: forces into each node's frame, displacements out of "
                        "it), on by default with the modal solver; --no-warp: the linear modal face, "
                        "twice the output rate")
    s.add_argument("--springs", choices=["linear", "kim"], default="linear",
                   help="the muscle-to-skin springs: linear, k (u_m - u_s) (default); kim: Kim's eq. 15 "
                        "(relative elongation) along the spring's deformation, linearized each step "
                        "(docs/benchmarks.md)")
    s.add_argument("--wrinkles", metavar="MASK", help="wrinkle mask of this face (`mimica wrinkle-mask`): "
                   "bulges follow the skin's compression and the age")
    s.add_argument("--age", type=float, default=50.0, help="age in years for the wrinkles (a timeline's "
                   "'age' channel overrides it)")
    s.add_argument("--no-refine", action="store_true", help="keep the rig's mesh (no refinement along wrinkles)")
    s.add_argument("--maps", type=int, nargs="?", const=1024, metavar="SIZE",
                   help="also write displacement and normal maps (SIZE px, default 1024) of the most "
                        "compressed frame (or as --maps-set says)")
    s.add_argument("--maps-set", choices=["peak", "frames", "engine"], default="peak",
                   help="peak: the most compressed frame's maps; frames: every frame's; engine: per wrinkle "
                        "region a normal and displacement map, a mask and per-frame weights (weights.csv), as "
                        "game engines blend wrinkle maps")
    s.add_argument("--out", required=True, help="output folder")
    s.set_defaults(func=cmd_simulate)

    w = sub.add_parser("wrinkle-mask", help="carry the reference wrinkle mask onto a face (Viaud & Yahia §3.2)")
    w.add_argument("face", help="face mesh (OBJ/PLY/glTF), any topology")
    w.add_argument("--landmarks", help="68-point landmark JSON (built in for ICT-FaceKit)")
    w.add_argument("--anchors", metavar="MASK", help="a mask of this face whose anchors you moved: relax again "
                   "with those characteristic points")
    w.add_argument("--reference", metavar="MASK", help="another reference mask on the ICT-FaceKit generic face")
    w.add_argument("--show", metavar="PNG", help="also draw the mask on the face")
    w.add_argument("--out", required=True, help="mask file to write (.wrinkles, JSON)")
    w.set_defaults(func=cmd_wrinkle_mask)

    ag = sub.add_parser("age", help="a face with its wrinkles at several ages, neutral and with an expression")
    ag.add_argument("face", help="face mesh (OBJ/PLY/glTF)")
    ag.add_argument("--ages", default="25,45,65,85", help="ages in years, comma-separated")
    ag.add_argument("--expression", default="happiness", help="expression preset (see `simulate`)")
    ag.add_argument("--landmarks", help="68-point landmark JSON (built in for ICT-FaceKit)")
    ag.add_argument("--rig", help="a rig of this face (default: built with all muscles, about a minute)")
    ag.add_argument("--wrinkles", metavar="MASK", help="wrinkle mask of this face (default: the reference, carried)")
    ag.add_argument("--size", type=int, default=360, help="pixels per picture")
    ag.add_argument("--out", required=True, help="PNG contact sheet")
    ag.set_defaults(func=cmd_age)

    ti = sub.add_parser("transfer-image", help="move the expression of one photo pair onto another photo (Song §VI)",
                        description="Feature points come from PHOTO.landmarks.json beside a photo when present "
                                    "(see `mimica landmarks`), else they are found automatically.")
    ti.add_argument("source_neutral", help="photo of the source person, neutral")
    ti.add_argument("source_expr", nargs="*", help="photos of the same person with expressions")
    ti.add_argument("--driving", metavar="VIDEO", help="a video (MP4) or folder of frames of the source person")
    ti.add_argument("--target", required=True, help="photo of the target person, neutral")
    ti.add_argument("--method", choices=["shading", "vtc", "eri", "warp"], default="shading",
                    help="shading (default): the expression's shading on a 3D face under the target's own light; "
                         "vtc: Song's vertex-tent luminance transfer (eq. 4); eri: expression ratio images "
                         "(Liu 2001); warp: feature-point warp only")
    ti.add_argument("--strength", default="1", metavar="A",
                    help="how much of the expression: 0 none, 1 the source's (default), up to 2 exaggerated; "
                         "or per region, e.g. brows=0.5,mouth=1.2 (regions: brows, eyes, nose, mouth, jaw; "
                         "a leading number sets the others: 0,mouth=1)")
    ti.add_argument("--no-mouth", action="store_true", help="keep the target's own mouth when the source opens "
                    "its mouth (default: the source's teeth and mouth interior, Song's teeth template)")
    ti.add_argument("--head", choices=["still", "follow"], default="still",
                    help="still: the target's head stays where it is; follow: it moves as the source's head "
                         "moves between its neutral and each expression (or frame of --driving)")
    ti.add_argument("--face", type=int, default=0, help="the target photo's face (0: the largest; "
                                                        "`mimica landmarks PHOTO --list` numbers them)")
    ti.add_argument("--source-face", type=int, default=0, help="the source photos' (or video's) face, as --face")
    ti.add_argument("--detector", choices=["dlib", "mediapipe"], default="mediapipe", help=DETECTOR_HELP)
    ti.add_argument("--out", required=True, help="output folder (photos), or an .mp4 with --driving")
    ti.set_defaults(func=cmd_transfer_image)

    lm = sub.add_parser("landmarks", help="find the 68 feature points on a photo or a mesh")
    lm.add_argument("face", help="photo (JPEG/PNG/GIF...) or mesh (OBJ/PLY/glTF)")
    lm.add_argument("--out", help="landmark JSON to write (pixels for photos, 3D for meshes)")
    lm.add_argument("--list", action="store_true", help="photos: list the faces found (numbered by size)")
    lm.add_argument("--face", type=int, default=0, dest="face_number",
                    help="photos: which face (0: the largest; --list numbers them)")
    lm.add_argument("--show", metavar="PNG", help="also draw the points")
    lm.add_argument("--detector", choices=["dlib", "mediapipe"], default="mediapipe", help=DETECTOR_HELP)
    lm.set_defaults(func=cmd_landmarks)

    rd = sub.add_parser("render", help="pictures and videos of a face or a sequence (no GPU needed)")
    rd.add_argument("face", help="a mesh, or a folder of meshes (a sequence)")
    rd.add_argument("--out", required=True, help=".png (views, contact sheet) or .mp4 (sequence or turntable)")
    rd.add_argument("--view", choices=["all", "front", "three-quarter", "profile"], default="all")
    rd.add_argument("--turntable", action="store_true", help="turn the face around (PNG: 8 angles; MP4: --frames)")
    rd.add_argument("--heatmap", metavar="VALUES", help="colour by per-vertex values (.npy, .txt) or by the "
                    "distance to a mesh of the same topology; a legend is added")
    rd.add_argument("--size", type=int, default=512, help="pixels per view")
    rd.add_argument("--frames", type=int, default=120, help="turntable video length in frames")
    rd.add_argument("--fps", type=float, default=30.0)
    rd.set_defaults(func=cmd_render)

    ex = sub.add_parser("export", help="a sequence of meshes as one glTF animation, or as OBJ/PLY files")
    ex.add_argument("frames", nargs="+", help="mesh files or a folder, one topology")
    ex.add_argument("--out", required=True, help="anim.glb / anim.gltf, anim.usd / .usda / .usdc (UsdSkel), or a folder")
    ex.add_argument("--rest", help="the rest mesh the morph targets are relative to (default: the first frame)")
    ex.add_argument("--fps", type=float, default=30.0)
    ex.add_argument("--format", default="obj", help="obj or ply, for a folder; glb, gltf, usd, usda or usdc "
                                                     "for one file (the same as --out's suffix)")
    ex.add_argument("--units", choices=["auto", "cm", "mm", "m"], default="auto", help=UNITS_HELP)
    ex.add_argument("--compact", choices=["auto", "off"], default="auto",
                    help="auto: the clip as a few basis shapes and per-frame weights when that keeps every "
                         "vertex within 0.1 mm (far smaller files); off: one morph target per frame")
    ex.add_argument("--quantize", action="store_true", help=QUANTIZE_HELP)
    ex.set_defaults(func=cmd_export)

    an = sub.add_parser("animate", help="play an ARKit take (a Live Link Face CSV) on a head's ARKit blendshapes")
    an.add_argument("head", help="the head's ARKit blendshapes, a .glb (as `mimica blendshapes` writes it)")
    an.add_argument("--arkit", help="the take: a Live Link Face CSV (Timecode, BlendShapeCount, the "
                                    "52 weights ...), or a CSV or JSON of the 52 weights with a time column")
    an.add_argument("--video", help="or the take as a video (or a folder of frames) of a face: its 68 points are "
                                    "tracked and the 52 weights fitted through the head's blendshapes, written "
                                    "also as a Live Link-style CSV beside --out")
    an.add_argument("--rest-frame", type=int, default=0,
                    help="with --video: a frame where the performer's face is at rest (default: the first)")
    an.add_argument("--fps", type=float, help="the frame rate of a Timecode column (default: from its frame numbers)")
    an.add_argument("--head-rotation", action="store_true",
                    help="also turn the head by the take's HeadYaw, HeadPitch, HeadRoll (radians)")
    an.add_argument("--pivot", help="x,y,z in metres, in the GLB's frame: the point the head turns about "
                                    "(default: the one `blendshapes` placed from the landmarks, with the neck "
                                    "bending below the chin)")
    an.add_argument("--out", required=True, help="take.glb: the head with the take as an animation (or take.usd / "
                                                 ".usda / .usdc: its blend shapes and a SkelAnimation)")
    an.set_defaults(func=cmd_animate)

    bs = sub.add_parser("blendshapes", help="the 52 ARKit blendshapes on any head mesh, as one GLB")
    bs.add_argument("head", help="head mesh (OBJ/PLY/glTF), any topology, neutral")
    bs.add_argument("--landmarks", help="68-point landmark JSON (found automatically otherwise)")
    _head_options(bs, "head")
    bs.add_argument("--out", required=True, help="head_arkit.glb (or .usd/.usda/.usdc: UsdSkel blend shapes)")
    bs.add_argument("--units", choices=["auto", "cm", "mm", "m"], default="auto", help=UNITS_HELP)
    bs.add_argument("--quantize", action="store_true", help=QUANTIZE_HELP)
    bs.add_argument("--format", choices=FILE_FORMATS + ("npz",), help="the file's kind, where --out has no suffix")
    bs.set_defaults(func=cmd_blendshapes)

    vw = sub.add_parser("view", help="a live viewer in the browser: muscles, facial actions, age, presets, "
                                     "a timeline, a second face")
    vw.add_argument("face", help="face mesh (OBJ/PLY/glTF); with --rig, the rig's own face is shown")
    vw.add_argument("--rig", help="a rig from `mimica rig` (else one is built, about 10 s)")
    vw.add_argument("--landmarks", help="68-point landmark JSON (built in for ICT-FaceKit, else found)")
    vw.add_argument("--no-wrinkles", action="store_true", help="no wrinkle layer (and no age slider)")
    vw.add_argument("--port", type=int, default=0, help="port on 127.0.0.1 (default: a free one)")
    vw.add_argument("--no-browser", action="store_true", help="only print the address")
    vw.set_defaults(func=cmd_view)

    bt = sub.add_parser("batch", help="many heads x many performances from a manifest (TOML), resumable, "
                        "on this machine's cores or a Ray cluster",
                        description="Jobs whose inputs and options did not change since they finished are skipped; "
                                    "a bad input fails its own jobs and the rest go on (exit 1 if any failed).")
    bt.add_argument("manifest", nargs="?", help="jobs.toml: [heads], [performances], [jobs.NAME] (see mimica.batch.manifest)")
    bt.add_argument("--workers", type=int, help="worker processes (default: the core count)")
    bt.add_argument("--ray", metavar="ADDRESS", help="run on Ray: a cluster's address, or auto (a running cluster, "
                    "else a local one); pip install 'mimica[ray]'")
    bt.add_argument("--retry", type=int, default=2, help="times a job is retried when its worker dies")
    bt.add_argument("--status", action="store_true", help="say what is done, pending and failed in --out, and why")
    bt.add_argument("--out", required=True, help="the batch's folder")
    bt.set_defaults(func=cmd_batch)

    d = sub.add_parser("demo", help="transfer bundled ICT-FaceKit expressions; write meshes and a contact sheet")
    d.add_argument("--out", default="out/demo")
    d.add_argument("--quick", action="store_true", help="fewer faces and expressions")
    d.set_defaults(func=cmd_demo)
    return p


# options that name what a command writes; every other path-like argument is an input
OUTPUT_OPTIONS = ("out", "show")


def _writes_folder(a) -> bool:
    """Whether --out is a folder (replaced whole when the run completes) or one file."""
    suffix = Path(a.out).suffix.lower()
    return (a.cmd in ("transfer", "simulate", "demo")
            or (a.cmd == "transfer-image" and suffix != ".mp4")
            or (a.cmd == "export" and suffix not in (".glb", ".gltf")))


def _inputs(a) -> list[Path]:
    """Every argument that names an existing file or folder and is not an output."""
    found = []
    for k, v in vars(a).items():
        if k in OUTPUT_OPTIONS or k == "func":
            continue
        for x in v if isinstance(v, list) else [v]:
            if isinstance(x, str) and x and "\0" not in x:
                try:
                    if Path(x).exists():
                        found.append(Path(x))
                except (OSError, ValueError):
                    pass
    return found


# numeric options: (command, option) -> (low, high, integer?); NaN and infinities never pass
LIMITS = {
    ("simulate", "fps"): (1.0, 1000.0, False), ("simulate", "duration"): (1e-3, 3600.0, False),
    ("simulate", "age"): (0.0, 150.0, False), ("simulate", "gravity"): (-1e4, 1e4, False),
    ("simulate", "maps"): (16, 8192, True),
    ("rig", "alpha"): (1e-3, 1e3, False), ("rig", "modes"): (1, 200, True),
    ("render", "size"): (16, 4096, True), ("render", "frames"): (1, 100_000, True),
    ("render", "fps"): (0.1, 240.0, False),
    ("export", "fps"): (0.1, 1000.0, False),
    ("age", "size"): (16, 4096, True),
    ("batch", "workers"): (1, 256, True), ("batch", "retry"): (0, 100, True),
}


def check_numbers(a) -> None:
    """Every numeric option finite and in its range, before any work."""
    for (cmd, opt), (lo, hi, integer) in LIMITS.items():
        v = getattr(a, opt, None) if a.cmd == cmd else None
        if v is None:
            continue
        if not np.isfinite(v) or not lo <= v <= hi:
            flag = "--" + opt.replace("_", "-")
            raise MimicaError(f"{flag} {v:g}: expected {'a whole number' if integer else 'a number'} "
                              f"from {lo:g} to {hi:g}")


def check_paths(a) -> None:
    """Before any work: no output may destroy an input; a folder output must be replaceable."""
    from .outputs import check_output_dir, guard_outputs
    outs = []
    if getattr(a, "out", None):
        outs.append((a.out, _writes_folder(a)))
    if getattr(a, "show", None):
        outs.append((a.show, False))
    guard_outputs(_inputs(a), outs)
    for o, folder in outs:
        if folder:
            check_output_dir(o)


def _terminate(signum, frame):
    raise KeyboardInterrupt          # SIGTERM unwinds like Ctrl-C: stages and temporary files go


def main(argv=None) -> int:
    import signal
    from ._memory import keep_memory
    from .outputs import os_error
    args = build_parser().parse_args(argv)
    keep_memory()
    try:
        previous = signal.signal(signal.SIGTERM, _terminate)
    except ValueError:                                     # not the main thread (tests, embedding)
        previous = None
    try:
        check_numbers(args)
        check_paths(args)
        return int(args.func(args) or 0)
    except MimicaError as e:
        print(f"mimica: error: {_one_line(e)}", file=sys.stderr)
        return 2
    except OSError as e:                                   # an OS error no command turned into ours
        print(f"mimica: error: {_one_line(os_error(e.filename or '?', e, 'read or write'))}", file=sys.stderr)
        return 2
    except MemoryError:
        print("mimica: error: out of memory; the input is too large for this machine", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("mimica: interrupted; nothing of this run was kept", file=sys.stderr)
        return 130
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


def _one_line(e) -> str:
    return " ".join(str(e).split())


if __name__ == "__main__":
    sys.exit(main())
