"""An age sheet (Viaud and Yahia 1992): a face at rest and in an expression, its wrinkles at each
of several ages, drawn as one contact sheet."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..errors import MimicaError
from ..mesh import Mesh
from .rig import RigOptions


@dataclass(frozen=True)
class AgeOptions:
    """What the age sheet shows; each default is the one every user of it gets.

    Attributes
    ----------
    ages : tuple of float
        Years, 0 to 150, one column each.
    expression : str
        The preset of the second row (anim.PRESETS).
    size : int
        Pixels a picture.
    rig : str or Path or None
        A rig of this face; None: one made with RigOptions' muscles.
    wrinkles : str or Path or None
        A wrinkle mask of this face; None: the reference mask, carried onto it.
    """
    ages: tuple = (25.0, 45.0, 65.0, 85.0)
    expression: str = "happiness"
    size: int = 360
    rig: str | Path | None = None
    wrinkles: str | Path | None = None


def age_sheet(face, out, landmarks=None, options: AgeOptions | None = None, progress=None) -> int:
    """Draw the age sheet of a face into the PNG `out`.

    Parameters
    ----------
    face : str or Path or Mesh
        The face.
    out : str or Path
        The PNG to write.
    landmarks : str or Path or Landmarks or None
        Its 68 landmarks (None: built in for ICT-FaceKit, else found on renders).
    options : AgeOptions, optional
    progress : callable, optional
        Called as progress(k, n, name) while the rig's modal systems are made.

    Returns
    -------
    int
        How many pictures the sheet holds.
    """
    from ..anim import PRESETS, Timeline
    from ..landmarks import Landmarks, landmarks_for
    from ..mesh import read_mesh
    from ..physics.face import FaceSimulator
    from ..render import contact_sheet, face_framing, render_mesh, save_png
    from ..rig import Rig
    from ..wrinkles import WrinkledSkin, mask_for, mask_on
    from .rig import make_rig
    o = options or AgeOptions()
    ages = [float(x) for x in o.ages]
    if not ages or not all(0 <= x <= 150 for x in ages):                 # NaN fails too
        raise MimicaError(f"ages {o.ages!r}: expected ages in years from 0 to 150, e.g. 25,45,65,85")
    if not str(out).lower().endswith(".png"):
        raise MimicaError(f"{out}: the age sheet is a PNG picture; name it *.png")
    if o.expression not in PRESETS:
        raise MimicaError(f"expression {o.expression!r}: one of {', '.join(PRESETS)}")
    mesh = face if isinstance(face, Mesh) else read_mesh(face)
    lm = landmarks if isinstance(landmarks, Landmarks) else landmarks_for(mesh, landmarks, str(face))
    if o.rig is not None:
        rig = Rig.load(o.rig)
        if rig.skin.n_vertices != mesh.n_vertices:
            raise MimicaError(f"{o.rig}: the rig's skin has {rig.skin.n_vertices} nodes, the face has "
                              f"{mesh.n_vertices}; build the rig from this face")
    else:
        rig = make_rig(mesh, lm, RigOptions(), progress=progress)
    names = [m.name for m in rig.muscles]
    tl = Timeline.preset(o.expression, names, duration=1.2)
    expr = FaceSimulator(rig).run(lambda t: tl.values(t, names), 1.2)[-1]
    pts = lm.positions(mesh)
    mask = mask_on(o.wrinkles, mesh, str(face)) if o.wrinkles is not None else mask_for(mesh, pts)[0]
    ws = WrinkledSkin.build(mesh, mask)
    frame = face_framing(pts)
    tiles, labels = [], []
    for name, X in (("neutral", mesh.vertices), (o.expression, expr)):
        for g in ages:
            tiles.append(render_mesh(ws.mesh, ws.frame(X, g), size=(o.size, o.size), frame=frame))
            labels.append(f"{name}, age {g:g}")
    title = Path(face).name if not isinstance(face, Mesh) else (mesh.name or "face")
    save_png(out, contact_sheet(tiles, labels, columns=len(ages), title=f"{title}: wrinkles by age (Viaud & Yahia 1992)"))
    return len(tiles)
