"""2D expression analogy between photos (Song et al. §VI) and its ERI baseline (Liu et al. 2001).

- `io`: read/write images (any format Pillow reads; GIF, PNG, JPEG), YUV conversion.
- `raster`: a software rasterizer (a mesh drawn into an image; every picture mimica makes).
- `warp`: triangulated piecewise-affine warps driven by the feature points (§VI.B, C).
- `analogy`: the image grid as a height field (i, j, Y), the VTC system of eq. 4 solved for
  luminance only, factorized once per image size (§VI.A, D); ERI for comparison.
"""

from .analogy import ImageAnalogy, psnr
from .io import read_image, rgb_to_yuv, write_image, yuv_to_rgb

__all__ = ["ImageAnalogy", "psnr", "read_image", "write_image", "rgb_to_yuv", "yuv_to_rgb"]
