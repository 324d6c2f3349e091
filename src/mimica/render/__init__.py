"""Pictures: shaded renders, heat maps, contact sheets (software rasterizer, no GPU)."""

from ..image.raster import face_framing, framing, project, rasterize, render_mesh, shared_frame, view_matrix
from ..image.io import write_image as save_png  # one image writer for the project
from .sheet import colormap, contact_sheet, heat_colors
from .shots import VIEWS, render_views, turntable_angles, with_legend

__all__ = ["face_framing", "framing", "project", "rasterize", "render_mesh", "shared_frame", "view_matrix", "contact_sheet",
           "save_png", "heat_colors", "colormap", "VIEWS", "render_views", "turntable_angles", "with_legend"]
