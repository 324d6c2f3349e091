"""ARKit performances on a head: a Live Link Face take played on the 52
morph targets of a head mimica made blendshapes for.

A take is a CSV as Apple's Live Link Face app writes it -- `Timecode` (HH:MM:SS:FF.fff at the
take's frame rate), `BlendShapeCount`, the 52 ARKit weights in PascalCase (`EyeBlinkLeft` ...),
then head and eye rotations -- or any CSV of ARKit weights with a `time` column in seconds
(camelCase or PascalCase names).  `animate_glb` copies the head's GLB and adds an animation of
its morph target weights, one keyframe per row of the take; `animate_fbx` does the same for an
FBX head's shape keys.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from .. import facts
from ..errors import MimicaError
from ..mesh.io.gltf import read_accessor
from .extras import HEAD_KEY, stored_head  # noqa: F401  (the key, for readers of this module)


HEAD_ROTATION = list(facts.HEAD_ROTATION)     # Live Link Face: radians (ARKit's Euler angles)


def _json_rows(path: Path) -> list[list[str]]:
    """A JSON take as the CSV's rows: {"time": [seconds ...], "jawOpen": [...], ...} (columns) or
    [{"time": t, "jawOpen": w, ...}, ...] (one object a frame)."""
    from ..mesh.io import read_json
    data = read_json(path, "take")
    if isinstance(data, dict) and isinstance(data.get("time"), list):
        header = list(data)
        cols = [data[h] if isinstance(data[h], list) else [] for h in header]
        n = len(data["time"])
        if any(len(c) != n for c in cols):
            bad = next(h for h, c in zip(header, cols) if len(c) != n)
            raise MimicaError(f"{path}: {bad!r} has not one value per time ({n})")
        return [header] + [[str(c[i]) for c in cols] for i in range(n)]
    if isinstance(data, list) and data and all(isinstance(r, dict) for r in data):
        header = list(data[0])
        return [header] + [[str(r.get(h, "")) for h in header] for r in data]
    raise MimicaError(f"{path}: a JSON take is {{\"time\": [...], \"jawOpen\": [...], ...}} or a list of "
                      "{\"time\": t, \"jawOpen\": w, ...} frames")


def read_take(path, fps: float | None = None) -> tuple[np.ndarray, dict, float]:
    """A take: the 52 ARKit weights over time, from a CSV (Live Link Face's, or with a `time`
    column) or a JSON file.

    Parameters
    ----------
    path : str or Path
        The take (facts.take_from_rows reads its rows).
    fps : float or None
        The frame rate of a Timecode column (None: one more than the largest frame number in
        the take, e.g. 60 for frames 0-59).

    Returns
    -------
    times : (F,) float array
        Seconds from the take's first frame.
    weights : dict
        {ARKit name: (F,) float array}; the head's rotation, where the take has it, as
        headYaw, headPitch, headRoll (radians).
    rate : float
        The Timecode's frame rate, or the median of the time column's steps.
    """
    path = Path(path)
    if path.suffix.lower() == ".json":
        rows = _json_rows(path)
    else:
        try:
            with open(path, newline="", encoding="utf-8-sig") as f:
                rows = list(csv.reader(f))
        except OSError as e:
            raise MimicaError(f"{path}: cannot read the take ({e.strerror})") from None
        except (UnicodeDecodeError, csv.Error) as e:
            raise MimicaError(f"{path}: not a CSV file ({e})") from None
    try:
        times, weights, rate = facts.take_from_rows(rows, path, fps)
    except facts.TakeError as e:
        raise MimicaError(str(e)) from None
    times = np.asarray(times, float)
    weights = {n: np.asarray(w, float) for n, w in weights.items()}
    if rate is None:
        rate = float(1.0 / np.median(np.diff(times))) if len(times) > 1 else 0.0
    return times, weights, rate


def animate_fbx(head_fbx, out, times: np.ndarray, weights: dict, rate: float) -> dict:
    """Write `out`: the head's FBX with the take keyed on its shape keys named as ARKit shapes
    (facts.arkit_targets), one key a frame, linear between (through Blender, as every FBX
    mimica writes: mesh.io.fbx.write_fbx_take); everything else of the file as Blender's
    importer and exporter carry it.

    Parameters
    ----------
    head_fbx : str or Path
        An FBX head with ARKit shape keys (`blendshapes --out head.fbx` adds them).
    out : str or Path
        The FBX to write.
    times : (F,) float array
        Seconds.
    weights : dict
        {ARKit name: (F,) float array}.
    rate : float
        The take's frames a second (30 where unknown).

    Returns
    -------
    dict
        {"driven": how many shape keys the take drives, "pivot": None, "bending": 0}.
    """
    from ..mesh.io.fbx import write_fbx_take
    arkit = {n: w for n, w in weights.items() if n in facts.ARKIT_52}
    keyed = write_fbx_take(out, head_fbx, times, rate if rate and rate > 0 else 30.0, arkit)
    if not keyed:
        raise MimicaError(f"{head_fbx}: no object with shape keys named as ARKit shapes (make them with "
                          "`blendshapes`)")
    return {"driven": len(set(keyed)), "pivot": None, "bending": 0}


def head_quaternions(yaw, pitch, roll) -> np.ndarray:
    """glTF quaternions of the head's rotation, each next to the last (glTF's slerp between
    keyframes then takes the short way).

    Parameters
    ----------
    yaw, pitch, roll : (F,) float arrays
        Radians: yaw about the head's up (y), pitch about its left-right axis (x), roll about its
        forward axis (z), turned in that order (R = Ry Rx Rz, right-handed, the face looking
        along +z as mimica's heads do).

    Returns
    -------
    (F, 4) float32 array
        (x, y, z, w).
    """
    from scipy.spatial.transform import Rotation
    q = Rotation.from_euler("YXZ", np.stack([yaw, pitch, roll], 1)).as_quat()
    # q and -q are one rotation: keep each next to the last, so that glTF's slerp between
    # keyframes takes the short way
    flip = np.r_[False, (q[1:] * q[:-1]).sum(1) < 0]
    return (q * np.where(np.logical_xor.accumulate(flip), -1.0, 1.0)[:, None]).astype(np.float32)


def neck_weights(y: np.ndarray, pivot_y: float, chin_y: float | None) -> np.ndarray:
    """How much each vertex turns with the head: 1 from the chin up, easing (smoothstep) to 0 at
    the mesh's lowest point, so that a neck bends and the shoulders stay.

    Parameters
    ----------
    y : (n,) float array
        Each vertex's height.
    pivot_y : float
        The head's pivot's height.
    chin_y : float or None
        The chin's height; None, or a face that ends at its chin: it turns whole.

    Returns
    -------
    (n,) float array
        0 to 1.
    """
    top = pivot_y - 1.2 * (pivot_y - chin_y) if chin_y is not None else pivot_y
    bottom = float(y.min())
    if chin_y is None or top - bottom < 0.25 * (pivot_y - chin_y):
        return np.ones(len(y))
    t = np.clip((y - bottom) / (top - bottom), 0.0, 1.0)
    return t * t * (3 - 2 * t)


def animate_glb(head_glb, out, times: np.ndarray, weights: dict, head_rotation: bool = False,
                pivot=None) -> dict:
    """Write `out`: the head's GLB with an animation of its morph targets' weights (one
    keyframe per time; targets the take does not name stay at 0).

    Parameters
    ----------
    head_glb : str or Path
        A GLB whose morph targets are named as ARKit shapes (`blendshapes` makes one; other
        tools' names are read as facts.arkit_targets reads them).
    out : str or Path
        The GLB to write.
    times : (F,) float array
        Seconds.
    weights : dict
        {name: (F,) float array}, as read_take gives them.
    head_rotation : bool
        Also turn the head by the take's headYaw/headPitch/headRoll, as a skin of two joints
        (neck, head) at the pivot: the head turns whole, the neck below the chin bends
        (neck_weights), the shoulders stay.
    pivot : (3,) float array or None
        The pivot (metres, in the file's frame); None: the one `blendshapes` stored (HEAD_KEY).
        A GLB without one needs it (it then turns whole).

    Returns
    -------
    dict
        {"driven": how many of the head's targets the take drives, "pivot": the pivot used or
        None, "bending": how many vertices bend with the neck, "notes": what a user should know of
        the head as written back (gltf.open_for_edit)}.
    """
    from ..mesh.io.gltf import ARRAY_BUFFER, FLOAT, UNSIGNED_BYTE, decompressed, placed_meshes, open_for_edit, save_edited
    head_glb = Path(head_glb)
    g, doc, buf, notes = open_for_edit(head_glb)
    notes += [f"its {n} {what}{'s' if n > 1 else ''} written back uncompressed" for what, n in decompressed(g).items()]
    # every node of the scene showing a mesh with morph targets named like the take's shapes
    shown, plays = {}, {}                # mesh -> its placing nodes; mesh -> {its target: ARKit name}
    for node, mi, _, _ in placed_meshes(g, head_glb):
        if mi not in plays:
            names = list((doc["meshes"][mi].get("extras") or {}).get("targetNames") or [])
            plays[mi] = {n: a for a, n in facts.arkit_targets(names).items() if a in weights}
        if plays[mi]:
            shown.setdefault(mi, []).append(node)
    if not shown:
        raise MimicaError(f"{head_glb}: no mesh with morph targets named as ARKit shapes (make them with "
                          "`blendshapes`)")
    if head_rotation and not all(n in weights for n in HEAD_ROTATION):
        raise MimicaError("the take has no HeadYaw, HeadPitch and HeadRoll columns to turn the head by")
    it = buf.add(np.asarray(times, np.float32), None, "SCALAR", FLOAT, True)
    samplers, channels, driven = [], [], set()
    for mi, nodes in shown.items():
        names = list(doc["meshes"][mi]["extras"]["targetNames"])
        w = np.zeros((len(times), len(names)), np.float32)
        for j, n in enumerate(names):
            if n in plays[mi]:
                w[:, j] = weights[plays[mi][n]]
                driven.add(n)
        samplers.append({"input": it, "output": buf.add(w.reshape(-1), None, "SCALAR", FLOAT),
                         "interpolation": "LINEAR"})
        channels += [{"sampler": len(samplers) - 1, "target": {"node": nd, "path": "weights"}} for nd in nodes]
    used_pivot, bending = None, 0
    if head_rotation:
        placings = [(mi, nd) for mi, nodes in shown.items() for nd in nodes]
        if len(placings) != 1:
            raise MimicaError(f"{head_glb}: the head is several meshes or placings; it can only be turned on a "
                              "head as `blendshapes` writes it from an OBJ")
        mi, nd = placings[0]
        mesh, node = doc["meshes"][mi], doc["nodes"][nd]
        stored = stored_head(mesh.get("extras"))
        pivot = pivot if pivot is not None else stored.get("pivot")
        if pivot is None:
            raise MimicaError(f"{head_glb}: no head pivot stored (made by an older mimica?): say where the head "
                              "turns (x,y,z in metres)")
        used_pivot = [float(x) for x in pivot]
        if any(k in node for k in ("rotation", "scale", "matrix", "translation", "skin")):
            raise MimicaError(f"{head_glb}: its mesh's node is placed or skinned already; the head can only be "
                              "turned on a mesh as `blendshapes` writes it")
        # glTF skin (2.0 3.7.3): JOINTS_0 / WEIGHTS_0 on every vertex, joint 0 the neck (still),
        # joint 1 the head beneath it, both at the pivot (inverse bind: minus the pivot)
        y = read_accessor(g, mesh["primitives"][0]["attributes"]["POSITION"])[:, 1].astype(np.float64)
        chin = stored.get("chin")
        wh = neck_weights(y, used_pivot[1], None if chin is None else float(chin[1]))
        bending = int(((wh > 0) & (wh < 1)).sum())
        head_b = np.rint(wh * 255).astype(np.uint8)
        zero = np.zeros_like(head_b)
        # the head's weight first; a joint without weight is joint 0 (the validator's rule)
        iw_ = buf.add(np.stack([head_b, 255 - head_b, zero, zero], 1), ARRAY_BUFFER, "VEC4", UNSIGNED_BYTE,
                      normalized=True)
        ij_ = buf.add(np.stack([(head_b > 0).astype(np.uint8), zero, zero, zero], 1), ARRAY_BUFFER, "VEC4",
                      UNSIGNED_BYTE)
        for pr in mesh["primitives"]:
            pr["attributes"]["JOINTS_0"], pr["attributes"]["WEIGHTS_0"] = ij_, iw_
        q = head_quaternions(weights["headYaw"], weights["headPitch"], weights["headRoll"])
        neck, turn = len(doc["nodes"]), len(doc["nodes"]) + 1
        doc["nodes"] += [{"name": "neck", "translation": used_pivot, "children": [turn]},
                         {"name": "head", "rotation": q[0].tolist()}]
        ibm = np.tile(np.eye(4, dtype=np.float32), (2, 1, 1))
        ibm[:, 3, :3] = -np.asarray(used_pivot, np.float32)           # column-major: translation last
        doc.setdefault("skins", []).append({"name": "neck", "joints": [neck, turn], "skeleton": neck,
                                            "inverseBindMatrices": buf.add(ibm.reshape(2, 16), None, "MAT4", FLOAT)})
        node["skin"] = len(doc["skins"]) - 1
        for sc in doc.get("scenes", []):
            sc["nodes"] = list(sc.get("nodes", [])) + [neck]
        samplers.append({"input": it, "output": buf.add(q, None, "VEC4", FLOAT), "interpolation": "LINEAR"})
        channels.append({"sampler": len(samplers) - 1, "target": {"node": turn, "path": "rotation"}})
    # the file's own animations stay; the take is one more
    doc.setdefault("animations", []).append({"name": Path(out).stem, "samplers": samplers, "channels": channels})
    save_edited(doc, buf, out, binary=Path(out).suffix.lower() != ".gltf")
    return {"driven": len(driven), "pivot": used_pivot, "bending": bending, "notes": notes}
