"""Wrinkles (Viaud & Yahia 1992): the wrinkle mask and its transfer to any face (§3), the
bulge model (§5) driven by the skin's compression and by age, refinement along wrinkle
lines, and displacement/normal maps."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .bulge import ArcLengthTable, arc_length, dilation
from .cylinder import CylinderFit, fit_cylinder, flatten
from .layer import WrinkleLayer
from .mask import Wrinkle, WrinkleMask, reference_mask
from .refine import Refined, refine_along
from .transfer import carry_mask, mask_for, mask_on, snap_mask, transfer_mask


@dataclass
class WrinkledSkin:
    """A skin mesh refined along the mask's lines and its wrinkle layer: `frame(X, age)` takes
    positions of the coarse skin (a simulated frame) to the wrinkled fine skin.

    Attributes
    ----------
    refined : Refined or None
        The refinement (None: the skin as it is).
    layer : WrinkleLayer
        On the refined skin.
    """
    refined: Refined | None
    layer: WrinkleLayer

    @classmethod
    def build(cls, skin, mask: WrinkleMask, refine: bool = True) -> "WrinkledSkin":
        r = refine_along(skin, mask) if refine else None
        layer = WrinkleLayer(r.mesh if r else skin, mask)
        if r is not None:                 # the refined mesh is ours to order: the bound points
            b = layer.vertex_binding      # last and consecutive, so a frame adds to a slice
            rest = np.ones(r.mesh.n_vertices, bool)
            rest[b.point] = False
            r, new_index = r.reordered(np.r_[np.nonzero(rest)[0], b.point])
            layer.relabel(r.mesh, new_index)
        return cls(r, layer)

    @property
    def mesh(self):
        return self.layer.mesh

    def carry(self, X) -> np.ndarray:
        """Coarse skin positions -> the layer's (refined) mesh, before the bulges."""
        return self.refined.carry(X) if self.refined is not None else X

    def frame(self, X, age: float) -> np.ndarray:
        if self.refined is not None:                      # carry makes a new array: bulge it in place
            return self.layer.apply(self.refined.carry(X), age, inplace=True)
        return self.layer.apply(X, age)


@dataclass
class WrinkledFrames:
    """Simulated frames with the wrinkle layer on (wrinkle_frames).

    Attributes
    ----------
    skin : WrinkledSkin
    frames : (F, n_fine, 3) float array
        The wrinkled fine skin.
    carried : list of (n_fine, 3) float arrays
        Per frame, the fine skin before the bulges.
    compression : (F, n_wrinkles) float array
        Each wrinkle's compression (1: at rest).
    ages : (F,) float array
    build_s : float
        Seconds to refine and build the layer.
    frame_s : float
        Seconds a frame.
    """
    skin: WrinkledSkin
    frames: np.ndarray            # (F, n_fine, 3) the wrinkled fine skin
    carried: list                 # per frame, the fine skin before the bulges
    compression: np.ndarray       # (F, n_wrinkles) each wrinkle's compression (1: at rest)
    ages: np.ndarray              # (F,)
    build_s: float                # seconds to refine and build the layer
    frame_s: float                # seconds a frame
    emphasis: list = None         # per frame, each wrinkle's muscle emphasis (None: not driven)

    @property
    def peak(self) -> int:
        """The frame with the most compression."""
        return int(np.argmin(np.minimum(self.compression, 1.0).mean(1)))


def wrinkle_frames(skin, mask: WrinkleMask, frames, ages, refine: bool = True, activations=None) -> WrinkledFrames:
    """The wrinkle layer on simulated frames (V&Y §5.3): the skin refined along the mask, each frame
    carried onto it and bulged at its age.

    Parameters
    ----------
    skin : Mesh
        The simulated skin.
    mask : WrinkleMask
        On it.
    frames : (F, n, 3) float array
    ages : (F,) float array
        Years, one a frame.
    refine : bool
        Refine the skin along the mask's lines first.
    activations : list of dict or None
        Per frame a {muscle: activation} (the simulation's), each wrinkle then deepened by the
        muscles its mask names (WrinkleLayer.muscle_emphasis).

    Returns
    -------
    WrinkledFrames
    """
    t0 = time.perf_counter()
    ws = WrinkledSkin.build(skin, mask, refine=refine)
    build_s = time.perf_counter() - t0
    ages = np.broadcast_to(np.asarray(ages, float), (len(frames),))
    t0 = time.perf_counter()
    carried = [ws.carry(v) for v in frames]
    emph = [None] * len(frames) if activations is None else [ws.layer.muscle_emphasis(a) for a in activations]
    fine = np.stack([ws.layer.apply(X, float(g), emphasis=e) for X, g, e in zip(carried, ages, emph)])
    per = (time.perf_counter() - t0) / max(len(frames), 1)
    comp = np.stack([ws.layer.compression(X) for X in carried])
    return WrinkledFrames(ws, fine, carried, comp, np.array(ages), build_s, per, emph)


__all__ = ["ArcLengthTable", "arc_length", "dilation", "CylinderFit", "fit_cylinder", "flatten",
           "WrinkleLayer", "Wrinkle", "WrinkleMask", "reference_mask", "Refined", "refine_along",
           "snap_mask", "carry_mask", "transfer_mask", "mask_on", "mask_for", "WrinkledSkin", "WrinkledFrames",
           "wrinkle_frames"]
