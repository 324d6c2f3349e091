"""The viewer's face: its rig (loaded, or made as `rig` makes it, with the same defaults) and its
wrinkle mask, built before the page opens; the rig's force systems made then too, or beside the
page as it first moves them (viewer.ViewerSession.make_systems)."""

from __future__ import annotations

from dataclasses import dataclass, field

from ..errors import MimicaError
from .rig import RigOptions, make_rig


@dataclass(frozen=True)
class ViewOptions:
    """What the viewer shows; each default is the one every user of it gets.

    Attributes
    ----------
    rig : RigOptions
        How a face without a rig is rigged (the same defaults as `make_rig`: the calibrated
        library).
    wrinkles : bool
        The wrinkle layer and its age slider.
    systems : str
        When a face without a rig file gets its force systems: "as needed" (the page opens on
        the face at rest, and the session makes them beside it, those moved first: seconds
        instead of a minute on a whole head) or "first" (all before the page opens).
    """
    rig: RigOptions = field(default_factory=RigOptions)
    wrinkles: bool = True
    systems: str = "as needed"


@dataclass
class ViewedFace:
    """What the viewer's session is made from.

    Attributes
    ----------
    rig : Rig
        Its modal systems made, or (ViewOptions.systems "as needed") to be made by the session.
    mask : WrinkleMask or None
        None without wrinkles.
    """
    rig: object
    mask: object


def prepare_view(face, landmarks=None, rig=None, options: ViewOptions | None = None, progress=None) -> ViewedFace:
    """The rig and wrinkle mask the viewer plays: `rig`'s when given, else the face rigged.

    Parameters
    ----------
    face : str or Path or Mesh
        The face (any topology); unused when `rig` is given (the rig's own face is shown).
    landmarks : str or Path or Landmarks or None
        Its 68 landmarks (None: built in for ICT-FaceKit, else found on renders).
    rig : str or Path or Rig or None
        A rig made before (`make_rig`'s file, or a Rig).
    options : ViewOptions, optional
    progress : callable, optional
        Called as progress(k, n, name) after each force's modal system (`make_rig`).

    Returns
    -------
    ViewedFace
    """
    from ..rig import Rig
    o = options or ViewOptions()
    if o.systems not in ("as needed", "first"):
        raise MimicaError(f"view: systems {o.systems!r}: 'as needed' or 'first'")
    if rig is not None:
        r = rig if isinstance(rig, Rig) else Rig.load(rig)
    else:
        r = make_rig(face, landmarks, o.rig, progress=progress, systems=o.systems == "first")
    mask = None
    if o.wrinkles:
        from ..wrinkles import mask_for
        mask, _ = mask_for(r.skin, r.landmarks)
    return ViewedFace(r, mask)
