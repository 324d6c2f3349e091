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
    take  FILE.fbx IN OUT   IN.json: the take's rate and, per object, the shape keys it keys;
                            IN.npz: the times (t) and per object i the keys' values (w{i}: frames x
                            keys); keyed at each time (linear between), exported to OUT with its
                            animation
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
    """Key a take's weights on an FBX's shape keys and export it with the animation (the
    module's `take`).

    Parameters
    ----------
    path : str
        The FBX read.
    keyed : str
        IN: IN.json ({"fps": rate, "objects": [{"name", "keys"}]}) and IN.npz (t, w{i}).
    out : str
        The FBX written.
    """
    import bpy
    import_fbx(path)
    spec = json.loads(Path(keyed + ".json").read_text())
    z = np.load(keyed + ".npz")
    scene = bpy.context.scene
    rate = float(spec["fps"])
    scene.render.fps = max(1, int(round(rate)))
    scene.render.fps_base = scene.render.fps / rate
    frames = z["t"] * rate                           # the take's start at the file's time 0
    scene.frame_start, scene.frame_end = 0, int(round(frames[-1]))
    obs = {o.name: o for o in objects()}
    for i, ob in enumerate(spec["objects"]):
        keys = obs[ob["name"]].data.shape_keys
        w = z[f"w{i}"]
        for j, name in enumerate(ob["keys"]):
            kb = keys.key_blocks[name]
            for f, x in zip(frames, w[:, j]):
                kb.value = float(x)
                kb.keyframe_insert("value", frame=float(f))
        act = keys.animation_data.action if keys.animation_data else None
        for fc in (_fcurves(act) if act is not None else []):          # linear, as glTF plays a take
            for kp in fc.keyframe_points:
                kp.interpolation = "LINEAR"
    bpy.ops.export_scene.fbx(filepath=out, bake_anim=True, bake_anim_use_all_actions=False,
                             bake_anim_use_nla_strips=False)


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
