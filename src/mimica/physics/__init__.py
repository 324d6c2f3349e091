"""Skin simulation (Kim 2020): discrete shells; more of issue 3 to come."""

from .shell import ShellEnergy, hinges_of, lumped_mass, rayleigh_damping

__all__ = ["ShellEnergy", "hinges_of", "lumped_mass", "rayleigh_damping"]
