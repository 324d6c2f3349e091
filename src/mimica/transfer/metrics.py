"""Error measures for transferred expressions."""

from __future__ import annotations

import numpy as np


def relative_error(result, truth, rest, region=None) -> float:
    """mean |result - truth| / mean |truth - rest| over a region: the transfer's figure of merit.

    Parameters
    ----------
    result, truth : (..., n, 3) float arrays
    rest : (n, 3) float array
    region : slice or index array or None
        The vertices counted (None: all).

    Returns
    -------
    float
    """
    r = slice(None) if region is None else region
    num = np.linalg.norm(np.asarray(result)[..., r, :] - np.asarray(truth)[..., r, :], axis=-1).mean()
    den = np.linalg.norm(np.asarray(truth)[..., r, :] - np.asarray(rest)[..., r, :], axis=-1).mean()
    return float(num / max(den, 1e-300))


def song_vertex_error(result, result_rest, reference, reference_rest, min_motion=0.01):
    """Song et al., appendix: E = | |V_TE - V_TN| / |V_SE - V_SN| - 1 | per vertex.

    The ratio is unstable where the reference barely moves, so vertices whose reference motion is
    below `min_motion` of the largest motion have no defined error (NaN).

    Parameters
    ----------
    result, result_rest : (n, 3) float arrays
        The target's expression and neutral.
    reference, reference_rest : (n, 3) float arrays
        The reference's (the truth, or the source's).
    min_motion : float

    Returns
    -------
    (n,) float array
    """
    mt = np.linalg.norm(np.asarray(result) - np.asarray(result_rest), axis=-1)
    ms = np.linalg.norm(np.asarray(reference) - np.asarray(reference_rest), axis=-1)
    ok = ms > min_motion * max(float(ms.max()), 1e-300)
    e = np.full(ms.shape, np.nan)
    e[ok] = np.abs(mt[ok] / ms[ok] - 1.0)
    return e
