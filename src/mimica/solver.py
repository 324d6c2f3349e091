"""Sparse symmetric positive-definite factorization, factored once and reused.

Three backends, fastest first, each taking a block of right-hand sides at once:

- "cholmod": CHOLMOD through scikit-sparse (needs SuiteSparse's headers to build; `make`
  and CI install them on Debian), supernodal with the system BLAS;
- "cholespy": CHOLMOD inside a self-contained wheel (`pip install cholespy`, no system
  packages), the fast path that any machine reaches;
- "scipy": SciPy's SuperLU in symmetric mode, always there.

Measured on the transfer system of the ICT head (n = 11,248, 145k non-zeros, 96 right-hand
sides; best of 7 over two runs, 2-core VM; docs/benchmarks.md): factor 0.06 / 0.13-0.17 /
0.28-0.38 s, solve 48-62 / 52-156 / 275-360 ms.  `backend()` says which one is in use; MIMICA_SOLVER=cholmod|cholespy|scipy
chooses among the installed ones.
"""

from __future__ import annotations

import os
import threading

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .errors import MimicaError
from .parallel import cores

# CHOLMOD's supernodal factorization (SuiteSparse 5, Debian's) opens many small OpenMP regions
# on 4 threads whatever the machine has; on fewer cores the threads wait on one another (1.4
# million futex calls in the library's precompute).  Measured on 2 cores, OpenMP limited to 1 /
# 2 threads / not: the library's precompute in one process 13.4 / 13.3 / 19.9 s, the full
# solver on a 945-node patch 17.0 / 3.2 / 5.6 steps/s.  GNU OpenMP reads its thread limit when
# it loads, with CHOLMOD, just below; a limit the user set is kept.
if "OMP_THREAD_LIMIT" not in os.environ and 0 < cores() < 4:
    os.environ["OMP_THREAD_LIMIT"] = "1"
try:  # pragma: no cover - depends on the machine
    from sksparse.cholmod import cholesky as _cholmod_cholesky
except Exception:  # ImportError, or a broken shared library
    _cholmod_cholesky = None
try:  # pragma: no cover - depends on the machine
    import cholespy as _cholespy
except Exception:
    _cholespy = None

KINDS = ("cholmod", "cholespy", "scipy")


def available() -> list[str]:
    """The sparse Cholesky backends installed here, fastest first.

    Returns
    -------
    list of str
        Of "cholmod" (scikit-sparse), "cholespy", "scipy" (SuperLU, always there).
    """
    have = {"cholmod": _cholmod_cholesky is not None, "cholespy": _cholespy is not None, "scipy": True}
    return [k for k in KINDS if have[k]]


def backend() -> str:
    """The backend a solver gets by default.

    Returns
    -------
    str
        $MIMICA_SOLVER if installed, else the fastest available.
    """
    want = os.environ.get("MIMICA_SOLVER", "")
    have = available()
    return want if want in have else have[0]


def _splu(m: sp.csc_matrix):
    """SuperLU in symmetric mode (no pivoting off the diagonal), the fallback factor."""
    return spla.splu(m, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})


def _cholespy_factor(m: sp.csc_matrix):
    return _cholespy.CholeskySolverD(m.shape[0], m.indptr.astype(np.int32), m.indices.astype(np.int32),
                                     np.ascontiguousarray(m.data, dtype=np.float64), _cholespy.MatrixType.CSC)


class SPDSolver:
    """Factor a sparse symmetric positive definite matrix once; `solve(B)` for B of shape (n,) or
    (n, k); `refactor(m)` for a matrix of the same pattern.  One solve at a time per factor.

    Parameters
    ----------
    m : (n, n) sparse matrix
    kind : str or None
        "cholmod", "cholespy" or "scipy" (None: backend()).
    """

    def __init__(self, m: sp.spmatrix, kind: str | None = None):
        self.kind = kind or backend()
        if self.kind not in available():
            raise MimicaError(f"sparse solver {self.kind!r} is not installed here (installed: "
                              f"{', '.join(available())})")
        self._lock = threading.Lock()
        m = sp.csc_matrix(m)
        self.n = m.shape[0]
        self._f = self._factor(m)

    def _factor(self, m):
        if self.kind == "cholmod":
            return _cholmod_cholesky(m)
        if self.kind == "cholespy":
            return _cholespy_factor(m)
        return _splu(m)

    def refactor(self, m: sp.spmatrix) -> "SPDSolver":
        """Factor a new matrix of the same sparsity pattern, reusing CHOLMOD's symbolic
        analysis (the fill-reducing ordering); cholespy and SuperLU start over."""
        m = sp.csc_matrix(m)
        with self._lock:
            if self.kind == "cholmod":
                self._f.cholesky_inplace(m)
            else:
                self._f = self._factor(m)
        return self

    def solve(self, b: np.ndarray) -> np.ndarray:
        b = np.asarray(b, dtype=np.float64)
        # one solve at a time per factor: CHOLMOD keeps workspace in its common object, so
        # concurrent solves must not share it; other stages of a batch still overlap
        with self._lock:
            if self.kind == "cholmod":
                return self._f(b)
            if self.kind == "cholespy":
                b = np.ascontiguousarray(b)
                x = np.empty_like(b)
                self._f.solve(b, x)
                return x
            return self._f.solve(np.asfortranarray(b))
