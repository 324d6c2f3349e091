"""FBX, read and written through Blender (fbx_blender, run by Blender's Python).

No Python FBX library does what a character head needs here: the ufbx binding (0.0.5) hands
out its scene's objects without a reference of their own, so a read node name or material
crashes the interpreter when the scene is freed (measured: 3 of 8 ordinary accesses); Assimp's
bindings need the system's libassimp and split every vertex at its seams; neither writes FBX.
Blender's importer and exporter are the FBX path DCC heads are kept on, so FBX needs Blender:
the `blender` command on PATH, or MIMICA_BLENDER_PYTHON naming a Python with the bpy package
(Python 3.11: `pip install bpy`, in a venv of its own: bpy needs numpy < 2).

Reading: every mesh object, placed in the world by Blender's import of the file (its unit to
metres, its axes to mimica's y up), polygons, uv and materials as the file has them (FBX keeps
one vertex per control point), shape keys; seams between objects welded (weld.weld_seams).
`FbxLayout` remembers where each object's vertices went; writing back adds shape keys (and a
cut mouth's vertices) to the user's objects and exports the file again through Blender.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ... import facts
from ...errors import MimicaError
from ..core import Mesh
from .weld import move_key, weld_seams

SCRIPT = Path(__file__).with_name("fbx_blender.py")
# Blender's z up -> mimica's y up (facts.Z_UP_TO_Y_UP), as a 4 x 4 transform
Z_UP_TO_Y_UP = np.eye(4)
Z_UP_TO_Y_UP[:3, :3] = facts.Z_UP_TO_Y_UP


@dataclass
class FbxPiece:
    """One mesh object of an FBX file.

    Attributes
    ----------
    name : str
    world : (4, 4) float array
        The object's vertices -> work space.
    vertex : (n,) int array
        The work vertex of each of the object's vertices.
    first_face : int
        Its first polygon in the work mesh.
    n_faces : int
    keys : list of str
        Its shape keys' names (Basis first).
    """

    name: str
    world: np.ndarray              # (4, 4) the object's vertices -> work space
    vertex: np.ndarray             # (n,) work vertex of each of the object's vertices
    first_face: int                # its first polygon in the work mesh
    n_faces: int
    keys: list = field(default_factory=list)     # its shape keys' names (Basis first)

    def vectors_to_local(self, d: np.ndarray) -> np.ndarray:
        """(k, 3) work-space displacements -> the object's own space (shape keys)."""
        return np.linalg.solve(self.world[:3, :3], np.asarray(d, np.float64).T).T

    def to_local(self, points: np.ndarray) -> np.ndarray:
        return np.linalg.solve(self.world[:3, :3], (np.asarray(points, np.float64) - self.world[:3, 3]).T).T


@dataclass
class FbxLayout:
    """Where an FBX file's vertices went in the work mesh read_fbx made of it.

    Attributes
    ----------
    path : Path
    pieces : list of FbxPiece
    n_vertices, n_faces : int
        The work mesh's.
    notes : list of str
        What reading it did that a user should know.
    extras : dict
        (glTF's mimica keys: an FBX has none.)
    targets : dict
        Shape key name -> (n, 3) work positions.
    unit : str
        "m".
    """

    path: Path
    pieces: list
    n_vertices: int
    n_faces: int
    notes: list = field(default_factory=list)
    extras: dict = field(default_factory=dict)       # (glTF's mimica keys: an FBX has none)
    targets: dict = field(default_factory=dict)      # shape key name -> (n, 3) work positions
    unit: str = "m"


def blender_command(script: Path) -> list:
    """The command that runs a script in Blender's Python.

    Parameters
    ----------
    script : Path

    Returns
    -------
    list of str
        $MIMICA_BLENDER_PYTHON (a Python with bpy), else `blender` on PATH in the background;
        a one-line MimicaError saying how to get one otherwise.
    """
    exe = os.environ.get("MIMICA_BLENDER_PYTHON")
    if exe:
        if not Path(exe).is_file():
            raise MimicaError(f"MIMICA_BLENDER_PYTHON={exe}: no such file (a Python with Blender's bpy package)")
        return [exe, str(script), "--"]
    blender = shutil.which("blender")
    if blender:
        return [blender, "-b", "--factory-startup", "--python-exit-code", "1", "--python", str(script), "--"]
    raise MimicaError("FBX is read and written through Blender: put the `blender` command on PATH, or set "
                      "MIMICA_BLENDER_PYTHON to a Python with the bpy package (pip install bpy, Python 3.11, "
                      "in a venv of its own)")


def _blender(path: Path, *args, what="read") -> None:
    cmd = blender_command(SCRIPT) + [str(a) for a in args]
    try:
        run = subprocess.run(cmd, capture_output=True, text=True, timeout=1800, stdin=subprocess.DEVNULL)
    except (OSError, subprocess.TimeoutExpired) as e:
        raise MimicaError(f"{path}: Blender could not be run to {what} it ({e})") from None
    if run.returncode != 0:
        last = [ln for ln in (run.stderr + run.stdout).splitlines() if ln.strip()]
        why = next((ln for ln in reversed(last) if "Error" in ln or "error" in ln), last[-1] if last else "")
        raise MimicaError(f"{path}: Blender could not {what} it as FBX ({why.strip()[:200]})")


def read_fbx_layout(path) -> tuple[Mesh, FbxLayout]:
    """The work mesh of an FBX file (every mesh object in world space, y up, metres) and where its
    vertices came from, read through Blender's importer.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    mesh : Mesh
    layout : FbxLayout
        Its shape keys as `targets`.
    """
    path = Path(path)
    with tempfile.TemporaryDirectory(prefix="mimica-fbx-") as d:
        _blender(path, "read", path, Path(d) / "scene")
        spec = json.loads((Path(d) / "scene.json").read_text())
        with np.load(Path(d) / "scene.npz") as z:
            arrays = {k: z[k] for k in z.files}
    try:
        return _build(path, spec["objects"], arrays)
    except MimicaError:
        raise
    except Exception as e:
        raise MimicaError(f"{path}: not a readable FBX file ({type(e).__name__}: {e})") from None


def _build(path: Path, objects: list, a: dict) -> tuple[Mesh, FbxLayout]:
    if not objects:
        raise MimicaError(f"{path}: no mesh objects in its scene")
    pieces, pos, fi, sizes, uv, mats, names, notes = [], [], [], [], [], [], [], []
    n_v = n_f = 0
    for i, ob in enumerate(objects):
        world = Z_UP_TO_Y_UP @ np.asarray(ob["matrix"], np.float64)
        v = a[f"v{i}"]
        s = a[f"s{i}"]
        pieces.append(FbxPiece(ob["name"], world, np.arange(n_v, n_v + len(v)), n_f, len(s), ob["shape_keys"]))
        pos.append(v @ world[:3, :3].T + world[:3, 3])
        fi.append(a[f"c{i}"] + n_v)
        sizes.append(s)
        uv.append(a.get(f"u{i}", np.zeros((len(a[f"c{i}"]), 2))))
        slots = [m or ob["name"] for m in ob["materials"]] or [ob["name"]]
        names += [m for m in dict.fromkeys(slots) if m not in names]
        gid = np.array([names.index(m) for m in slots])
        mats.append(gid[np.minimum(a[f"m{i}"], len(gid) - 1)])
        n_v += len(v)
        n_f += len(s)
    if sum(ob["armature"] for ob in objects):
        notes.append("skinned objects read in the bind pose (the armature's pose is not applied)")
    raw = np.vstack(pos)
    flat = np.concatenate(fi)
    st = np.r_[0, np.cumsum(np.concatenate(sizes))]
    set_of = np.repeat(np.arange(len(pieces)), [len(p) for p in pos])
    # the objects' seams welded where their sides also move alike in the shape keys (by name)
    keys = sorted({k for ob in objects for k in ob["shape_keys"][1:]})
    same = None
    if keys:
        moves = np.zeros((len(raw), 3 * len(keys)))
        for i, (p, ob) in enumerate(zip(pieces, objects)):
            rows = slice(p.vertex[0], p.vertex[0] + len(p.vertex))
            for j, name in enumerate(ob["shape_keys"][1:], start=1):
                c = keys.index(name)
                moves[rows, 3 * c:3 * c + 3] = (a[f"k{i}_{j}"] - a[f"v{i}"]) @ p.world[:3, :3].T
        same = move_key(moves)
    label = weld_seams(raw, Mesh(raw, flat, st).half_edges, set_of, np.arange(len(raw)), same)
    uniq, first = np.unique(label, return_index=True)
    order = np.argsort(first, kind="stable")
    rank = np.empty(len(uniq), np.int64)
    rank[order] = np.arange(len(uniq))
    work = rank[np.searchsorted(uniq, label)]
    mesh = Mesh(raw[first[order]], work[flat], st)
    for p in pieces:
        p.vertex = work[p.vertex]
    mesh.uv, mesh.face_uv_indices = np.vstack(uv), np.arange(len(flat))
    mesh.groups, mesh.group_names = np.concatenate(mats).astype(np.int32), tuple(names)
    layout = FbxLayout(path, pieces, mesh.n_vertices, mesh.n_faces, notes)
    # the shape keys, as work positions (a vertex takes its first object's move)
    targets = {}
    for i, (p, ob) in reversed(list(enumerate(zip(pieces, objects)))):
        base = a[f"v{i}"]
        for j, name in enumerate(ob["shape_keys"][1:], start=1):
            d = (a[f"k{i}_{j}"] - base) @ p.world[:3, :3].T
            targets.setdefault(name, np.zeros_like(mesh.vertices))[p.vertex[::-1]] = d[::-1]
    layout.targets = {n: mesh.vertices + d for n, d in targets.items()}
    mesh.layout = layout
    return mesh, layout


def read_fbx(path) -> Mesh:
    """The work mesh of an FBX file (read_fbx_layout).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    Mesh
    """
    return read_fbx_layout(path)[0]


def read_fbx_shapes(path) -> tuple[Mesh, dict, str]:
    """An FBX head's shape keys.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    mesh : Mesh
        The work mesh.
    shapes : dict
        {shape key name: (n, 3) world positions}.
    unit : str
        "m".
    """
    from .checks import validate
    path = Path(path)
    mesh = validate(read_fbx(path), str(path))
    mesh.name = path.stem
    targets = mesh.layout.targets
    if not targets:
        raise MimicaError(f"{path}: no shape keys")
    return mesh, targets, "m"


def write_fbx_layout(path, layout: FbxLayout, mesh: Mesh, targets: dict | None = None) -> dict:
    """The FBX file `layout` was read from, exported again through Blender to `path` with the
    result's shape keys {name: (n, 3) positions of `mesh`'s vertices} added to each object (and
    a cut mouth's vertices added to the objects it cut, its corners re-pointed).  Returns
    {"appended": vertices added}."""
    if mesh.n_faces != layout.n_faces:
        raise ValueError(f"the result has {mesh.n_faces} faces; the file was read with {layout.n_faces}")
    targets = targets or {}
    spec, arrays, appended = [], {}, 0
    fs, fi = mesh.face_starts, mesh.face_indices
    for i, p in enumerate(layout.pieces):
        rows_f = np.arange(p.first_face, p.first_face + p.n_faces)
        corners = np.concatenate([np.arange(fs[f], fs[f + 1]) for f in rows_f]) if len(rows_f) else np.zeros(0, int)
        w_out = fi[corners]
        poly = np.repeat(np.arange(p.n_faces), np.diff(fs[p.first_face: p.first_face + p.n_faces + 1]))
        within = corners - fs[p.first_face + poly]
        # a corner whose work vertex is past the read ones: a cut's copy, added to this object
        cut = w_out >= layout.n_vertices
        new_w, k = np.unique(w_out[cut], return_inverse=True)
        work = np.r_[p.vertex, new_w]
        if len(new_w):
            arrays[f"a{i}"] = p.to_local(mesh.vertices[new_w])
            arrays[f"r{i}"] = np.stack([poly[cut], within[cut], k.ravel()], 1)
            appended += len(new_w)
        for j, q in enumerate(targets.values()):
            arrays[f"k{i}_{j}"] = p.vectors_to_local(np.asarray(q)[work] - mesh.vertices[work])
        spec.append({"name": p.name, "keys": list(targets)})
    with tempfile.TemporaryDirectory(prefix="mimica-fbx-") as d:
        (Path(d) / "edits.json").write_text(json.dumps({"objects": spec}))
        np.savez(Path(d) / "edits.npz", **arrays)
        _blender(layout.path, "write", layout.path, Path(d) / "edits", Path(path), what="write")
    return {"appended": appended}


def write_fbx_take(path, head, times: np.ndarray, rate: float, weights: dict) -> list:
    """The FBX `head` exported again through Blender to `path` with a take keyed on its shape
    keys named as ARKit shapes (facts.arkit_targets, matched inside Blender: one run), one key a
    time, linear between (Blender's exporter bakes it into the FBX's animation).

    Parameters
    ----------
    path : str or Path
        The FBX to write (written only where some shape key is keyed).
    head : str or Path
        The FBX read.
    times : (F,) float array
        Seconds from the take's first frame.
    rate : float
        The take's frames a second (the scene's rate).
    weights : dict
        {ARKit name: (F,) values}.

    Returns
    -------
    list of str
        The shape keys keyed (empty: nothing written).
    """
    head = Path(head)
    names = list(weights)
    with tempfile.TemporaryDirectory(prefix="mimica-fbx-") as d:
        (Path(d) / "take.json").write_text(json.dumps({"fps": float(rate), "names": names}))
        np.savez(Path(d) / "take.npz", t=np.asarray(times, np.float64),
                 w=np.stack([np.asarray(weights[n], np.float64) for n in names], 1))
        _blender(head, "take", head, Path(d) / "take", Path(path), what="write a take into")
        return json.loads((Path(d) / "take.keyed.json").read_text())
