"""`mimica error`: Song's per-vertex error of a result against a reference, as a PNG map."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import MimicaError
from ..validate import floats
from ._common import _say


def cmd_error(a):
    """`mimica error`: Song's per-vertex error of a result against a reference, as a PNG map.

    Parameters
    ----------
    a : argparse.Namespace
        The command's options (its add_args).

    Returns
    -------
    int
        The exit status (0: done).
    """
    from ..mesh import read_mesh
    from ..render.errormap import error_map_png
    from ..transfer import relative_error, song_vertex_error

    res = read_mesh(a.result, allow_degenerate=True)
    ref = read_mesh(a.reference, allow_degenerate=True)
    ref_n = read_mesh(a.reference_neutral, allow_degenerate=True)
    res_n = read_mesh(a.result_neutral, allow_degenerate=True) if a.result_neutral else ref_n
    for m, p in ((ref, a.reference), (ref_n, a.reference_neutral), (res_n, a.result_neutral or a.reference_neutral)):
        if m.n_vertices != res.n_vertices:
            raise MimicaError(f"{p}: has {m.n_vertices} vertices, the result has {res.n_vertices}; "
                              "the error needs meshes of one topology")
    region, bins = _region(a.region, res.n_vertices), _bins(a.bins)
    e = song_vertex_error(res.vertices, res_n.vertices, ref.vertices, ref_n.vertices)
    rel = relative_error(res.vertices, ref.vertices + (res_n.vertices - ref_n.vertices), res_n.vertices, region)
    ee = e if region is None else e[region]
    _say(f"Song per-vertex error: median {100 * np.nanmedian(ee):.2f}%, mean {100 * np.nanmean(ee):.2f}%; "
         f"relative error {rel:.4f}")
    if a.out:
        error_map_png(a.out, res, e, title=f"{Path(a.result).name} vs {Path(a.reference).name}", bins=bins)
        _say(f"error map -> {a.out}")
    return 0


def _region(spec: str | None, n: int) -> slice | None:
    """--region LO:HI as a slice of the n vertices (None: every vertex)."""
    if not spec:
        return None
    try:
        lo, hi = (int(x) for x in spec.split(":"))
    except ValueError:
        lo = hi = -1
    if not 0 <= lo < hi <= n:
        raise MimicaError(f"--region {spec!r}: expected LO:HI vertex indices with 0 <= LO < HI <= {n}, e.g. 0:9409")
    return slice(lo, hi)


def _bins(spec: str) -> tuple:
    """--bins as three increasing fractions (given in percent)."""
    bins = tuple(x / 100 for x in floats(spec, 3, "--bins"))
    if min(bins) <= 0 or list(bins) != sorted(bins):
        raise MimicaError(f"--bins {spec!r}: expected three increasing positive percentages, e.g. 0.1,0.5,2")
    return bins


def add_args(sub) -> None:
    """Put `mimica error` and its options on the `mimica` parser.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The parser's commands (ArgumentParser.add_subparsers).
    """
    e = sub.add_parser("error", help="Song's per-vertex error of a result against a reference, as a PNG map")
    e.add_argument("result", help="transferred expression")
    e.add_argument("reference", help="reference expression (same topology)")
    e.add_argument("--reference-neutral", required=True, help="the reference's neutral")
    e.add_argument("--result-neutral", help="the result's neutral (default: the reference neutral)")
    e.add_argument("--region", help="vertex range LO:HI for the summary (e.g. 0:9409, ICT face area)")
    e.add_argument("--bins", default="0.1,0.5,2", help="colour thresholds in percent (Song Fig. 11: 0.1,0.5,2)")
    e.add_argument("-o", "--out", help="PNG to write")
    e.set_defaults(func=cmd_error)


run = cmd_error
