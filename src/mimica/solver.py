"""Sparse symmetric positive-definite factorization, factored once and reused.

CHOLMOD (scikit-sparse) when it is installed, else SciPy's SuperLU; both take a block of
right-hand sides at once. `backend()` says which one is in use.
"""

from __future__ import annotations

import os
import threading

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

try:  # pragma: no cover - depends on the machine
    from sksparse.cholmod import cholesky as _cholmod_cholesky
except Exception:  # ImportError, or a broken shared library
    _cholmod_cholesky = None


def backend() -> str:
    if _cholmod_cholesky is not None and os.environ.get("MIMICA_SOLVER", "") != "scipy":
        return "cholmod"
    return "scipy"


def _splu(m: sp.csc_matrix):
    """SuperLU in symmetric mode (no pivoting off the diagonal), the fallback factor."""
    return spla.splu(m, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})


class SPDSolver:
    """Factor a sparse SPD matrix once; `solve(B)` for B of shape (n,) or (n, k)."""

    def __init__(self, m: sp.spmatrix, kind: str | None = None):
        self.kind = kind or backend()
        self._lock = threading.Lock()
        m = sp.csc_matrix(m)
        self.n = m.shape[0]
        self._f = _cholmod_cholesky(m) if self.kind == "cholmod" else _splu(m)

    def refactor(self, m: sp.spmatrix) -> "SPDSolver":
        """Factor a new matrix of the same sparsity pattern, reusing CHOLMOD's symbolic
        analysis (the fill-reducing ordering); SuperLU starts over."""
        m = sp.csc_matrix(m)
        with self._lock:
            if self.kind == "cholmod":
                self._f.cholesky_inplace(m)
            else:
                self._f = _splu(m)
        return self

    def solve(self, b: np.ndarray) -> np.ndarray:
        b = np.asarray(b, dtype=np.float64)
        # one solve at a time per factor: CHOLMOD keeps workspace in its common object, so
        # concurrent solves must not share it; other stages of a batch still overlap
        with self._lock:
            if self.kind == "cholmod":
                return self._f(b)
            return self._f.solve(np.asfortranarray(b))
