"""mimica in Blender: a Blender add-on.

Blender's Python carries numpy < 2 (bpy 4.x and 5.0 require it) and mimica numpy >= 2, so the
two cannot share one interpreter.  The add-on therefore runs the `mimica` command of the
user's own installation (set in the add-on's preferences, or found on PATH) and exchanges files
with it: the selected head goes out as an OBJ in Blender's vertex order (turned from Blender's z
up to mimica's y up), the shapes come back in that order (`blendshapes --out FILE.npz`, the
OBJs of `transfer` and `simulate`), which Blender's numpy reads.  Four operators: the 52 ARKit
shape keys on the active mesh; a Live Link Face take (or any CSV of ARKit weights with a time
column, as `animate --video` also writes) keyed onto them at the scene's frame rate; the active
mesh's shape keys moved onto the other selected meshes (any topology); Kim's muscles rigged on
the active mesh and preset expressions simulated into shape keys.  Progress shows in the status
bar; mimica's one-line errors become Blender reports.

Install: `mimica blender-addon --out DIR` writes mimica_blender.zip -- this file as the package's
__init__, and mimica/facts.py beside it (the ARKit names, the take reader and the axes, shared
with mimica); in Blender: Edit > Preferences > Add-ons > Install from disk..., the zip.  The panel
is in the 3D view's sidebar, "mimica".  This module imports without Blender (mimica's own tests
read it); its classes exist only inside Blender.
"""

from __future__ import annotations

import csv
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

from . import facts      # shipped beside this file (mimica blender-addon); mimica's own when imported from mimica

bl_info = {
    "name": "mimica: ARKit shape keys, Live Link takes, transfer, muscles",
    "author": "mimica",
    "version": (0, 1, 0),
    "blender": (4, 2, 0),
    "location": "View3D > Sidebar > mimica",
    "description": "ARKit shape keys for any head, Live Link Face takes as actions, shape keys moved between "
                   "meshes, muscle-simulated shape keys (runs the mimica command)",
    "category": "Animation",
}

try:  # inside Blender
    import bpy
except ImportError:  # mimica's own tests read this module without Blender
    bpy = None

ARKIT = list(facts.ARKIT_52)
EXPRESSIONS = facts.EXPRESSIONS


class AddonError(Exception):
    """What the user is told, in one line (a Blender report).

    Parameters
    ----------
    message : str
    """


def mimica_command(configured: str = "") -> str:
    """The mimica executable the add-on runs.

    Parameters
    ----------
    configured : str
        The add-on's preference ("" for none).

    Returns
    -------
    str
        The preference, else $MIMICA_COMMAND, else `mimica` on PATH; AddonError where none is found.
    """
    exe = configured or os.environ.get("MIMICA_COMMAND", "") or shutil.which("mimica") or ""
    if not exe or not (Path(exe).is_file() or shutil.which(exe)):
        raise AddonError("the mimica command was not found: install mimica (pip install mimica) and set its "
                         "path in the add-on's preferences")
    return exe


def write_obj(path, vertices, polygons) -> None:
    """An OBJ of a Blender mesh in its vertex order (1-based faces), turned from Blender's z up to
    mimica's y up (facts.Z_UP_TO_Y_UP), as Blender's own OBJ export does.

    Parameters
    ----------
    path : str or Path
    vertices : (n, 3) float array
        Blender's positions.
    polygons : list of tuple of int
        Each polygon's vertices.
    """
    import numpy as np
    turned = np.asarray(vertices, dtype=float).reshape(-1, 3) @ np.asarray(facts.Z_UP_TO_Y_UP).T
    with open(path, "w") as f:
        f.writelines(f"v {x:.9g} {y:.9g} {z:.9g}\n" for x, y, z in turned)
        f.writelines("f " + " ".join(str(i + 1) for i in p) + "\n" for p in polygons)


def to_blender(v):
    """Positions from mimica's y up back to Blender's z up: (x, -z, y).

    Parameters
    ----------
    v : (n, 3) float array

    Returns
    -------
    (n, 3) float array
    """
    import numpy as np
    return np.asarray(v, dtype=float) @ np.asarray(facts.Z_UP_TO_Y_UP)      # the turn's inverse: its transpose


def run_mimica(args, progress=None) -> list[str]:
    """Run mimica, its progress passed on.

    Parameters
    ----------
    args : list of str
        The command line.
    progress : callable, optional
        Called with each line mimica writes on stderr.

    Returns
    -------
    list of str
        Those lines; a failure raises AddonError with its last line.
    """
    proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    lines = []
    for line in proc.stderr:
        line = line.rstrip()
        if line:
            lines.append(line)
            if progress:
                progress(line)
    if proc.wait():
        raise AddonError(lines[-1] if lines else f"mimica stopped (exit status {proc.returncode})")
    return lines


class Shapes(dict):
    """{name: (n, 3) positions} with where mimica cut the head.

    Attributes
    ----------
    cut : dict or None
        Where mimica cut the head (sealed lips, one-surface eyes), to apply to the mesh before the
        shape keys: {"copies": (k,) the vertex each added one copies, "corners": (m, 3) rows
        (polygon, corner, added vertex)}; None where nothing was cut.
    """
    cut = None


def arkit_shapes(vertices, polygons, exe: str, progress=None) -> dict:
    """The 52 ARKit shapes of a head given as Blender's vertices and polygons (`mimica blendshapes`).

    Parameters
    ----------
    vertices : (n, 3) float array
    polygons : list of tuple of int
    exe : str
        The mimica command.
    progress : callable, optional
        Called with each of mimica's progress lines.

    Returns
    -------
    Shapes
        {ARKit name: (n + k, 3) positions in Blender's frame}, k the vertices of any cut (after the
        head's).
    """
    import numpy as np
    with tempfile.TemporaryDirectory(prefix="mimica-blender-") as d:
        obj, out = Path(d) / "head.obj", Path(d) / "shapes.npz"
        write_obj(obj, vertices, polygons)
        run_mimica([exe, "blendshapes", str(obj), "--out", str(out)], progress)
        with np.load(out) as z:
            added = z["vertices"].shape[0] - len(vertices)
            if added < 0 or (added and "cut_copies" not in z.files):
                raise AddonError(f"mimica gave {z['vertices'].shape[0]} vertices for a head of {len(vertices)}")
            shapes = Shapes((n, to_blender(z[n])) for n in ARKIT if n in z)
            if added:
                shapes.cut = {"copies": z["cut_copies"].copy(), "corners": z["cut_corners"].copy()}
            return shapes


def read_obj_vertices(path):
    """The vertex positions of an OBJ mimica wrote.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    (n, 3) float array
        Its `v` lines, in order.
    """
    import numpy as np
    with open(path) as f:
        rows = [ln.split()[1:4] for ln in f if ln.startswith("v ")]
    return np.array(rows, dtype=float)


def transfer_shapes(source_vertices, polygons, shapes: dict, target_vertices, target_polygons, exe: str,
                    progress=None) -> dict:
    """The source's shapes moved onto the target by `mimica transfer` (any topology).

    Parameters
    ----------
    source_vertices : (n, 3) float array
        The source at rest.
    polygons : list of tuple of int
        The source's polygons.
    shapes : dict
        {name: (n, 3) positions} of the source.
    target_vertices : (m, 3) float array
    target_polygons : list of tuple of int
    exe : str
        The mimica command.
    progress : callable, optional

    Returns
    -------
    dict
        {name: (m, 3) target positions}.
    """
    with tempfile.TemporaryDirectory(prefix="mimica-blender-") as d:
        d = Path(d)
        (d / "shapes").mkdir()
        write_obj(d / "source.obj", source_vertices, polygons)
        write_obj(d / "target.obj", target_vertices, target_polygons)
        files = {}
        for i, (name, pos) in enumerate(shapes.items()):
            files[name] = f"s{i:04d}.obj"                      # names a file system takes
            write_obj(d / "shapes" / files[name], pos, polygons)
        run_mimica([exe, "transfer", str(d / "source.obj"), str(d / "shapes"), "--target", str(d / "target.obj"),
                    "--cut-mouth", "off", "--out", str(d / "out")], progress)
        out = {}
        for name, fn in files.items():
            v = read_obj_vertices(d / "out" / fn)
            if len(v) != len(target_vertices):
                raise AddonError(f"mimica gave {len(v)} vertices for a target of {len(target_vertices)}")
            out[name] = to_blender(v)
        return out




def simulated_shapes(vertices, polygons, expressions, exe: str, progress=None, seconds: float = 1.0) -> dict:
    """Kim's muscles rigged on the head (`mimica rig`) and each preset expression simulated
    (`mimica simulate`), its last frame.

    Parameters
    ----------
    vertices : (n, 3) float array
    polygons : list of tuple of int
    expressions : list of str
        Presets (facts.EXPRESSIONS).
    exe : str
        The mimica command.
    progress : callable, optional
    seconds : float
        How long each is simulated.

    Returns
    -------
    dict
        {"muscles_<expression>": (n, 3) positions}.
    """
    with tempfile.TemporaryDirectory(prefix="mimica-blender-") as d:
        d = Path(d)
        write_obj(d / "head.obj", vertices, polygons)
        run_mimica([exe, "rig", str(d / "head.obj"), "--out", str(d / "head.rig")], progress)
        out = {}
        for e in expressions:
            run_mimica([exe, "simulate", str(d / "head.rig"), "--expression", e, "--duration", str(seconds),
                        "--fps", "30", "--no-refine", "--out", str(d / e)], progress)
            last = sorted((d / e).glob("frame_*.obj"))[-1]
            v = read_obj_vertices(last)
            if len(v) != len(vertices):
                raise AddonError(f"mimica simulated {len(v)} vertices for a head of {len(vertices)}")
            out[f"muscles_{e}"] = to_blender(v)
        return out


def read_take(path, fps: float | None = None):
    """A take's times and ARKit weights (facts.take_from_rows, as mimica reads takes).

    Parameters
    ----------
    path : str or Path
        A Live Link Face CSV (Timecode HH:MM:SS:FF.fff, PascalCase names) or a CSV with a `time`
        column.
    fps : float or None
        The Timecode's frame rate (None: one more than its largest frame number).

    Returns
    -------
    times : list of float
        Seconds from the start.
    weights : dict
        {ARKit name: list of float}; AddonError for a take that cannot be read.
    """
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:
            rows = list(csv.reader(f))
        times, weights, _ = facts.take_from_rows(rows, path, fps)
    except (OSError, UnicodeDecodeError, csv.Error) as e:
        raise AddonError(f"{path}: cannot read the take ({e})") from None
    except facts.TakeError as e:
        raise AddonError(str(e)) from None
    return times, {n: weights[n] for n in ARKIT}


if bpy is not None:  # pragma: no cover - runs inside Blender (tests/blender_addon/test_blender.py drives it headless)

    class MimicaPreferences(bpy.types.AddonPreferences):
        bl_idname = __name__
        command: bpy.props.StringProperty(name="mimica command", subtype="FILE_PATH",
                                          description="the mimica executable (default: mimica on PATH)")

        def draw(self, context):
            self.layout.prop(self, "command")

    def _command(context) -> str:
        prefs = context.preferences.addons.get(__name__)
        return mimica_command(prefs.preferences.command if prefs else "")

    def _shape_keys_from(obj, shapes: dict) -> None:
        """Shape keys from {name: (n, 3) world positions}."""
        me = obj.data
        if me.shape_keys is None:
            obj.shape_key_add(name="Basis", from_mix=False)
        for name, pos in shapes.items():
            kb = me.shape_keys.key_blocks.get(name) or obj.shape_key_add(name=name, from_mix=False)
            kb.data.foreach_set("co", _local(obj, pos).astype("float32").ravel())

    def _fcurves(action) -> list:
        """An action's F-curves: Blender 4.4+ keeps them in layers, strips and channel bags."""
        if action is None:
            return []
        if hasattr(action, "layers") and len(action.layers):
            return [fc for layer in action.layers for strip in layer.strips for bag in strip.channelbags
                    for fc in bag.fcurves]
        return list(action.fcurves)

    def _world(obj, local):
        """(n, 3) object-space positions in the world (z up): mimica sees the head standing as it
        stands in the scene, whether its mesh data is z up or an import turned by its object."""
        import numpy as np
        m = np.array(obj.matrix_world)
        return np.asarray(local, dtype=float) @ m[:3, :3].T + m[:3, 3]

    def _local(obj, world):
        import numpy as np
        m = np.array(obj.matrix_world)
        return (np.asarray(world, dtype=float) - m[:3, 3]) @ np.linalg.inv(m[:3, :3]).T

    def _mesh_arrays(obj):
        """The mesh's vertices in the world and its polygons."""
        me = obj.data
        return _world(obj, [tuple(v.co) for v in me.vertices]), [tuple(p.vertices) for p in me.polygons]

    def _with_progress(context, work):
        """Run work(progress) with Blender's progress bar and status text; AddonError passes."""
        wm = context.window_manager
        wm.progress_begin(0, 100)
        step = [0]

        def progress(line):
            step[0] = min(step[0] + 5, 95)
            wm.progress_update(step[0])
            if context.workspace is not None:
                context.workspace.status_text_set(f"mimica: {line}")
        try:
            return work(progress)
        finally:
            wm.progress_end()
            if context.workspace is not None:
                context.workspace.status_text_set(None)

    def _make_shape_keys(op, context, make, what: str):
        """An operator's work: shape keys on the active mesh from make(vertices, polygons,
        command, progress) -> {name: world positions}; errors as the operator's reports."""
        obj = context.active_object
        if obj is None or obj.type != "MESH":
            op.report({"ERROR"}, "select a head mesh first")
            return {"CANCELLED"}
        verts, polys = _mesh_arrays(obj)
        try:
            shapes = _with_progress(context, lambda pr: make(verts, polys, _command(context), pr))
        except AddonError as e:
            op.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        cut = getattr(shapes, "cut", None)
        if cut is not None:
            _split(obj, cut)
        _shape_keys_from(obj, shapes)
        op.report({"INFO"}, f"{len(shapes)} {what} shape keys on {obj.name}"
                  + (f"; its sealed lips or eyes cut apart, {len(cut['copies'])} vertices added after its own "
                     "(Edit > Undo takes it back)" if cut is not None else ""))
        return {"FINISHED"}

    def _split(obj, cut) -> None:
        """mimica's cut applied to the mesh: copies of the listed vertices added after its own,
        the listed polygon corners moved onto them (materials, smoothing and uv kept)."""
        import bmesh
        bm = bmesh.new()
        bm.from_mesh(obj.data)
        bm.verts.ensure_lookup_table()
        bm.faces.ensure_lookup_table()
        uv = bm.loops.layers.uv.active
        old = [bm.verts[int(i)] for i in cut["copies"]]       # (before any is added: the table goes stale)
        new = [bm.verts.new(v.co) for v in old]
        for layer in bm.verts.layers.shape.values():          # the mesh's own shape keys: the copies too
            for v, o in zip(new, old):
                v[layer] = o[layer]
        rows = cut["corners"]
        faces = {int(f): bm.faces[int(f)] for f in set(rows[:, 0].tolist())}
        for f, face in faces.items():
            verts = [lp.vert for lp in face.loops]
            uvs = [lp[uv].uv.copy() for lp in face.loops] if uv is not None else None
            for _, c, k in rows[rows[:, 0] == f]:
                verts[int(c)] = new[int(k)]
            nf = bm.faces.new(verts, face)
            if uvs is not None:
                for lp, t in zip(nf.loops, uvs):
                    lp[uv].uv = t
            bm.faces.remove(face)
        bm.to_mesh(obj.data)
        bm.free()
        obj.data.update()

    class MIMICA_OT_arkit_shape_keys(bpy.types.Operator):
        """Put the 52 ARKit shapes on the active mesh as shape keys (mimica blendshapes)"""
        bl_idname = "mimica.arkit_shape_keys"
        bl_label = "ARKit shape keys"
        bl_options = {"REGISTER", "UNDO"}

        def execute(self, context):
            return _make_shape_keys(self, context, arkit_shapes, "ARKit")

    class MIMICA_OT_transfer_shape_keys(bpy.types.Operator):
        """Move the active mesh's shape keys onto the other selected meshes (mimica transfer, any topology)"""
        bl_idname = "mimica.transfer_shape_keys"
        bl_label = "Transfer shape keys"
        bl_options = {"REGISTER", "UNDO"}

        def execute(self, context):
            src = context.active_object
            keys = src.data.shape_keys.key_blocks if src and src.type == "MESH" and src.data.shape_keys else None
            targets = [o for o in context.selected_objects if o.type == "MESH" and o != src]
            if keys is None or len(keys) < 2 or not targets:
                self.report({"ERROR"}, "make the source (with shape keys) active and select the target meshes too")
                return {"CANCELLED"}
            import numpy as np

            def world(kb):                                # a shape key's positions in the world
                a = np.zeros(len(kb.data) * 3)
                kb.data.foreach_get("co", a)
                return _world(src, a.reshape(-1, 3))
            rest = world(keys[0])
            shapes = {kb.name: world(kb) for kb in keys[1:]}
            polys = [tuple(p.vertices) for p in src.data.polygons]
            try:
                for tgt in targets:
                    tv, tp = _mesh_arrays(tgt)
                    got = _with_progress(context, lambda pr: transfer_shapes(rest, polys, shapes, tv, tp,
                                                                             _command(context), pr))
                    _shape_keys_from(tgt, got)
            except AddonError as e:
                self.report({"ERROR"}, str(e))
                return {"CANCELLED"}
            self.report({"INFO"}, f"{len(shapes)} shape keys on {', '.join(o.name for o in targets)}")
            return {"FINISHED"}

    class MIMICA_OT_muscle_shape_keys(bpy.types.Operator):
        """Rig Kim's muscles on the active mesh and simulate expressions into shape keys (mimica rig, simulate)"""
        bl_idname = "mimica.muscle_shape_keys"
        bl_label = "Muscle shape keys"
        bl_options = {"REGISTER", "UNDO"}
        expressions: bpy.props.EnumProperty(name="Expressions", options={"ENUM_FLAG"},
                                            items=[(e, e, f"simulate {e}") for e in EXPRESSIONS],
                                            default={"happiness"})

        def execute(self, context):
            return _make_shape_keys(self, context, lambda v, p, exe, pr: simulated_shapes(
                v, p, sorted(self.expressions), exe, pr), "muscle")

    class MIMICA_OT_live_link_take(bpy.types.Operator):
        """Key a Live Link Face take (CSV) onto the active mesh's ARKit shape keys"""
        bl_idname = "mimica.live_link_take"
        bl_label = "Apply Live Link take"
        bl_options = {"REGISTER", "UNDO"}
        filepath: bpy.props.StringProperty(subtype="FILE_PATH")

        def invoke(self, context, event):
            context.window_manager.fileselect_add(self)
            return {"RUNNING_MODAL"}

        def execute(self, context):
            obj = context.active_object
            keys = obj.data.shape_keys.key_blocks if obj and obj.type == "MESH" and obj.data.shape_keys else None
            if keys is None:
                self.report({"ERROR"}, "the active object has no shape keys: make the ARKit shape keys first")
                return {"CANCELLED"}
            try:
                times, weights = read_take(self.filepath)
            except (AddonError, OSError) as e:
                self.report({"ERROR"}, str(e))
                return {"CANCELLED"}
            fps = context.scene.render.fps / context.scene.render.fps_base
            start = context.scene.frame_start
            n = 0
            plays = facts.arkit_targets(kb.name for kb in keys)      # other tools' names too (EyeBlinkLeft ...)
            for name, w in weights.items():
                kb = keys.get(plays.get(name, name))
                if kb is None:
                    continue
                n += 1
                for t, x in zip(times, w):
                    kb.value = x
                    kb.keyframe_insert("value", frame=start + t * fps)
            # linear between the take's samples (as glTF plays them), not Blender's default Bezier
            anim = obj.data.shape_keys.animation_data
            for fc in _fcurves(anim.action if anim else None):
                if fc.data_path.startswith("key_blocks[") and fc.data_path.endswith(".value"):
                    for kp in fc.keyframe_points:
                        kp.interpolation = "LINEAR"
            context.scene.frame_end = int(start + times[-1] * fps)
            self.report({"INFO"}, f"{len(times)} frames keyed on {n} shape keys")
            return {"FINISHED"}

    class MIMICA_PT_panel(bpy.types.Panel):
        bl_label = "mimica"
        bl_space_type = "VIEW_3D"
        bl_region_type = "UI"
        bl_category = "mimica"

        def draw(self, context):
            self.layout.operator(MIMICA_OT_arkit_shape_keys.bl_idname)
            self.layout.operator(MIMICA_OT_live_link_take.bl_idname)
            self.layout.operator(MIMICA_OT_transfer_shape_keys.bl_idname)
            self.layout.operator(MIMICA_OT_muscle_shape_keys.bl_idname)

    _CLASSES = (MimicaPreferences, MIMICA_OT_arkit_shape_keys, MIMICA_OT_live_link_take, MIMICA_OT_transfer_shape_keys,
                MIMICA_OT_muscle_shape_keys, MIMICA_PT_panel)

    def register():
        for c in _CLASSES:
            bpy.utils.register_class(c)

    def unregister():
        for c in reversed(_CLASSES):
            bpy.utils.unregister_class(c)
