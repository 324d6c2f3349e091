"""Photos with exact truth: ICT-FaceKit faces rendered as "photos" under a chosen light, with
their 68 landmark vertices projected (for benchmarks and tests of the 2D path).  The whole
model is drawn (eyeballs, mouth interior), so that open eyes and mouths show something other
than the inside of the back of the head."""

from __future__ import annotations

import numpy as np

from ..data import ICT_LANDMARKS_68, ICTModel
from .raster import face_framing, project, render_mesh

LIGHT_LEFT = (-0.5, 0.3, 0.8)
LIGHT_RIGHT = (0.45, 0.5, 0.75)


class ICTPhotos:
    """Photos with exact truth: ICT-FaceKit faces rendered under a chosen light, with their 68
    landmark vertices projected (for benchmarks and tests of the 2D path).

    Parameters
    ----------
    size : tuple of int
        (w, h) pixels.
    zoom : float
        The face's framing grown by this.
    """
    def __init__(self, size=(311, 419), zoom=1.3):
        self.model = ICTModel()
        c, half = face_framing(self.model.neutral[ICT_LANDMARKS_68])
        self.frame, self.size = (c, half * zoom), tuple(size)

    def vertices(self, identity, expression=None, amount=1.0):
        v = self.model.identity(identity)
        if expression:
            v = v + amount * self.model.delta(self.model.expression(expression))
        return v

    def photo(self, identity, expression=None, light=LIGHT_LEFT, amount=1.0):
        """(h, w, 3) float image in [0, 1] and the (68, 2) projected landmarks."""
        v = self.vertices(identity, expression, amount)
        img = render_mesh(self.model.mesh, v, size=self.size, frame=self.frame, light=light,
                          background=(90, 90, 90)).astype(np.float32) / 255.0
        xy, _ = project(v[ICT_LANDMARKS_68], self.frame, self.size)
        return img, xy
