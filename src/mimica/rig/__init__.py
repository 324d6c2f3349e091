"""The face rig (Kim 2020 §IV-V): skin, muscles as thin shell strips, the spring layer,
per-muscle regions of interest, and one modal system per force type (Kim §VI).

`build_rig(skin, landmarks)` places every muscle of the library from the 68 landmarks, so
the same definitions fit any face of any topology.  A `Rig` saves to one `.rig` file.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from ..correspond import face_cylinder
from ..errors import MimicaError
from ..mesh import Mesh, atomic_path, validate
from ..mesh.query import TriangleLocator
from ..physics.face import tether_springs
from ..physics.modal import ModalBasis, rotation_operator
from ..physics.shell import ShellEnergy, lumped_mass
from .muscles import KIM_MUSCLES, MUSCLES, MuscleDef

ROWS, COLS = 9, 4                # strip resolution along / across (Kim: 36 nodes a muscle)
FORMAT = "mimica-rig/1"
WARP_SMOOTH = 4                  # rings over which the modal-warping rotation is averaged


@dataclass
class Muscle:
    """One placed muscle: strip nodes, its stretch mode, springs to the skin, ROI system."""

    name: str
    nodes: np.ndarray            # (k, 3) rest positions
    stretch: np.ndarray          # (k, 3) displacement at full contraction (activation 1)
    omega: float                 # frequency of the stretch mode (rad/s), critically damped
    attach: np.ndarray           # (k,) skin node of each muscle node's spring
    roi: np.ndarray              # (n_skin,) bool, Kim eq. 19
    basis: ModalBasis | None = None


@dataclass
class Rig:
    skin: Mesh
    landmarks: np.ndarray        # (68, 3)
    muscles: list[Muscle]
    params: dict = field(default_factory=dict)
    gravity_basis: ModalBasis | None = None

    def muscle(self, name: str) -> Muscle:
        for m in self.muscles:
            if m.name == name:
                return m
        raise MimicaError(f"rig: no muscle named {name!r}; it has {', '.join(m.name for m in self.muscles)}")

    # ------------------------------------------------------------------ IO
    def save(self, path) -> Path:
        path = Path(path)
        arrays = {"skin_v": self.skin.vertices, "skin_fi": self.skin.face_indices,
                  "skin_fs": self.skin.face_starts, "landmarks": self.landmarks}
        if self.skin.uv is not None and self.skin.face_uv_indices is not None:
            arrays.update(skin_uv=self.skin.uv, skin_fuv=self.skin.face_uv_indices)   # for texture maps
        meta = {"format": FORMAT, "params": self.params, "muscles": []}
        for i, m in enumerate(self.muscles):
            meta["muscles"].append({"name": m.name, "omega": m.omega})
            arrays.update({f"m{i}_nodes": m.nodes, f"m{i}_stretch": m.stretch, f"m{i}_attach": m.attach,
                           f"m{i}_roi": m.roi})
            _put_basis(arrays, f"m{i}_b", m.basis)
        _put_basis(arrays, "g_b", self.gravity_basis)
        arrays["meta"] = np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8)
        with atomic_path(path) as tmp:
            with open(tmp, "wb") as fh:
                np.savez_compressed(fh, **arrays)
        return path

    @classmethod
    def load(cls, path) -> "Rig":
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
            W = rotation_operator(skin.vertices, skin.triangles, smooth=WARP_SMOOTH)
            muscles = [Muscle(str(d["name"]), z[f"m{i}_nodes"], z[f"m{i}_stretch"], float(d["omega"]),
                              z[f"m{i}_attach"], z[f"m{i}_roi"], _get_basis(z, f"m{i}_b", W))
                       for i, d in enumerate(meta["muscles"])]
            rig = cls(skin, z["landmarks"], muscles, meta["params"], _get_basis(z, "g_b", W))
        except KeyError as e:
            raise MimicaError(f"{path}: rig file is missing {e.args[0]!r}; rebuild it with `mimica rig`") from None
        except MimicaError:
            raise
        except Exception as e:       # a damaged member (bad CRC, truncated), wrong shapes or types
            raise MimicaError(f"{path}: the rig file is damaged ({type(e).__name__}); rebuild it with "
                              "`mimica rig`") from None
        for m in rig.muscles:
            arrays = [m.nodes, m.stretch] + ([m.basis.phi, m.basis.lam] if m.basis is not None else [])
            if not all(np.isfinite(np.asarray(a, float)).all() for a in arrays):
                raise MimicaError(f"{path}: muscle {m.name} holds non-finite numbers; rebuild the rig with `mimica rig`")
        return rig


def _put_basis(arrays, key, b):
    """Mode shapes are stored in single precision; the rotation fields are derived on load."""
    if b is None:
        return
    arrays.update({f"{key}_free": b.free, f"{key}_phi": b.phi.astype(np.float32), f"{key}_lam": b.lam,
                   f"{key}_mass": b.mass, f"{key}_n": np.array(b.n)})


def _get_basis(z, key, W):
    if f"{key}_phi" not in z:
        return None
    free, phi, n = z[f"{key}_free"], z[f"{key}_phi"].astype(np.float64), int(z[f"{key}_n"])
    dof = (3 * free[:, None] + np.arange(3)).ravel()
    full = np.zeros((3 * n, phi.shape[1]))
    full[dof] = phi
    return ModalBasis(free, phi, z[f"{key}_lam"], (W @ full)[dof], z[f"{key}_mass"], n)


# ---------------------------------------------------------------------- placement
def _point(d: dict, lm: np.ndarray) -> np.ndarray:
    w = np.array(list(d.values()), float)
    return (w[:, None] * lm[list(d.keys())]).sum(0) / w.sum()


def place_strip(mdef: MuscleDef, skin: Mesh, lm: np.ndarray, locator: TriangleLocator, normals: np.ndarray):
    """Strip nodes (ROWS*COLS, 3) under the skin from origin (row 0) to insertion, and triangles."""
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
    g = np.arange(ROWS * COLS).reshape(ROWS, COLS)
    a, b, c, d = g[:-1, :-1].ravel(), g[:-1, 1:].ravel(), g[1:, 1:].ravel(), g[1:, :-1].ravel()
    tris = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return nodes, tris


def _normal_at(locator, skin, normals, points):
    """Closest skin points and the interpolated unit normals there."""
    tri, bary, on_skin, _ = locator.closest(points)
    n = np.einsum("ij,ijk->ik", bary, normals[skin.triangles[tri]])
    return on_skin, n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)


def stretch_mode(nodes: np.ndarray) -> np.ndarray:
    """Kim eqs. 11-12: the muscle's stretch mode with its origin row fixed, (k, 3).

    A strip fixed at its origin and pulled along itself deforms, to first order, as a bar:
    every node slides toward the origin along the strip, in proportion to its arc length
    from the origin (so a muscle curved over the skull keeps following it).  Scaled so that
    the insertion moves by the whole length: activation 1 with contraction c shortens the
    muscle by c.  The origin row does not move.
    """
    g = nodes.reshape(ROWS, COLS, 3)
    seg = np.linalg.norm(np.diff(g, axis=0), axis=2)                 # (ROWS-1, COLS)
    arc = np.vstack([np.zeros((1, COLS)), np.cumsum(seg, axis=0)])  # (ROWS, COLS)
    tan = np.gradient(g, axis=0)
    tan /= np.maximum(np.linalg.norm(tan, axis=2, keepdims=True), 1e-300)
    return (-arc[:, :, None] * tan).reshape(-1, 3)


def build_rig(skin: Mesh, landmarks: np.ndarray, muscles=None, alpha: float = 10.0, modes: int = 8,
              contraction: float = 0.25, gravity: bool = True, muscle_omega: float = 40.0,
              tether: float = 0.02, progress=None) -> Rig:
    """Place the muscles, springs and ROIs on a face; precompute one modal system per force.

    alpha: Kim eq. 19 ROI range; contraction: muscle shortening at full activation;
    muscle_omega: the stretch mode's frequency (rad/s; the muscle follows its activation
    critically damped, time constant 1/omega); tether: stiffness of the subcutaneous
    layer that ties every skin node to the skull, relative to a skin edge (Viaud & Yahia's
    rest-position feedback; without it the whole ROI slides as one sheet).
    """
    lm = np.asarray(landmarks, float)
    if not np.isfinite(lm).all():
        raise MimicaError("rig: all 68 landmarks are needed to place the muscles")
    if isinstance(muscles, str) and muscles not in ("kim", "all"):
        muscles = [m.strip() for m in muscles.split(",") if m.strip()]
    names = list(KIM_MUSCLES if muscles in (None, "kim") else MUSCLES if muscles == "all" else muscles)
    if not names:
        raise MimicaError("rig: no muscles named; give 'kim', 'all' or muscle names separated by commas")
    for n in names:
        if n not in MUSCLES:
            raise MimicaError(f"rig: unknown muscle {n!r}; known: {', '.join(MUSCLES)}")
    skin_e = ShellEnergy.default(skin)
    mass = lumped_mass(skin)
    mean_edge = skin.mean_edge_length()
    k_node = tether_springs(tether, skin_e.k_length, mean_edge, mass)             # K + the tethers
    K = (skin_e.hessian(skin_e.rest) + sp.diags(np.repeat(k_node, 3))).tocsr()
    W = rotation_operator(skin.vertices, skin.triangles, smooth=WARP_SMOOTH)
    loc = TriangleLocator(skin.vertices, skin.triangles)
    normals = skin.vertex_normals()
    tree = cKDTree(skin.vertices)
    out = []
    for k, n in enumerate(names):
        if progress:
            progress(k, len(names), n)
        nodes, tris = place_strip(MUSCLES[n], skin, lm, loc, normals)
        shape = stretch_mode(nodes)
        dist, attach = tree.query(nodes)                           # spring to the nearest skin node
        s_init = np.maximum(dist, 1e-9)
        # Kim eq. 19: skin node j is in the ROI when alpha |S_init^i| > |m_i - s_j| for some i
        roi = np.zeros(skin.n_vertices, bool)
        a_m = MUSCLES[n].alpha or alpha
        for p, r in zip(nodes, a_m * s_init):
            roi[tree.query_ball_point(p, r)] = True
        roi[attach] = True
        basis = ModalBasis.compute(skin_e, mass, ~roi, r=modes, load_nodes=np.unique(attach), stiffness=K,
                                   rotation=W)
        out.append(Muscle(n, nodes, shape * contraction, muscle_omega, attach, roi, basis))
    gb = None
    if gravity:
        # gravity: the skin hangs from its outline (the back of the head / scan border) and
        # from the landmarks (feature points held by the skull), Kim §VI
        fixed = skin.boundary_vertices()
        fixed[tree.query(lm)[1]] = True
        gb = ModalBasis.compute(skin_e, mass, fixed, r=modes, stiffness=K, rotation=W)
    params = {"alpha": alpha, "modes": modes, "contraction": contraction, "tether": tether,
              "mean_edge": mean_edge,
              "k_area": skin_e.k_area, "k_length": skin_e.k_length, "k_bend": skin_e.k_bend}
    return Rig(skin, lm, out, params, gb)


def build_region_system(rig: Rig, center: np.ndarray, radius: float, reach: float = 3.0):
    """A modal system for a force on the skin within `radius` of `center` (a user pull):
    its ROI is the skin within reach x radius; returns (basis, loaded nodes, weights)."""
    skin = rig.skin
    d = np.linalg.norm(skin.vertices - center, axis=1)
    nodes = np.nonzero(d < radius)[0]
    if len(nodes) == 0:
        raise MimicaError(f"pull: no skin within {radius:g} of {np.round(center, 3).tolist()}")
    w = (1 - d[nodes] / radius) ** 2
    energy = ShellEnergy.default(skin)
    mass = lumped_mass(skin)
    k_node = tether_springs(rig.params.get("tether", 0.0), energy.k_length, rig.params["mean_edge"], mass)
    K = (energy.hessian(energy.rest) + sp.diags(np.repeat(k_node, 3))).tocsr()
    W = rotation_operator(skin.vertices, skin.triangles, smooth=WARP_SMOOTH)
    basis = ModalBasis.compute(energy, mass, d > reach * radius, r=rig.params.get("modes", 8),
                               load_nodes=nodes[:: max(1, len(nodes) // 24)], stiffness=K, rotation=W)
    return basis, nodes, w / w.sum()
