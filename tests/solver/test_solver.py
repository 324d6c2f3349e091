"""The sparse Cholesky's process settings: CHOLMOD's OpenMP held to one thread on small machines."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

READ = ("import ctypes, os; import mimica.solver as s; from mimica.parallel import cores; "
        "print(s.backend(), cores(), os.environ.get('OMP_THREAD_LIMIT'), "
        "ctypes.CDLL('libgomp.so.1').omp_get_thread_limit() if s.backend() == 'cholmod' else 0)")


def _read(**env):
    base = {k: v for k, v in os.environ.items() if k not in ("OMP_THREAD_LIMIT", "MIMICA_SOLVER")}
    out = subprocess.run([sys.executable, "-c", READ], env={**base, **env}, capture_output=True, text=True, check=True)
    kind, cores, limit, gomp = out.stdout.split()
    return kind, int(cores), limit, int(gomp)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="GNU OpenMP (Debian's CHOLMOD) is Linux's")
def test_cholmod_runs_its_openmp_on_one_thread_below_four_cores():
    """SuiteSparse 5's CHOLMOD opens its OpenMP regions on 4 threads whatever the machine has:
    where it has fewer cores, GNU OpenMP's thread limit is 1 (read back from libgomp itself);
    a limit the user set is kept."""
    kind, cores, limit, gomp = _read()
    if kind != "cholmod":
        if os.environ.get("CI") is not None:
            pytest.fail("scikit-sparse (CHOLMOD) is not installed, though CI builds it")
        pytest.skip("scikit-sparse (CHOLMOD) is not installed here")
    if cores < 4:
        assert (limit, gomp) == ("1", 1)
    else:
        assert limit is None
    assert _read(OMP_THREAD_LIMIT="3")[2:] == ("3", 3)
