"""Every bad input is one line: a fuzz set over every command and every kind of bad
input, generated from the shared data.  Each case must exit 2 with one line on stderr, no
traceback, nothing written, and every input left as it was; a success is a false success."""

from __future__ import annotations

import json
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest

from mimica.cli import main
from mimica.data import ICT_LANDMARKS_68
from mimica.landmarks import write_landmarks
from mimica.mesh import write_mesh

TRI = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\n"
BAD_MESHES = {
    "missing": None,
    "empty": "",
    "garbage": b"\x00\xff\x13 not a mesh \x89PNG\r\n",
    "truncated": TRI[:-9] + "f 1 2",                                   # cut in the last line
    "truncated_number": "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\nv 0.5 0.",
    "index_out_of_range": TRI + "f 1 2 9\n",
    "index_zero": TRI + "f 0 1 2\n",
    "nan_vertex": TRI.replace("v 1 1 0", "v nan 1 0"),
    "inf_vertex": TRI.replace("v 1 1 0", "v 1 inf 0"),
    "huge_vertex": TRI.replace("v 1 1 0", "v 1e308 1e308 0"),
    "no_faces": "v 0 0 0\nv 1 0 0\nv 0 1 0\n",
    "no_vertices": "f 1 2 3\n",
    "repeated_corner": TRI + "f 1 1 2\n",
    "zero_area": TRI.replace("v 1 1 0", "v 2 0 0") + "f 1 2 4\n",
    "unreferenced_vertex": TRI + "v 5 5 5\n",
    "two_d_vertices": "v 0 0\nv 1 0\nv 0 1\nf 1 2 3\n",
    "two_corner_face": TRI + "f 1 2\n",
    "words": TRI.replace("v 1 1 0", "v one 1 0"),
    "latin1": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n# \xe9\xff\nv 1 \xe9 0\n",
    "folder": "<folder>",
    "stl": "<stl>",
    "ply_garbage": "<ply>",
    "glb_garbage": "<glb>",
    "gltf_wrong_json": "<gltf>",
    "all_points_equal": "v 0 0 0\nv 0 0 0\nv 0 0 0\nf 1 2 3\n",
}

BAD_LANDMARKS = {
    "missing": None,
    "not_json": "{points: [",
    "a_list": "[1, 2, 3]",
    "wrong_scheme": {"scheme": "mediapipe", "points": [[0, 0, 0]] * 68},
    "too_few": {"scheme": "ibug68", "points": [[0, 0, 0]] * 5},
    "strings": {"scheme": "ibug68", "points": [["a", "b", "c"]] * 68},
    "nan": {"scheme": "ibug68", "points": [[float("nan"), 0, 0]] * 68},
    "points_a_dict": {"scheme": "ibug68", "points": {"a": 1}},
    "two_d": {"scheme": "ibug68", "points": [[0, 0]] * 68},
    "all_coincident": "<coincident>",
    "far_off_surface": "<far>",
    "all_null": {"scheme": "ibug68", "points": [None] * 68},
}


def _write(p: Path, content):
    if content is None:
        return p
    if isinstance(content, bytes):
        p.write_bytes(content)
    elif isinstance(content, (dict, list)):
        p.write_text(json.dumps(content))          # NaN and Infinity as Python's json writes them
    else:
        p.write_text(content)
    return p


def _png(path: Path, w: int, h: int):
    """A valid PNG header of any size with almost no data (a decompression-bomb stand-in)."""
    def chunk(t, d):
        return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xffffffff)
    raw = zlib.compress(b"\x00" * 64)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0))
                     + chunk(b"IDAT", raw) + chunk(b"IEND", b""))
    return path


@pytest.fixture(scope="module")
def kit(tmp_path_factory, head_model):
    """Good inputs: an ICT head (landmarks built in), an expression, a scan of another
    topology with its landmark file, a rig, a mask, a timeline, photos; then the bad ones."""
    d = tmp_path_factory.mktemp("kit")
    head = head_model.mesh
    write_mesh(d / "head.obj", head)
    write_mesh(d / "smile.obj", head.with_vertices(head_model.shape("mouthSmile_L")))
    (d / "seq").mkdir()
    write_mesh(d / "seq" / "f0.obj", head.with_vertices(head_model.shape("jawOpen")))
    face, _ = head.submesh(np.arange(2000))
    write_mesh(d / "small.obj", face)
    # the head of another topology (vertices in another order): its landmarks are head.json's
    perm = np.random.default_rng(0).permutation(head.n_vertices)
    inv = np.argsort(perm)
    from mimica.mesh import Mesh
    write_mesh(d / "perm.obj", Mesh(head.vertices[perm], inv[head.face_indices], head.face_starts))
    write_mesh(d / "big.obj", head.with_vertices(head.vertices * 1.5 + 3.0))
    write_landmarks(d / "head.json", head.vertices[ICT_LANDMARKS_68])
    assert main(["rig", str(d / "head.obj"), "--out", str(d / "head.rig")]) == 0
    assert main(["wrinkle-mask", str(d / "head.obj"), "--out", str(d / "head.wrinkles")]) == 0
    assert main(["wrinkle-mask", str(d / "big.obj"), "--out", str(d / "big.wrinkles")]) == 0
    np.save(d / "vals.npy", np.zeros(head.n_vertices))
    from PIL import Image
    Image.fromarray(np.full((64, 48), 128, np.uint8)).save(d / "grey.png")
    from mimica.data import data_dir
    yale = data_dir() / "yalefaces"
    for n in ("subject01.normal", "subject01.happy", "subject02.normal"):
        Image.open(yale / f"{n}.gif").convert("L").save(d / f"{n}.png")
    bad = d / "bad"
    bad.mkdir()
    for k, c in BAD_MESHES.items():
        p = bad / f"{k}.obj"
        if c == "<folder>":
            p.mkdir()
        elif c == "<stl>":
            (p := bad / f"{k}.stl").write_text(TRI)
        elif c == "<ply>":
            (p := bad / f"{k}.ply").write_bytes(b"ply\nformat ascii 1.0\nelement vertex 3\nend_header\n1 2\n")
        elif c == "<glb>":
            (p := bad / f"{k}.glb").write_bytes(b"glTF\x02\x00\x00\x00garbage")
        elif c == "<gltf>":
            (p := bad / f"{k}.gltf").write_text('{"asset": {"version": "2.0"}, "meshes": [{"primitives": [{}]}]}')
        else:
            _write(p, c)
    lms = d / "badlm"
    lms.mkdir()
    for k, c in BAD_LANDMARKS.items():
        if c == "<coincident>":
            c = {"scheme": "ibug68", "points": [head.vertices[0].tolist()] * 68}
        elif c == "<far>":
            c = {"scheme": "ibug68", "points": (head.vertices[ICT_LANDMARKS_68] + 1e6).tolist()}
        _write(lms / f"{k}.json", c)
    return d


def _mesh_cases():
    """(name, argv with {M} for the bad mesh) for every command's mesh inputs."""
    k = "{K}"
    return [
        ("transfer.source", ["transfer", "{M}", f"{k}/smile.obj", "--target", f"{k}/head.obj", "--out", "{O}"]),
        ("transfer.expr", ["transfer", f"{k}/head.obj", "{M}", "--target", f"{k}/head.obj", "--out", "{O}"]),
        ("transfer.target", ["transfer", f"{k}/head.obj", f"{k}/smile.obj", "--target", "{M}", "--out", "{O}"]),
        ("error.result", ["error", "{M}", f"{k}/smile.obj", "--reference-neutral", f"{k}/head.obj", "--out", "{O}.png"]),
        ("error.neutral", ["error", f"{k}/smile.obj", f"{k}/smile.obj", "--reference-neutral", "{M}", "--out", "{O}.png"]),
        ("rig", ["rig", "{M}", "--out", "{O}.rig"]),
        ("wrinkle-mask", ["wrinkle-mask", "{M}", "--out", "{O}.wrinkles"]),
        ("age", ["age", "{M}", "--out", "{O}.png"]),
        ("landmarks.mesh", ["landmarks", "{M}", "--out", "{O}.json"]),
        ("render", ["render", "{M}", "--out", "{O}.png"]),
        ("export", ["export", "{M}", "--out", "{O}.glb"]),
        ("export.rest", ["export", f"{k}/seq", "--rest", "{M}", "--out", "{O}.glb"]),
        ("blendshapes", ["blendshapes", "{M}", "--out", "{O}.glb"]),
        ("view", ["view", "{M}", "--no-browser"]),
    ]


def _landmark_cases():
    k = "{K}"
    return [
        ("transfer.source_lm", ["transfer", f"{k}/perm.obj", f"{k}/perm.obj", "--target", f"{k}/head.obj",
                                "--source-landmarks", "{L}", "--target-landmarks", f"{k}/head.json", "--out", "{O}"]),
        ("transfer.target_lm", ["transfer", f"{k}/head.obj", f"{k}/smile.obj", "--target", f"{k}/perm.obj",
                                "--target-landmarks", "{L}", "--out", "{O}"]),
        ("rig.lm", ["rig", f"{k}/perm.obj", "--landmarks", "{L}", "--out", "{O}.rig"]),
        ("wrinkle-mask.lm", ["wrinkle-mask", f"{k}/perm.obj", "--landmarks", "{L}", "--out", "{O}.wrinkles"]),
        ("blendshapes.lm", ["blendshapes", f"{k}/perm.obj", "--landmarks", "{L}", "--out", "{O}.glb"]),
    ]


def _timeline(**kw):
    t = {"format": "mimica-timeline/1", "duration": 1.0,
         "channels": {"zygomaticus_major_L": {"interp": "cubic", "keys": [[0, 0], [0.5, 1], [1, 0]]}}}
    t.update(kw)
    return t


TIMELINES = {
    "duration_nan": _timeline(duration=float("nan")),
    "duration_inf": "<inf>",
    "duration_huge": _timeline(duration=1e9),
    "duration_negative": _timeline(duration=-1),
    "duration_string": _timeline(duration="long"),
    "channels_list": _timeline(channels=[1, 2]),
    "channel_not_dict": _timeline(channels={"zygomaticus_major_L": 3}),
    "keys_strings": _timeline(channels={"zygomaticus_major_L": {"keys": [["a", "b"]]}}),
    "keys_nan": _timeline(channels={"zygomaticus_major_L": {"keys": [[0, float("nan")], [1, 1]]}}),
    "keys_time_inf": "<keyinf>",
    "keys_flat": _timeline(channels={"zygomaticus_major_L": {"keys": [1, 2, 3]}}),
    "keys_empty": _timeline(channels={"zygomaticus_major_L": {"keys": []}}),
    "interp_bogus": _timeline(channels={"zygomaticus_major_L": {"interp": "spline9", "keys": [[0, 0], [1, 1]]}}),
    "unknown_channel": _timeline(channels={"no_such_muscle": {"keys": [[0, 0], [1, 1]]}}),
    "activation_huge": _timeline(channels={"zygomaticus_major_L": {"keys": [[0, 0], [1, 1e12]]}}),
    "age_nan": _timeline(channels={"age": {"keys": [[0, float("nan")], [1, 30]]}}),
    "format_wrong": _timeline(format="other/2"),
    "a_list": [1, 2],
    "not_json": "{duration: ",
    "missing": None,
}


def _option_cases():
    """(name, argv) of bad options and bad files that are not meshes or landmarks."""
    k = "{K}"
    sim = ["simulate", f"{k}/head.rig", "--out", "{O}"]
    cases = []
    for v in ("0", "nan", "-1", "inf", "1e9", "-inf"):
        cases.append((f"simulate.fps={v}", sim + ["--fps", v]))
    for v in ("-1", "nan", "inf", "1e4", "0"):
        cases.append((f"simulate.duration={v}", sim + ["--duration", v]))
    for v in ("nan", "-5", "1e9", "inf"):
        cases.append((f"simulate.age={v}", sim + ["--wrinkles", f"{k}/head.wrinkles", "--age", v]))
    for v in ("nan", "inf", "-inf", "1e300"):
        cases.append((f"simulate.gravity={v}", sim + ["--gravity", v]))
    for v in ("nan,0,0:1:0,0,1", "0,0,0:0:0,0,1", "0,0,0:-1:0,0,1", "0,0,0:1:inf,0,0", "0,0:1:0,0,1",
              "0,0,0:1", "a,b,c:1:0,0,1", "0,0,0:nan:0,0,1", "0,0,0:1:1e300,0,0"):
        cases.append((f"simulate.pull={v}", sim + ["--pull", v]))
    for v in ("0", "-1", "100000", "3"):
        cases.append((f"simulate.maps={v}", sim + ["--wrinkles", f"{k}/head.wrinkles", "--maps", v]))
    cases.append(("simulate.expression", sim + ["--expression", "joy"]))
    cases.append(("simulate.action", sim + ["--action", "AU99_nothing"]))
    cases.append(("simulate.sprung_gravity", sim + ["--engine", "sprung", "--gravity", "1"]))
    cases.append(("simulate.wrinkles_missing", sim + ["--wrinkles", f"{k}/nothing.wrinkles"]))
    cases.append(("simulate.wrinkles_not_json", sim + ["--wrinkles", f"{k}/head.obj"]))
    cases.append(("simulate.wrinkles_other_face", ["simulate", f"{k}/head.rig", "--wrinkles", "{W}", "--out", "{O}"]))
    for name in TIMELINES:
        cases.append((f"simulate.timeline.{name}", sim + ["--timeline", f"{k}/tl/{name}.json"]))
    for name in RIGS:
        cases.append((f"simulate.rig.{name}", ["simulate", f"{k}/rigs/{name}.rig", "--out", "{O}"]))
        cases.append((f"view.rig.{name}", ["view", f"{k}/head.obj", "--rig", f"{k}/rigs/{name}.rig", "--no-browser"]))
    rig = ["rig", f"{k}/head.obj", "--out", "{O}.rig"]
    for v in ("nan", "-1", "0", "inf"):
        cases.append((f"rig.alpha={v}", rig + ["--alpha", v]))
    for v in ("0", "-1", "100000"):
        cases.append((f"rig.modes={v}", rig + ["--modes", v]))
    for v in ("nobody", "", ",", "kim,nobody"):
        cases.append((f"rig.muscles={v!r}", rig + ["--muscles", v]))
    rd = ["render", f"{k}/head.obj", "--out", "{O}.png"]
    for v in ("0", "-1", "100000"):
        cases.append((f"render.size={v}", rd + ["--size", v]))
    for v in ("0", "-5", "1000000"):
        cases.append((f"render.frames={v}", ["render", f"{k}/head.obj", "--turntable", "--out", "{O}.mp4",
                                             "--frames", v]))
    for v in ("0", "nan", "-1", "inf"):
        cases.append((f"render.fps={v}", ["render", f"{k}/head.obj", "--turntable", "--out", "{O}.mp4", "--fps", v]))
    cases.append(("render.out_suffix", ["render", f"{k}/head.obj", "--out", "{O}.tiff2"]))
    for name in ("missing", "garbage", "short", "nan"):
        cases.append((f"render.heatmap.{name}", rd + ["--heatmap", f"{k}/heat/{name}.txt"]))
    cases.append(("render.heatmap.other_topology", rd + ["--heatmap", f"{k}/small.obj"]))
    ex = ["export", f"{k}/seq", "--out", "{O}.glb"]
    for v in ("0", "nan", "-1", "inf"):
        cases.append((f"export.fps={v}", ex + ["--fps", v]))
    cases.append(("export.format", ["export", f"{k}/seq", "--out", "{O}", "--format", "fbx"]))
    cases.append(("export.suffix", ["export", f"{k}/seq", "--out", "{O}.abc"]))
    cases.append(("export.rest_other_topology", ex + ["--rest", f"{k}/small.obj"]))
    cases.append(("export.mixed_topology", ["export", f"{k}/head.obj", f"{k}/small.obj", "--out", "{O}.glb"]))
    cases.append(("export.empty_folder", ["export", f"{k}/empty", "--out", "{O}.glb"]))
    ag = ["age", f"{k}/head.obj", "--out", "{O}.png"]
    for v in ("", "nan", "-5", "200", "a,b", "30,,40", "inf"):
        cases.append((f"age.ages={v!r}", ag + ["--ages", v]))
    for v in ("0", "-1", "100000"):
        cases.append((f"age.size={v}", ag + ["--size", v]))
    cases.append(("age.expression", ag + ["--expression", "joy"]))
    cases.append(("age.out_suffix", ["age", f"{k}/head.obj", "--out", "{O}.obj"]))
    er = ["error", f"{k}/smile.obj", f"{k}/smile.obj", "--reference-neutral", f"{k}/head.obj"]
    for v in ("1:2:3", "a:b", "5:2", "-3:2", "0:99999999", ":"):
        cases.append((f"error.region={v}", er + ["--region", v]))
    for v in ("1,2", "3,2,1", "nan,1,2", "a,b,c", "-1,0,1"):
        cases.append((f"error.bins={v}", er + ["--bins", v]))
    cases.append(("error.other_topology", ["error", f"{k}/smile.obj", f"{k}/small.obj", "--reference-neutral",
                                           f"{k}/head.obj"]))
    cases.append(("transfer.dup_names", ["transfer", f"{k}/head.obj", f"{k}/smile.obj", f"{k}/dup/smile.obj",
                                         "--target", f"{k}/head.obj", "--out", "{O}"]))
    cases.append(("transfer.other_topology_frame", ["transfer", f"{k}/head.obj", f"{k}/small.obj", "--target",
                                                    f"{k}/head.obj", "--out", "{O}"]))
    cases.append(("transfer.empty_folder", ["transfer", f"{k}/head.obj", f"{k}/empty", "--target",
                                            f"{k}/head.obj", "--out", "{O}"]))
    cases.append(("transfer.no_landmarks_no_face", ["transfer", f"{k}/head.obj", f"{k}/smile.obj", "--target",
                                                    f"{k}/bad/all_points_equal.obj", "--out", "{O}"]))
    ti = ["transfer-image", f"{k}/subject01.normal.png", f"{k}/subject01.happy.png", "--target",
          f"{k}/subject02.normal.png", "--out", "{O}"]
    for v in ("nan", "-1", "5", "inf"):
        cases.append((f"transfer-image.strength={v}", ti + ["--strength", v]))
    for name in PHOTOS:
        cases.append((f"transfer-image.target.{name}", ["transfer-image", f"{k}/subject01.normal.png",
                                                        f"{k}/subject01.happy.png", "--target",
                                                        f"{k}/photos/{name}", "--out", "{O}"]))
        cases.append((f"transfer-image.source.{name}", ["transfer-image", f"{k}/photos/{name}",
                                                        f"{k}/subject01.happy.png", "--target",
                                                        f"{k}/subject02.normal.png", "--out", "{O}"]))
        cases.append((f"landmarks.photo.{name}", ["landmarks", f"{k}/photos/{name}", "--out", "{O}.json"]))
    cases.append(("transfer-image.both", ti + ["--driving", f"{k}/seq"]))
    cases.append(("transfer-image.neither", ["transfer-image", f"{k}/subject01.normal.png", "--target",
                                             f"{k}/subject02.normal.png", "--out", "{O}"]))
    cases.append(("transfer-image.driving_missing", ["transfer-image", f"{k}/subject01.normal.png", "--driving",
                                                     f"{k}/nothing.mp4", "--target", f"{k}/subject02.normal.png",
                                                     "--out", "{O}.mp4"]))
    cases.append(("transfer-image.driving_garbage", ["transfer-image", f"{k}/subject01.normal.png", "--driving",
                                                     f"{k}/photos/garbage.png", "--target",
                                                     f"{k}/subject02.normal.png", "--out", "{O}.mp4"]))
    cases.append(("transfer-image.driving_not_mp4", ["transfer-image", f"{k}/subject01.normal.png", "--driving",
                                                     f"{k}/frames", "--target", f"{k}/subject02.normal.png",
                                                     "--out", "{O}.avi"]))
    wm = ["wrinkle-mask", f"{k}/head.obj", "--out", "{O}.wrinkles"]
    cases.append(("wrinkle-mask.reference_missing", wm + ["--reference", f"{k}/nothing.wrinkles"]))
    cases.append(("wrinkle-mask.reference_garbage", wm + ["--reference", f"{k}/tl/a_list.json"]))
    cases.append(("wrinkle-mask.anchors_garbage", wm + ["--anchors", f"{k}/tl/not_json.json"]))
    for v in ("-1", "70000", "99999999"):
        cases.append((f"view.port={v}", ["view", f"{k}/head.obj", "--rig", f"{k}/head.rig", "--port", v,
                                         "--no-browser"]))
    return cases


RIGS = ["missing", "empty", "not_zip", "bad_crc", "truncated", "meta_list", "meta_not_json", "nan_vertices",
        "muscles_not_list", "wrong_format", "missing_array", "faces_out_of_range"]
PHOTOS = {"missing.png": None, "garbage.png": b"\x89PNG\r\n\x1a\nnot really", "empty.jpg": b"",
          "huge.png": "<huge>", "tiny.png": "<tiny>", "no_face.png": "<grey>", "text.gif": "GIF89a?"}


def _make_rigs(d: Path):
    good = (d / "head.rig").read_bytes()
    r = d / "rigs"
    r.mkdir()
    (r / "empty.rig").write_bytes(b"")
    (r / "not_zip.rig").write_text("hello")
    b = bytearray(good)
    b[len(b) // 2] ^= 0xFF
    (r / "bad_crc.rig").write_bytes(bytes(b))
    (r / "truncated.rig").write_bytes(good[: len(good) // 3])
    with np.load(d / "head.rig") as z:
        arrays = {k: z[k] for k in z.files}

    def variant(name, **changes):
        a = dict(arrays)
        for key, val in changes.items():
            if val is None:
                a.pop(key)
            else:
                a[key] = val
        with open(r / f"{name}.rig", "wb") as fh:
            np.savez_compressed(fh, **a)
    meta = json.loads(bytes(arrays["meta"]).decode())

    def m(x):
        return np.frombuffer(json.dumps(x).encode(), np.uint8)
    variant("meta_list", meta=m([1, 2]))
    variant("meta_not_json", meta=np.frombuffer(b"{nope", np.uint8))
    v = arrays["skin_v"].copy()
    v[5] = np.nan
    variant("nan_vertices", skin_v=v)
    variant("muscles_not_list", meta=m({**meta, "muscles": 3}))
    variant("wrong_format", meta=m({**meta, "format": "rig/0"}))
    variant("missing_array", m0_nodes=None)
    fi = arrays["skin_fi"].copy()
    fi[0] = 10 ** 7
    variant("faces_out_of_range", skin_fi=fi)


def _make_extras(d: Path):
    (d / "empty").mkdir(exist_ok=True)
    (d / "dup").mkdir(exist_ok=True)
    (d / "dup" / "smile.obj").write_bytes((d / "smile.obj").read_bytes())
    (d / "frames").mkdir(exist_ok=True)
    (d / "frames" / "a.png").write_bytes((d / "subject01.happy.png").read_bytes())
    tl = d / "tl"
    tl.mkdir()
    for k, c in TIMELINES.items():
        if c == "<inf>":
            c = json.dumps(_timeline()).replace('"duration": 1.0', '"duration": Infinity')
        elif c == "<keyinf>":
            c = json.dumps(_timeline()).replace("[1, 0]", "[Infinity, 0]")
        _write(tl / f"{k}.json", c)
    h = d / "heat"
    h.mkdir()
    (h / "garbage.txt").write_text("one\ntwo\n")
    (h / "short.txt").write_text("1\n2\n3\n")
    (h / "nan.txt").write_text("nan\n" * 11248)
    p = d / "photos"
    p.mkdir()
    from PIL import Image
    for k, c in PHOTOS.items():
        if c == "<huge>":
            _png(p / k, 20000, 20000)
        elif c == "<tiny>":
            Image.fromarray(np.zeros((1, 1), np.uint8)).save(p / k)
        elif c == "<grey>":
            (p / k).write_bytes((d / "grey.png").read_bytes())
        else:
            _write(p / k, c)


def _digest(root: Path) -> dict:
    """Every input's size, inode and modification time (any write changes them)."""
    out = {}
    for p in sorted(root.rglob("*")):
        st = p.stat()
        out[str(p.relative_to(root))] = (st.st_size, st.st_ino, st.st_mtime_ns) if p.is_file() else "dir"
    return out


def _all_cases():
    cases = []
    for name, argv in _mesh_cases():
        for bad in BAD_MESHES:
            cases.append((f"{name}[{bad}]", argv, {"M": bad}))
    for name, argv in _landmark_cases():
        for bad in BAD_LANDMARKS:
            cases.append((f"{name}[{bad}]", argv, {"L": bad}))
    for name, argv in _option_cases():
        cases.append((name, argv, {}))
    return cases


CASES = _all_cases()


def test_the_fuzz_set_is_large_enough():
    assert len(CASES) >= 300, len(CASES)


@pytest.fixture(scope="module")
def full_kit(kit):
    _make_rigs(kit)
    _make_extras(kit)
    return kit


def _mesh_path(kit: Path, bad: str) -> str:
    hits = sorted((kit / "bad").glob(f"{bad}.*"))
    return str(hits[0]) if hits else str(kit / "bad" / f"{bad}.obj")


@pytest.fixture
def no_serving(monkeypatch):
    """`view` never serves here: a case that gets as far as serving is a false success."""
    from mimica.viewer import ViewerServer

    async def run(self, ready=None):
        return None
    monkeypatch.setattr(ViewerServer, "run", run)


@pytest.mark.parametrize("name,argv,sub", CASES, ids=[c[0] for c in CASES])
def test_bad_input_is_one_line(full_kit, tmp_path, capsys, no_serving, name, argv, sub):
    k = full_kit
    out = tmp_path / "out"
    out.mkdir()
    before = _digest(k)
    rep = {"{K}": str(k), "{O}": str(out / "result"), "{W}": str(k / "big.wrinkles")}
    if "M" in sub:
        rep["{M}"] = _mesh_path(k, sub["M"])
    if "L" in sub:
        rep["{L}"] = str(k / "badlm" / f"{sub['L']}.json")
    args = []
    for a in argv:
        for key, val in rep.items():
            a = a.replace(key, val)
        args.append(a)
    try:
        code = main(args)
    except SystemExit as e:                      # argparse's own refusals: exit 2, usage + one line
        code = e.code
    err = capsys.readouterr().err.strip()
    assert code == 2, f"{name}: exit {code} (a false success or a crash): {err[-300:]}"
    lines = [ln for ln in err.splitlines() if ln.startswith("mimica: error:") or "error:" in ln]
    assert "Traceback" not in err, err[-500:]
    assert len(lines) == 1 and (err.splitlines()[-1] == lines[0]), err[-500:]
    assert list(out.iterdir()) == [], f"{name}: left {[p.name for p in out.iterdir()]}"
    assert _digest(k) == before, f"{name}: an input was modified"
