"""The pipeline layer (mimica.pipeline): each job callable from Python, with the same result and
the same defaults as the command line that calls it."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from mimica.errors import MimicaError
from mimica.pipeline import BlendshapesOptions, make_blendshapes

HEAD = Path(os.environ["MIMICA_DATA"]) / "real-heads" / "mediapipe-canonical" / "head.obj"


def test_blendshapes_from_python_is_the_command_lines(tmp_path):
    """A GLB written from Python carries what `animate` reads (the landmarks `--video` fits, the
    pivot the head turns about), and its shapes are the command line's."""
    from mimica.cli import main
    from mimica.export.extras import stored_head
    from mimica.export.video import landmark_basis
    from mimica.mesh.io import read_morph_targets
    head_glb = tmp_path / "cli.glb"
    assert main(["blendshapes", str(HEAD), "--out", str(head_glb)]) == 0
    progress = []
    r = make_blendshapes(HEAD, tmp_path / "py.glb", progress=progress.append)
    assert r.path.is_file() and r.landmarks_found and r.written["kind"] == "gltf"
    assert any("transferring 52 shapes" in p for p in progress)
    a, b = landmark_basis(r.path), landmark_basis(head_glb)
    assert np.array_equal(a.rest, b.rest) and np.array_equal(a.motion, b.motion)
    mesh, targets, _ = read_morph_targets(r.path)
    _, cli_targets, _ = read_morph_targets(head_glb)
    assert set(targets) == set(cli_targets) and all(np.array_equal(targets[n], cli_targets[n]) for n in targets)
    assert len(stored_head(mesh.layout.extras)["pivot"]) == 3


def test_blendshapes_refuses_an_unknown_file_kind_before_the_work(tmp_path):
    calls = []
    with pytest.raises(MimicaError, match="glTF"):
        make_blendshapes(HEAD, tmp_path / "head.stl", progress=calls.append)
    assert not calls and not (tmp_path / "head.stl").exists()
    with pytest.raises(MimicaError, match="FBX is written back"):
        make_blendshapes(HEAD, tmp_path / "head.fbx")


def test_the_command_line_takes_its_blendshapes_defaults_from_the_pipeline():
    from dataclasses import fields
    from mimica.cli import build_parser
    a = build_parser().parse_args(["blendshapes", "head.obj", "--out", "x.glb"])
    d = BlendshapesOptions()
    given = {"landmarks": a.landmarks, "cut_mouth": a.cut_mouth == "auto", "cut_eyes": a.cut_eyes == "auto",
             "match": a.match, "units": a.units, "quantize": a.quantize}
    assert given == {f.name: getattr(d, f.name) for f in fields(d)}


def test_the_batch_takes_its_defaults_from_the_pipeline():
    from mimica.batch.manifest import KINDS
    from mimica.pipeline import TransferOptions
    b, t = BlendshapesOptions(), TransferOptions()
    auto = {True: "auto", False: "off"}
    assert KINDS["blendshapes"][1] == {"quantize": b.quantize, "cut_mouth": auto[b.cut_mouth],
                                       "cut_eyes": auto[b.cut_eyes], "match": b.match}
    assert KINDS["transfer"][1] == {"method": t.method, "cut_mouth": auto[t.cut_mouth], "cut_eyes": auto[t.cut_eyes],
                                    "match": t.match}


def test_the_command_line_takes_its_transfer_defaults_from_the_pipeline():
    from dataclasses import fields
    from mimica.cli import build_parser
    from mimica.pipeline import TransferOptions
    a = build_parser().parse_args(["transfer", "s.obj", "e.obj", "--target", "t.obj", "--out", "o"])
    d = TransferOptions()
    given = {"method": a.method, "match": a.match, "cut_mouth": a.cut_mouth == "auto", "cut_eyes": a.cut_eyes == "auto"}
    assert given == {f.name: getattr(d, f.name) for f in fields(d)}


def test_a_sequence_from_python_equals_the_command_lines(tmp_path):
    """transfer_sequence on ICT's own files (a remeshed target would be slow): the results are the
    command line's, file for file."""
    from mimica.cli import main
    from mimica.data import ICTModel, ICT_HEAD_VERTICES
    from mimica.mesh import read_vertices, write_mesh
    from mimica.pipeline import transfer_sequence
    model = ICTModel(ICT_HEAD_VERTICES)
    S = model.mesh
    write_mesh(tmp_path / "S.obj", S)
    write_mesh(tmp_path / "T.obj", S.with_vertices(model.identity(np.linspace(-1, 1, 20))))
    exprs = []
    for name in ("jawOpen", "mouthSmile_L"):
        write_mesh(tmp_path / f"{name}.obj", S.with_vertices(model.neutral + model.delta({name: 1.0})))
        exprs.append(tmp_path / f"{name}.obj")
    r = transfer_sequence(tmp_path / "S.obj", exprs, tmp_path / "T.obj", tmp_path / "py")
    assert main(["transfer", str(tmp_path / "S.obj"), *map(str, exprs), "--target", str(tmp_path / "T.obj"),
                 "--out", str(tmp_path / "cli")]) == 0
    assert [f.name for f in r.files] == ["jawOpen.obj", "mouthSmile_L.obj"]
    for f in r.files:
        assert np.array_equal(read_vertices(f), read_vertices(tmp_path / "cli" / f.name))
    with pytest.raises(MimicaError, match="exists and is not a folder"):
        (tmp_path / "file").write_text("x")
        transfer_sequence(tmp_path / "S.obj", exprs, tmp_path / "T.obj", tmp_path / "file")


def test_rig_and_simulate_defaults_are_the_pipelines_everywhere():
    from dataclasses import fields
    from mimica.batch.manifest import KINDS
    from mimica.cli import build_parser
    from mimica.pipeline import RigOptions, SimulateOptions
    p = build_parser()
    r = p.parse_args(["rig", "f.obj", "--out", "r.rig"])
    assert {"muscles": r.muscles, "alpha": r.alpha, "modes": r.modes, "stretch": r.stretch} == \
        {f.name: getattr(RigOptions(), f.name) for f in fields(RigOptions)}
    s = p.parse_args(["simulate", "r.rig", "--out", "o"])
    given = {"expression": s.expression, "timeline": s.timeline, "action": s.action, "duration": s.duration,
             "fps": s.fps, "gravity": s.gravity, "pulls": tuple(s.pull or ()), "engine": s.engine,
             "solver": s.solver, "warp": s.warp, "springs": s.springs, "wrinkles": s.wrinkles, "age": s.age,
             "refine": not s.no_refine, "maps": s.maps, "maps_set": s.maps_set}
    assert given == {f.name: getattr(SimulateOptions(), f.name) for f in fields(SimulateOptions)}
    assert KINDS["simulate"][1] == {"muscles": RigOptions().muscles, "fps": SimulateOptions().fps}


def test_simulate_refuses_what_its_engine_cannot_do_before_the_work(tmp_path):
    from mimica.pipeline import SimulateOptions, simulate
    for o, why in ((SimulateOptions(engine="sprung", gravity=1.0), "shell engine only"),
                   (SimulateOptions(solver="full", springs="kim"), "full solver simulates the muscles only"),
                   (SimulateOptions(engine="cloth"), "engine 'cloth'")):
        with pytest.raises(MimicaError, match=why):
            simulate(tmp_path / "none.rig", tmp_path / "out", o)
    assert not (tmp_path / "out").exists()


def test_age_render_export_animate_defaults_are_the_pipelines():
    from mimica.cli import build_parser
    from mimica.pipeline import AgeOptions, AnimateOptions, ExportOptions, RenderOptions
    p = build_parser()
    a = p.parse_args(["age", "f.obj", "--out", "s.png"])
    assert (tuple(float(x) for x in a.ages.split(",")), a.expression, a.size) == \
        (AgeOptions().ages, AgeOptions().expression, AgeOptions().size)
    r = p.parse_args(["render", "f.obj", "--out", "s.png"])
    d = RenderOptions()
    assert (r.view, r.turntable, r.size, r.frames, r.fps, r.heatmap) == \
        (d.view, d.turntable, d.size, d.frames, d.fps, d.heatmap)
    e = p.parse_args(["export", "d", "--out", "a.glb"])
    x = ExportOptions()
    assert (e.fps, e.format, e.units, e.compact == "auto", e.quantize, e.rest) == \
        (x.fps, x.format, x.units, x.compact, x.quantize, x.rest)
    n = p.parse_args(["animate", "h.glb", "--arkit", "t.csv", "--out", "t.glb"])
    assert (n.head_rotation, n.pivot, n.fps, n.rest_frame, n.landmarks, n.tracker) == \
        tuple(vars(AnimateOptions()).values())


def test_the_demo_runs_on_the_pipeline_and_its_glb_plays(tmp_path):
    """`make demo` (quick): the contact sheet, the targets' expressions, and the real head's GLB
    as `blendshapes` writes it -- its landmarks stored, so `animate --video` can fit it."""
    from mimica.cli import main
    from mimica.export.video import landmark_basis
    from mimica.image import read_image
    out = tmp_path / "demo"
    assert main(["demo", "--quick", "--out", str(out)]) == 0
    assert read_image(out / "contact_sheet.png").shape[0] > 300
    assert len(list((out / "identity_B").glob("*.obj"))) == 4          # neutral and three expressions
    basis = landmark_basis(out / "real_head" / "arkit_52.glb")
    assert basis.motion.shape[0] == 52 and np.abs(basis.motion).max() > 0


def test_the_validators_say_what_was_given_and_what_is_expected():
    from mimica.validate import floats, number_in, pull, strengths
    assert floats("0,1.5,-0.1", 3, "pivot") == [0.0, 1.5, -0.1]
    assert number_in(8, 1, 200, "modes", integer=True) == 8
    c, r, f = pull("0,1,2:0.5:0,0,3", "pull")
    assert c.tolist() == [0, 1, 2] and r == 0.5 and f.tolist() == [0, 0, 3]
    assert strengths("0,mouth=1", "strength") == {"all": 0.0, "mouth": 1.0} and strengths("0.5", "s") == 0.5
    for call, words in ((lambda: floats("1,nan,2", 3, "--pivot"), "--pivot '1,nan,2': expected 3 finite"),
                        (lambda: number_in(float("inf"), 1, 2, "--fps"), "--fps inf: expected a number"),
                        (lambda: number_in(2.5, 1, 9, "--modes", integer=True), "a whole number"),
                        (lambda: pull("1,2:3", "--pull"), "x,y,z:radius:fx,fy,fz"),
                        (lambda: strengths("brows=x", "--strength"), "regions as brows=0.5")):
        with pytest.raises(MimicaError, match=words.replace("(", r"\(")):
            call()


def test_the_viewer_rigs_a_face_as_rig_does(monkeypatch):
    """`mimica view` on a face without a rig rigs it through the pipeline with make_rig's own
    defaults (the calibrated library, not a set of its own), wrinkles on as the CLI's default,
    its force systems left to the viewer's session (made as the page moves them)."""
    import mimica.pipeline.view as view
    from mimica.cli import build_parser
    from mimica.pipeline import RigOptions, ViewOptions, prepare_view
    seen = {}

    class Stop(Exception):
        pass

    def fake(face, landmarks, options, progress=None, systems=True):
        seen["options"], seen["systems"] = options, systems
        raise Stop
    monkeypatch.setattr(view, "make_rig", fake)
    with pytest.raises(Stop):
        prepare_view("face.obj")
    assert seen["options"] == RigOptions() and ViewOptions().rig == RigOptions()
    # the page opens on the placed muscles; the session makes their systems beside it
    assert seen["systems"] is False and ViewOptions().systems == "as needed"
    with pytest.raises(MimicaError, match="'as needed' or 'first'"):
        prepare_view("face.obj", options=ViewOptions(systems="later"))
    assert (not build_parser().parse_args(["view", "f.obj"]).no_wrinkles) == ViewOptions().wrinkles
