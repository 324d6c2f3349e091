"""The face rig (Kim 2020 §IV-V): skin, muscles as thin shell strips, the spring layer,
per-muscle regions of interest and the nodes the skull holds.

`build_rig(skin, landmarks)` places every muscle of the library from the 68 landmarks, so
the same definitions fit any face of any topology.  A `Rig` saves to one `.rig` file, with
the modal system of each force type (Kim §VI) when the physics stage has precomputed them
(`mimica.physics.precompute`): the rig carries them, it does not make them.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.distance import cdist

from ..align import face_cylinder
from ..errors import MimicaError
from ..mesh import Mesh, atomic_path, validate
from ..mesh.query import TriangleLocator
from .drives import DRIVES, place_drive
from .muscles import KIM_MUSCLES, MUSCLES, MuscleDef

ROWS, COLS = 9, 4                # strip resolution along / across (Kim: 36 nodes a muscle)
FORMAT = "mimica-rig/2"          # 2: the strips' springs fan out over the skin (spring_fan)


@dataclass
class Muscle:
    """One placed muscle (Kim 2020 §IV): a thin strip of nodes from the skull to under the skin,
    its stretch mode, a spring from each node to the skin, and its region of interest.

    Attributes
    ----------
    name : str
        As in the library (rig.muscles.MUSCLES, rig.drives.DRIVES), "_L"/"_R" for a side.
    nodes : (k, 3) float array
        The strip's nodes at rest.
    stretch : (k, 3) float array
        Their displacement at full contraction (activation 1).
    omega : float
        The stretch mode's frequency, rad/s (critically damped).
    attach : (k,) int array
        The skin node each node's spring ties to.
    roi : (n_skin,) bool array
        The skin its system covers (Kim eq. 19).
    basis : ModalBasis or dict or None
        Its skin system (physics.precompute); arrays when loaded from a file, None until made.
    kind : str
        "strip" (a muscle) or "drive" (the jaw, a lid, a cheek: rig.drives).
    weight : (k,) float array or None
        A drive's attachment strengths.
    info : dict
        What placed it (its origin and insertion, calibration).
    """

    name: str
    nodes: np.ndarray            # (k, 3) rest positions
    stretch: np.ndarray          # (k, 3) displacement at full contraction (activation 1)
    omega: float                 # frequency of the stretch mode (rad/s), critically damped
    attach: np.ndarray           # (k,) skin node of each muscle node's spring
    roi: np.ndarray              # (n_skin,) bool, Kim eq. 19
    basis: object = None         # its skin system (physics.precompute); a dict of arrays when loaded
    kind: str = "strip"          # "strip": a muscle of the library; "drive": the jaw or a lid (rig.drives)
    weight: np.ndarray | None = None   # (k,) a drive's attachment strengths (springs k x weight)
    info: dict = field(default_factory=dict)
    fan: tuple | None = None     # a strip's springs spread over the skin: (skin node, weight, node) (spring_fan)

    def springs(self) -> tuple:
        """(skin node, weight, muscle node) of each spring: a strip node's spring fans out over
        the skin around its attachment (spring_fan, weights summing to 1 a node); a drive's
        anchors hold their own skin node, by their weight."""
        if self.fan is not None:
            return self.fan
        w = self.weight if self.weight is not None else np.ones(len(self.attach))
        return self.attach, w, np.arange(len(self.attach))


@dataclass
class Rig:
    """A face ready to simulate: its skin, its 68 landmarks, the placed muscles and their
    systems, saved to and loaded from one file (`save`, `load`; pipeline.make_rig makes one).

    Attributes
    ----------
    skin : Mesh
        The face (n_skin vertices).
    landmarks : (68, 3) float array
        Its landmarks, iBUG order.
    muscles : list of Muscle
        The muscles and drives, in the order activations are given.
    params : dict
        How it was built (ROI range, modes, contraction, the spring layer's stiffness, ...).
    gravity_basis : ModalBasis or dict or None
        The gravity system (physics.precompute), as a muscle's `basis`.
    """
    skin: Mesh
    landmarks: np.ndarray        # (68, 3)
    muscles: list[Muscle]
    params: dict = field(default_factory=dict)
    gravity_basis: object = None  # the gravity system (physics.precompute), as `basis`

    def held(self) -> np.ndarray:
        """(n_skin,) bool: the nodes the skull holds under gravity -- the skin's outline (the
        back of the head, a scan's border) and the node under each landmark (Kim §VI)."""
        held = self.skin.boundary_vertices()
        held[cKDTree(self.skin.vertices).query(self.landmarks)[1]] = True
        return held

    def muscle(self, name: str) -> Muscle:
        """The muscle of that name; a MimicaError listing the rig's muscles otherwise."""
        for m in self.muscles:
            if m.name == name:
                return m
        raise MimicaError(f"rig: no muscle named {name!r}; it has {', '.join(m.name for m in self.muscles)}")

    # ------------------------------------------------------------------ IO
    def save(self, path) -> Path:
        """Write the rig (skin, landmarks, muscles, their systems) as one .npz file, whole or not
        at all; returns the path."""
        path = Path(path)
        arrays = {"skin_v": self.skin.vertices, "skin_fi": self.skin.face_indices,
                  "skin_fs": self.skin.face_starts, "landmarks": self.landmarks}
        if self.skin.uv is not None and self.skin.face_uv_indices is not None:
            arrays.update(skin_uv=self.skin.uv, skin_fuv=self.skin.face_uv_indices)   # for texture maps
        meta = {"format": FORMAT, "params": self.params, "muscles": []}
        for i, m in enumerate(self.muscles):
            meta["muscles"].append({"name": m.name, "omega": m.omega, "kind": m.kind, "info": m.info})
            arrays.update({f"m{i}_nodes": m.nodes, f"m{i}_stretch": m.stretch, f"m{i}_attach": m.attach,
                           f"m{i}_roi": m.roi})
            if m.weight is not None:
                arrays[f"m{i}_weight"] = m.weight
            if m.fan is not None:
                arrays.update({f"m{i}_fan_{k}": a for k, a in zip("jwi", m.fan)})
            _put_basis(arrays, f"m{i}_b", m.basis)
        _put_basis(arrays, "g_b", self.gravity_basis)
        arrays["meta"] = np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8)
        with atomic_path(path) as tmp:
            with open(tmp, "wb") as fh:
                np.savez_compressed(fh, **arrays)
        return path

    @classmethod
    def load(cls, path) -> "Rig":
        """A rig file read back (its systems as arrays, made ready on first use); a MimicaError
        naming the file where it is not one."""
        path = Path(path)
        try:
            z = np.load(path, allow_pickle=False)
            meta = json.loads(bytes(z["meta"]).decode())
        except FileNotFoundError:
            raise MimicaError(f"{path}: no such rig file") from None
        except Exception as e:  # zip, npy and JSON errors alike
            raise MimicaError(f"{path}: not a mimica rig file ({type(e).__name__})") from None
        if not isinstance(meta, dict) or meta.get("format") != FORMAT:
            got = meta.get("format") if isinstance(meta, dict) else type(meta).__name__
            raise MimicaError(f"{path}: rig format {got!r}, expected {FORMAT!r}; rebuild it with `mimica rig`")
        if not isinstance(meta.get("muscles"), list) or not all(isinstance(d, dict) for d in meta["muscles"]):
            raise MimicaError(f"{path}: the rig's muscle list is damaged; rebuild it with `mimica rig`")
        try:
            uv = (z["skin_uv"], z["skin_fuv"]) if "skin_uv" in z.files else (None, None)
            skin = Mesh(np.asarray(z["skin_v"], np.float64), z["skin_fi"], z["skin_fs"], *uv)
            validate(skin, f"{path} (the rig's skin)")
            muscles = [Muscle(str(d["name"]), z[f"m{i}_nodes"], z[f"m{i}_stretch"], float(d["omega"]),
                              z[f"m{i}_attach"], z[f"m{i}_roi"], _get_basis(z, f"m{i}_b"),
                              str(d.get("kind", "strip")), z[f"m{i}_weight"] if f"m{i}_weight" in z.files else None,
                              dict(d.get("info", {})),
                              tuple(z[f"m{i}_fan_{k}"] for k in "jwi") if f"m{i}_fan_j" in z.files else None)
                       for i, d in enumerate(meta["muscles"])]
            rig = cls(skin, z["landmarks"], muscles, meta["params"], _get_basis(z, "g_b"))
        except KeyError as e:
            raise MimicaError(f"{path}: rig file is missing {e.args[0]!r}; rebuild it with `mimica rig`") from None
        except MimicaError:
            raise
        except Exception as e:       # a damaged member (bad CRC, truncated), wrong shapes or types
            raise MimicaError(f"{path}: the rig file is damaged ({type(e).__name__}); rebuild it with "
                              "`mimica rig`") from None
        for m in rig.muscles:
            arrays = [m.nodes, m.stretch] + ([m.basis["phi"], m.basis["lam"]] if m.basis is not None else [])
            if not all(np.isfinite(np.asarray(a, float)).all() for a in arrays):
                raise MimicaError(f"{path}: muscle {m.name} holds non-finite numbers; rebuild the rig with `mimica rig`")
        return rig


_BASIS_KEYS = ("free", "phi", "lam", "mass", "n")


def _put_basis(arrays, key, b):
    """A force's system as the physics stage hands it over (its to_arrays(), or the arrays
    it was loaded as)."""
    if b is None:
        return
    d = b if isinstance(b, dict) else b.to_arrays()
    arrays.update({f"{key}_{k}": d[k] for k in _BASIS_KEYS})


def _get_basis(z, key):
    if f"{key}_phi" not in z:
        return None
    return {k: z[f"{key}_{k}"] for k in _BASIS_KEYS}


# ---------------------------------------------------------------------- placement
def _point(d: dict, lm: np.ndarray) -> np.ndarray:
    w = np.array(list(d.values()), float)
    return (w[:, None] * lm[list(d.keys())]).sum(0) / w.sum()


def place_strip(mdef: MuscleDef, skin: Mesh, lm: np.ndarray, locator: TriangleLocator, normals: np.ndarray):
    """A muscle strip placed under the skin, from its origin (row 0) to its insertion.

    Parameters
    ----------
    mdef : MuscleDef
        The library's definition (its origin and insertion in landmark terms, width, depths).
    skin : Mesh
    lm : (68, 3) float array
    locator : TriangleLocator
        Of the skin.
    normals : (n, 3) float array
        The skin's vertex normals.

    Returns
    -------
    nodes : (ROWS * COLS, 3) float array
    tris : (k, 3) int array
        strip_triangles().
    """
    cyl = face_cylinder(lm)
    right, up = cyl.axes[0], cyl.axes[1]
    ew = float(np.linalg.norm(lm[45] - lm[36]))
    side = -1.0 if mdef.name.endswith("_R") else 1.0                 # subject's right is -x
    o = _point(mdef.origin, lm) + ew * (mdef.origin_lift * up + side * mdef.origin_out * right)
    i = _point(mdef.insertion, lm) + ew * (mdef.insertion_lift * up + side * mdef.insertion_out * right)
    s = np.linspace(0, 1, ROWS)[:, None, None]
    across = np.linspace(-0.5, 0.5, COLS)[None, :, None]
    axis = i - o
    nmid = _normal_at(locator, skin, normals, 0.5 * (o + i)[None])[1][0]
    perp = np.cross(nmid, axis)
    perp /= np.linalg.norm(perp) + 1e-300
    pts = (o + s * axis + across * perp * mdef.width * ew).reshape(-1, 3)
    on_skin, nn = _normal_at(locator, skin, normals, pts)
    depth = (mdef.origin_depth + (mdef.insertion_depth - mdef.origin_depth) * np.repeat(s.ravel(), COLS)) * ew
    nodes = on_skin - nn * depth[:, None]
    return nodes, strip_triangles()


def strip_triangles() -> np.ndarray:
    """The triangles of a muscle strip's ROWS x COLS grid of nodes (two a cell), origin row first.

    Returns
    -------
    (2 (ROWS - 1) (COLS - 1), 3) int array
    """
    g = np.arange(ROWS * COLS).reshape(ROWS, COLS)
    a, b, c, d = g[:-1, :-1].ravel(), g[:-1, 1:].ravel(), g[1:, 1:].ravel(), g[1:, :-1].ravel()
    return np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


def _normal_at(locator, skin, normals, points):
    """Closest skin points and the interpolated unit normals there."""
    tri, bary, on_skin, _ = locator.closest(points)
    n = np.einsum("ij,ijk->ik", bary, normals[skin.triangles[tri]])
    return on_skin, n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)


def stretch_mode(nodes: np.ndarray) -> np.ndarray:
    """Kim eqs. 11-12: the muscle's stretch mode with its origin row fixed.

    A strip fixed at its origin and pulled along itself deforms, to first order, as a bar: every
    node slides toward the origin along the strip, in proportion to its arc length from the origin
    (so a muscle curved over the skull keeps following it).  Scaled so that the insertion moves by
    the whole length: activation 1 with contraction c shortens the muscle by c.  The origin row
    does not move.

    Parameters
    ----------
    nodes : (ROWS * COLS, 3) float array

    Returns
    -------
    (ROWS * COLS, 3) float array
    """
    g = nodes.reshape(ROWS, COLS, 3)
    seg = np.linalg.norm(np.diff(g, axis=0), axis=2)                 # (ROWS-1, COLS)
    arc = np.vstack([np.zeros((1, COLS)), np.cumsum(seg, axis=0)])  # (ROWS, COLS)
    tan = np.gradient(g, axis=0)
    tan /= np.maximum(np.linalg.norm(tan, axis=2, keepdims=True), 1e-300)
    return (-arc[:, :, None] * tan).reshape(-1, 3)


def strip_muscle(mdef: MuscleDef, skin: Mesh, lm: np.ndarray, near, alpha: float = 10.0,
                 contraction: float = 0.25, omega: float = 40.0) -> Muscle:
    """One muscle of the library placed on the skin: its strip, stretch mode, springs and ROI.

    Parameters
    ----------
    mdef : MuscleDef
    skin : Mesh
    lm : (68, 3) float array
    near : tuple
        (TriangleLocator, vertex normals, cKDTree) of the skin, made once for all its muscles.
    alpha : float
        Kim eq. 19's ROI range.
    contraction : float
        Shortening at full activation.
    omega : float
        The stretch mode's frequency, rad/s.

    Returns
    -------
    Muscle
    """
    loc, normals, tree = near
    nodes, tris = place_strip(mdef, skin, lm, loc, normals)
    shape = stretch_mode(nodes)
    dist, attach = tree.query(nodes)                           # spring to the nearest skin node
    s_init = np.maximum(dist, 1e-9)
    fan = spring_fan(skin.vertices, nodes, attach, tree)
    # Kim eq. 19: skin node j is in the ROI when alpha |S_init^i| > |m_i - s_j| for some i
    # (every node against every skin node, vectorized: the k-d tree's ball lists took seconds
    # on a whole head, where deep strips reach all of it)
    reach = (mdef.alpha or alpha) * s_init
    roi = np.zeros(skin.n_vertices, bool)
    for c in range(0, len(nodes), 8):
        roi |= (cdist(skin.vertices, nodes[c:c + 8]) <= reach[None, c:c + 8]).any(1)
    roi[fan[0]] = True
    # a calibrated muscle's own contraction, scaled as the rig's knob is (0.25 by default)
    c = contraction if mdef.contraction is None else mdef.contraction * contraction / 0.25
    return Muscle(mdef.name, nodes, shape * c, omega, attach, roi, fan=fan)


# A strip node's spring spread over the skin within this part of half the strip's node spacing
# (Gaussian weights, sigma half the radius, summing to 1: the node's pull and stiffness as one
# spring's).  Kim attaches each node to one skin point; on ICT's 9.4k-vertex face that pulls the
# skin in streaks between the 9 x 4 nodes where ICT's sculpted shapes are smooth.  Chosen on the
# training faces (the generic one, seeds 11 and 12) from 0 / 0.5 / 1 / 1.5 / 2 / 3, the library's
# fit of the 47 coverage shapes: median 0.903 / 0.907 / 0.908 / 0.907 / 0.905 / 0.901, min 0.792 /
# 0.796 / 0.799 / 0.799 / 0.800 / 0.796 (docs/benchmarks.md).
FAN = 1.0


def spring_fan(vertices: np.ndarray, nodes: np.ndarray, attach: np.ndarray, tree) -> tuple:
    """A strip's springs fanned out around each node's attachment (FAN).

    Parameters
    ----------
    vertices : (n, 3) float array
        The skin's.
    nodes : (ROWS * COLS, 3) float array
        The strip's.
    attach : (ROWS * COLS,) int array
        The skin node each strip node is attached to.
    tree : scipy.spatial.cKDTree
        Of the skin's vertices.

    Returns
    -------
    skin_node : (k,) int array
    weight : (k,) float array
    strip_node : (k,) int array
    """
    g = nodes.reshape(ROWS, COLS, 3)
    spacing = max(np.linalg.norm(np.diff(g, axis=0), axis=2).mean(),
                  np.linalg.norm(np.diff(g, axis=1), axis=2).mean())
    r = FAN * 0.5 * spacing
    near = tree.query_ball_point(vertices[attach], r) if r > 0 else [[a] for a in attach]
    near = [js if len(js) else [a] for js, a in zip(near, attach)]   # the attachment is its own nearest
    i = np.repeat(np.arange(len(attach)), [len(js) for js in near])
    j = np.concatenate([np.asarray(js, int) for js in near])
    d = np.linalg.norm(vertices[j] - vertices[attach[i]], axis=1)
    w = np.exp(-2.0 * (d / max(r, 1e-300)) ** 2)
    return j, w / np.bincount(i, w)[i], i


DRIVE_REACH = 0.25               # a drive's region of interest: its attached skin and this many eye widths


def _drive_muscle(name, skin, lm, omega) -> Muscle:
    """A drive (rig.drives: the jaw, a lid) as one more force type of the rig: its anchors at the
    attached skin nodes, their motion at full activation as the stretch."""
    d = place_drive(name, skin.vertices, lm)
    if len(d.attach) == 0:
        raise MimicaError(f"rig: {name} finds no skin to move (is the face's {d.info['part']} in the mesh?)")
    ew = float(np.linalg.norm(lm[45] - lm[36]))
    # the skin within the reach of any attached node (its distance to the nearest of them: the
    # k-d tree's ball lists took seconds on a whole head's thousands of cheek nodes)
    r = DRIVE_REACH * ew
    roi = cKDTree(skin.vertices[d.attach]).query(skin.vertices, distance_upper_bound=r * (1 + 1e-9))[0] <= r
    return Muscle(name, skin.vertices[d.attach].copy(), d.motion, omega, d.attach, roi, kind="drive",
                  weight=d.weight, info=d.info)


def build_rig(skin: Mesh, landmarks: np.ndarray, muscles=None, alpha: float = 10.0, modes: int = 8,
              contraction: float = 0.25, gravity: bool = True, muscle_omega: float = 40.0,
              tether: float = 0.02, progress=None) -> Rig:
    """Place the muscles, springs and ROIs on a face (the modal system of each force is the physics
    stage's: `mimica.physics.precompute(rig)`, or made when the rig is first simulated).

    Parameters
    ----------
    skin : Mesh
        The face.
    landmarks : (68, 3) float array
        All 68 are needed.
    muscles : str or list of str or None
        "all" (the calibrated library and the drives), "kim" (Kim's 8), or names (a list, or
        one string separated by commas); None: "kim".
    alpha : float
        Kim eq. 19's ROI range.
    modes : int
        The size of each force's modal system (kept in params).
    contraction : float
        Muscle shortening at full activation (a calibrated muscle's own, rig/calibration.json,
        is scaled by contraction / 0.25).
    gravity : bool
        Gravity gets a modal system (kept in params).
    muscle_omega : float
        The stretch mode's frequency (rad/s; the muscle follows its activation critically damped,
        time constant 1/omega).
    tether : float
        Stiffness of the subcutaneous layer that ties every skin node to the skull, relative to a
        skin edge (Viaud & Yahia's rest-position feedback; without it the whole ROI slides as one
        sheet).
    progress : callable, optional
        Called as progress(k, n, name) before each muscle is placed.

    Returns
    -------
    Rig
    """
    lm = np.asarray(landmarks, float)
    if not np.isfinite(lm).all():
        raise MimicaError("rig: all 68 landmarks are needed to place the muscles")
    if isinstance(muscles, str) and muscles not in ("kim", "all"):
        muscles = [m.strip() for m in muscles.split(",") if m.strip()]
    names = list(KIM_MUSCLES if muscles in (None, "kim") else list(MUSCLES) + list(DRIVES) if muscles == "all"
                 else muscles)
    if not names:
        raise MimicaError("rig: no muscles named; give 'kim', 'all' or muscle names separated by commas")
    for n in names:
        if n not in MUSCLES and n not in DRIVES:
            raise MimicaError(f"rig: unknown muscle {n!r}; known: {', '.join(list(MUSCLES) + list(DRIVES))}")
    mean_edge = skin.mean_edge_length()
    loc = TriangleLocator(skin.vertices, skin.triangles)
    normals = skin.vertex_normals()
    tree = cKDTree(skin.vertices)
    out = []
    for k, n in enumerate(names):
        if progress:
            progress(k, len(names), n)
        if n in DRIVES:
            out.append(_drive_muscle(n, skin, lm, muscle_omega))
            continue
        out.append(strip_muscle(MUSCLES[n], skin, lm, (loc, normals, tree), alpha, contraction, muscle_omega))
    params = {"alpha": alpha, "modes": modes, "contraction": contraction, "tether": tether,
              "gravity": bool(gravity), "mean_edge": mean_edge}
    return Rig(skin, lm, out, params)
