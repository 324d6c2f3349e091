"""Run inside Blender's Python (bpy), by tests/mesh/test_foreign_files.py and bench/foreign_files.py:
Blender as the other tool a user's files come from and go back to.

    python-with-bpy blender_files.py export HEAD.obj|HEAD.glb|HEAD.fbx OUT.glb|OUT.fbx
        Blender's OBJ (glTF, FBX) importer, then its glTF or FBX exporter, all with their
        defaults: a file as a user's round trip through Blender writes it back.
    python-with-bpy blender_files.py export-draco HEAD.obj|HEAD.glb|HEAD.fbx OUT.glb
        the same with the glTF exporter's Draco mesh compression on (its default settings).
    python-with-bpy blender_files.py import FILE.glb|FILE.fbx OUT.json
        the file imported as a user imports it; OUT.json: each mesh object's name, world matrix,
        vertex count, world-space vertices (OUT.json's .npz beside it), materials, shape keys and
        the largest move of each key; the scene's rate and frame range, and where the shape keys
        are animated, each key's value at every frame.
"""

import json
import sys
from pathlib import Path

import bpy
import numpy as np

mode, src, out = sys.argv[-3:]
bpy.ops.wm.read_factory_settings(use_empty=True)
# the file imported as a user imports it: Blender's importer for its suffix
{".fbx": bpy.ops.import_scene.fbx, ".glb": bpy.ops.import_scene.gltf,
 ".gltf": bpy.ops.import_scene.gltf}.get(Path(src).suffix.lower(), bpy.ops.wm.obj_import)(filepath=src)
if mode in ("export", "export-draco"):
    if out.lower().endswith(".fbx"):
        bpy.ops.export_scene.fbx(filepath=out)
    else:
        bpy.ops.export_scene.gltf(filepath=out, export_draco_mesh_compression_enable=mode == "export-draco")
    sys.exit(0)

report, arrays = {"objects": []}, {}
for obj in bpy.data.objects:
    if obj.type != "MESH":
        continue
    m = np.array(obj.matrix_world)
    co = np.zeros(len(obj.data.vertices) * 3)
    obj.data.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)
    world = co @ m[:3, :3].T + m[:3, 3]
    keys = {}
    if obj.data.shape_keys:
        for kb in obj.data.shape_keys.key_blocks:
            a = np.zeros(len(kb.data) * 3)
            kb.data.foreach_get("co", a)
            keys[kb.name] = float(np.linalg.norm((a.reshape(-1, 3) - co) @ m[:3, :3].T, axis=1).max())
    arrays[obj.name] = world
    report["objects"].append({"name": obj.name, "matrix": m.tolist(), "vertices": len(co),
                              "materials": [s.material.name if s.material else None for s in obj.material_slots],
                              "shape_keys": keys})
# an animation of the shape keys, as the file plays it: each key's value at every frame of the scene
scene = bpy.context.scene
report["fps"] = scene.render.fps / scene.render.fps_base
report["frames"] = [scene.frame_start, scene.frame_end]
animated = [o for o in bpy.data.objects if o.type == "MESH" and o.data.shape_keys
            and o.data.shape_keys.animation_data and o.data.shape_keys.animation_data.action]
report["key_values"] = {o.name: {kb.name: [] for kb in o.data.shape_keys.key_blocks[1:]} for o in animated}
for f in range(scene.frame_start, scene.frame_end + 1) if animated else ():
    scene.frame_set(f)
    for o in animated:
        for kb in o.data.shape_keys.key_blocks[1:]:
            report["key_values"][o.name][kb.name].append(kb.value)
np.savez(str(Path(out).with_suffix(".npz")), **arrays)
Path(out).write_text(json.dumps(report))
