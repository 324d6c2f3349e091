"""A picture of how a transfer sees its target: the parts in colour, the
skin without a source partner, the cut mouth's seam and the lid rims the contacts pair; and the
correspondence's confidence per vertex as a map."""

from __future__ import annotations

import numpy as np

from ..correspond import Correspondence
from ..correspond.parts import ROLES
from ..image.raster import render_mesh
from .sheet import label_font, contact_sheet
from .shots import VIEWS, shared_frame_all_views

# what each colour means (RGB in [0, 1]), in the order the legend lists them
KEY = [("skin", (0.82, 0.72, 0.64)), ("skull: upper teeth, gums", (0.95, 0.85, 0.35)),
       ("jaw: lower teeth, gums, tongue", (0.95, 0.55, 0.2)), ("eyeballs (rigid)", (0.55, 0.75, 1.0)),
       ("rides on the skin: lashes, shells", (0.45, 0.8, 0.45)),
       ("skin with no partner on the source", (0.85, 0.2, 0.85)), ("mouth seam, cut", (0.9, 0.1, 0.1)),
       ("lid rims, paired", (0.1, 0.8, 0.85)), ("mouth: looked for a seam, none cut", (0.1, 0.1, 0.1)),
       ("pockets: mouth bag, eye sockets", (0.8, 0.45, 0.55))]
_ROLE_KEY = {"skin": 0, "skull": 1, "jaw": 2, "eye.left": 3, "eye.right": 3, "follow": 4, "pocket": 9}


def transfer_picture(xfer, title: str = "", size: int = 420) -> np.ndarray:
    """The target of an ExpressionTransfer in two views, coloured by what the transfer does to each
    vertex (solved, rigid part, filled, cut, ...), and a front view of the correspondence's
    confidence (red 0 -> yellow 0.5 -> green 1), with a legend.

    Parameters
    ----------
    xfer : ExpressionTransfer
    title : str
    size : int
        Each view's side.

    Returns
    -------
    (h, w, 3) uint8 array
    """
    mesh = xfer.output_mesh
    r = xfer.vertex_report()
    role_key = np.array([_ROLE_KEY[ROLES[i]] for i in range(len(ROLES))])[r["role"]]
    colors = np.array([c for _, c in KEY])
    key = role_key.copy()
    key[~r["matched"] & (role_key == 0)] = 5
    key[r["seam"]] = 6
    key[r["rim"]] = 7
    key[r["looked"]] = 8
    views = ("front", "three-quarter")
    frame = shared_frame_all_views(mesh.vertices, views)
    tiles = [render_mesh(mesh, size=(size, size), yaw=VIEWS[v][0], pitch=VIEWS[v][1], colors=colors[key],
                         frame=frame) for v in views]
    conf = np.clip(r["confidence"], 0, 1)
    tiles.append(render_mesh(mesh, size=(size, size), yaw=VIEWS["front"][0], pitch=VIEWS["front"][1],
                             colors=confidence_colors(conf), frame=frame))
    skin = role_key == 0
    low = skin & r["matched"] & (conf < LOW)
    entries = [(f"{name}: {int((key == k).sum()):,}", c) for k, (name, c) in enumerate(KEY) if (key == k).any()]
    entries.append((f"skin matched, confidence < {LOW}: {int(low.sum()):,}", tuple(confidence_colors(np.array([0.2]))[0])))
    tiles.append(_legend(entries, size))
    return contact_sheet(tiles, list(views) + ["confidence", "vertices"], title=title or None)


LOW = Correspondence.LOW


def confidence_colors(c: np.ndarray) -> np.ndarray:
    """Confidence -> RGB: red at 0, yellow at 0.5, green at 1.

    Parameters
    ----------
    c : (n,) float array
        In [0, 1] (clipped).

    Returns
    -------
    (n, 3) float array
    """
    c = np.clip(np.asarray(c, float), 0, 1)[:, None]
    red, yellow, green = np.array([0.85, 0.15, 0.1]), np.array([0.95, 0.85, 0.2]), np.array([0.2, 0.7, 0.3])
    lo = red + (yellow - red) * np.clip(2 * c, 0, 1)
    return np.where(c < 0.5, lo, yellow + (green - yellow) * np.clip(2 * c - 1, 0, 1))


def _legend(entries, size) -> np.ndarray:
    """A tile of colour swatches and their meaning."""
    from PIL import Image, ImageDraw
    img = Image.new("RGB", (size, size), (255, 255, 255))
    d = ImageDraw.Draw(img)
    font = label_font(15)
    for i, (text, c) in enumerate(entries):
        y = 20 + 30 * i
        d.rectangle([12, y, 34, y + 20], fill=tuple(int(255 * x) for x in c), outline=(60, 60, 60))
        d.text((44, y + 1), text, fill=(20, 20, 20), font=font)
    return np.asarray(img)
