"""Skin simulation.

shell    discrete shell energy (Kim 2020 eqs. 1-4) with exact derivatives, mass, damping
modal    modal bases (eq. 8), modal warping integration (eq. 10), full-space reference solver
face     the muscle-driven face: springs, ROIs, one system per force type (eqs. 11-21);
         precompute(rig) makes those systems (the rig carries them, a .rig file keeps them)
sprung   Viaud & Yahia 1992's force-field engine (eq. 9), driven by the rig's muscles
"""

from .face import precompute
from .shell import ShellEnergy, hinges_of, lumped_mass, rayleigh_damping

__all__ = ["ShellEnergy", "hinges_of", "lumped_mass", "precompute", "rayleigh_damping"]
