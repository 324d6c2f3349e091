"""Skin simulation.

shell    discrete shell energy (Kim 2020 eqs. 1-4) with exact derivatives, mass, damping
modal    modal bases (eq. 8), modal warping integration (eq. 10), full-space reference solver
springs  the springs that tie the skin to the muscles, the drives and its rest (Kim eqs. 14-16)
drives   the drives' loads, the lids' contact, channels to activations (ActivationMap)
systems  the skin's and each force type's systems: ROIs, modes, stretch modes (eqs. 8, 11-19);
         precompute(rig) makes them (the rig carries them, a .rig file keeps them)
face     the muscle-driven face stepped: one system per force type, summed (eqs. 20-21)
sprung   Viaud & Yahia 1992's force-field engine (eq. 9), driven by the rig's muscles
engine   the engines' one interface (Engine), chosen by name (make_engine), and their frame loop
"""

from ..errors import MimicaError
from .engine import ENGINES, Engine
from .face import FaceSimulator
from .fullface import FullFaceSimulator
from .shell import ShellEnergy, hinges_of, lumped_mass, rayleigh_damping
from .sprung import SprungFace
from .systems import precompute

__all__ = ["ENGINES", "Engine", "FaceSimulator", "FullFaceSimulator", "SprungFace", "make_engine", "ShellEnergy",
           "hinges_of", "lumped_mass", "precompute", "rayleigh_damping"]


def make_engine(name: str, rig, fps: float = 60.0, **options) -> Engine:
    """A physics engine on a rig, chosen by name.

    Parameters
    ----------
    name : str
        "modal" (face.FaceSimulator, Kim's modal warping), "full" (the full nonlinear shell) or
        "sprung" (Viaud and Yahia's sprung skin).
    rig : Rig
    fps : float
    **options
        The engine's own (FaceSimulator's warp and springs; none for the others).

    Returns
    -------
    Engine
    """
    kinds = {"modal": FaceSimulator, "full": FullFaceSimulator, "sprung": SprungFace}
    if name in kinds:
        return kinds[name](rig, fps=fps, **options)
    raise MimicaError(f"engine {name!r}: one of {', '.join(ENGINES)}")
