"""Jobs in worker processes (mimica.parallel): the same results as in the caller, a job's error
raised there, workers that cannot start leave the work to the caller; a rig's systems made in
workers equal those made in one process."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mimica.data import ICT_LANDMARKS_68
from mimica.parallel import run_jobs
from mimica.physics import precompute
from mimica.rig import build_rig


class OnlyHere:
    """Pickled by reference to this test module, which a worker cannot import."""

    def __pow__(self, exponent):
        return -exponent

    def __rpow__(self, base):
        return base


def test_jobs_in_workers_give_each_result_once():
    jobs = [0.5, 1.0, 2.0, 3.0, 4.0, 5.5]
    got = dict(run_jobs(math.pow, 2.0, jobs, workers=2))
    assert sorted(got) == list(range(len(jobs)))
    assert all(got[i] == math.pow(2.0, j) for i, j in enumerate(jobs))


def test_a_jobs_error_is_raised_in_the_caller():
    with pytest.raises(ValueError, match="math domain error"):
        dict(run_jobs(math.pow, 0.0, [1.0, -1.0, 2.0], workers=2))


def test_workers_that_cannot_start_or_die_leave_the_jobs_to_the_caller():
    # a worker cannot unpickle what names this module: the shared state (each stops at once) ...
    assert dict(run_jobs(pow, OnlyHere(), [2.0, 3.0, 4.0], workers=2)) == {0: -2.0, 1: -3.0, 2: -4.0}
    # ... or a job (its worker dies on it; the others go on)
    assert dict(run_jobs(pow, 3.0, [2.0, OnlyHere(), 1.0, 0.0], workers=2)) == {0: 9.0, 1: 3.0, 2: 3.0, 3: 1.0}


def test_systems_made_in_workers_equal_those_made_in_one_process(face):
    names = ["zygomaticus_major_L", "zygomaticus_major_R", "frontalis_L", "depressor_anguli_oris_R"]
    lm = face.neutral[ICT_LANDMARKS_68]
    one = precompute(build_rig(face.mesh, lm, muscles=names), workers=1)
    seen = []
    two = precompute(build_rig(face.mesh, lm, muscles=names), workers=2,
                     progress=lambda k, n, name: seen.append((k, n, name)))
    # each system said once as it is made, gravity's too
    assert sorted(name for _, _, name in seen) == sorted(names + ["gravity"])
    assert [k for k, _, _ in seen] == [1, 2, 3, 4, 5] and {n for _, n, _ in seen} == {5}
    for a, b in [(m.basis, w.basis) for m, w in zip(one.muscles, two.muscles)] + [(one.gravity_basis, two.gravity_basis)]:
        np.testing.assert_array_equal(a.free, b.free)
        np.testing.assert_allclose(a.lam, b.lam, rtol=1e-9)
        np.testing.assert_allclose(a.phi, b.phi, atol=1e-9 * np.abs(a.phi).max())
    # the skin's rotation operator is the caller's (the warp's fields made from it)
    b = two.muscles[0].basis
    np.testing.assert_allclose(b.psi, one.muscles[0].basis.psi, atol=1e-9 * np.abs(b.psi).max())
