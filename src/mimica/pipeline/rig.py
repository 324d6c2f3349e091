"""Rig a face (Kim 2020): place the muscles, springs and regions of interest (rig.build_rig) and
make each force's modal system (physics.precompute), written as one rig file."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..errors import MimicaError
from ..mesh import Mesh


@dataclass(frozen=True)
class RigOptions:
    """How a face is rigged; each default is the one every user of it gets.

    Attributes
    ----------
    muscles : str
        "all" (the calibrated library: 44 muscles, and the jaw, the lids and the cheeks as
        drives), "kim" (Kim's 8), or names separated by commas.
    alpha : float
        ROI range (Kim eq. 19) where a muscle has none of its own.
    modes : int
        Skin modes per force type.
    stretch : str
        Each muscle's stretch: "bar" (nodes sliding toward the origin by arc length, what the
        library was calibrated with) or "shell" (the strip's own shell eigenproblem, Kim eqs.
        11-12).
    """
    muscles: str = "all"
    alpha: float = 10.0
    modes: int = 8
    stretch: str = "bar"


def make_rig(face, landmarks=None, options: RigOptions | None = None, out=None, progress=None, systems=True):
    """A face's rig, its modal systems made.

    Parameters
    ----------
    face : str or Path or Mesh
        The face (any topology).
    landmarks : str or Path or Landmarks or None
        Its 68 landmarks: a file, Landmarks, or None (built in for ICT-FaceKit, else found on
        renders).
    options : RigOptions, optional
    out : str or Path, optional
        Where to save the rig (`Rig.load` reads it back).
    progress : callable, optional
        Called as progress(k, n, name) after each force's modal system.
    systems : bool
        Make the modal systems now (False: the muscles placed only; physics.precompute, or the
        first simulation, or a viewer's session makes them).

    Returns
    -------
    Rig
    """
    from ..landmarks import Landmarks, landmarks_for
    from ..mesh import read_mesh
    from ..physics import precompute
    from ..rig import build_rig
    o = options or RigOptions()
    if o.stretch not in ("bar", "shell"):
        raise MimicaError(f"rig: stretch {o.stretch!r}: bar or shell")
    skin = face if isinstance(face, Mesh) else read_mesh(face)
    lm = landmarks if isinstance(landmarks, Landmarks) else landmarks_for(skin, landmarks, str(face))
    rig = build_rig(skin, lm.positions(skin), muscles=o.muscles, alpha=o.alpha, modes=o.modes)
    if o.stretch == "shell":
        from ..physics.systems import shell_stretch_modes
        shell_stretch_modes(rig)
    if systems:
        precompute(rig, progress=progress)
    if out is not None:
        rig.save(Path(out))
    return rig
