"""The force-field engine of Viaud & Yahia 1992 (§4, eq. 9): a sprung mesh with rest-position
feedback, driven by muscle force fields.

    m_i a_i = sum_j k_ij (|P_iP_j| - |P0_iP0_j|) P_iP_j / |P_iP_j| - h v_i + F_ext + k (P0_i - P_i)

Springs are the mesh's edges; F_ext is the sum of the muscle force fields, each pulling the
skin over its region toward the muscle's origin with a smooth fall-off.  Integration is
linearly implicit Euler with the stiffness taken at rest, factored once:
(M + dt h + dt^2 K0) v' = M v + dt F(x), which is stable at the frame rates used here.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..solver import SPDSolver
from .engine import run_frames
from .shell import lumped_mass

MAX_DT = 1.0 / 120.0                  # seconds: the longest step of the sprung engine


class SprungFace:
    """Viaud and Yahia's sprung skin (springs along the edges, tethers to rest, semi-implicit steps),
    with the rig's muscles as force fields; the Engine interface.

    Parameters
    ----------
    rig : Rig
    fps : float
    substeps : int
        At least what keeps the step stable (MAX_DT).
    k_spring : float
        The edges' springs.
    k_rest : float
        The tethers to rest, relative to a spring's k (unit mean mass).
    damping : float
        V&Y's h per unit mass (1/s).
    falloff : float
        The reach of a muscle's pull around each of its strip's nodes, in 0.3 eye widths.
    strength : float
        The muscles' force, relative to a spring's k.
    """

    def __init__(self, rig, fps: float = 60.0, substeps: int = 2, k_spring: float = 1.0,
                 k_rest: float = 0.05, damping: float = 8.0, falloff: float = 1.5, strength: float = 5.0):
        """Stiffnesses are relative (k_rest and strength to a spring's k; unit mean mass);
        damping is V&Y's h per unit mass (1/s)."""
        skin = rig.skin
        # the step is semi-implicit with the stiffness taken at rest: stable up to MAX_DT
        # (measured: at 1, 5 and 10 fps with 2 substeps vertices flew 1e11-1e19 units away),
        # so low frame rates take more substeps
        substeps = max(substeps, int(np.ceil(1.0 / (fps * MAX_DT) - 1e-9)))
        self.rig, self.fps, self.substeps = rig, fps, substeps
        self.dt = 1.0 / (fps * substeps)
        x0 = skin.vertices
        self.x0, self.n = x0, len(x0)
        e = skin.edges
        self.e = e
        d = x0[e[:, 1]] - x0[e[:, 0]]
        self.l0 = np.linalg.norm(d, axis=1)
        mean_edge = skin.mean_edge_length()
        mass = lumped_mass(skin)
        self.m = mass / mass.mean()                            # unit mean mass: time scale from k
        # scale-free stiffnesses: a spring's k is relative to the mean edge, the feedback k
        # (V&Y's F_r) relative to one spring
        self.k = k_spring / self.l0 * mean_edge
        self.k_rest = k_rest * k_spring * self.m
        self.h = damping
        # stiffness at rest: springs along their directions, plus the feedback
        dh = d / self.l0[:, None]
        blocks = self.k[:, None, None] * dh[:, :, None] * dh[:, None, :]        # (E, 3, 3)
        rows, cols, vals = [], [], []
        for a, b, s in ((0, 0, 1), (1, 1, 1), (0, 1, -1), (1, 0, -1)):
            r = 3 * e[:, a][:, None, None] + np.arange(3)[None, :, None]
            c = 3 * e[:, b][:, None, None] + np.arange(3)[None, None, :]
            rows.append(np.broadcast_to(r, blocks.shape).ravel())
            cols.append(np.broadcast_to(c, blocks.shape).ravel())
            vals.append((s * blocks).ravel())
        K0 = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                           shape=(3 * self.n, 3 * self.n)) + sp.diags(np.repeat(self.k_rest, 3))
        m3 = np.repeat(self.m, 3)
        self.m3 = m3
        self.solver = SPDSolver((sp.diags(m3 * (1 + self.dt * self.h)) + self.dt ** 2 * K0).tocsc())
        # muscle force fields: over each muscle's spring nodes and their surroundings, toward
        # the origin along the muscle's stretch direction, with a smooth fall-off
        fields = []
        for mu in rig.muscles:
            pull = np.zeros((self.n, 3))
            wsum = np.zeros(self.n)
            ew = float(np.linalg.norm(rig.landmarks[45] - rig.landmarks[36]))
            radius = falloff * 0.15 * ew
            for node, s in zip(mu.nodes, mu.stretch):
                dist = np.linalg.norm(x0 - node, axis=1)
                w = np.clip(1 - dist / (2 * radius), 0, None) ** 2
                pull += w[:, None] * s[None, :]
                wsum += w
            pull /= np.maximum(wsum, 1e-12)[:, None]
            pull *= np.clip(wsum, 0, 1)[:, None]
            # force per node: `strength` springs stretched by the muscle's own stretch
            fields.append(pull * (strength * k_spring * self.m)[:, None])
        self.fields = np.stack(fields) if fields else np.zeros((0, self.n, 3))
        self.x = x0.copy()
        self.v = np.zeros_like(x0)

    def forces(self, x, activations):
        d = x[self.e[:, 1]] - x[self.e[:, 0]]
        ln = np.linalg.norm(d, axis=1)
        fs = (self.k * (ln - self.l0) / np.maximum(ln, 1e-300))[:, None] * d         # eq. 9, springs
        f = np.zeros_like(x)
        np.add.at(f, self.e[:, 0], fs)
        np.add.at(f, self.e[:, 1], -fs)
        f += self.k_rest[:, None] * (self.x0 - x)                                    # F_r = k P_i P_0
        f += np.einsum("m,mnc->nc", np.asarray(activations, float), self.fields)    # force fields
        return f

    def step(self, activations):
        dt = self.dt
        rhs = self.m3 * self.v.ravel() + dt * self.forces(self.x, activations).ravel()
        self.v = self.solver.solve(rhs).reshape(-1, 3)
        self.x = self.x + dt * self.v

    def displacement(self):
        return self.x - self.x0

    def run(self, activation_at, duration, progress=None):
        return run_frames(self, activation_at, duration, progress)
