"""Mesh files: OBJ (own fast reader/writer, polygons kept), PLY (plyfile), glTF/GLB (pygltflib).

Every failure a user can cause raises `MimicaError` naming the file and the problem.
Writes are atomic: the file appears complete or not at all.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import MimicaError
from ..outputs import atomic_path  # noqa: F401  (re-exported: mesh.atomic_path)
from .core import Mesh

MESH_SUFFIXES = (".obj", ".ply", ".glb", ".gltf")


def natural_order(path: Path):
    """Sort key: frame2 before frame10."""
    import re
    return [(0, int(t), "") if t.isdigit() else (1, 0, t.lower()) for t in re.split(r"(\d+)", Path(path).name) if t]


def sequence_files(folder) -> tuple[list[Path], list[str]]:
    """The frames of a folder of meshes, in natural order, and the files left out: a sequence is
    one format, so files of another (a previous run's animation.glb beside OBJ frames) are not
    frames.  A folder with no mesh file is refused in one line."""
    folder = Path(folder)
    files = sorted((f for f in folder.iterdir() if f.suffix.lower() in MESH_SUFFIXES), key=natural_order)
    if not files:
        raise MimicaError(f"{folder}: the folder holds no mesh files ({', '.join(MESH_SUFFIXES)})")
    kinds = [f.suffix.lower() for f in files]
    main = max(sorted(set(kinds)), key=kinds.count)
    return [f for f, k in zip(files, kinds) if k == main], [f.name for f, k in zip(files, kinds) if k != main]


def read_json(path, what="file"):
    """Parse a JSON file; a missing, unreadable or malformed one is a one-line MimicaError."""
    import json
    path = Path(path)
    try:
        return json.loads(path.read_text())
    except OSError as e:
        raise MimicaError(f"{path}: cannot read the {what} ({e.strerror})") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        where = f" (line {e.lineno}: {e.msg})" if isinstance(e, json.JSONDecodeError) else ""
        raise MimicaError(f"{path}: not valid JSON{where}") from None


# ------------------------------------------------------------------- validation
def validate(mesh: Mesh, source="mesh", allow_degenerate=False) -> Mesh:
    """Raise MimicaError (naming `source`) if the mesh cannot be used."""
    v = mesh.vertices
    if v.ndim != 2 or v.shape[1] != 3:
        raise MimicaError(f"{source}: vertices must be 3D points, got shape {v.shape}")
    if len(v) == 0:
        raise MimicaError(f"{source}: the mesh has no vertices")
    if mesh.n_faces == 0:
        raise MimicaError(f"{source}: the mesh has no faces")
    bad = ~np.isfinite(v).all(axis=1)
    if bad.any():
        raise MimicaError(f"{source}: {int(bad.sum())} vertices have non-finite coordinates "
                          f"(first: vertex {int(np.argmax(bad)) + 1})")
    fi = mesh.face_indices
    if fi.size and (fi.min() < 0 or fi.max() >= len(v)):
        k = int(np.argmax((fi < 0) | (fi >= len(v))))
        face = int(np.searchsorted(mesh.face_starts, k, side="right"))
        raise MimicaError(f"{source}: face {face} refers to vertex {int(fi[k]) + 1}, "
                          f"but the mesh has {len(v)} vertices")
    if (mesh.face_sizes < 3).any():
        face = int(np.argmax(mesh.face_sizes < 3)) + 1
        raise MimicaError(f"{source}: face {face} has fewer than 3 corners")
    if not allow_degenerate:
        used = np.zeros(len(v), bool)
        used[fi] = True
        if not used.all():
            raise MimicaError(f"{source}: {int((~used).sum())} vertices belong to no face (first: vertex "
                              f"{int(np.argmin(used)) + 1}); remove the loose vertices first (Blender: "
                              "Mesh > Clean Up > Delete Loose)")
        t = mesh.triangles
        rep = (t[:, 0] == t[:, 1]) | (t[:, 1] == t[:, 2]) | (t[:, 0] == t[:, 2])
        area2 = np.linalg.norm(mesh.face_normals(), axis=1)
        scale = mesh.bounding_box_diagonal()
        deg = rep | (area2 <= (1e-12 * scale) ** 2)
        if deg.any():
            face = int(mesh.tri_face[np.argmax(deg)]) + 1
            raise MimicaError(f"{source}: {int(deg.sum())} degenerate faces (zero area or a repeated "
                              f"corner; first: face {face}); clean the mesh first")
    return mesh


# ------------------------------------------------------------------------- OBJ
def _read_obj(path: Path) -> Mesh:
    try:
        text = path.read_text(errors="replace")
    except OSError as e:
        raise MimicaError(f"{path}: cannot read the file ({e.strerror})") from None
    lines = text.splitlines()
    vl = [ln[2:] for ln in lines if ln.startswith("v ")]
    tl = [ln[3:] for ln in lines if ln.startswith("vt ")]
    fl = [ln[2:].split() for ln in lines if ln.startswith("f ")]
    if not vl:
        raise MimicaError(f"{path}: no vertices found (is this an OBJ file?)")
    try:
        v = _parse_rows(vl, 3)
        uv = _parse_rows(tl, 2) if tl else None
        sizes = np.fromiter((len(f) for f in fl), dtype=np.int64, count=len(fl))
        vidx, tidx = _parse_corners(fl, int(sizes.sum()))
        has_uv = tidx is not None
    except ValueError as e:
        bad = _first_bad_line(lines)
        raise MimicaError(f"{path}: {bad or f'not a valid OBJ file ({e})'}") from None
    starts = np.zeros(len(sizes) + 1, dtype=np.int64)
    np.cumsum(sizes, out=starts[1:])
    n = len(v)
    mesh = Mesh(v, np.where(vidx < 0, vidx + n, vidx - 1), starts)   # 1-based, negative = relative
    if has_uv and uv is not None:
        fu = np.where(tidx < 0, tidx + len(uv), tidx - 1)
        if fu.size and fu.min() >= 0 and fu.max() < len(uv):
            mesh.uv, mesh.face_uv_indices = uv, fu
    mesh.groups, mesh.group_names = _obj_groups(lines)
    return mesh


def _obj_groups(lines):
    """Each face's material (`usemtl`), else its group (`g`, then `o`): (groups, names) or (None, ())."""
    for key in ("usemtl ", "g ", "o "):
        marks = [(i, ln[len(key):].strip()) for i, ln in enumerate(lines) if ln.startswith(key)]
        if marks:
            break
    else:
        return None, ()
    names = tuple(dict.fromkeys(n or "(unnamed)" for _, n in marks))
    at = np.array([i for i, _ in marks])
    ids = np.array([names.index(n or "(unnamed)") for _, n in marks])
    faces = np.array([i for i, ln in enumerate(lines) if ln.startswith("f ")])
    k = np.searchsorted(at, faces) - 1                 # the last mark before each face
    if (k < 0).any():                                  # faces before the first mark
        names = names + ("(none)",)
        ids = np.r_[ids, len(names) - 1]
        k = np.where(k < 0, len(ids) - 1, k)
    return ids[k].astype(np.int32), names


def read_vertices(path) -> np.ndarray:
    """Only the vertex positions of a mesh file, (n, 3), checked finite.

    For OBJ only the 'v' lines are parsed (several times faster than a full read), which
    suits frame sequences whose topology is known already.
    """
    path = Path(path)
    if _suffix(path) != ".obj":
        return read_mesh(path, allow_degenerate=True).vertices
    try:
        text = path.read_text(errors="replace")
    except OSError as e:
        raise MimicaError(f"{path}: cannot read the file ({e.strerror})") from None
    rows = [ln[2:] for ln in text.splitlines() if ln.startswith("v ")]
    if not rows:
        raise MimicaError(f"{path}: no vertices found (is this an OBJ file?)")
    try:
        v = _parse_rows(rows, 3)
    except ValueError:
        raise MimicaError(f"{path}: {_first_bad_line(text.splitlines()) or 'not a valid OBJ file'}") from None
    bad = ~np.isfinite(v).all(axis=1)
    if bad.any():
        raise MimicaError(f"{path}: {int(bad.sum())} vertices have non-finite coordinates "
                          f"(first: vertex {int(np.argmax(bad)) + 1})")
    return v


def _parse_corners(fl, n_corners):
    """Face corners 'v', 'v/t', 'v//n' or 'v/t/n' -> (vertex indices, uv indices or None)."""
    if not fl:
        return np.zeros(0, np.int64), None
    first = fl[0][0]
    fields = first.replace("//", "/").count("/") + 1
    has_t = "/" in first and "//" not in first
    joined = " ".join(" ".join(f) for f in fl)
    if joined.count("/") == first.count("/") * n_corners:     # one corner format throughout
        arr = np.array(joined.replace("//", " ").replace("/", " ").split(), dtype=np.int64)
        if arr.size == fields * n_corners:
            arr = arr.reshape(-1, fields)
            return arr[:, 0], (arr[:, 1] if has_t else None)
    corners = [c.split("/") for f in fl for c in f]
    vidx = np.array([c[0] for c in corners], dtype=np.int64)
    uv_ok = all(len(c) > 1 and c[1] for c in corners)
    return vidx, (np.array([c[1] for c in corners], dtype=np.int64) if uv_ok else None)


def _parse_rows(rows, k):
    """Lines of numbers -> (m, k) floats (extra columns such as vertex colours are dropped)."""
    flat = np.array(" ".join(rows).split(), dtype=np.float64)
    if flat.size == len(rows) * k:
        return flat.reshape(-1, k)
    return np.array([[float(x) for x in r.split()[:k]] for r in rows], dtype=np.float64).reshape(-1, k)


def _first_bad_line(lines):
    for no, ln in enumerate(lines, 1):
        parts = ln.split()
        if not parts or parts[0] not in ("v", "vt", "f"):
            continue
        try:
            if parts[0] == "f":
                [int(c.split("/")[0]) for c in parts[1:]]
            else:
                want = 3 if parts[0] == "v" else 1
                if len(parts) - 1 < want:
                    raise ValueError
                [float(x) for x in parts[1:]]
        except ValueError:
            return f"line {no} is not valid OBJ: {ln.strip()[:60]!r}"
    return None


def _write_obj(mesh: Mesh, path: Path) -> None:
    out = [f"# written by mimica: {mesh.n_vertices} vertices, {mesh.n_faces} faces\n"]
    out.append("".join(f"v {x:.8g} {y:.8g} {z:.8g}\n" for x, y, z in mesh.vertices.tolist()))
    fi = (mesh.face_indices + 1).astype(str)
    if mesh.uv is not None and mesh.face_uv_indices is not None:
        out.append("".join(f"vt {u:.8g} {w:.8g}\n" for u, w in mesh.uv.tolist()))
        fi = np.char.add(np.char.add(fi, "/"), (mesh.face_uv_indices + 1).astype(str))
    st = mesh.face_starts
    corners = fi.tolist()
    lines = ["f " + " ".join(corners[st[k]:st[k + 1]]) + "\n" for k in range(mesh.n_faces)]
    if mesh.groups is not None and mesh.group_names:   # each run of faces under its material
        g = mesh.groups
        for k in np.nonzero(np.r_[True, g[1:] != g[:-1]])[0][::-1]:
            lines.insert(k, f"usemtl {mesh.group_names[g[k]]}\n")
    out.append("".join(lines))
    path.write_text("".join(out))


# ------------------------------------------------------------------------- PLY
def _read_ply(path: Path) -> Mesh:
    from plyfile import PlyData
    try:
        ply = PlyData.read(str(path))
        vx = ply["vertex"]
        v = np.stack([vx["x"], vx["y"], vx["z"]], axis=1).astype(np.float64)
        fe = ply["face"] if "face" in ply else None
        if fe is None:
            faces = np.zeros((0, 3), np.int64)
        else:
            name = "vertex_indices" if "vertex_indices" in fe.data.dtype.names else "vertex_index"
            faces = [np.asarray(f, dtype=np.int64) for f in fe[name]]
        # uv: per face corner ("texcoord" lists, as MeshLab writes them), else per vertex
        # ("s"/"t", "u"/"v" or "texture_u"/"texture_v")
        fuv = [np.asarray(t, dtype=np.float64).reshape(-1, 2) for t in fe["texcoord"]] \
            if fe is not None and "texcoord" in fe.data.dtype.names else None
        names = vx.data.dtype.names
        pair = next((p for p in (("s", "t"), ("u", "v"), ("texture_u", "texture_v")) if set(p) <= set(names)), None)
        vuv = np.stack([vx[pair[0]], vx[pair[1]]], 1).astype(np.float64) if pair else None
    except MimicaError:
        raise
    except Exception as e:  # plyfile raises several types for malformed input
        raise MimicaError(f"{path}: not a readable PLY file ({e})") from None
    mesh = Mesh.from_faces(v, faces)
    if fuv is not None and all(len(t) == len(f) for t, f in zip(fuv, faces)) and len(fuv):
        mesh.uv = np.vstack(fuv)
        mesh.face_uv_indices = np.arange(len(mesh.uv))
    elif vuv is not None:
        mesh.uv, mesh.face_uv_indices = vuv, mesh.face_indices.copy()
    return mesh


def _write_ply(mesh: Mesh, path: Path) -> None:
    from plyfile import PlyData, PlyElement
    v = np.empty(mesh.n_vertices, dtype=[("x", "f8"), ("y", "f8"), ("z", "f8")])
    v["x"], v["y"], v["z"] = mesh.vertices.T
    corners = np.split(np.arange(len(mesh.face_indices)), mesh.face_starts[1:-1])
    has_uv = mesh.uv is not None and mesh.face_uv_indices is not None
    f = np.empty(mesh.n_faces, dtype=[("vertex_indices", "O")] + ([("texcoord", "O")] if has_uv else []))
    f["vertex_indices"] = [mesh.face_indices[c].astype(np.int32) for c in corners]
    if has_uv:         # per face corner (MeshLab's "texcoord" list): the vertices keep their order
        f["texcoord"] = [mesh.uv[mesh.face_uv_indices[c]].astype(np.float32).reshape(-1) for c in corners]
    PlyData([PlyElement.describe(v, "vertex"),
             PlyElement.describe(f, "face", val_types={"texcoord": "f4"} if has_uv else {})],
            text=False).write(str(path))


# ------------------------------------------------------------------------ glTF
def _read_gltf(path: Path) -> Mesh:
    from pygltflib import GLTF2
    try:
        g = GLTF2().load(str(path))
        prims = g.meshes[0].primitives
        prim = prims[0]
        pos = _gltf_accessor(g, prim.attributes.POSITION)
        # the primitives mimica writes (one per material) share one set of vertices; others
        # are read as the first primitive only
        same = [p for p in prims if p.attributes.POSITION == prim.attributes.POSITION and p.indices is not None]
        idx = np.vstack([_gltf_accessor(g, p.indices).reshape(-1, 3) for p in same]) if prim.indices is not None \
            else np.arange(len(pos)).reshape(-1, 3)
        face_group = np.repeat(np.arange(len(same)), [g.accessors[p.indices].count // 3 for p in same]) \
            if len(same) > 1 else None
        group_names = tuple((g.materials[p.material].name if p.material is not None and g.materials[p.material].name
                             else f"part{i}") for i, p in enumerate(same)) if face_group is not None else ()
        uv = _gltf_accessor(g, prim.attributes.TEXCOORD_0) if prim.attributes.TEXCOORD_0 is not None else None
        v_of = None
        extras = prim.extras if isinstance(prim.extras, dict) else {}
        if UNITS.get(extras.get(UNITS_KEY)):                 # back to the mesh's own unit
            pos = pos.astype(np.float64) / UNITS[extras[UNITS_KEY]]
        if VERTEX_MAP in extras:
            view = g.bufferViews[int(prim.extras[VERTEX_MAP])]
            v_of = np.frombuffer(_gltf_buffer(g, view.buffer), dtype=np.uint32, count=len(pos),
                                 offset=view.byteOffset or 0).astype(np.int64)
    except MimicaError:
        raise
    except Exception as e:
        raise MimicaError(f"{path}: not a readable glTF file ({type(e).__name__}: {e})") from None
    idx = idx.astype(np.int64)
    if v_of is None:
        mesh = Mesh.from_faces(pos.astype(np.float64), idx)
    else:                                   # back to the mesh's own vertices (a uv seam split)
        n = int(v_of.max()) + 1 if len(v_of) else 0
        if len(v_of) != len(pos) or (idx >= len(v_of)).any():
            raise MimicaError(f"{path}: its vertex map does not match its vertices")
        verts = np.zeros((n, 3))
        verts[v_of[::-1]] = pos[::-1]               # each mesh vertex from its first file vertex
        mesh = Mesh.from_faces(verts, v_of[idx])
    if uv is not None:
        mesh.uv = uv.astype(np.float64) * [1, -1] + [0, 1]
        mesh.face_uv_indices = idx.reshape(-1).copy()
    if face_group is not None:
        mesh.groups, mesh.group_names = face_group, group_names
    return mesh


def read_morph_targets(path) -> tuple[Mesh, dict, str]:
    """(the mesh, {target name: (n, 3) positions}, the mesh's unit ("m" when the file does not
    say)) of a glTF file with named morph targets (extras.targetNames, as mimica writes them),
    in the mesh's own vertices and unit."""
    import pygltflib as gl
    path = Path(path)
    mesh = read_mesh(path)
    try:
        g = gl.GLTF2().load(str(path))
        gm = g.meshes[0]
        prim = gm.primitives[0]
        names = list((gm.extras or {}).get("targetNames") or [])
        extras = prim.extras if isinstance(prim.extras, dict) else {}
        unit = extras.get(UNITS_KEY) if extras.get(UNITS_KEY) in UNITS else "m"
        k = UNITS[unit]
        n_file = g.accessors[prim.attributes.POSITION].count
        v_of = np.arange(n_file)
        if VERTEX_MAP in extras:
            view = g.bufferViews[int(extras[VERTEX_MAP])]
            v_of = np.frombuffer(_gltf_buffer(g, view.buffer), np.uint32, n_file, view.byteOffset or 0).astype(np.int64)
        out = {}
        for name, t in zip(names, prim.targets or []):
            d = np.zeros((mesh.n_vertices, 3))
            d[v_of[::-1]] = _gltf_accessor(g, t["POSITION"]).astype(np.float64)[::-1] / k
            out[name] = mesh.vertices + d
    except Exception as e:
        raise MimicaError(f"{path}: its morph targets cannot be read ({type(e).__name__}: {e})") from None
    if not out:
        raise MimicaError(f"{path}: no named morph targets")
    return mesh, out, unit


_COMPONENT = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_NCOMP = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}


def _gltf_buffer(g, i) -> bytes:
    """The bytes of buffer i (the GLB's own chunk, or a data URI)."""
    return g.binary_blob() if g.buffers[i].uri is None else g.get_data_from_buffer_uri(g.buffers[i].uri)


def _gltf_accessor(g, index) -> np.ndarray:
    """The accessor's rows; normalized integers (KHR_mesh_quantization) as the floats they stand for."""
    acc = g.accessors[index]
    if acc.sparse is not None:                    # zeros (or its buffer view), then the listed rows
        dt, nc = np.dtype(_COMPONENT[acc.componentType]), _NCOMP[acc.type]
        out = np.zeros((acc.count, nc), dt) if acc.bufferView is None else \
            _gltf_accessor_raw(g, acc).reshape(acc.count, nc).copy()
        sp_ = acc.sparse
        iv, vv = g.bufferViews[sp_.indices.bufferView], g.bufferViews[sp_.values.bufferView]
        rows = np.frombuffer(_gltf_buffer(g, iv.buffer), _COMPONENT[sp_.indices.componentType], sp_.count,
                             (iv.byteOffset or 0) + (sp_.indices.byteOffset or 0))
        out[rows.astype(np.int64)] = np.frombuffer(_gltf_buffer(g, vv.buffer), dt, sp_.count * nc,
                                                   (vv.byteOffset or 0) + (sp_.values.byteOffset or 0)).reshape(-1, nc)
        out = out.squeeze(-1) if nc == 1 else out
    else:
        out = _gltf_accessor_raw(g, acc)
    if acc.normalized and out.dtype.kind in "iu":  # glTF 2.0 3.11: c / (2^b - 1) or max(c / (2^(b-1) - 1), -1)
        top = float(np.iinfo(out.dtype).max)
        out = out / top if out.dtype.kind == "u" else np.maximum(out / top, -1.0)
    return out


def _gltf_accessor_raw(g, acc) -> np.ndarray:
    view = g.bufferViews[acc.bufferView]
    data = _gltf_buffer(g, view.buffer)
    dt = np.dtype(_COMPONENT[acc.componentType])
    nc = _NCOMP[acc.type]
    start = (view.byteOffset or 0) + (acc.byteOffset or 0)
    stride = view.byteStride or dt.itemsize * nc
    raw = np.frombuffer(data, dtype=np.uint8, count=stride * (acc.count - 1) + dt.itemsize * nc, offset=start)
    rows = np.lib.stride_tricks.as_strided(raw, shape=(acc.count, dt.itemsize * nc), strides=(stride, 1))
    return np.ascontiguousarray(rows).view(dt).reshape(acc.count, nc).squeeze(-1) if nc == 1 else \
        np.ascontiguousarray(rows).view(dt).reshape(acc.count, nc)


VERTEX_MAP = "mimica_vertex_of"     # primitive extras: buffer view of uint32, file vertex -> mesh vertex
UNITS_KEY = "mimica_units"          # primitive extras: the mesh's own unit (the file is in metres)
UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}
SPARSE_TOLERANCE = 1e-5             # metres: 0.01 mm, below what a morph target's vertex counts as still
QUANTIZATION = "KHR_mesh_quantization"
QUANTIZE_ERROR = 0.5 / 32767          # metres: the largest error of a quantized move, per axis
SPARSE_NORMAL = 1e-3                # the change of a unit normal below which it counts as unturned


def glb_units(mesh: Mesh, units: str = "auto") -> tuple[str, float]:
    """(the mesh's unit, metres per unit).  auto: a head up to 3 units tall is in metres, up to
    100 in centimetres (ICT-FaceKit: 33), taller in millimetres."""
    if units != "auto":
        if units not in UNITS:
            raise MimicaError(f"units {units!r}: use one of auto, {', '.join(UNITS)}")
        return units, UNITS[units]
    height = float(np.ptp(mesh.vertices[:, 1])) if mesh.n_vertices else 0.0
    name = "m" if height <= 3 else "cm" if height <= 100 else "mm"
    return name, UNITS[name]


def _gltf_vertices(mesh: Mesh):
    """(mesh vertex of each file vertex, uv index of each (-1: none) or None, file triangles):
    one file vertex per (vertex, uv) pair the triangles use, then the vertices no triangle uses."""
    tri = mesh.triangles
    uvt = mesh.uv_triangles
    if uvt is None:
        return np.arange(mesh.n_vertices), None, tri
    pairs, inv = np.unique(np.stack([tri.reshape(-1), uvt.reshape(-1)], 1), axis=0, return_inverse=True)
    unused = np.setdiff1d(np.arange(mesh.n_vertices), pairs[:, 0])
    v_of = np.r_[pairs[:, 0], unused]
    uv_of = np.r_[pairs[:, 1], np.full(len(unused), -1)]
    return v_of, uv_of, inv.reshape(-1, 3)


def _unit_normals(mesh: Mesh, vertices: np.ndarray) -> np.ndarray:
    """Unit vertex normals; a vertex no triangle uses (no normal) gets +z, as glTF wants unit
    normals on every vertex."""
    n = mesh.vertex_normals(vertices)
    n[np.linalg.norm(n, axis=1) < 0.5] = (0.0, 0.0, 1.0)
    return n


def _reachable_normal_change(n0: np.ndarray, n1: np.ndarray) -> np.ndarray:
    """The change of each unit normal n0 -> n1 as 8-bit normalized integers hold it (within +-1
    per axis, steps of 1/127).  A normal that turns far (a lid's or lip's inner shell: ICT's
    eyeBlink_R turns 85 of its normals past the reach of n1 - n0) takes lambda n1 - n0 instead,
    the lambda in (0, 1] whose stored change points n0 + dn nearest n1: viewers normalize
    n0 + w dn, so at full weight it points along n1 (to within some degrees for the few turned
    nearly 180 degrees, where no change within +-1 does)."""
    dn = n1 - n0
    far = np.abs(dn).max(1) > 1.0
    if far.any():
        lam = np.linspace(0.02, 1.0, 50)[:, None, None]
        cand = np.rint(np.clip(lam * n1[far][None] - n0[far][None], -1.0, 1.0) * 127) / 127
        r = n0[far][None] + cand
        cos = (r * n1[far][None]).sum(2) / np.maximum(np.linalg.norm(r, axis=2), 1e-12)
        dn[far] = cand[cos.argmax(0), np.arange(far.sum())]
    return dn


def write_glb(path: Path, mesh: Mesh, morph_targets=None, binary=True, fps=None, units: str = "auto",
              sparse: float | None = None, weights=None, extras: dict | None = None, quantize: bool = False) -> dict:
    """Write a triangulated mesh, optionally with named morph targets {name: (n,3) positions}.

    fps: also write an animation that plays the morph targets in order, one per frame at
    this rate (weights interpolated linearly between frames), for frame sequences.
    units: the mesh's unit ("m", "cm", "mm", or "auto": glb_units); glTF is in metres, so the
    positions are scaled to metres and the unit is kept in the primitive's extras, which
    mimica's reader undoes.  Returns {"units": the unit used, "sparse": how many targets were
    written sparse}.
    sparse: morph targets as sparse accessors: a vertex that moves less than this many metres
    (SPARSE_TOLERANCE: 0.01 mm) keeps zero, as does a normal that turns less than
    SPARSE_NORMAL; None writes every target dense.
    weights: with fps, the animation's weights per frame (F, number of targets) instead of one
    target per frame (a clip as a few basis shapes, export.compact).
    extras: more of the mesh's extras (with targetNames).
    quantize: morph targets in KHR_mesh_quantization's normalized integers (moves to 0.015 mm,
    QUANTIZE_ERROR; about half the size), the extension then required of readers.
    """
    import pygltflib as gl
    # glTF keeps one uv per vertex: a vertex on a uv seam is written once per uv it has, and the
    # map from the file's vertices back to the mesh's is kept (VERTEX_MAP) for mimica's reader
    v_of, uv_of, t = _gltf_vertices(mesh)
    unit, k = glb_units(mesh, units)
    v = (k * mesh.vertices[v_of]).astype(np.float32)
    t = t.astype(np.uint32)
    blobs, views, accs = [], [], []

    def add(arr, target, acc_type, comp, minmax=False, normalized=False):
        arr = np.ascontiguousarray(arr)
        stride = None
        if target == gl.ARRAY_BUFFER and arr.ndim == 2 and arr.itemsize * arr.shape[1] % 4:
            # glTF 2.0 3.6.2.4: each vertex's element starts on 4 bytes (quantized VEC3s padded)
            width = -(-arr.itemsize * arr.shape[1] // 4) * 4 // arr.itemsize
            stride = width * arr.itemsize
            data = np.zeros((len(arr), width), arr.dtype)
            data[:, :arr.shape[1]] = arr
        else:
            data = arr
        off = sum(len(b) for b in blobs)
        blobs.append(data.tobytes() + b"\0" * ((-data.nbytes) % 4))
        views.append(gl.BufferView(buffer=0, byteOffset=off, byteLength=data.nbytes, target=target, byteStride=stride))
        a = gl.Accessor(bufferView=len(views) - 1, componentType=comp, count=len(arr), type=acc_type,
                        normalized=True if normalized else None)
        if minmax:
            a.min, a.max = np.atleast_1d(arr.min(0)).tolist(), np.atleast_1d(arr.max(0)).tolist()
        accs.append(a)
        return len(accs) - 1

    def encode(arr, q):
        """(stored array, component type, normalized): float32, or with q ("short", "byte") the
        normalized integers of KHR_mesh_quantization (glTF 2.0 3.11: f = max(c / (2^(b-1) - 1), -1);
        values beyond +-1 clipped)."""
        if q is None:
            return np.asarray(arr, np.float32), gl.FLOAT, False
        dt, comp = (np.int16, gl.SHORT) if q == "short" else (np.int8, gl.BYTE)
        top = np.iinfo(dt).max
        return np.clip(np.rint(np.asarray(arr) * top), -top, top).astype(dt), comp, True

    def add_sparse(arr, keep, minmax=False, q=None):
        """A VEC3 accessor of len(arr) rows, zero but where `keep` (a sparse accessor); dense
        where more than a third of the rows are kept (smaller so).  q: quantized (encode)."""
        if not keep.any():                          # glTF wants one row at least
            keep = np.r_[True, np.zeros(len(keep) - 1, bool)]
        if keep.mean() > 1 / 3:
            vals, comp, norm = encode(np.where(keep[:, None], arr, 0), q)
            return add(vals, gl.ARRAY_BUFFER, gl.VEC3, comp, minmax, norm)
        rows = np.nonzero(keep)[0]
        # indices as 16 bits where the vertices allow (glTF: UNSIGNED_BYTE, _SHORT or _INT)
        rows, icomp = (rows.astype(np.uint16), gl.UNSIGNED_SHORT) if len(arr) <= 65535 else \
            (rows.astype(np.uint32), gl.UNSIGNED_INT)
        vals, comp, norm = encode(arr[rows], q)
        add(rows, None, gl.SCALAR, icomp)
        accs.pop()
        i_rows = len(views) - 1
        add(vals, None, gl.VEC3, comp)
        accs.pop()
        a = gl.Accessor(componentType=comp, count=len(arr), type=gl.VEC3, normalized=True if norm else None,
                        sparse=gl.Sparse(count=len(rows),
                                         indices=gl.AccessorSparseIndices(bufferView=i_rows, componentType=icomp),
                                         values=gl.AccessorSparseValues(bufferView=len(views) - 1)))
        a.byteOffset = None                         # no buffer view of its own: zeros but the rows
        if minmax:
            full = vals if len(rows) == len(arr) else np.vstack([vals, np.zeros((1, 3), vals.dtype)])
            a.min, a.max = full.min(0).tolist(), full.max(0).tolist()
        accs.append(a)
        return len(accs) - 1

    ipos = add(v, gl.ARRAY_BUFFER, gl.VEC3, gl.FLOAT, True)
    # smooth normals, so that viewers shade the surface smooth and a DCC's round trip keeps the
    # vertices whole (without them three.js and Blender shade flat, and Blender's re-export
    # splits every vertex); morph targets carry the change of the normal (glTF: deltas)
    n0 = _unit_normals(mesh, mesh.vertices)
    inrm = add(n0[v_of].astype(np.float32), gl.ARRAY_BUFFER, gl.VEC3, gl.FLOAT)
    grouped = mesh.groups is not None and len(mesh.group_names) > 0
    iidx = None if grouped else add(t.reshape(-1), gl.ELEMENT_ARRAY_BUFFER, gl.SCALAR, gl.UNSIGNED_INT)
    attrs = gl.Attributes(POSITION=ipos, NORMAL=inrm)
    if uv_of is not None:
        tex = np.where(uv_of[:, None] >= 0, mesh.uv[np.maximum(uv_of, 0)], 0.0) * [1, -1] + [0, 1]
        attrs.TEXCOORD_0 = add(tex.astype(np.float32), gl.ARRAY_BUFFER, gl.VEC2, gl.FLOAT)
    prim_extras = {UNITS_KEY: unit}
    if len(v_of) != mesh.n_vertices or (v_of != np.arange(len(v_of))).any():
        add(v_of.astype(np.uint32), None, gl.SCALAR, gl.UNSIGNED_INT)
        accs.pop()                                  # the map is a buffer view, not an accessor
        prim_extras[VERTEX_MAP] = len(views) - 1
    # one primitive and material per OBJ material / group, all on the same vertices
    prims, materials = [], []
    if grouped:
        tri_group = np.asarray(mesh.groups)[mesh.tri_face]
        for gi in np.unique(tri_group):
            sel = t[tri_group == gi].reshape(-1)
            materials.append(gl.Material(name=str(mesh.group_names[gi]), doubleSided=False,
                                         pbrMetallicRoughness=gl.PbrMetallicRoughness(metallicFactor=0.0,
                                                                                      roughnessFactor=0.6)))
            prims.append(gl.Primitive(attributes=attrs, indices=add(sel, gl.ELEMENT_ARRAY_BUFFER, gl.SCALAR,
                                                                    gl.UNSIGNED_INT),
                                      material=len(materials) - 1, extras=prim_extras))
    else:
        prims.append(gl.Primitive(attributes=attrs, indices=iidx, extras=prim_extras))
    prim = prims[0]
    names = []
    if morph_targets:
        prim.targets = []
        for name, pos in morph_targets.items():
            pos = np.asarray(pos, dtype=np.float64)
            dp = (k * (pos - mesh.vertices)[v_of]).astype(np.float32)
            n1 = _unit_normals(mesh, pos)
            dn = ((_reachable_normal_change(n0, n1) if quantize else n1 - n0)[v_of]).astype(np.float32)
            # quantized: moves as 16-bit normalized metres (0.03 mm steps; normalized integers
            # reach +-1 only: a target that moves a vertex over 1 m stays float), normal changes
            # as 8 bits (1/127 steps)
            qp = "short" if quantize and np.abs(dp).max() < 1.0 else None
            qn = "byte" if quantize else None
            if sparse is None:
                prim.targets.append({"POSITION": add_sparse(dp, np.ones(len(dp), bool), True, qp),
                                     "NORMAL": add_sparse(dn, np.ones(len(dn), bool), False, qn)})
            else:
                # sparse targets: the vertices that move more than `sparse` metres, and the
                # normals that turn by more than SPARSE_NORMAL, are stored; the rest are zero
                prim.targets.append({"POSITION": add_sparse(dp, np.linalg.norm(dp, axis=1) > sparse, True, qp),
                                     "NORMAL": add_sparse(dn, np.linalg.norm(dn, axis=1) > SPARSE_NORMAL, False, qn)})
            names.append(name)
        for other in prims[1:]:                     # the same targets on every primitive
            other.targets = prim.targets
    gmesh = gl.Mesh(primitives=prims)
    if names:
        gmesh.extras = {"targetNames": names, **(extras or {})}
        gmesh.weights = [0.0] * len(names)
    animations = []
    if fps and names:
        w = np.eye(len(names), dtype=np.float32) if weights is None else np.asarray(weights, np.float32)
        if w.ndim != 2 or w.shape[1] != len(names):
            raise MimicaError(f"weights: {w.shape} for {len(names)} morph targets")
        times = (np.arange(len(w)) / float(fps)).astype(np.float32)
        itime = add(times, None, gl.SCALAR, gl.FLOAT, True)
        iw = add(w.reshape(-1), None, gl.SCALAR, gl.FLOAT)
        animations = [gl.Animation(name="frames", samplers=[gl.AnimationSampler(input=itime, output=iw,
                                                                              interpolation="LINEAR")],
                                   channels=[gl.AnimationChannel(sampler=0, target=gl.AnimationChannelTarget(
                                       node=0, path="weights"))])]
    blob = b"".join(blobs)
    g = gl.GLTF2(scene=0, scenes=[gl.Scene(nodes=[0])], nodes=[gl.Node(mesh=0)], meshes=[gmesh],
                 accessors=accs, bufferViews=views, buffers=[gl.Buffer(byteLength=len(blob))],
                 animations=animations, materials=materials)
    if any(a.normalized for a in accs):             # its readers must know the integer attributes
        g.extensionsUsed = g.extensionsRequired = [QUANTIZATION]
    g.set_binary_blob(blob)
    if binary:
        g.save_binary(str(path))
    else:
        g.buffers[0].uri = "data:application/octet-stream;base64," + __import__("base64").b64encode(blob).decode()
        g._glb_data = None
        g.save_json(str(path))
    return {"units": unit, "sparse": sum(accs[tg["POSITION"]].sparse is not None for tg in (prim.targets or [])),
            "quantized": sum(bool(accs[tg["POSITION"]].normalized) for tg in (prim.targets or []))}


# ------------------------------------------------------------------------ API
def _suffix(path: Path) -> str:
    s = path.suffix.lower()
    if s not in MESH_SUFFIXES:
        raise MimicaError(f"{path}: unknown mesh format {s or '(no extension)'!r}; "
                          f"use one of {', '.join(MESH_SUFFIXES)}")
    return s


def read_mesh(path, validate_mesh=True, allow_degenerate=False) -> Mesh:
    """Read an OBJ/PLY/glTF/GLB mesh; polygons stay polygons (glTF holds triangles only)."""
    path = Path(path)
    s = _suffix(path)
    if not path.is_file():
        raise MimicaError(f"{path}: no such file")
    reader = {".obj": _read_obj, ".ply": _read_ply, ".glb": _read_gltf, ".gltf": _read_gltf}[s]
    mesh = reader(path)
    mesh.name = path.stem
    if validate_mesh:
        validate(mesh, str(path), allow_degenerate=allow_degenerate)
    return mesh


def write_mesh(path, mesh: Mesh, units: str = "auto") -> Path:
    """Write atomically; the format follows the extension (units: glTF only, see write_glb)."""
    path = Path(path)
    s = _suffix(path)
    with atomic_path(path) as tmp:
        if s == ".obj":
            _write_obj(mesh, tmp)
        elif s == ".ply":
            _write_ply(mesh, tmp)
        else:
            write_glb(tmp, mesh, binary=(s == ".glb"), units=units)
    return path
