"""A picture of how a transfer sees its target (issue 16, part 5): the parts in colour, the
skin without a source partner, the cut mouth's seam and the lid rims the contacts pair."""

from __future__ import annotations

import numpy as np

from ..correspond.parts import ROLES
from ..image.raster import render_mesh
from .sheet import _font, contact_sheet
from .shots import VIEWS, shared_frame_all_views

# what each colour means (RGB in [0, 1]), in the order the legend lists them
KEY = [("skin", (0.82, 0.72, 0.64)), ("skull: upper teeth, gums", (0.95, 0.85, 0.35)),
       ("jaw: lower teeth, gums, tongue", (0.95, 0.55, 0.2)), ("eyeballs (rigid)", (0.55, 0.75, 1.0)),
       ("rides on the skin: lashes, shells, sockets", (0.45, 0.8, 0.45)),
       ("skin with no partner on the source", (0.85, 0.2, 0.85)), ("mouth seam, cut", (0.9, 0.1, 0.1)),
       ("lid rims, paired", (0.1, 0.8, 0.85))]
_ROLE_KEY = {"skin": 0, "skull": 1, "jaw": 2, "eye.left": 3, "eye.right": 3, "follow": 4}


def transfer_picture(xfer, title: str = "", size: int = 420) -> np.ndarray:
    """The target of an ExpressionTransfer in two views, coloured by what the transfer does."""
    mesh = xfer.output_mesh
    r = xfer.vertex_report()
    role_key = np.array([_ROLE_KEY[ROLES[i]] for i in range(len(ROLES))])[r["role"]]
    colors = np.array([c for _, c in KEY])
    key = role_key.copy()
    key[~r["matched"] & (role_key == 0)] = 5
    key[r["seam"]] = 6
    key[r["rim"]] = 7
    views = ("front", "three-quarter")
    frame = shared_frame_all_views(mesh.vertices, views)
    tiles = [render_mesh(mesh, size=(size, size), yaw=VIEWS[v][0], pitch=VIEWS[v][1], colors=colors[key],
                         frame=frame) for v in views]
    tiles.append(_legend([(f"{name}: {int((key == k).sum()):,}", c) for k, (name, c) in enumerate(KEY)
                          if (key == k).any()], size))
    return contact_sheet(tiles, list(views) + ["vertices"], title=title or None)


def _legend(entries, size) -> np.ndarray:
    """A tile of colour swatches and their meaning."""
    from PIL import Image, ImageDraw
    img = Image.new("RGB", (size, size), (255, 255, 255))
    d = ImageDraw.Draw(img)
    font = _font(15)
    for i, (text, c) in enumerate(entries):
        y = 20 + 30 * i
        d.rectangle([12, y, 34, y + 20], fill=tuple(int(255 * x) for x in c), outline=(60, 60, 60))
        d.text((44, y + 1), text, fill=(20, 20, 20), font=font)
    return np.asarray(img)
