"""How the parts of a head that are not skin move in a transfer.

The skin is transferred skin to skin (Song et al.); the other target parts take their role's
motion (correspond.parts): rigid bodies take the rigid motion that best fits the source's
part of the same role in each frame (Challis 1995 without scale) -- the jaw's from the
source's lower teeth, gums and tongue, or, where the source has none, from its chin; an eye's
rotation about the target eyeball's own centre; the skull stays -- and `follow` parts move
with the skin under them (the displacement of their closest skin point).
"""

from __future__ import annotations

import numpy as np

from ..align import Similarity, fit_similarity
from ..correspond.parts import EYE_LEFT, EYE_RIGHT, FOLLOW, JAW, Parts, fit_sphere
from ..mesh import Mesh
from ..mesh.query import TriangleLocator


class PartMotion:
    """The motion of a split head's other parts, precomputed for one (source, target) pair; `apply`
    fills the non-skin target vertices of each frame from the source frames and the transferred
    skin (eyeballs and teeth rigid, lashes and shells riding the skin).

    Parameters
    ----------
    source : Mesh
    ps : Parts
        The source's.
    target : Mesh
    pt : Parts
        The target's.
    skin : Mesh
        The target's skin.
    skin_index : (k,) int array
        The skin's vertices in the target.
    similarity : Similarity
        The target's alignment onto the source.
    source_landmarks : (68, 3) float array
    """

    def __init__(self, source: Mesh, ps: Parts, target: Mesh, pt: Parts, skin: Mesh, skin_index: np.ndarray,
                 similarity: Similarity, source_landmarks: np.ndarray):
        self.similarity, self._back = similarity, similarity.inverse()
        self.rest = source.vertices
        self.target = target.vertices
        self.bodies = []                          # (target vertices, source vertices, eye centres or None)
        for role in (JAW, EYE_LEFT, EYE_RIGHT):
            tv = pt.of(role)
            if not len(tv):
                continue
            sv = ps.of(role)
            if role == JAW and not len(sv):
                sv = _chin(source, ps, source_landmarks)
            if not len(sv):                       # no counterpart: stays with the head
                continue
            centres = None
            if role != JAW:                       # rotate about each eyeball's own centre
                cs, rs, _ = fit_sphere(source.vertices[sv])
                ct, rt, res = fit_sphere(similarity.apply(target.vertices[tv]))
                if not (0.5 * rs < rt < 2 * rs) or res > 0.1:      # an eye's front only (cut from its lids):
                    ct = cs                                        # about where the source's turns
                centres = (ct, cs)
            self.bodies.append((tv, sv, centres))
        self.follow = pt.of(FOLLOW)
        self.skin_index = skin_index
        if len(self.follow):
            tri, bary, _, _ = TriangleLocator(skin.vertices, skin.triangles).closest(target.vertices[self.follow])
            self._corners, self._bary = skin.triangles[tri], bary
        self._skin_rest = skin.vertices

    def rigid(self, frame: np.ndarray, sv: np.ndarray) -> Similarity:
        """The source part's best rigid motion from rest to `frame` (in the source's frame)."""
        return fit_similarity(self.rest[sv], frame[sv], what="a rigid part", scale=False)

    def apply(self, frames: np.ndarray, skin_out: np.ndarray) -> np.ndarray:
        """Source frames (F, n_S, 3) and the transferred skin (F, n_skin, 3) -> (F, n_T, 3)."""
        out = np.repeat(self.target[None], len(frames), axis=0)
        out[:, self.skin_index] = skin_out
        for tv, sv, centres in self.bodies:
            a = self.similarity.apply(self.target[tv])           # the target part in the source's frame
            for f, frame in enumerate(frames):
                m = self.rigid(frame, sv)
                if centres is None:
                    moved = m.apply(a)
                else:                                              # about the target eye's centre
                    ct, cs = centres
                    moved = ct + (m.apply(cs) - cs) + (a - ct) @ m.rotation.T
                out[f, tv] = self._back.apply(moved)
        if len(self.follow):
            d = skin_out - self._skin_rest                         # (F, n_skin, 3)
            out[:, self.follow] = self.target[self.follow] + np.einsum("kc,fkcd->fkd", self._bary,
                                                                       d[:, self._corners])
        return out


def _chin(source: Mesh, ps: Parts, lm) -> np.ndarray:
    """Source skin vertices near the chin (landmarks 6-10): the jaw's motion where the source
    has no lower teeth."""
    lm = np.asarray(lm, float)
    width = float(np.linalg.norm(lm[45] - lm[36]))
    skin = ps.skin
    near = np.zeros(source.n_vertices, bool)
    for k in range(6, 11):
        if np.isfinite(lm[k]).all():
            near |= np.linalg.norm(source.vertices - lm[k], axis=1) < 0.25 * width
    return np.nonzero(near & skin)[0]
