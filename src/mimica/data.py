"""The data directory and the facts about the bundled ICT-FaceKit template.

The data directory is `$MIMICA_DATA` if set, else, in a checkout of this repository,
`../shared/data` beside it; an installed wheel has none and reads ICT-FaceKit through the
template store (`mimica.store`: the user cache, filled once by a checked download).  Nothing
from it is copied into the project.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from .errors import MimicaError
from .store import data_dir, default_store, shape_names  # noqa: F401  (data_dir: the store owns it)


# ICT-FaceKit topology (README.upstream.md, "Face Model Topology").
ICT_N_VERTICES = 26719
ICT_FACE_AREA_VERTICES = 9409        # vertices [0:9408]
ICT_FACE_AREA_FACES = 9230
ICT_HEAD_VERTICES = 11248            # face + head and neck, vertices [0:11247]
ICT_HEAD_FACES = 11144
# Multi-PIE 68-point landmark vertex indices (README.upstream.md, "Facial Landmarks").
ICT_LANDMARKS_68 = np.array([
    1225, 1888, 1052, 367, 1719, 1722, 2199, 1447, 966, 3661, 4390, 3927, 3924, 2608, 3272, 4088,
    3443, 268, 493, 1914, 2044, 1401, 3615, 4240, 4114, 2734, 2509, 978, 4527, 4942, 4857, 1140,
    2075, 1147, 4269, 3360, 1507, 1542, 1537, 1528, 1518, 1511, 3742, 3751, 3756, 3721, 3725,
    3732, 5708, 5695, 2081, 0, 4275, 6200, 6213, 6346, 6461, 5518, 5957, 5841, 5702, 5711, 5533,
    6216, 6207, 6470, 5517, 5966], dtype=np.int64)
# sha256 of the face-area polygons (first 9230 faces, 0-based int64): identifies the topology
ICT_FACE_AREA_SHA256 = "9be0b1b432fef37dd62416d07dd400bab4c925047a6c1f14b5b7a582f8cb3504"


def ict_path(name: str) -> Path:
    """Path of an ICT-FaceKit OBJ, through the one template store (store.TemplateStore).

    Parameters
    ----------
    name : str
        Its stem: 'generic_neutral_mesh', 'identity003', 'jawOpen', ...

    Returns
    -------
    Path
        The file (fetched into the cache where the store fetches).
    """
    return default_store().path(name)


def ict_expression_names() -> list[str]:
    """The names of ICT-FaceKit's expression shapes (its OBJs but the neutral and the identities).

    Returns
    -------
    list of str
        As the store lists them ('jawOpen', 'eyeBlink_L', ...).
    """
    return [n for n in shape_names() if n != "generic_neutral_mesh" and not n.startswith("identity")]


def face_area_hash(face_indices: np.ndarray, face_starts: np.ndarray) -> str | None:
    """A fingerprint of a mesh's first ICT_FACE_AREA_FACES polygons (is_ict_topology compares it
    with ICT-FaceKit's).

    Parameters
    ----------
    face_indices : (k,) int array
        The polygons' corners, concatenated (Mesh.face_indices).
    face_starts : (n_faces + 1,) int array
        Where each polygon starts in face_indices (Mesh.face_starts).

    Returns
    -------
    str or None
        The sha256 hex digest; None for a mesh with fewer polygons.
    """
    if len(face_starts) <= ICT_FACE_AREA_FACES:
        return None
    end = face_starts[ICT_FACE_AREA_FACES]
    h = hashlib.sha256(np.ascontiguousarray(face_indices[:end], dtype=np.int64).tobytes())
    h.update(np.ascontiguousarray(face_starts[:ICT_FACE_AREA_FACES + 1], dtype=np.int64).tobytes())
    return h.hexdigest()


def is_ict_topology(mesh) -> bool:
    """Whether a mesh is ICT-FaceKit's topology (any identity, any expression).

    Parameters
    ----------
    mesh : Mesh

    Returns
    -------
    bool
        Its first 9,230 polygons are ICT-FaceKit's face area, vertex for vertex.
    """
    return (mesh.n_vertices >= ICT_FACE_AREA_VERTICES
            and face_area_hash(mesh.face_indices, mesh.face_starts) == ICT_FACE_AREA_SHA256)


# ------------------------------------------------------------------ linear model
# Basic expressions as ICT-FaceKit shape weights, from the FACS units in the upstream
# README's table (AU1+2+5+26 surprise, AU6+12 happiness, AU1+4+15 sadness, AU4+5+7+23
# anger, AU9+15+16 disgust, AU1+2+4+5+20+26 fear; Ekman & Friesen).
EXPRESSIONS = {
    "happiness": {"mouthSmile_L": 1.0, "mouthSmile_R": 1.0, "cheekSquint_L": 0.8, "cheekSquint_R": 0.8},
    "surprise": {"browInnerUp_L": 1.0, "browInnerUp_R": 1.0, "browOuterUp_L": 1.0, "browOuterUp_R": 1.0,
                 "eyeWide_L": 0.8, "eyeWide_R": 0.8, "jawOpen": 0.45},
    "sadness": {"browInnerUp_L": 0.8, "browInnerUp_R": 0.8, "browDown_L": 0.3, "browDown_R": 0.3,
                "mouthFrown_L": 1.0, "mouthFrown_R": 1.0, "mouthShrugLower": 0.4},
    "anger": {"browDown_L": 1.0, "browDown_R": 1.0, "eyeSquint_L": 0.6, "eyeSquint_R": 0.6,
              "mouthPress_L": 0.8, "mouthPress_R": 0.8, "noseSneer_L": 0.4, "noseSneer_R": 0.4},
    "disgust": {"noseSneer_L": 1.0, "noseSneer_R": 1.0, "mouthUpperUp_L": 0.7, "mouthUpperUp_R": 0.7,
                "mouthFrown_L": 0.5, "mouthFrown_R": 0.5, "mouthLowerDown_L": 0.3, "mouthLowerDown_R": 0.3},
    "fear": {"browInnerUp_L": 1.0, "browInnerUp_R": 1.0, "browDown_L": 0.3, "browDown_R": 0.3,
             "eyeWide_L": 1.0, "eyeWide_R": 1.0, "mouthStretch_L": 0.8, "mouthStretch_R": 0.8, "jawOpen": 0.25},
}


class ICTModel:
    """ICT-FaceKit's linear model: face = N + sum w_i (identity_i - N) + sum e_j (E_j - N).

    Shapes are read on first use and kept.

    Parameters
    ----------
    n : int or None
        Restricts every shape to its first n vertices (ICT_HEAD_VERTICES: face, head and neck;
        ICT_FACE_AREA_VERTICES: the face alone); None: the whole mesh (26,719 vertices, eyes,
        teeth and the rest).

    Attributes
    ----------
    mesh : Mesh
        The neutral, restricted to n vertices.
    """

    def __init__(self, n: int | None = None):
        from .mesh import read_mesh
        full = read_mesh(ict_path("generic_neutral_mesh"))
        if n is None or n == full.n_vertices:
            self.mesh = full
        else:
            nf = {ICT_HEAD_VERTICES: ICT_HEAD_FACES, ICT_FACE_AREA_VERTICES: ICT_FACE_AREA_FACES}.get(n)
            if nf is None:
                raise MimicaError(f"ICT model: no known part with {n} vertices")
            self.mesh, _ = full.submesh(np.arange(nf))
        self.n = self.mesh.n_vertices
        self._shapes: dict[str, np.ndarray] = {}

    @property
    def neutral(self) -> np.ndarray:
        return self.mesh.vertices

    def shape(self, name: str) -> np.ndarray:
        if name not in self._shapes:
            from .mesh import read_vertices
            self._shapes[name] = read_vertices(ict_path(name))[:self.n]
        return self._shapes[name]

    def delta(self, weights: dict) -> np.ndarray:
        d = np.zeros_like(self.neutral)
        for k, w in weights.items():
            d += w * (self.shape(k) - self.neutral)
        return d

    def identity(self, which) -> np.ndarray:
        """'identity007', a dict of identity weights, or an array of coefficients for identity000.."""
        if isinstance(which, str):
            return self.shape(which)
        if isinstance(which, dict):
            return self.neutral + self.delta(which)
        return self.neutral + self.delta({f"identity{i:03d}": c for i, c in enumerate(which) if c})

    def expression(self, name_or_weights) -> dict:
        if isinstance(name_or_weights, str):
            return EXPRESSIONS.get(name_or_weights, {name_or_weights: 1.0})
        return dict(name_or_weights)

    def performance(self, n_frames: int, seed: int = 0) -> np.ndarray:
        """A smooth performance on the neutral: the six basic expressions (EXPRESSIONS) blended
        with slowly varying weights, each a clipped sine of its own random rate and phase (the
        benchmarks' and tests' sequences; rank 6).

        Parameters
        ----------
        n_frames : int
        seed : int
            The rates' and phases' random seed.

        Returns
        -------
        (n_frames, n, 3) float array
        """
        names = list(EXPRESSIONS)
        d = np.stack([self.delta(EXPRESSIONS[e]) for e in names])
        rng = np.random.default_rng(seed)
        t = np.linspace(0, 2 * np.pi, n_frames)[:, None]
        w = np.clip(np.sin(t * rng.uniform(0.5, 2.0, len(names)) + rng.uniform(0, 2 * np.pi, len(names))), 0, None)
        return self.neutral + np.einsum("fk,knd->fnd", w, d)
