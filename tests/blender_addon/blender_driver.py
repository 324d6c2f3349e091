"""Run inside Blender's Python (bpy), by tests/blender_addon/test_blender.py: the add-on's four operators on
real meshes, headless; what they made is written as JSON for the test to check.

    python-with-bpy blender_driver.py mimica_blender.zip HEAD.obj TAKE.csv OUT.json [GLB ...]

and each GLB given after them imported as a user would (File > Import > glTF): its vertices,
smooth shading, uv layers, materials, shape keys, armature; the first also through FBX and back.
"""

import json
import os
import sys
from pathlib import Path

import bpy
import numpy as np

addon_zip, head_obj, take_csv, out_json, *glbs = sys.argv[1:]
bpy.ops.wm.read_factory_settings(use_empty=True)
# installed as a user installs it (Edit > Preferences > Add-ons > Install from disk, then enabled)
assert bpy.ops.preferences.addon_install(filepath=addon_zip, overwrite=True) == {"FINISHED"}
assert bpy.ops.preferences.addon_enable(module="mimica_blender") == {"FINISHED"}
report = {}


def keys(obj, world=True):
    """{name: (n, 3)} of the shape keys, in the world (the OBJ import turns its object, not its data)."""
    m = np.array(obj.matrix_world) if world else np.eye(4)
    out = {}
    for kb in obj.data.shape_keys.key_blocks:
        a = np.zeros(len(kb.data) * 3)
        kb.data.foreach_get("co", a)
        out[kb.name] = a.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]
    return out


def select(active, *others):
    bpy.ops.object.select_all(action="DESELECT")
    for o in (active, *others):
        o.select_set(True)
    bpy.context.view_layer.objects.active = active


bpy.ops.wm.obj_import(filepath=head_obj)                  # Blender's default axes: z up
head = bpy.context.selected_objects[0]
head.name = "head"
report["vertices"] = len(head.data.vertices)
rest = np.array([(head.matrix_world @ v.co)[:] for v in head.data.vertices])
report["height_z"] = float(np.ptp(rest[:, 2]))                 # standing: its height along z

select(head)
report["arkit"] = list(bpy.ops.mimica.arkit_shape_keys())
report["vertices_after"] = len(head.data.vertices)            # the sealed lips cut apart in Blender too
k = keys(head)
report["arkit_keys"] = len(k)
jaw = k["jawOpen"] - k["Basis"]
report["jaw_moves_down"] = float(jaw[:, 2].min())             # the chin goes down Blender's z
report["jaw_largest"] = float(np.linalg.norm(jaw, axis=1).max())

report["take"] = list(bpy.ops.mimica.live_link_take(filepath=take_csv))
scene = bpy.context.scene
report["fps"] = scene.render.fps / scene.render.fps_base
samples = {}
for f in (1, 11, 31):
    scene.frame_set(f)
    samples[str(f)] = {n: head.data.shape_keys.key_blocks[n].value for n in ("jawOpen", "eyeBlinkLeft")}
report["take_samples"] = samples

# a second head: the same mesh moved aside and scaled (another person, to Blender)
bpy.ops.wm.obj_import(filepath=head_obj)
other = bpy.context.selected_objects[0]
other.name = "other"
v = np.array([p.co[:] for p in other.data.vertices]) * 1.1
other.data.vertices.foreach_set("co", v.ravel())
other.location.x += 30.0
bpy.context.view_layer.update()
src_keys = {n: k[n] for n in ("Basis", "jawOpen", "mouthSmileLeft")}
# a source with three keys only (the transfer of all 52 would be slow here)
bpy.ops.wm.obj_import(filepath=head_obj)
src = bpy.context.selected_objects[0]
src.name = "source"
src.shape_key_add(name="Basis", from_mix=False)
local = keys(head, world=False)
for n in ("jawOpen", "mouthSmileLeft"):
    kb = src.shape_key_add(name=n, from_mix=False)
    kb.data.foreach_set("co", local[n].astype("float32").ravel())
select(src, other)
report["transfer"] = list(bpy.ops.mimica.transfer_shape_keys())
ko = keys(other)
report["transfer_keys"] = sorted(ko)
d_src = np.linalg.norm(src_keys["jawOpen"] - src_keys["Basis"], axis=1)
d_other = np.linalg.norm(ko["jawOpen"] - ko["Basis"], axis=1)
report["transfer_ratio"] = float(d_other.max() / d_src.max())      # about the scale, 1.1
report["transfer_jaw_down"] = float((ko["jawOpen"] - ko["Basis"])[:, 2].min())

select(other)
report["muscles"] = list(bpy.ops.mimica.muscle_shape_keys(expressions={"happiness"}))
km = keys(other)
report["muscle_largest"] = float(np.linalg.norm(km["muscles_happiness"] - km["Basis"], axis=1).max())

# keys another tool named (a Maya namespace and case, ICT's side suffix): the take keys them too
named = bpy.data.objects.new("named", head.data.copy())
bpy.context.collection.objects.link(named)
named.shape_key_clear()
named.shape_key_add(name="Basis", from_mix=False)
for n in ("blendShape1.JawOpen", "eyeBlink_L"):
    named.shape_key_add(name=n, from_mix=False)
select(named)
bpy.ops.mimica.live_link_take(filepath=take_csv)
report["named_take_samples"] = {}
for f in (1, 11, 31):
    scene.frame_set(f)
    report["named_take_samples"][str(f)] = {n: named.data.shape_keys.key_blocks[n].value
                                            for n in ("blendShape1.JawOpen", "eyeBlink_L")}

# an error: no shape keys on the active object -> a report, nothing changed
bpy.ops.mesh.primitive_cube_add()
cube = bpy.context.active_object
try:
    report["cube_take"] = list(bpy.ops.mimica.live_link_take(filepath=take_csv))
except RuntimeError as e:                 # Blender raises the operator's ERROR report
    report["cube_take_error"] = str(e)
# the shapes, in the world, for a picture (docs/figures/blender_addon.png)
np.savez(out_json[:-5] + ".npz", faces=np.array([p.vertices[:3] for p in head.data.polygons]),
         rest=k["Basis"], jawOpen=k["jawOpen"], mouthSmileLeft=k["mouthSmileLeft"], other=km["Basis"],
         other_jawOpen=km["jawOpen"], other_happiness=km["muscles_happiness"])
# GLBs as a user imports them
report["glb"] = {}
for i, glb in enumerate(glbs):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_scene.gltf(filepath=glb)
    meshes = [o for o in bpy.context.scene.objects if o.type == "MESH"]
    ob = max(meshes, key=lambda o: len(o.data.vertices))
    me = ob.data
    info = {"vertices": len(me.vertices), "smooth": all(p.use_smooth for p in me.polygons),
            "uv_layers": len(me.uv_layers), "materials": len([m for m in me.materials if m]),
            "shape_keys": len(me.shape_keys.key_blocks) if me.shape_keys else 0,
            "armature": any(o.type == "ARMATURE" for o in bpy.context.scene.objects),
            "height": float(np.ptp(np.array([(ob.matrix_world @ v.co)[:] for v in me.vertices])[:, 2]))}
    if me.shape_keys and len(me.shape_keys.key_blocks) > 1:
        kb = me.shape_keys.key_blocks
        a, b = np.zeros(len(me.vertices) * 3), np.zeros(len(me.vertices) * 3)
        kb[0].data.foreach_get("co", a)
        kb[1].data.foreach_get("co", b)
        info["first_key"] = kb[1].name
        info["first_key_largest"] = float(np.abs(b - a).max())
    if me.shape_keys and me.shape_keys.animation_data:
        scene = bpy.context.scene
        info["animated"] = {}
        for f in (0, 12):
            scene.frame_set(f)
            info["animated"][str(f)] = {k.name: k.value for k in me.shape_keys.key_blocks[1:4]}
    if i == 0:                                  # glTF -> FBX -> glTF keeps the vertices whole
        fbx = out_json[:-5] + ".fbx"
        bpy.ops.export_scene.fbx(filepath=fbx, use_selection=False)
        bpy.ops.wm.read_factory_settings(use_empty=True)
        bpy.ops.import_scene.fbx(filepath=fbx)
        back = max((o for o in bpy.context.scene.objects if o.type == "MESH"), key=lambda o: len(o.data.vertices))
        info["fbx_vertices"] = len(back.data.vertices)
        bpy.ops.export_scene.gltf(filepath=out_json[:-5] + "_roundtrip.glb")      # and on to glTF again
    report["glb"][Path(glb).name] = info

with open(out_json, "w") as f:
    json.dump(report, f)
sys.stdout.flush()
sys.stderr.flush()
# bpy (4.5) as a module hangs on a futex at interpreter exit after operators ran: leave at once
os._exit(0)
