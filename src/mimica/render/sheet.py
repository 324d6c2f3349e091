"""Contact sheets and colour maps (PNG output: image.io.write_image)."""

from __future__ import annotations

import numpy as np
from PIL import Image, ImageDraw, ImageFont


def label_font(size=14):
    """The pictures' label font: DejaVu Sans where installed, else Pillow's own.

    Parameters
    ----------
    size : int
        Pixels.

    Returns
    -------
    PIL.ImageFont.FreeTypeFont or PIL.ImageFont.ImageFont
    """
    for name in ("DejaVuSans.ttf", "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf"):
        try:
            return ImageFont.truetype(name, size)
        except OSError:
            continue
    return ImageFont.load_default()


def contact_sheet(tiles, labels=None, columns=None, title=None, row_labels=None, pad=6) -> np.ndarray:
    """A grid of equally sized tiles with captions under each.

    Parameters
    ----------
    tiles : list of (h, w, 3) uint8 arrays
    labels : list of str or None
        A caption a tile.
    columns : int or None
        None: one row.
    title : str or None
        Over the grid.
    row_labels : list of str or None
        Left of each row.
    pad : int
        Pixels between tiles.

    Returns
    -------
    (H, W, 3) uint8 array
    """
    tiles = list(tiles)
    h, w = tiles[0].shape[:2]
    cols = columns or len(tiles)
    rows = (len(tiles) + cols - 1) // cols
    cap = 20
    top = 30 if title else 0
    left = 200 if row_labels else 0
    sheet = Image.new("RGB", (left + cols * (w + pad) + pad, top + rows * (h + cap + pad) + pad), "white")
    draw = ImageDraw.Draw(sheet)
    font = label_font(14)
    if title:
        draw.text((pad, 6), title, fill=(20, 20, 20), font=label_font(18))
    for i, tile in enumerate(tiles):
        r, c = divmod(i, cols)
        x, y = left + pad + c * (w + pad), top + pad + r * (h + cap + pad)
        sheet.paste(Image.fromarray(tile), (x, y))
        if labels:
            draw.text((x + 4, y + h + 2), str(labels[i]), fill=(30, 30, 30), font=font)
    if row_labels:
        for r, lab in enumerate(row_labels):
            draw.text((pad, top + pad + r * (h + cap + pad) + h // 2), str(lab), fill=(30, 30, 30), font=font)
    return np.asarray(sheet)


def colormap(t: np.ndarray) -> np.ndarray:
    """A perceptually ordered ramp, blue -> green -> yellow -> red.

    Parameters
    ----------
    t : (m,) float array
        In [0, 1] (clipped).

    Returns
    -------
    (m, 3) float array
        RGB in [0, 1].
    """
    stops = np.array([[0.19, 0.25, 0.62], [0.13, 0.57, 0.55], [0.45, 0.78, 0.30],
                      [0.99, 0.85, 0.22], [0.86, 0.19, 0.15]])
    t = np.clip(np.asarray(t, float), 0, 1) * (len(stops) - 1)
    i = np.minimum(t.astype(int), len(stops) - 2)
    f = (t - i)[:, None]
    return stops[i] * (1 - f) + stops[i + 1] * f


def heat_colors(values: np.ndarray) -> np.ndarray:
    """Per-vertex colours on the colormap, scaled to the largest value.

    Parameters
    ----------
    values : (n,) float array

    Returns
    -------
    (n, 3) float array
    """
    v = np.asarray(values, float)
    return colormap(v / max(np.nanmax(v), 1e-12))
