"""Graphs over a mesh's vertices: edge graphs and harmonic fills (Laplace's equation on the
graph Laplacian, one factorization, one back-substitution per batch of values) -- what the lid
contacts, the low-confidence fill, the pockets' join and the jaw's share of a spanning piece
solve alike."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..solver import SPDSolver


def edge_graph(n: int, edges: np.ndarray, weights: np.ndarray | None = None) -> sp.csr_matrix:
    """The (n, n) symmetric sparse graph of undirected edges (E, 2), each with its weight (1
    where none are given), in CSR."""
    e = np.asarray(edges).reshape(-1, 2)
    w = np.ones(len(e)) if weights is None else np.asarray(weights, float)
    return sp.coo_matrix((np.r_[w, w], (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])), shape=(n, n)).tocsr()


class HarmonicFill:
    """Values on the vertices `inside` harmonic over a graph (its Laplacian L = D - A), given on
    the vertices `ring` around them: (L_ii + screen I) x = -L_ir y + screen * prior.  A small
    screen keeps a piece that meets no ring at its prior (0 unless given); a larger one makes
    what the ring says fade over about 1/sqrt(screen) edges.  Factored once.

    Parameters
    ----------
    adjacency : (n, n) sparse matrix
        The graph (0/1 or weighted, symmetric).
    inside, ring : int arrays
        The vertices solved for and those given.
    screen : float
    """

    def __init__(self, adjacency, inside: np.ndarray, ring: np.ndarray, screen: float = 1e-9):
        a = sp.csr_matrix(adjacency)
        lap = (sp.diags(np.asarray(a.sum(1)).ravel()) - a).tocsr()
        self.inside, self.ring, self.screen = np.asarray(inside), np.asarray(ring), float(screen)
        rows = lap[self.inside]
        self._solver = SPDSolver((rows[:, self.inside] + screen * sp.identity(len(self.inside))).tocsc())
        self._coupling = rows[:, self.ring].tocsr()

    def __call__(self, given: np.ndarray, prior: np.ndarray | None = None) -> np.ndarray:
        """The inside's values (m, ...) from the ring's (r, ...), any trailing shape."""
        given = np.asarray(given, float)
        tail = given.shape[1:]
        k = int(np.prod(tail))
        rhs = -(self._coupling @ given.reshape(len(self.ring), k))
        if prior is not None:
            rhs = rhs + self.screen * np.asarray(prior, float).reshape(len(self.inside), k)
        return self._solver.solve(np.asarray(rhs)).reshape((len(self.inside),) + tail)
