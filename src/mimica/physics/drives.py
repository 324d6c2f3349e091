"""What drives the skin besides the muscles' springs (rig.drives): the loads of the strip muscles
and of the jaw, lid and cheek drives, the lids' contact where the rims meet, and the map from a
frame's channels to the muscles' activations and the drives' motions."""

from __future__ import annotations

import numpy as np

from ..rig.drives import JAW_CLOSERS, LID_MARGIN, jaw_open_parts, lid_pairs, margin_opening
from .springs import drive_springs


def strip_loads(rig, muscle) -> np.ndarray:
    """A strip's load patterns: each spring pulling its fan along x, y and z, once for the nodes
    that share a skin node (their fans are the same).

    Parameters
    ----------
    rig : Rig
    muscle : Muscle
        A strip muscle.

    Returns
    -------
    (3n, 3u) float array
        n: the skin's vertices; u: the strip's distinct skin nodes.
    """
    at, wt, of = muscle.springs()
    _, first = np.unique(muscle.attach, return_index=True)
    col = np.full(len(muscle.nodes), -1)
    col[first] = np.arange(len(first))
    keep = col[of] >= 0
    loads = np.zeros((3 * rig.skin.n_vertices, 3 * len(first)))
    for c in range(3):
        np.add.at(loads, (3 * at[keep] + c, 3 * col[of[keep]] + c), wt[keep])
    return loads


def drive_load(rig, muscle, motion=None) -> np.ndarray:
    """The force of a drive's anchors moved by `motion`, K_s u_part.

    Parameters
    ----------
    rig : Rig
    muscle : Muscle
        A drive.
    motion : (k, 3) float array or None
        Its anchors' motion (None: their motion at full activation, muscle.stretch).

    Returns
    -------
    (n, 3) float array
    """
    f = np.zeros((rig.skin.n_vertices, 3))
    k = drive_springs(rig, muscle)
    f[muscle.attach] = k[muscle.attach, None] * (muscle.stretch if motion is None else motion)
    return f


def drive_motions(m) -> list:
    """A drive's anchor motions whose loads its system must hold.

    Parameters
    ----------
    m : Muscle
        A drive.

    Returns
    -------
    list of (k, 3) float arrays
        The jaw's opening as its two parts (exact rotation at any angle, rig.drives.jaw_open_parts);
        any other drive's one motion.
    """
    if m.info.get("part") == "jaw" and m.info.get("motion") == "open" and "pivot" in m.info:
        ms, mc, _ = jaw_open_parts(m.nodes, m.info)
        return [ms, mc]
    return [m.stretch]


CONTACT_SLACK = 1.15            # measured: the lower lid's skin rises 2 % of the opening past its anchors


def _shares(xp, ucp, info, steps: int = 24) -> np.ndarray:
    """Per pair of margin nodes xp (k, 2, 3), the smallest share of the closing field there ucp
    (k, 2, 3) whose removal leaves it open (margin_opening >= 0); 1 where even all of it does
    not.  Bisection, all pairs at once."""
    lo, hi = np.zeros(len(xp)), np.ones(len(xp))
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        ok = margin_opening(xp - mid[:, None, None] * ucp, info) >= 0
        lo, hi = np.where(ok, lo, mid), np.where(ok, mid, hi)
    return hi


def lid_contact(u, uc, rest, info, passes: int = 4):
    """Lid contact, position by position.

    Where the margins would cross, the closing field is taken away there, along the eye, until
    they meet: at each pair of facing margin nodes the share of uc that brings the opening to 0
    (bisection, all pairs at once), interpolated across the eye between the pairs (by the position
    of their upper nodes) for every node the closing drive moves.  The rims then meet wherever the
    closing lid reaches the lower one and are held apart nowhere else -- a share of the whole
    field, the same at every pair, held the ends of a fitted blink 9 % of the opening apart where
    its middle met (docs/benchmarks.md).  Passes repeat it for the lower nodes' own shares; what
    still crosses after them has the rest of the field taken away evenly.

    Parameters
    ----------
    u : (n, 3) float array
        The skin's displacement; changed in place.
    uc : (n, 3) float array
        The closing drive's part of it.
    rest : (n, 3) float array
        The skin at rest.
    info : dict
        The closing drive's (Muscle.info): the eye's centre, up and fwd, and its margins' facing
        pairs (lid_pairs).
    passes : int

    Returns
    -------
    (n, 3) float array
        u.
    """
    p = lid_pairs(info)
    if len(p) == 0:
        return u
    c, up, fwd = (np.asarray(info[k], float) for k in ("centre", "up", "fwd"))
    across = np.cross(fwd, up)
    moving = np.nonzero(np.abs(uc).max(axis=1) > 0)[0]
    if len(moving) == 0:
        return u
    uc = uc[moving]
    t = (rest[moving] - c) @ across
    tp = (rest[p[:, 0]] - c) @ across
    order = np.argsort(tp)
    where = np.minimum(np.searchsorted(moving, p), len(moving) - 1)   # the pairs' nodes among the moving
    inside = moving[where] == p

    def at_pairs(field):                               # (k, 2, 3), zero where it moves no pair node
        return np.where(inside[..., None], field[where], 0.0)
    for _ in range(passes):
        xp = rest[p] + u[p]
        o = margin_opening(xp, info)
        if o.min() >= 0:
            return u
        h = np.where(o < 0, _shares(xp, at_pairs(uc), info), 0.0)
        hn = np.interp(t, tp[order], h[order])
        u[moving] -= hn[:, None] * uc
        uc = uc * (1.0 - hn)[:, None]                   # what is left of the closing field
    xp = rest[p] + u[p]
    o = margin_opening(xp, info)
    if o.min() < 0:                                     # the lower nodes' shares left a crossing:
        u[moving] -= _shares(xp, at_pairs(uc), info)[o < 0].max() * uc      # the same share everywhere
    return u


class ActivationMap:
    """The muscles' activations -> each force system's input.

    A muscle's input is its activation, except for the drives (rig.drives): the jaw opens by the
    digastric's activation less its strongest closer's (masseter, temporalis: the teeth stop it at
    rest, so never below 0).  With `lid_room` (the full-space solver, which has no contact), a lid
    closes at most until its rim meets the other (the closing drive moves the rim by its input x
    the opening, the lower lid's raise by its `raise` part of it, the levator lifts it by its
    `wide` angle; the input is held where they meet); the modal face instead stops the lids where
    they touch, position by position (lid_contact).  Drive inputs stay in 0..1.

    Parameters
    ----------
    muscles : list of Muscle
        The rig's.
    lid_room : bool
        Hold each lid's input where its rim meets the other's.
    """

    def __init__(self, muscles, lid_room: bool = True):
        names = [m.name for m in muscles]
        self.drives = [i for i, m in enumerate(muscles) if m.kind == "drive"]
        self.closers = [i for i, n in enumerate(names) if n.rsplit("_", 1)[0] in JAW_CLOSERS]
        self.jaw_open = [i for i, m in enumerate(muscles) if m.kind == "drive"
                         and m.info.get("part") == "jaw" and m.info.get("motion") == "open"]
        self.lid_close = [i for i in self.drives if muscles[i].info.get("part") == "lid"
                          and muscles[i].info.get("motion") == "close"]
        self.lids = []                               # (close, raise, wide, wide/opening, raise part)
        for i in self.lid_close:
            m = muscles[i]
            same = {muscles[j].info.get("motion"): j for j in self.drives if muscles[j].info.get("eye") == m.info["eye"]}
            w, r = same.get("wide"), same.get("raise")
            ratio = muscles[w].info["wide"] / max(float(m.info.get("gap_max", 1.0)), 1e-9) if w is not None else 0.0
            self.lids.append((i, r, w, ratio, muscles[r].info["raise"] if r is not None else 0.0))
        self.lid_room = lid_room

    def __call__(self, activations) -> np.ndarray:
        if not self.drives:
            return activations
        a = np.array(activations, float)
        if self.closers:
            for j in self.jaw_open:
                a[j] -= max(a[self.closers].max(), 0.0)
        a[self.drives] = np.clip(a[self.drives], 0.0, 1.0)
        for c, r, w, ratio, lift in (self.lids if self.lid_room else []):
            # (the raised lower lid's skin reaches a little past its anchors: CONTACT_SLACK)
            room = 1.0 - (a[r] * lift * CONTACT_SLACK if r is not None else 0.0) + \
                (a[w] * ratio if w is not None else 0.0)
            a[c] = min(a[c], max(room, 0.0) / (1.0 - LID_MARGIN))
        return a
