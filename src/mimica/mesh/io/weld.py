"""The seams a writer split between the pieces of a file (a material's primitive in glTF,
an object in FBX), made one again for the work."""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ..core import unique_rows


def move_key(moves: np.ndarray) -> np.ndarray:
    """Each vertex's morph-target moves (n, m), all targets side by side, as two fixed random
    projections: equal rows for vertices that move alike, apart but for a chance of measure zero
    for ones that do not -- the `same` of Mesh.welded and weld_seams, light to sort.

    Parameters
    ----------
    moves : (n, m) float array

    Returns
    -------
    (n, 2) float array
    """
    return moves @ np.random.default_rng(0).normal(size=(moves.shape[1], 2))


def weld_seams(wpos, e, set_of, label, same=None) -> np.ndarray:
    """Across vertex sets: a boundary edge a -> b of one set that meets exactly one boundary edge
    b' -> a' of another at the same points (the two sides of a seam a writer split, one oriented
    surface), moving alike in `same`, has its ends made one.

    Parameters
    ----------
    wpos : (n, 3) float array
        The labels' positions.
    e : (k, 2) int array
        The faces' half-edges in labels (Mesh.half_edges).
    set_of : (raw,) int array
        Each raw vertex's set.
    label : (raw,) int array
        Each raw vertex's label.
    same : (n, k) float array or None
        Per label, values the two sides must share too (their morph-target moves: a slit's
        sides move apart, a seam's together).

    Returns
    -------
    (raw,) int array
        The raw vertices' labels, seams welded.
    """
    lab_set = np.zeros(len(wpos), np.int64)
    lab_set[label] = set_of
    _, inv, cnt = unique_rows(np.sort(e, 1))
    b = e[cnt[inv] == 1]
    if not len(b) or len(np.unique(lab_set)) < 2:
        return label
    _, pid, _ = unique_rows(wpos if same is None else np.c_[wpos, same])
    n_p = int(pid.max()) + 1
    fwd = pid[b[:, 0]] * n_p + pid[b[:, 1]]
    rev = pid[b[:, 1]] * n_p + pid[b[:, 0]]
    keys, kcount = np.unique(fwd, return_counts=True)
    order = np.argsort(fwd, kind="stable")
    partner = order[np.minimum(np.searchsorted(fwd[order], rev), len(b) - 1)]
    found = fwd[partner] == rev
    once = kcount[np.searchsorted(keys, fwd)] == 1          # no third edge at the same points
    ok = found & once & once[partner] & (lab_set[b[:, 0]] != lab_set[b[partner, 0]])
    i = np.nonzero(ok)[0]
    if not len(i):
        return label
    a = np.r_[b[i, 0], b[i, 1]]
    c = np.r_[b[partner[i], 1], b[partner[i], 0]]
    n = len(wpos)
    graph = coo_matrix((np.ones(len(a)), (a, c)), shape=(n, n))
    _, root = connected_components(graph, directed=False)
    return root[label]
