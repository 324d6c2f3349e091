"""Robustness (issue 15): no races, no destroyed inputs, one line for every OS error."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from conftest import skin_patch

from mimica.transfer import ExpressionTransfer, static_vertices


def test_apply_on_threads_never_races(head_model):
    """Song transfer of 300 frames on 4 threads, 50 times, each on a fresh solver (the lazily
    built state of a fresh one is what raced): every result equals the one-thread result."""
    S, _ = skin_patch(head_model, 3.0)
    rng = np.random.default_rng(0)
    moving = np.linalg.norm(S.vertices - S.vertices.mean(0), axis=1) < 1.5     # the rest is static
    frames = S.vertices + rng.normal(0, 0.01, (300, S.n_vertices, 3)) * moving[None, :, None]
    static = static_vertices(S.vertices, frames)
    assert 0 < static.sum() < S.n_vertices
    T = S.with_vertices(S.vertices * 1.1)
    ref = ExpressionTransfer(S, T, static=static).apply(frames, workers=1)
    for _ in range(50):
        out = ExpressionTransfer(S, T, static=static).apply(frames, batch=8, workers=4)
        assert np.array_equal(out, ref)
