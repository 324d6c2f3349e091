"""glTF 2.0 and GLB: pygltflib reads the file (its JSON decoded by gltf_decode); the scene is read here, whole.

Reading (`read_gltf_layout`): every node of the default scene that holds a mesh, every
primitive, taken to world space through the node hierarchy (TRS or matrix); vertices a writer
split at uv, normal or material seams welded for the work; `GltfLayout` remembers where each of
the file's vertices went.  Writing back (`write_gltf_layout`): the user's own file with the
result's positions and morph targets in each node's own space, and everything else as it was.
(trimesh's loader, the other well-kept reader, merges primitives per material and drops morph
targets and the file's own vertex layout, so a result could not go back where it stood.)
`write_glb` writes a mesh mimica made (sparse, quantized, compact clips, which no library writes).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ...errors import MimicaError
from ..core import Mesh, unique_rows
from .draco import EXTENSION as DRACO, decode_draco
from .gltf_spec import (ARRAY_BUFFER, BYTE, ELEMENT_ARRAY_BUFFER, FLOAT, SHORT, UNSIGNED_BYTE,  # noqa: F401
                        UNSIGNED_INT, UNSIGNED_SHORT)
from .gltf_spec import COMPONENT as _COMPONENT, NCOMP as _NCOMP
from .meshopt import EXTENSION as MESHOPT, decode_meshopt, placeholder
from .weld import move_key, weld_seams


VERTEX_MAP = "mimica_vertex_of"     # primitive extras: buffer view of uint32, file vertex -> mesh vertex
UNITS_KEY = "mimica_units"          # primitive extras: the mesh's own unit (the file is in metres)
UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}
SPARSE_TOLERANCE = 1e-5             # metres: 0.01 mm, below what a morph target's vertex counts as still
QUANTIZATION = "KHR_mesh_quantization"
QUANTIZE_ERROR = 0.5 / 32767          # metres: the largest error of a quantized move, per axis
SPARSE_NORMAL = 1e-3                # the change of a unit normal below which it counts as unturned
# Geometry compressed by Draco (DRACO) or EXT_meshopt (MESHOPT) is decoded on reading (mesh.io.draco,
# mesh.io.meshopt; written back uncompressed); these extensions' files are refused
REFUSED = {"KHR_meshopt_compression": "meshopt"}
SURFACE_MODES = (4, 5, 6)             # TRIANGLES, TRIANGLE_STRIP, TRIANGLE_FAN


@dataclass
class VertexSet:
    """One POSITION accessor as one node places it: the vertices of the primitives that share it
    (mimica writes every material's primitive on one set; Blender writes a set a primitive).

    Attributes
    ----------
    node : int or None
        The node placing it (None: a mesh no node places).
    mesh : int
        The glTF mesh.
    position : int
        Its POSITION accessor.
    world : (4, 4) float array
        The node's world matrix (the identity for a skinned mesh).
    scale : float
        Metres per unit of the work mesh in the file (mimica's own files).
    primitives : list of int
        The primitives (triangles, strips or fans).
    triangles : list of (m, 3) int arrays
        Per primitive, its triangles' file vertex indices.
    first_face : list of int
        Per primitive, its first face in the work mesh.
    vertex : (count,) int array or None
        The work vertex of each file vertex.
    own : bool
        The first node placing its mesh: the one written back.
    offset : int
        Its first vertex among all sets' file vertices.
    """

    node: int | None               # the node placing it (None: a mesh no node places)
    mesh: int                      # the glTF mesh
    position: int                  # its POSITION accessor
    world: np.ndarray              # (4, 4) the node's world matrix (identity for a skinned mesh)
    scale: float                   # metres per unit of the work mesh in the file (mimica's own files)
    primitives: list = field(default_factory=list)    # primitive indices (triangles, strips or fans)
    triangles: list = field(default_factory=list)     # per primitive: (m, 3) int64 file vertex indices
    first_face: list = field(default_factory=list)    # per primitive: its first face in the work mesh
    vertex: np.ndarray | None = None                  # (count,) int64: the work vertex of each file vertex
    own: bool = True               # the first node placing its mesh: the one written back
    offset: int = 0                # its first vertex among all sets' file vertices

    def to_local(self, points: np.ndarray) -> np.ndarray:
        """(k, 3) work-space points -> the accessor's space (the node's inverse, the unit)."""
        m = self.world
        return self.scale * np.linalg.solve(m[:3, :3], (np.asarray(points) - m[:3, 3]).T).T

    def vectors_to_local(self, d: np.ndarray) -> np.ndarray:
        """(k, 3) work-space displacements -> the accessor's space (morph target deltas)."""
        return self.scale * np.linalg.solve(self.world[:3, :3], np.asarray(d).T).T


@dataclass
class GltfLayout:
    """Where a glTF file's vertices went in the work mesh `read_gltf` made of it, for writing the
    result back into the file (`write_gltf_layout`).

    Attributes
    ----------
    path : Path
        The file.
    sets : list of VertexSet
        In the work mesh's order.
    unit : str
        The work mesh's unit ("m" unless mimica wrote the file).
    n_vertices, n_faces : int
        The work mesh's.
    notes : list of str
        What the reading did that a user should know (seams welded, skins in their bind pose, ...).
    extras : dict
        The meshes' extras, merged (mimica's keys).
    """

    path: Path
    sets: list                     # VertexSet, in the work mesh's order
    unit: str                      # the work mesh's unit ("m" unless mimica wrote the file)
    n_vertices: int                # the work mesh's
    n_faces: int
    notes: list = field(default_factory=list)        # what the reading did that a user should know
    extras: dict = field(default_factory=dict)       # the meshes' extras, merged (mimica's keys)

    @property
    def meshes(self) -> list:
        """The glTF meshes written back (their first placing)."""
        return list(dict.fromkeys(s.mesh for s in self.sets if s.own))


def _load(path: Path):
    from .gltf_decode import fast_gltf_class
    try:
        g = fast_gltf_class()().load(str(path))
    except Exception as e:
        raise MimicaError(f"{path}: not a readable glTF file ({type(e).__name__}: {e})") from None
    if g is None:
        raise MimicaError(f"{path}: not a readable glTF file")
    squeezed = [e for e in (g.extensionsRequired or []) if e in REFUSED]
    if squeezed:
        raise MimicaError(f"{path}: its geometry is {REFUSED[squeezed[0]]}-compressed ({squeezed[0]}), which "
                          "is not read here; export it again without compression, or with Draco's or EXT_meshopt's")
    if {DRACO, MESHOPT} & set((g.extensionsUsed or []) + (g.extensionsRequired or [])):
        g = _decoded(path, g)
    return g


def _decoded(path: Path, g):
    """The file with its meshopt-compressed buffer views and Draco-compressed primitives decoded
    (mesh.io.meshopt, mesh.io.draco): parsed again from the decoded JSON over one buffer; what
    open_for_edit starts from kept on it (`_mimica_doc`)."""
    import json
    from .gltf_decode import fast_gltf_class
    doc, buf = _merged(path, g)
    views = decode_meshopt(doc, buf, path)
    n = decode_draco(doc, buf, path)
    if not (n or views):
        return g
    blob = buf.blob()
    doc["buffers"] = [{"byteLength": len(blob)}]
    try:
        out = fast_gltf_class().from_json(json.dumps(doc))
    except Exception as e:
        raise MimicaError(f"{path}: not a readable glTF file ({type(e).__name__}: {e})") from None
    out.set_binary_blob(blob)
    out._mimica_doc = doc                        # open_for_edit takes a copy of it each time
    out._mimica_draco, out._mimica_meshopt = n, views
    return out


def decompressed(g) -> dict:
    """What reading decompressed in a parsed file (_load): {"Draco-compressed primitive": n,
    "meshopt-compressed buffer view": n}, those above 0 -- written back uncompressed."""
    got = {"Draco-compressed primitive": getattr(g, "_mimica_draco", 0),
           "meshopt-compressed buffer view": getattr(g, "_mimica_meshopt", 0)}
    return {k: n for k, n in got.items() if n}


def node_matrix(node) -> np.ndarray:
    """A node's local matrix.

    Parameters
    ----------
    node : pygltflib.Node

    Returns
    -------
    (4, 4) float array
        Its `matrix` (stored column-major), else T R S.
    """
    if node.matrix:
        return np.asarray(node.matrix, np.float64).reshape(4, 4).T
    from scipy.spatial.transform import Rotation
    m = np.eye(4)
    if node.rotation:
        m[:3, :3] = Rotation.from_quat(node.rotation).as_matrix()      # glTF: (x, y, z, w)
    if node.scale:
        m[:3, :3] = m[:3, :3] * np.asarray(node.scale, np.float64)
    if node.translation:
        m[:3, 3] = node.translation
    return m


def placed_meshes(g, path) -> list:
    """Every node of the default scene that holds a mesh, depth first, with its place in the world
    (a scene with no nodes: every mesh at the origin).

    Parameters
    ----------
    g : pygltflib.GLTF2
        The file, read.
    path : str or Path
        Its path, for messages.

    Returns
    -------
    list of tuple
        (node index or None, mesh index, world matrix (4, 4) float array, skinned: bool) each.
    """
    if g.scenes:
        roots = list(g.scenes[g.scene if g.scene is not None else 0].nodes or [])
    else:
        children = {c for n in g.nodes for c in (n.children or [])}
        roots = [i for i in range(len(g.nodes)) if i not in children]
    out, seen = [], set()
    stack = [(r, np.eye(4)) for r in reversed(roots)]
    while stack:
        i, parent = stack.pop()
        if not 0 <= i < len(g.nodes):
            raise MimicaError(f"{path}: the scene names node {i}, but the file has {len(g.nodes)} nodes")
        if i in seen:
            raise MimicaError(f"{path}: node {i} is reached twice (a node hierarchy must be a tree)")
        seen.add(i)
        node = g.nodes[i]
        world = parent @ node_matrix(node)
        if node.mesh is not None:
            out.append((i, node.mesh, world, node.skin is not None))
        stack.extend((c, world) for c in reversed(node.children or []))
    if not g.nodes and g.meshes:
        out = [(None, m, np.eye(4), False) for m in range(len(g.meshes))]
    return out


def _triangles(idx: np.ndarray, mode: int) -> np.ndarray:
    """A primitive's indices as (m, 3) triangles (strips and fans unrolled, glTF 2.0 3.7.2.1)."""
    if mode == 4:
        return idx[: len(idx) // 3 * 3].reshape(-1, 3)
    k = np.arange(max(len(idx) - 2, 0))
    if mode == 5:                                   # strip: every other triangle turned back
        a, b = np.where(k % 2 == 0, k, k + 1), np.where(k % 2 == 0, k + 1, k)
        return np.stack([idx[a], idx[b], idx[k + 2]], 1)
    return np.stack([np.full(len(k), idx[0]), idx[k + 1], idx[k + 2]], 1)


def _vertex_map(g, prim, count) -> np.ndarray | None:
    """The work vertex of each file vertex where mimica wrote the file: its map (VERTEX_MAP in
    the primitive's extras), or its vertices as they are (write_glb writes no map when it split
    no vertex); None for another writer's file."""
    extras = prim.extras if isinstance(prim.extras, dict) else {}
    if VERTEX_MAP in extras:
        view = g.bufferViews[int(extras[VERTEX_MAP])]
        return np.frombuffer(buffer_bytes(g, view.buffer), np.uint32, count, view.byteOffset or 0).astype(np.int64)
    return np.arange(count) if UNITS_KEY in extras else None


def read_gltf_layout(path, g=None) -> tuple[Mesh, GltfLayout]:
    """The work mesh of a glTF file (every mesh of its default scene, every primitive, in world
    space, welded) and where its vertices came from.

    Faces are the primitives' triangles in file order; groups are their materials; uv (the first
    set) stays per face corner.  Vertices a writer split are welded: within a primitive every exact
    copy where the surface stays a manifold (Mesh.welded), across primitives the two sides of a
    seam a writer split at a material (boundary edges that coincide, oriented opposite); either
    only where the copies also move alike in every morph target (copies that move apart are a
    slit, as a cut mouth's lips); a file mimica wrote keeps its own vertices (VERTEX_MAP).

    Parameters
    ----------
    path : str or Path
        A .gltf or .glb file.
    g : pygltflib.GLTF2 or None
        The file already parsed, else it is here.

    Returns
    -------
    mesh : Mesh
        The work mesh (`mesh.layout` is the layout).
    layout : GltfLayout
    """
    path = Path(path)
    g = _load(path) if g is None else g
    try:
        return _read_layout(g, path)
    except MimicaError:
        raise
    except Exception as e:
        raise MimicaError(f"{path}: not a readable glTF file ({type(e).__name__}: {e})") from None


def _read_layout(g, path: Path) -> tuple[Mesh, GltfLayout]:
    placed = placed_meshes(g, path)
    notes, sets, owner = [], {}, {}
    skipped = skinned = 0
    for node, mi, world, skin in placed:
        if not 0 <= mi < len(g.meshes):
            raise MimicaError(f"{path}: node {node} names mesh {mi}, but the file has {len(g.meshes)} meshes")
        owner.setdefault(mi, node)
        skinned += skin
        for j, prim in enumerate(g.meshes[mi].primitives):
            mode = 4 if prim.mode is None else prim.mode
            if prim.attributes.POSITION is None:
                raise MimicaError(f"{path}: mesh {mi}, primitive {j} has no POSITION (not valid glTF)")
            if mode not in SURFACE_MODES:
                skipped += owner[mi] == node
                continue
            key = (node, mi, prim.attributes.POSITION)
            s = sets.get(key)
            if s is None:
                extras = prim.extras if isinstance(prim.extras, dict) else {}
                scale = UNITS.get(extras.get(UNITS_KEY), 1.0)
                s = sets[key] = VertexSet(node, mi, prim.attributes.POSITION, np.eye(4) if skin else world,
                                          scale, own=owner[mi] == node)
            count = g.accessors[prim.attributes.POSITION].count
            idx = np.arange(count) if prim.indices is None else read_accessor(g, prim.indices).astype(np.int64)
            if len(idx) and (idx.min() < 0 or idx.max() >= count):
                raise MimicaError(f"{path}: mesh {mi}, primitive {j} refers to vertex {int(idx.max())}, but it "
                                  f"has {count} vertices")
            s.primitives.append(j)
            s.triangles.append(_triangles(idx, mode))
    sets = list(sets.values())
    if not sets:
        raise MimicaError(f"{path}: no triangle meshes in its scene (points and lines are not surfaces)")
    for what, n in decompressed(g).items():
        notes.append(f"{n} {what}{'s' if n > 1 else ''} decoded (a file written back from it holds them uncompressed)")
    if skinned:
        notes.append(f"{skinned} skinned mesh{'es' if skinned > 1 else ''} read in the bind pose (the skeleton's "
                     "pose is not applied)")
    if skipped:
        notes.append(f"{skipped} primitive{'s' if skipped > 1 else ''} of points or lines kept as "
                     f"{'they are' if skipped > 1 else 'it is'} (not surfaces)")
    twice = sorted({s.mesh for s in sets if not s.own})
    if twice:
        notes.append(f"mesh {', '.join(map(str, twice))} is placed by several nodes: a result is written on its "
                     "first placing")
    outside = len(g.meshes) - len({m for _, m, _, _ in placed})
    if outside:
        notes.append(f"{outside} mesh{'es' if outside > 1 else ''} outside the default scene kept as "
                     f"{'they are' if outside > 1 else 'it is'}")

    # the raw vertices (every set's file vertices, in order) in work space
    pos, uv, offset = [], [], 0
    for s in sets:
        p = read_accessor(g, s.position).astype(np.float64).reshape(-1, 3) / s.scale
        pos.append(p @ s.world[:3, :3].T + s.world[:3, 3])
        tex = g.meshes[s.mesh].primitives[s.primitives[0]].attributes.TEXCOORD_0
        uv.append(None if tex is None else read_accessor(g, tex).astype(np.float64).reshape(-1, 2))
        s.offset, offset = offset, offset + len(p)
    raw = np.vstack(pos)
    tris = np.vstack([t + s.offset for s in sets for t in s.triangles])
    sizes = [len(t) for s in sets for t in s.triangles]
    piece = np.repeat(np.arange(len(sizes)), sizes)
    label, exact = _labels(g, sets, raw, tris, piece)
    uniq, first = np.unique(label, return_index=True)
    if exact and uniq[0] == 0 and uniq[-1] == len(uniq) - 1:
        work_of, vertices = label, raw[first]         # mimica's own numbering
    else:                                           # in the order of their first file vertex
        order = np.argsort(first, kind="stable")
        rank = np.empty(len(uniq), np.int64)
        rank[order] = np.arange(len(uniq))
        work_of = rank[np.searchsorted(uniq, label)]
        vertices = raw[first[order]]
    face = 0
    for s, p in zip(sets, pos):
        s.vertex = work_of[s.offset: s.offset + len(p)]
        for t in s.triangles:
            s.first_face.append(face)
            face += len(t)
    mesh = Mesh.from_faces(vertices, work_of[tris])
    if any(u is not None for u in uv):
        mesh.uv = np.vstack([np.zeros((len(p), 2)) if u is None else u for p, u in zip(pos, uv)]) * [1, -1] + [0, 1]
        mesh.face_uv_indices = tris.reshape(-1).copy()
    mats = [_material_name(g, g.meshes[s.mesh].primitives[j].material, g.meshes[s.mesh].name)
            for s in sets for j in s.primitives]
    names = tuple(dict.fromkeys(mats))
    mesh.groups = np.repeat(np.array([names.index(m) for m in mats], np.int32), sizes)
    mesh.group_names = names
    extras = {}
    for mi in dict.fromkeys(s.mesh for s in sets):
        if isinstance(g.meshes[mi].extras, dict):
            extras.update(g.meshes[mi].extras)
    scales = {s.scale for s in sets}
    unit = next((u for u, k in UNITS.items() if {k} == scales), "m")
    unnamed = [mi for mi in dict.fromkeys(s.mesh for s in sets)
               if _targets(g, mi) and not (g.meshes[mi].extras or {}).get("targetNames")]
    if unnamed:
        notes.append("morph targets without names named by their index (target0, target1, ...)")
    weighted = [mi for mi in dict.fromkeys(s.mesh for s in sets) if any(w for w in (g.meshes[mi].weights or []))]
    if weighted:
        notes.append("default morph target weights not applied: the mesh is read at rest")
    layout = GltfLayout(path, sets, unit, mesh.n_vertices, mesh.n_faces, notes, extras)
    mesh.layout = layout
    return mesh, layout


def _material_name(g, mat, mesh_name) -> str:
    if mat is not None and 0 <= mat < len(g.materials or []) and g.materials[mat].name:
        return str(g.materials[mat].name)
    return f"material{mat}" if mat is not None else (mesh_name or "(no material)")


def _targets(g, mi) -> int:
    prims = g.meshes[mi].primitives
    return len(prims[0].targets or []) if prims else 0


def _labels(g, sets, raw, tris, piece) -> tuple[np.ndarray, bool]:
    """(a label per raw vertex, equal for the copies welded into one work vertex; whether the
    labels are the work vertices the file's maps name)."""
    maps = [_vertex_map(g, g.meshes[s.mesh].primitives[s.primitives[0]], g.accessors[s.position].count)
            for s in sets]
    if all(m is not None for m in maps):            # mimica's own file: its own vertices
        return np.concatenate(maps), True
    # within each primitive: exact copies, where the surface stays a manifold (Mesh.welded),
    # and where they move alike in every morph target (a cut mouth's lips stay two)
    m = Mesh.from_faces(raw, tris)
    m.groups, m.group_names = piece.astype(np.int32), tuple(range(int(piece.max()) + 1))
    moves = _target_moves(g, sets)
    w, label = m.welded(moves)
    set_of = np.repeat(np.arange(len(sets)), [g.accessors[s.position].count for s in sets])
    same = None
    if moves is not None:
        same = np.zeros((w.n_vertices, moves.shape[1]))
        same[label] = moves
    return weld_seams(w.vertices, label[m.half_edges], set_of, label, same), False


def _target_rows(g, index) -> np.ndarray:
    """A morph target's POSITION rows (n, 3) float64, decoded once per parsed file: the weld
    (_target_moves) and morph_targets both read them (read-only)."""
    done = g.__dict__.setdefault("_mimica_target_rows", {})
    if index not in done:
        done[index] = read_accessor(g, index).astype(np.float64).reshape(-1, 3)
        done[index].flags.writeable = False
    return done[index]


def _target_moves(g, sets):
    """(n_raw, 2) per raw vertex: its morph targets' moves (weld.move_key); None where no set
    has targets."""
    rows = []
    for s in sets:
        prim = g.meshes[s.mesh].primitives[s.primitives[0]]
        d = [_target_rows(g, t["POSITION"]) / s.scale @ s.world[:3, :3].T
             for t in (prim.targets or []) if t.get("POSITION") is not None]
        rows.append(d)
    k = max((len(d) for d in rows), default=0)
    if not k:
        return None
    out = []
    for s, d in zip(sets, rows):
        full = np.zeros((g.accessors[s.position].count, 3 * k))
        if d:
            full[:, :3 * len(d)] = np.hstack(d)
        out.append(full)
    return move_key(np.vstack(out))


def read_gltf(path) -> Mesh:
    """The work mesh of a glTF/GLB file (read_gltf_layout).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    Mesh
        `mesh.layout` says where its vertices came from.
    """
    return read_gltf_layout(path)[0]


def morph_targets(g, layout: GltfLayout, mesh: Mesh) -> dict:
    """Every morph target of the layout's meshes, on the work mesh.  A work vertex takes the target
    of its first file vertex; a vertex of a mesh without that target stays at rest.

    Parameters
    ----------
    g : pygltflib.GLTF2
        The parsed file.
    layout : GltfLayout
    mesh : Mesh
        The work mesh.

    Returns
    -------
    dict
        {name: (n, 3) float array} work positions; unnamed targets are `target<i>`.
    """
    def names(s):
        gm = g.meshes[s.mesh]
        given = list((gm.extras or {}).get("targetNames") or []) if isinstance(gm.extras, dict) else []
        prim = gm.primitives[s.primitives[0]]
        return [str(given[i]) if i < len(given) else f"target{i}" for i in range(len(prim.targets or []))]
    out = {n: np.zeros_like(mesh.vertices) for s in layout.sets for n in names(s)}
    for s in reversed(layout.sets):
        prim = g.meshes[s.mesh].primitives[s.primitives[0]]
        for name, t in zip(names(s), prim.targets or []):
            if t.get("POSITION") is None:
                continue
            d = _target_rows(g, t["POSITION"]) / s.scale @ s.world[:3, :3].T
            out[name][s.vertex[::-1]] = d[::-1]
    return {n: mesh.vertices + d for n, d in out.items()}


def read_morph_targets(path) -> tuple[Mesh, dict, str]:
    """A glTF file's morph targets, in world space on the work mesh's vertices.

    Parameters
    ----------
    path : str or Path
        A .gltf or .glb with morph targets (named by the mesh's extras.targetNames, else target0,
        target1, ...).

    Returns
    -------
    mesh : Mesh
        The work mesh.
    targets : dict
        {name: (n, 3) float array} positions.
    unit : str
        The mesh's unit ("m" unless mimica wrote the file).
    """
    from .checks import validate
    path = Path(path)
    if not path.is_file():
        raise MimicaError(f"{path}: no such file")
    g = _load(path)
    mesh = validate(read_gltf_layout(path, g)[0], str(path))
    mesh.name = path.stem
    try:
        out = morph_targets(g, mesh.layout, mesh)
    except Exception as e:
        raise MimicaError(f"{path}: its morph targets cannot be read ({type(e).__name__}: {e})") from None
    if not out:
        raise MimicaError(f"{path}: no morph targets")
    return mesh, out, mesh.layout.unit


# ----------------------------------------------------------------- writing back
# The writers work on the file's own JSON (a dict), so that nothing of it is lost: pygltflib's
# objects drop what they do not model (a node's `weights`, properties of extensions' authors).
_GLB_JSON, _GLB_BIN = 0x4E4F534A, 0x004E4942
_MIME = {".png": "image/png", ".jpg": "image/jpeg", ".jpeg": "image/jpeg", ".webp": "image/webp",
         ".ktx2": "image/ktx2"}


def _uri_bytes(uri: str, folder: Path) -> bytes | None:
    """The bytes a buffer's or image's uri names (a data URI, or a file beside the glTF)."""
    import base64
    from urllib.parse import unquote
    if uri.startswith("data:"):
        return base64.b64decode(uri.split(",", 1)[1])
    f = folder / unquote(uri)
    return f.read_bytes() if f.is_file() else None


def _json_of(path: Path) -> dict:
    """The JSON of a .gltf, or of a GLB's first chunk."""
    import json
    import struct
    data = path.read_bytes()
    if data[:4] == b"glTF":
        size, kind = struct.unpack_from("<II", data, 12)
        if kind != _GLB_JSON:
            raise MimicaError(f"{path}: a GLB whose first chunk is not its JSON")
        return json.loads(data[20:20 + size])
    return json.loads(data)


def open_for_edit(path):
    """A glTF file opened to add to: its buffers merged into one (the buffer views re-pointed), its
    images put inside it (glTF allows that in .gltf too), so the result stands on its own anywhere.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    g : pygltflib.GLTF2
        The parsed file, to read accessors from.
    doc : dict
        Its JSON.
    buf : _Buffers
        All its bytes as one buffer, to add to.
    notes : list of str
        What could not be put inside (an image not beside the file keeps its uri).
    """
    import copy
    path = Path(path)
    g = _load(path)
    if getattr(g, "_mimica_doc", None) is not None:          # decompressed on reading: its one buffer as read
        doc = copy.deepcopy(g._mimica_doc)
        buf = _Buffers(g.binary_blob(), doc["bufferViews"], doc["accessors"])
    else:
        doc, buf = _merged(path, g)
    notes = []
    for im in doc.get("images", []):
        if not im.get("uri"):
            continue
        data = _uri_bytes(im["uri"], path.parent)
        if data is None:
            notes.append(f"image {im['uri']!r} is not beside {path.name}: its uri is kept as it is")
            continue
        im["mimeType"] = im["uri"][5:].split(";", 1)[0] if im["uri"].startswith("data:") else \
            _MIME.get(Path(im["uri"]).suffix.lower(), "application/octet-stream")
        im["bufferView"] = buf.view(np.frombuffer(data, np.uint8))
        del im["uri"]
    return g, doc, buf, notes


def _merged(path: Path, g) -> tuple[dict, "_Buffers"]:
    """A glTF file's JSON and all its buffers as one (the buffer views re-pointed at it)."""
    try:
        doc = _json_of(path)
        parts, base, at = [], [], 0
        for i, b in enumerate(doc.get("buffers", [])):
            if b.get("uri") is not None:
                data = _uri_bytes(b["uri"], path.parent)
            elif MESHOPT in (doc.get("extensionsUsed") or []) and placeholder(doc, i):
                # meshopt's fallback: its views are decoded into place
                data = b""
            else:
                data = g.binary_blob() if i == 0 else None
            if data is None:
                raise MimicaError(f"{path}: its buffer {b.get('uri') or i!r} is missing (keep its .bin files beside it)")
            data = bytes(data[:b["byteLength"]])
            base.append(at)
            parts.append(data + b"\0" * ((-len(data)) % 8))
            at += len(parts[-1])
    except MimicaError:
        raise
    except Exception as e:
        raise MimicaError(f"{path}: not a readable glTF file ({type(e).__name__}: {e})") from None
    doc.setdefault("bufferViews", [])
    doc.setdefault("accessors", [])
    for v in doc["bufferViews"]:
        v["byteOffset"] = base[v["buffer"]] + v.get("byteOffset", 0)
        v["buffer"] = 0
        squeezed = (v.get("extensions") or {}).get(MESHOPT)
        if isinstance(squeezed, dict) and isinstance(squeezed.get("buffer"), int) and 0 <= squeezed["buffer"] < len(base):
            squeezed["byteOffset"] = base[squeezed["buffer"]] + squeezed.get("byteOffset", 0)
            squeezed["buffer"] = 0
    return doc, _Buffers(b"".join(parts), doc["bufferViews"], doc["accessors"])


def save_edited(doc: dict, buf: "_Buffers", path, binary: bool = True) -> None:
    """Write a glTF document with its bytes, whole or not at all.

    Parameters
    ----------
    doc : dict
        The glTF JSON.
    buf : _Buffers
        Its one buffer.
    path : str or Path
    binary : bool
        A GLB; else a .gltf with its bytes inside (a data URI).
    """
    import base64
    import json
    import struct
    blob = buf.blob()
    doc["buffers"] = [{"byteLength": len(blob)}] if blob else []
    for k in ("bufferViews", "accessors"):
        if not doc.get(k):
            doc.pop(k, None)
    if binary:
        j = json.dumps(doc, separators=(",", ":")).encode()
        j += b" " * ((-len(j)) % 4)
        body = struct.pack("<II", len(j), _GLB_JSON) + j
        if blob:
            body += struct.pack("<II", len(blob), _GLB_BIN) + blob
        Path(path).write_bytes(struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body)
    else:
        if blob:
            doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(blob).decode()
        Path(path).write_text(json.dumps(doc, indent=1))


def _copy_rows(g, buf, index, src, minmax=False) -> int:
    """A new accessor: accessor `index`'s rows `src` (its type, component and normalization)."""
    acc = g.accessors[index]
    return buf.add(read_accessor(g, index, normalize=False)[src], ARRAY_BUFFER, acc.type, acc.componentType, minmax,
                   bool(acc.normalized))


def _corners(s: VertexSet, tri: np.ndarray, n_read: int):
    """(file vertex -> source row (count + k,), file vertex -> work vertex, each primitive's
    triangles in file vertices) of a set in the result `tri` (the work mesh's triangles, a cut's
    corners re-pointed to vertices past n_read).  A file vertex whose corners all moved to one
    copy becomes that copy (the file had the cut's two sides apart already: a flat-shaded or
    uv-split export); one shared by both sides gets a vertex of its own, appended after the
    file's."""
    count = len(s.vertex)
    work = s.vertex.copy()
    corners = np.concatenate([t.reshape(-1) for t in s.triangles]) if s.triangles else np.zeros(0, np.int64)
    w_out = np.concatenate([tri[f0: f0 + len(t)].reshape(-1) for t, f0 in zip(s.triangles, s.first_face)]) \
        if s.triangles else np.zeros(0, np.int64)
    moved = w_out != s.vertex[corners]
    if (w_out[moved] < n_read).any():
        raise ValueError("the result's faces are not the read mesh's")
    # a file vertex whose corners all went to one copy: re-pointed in place
    lo = np.full(count, np.iinfo(np.int64).max)
    hi = np.full(count, -1)
    np.minimum.at(lo, corners, w_out)
    np.maximum.at(hi, corners, w_out)
    whole = (lo == hi) & (hi >= n_read)
    work[whole] = hi[whole]
    split = moved & ~whole[corners]
    pairs = np.stack([corners[split], w_out[split]], 1)
    first, inv, _ = unique_rows(pairs)
    pairs = pairs[first]
    new_corners = corners.copy()
    new_corners[split] = count + inv.ravel()
    tris, at = [], 0
    for t in s.triangles:
        tris.append(new_corners[at: at + t.size].reshape(-1, 3))
        at += t.size
    return np.r_[np.arange(count), pairs[:, 0]], np.r_[work, pairs[:, 1]], tris


def write_gltf_layout(path, layout: GltfLayout, mesh: Mesh, targets: dict | None = None, binary: bool = True,
                      extras: dict | None = None, sparse: float = SPARSE_TOLERANCE) -> dict:
    """Write the file `layout` was read from back, with a result and its morph targets.

    The result `mesh` has the work mesh's faces in their order: its vertices moved, and a cut's
    vertices appended after the read ones with corners re-pointed to them.  The morph targets are
    added to each of the file's meshes, in each node's own space.  Everything else -- nodes,
    transforms, materials, textures (put inside the file), skins, animations (weights animations
    given the new targets at zero), extensions, meshes outside the scene -- comes back as it was.
    Morph targets move only positions (normals are the client's).

    Parameters
    ----------
    path : str or Path
        The file to write.
    layout : GltfLayout
        From read_gltf_layout.
    mesh : Mesh
        The result.
    targets : dict or None
        {name: (n, 3) positions of `mesh`'s vertices}.
    binary : bool
        GLB, else .gltf.
    extras : dict or None
        Added to the extras of the mesh with the most vertices.
    sparse : float
        Metres (the file's unit) below which a target's vertex is stored as still.

    Returns
    -------
    dict
        {"appended": file vertices added, "accessors": target accessors written, "sparse": how many
        of them sparse, "notes": [...]}.
    """
    if mesh.n_faces != layout.n_faces:
        raise ValueError(f"the result has {mesh.n_faces} faces; the file was read with {layout.n_faces}")
    g, doc, buf, notes = open_for_edit(layout.path)
    targets = targets or {}
    names = list(targets)
    tri = mesh.triangles
    done, appended, n_sparse, grown = {}, 0, 0, {}
    for mi in layout.meshes:
        gm = doc["meshes"][mi]
        prims = gm.get("primitives", [])
        grown[mi] = len(prims[0].get("targets", [])) if prims else 0
        sets = {j: s for s in layout.sets if s.mesh == mi and s.own for j in s.primitives}
        zeros = {}
        for j, prim in enumerate(prims):
            s = sets.get(j)
            if s is None:                            # points or lines: targets of zeros (one count a mesh)
                if names:
                    cnt = g.accessors[prim["attributes"]["POSITION"]].count
                    if cnt not in zeros:
                        zeros[cnt] = buf.add_sparse(np.zeros((cnt, 3)), np.zeros(cnt, bool), True)
                    prim["targets"] = prim.get("targets", []) + [{"POSITION": zeros[cnt]} for _ in names]
                continue
            if id(s) not in done:
                done[id(s)] = _set_accessors(g, buf, s, mesh, tri, layout.n_vertices, targets, sparse)
                appended += done[id(s)]["appended"]
                n_sparse += done[id(s)]["sparse"]
            _rewrite_primitive(g, buf, prim, done[id(s)], s.primitives.index(j))
        if names:
            given = [str(n) for n in (gm.get("extras") or {}).get("targetNames", [])][:grown[mi]]
            gm["extras"] = {**(gm.get("extras") or {}),
                            "targetNames": given + [f"target{i}" for i in range(len(given), grown[mi])] + names}
            gm["weights"] = list(gm.get("weights") or [0.0] * grown[mi]) + [0.0] * len(names)
    if names:
        _grow_weights(g, doc, buf, {mi: (grown[mi], len(names)) for mi in layout.meshes})
    if extras:
        main = doc["meshes"][max(layout.sets, key=lambda s: len(s.vertex)).mesh]
        main["extras"] = {**(main.get("extras") or {}), **extras}
    save_edited(doc, buf, path, binary)
    return {"appended": appended, "accessors": len(done) * len(names), "sparse": n_sparse, "notes": notes}


def _rewrite_primitive(g, buf, prim: dict, r: dict, k: int) -> None:
    """One primitive of a set given its set's new accessors (r: _set_accessors); k: its place
    among the set's primitives."""
    if r["appended"]:                                # every attribute and target gets the copies' rows
        for attr, acc in prim["attributes"].items():
            if attr != "POSITION":
                if acc not in r["copies"]:
                    r["copies"][acc] = _copy_rows(g, buf, acc, r["src"])
                prim["attributes"][attr] = r["copies"][acc]
        for t in prim.get("targets", []):
            for a, acc in t.items():
                if ("t", acc) not in r["copies"]:
                    r["copies"]["t", acc] = _copy_rows(g, buf, acc, r["src"], a == "POSITION")
                t[a] = r["copies"]["t", acc]
        tk = r["triangles"][k].reshape(-1)
        big = len(r["src"]) > 65535
        prim["indices"] = buf.add(tk.astype(np.uint32 if big else np.uint16), ELEMENT_ARRAY_BUFFER, "SCALAR",
                                  UNSIGNED_INT if big else UNSIGNED_SHORT)
        prim.pop("mode", None)                       # strips and fans now triangles
    prim["attributes"]["POSITION"] = r["position"]
    if r["targets"]:
        prim["targets"] = prim.get("targets", []) + r["targets"]
    prim["extras"] = {**(prim.get("extras") if isinstance(prim.get("extras"), dict) else {}), VERTEX_MAP: r["map"]}


def _set_accessors(g, buf, s: VertexSet, mesh, tri, n_read, targets, sparse) -> dict:
    """The new accessors of one vertex set: positions (the file's own where the result kept
    them), the appended vertices' triangles, the vertex map, the new morph targets."""
    src, work, tris = _corners(s, tri, n_read)
    orig = read_accessor(g, s.position).astype(np.float64).reshape(-1, 3)
    local = s.to_local(mesh.vertices[work])
    size = max(float(np.ptp(orig, axis=0).max()), 1e-30)
    moved = bool(len(local)) and np.abs(local - orig[src]).max() > 1e-6 * size
    out = {"appended": len(src) - len(s.vertex), "src": src, "triangles": tris, "copies": {}, "sparse": 0}
    if moved:
        out["position"] = buf.add(local.astype(np.float32), ARRAY_BUFFER, "VEC3", FLOAT, True)
    elif out["appended"]:
        out["position"] = _copy_rows(g, buf, s.position, src, True)
    else:
        out["position"] = s.position
    out["map"] = buf.view(work.astype(np.uint32))
    out["targets"] = []
    for name, p in targets.items():
        d = s.vectors_to_local(np.asarray(p, np.float64)[work] - mesh.vertices[work])
        keep = np.linalg.norm(d, axis=1) > sparse
        out["sparse"] += int(keep.mean() <= 1 / 3)
        out["targets"].append({"POSITION": buf.add_sparse(d, keep, True)})
    return out


def _grow_weights(g, doc, buf, grow: dict) -> None:
    """The nodes' weights and the weights animations of meshes given new targets: zeros for
    them, at every key (CUBICSPLINE's tangents too)."""
    nodes = {i: grow[n["mesh"]] for i, n in enumerate(doc.get("nodes", [])) if n.get("mesh") in grow}
    for i, (before, added) in nodes.items():
        if doc["nodes"][i].get("weights"):
            doc["nodes"][i]["weights"] = list(doc["nodes"][i]["weights"]) + [0.0] * added
    for anim in doc.get("animations", []):
        grown = set()
        for ch in anim.get("channels", []):
            tgt = ch.get("target", {})
            if tgt.get("path") != "weights" or tgt.get("node") not in nodes or ch["sampler"] in grown:
                continue
            before, added = nodes[tgt["node"]]
            smp = anim["samplers"][ch["sampler"]]
            w = read_accessor(g, smp["output"]).astype(np.float32).reshape(-1, max(before, 1))
            w = np.concatenate([w, np.zeros((len(w), added), np.float32)], 1)
            smp["output"] = buf.add(w.reshape(-1), None, "SCALAR", FLOAT)
            grown.add(ch["sampler"])


def buffer_bytes(g, i) -> bytes:
    """The bytes of one of a glTF's buffers.

    Parameters
    ----------
    g : pygltflib.GLTF2
    i : int
        The buffer.

    Returns
    -------
    bytes
        The GLB's own chunk, or a data URI's.
    """
    return g.binary_blob() if g.buffers[i].uri is None else g.get_data_from_buffer_uri(g.buffers[i].uri)


def read_accessor(g, index, normalize: bool = True) -> np.ndarray:
    """An accessor's rows, sparse ones made whole.

    Parameters
    ----------
    g : pygltflib.GLTF2
    index : int
        The accessor.
    normalize : bool
        Normalized integers (KHR_mesh_quantization) as the floats they stand for; False: as stored
        (to copy them).

    Returns
    -------
    (count, components) array
    """
    acc = g.accessors[index]
    if acc.sparse is not None:                    # zeros (or its buffer view), then the listed rows
        dt, nc = np.dtype(_COMPONENT[acc.componentType]), _NCOMP[acc.type]
        out = np.zeros((acc.count, nc), dt) if acc.bufferView is None else \
            _accessor_raw(g, acc).reshape(acc.count, nc).copy()
        sp_ = acc.sparse
        iv, vv = g.bufferViews[sp_.indices.bufferView], g.bufferViews[sp_.values.bufferView]
        rows = np.frombuffer(buffer_bytes(g, iv.buffer), _COMPONENT[sp_.indices.componentType], sp_.count,
                             (iv.byteOffset or 0) + (sp_.indices.byteOffset or 0))
        out[rows.astype(np.int64)] = np.frombuffer(buffer_bytes(g, vv.buffer), dt, sp_.count * nc,
                                                   (vv.byteOffset or 0) + (sp_.values.byteOffset or 0)).reshape(-1, nc)
        out = out.squeeze(-1) if nc == 1 else out
    else:
        out = _accessor_raw(g, acc)
    if normalize and acc.normalized and out.dtype.kind in "iu":  # glTF 2.0 3.11: c / (2^b - 1) or max(c / (2^(b-1) - 1), -1)
        top = float(np.iinfo(out.dtype).max)
        out = out / top if out.dtype.kind == "u" else np.maximum(out / top, -1.0)
    return out


def _accessor_raw(g, acc) -> np.ndarray:
    view = g.bufferViews[acc.bufferView]
    data = buffer_bytes(g, view.buffer)
    dt = np.dtype(_COMPONENT[acc.componentType])
    nc = _NCOMP[acc.type]
    start = (view.byteOffset or 0) + (acc.byteOffset or 0)
    stride = view.byteStride or dt.itemsize * nc
    raw = np.frombuffer(data, dtype=np.uint8, count=stride * (acc.count - 1) + dt.itemsize * nc, offset=start)
    rows = np.lib.stride_tricks.as_strided(raw, shape=(acc.count, dt.itemsize * nc), strides=(stride, 1))
    return np.ascontiguousarray(rows).view(dt).reshape(acc.count, nc).squeeze(-1) if nc == 1 else \
        np.ascontiguousarray(rows).view(dt).reshape(acc.count, nc)


class _Buffers:
    """The binary chunk of a glTF being written, its buffer views and accessors (JSON dicts),
    appended to one by one; `data` may start with a file's own bytes."""

    def __init__(self, data: bytes = b"", views=None, accessors=None):
        self.data = bytearray(data)
        self.data += b"\0" * ((-len(self.data)) % 4)
        self.views = [] if views is None else views
        self.accessors = [] if accessors is None else accessors

    def blob(self) -> bytes:
        return bytes(self.data)

    def append(self, raw: bytes) -> int:
        """Bytes added on 4 bytes, as glTF wants; their offset."""
        off = len(self.data)
        self.data += raw + b"\0" * ((-len(raw)) % 4)
        return off

    def view(self, arr, target=None, stride=None) -> int:
        """A buffer view of the array's bytes (on 4 bytes, as glTF wants); its index."""
        data = np.ascontiguousarray(arr)
        v = {"buffer": 0, "byteOffset": self.append(data.tobytes()), "byteLength": int(data.nbytes)}
        if target is not None:
            v["target"] = target
        if stride is not None:
            v["byteStride"] = int(stride)
        self.views.append(v)
        return len(self.views) - 1

    def rows_view(self, arr, target) -> int:
        """A buffer view of arr's rows; in a vertex buffer each row padded to 4 bytes (glTF 2.0
        3.6.2.4: each vertex's element starts on 4 bytes -- quantized VEC3s); its index."""
        arr = np.ascontiguousarray(arr)
        if target == ARRAY_BUFFER and arr.ndim == 2 and arr.itemsize * arr.shape[1] % 4:
            width = -(-arr.itemsize * arr.shape[1] // 4) * 4 // arr.itemsize
            data = np.zeros((len(arr), width), arr.dtype)
            data[:, :arr.shape[1]] = arr
            return self.view(data, target, width * arr.itemsize)
        return self.view(arr, target)

    def add(self, arr, target, acc_type, comp, minmax=False, normalized=False) -> int:
        """An accessor of the rows of arr in a view of its own; its index."""
        arr = np.ascontiguousarray(arr)
        a = {"bufferView": self.rows_view(arr, target), "componentType": int(comp), "count": len(arr),
             "type": acc_type}
        if normalized:
            a["normalized"] = True
        if minmax:
            a["min"], a["max"] = np.atleast_1d(arr.min(0)).tolist(), np.atleast_1d(arr.max(0)).tolist()
        self.accessors.append(a)
        return len(self.accessors) - 1

    @staticmethod
    def encode(arr, q):
        """(stored array, component type, normalized): float32, or with q ("short", "byte") the
        normalized integers of KHR_mesh_quantization (glTF 2.0 3.11: f = max(c / (2^(b-1) - 1), -1);
        values beyond +-1 clipped)."""
        if q is None:
            return np.asarray(arr, np.float32), FLOAT, False
        dt, comp = (np.int16, SHORT) if q == "short" else (np.int8, BYTE)
        top = np.iinfo(dt).max
        return np.clip(np.rint(np.asarray(arr) * top), -top, top).astype(dt), comp, True

    def add_sparse(self, arr, keep, minmax=False, q=None) -> int:
        """A VEC3 accessor of len(arr) rows, zero but where `keep` (a sparse accessor); dense
        where more than a third of the rows are kept (smaller so).  q: quantized (encode)."""
        if not keep.any():                          # glTF wants one row at least
            keep = np.r_[True, np.zeros(len(keep) - 1, bool)]
        if keep.mean() > 1 / 3:
            vals, comp, norm = self.encode(np.where(keep[:, None], arr, 0), q)
            return self.add(vals, ARRAY_BUFFER, "VEC3", comp, minmax, norm)
        rows = np.nonzero(keep)[0]
        # indices as 16 bits where the vertices allow (glTF: UNSIGNED_BYTE, _SHORT or _INT)
        rows, icomp = (rows.astype(np.uint16), UNSIGNED_SHORT) if len(arr) <= 65535 else \
            (rows.astype(np.uint32), UNSIGNED_INT)
        vals, comp, norm = self.encode(arr[rows], q)
        a = {"componentType": int(comp), "count": len(arr), "type": "VEC3",
             "sparse": {"count": len(rows), "indices": {"bufferView": self.view(rows), "componentType": icomp},
                        "values": {"bufferView": self.view(vals)}}}
        if norm:
            a["normalized"] = True
        if minmax:                                  # of the whole accessor: its zeros too
            full = vals if len(rows) == len(arr) else np.vstack([vals, np.zeros((1, 3), vals.dtype)])
            a["min"], a["max"] = full.min(0).tolist(), full.max(0).tolist()
        self.accessors.append(a)
        return len(self.accessors) - 1


def glb_units(mesh: Mesh, units: str = "auto") -> tuple[str, float]:
    """A mesh's unit, for writing it in glTF's metres.

    Parameters
    ----------
    mesh : Mesh
    units : str
        "m", "cm", "mm", or "auto": a head up to 3 units tall is in metres, up to 100 in
        centimetres (ICT-FaceKit: 33), taller in millimetres.

    Returns
    -------
    unit : str
    metres_per_unit : float
    """
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
    pairs = np.stack([tri.reshape(-1), uvt.reshape(-1)], 1)
    first, inv, _ = unique_rows(pairs)
    pairs = pairs[first]
    unused = np.setdiff1d(np.arange(mesh.n_vertices), pairs[:, 0])
    v_of = np.r_[pairs[:, 0], unused]
    uv_of = np.r_[pairs[:, 1], np.full(len(unused), -1)]
    return v_of, uv_of, inv.reshape(-1, 3)


def unit_normals(mesh: Mesh, vertices: np.ndarray) -> np.ndarray:
    """Unit vertex normals, as glTF wants them on every vertex.

    Parameters
    ----------
    mesh : Mesh
    vertices : (n, 3) float array
        The positions to take them at.

    Returns
    -------
    (n, 3) float array
        A vertex no triangle uses gets +z.
    """
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
    """Write a triangulated mesh as glTF, optionally with named morph targets.

    Parameters
    ----------
    path : Path
    mesh : Mesh
    morph_targets : dict or None
        {name: (n, 3) positions}.
    binary : bool
        GLB, else .gltf.
    fps : float or None
        Also write an animation that plays the morph targets in order, one per frame at this rate
        (weights interpolated linearly between frames), for frame sequences.
    units : str
        The mesh's unit ("m", "cm", "mm", or "auto": glb_units); glTF is in metres, so the
        positions are scaled to metres and the unit is kept in the primitive's extras, which
        mimica's reader undoes.
    sparse : float or None
        Morph targets as sparse accessors: a vertex that moves less than this many metres
        (SPARSE_TOLERANCE: 0.01 mm) keeps zero, as does a normal that turns less than
        SPARSE_NORMAL; None writes every target dense.
    weights : (F, k) float array or None
        With fps, the animation's weights per frame instead of one target per frame (a clip as a
        few basis shapes, export.compact).
    extras : dict or None
        More of the mesh's extras (with targetNames).
    quantize : bool
        Morph targets in KHR_mesh_quantization's normalized integers (moves to 0.015 mm,
        QUANTIZE_ERROR; about half the size), the extension then required of readers.

    Returns
    -------
    dict
        {"units": the unit used, "sparse": how many targets were written sparse}.
    """
    # glTF keeps one uv per vertex: a vertex on a uv seam is written once per uv it has, and the
    # map from the file's vertices back to the mesh's is kept (VERTEX_MAP) for mimica's reader
    v_of, uv_of, t = _gltf_vertices(mesh)
    unit, k = glb_units(mesh, units)
    v = (k * mesh.vertices[v_of]).astype(np.float32)
    t = t.astype(np.uint32)
    buf = _Buffers()
    add, add_sparse, views, accs = buf.add, buf.add_sparse, buf.views, buf.accessors

    ipos = add(v, ARRAY_BUFFER, "VEC3", FLOAT, True)
    # smooth normals, so that viewers shade the surface smooth and a DCC's round trip keeps the
    # vertices whole (without them three.js and Blender shade flat, and Blender's re-export
    # splits every vertex); morph targets carry the change of the normal (glTF: deltas)
    n0 = unit_normals(mesh, mesh.vertices)
    inrm = add(n0[v_of].astype(np.float32), ARRAY_BUFFER, "VEC3", FLOAT)
    grouped = mesh.groups is not None and len(mesh.group_names) > 0
    attrs = {"POSITION": ipos, "NORMAL": inrm}
    if uv_of is not None:
        tex = np.where(uv_of[:, None] >= 0, mesh.uv[np.maximum(uv_of, 0)], 0.0) * [1, -1] + [0, 1]
        attrs["TEXCOORD_0"] = add(tex.astype(np.float32), ARRAY_BUFFER, "VEC2", FLOAT)
    prim_extras = {UNITS_KEY: unit}
    if len(v_of) != mesh.n_vertices or (v_of != np.arange(len(v_of))).any():
        prim_extras[VERTEX_MAP] = buf.view(v_of.astype(np.uint32))     # a buffer view, not an accessor
    # one primitive and material per OBJ material / group, all on the same vertices
    prims, materials = [], []
    if grouped:
        tri_group = np.asarray(mesh.groups)[mesh.tri_face]
        for gi in np.unique(tri_group):
            sel = t[tri_group == gi].reshape(-1)
            materials.append({"name": str(mesh.group_names[gi]),
                              "pbrMetallicRoughness": {"metallicFactor": 0.0, "roughnessFactor": 0.6}})
            prims.append({"attributes": attrs, "indices": add(sel, ELEMENT_ARRAY_BUFFER, "SCALAR", UNSIGNED_INT),
                          "material": len(materials) - 1, "extras": prim_extras})
    else:
        prims.append({"attributes": attrs, "indices": add(t.reshape(-1), ELEMENT_ARRAY_BUFFER, "SCALAR",
                                                          UNSIGNED_INT), "extras": prim_extras})
    names, tg = [], []
    if morph_targets:
        for name, pos in morph_targets.items():
            pos = np.asarray(pos, dtype=np.float64)
            dp = (k * (pos - mesh.vertices)[v_of]).astype(np.float32)
            n1 = unit_normals(mesh, pos)
            dn = ((_reachable_normal_change(n0, n1) if quantize else n1 - n0)[v_of]).astype(np.float32)
            # quantized: moves as 16-bit normalized metres (0.03 mm steps; normalized integers
            # reach +-1 only: a target that moves a vertex over 1 m stays float), normal changes
            # as 8 bits (1/127 steps)
            qp = "short" if quantize and np.abs(dp).max() < 1.0 else None
            qn = "byte" if quantize else None
            if sparse is None:
                tg.append({"POSITION": add_sparse(dp, np.ones(len(dp), bool), True, qp),
                           "NORMAL": add_sparse(dn, np.ones(len(dn), bool), False, qn)})
            else:
                # sparse targets: the vertices that move more than `sparse` metres, and the
                # normals that turn by more than SPARSE_NORMAL, are stored; the rest are zero
                tg.append({"POSITION": add_sparse(dp, np.linalg.norm(dp, axis=1) > sparse, True, qp),
                           "NORMAL": add_sparse(dn, np.linalg.norm(dn, axis=1) > SPARSE_NORMAL, False, qn)})
            names.append(name)
        for pr in prims:                            # the same targets on every primitive
            pr["targets"] = tg
    gmesh = {"primitives": prims}
    if names:
        gmesh["extras"] = {"targetNames": names, **(extras or {})}
        gmesh["weights"] = [0.0] * len(names)
    doc = {"asset": {"version": "2.0", "generator": "mimica"}, "scene": 0, "scenes": [{"nodes": [0]}],
           "nodes": [{"mesh": 0}], "meshes": [gmesh], "accessors": accs, "bufferViews": views}
    if materials:
        doc["materials"] = materials
    if fps and names:
        w = np.eye(len(names), dtype=np.float32) if weights is None else np.asarray(weights, np.float32)
        if w.ndim != 2 or w.shape[1] != len(names):
            raise MimicaError(f"weights: {w.shape} for {len(names)} morph targets")
        times = (np.arange(len(w)) / float(fps)).astype(np.float32)
        itime = add(times, None, "SCALAR", FLOAT, True)
        iw = add(w.reshape(-1), None, "SCALAR", FLOAT)
        doc["animations"] = [{"name": "frames", "samplers": [{"input": itime, "output": iw, "interpolation": "LINEAR"}],
                              "channels": [{"sampler": 0, "target": {"node": 0, "path": "weights"}}]}]
    if any(a.get("normalized") for a in accs):      # its readers must know the integer attributes
        doc["extensionsUsed"] = doc["extensionsRequired"] = [QUANTIZATION]
    save_edited(doc, buf, path, binary)
    return {"units": unit, "sparse": sum("sparse" in accs[x["POSITION"]] for x in tg),
            "quantized": sum(bool(accs[x["POSITION"]].get("normalized")) for x in tg)}
