"""Pictures of a wrinkle mask on its face: the curves drawn over shaded renders."""

from __future__ import annotations

import numpy as np
from PIL import Image, ImageDraw
from scipy.spatial import cKDTree

from ..mesh import Mesh
from ..image.raster import framing, project, render_mesh, view_matrix
from .surface import cardinal_spline

GROUP_COLORS = {"forehead": (220, 40, 40), "glabellar": (230, 120, 0), "procerus": (230, 120, 0),
                "crows": (30, 110, 220), "lower": (0, 160, 170), "bunny": (150, 60, 200),
                "nasolabial": (20, 150, 40), "marionette": (160, 110, 20), "mentolabial": (200, 40, 160)}


def color_of(name: str):
    """A wrinkle's colour in pictures, by its group (its name's first word).

    Parameters
    ----------
    name : str

    Returns
    -------
    tuple of int
        RGB 0-255.
    """
    return GROUP_COLORS.get(name.split("_")[0], (40, 40, 40))


def mask_image(mesh: Mesh, mask, vertices=None, size=480, yaw=0.0, anchors=True) -> np.ndarray:
    """A shaded render of the face with the mask's wrinkles (and anchors) drawn on it.

    Parameters
    ----------
    mesh : Mesh
    mask : WrinkleMask
    vertices : (n, 3) float array or None
    size : int
    yaw : float
        Degrees.
    anchors : bool
        Draw the anchors too.

    Returns
    -------
    (size, size, 3) uint8 array
    """
    v = mesh.vertices if vertices is None else vertices
    frame = framing(v, yaw)
    img = Image.fromarray(render_mesh(mesh, v, size=(size, size), yaw=yaw, frame=frame))
    draw = ImageDraw.Draw(img)
    view = view_matrix(yaw)[2]                       # toward the camera, in world coordinates
    normals = mesh.vertex_normals(v)
    tree = cKDTree(v)

    def facing(p):
        return normals[tree.query(p)[1]] @ view > 0.05
    for w in mask.wrinkles:
        curve = cardinal_spline(w.points, 8)
        xy, _ = project(curve, frame, (size, size), yaw)
        front = facing(curve)
        pts = [tuple(p) for p, f in zip(xy, front) if f]
        if len(pts) > 1:
            draw.line(pts, fill=color_of(w.name), width=max(2, size // 200))
    if anchors:
        ok = np.isfinite(mask.anchors).all(1)
        xy, _ = project(mask.anchors[ok], frame, (size, size), yaw)
        r = max(1.5, size / 300)
        for x, y in xy[facing(mask.anchors[ok])]:
            draw.ellipse([x - r, y - r, x + r, y + r], fill=(255, 255, 255), outline=(0, 0, 0))
    return np.asarray(img)
