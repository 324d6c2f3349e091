"""Run by Blender's Python (bpy); mimica runs it, never uses it (it imports without Blender): FBX read and written through
Blender's own FBX importer and exporter, the one FBX path kept up for character heads that a
Python program can drive.  (Blender's Python carries numpy < 2 and mimica numpy >= 2: the two
talk through files.)

    read  FILE.fbx OUT      OUT.json: each mesh object's name, world matrix (Blender's z up),
                            materials, shape key names; OUT.npz: per object i its vertices
                            (v{i}), polygon sizes (s{i}), corners (c{i}), uv per corner (u{i}),
                            material per polygon (m{i}), shape keys (k{i}_{j}), all local
    write FILE.fbx IN OUT   IN.json / IN.npz: per object, shape keys to add (k{i}_{j}: each vertex's
                            move, local, the object's vertices then the added ones) and vertices to add
                            (a{i}: positions; r{i}: (polygon, corner, new vertex) rows re-pointing
                            corners to them); the file imported, edited and exported to OUT
    take  FILE.fbx IN OUT   IN.json: the take's rate and its weights' ARKit names; IN.npz: the
                            times (t) and the weights (w: frames x names); each object's shape keys
                            named as ARKit shapes keyed at each time (linear between), exported to
                            OUT with its animation; IN.keyed.json: the keys keyed
"""

import json
import sys
from pathlib import Path

import numpy as np


def objects():
    """The scene's mesh objects (in Blender).

    Returns
    -------
    list of bpy.types.Object
    """
    import bpy
    return [o for o in bpy.context.scene.objects if o.type == "MESH"]


def import_fbx(path):
    """Import an FBX into an empty scene (Blender's importer, its defaults).

    Parameters
    ----------
    path : str
    """
    import bpy
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_scene.fbx(filepath=path)


def read(path, out):
    """Read an FBX for mimica: the objects' arrays and facts (the module's `read`).

    Parameters
    ----------
    path : str
        The FBX.
    out : str
        Written: OUT.json and OUT.npz.
    """
    import_fbx(path)
    report, arrays = [], {}
    for i, o in enumerate(objects()):
        me = o.data
        v = np.zeros(len(me.vertices) * 3)
        me.vertices.foreach_get("co", v)
        sizes = np.zeros(len(me.polygons), np.int64)
        me.polygons.foreach_get("loop_total", sizes)
        corners = np.zeros(len(me.loops), np.int64)
        me.loops.foreach_get("vertex_index", corners)
        mats = np.zeros(len(me.polygons), np.int64)
        me.polygons.foreach_get("material_index", mats)
        arrays[f"v{i}"], arrays[f"s{i}"], arrays[f"c{i}"], arrays[f"m{i}"] = v.reshape(-1, 3), sizes, corners, mats
        if me.uv_layers.active is not None:
            uv = np.zeros(len(me.loops) * 2)
            me.uv_layers.active.data.foreach_get("uv", uv)
            arrays[f"u{i}"] = uv.reshape(-1, 2)
        keys = []
        if me.shape_keys is not None:
            for j, kb in enumerate(me.shape_keys.key_blocks):
                k = np.zeros(len(kb.data) * 3)
                kb.data.foreach_get("co", k)
                arrays[f"k{i}_{j}"] = k.reshape(-1, 3)
                keys.append(kb.name)
        report.append({"name": o.name, "matrix": [list(r) for r in o.matrix_world],
                       "materials": [s.material.name if s.material else "" for s in o.material_slots],
                       "shape_keys": keys, "parent": o.parent.name if o.parent else None,
                       "armature": any(m.type == "ARMATURE" for m in o.modifiers)})
    np.savez(out + ".npz", **arrays)
    Path(out + ".json").write_text(json.dumps({"objects": report}))


def write(path, edits, out):
    """Add shape keys and vertices to an FBX's objects and export it (the module's `write`).

    Parameters
    ----------
    path : str
        The FBX read.
    edits : str
        IN: IN.json and IN.npz.
    out : str
        The FBX written.
    """
    import bpy
    import bmesh                                  # (bpy's package brings bmesh: bpy first)
    import_fbx(path)
    spec = json.loads(Path(edits + ".json").read_text())
    z = np.load(edits + ".npz")
    obs = {o.name: o for o in objects()}
    for i, ob in enumerate(spec["objects"]):
        o = obs[ob["name"]]
        if f"a{i}" in z.files and len(z[f"a{i}"]):            # the cut's vertices, after the object's own
            bm = bmesh.new()
            bm.from_mesh(o.data)
            bm.verts.ensure_lookup_table()
            bm.faces.ensure_lookup_table()
            uv = bm.loops.layers.uv.active
            new = [bm.verts.new(p) for p in z[f"a{i}"]]
            rows = z[f"r{i}"]
            # (as blender_addon._split does: each runs alone in Blender, neither can import mimica)
            faces = {int(f): bm.faces[int(f)] for f in np.unique(rows[:, 0])}      # before any is replaced
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
            bm.to_mesh(o.data)
            bm.free()
        if ob["keys"] and o.data.shape_keys is None:
            o.shape_key_add(name="Basis", from_mix=False)
        base = np.zeros(len(o.data.vertices) * 3)
        o.data.vertices.foreach_get("co", base)
        for j, name in enumerate(ob["keys"]):
            kb = o.shape_key_add(name=name, from_mix=False)
            kb.data.foreach_set("co", (base + z[f"k{i}_{j}"].ravel()).astype(np.float32))
    bpy.ops.export_scene.fbx(filepath=out)


def take(path, keyed, out):
    """Key a take's ARKit weights on an FBX's shape keys named as ARKit shapes (mimica's
    facts.arkit_targets) and export it with the animation (the module's `take`).

    Parameters
    ----------
    path : str
        The FBX read.
    keyed : str
        IN: IN.json ({"fps": rate, "names": the weights' ARKit names}) and IN.npz (t: seconds,
        w: frames x names); IN.keyed.json written: the shape keys keyed.
    out : str
        The FBX written (where any key was).
    """
    import bpy
    facts = _facts()
    import_fbx(path)
    spec = json.loads(Path(keyed + ".json").read_text())
    z = np.load(keyed + ".npz")
    column = {n: j for j, n in enumerate(spec["names"])}
    scene = bpy.context.scene
    rate = float(spec["fps"])
    scene.render.fps = max(1, int(round(rate)))
    scene.render.fps_base = scene.render.fps / rate
    frames = z["t"] * rate                           # the take's start at the file's time 0
    scene.frame_start, scene.frame_end = 0, int(round(frames[-1]))
    done = []
    for o in objects():
        keys = o.data.shape_keys
        plays = facts.arkit_targets(kb.name for kb in keys.key_blocks) if keys is not None else {}
        for arkit, name in plays.items():
            if arkit not in column:
                continue
            kb = keys.key_blocks[name]
            for f, x in zip(frames, z["w"][:, column[arkit]]):
                kb.value = float(x)
                kb.keyframe_insert("value", frame=float(f))
            done.append(name)
        act = keys.animation_data.action if keys is not None and keys.animation_data else None
        for fc in (_fcurves(act) if act is not None else []):          # linear, as glTF plays a take
            for kp in fc.keyframe_points:
                kp.interpolation = "LINEAR"
    Path(keyed + ".keyed.json").write_text(json.dumps(done))
    if done:
        bpy.ops.export_scene.fbx(filepath=out, bake_anim=True, bake_anim_use_all_actions=False,
                                 bake_anim_use_nla_strips=False)


def _facts():
    """mimica's facts.py (the ARKit names), loaded by its path: Blender's Python cannot import
    mimica (numpy < 2 there), and facts imports nothing of it."""
    import importlib.util
    spec = importlib.util.spec_from_file_location("mimica_facts", Path(__file__).resolve().parents[2] / "facts.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _fcurves(action):
    """An action's F-curves: Blender 4.4+ keeps them in layers, strips and channel bags (as the
    add-on reads them; neither script can import the other)."""
    if hasattr(action, "layers") and len(action.layers):
        return [fc for layer in action.layers for strip in layer.strips for bag in strip.channelbags
                for fc in bag.fcurves]
    return list(action.fcurves)


if __name__ == "__main__":
    args = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    if args[0] == "read":
        read(args[1], args[2])
    elif args[0] == "take":
        take(args[1], args[2], args[3])
    else:
        write(args[1], args[2], args[3])
