"""Image files and colour spaces."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image

from ..errors import MimicaError
from ..outputs import atomic_path

__all__ = ["read_image", "write_image", "to_uint8", "rgb_to_yuv", "yuv_to_rgb", "luminance"]

# BT.601 (the YUV of Song et al. §VI.A): Y = luminance, U/V = colour differences
_RGB2YUV = np.array([[0.299, 0.587, 0.114],
                     [-0.14713, -0.28886, 0.436],
                     [0.615, -0.51499, -0.10001]])
_YUV2RGB = np.linalg.inv(_RGB2YUV)


def to_uint8(img) -> np.ndarray:
    """An image's pixels as uint8.

    Parameters
    ----------
    img : array
        Float in [0, 1] (clipped), or already uint8.

    Returns
    -------
    uint8 array
        The same shape.
    """
    img = np.asarray(img)
    if img.dtype == np.uint8:
        return img
    return (np.clip(img, 0, 1) * 255 + 0.5).astype(np.uint8)


def write_image(path, img: np.ndarray) -> Path:
    """Write an RGB or grey image, whole or not at all, its folder made; the format follows the
    suffix (PNG for .png and anything Pillow does not know).

    Parameters
    ----------
    path : str or Path
    img : (h, w) or (h, w, 3) array
        uint8, or float in [0, 1].

    Returns
    -------
    Path
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fmt = Image.registered_extensions().get(path.suffix.lower(), "PNG")
    with atomic_path(path) as tmp:
        Image.fromarray(to_uint8(img)).save(tmp, format=fmt, **({"compress_level": 3} if fmt == "PNG" else {}))
    return path


MAX_PIXELS = 40_000_000           # 40 megapixels: more than any camera frame mimica is meant for


def read_image(path) -> np.ndarray:
    """An image file as float RGB; a file that cannot be read is one MimicaError naming it.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    (h, w, 3) float array
        In [0, 1].
    """
    from PIL import UnidentifiedImageError
    path = Path(path)
    if not path.is_file():
        raise MimicaError(f"{path}: no such image file")
    try:
        with Image.open(path) as im:
            if im.width * im.height > MAX_PIXELS:
                raise MimicaError(f"{path}: image is {im.width}x{im.height}; photos of up to "
                                  f"{MAX_PIXELS // 10**6} megapixels are taken, resize it first")
            im.seek(0)
            arr = np.asarray(im.convert("RGB"), dtype=np.float32) / 255.0
    except (UnidentifiedImageError, OSError, ValueError, Image.DecompressionBombError, EOFError) as e:
        raise MimicaError(f"{path}: not an image Pillow can read ({e.__class__.__name__})") from None
    if arr.shape[0] < 16 or arr.shape[1] < 16:
        raise MimicaError(f"{path}: image is {arr.shape[1]}x{arr.shape[0]}; a face needs at least 16x16 pixels")
    return arr


def rgb_to_yuv(rgb) -> np.ndarray:
    """RGB to YUV (BT.601), float32.

    Parameters
    ----------
    rgb : (..., 3) array

    Returns
    -------
    (..., 3) float32 array
    """
    return np.asarray(rgb, np.float32) @ _RGB2YUV.T.astype(np.float32)


def yuv_to_rgb(yuv) -> np.ndarray:
    """YUV (BT.601) to RGB, float32.

    Parameters
    ----------
    yuv : (..., 3) array

    Returns
    -------
    (..., 3) float32 array
    """
    return np.asarray(yuv, np.float32) @ _YUV2RGB.T.astype(np.float32)


def luminance(img) -> np.ndarray:
    """The luminance Y of an image.

    Parameters
    ----------
    img : (h, w, 3) or (h, w) array
        A single-channel image is already its own luminance.

    Returns
    -------
    (h, w) float32 array
    """
    img = np.asarray(img, np.float32)
    if img.ndim == 2:
        return img
    return img[..., 0] * np.float32(0.299) + img[..., 1] * np.float32(0.587) + img[..., 2] * np.float32(0.114)
