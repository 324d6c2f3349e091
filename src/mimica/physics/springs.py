"""The springs that tie the skin to what moves it (Kim 2020 §V): the spring laws (linear, or
Kim's eqs. 14-16), a muscle's springs, the drives' attachments and the tether to rest, each as
stiff as a number of the skin's own edges."""

from __future__ import annotations

import numpy as np


SPRING_LAWS = ("linear", "kim")


def kim_spring(s_init: np.ndarray, u_m: np.ndarray, u_s: np.ndarray, k) -> tuple:
    """The subcutaneous springs of Kim 2020 §V.B, eqs. 14-16, on the skin's end, vectorized over
    springs.

      S_d = s_init + u_m - u_s                                  (the deformed spring)
      |F| = k | |S_d| - |s_init| | / |s_init|                   (eqs. 14-15: relative elongation)
      F / |F| = (S_d - s_init) / |S_d - s_init|                 (eq. 16, S_ud read as the spring at rest)

    Eq. 16 as printed takes S_ud with the skin's end moved and the muscle's not, so S_d - S_ud =
    u_m: the force keeps pushing along the muscle's motion once the skin has passed it, and the
    magnitude grows again there (the springs stand nearly across the muscles' motion: |cos|
    0.07-0.22 on ICT's face), so nothing restores it -- measured, every calibrated muscle's skin
    diverged within a second at 60 fps.  Along the spring's own deformation u_m - u_s it restores.

    Parameters
    ----------
    s_init : (m, 3) float array
        The initial spring vectors (skin node -> muscle node).
    u_m, u_s : (m, 3) float arrays
        The muscle nodes' and the skin nodes' displacements.
    k : float or (m,) float array
        The springs' stiffness.

    Returns
    -------
    F : (m, 3) float array
        The force on the skin's end; 0 where the spring is undeformed.
    dF_du_s, dF_du_m : (m, 3, 3) float arrays
        Its derivatives (F depends on u_m - u_s only, so dF/du_m = -dF/du_s); the magnitude's kink
        at |S_d| = |s_init| takes the derivative of the side the spring is on.
    """
    s_init, u_m, u_s = (np.asarray(x, float) for x in (s_init, u_m, u_s))
    k = np.broadcast_to(np.asarray(k, float), len(s_init))
    l0 = np.linalg.norm(s_init, axis=1)
    w = u_m - u_s
    sd = s_init + w
    ld = np.linalg.norm(sd, axis=1)
    e = (ld - l0) / l0                                            # eq. 15's relative elongation
    lw = np.linalg.norm(w, axis=1)
    moved = lw > 1e-12 * np.maximum(l0, 1e-300)
    d = np.where(moved[:, None], w / np.where(moved, lw, 1.0)[:, None], 0.0)        # eq. 16
    sd_hat = sd / np.maximum(ld, 1e-300)[:, None]
    f = (k * np.abs(e))[:, None] * d
    g = (k * np.sign(e) / l0)[:, None, None] * d[:, :, None] * sd_hat[:, None, :]   # d |F| along d
    g += np.where(moved, k * np.abs(e) / np.where(moved, lw, 1.0), 0.0)[:, None, None] * \
        (np.eye(3)[None] - d[:, :, None] * d[:, None, :])                            # d direction
    return f, -g, g


DRIVE_SPRING = 4.0               # a drive's attachments, as stiff as this many `spring`s (at weight 1)


def drive_springs(rig, muscle) -> np.ndarray:
    """A drive's attachment stiffness per skin node: DRIVE_SPRING default springs x its weight
    (part of its system's stiffness, so fixed at precompute).

    Parameters
    ----------
    rig : Rig
    muscle : Muscle
        A drive (kind "drive").

    Returns
    -------
    (n,) float array
        n: the skin's vertices.
    """
    k = np.zeros(rig.skin.n_vertices)
    w = muscle.weight if muscle.weight is not None else np.ones(len(muscle.attach))
    np.add.at(k, muscle.attach, DRIVE_SPRING * spring_stiffness(rig, 4.0) * w)
    return k


def strip_springs(rig, muscle, spring: float = 4.0) -> tuple:
    """A strip muscle's springs on the skin, each strip node's spring fanned out (rig.spring_fan).

    Parameters
    ----------
    rig : Rig
    muscle : Muscle
        A strip muscle.
    spring : float
        Each spring's stiffness in edges' stiffness (spring_stiffness).

    Returns
    -------
    stiffness : (n,) float array
        Per skin node.
    pull : (n, 3) float array
        Their pull at full activation, K_s u_m.
    """
    at, wt, of = muscle.springs()
    k = spring_stiffness(rig, spring) * wt
    f = np.zeros((rig.skin.n_vertices, 3))
    np.add.at(f, at, k[:, None] * muscle.stretch[of])
    return np.bincount(at, k, minlength=rig.skin.n_vertices), f


def tether_springs(tether: float, k_length: float, mean_edge: float, mass: np.ndarray) -> np.ndarray:
    """Per-node stiffness of the subcutaneous tethers to the skull: tether x an edge's stiffness
    2 k_L / l, shared out by the nodes' lumped areas.

    Parameters
    ----------
    tether : float
        The tethers' strength in edges' stiffness.
    k_length : float
        The shell's length stiffness k_L.
    mean_edge : float
        The skin's mean edge length l.
    mass : (n,) float array
        The nodes' lumped masses (areas).

    Returns
    -------
    (n,) float array
    """
    return tether * 2 * k_length / mean_edge * mass / mass.mean()


def spring_stiffness(rig, spring: float) -> float:
    """The muscle-to-skin spring's stiffness (Kim eqs. 14-16).

    Parameters
    ----------
    rig : Rig
    spring : float
        In edges' stiffness, 2 k_L / l each.

    Returns
    -------
    float
    """
    return spring * 2.0 * rig.params["k_length"] / rig.params["mean_edge"]
