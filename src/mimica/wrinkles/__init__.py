"""Wrinkles (Viaud & Yahia 1992): so far the cylinder fit and flattening of §3.1."""

from .cylinder import CylinderFit, fit_cylinder, flatten

__all__ = ["CylinderFit", "fit_cylinder", "flatten"]
