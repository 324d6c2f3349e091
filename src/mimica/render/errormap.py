"""Colour-coded per-vertex error maps, like Song et al. Fig. 11."""

from __future__ import annotations

import numpy as np
from PIL import Image, ImageDraw

from ..mesh import Mesh
from ..image.raster import render_mesh
from ..image.io import write_image as save_png
from .sheet import label_font

# Song Fig. 11 levels: < 0.1 % green, [0.1 %, 0.5 %) blue, [0.5 %, 2 %) red; beyond: purple
BINS = (0.001, 0.005, 0.02)
COLORS = ((0.20, 0.72, 0.30), (0.20, 0.40, 0.85), (0.85, 0.18, 0.15), (0.45, 0.10, 0.45))
NO_MOTION = (0.75, 0.75, 0.75)


def bin_labels(bins) -> tuple[str, ...]:
    """The legend's labels of error bins.

    Parameters
    ----------
    bins : tuple of float
        Increasing thresholds (shares, 0.001 = 0.1 %).

    Returns
    -------
    tuple of str
        "< 0.1%", "0.1% - 0.5%", ..., ">= 2%".
    """
    pct = [f"{100 * b:g}%" for b in bins]
    return tuple([f"< {pct[0]}"] + [f"{a} - {b}" for a, b in zip(pct, pct[1:])] + [f">= {pct[-1]}"])


def error_colors(err: np.ndarray, bins=BINS, colors=COLORS) -> np.ndarray:
    """Per-vertex colours of an error by bin (Song Fig. 11's levels by default).

    Parameters
    ----------
    err : (n,) float array
        NaN: a vertex that does not move (drawn grey).
    bins : tuple of float
    colors : tuple of RGB
        One more than bins.

    Returns
    -------
    (n, 3) float array
        RGB in [0, 1].
    """
    idx = np.digitize(np.nan_to_num(err, nan=0.0), bins)
    col = np.asarray(colors, float)[np.minimum(idx, len(colors) - 1)]
    col[~np.isfinite(err)] = NO_MOTION
    return col


def error_map_image(mesh: Mesh, err: np.ndarray, title="", size=420, bins=BINS) -> np.ndarray:
    """Front and three-quarter views coloured by error level (3 thresholds, 4 colours), with a legend.

    Parameters
    ----------
    mesh : Mesh
    err : (n,) float array
    title : str
    size : int
        Each view's side, pixels.
    bins : tuple of float
        Three increasing thresholds.

    Returns
    -------
    (h, w, 3) uint8 array
    """
    if len(bins) != 3 or list(bins) != sorted(bins):
        raise ValueError("bins: three increasing thresholds")
    col = error_colors(err, bins)
    views = [render_mesh(mesh, size=(size, size), yaw=y, colors=col) for y in (0.0, 35.0)]
    pad, legend_h, top = 8, 34, 28
    w = 2 * size + 3 * pad
    img = Image.new("RGB", (w, top + size + legend_h + pad), "white")
    draw = ImageDraw.Draw(img)
    draw.text((pad, 6), title, fill=(20, 20, 20), font=label_font(16))
    for i, v in enumerate(views):
        img.paste(Image.fromarray(v), (pad + i * (size + pad), top))
    x = pad
    y = top + size + 8
    font = label_font(13)
    entries = list(zip(bin_labels(bins), COLORS)) + [("no motion", NO_MOTION)]
    for lab, c in entries:
        draw.rectangle([x, y, x + 16, y + 16], fill=tuple(int(255 * t) for t in c))
        draw.text((x + 22, y + 1), lab, fill=(30, 30, 30), font=font)
        x += 40 + int(draw.textlength(lab, font=font))
    return np.asarray(img)


def error_map_png(path, mesh: Mesh, err: np.ndarray, title="", bins=BINS):
    """Write error_map_image as a PNG.

    Parameters
    ----------
    path : str or Path
    mesh : Mesh
    err : (n,) float array
    title : str
    bins : tuple of float

    Returns
    -------
    Path
    """
    return save_png(path, error_map_image(mesh, err, title, bins=bins))
