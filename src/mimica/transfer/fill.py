"""Low-confidence skin takes its motion from the skin around it.

Where the correspondence is weak -- a sealed eye's skin across an opening the source has, a
target reaching past the source's edge -- the source's deformation there is the wrong one
(a lid rim's closing squeezed onto the skin across a sealed eye pushes it out: on the shared
real head's blinks the worst vertex moves 0.23 eye widths without this step, 0.17 with it;
before the transfer averaged each tent over its one-ring, 0.82 and 0.37).  Here every skin vertex whose confidence c is under LOW gets its
displacement blended toward the harmonic interpolation of its neighbours' (a graph-Laplacian
fill of the low-confidence region, the confident skin around it as the boundary), with the
weight 1 - c / LOW; one factorization per target, one back-substitution per batch of frames.
Our own step, not the paper's; measured in bench/real_heads.py.
"""

from __future__ import annotations

import numpy as np

from ..mesh import Mesh
from ..mesh.graph import HarmonicFill


class LowConfidenceFill:
    """Skin whose correspondence has low confidence takes its motion from the skin around it: a
    harmonic fill (Laplace's equation, factored once) blended in by how low the confidence is.

    Parameters
    ----------
    mesh : Mesh
        The target.
    confidence : (n,) float array
    low : float
        Below it a vertex is filled.

    Attributes
    ----------
    ok : bool
        Whether there is anything to fill.
    """
    def __init__(self, mesh: Mesh, confidence: np.ndarray, low: float):
        c = np.asarray(confidence, float)
        weak = c < low
        a = mesh.adjacency
        inside = np.nonzero(weak)[0]
        ring = np.nonzero(~weak & (np.asarray(a[:, weak].sum(1)).ravel() > 0))[0]
        self.ok = len(inside) > 0 and len(ring) > 0
        if not self.ok:
            return
        # pieces of the weak region that touch no confident skin keep their own motion (the
        # small screen)
        self.inside, self.ring = inside, ring
        self.fill = HarmonicFill(a, inside, ring)
        self.blend = (1.0 - c[inside] / low)[None, :, None]
        self.rest = mesh.vertices

    def apply(self, out: np.ndarray) -> np.ndarray:
        """out: (F, n, 3) results; the weak skin's displacements blended toward the fill."""
        if not self.ok:
            return out
        filled = self.fill((out[:, self.ring] - self.rest[self.ring]).transpose(1, 0, 2)).transpose(1, 0, 2)
        own = out[:, self.inside] - self.rest[self.inside]
        out[:, self.inside] = self.rest[self.inside] + own + self.blend * (filled - own)
        return out
