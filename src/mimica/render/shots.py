"""Shots a person looks at: named views, turntables, heat maps with a legend, sequences."""

from __future__ import annotations

import numpy as np
from PIL import Image, ImageDraw

from ..image.raster import framing, render_mesh
from .sheet import label_font, colormap

# (yaw, pitch) in degrees; yaw turns the face to its left (the viewer sees its right cheek)
VIEWS = {"front": (0.0, 0.0), "three-quarter": (-35.0, 0.0), "profile": (-90.0, 0.0)}


def shared_frame_all_views(v, views, margin=1.08):
    """One framing that fits the mesh in every view.

    Parameters
    ----------
    v : (n, 3) float array
    views : list
        View names (VIEWS) or (yaw, pitch) pairs.
    margin : float

    Returns
    -------
    center : (3,) float array
    half_extent : float
    """
    c = 0.5 * (v.min(0) + v.max(0))
    half = max(framing(v, *(VIEWS[w] if isinstance(w, str) else w), margin)[1] for w in views)
    return c, half


def render_views(mesh, vertices=None, views=("front", "three-quarter", "profile"), size=512, colors=None,
                 frame=None) -> list:
    """A mesh drawn from several views with one framing.

    Parameters
    ----------
    mesh : Mesh
    vertices : (n, 3) float array or None
        Positions to draw (None: the mesh's).
    views : tuple
        View names (VIEWS: "front", "three-quarter", "profile", ...) or (yaw, pitch) pairs.
    size : int
        Each picture's side, pixels.
    colors : (n, 3) float array or None
        Per-vertex RGB in [0, 1].
    frame : tuple or None
        (center, half extent); None: shared_frame_all_views.

    Returns
    -------
    list of (size, size, 3) uint8 arrays
    """
    v = mesh.vertices if vertices is None else np.asarray(vertices)
    frame = frame or shared_frame_all_views(v, views)
    out = []
    for w in views:
        yaw, pitch = VIEWS[w] if isinstance(w, str) else w
        out.append(render_mesh(mesh, v, size=(size, size), yaw=yaw, pitch=pitch, colors=colors, frame=frame))
    return out


def turntable_angles(n: int) -> np.ndarray:
    """Yaws of a turntable, evenly around.

    Parameters
    ----------
    n : int

    Returns
    -------
    (n,) float array
        Degrees, from 0, 360 left out.
    """
    return np.linspace(0.0, 360.0, int(n), endpoint=False)


def with_legend(img: np.ndarray, vmin: float, vmax: float, label: str = "") -> np.ndarray:
    """The picture with a horizontal colour bar (colormap) and its scale under it.

    Parameters
    ----------
    img : (h, w, 3) uint8 array
    vmin, vmax : float
        The bar's ends.
    label : str
        What the values are.

    Returns
    -------
    (h + 56, w, 3) uint8 array
    """
    h, w = img.shape[:2]
    bar_h, pad = 14, 10
    canvas = Image.new("RGB", (w, h + bar_h + 42), "white")
    canvas.paste(Image.fromarray(img), (0, 0))
    x0, x1 = pad + 40, w - pad - 40
    ramp = (colormap(np.linspace(0, 1, max(x1 - x0, 2))) * 255).astype(np.uint8)
    canvas.paste(Image.fromarray(np.repeat(ramp[None], bar_h, 0)), (x0, h + 8))
    d = ImageDraw.Draw(canvas)
    f = label_font(12)
    for frac in (0.0, 0.25, 0.5, 0.75, 1.0):
        x = x0 + frac * (x1 - x0)
        d.line([(x, h + 8 + bar_h), (x, h + 12 + bar_h)], fill="black")
        txt = f"{vmin + frac * (vmax - vmin):.3g}"
        d.text((x - 3 * len(txt), h + 14 + bar_h), txt, fill="black", font=f)
    if label:
        d.text((pad, h + 28 + bar_h), label, fill="black", font=f)
    return np.asarray(canvas)
