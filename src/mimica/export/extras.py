"""What mimica keeps in the glTF files it writes for its own later reading: the mesh's extras
(glTF 2.0 §3.12), written by `write_blendshapes` and read back by `animate` (export.take: where
the head turns) and `animate --video` (export.video: the 68 points it fits).  One module writes
and reads them, so a head made from Python plays as one made on the command line."""

from __future__ import annotations

import numpy as np

from ..errors import MimicaError

HEAD_KEY = "mimica_head"            # {"pivot": (3,), "chin": (3,)}, metres: where the head turns
LANDMARKS_KEY = "mimica_landmarks"  # {"vertices": (68, 3) int, "bary": (68, 3)}: the 68 landmarks, user's order


def head_joint(mesh, landmarks) -> dict | None:
    """Where a head turns, from its 68 landmarks -- a mimica estimate, not measured on anatomy.

    Parameters
    ----------
    mesh : Mesh
        The head.
    landmarks : Landmarks
        Its 68 landmarks (0, 1, 2, 8, 14, 15, 16 and 30 are used).

    Returns
    -------
    dict or None
        {"pivot": (3,) the top of the neck (near the atlanto-occipital joint): level with the jaw
        outline under the ears (points 1, 2, 14, 15), a third of the face's width (0 to 16)
        behind them; "chin": (3,) point 8}, in the mesh's units.  None where those landmarks
        are missing.
    """
    p = landmarks.positions(mesh)
    if np.isnan(p[[0, 1, 2, 8, 14, 15, 16, 30]]).any():
        return None
    ears = p[[1, 2, 14, 15]].mean(0)
    across = p[16] - p[0]
    width = float(np.linalg.norm(across))
    forward = p[30] - (p[0] + p[16]) / 2
    forward -= forward @ across / width ** 2 * across                  # square to the ears' line
    forward /= max(np.linalg.norm(forward), 1e-12)
    return {"pivot": ears - width / 3 * forward, "chin": p[8]}


def head_extras(mesh, landmarks, metres_per_unit: float) -> dict:
    """The extras for a head's mesh: where it turns (`head_joint`, in metres) and its
    68 landmarks as triangles of its vertices with barycentrics, each where it can be said.

    Parameters
    ----------
    mesh : Mesh
        The head as written (its vertices in the file's order).
    landmarks : Landmarks
        Its 68 landmarks.
    metres_per_unit : float
        The file's scale (glTF is in metres).

    Returns
    -------
    dict
        {HEAD_KEY: ..., LANDMARKS_KEY: ...}, either left out where its landmarks are missing.
    """
    out = {}
    joint = head_joint(mesh, landmarks)
    if joint is not None:
        out[HEAD_KEY] = {n: (metres_per_unit * np.asarray(p)).tolist() for n, p in joint.items()}
    if landmarks.present.all():
        out[LANDMARKS_KEY] = {"vertices": mesh.triangles[landmarks.triangle].tolist(),
                              "bary": np.round(landmarks.bary, 7).tolist()}
    return out


def stored_head(extras: dict | None) -> dict:
    """The head's joint as `head_extras` stored it.

    Parameters
    ----------
    extras : dict or None
        A glTF mesh's extras.

    Returns
    -------
    dict
        {"pivot": [x, y, z], "chin": [x, y, z]} in metres, or {} where none is stored.
    """
    return dict((extras or {}).get(HEAD_KEY) or {})


def stored_landmarks(extras: dict | None, n_vertices: int, what: str) -> tuple[np.ndarray, np.ndarray] | None:
    """The 68 landmarks `head_extras` stored.

    Parameters
    ----------
    extras : dict or None
        A glTF mesh's extras.
    n_vertices : int
        The mesh's vertex count, which the stored triangles must fit (MimicaError otherwise).
    what : str
        How the message names the file.

    Returns
    -------
    tuple or None
        (vertices (68, 3) int64 array, bary (68, 3) float64 array), or None where none are stored.
    """
    stored = (extras or {}).get(LANDMARKS_KEY)
    if not stored:
        return None
    tri = np.asarray(stored.get("vertices"), np.int64)
    bary = np.asarray(stored.get("bary"), np.float64)
    if tri.shape != (68, 3) or bary.shape != (68, 3) or (tri < 0).any() or (tri >= n_vertices).any():
        raise MimicaError(f"{what}: its stored landmarks do not match its vertices")
    return tri, bary
