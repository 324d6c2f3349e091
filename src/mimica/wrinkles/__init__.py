"""Wrinkles (Viaud & Yahia 1992): so far the cylinder fit and flattening (§3.1) and the
bulge model (§5: dilation law, arc-length table, its inversion)."""

from .bulge import ArcLengthTable, arc_length, dilation
from .cylinder import CylinderFit, fit_cylinder, flatten

__all__ = ["ArcLengthTable", "arc_length", "dilation", "CylinderFit", "fit_cylinder", "flatten"]
