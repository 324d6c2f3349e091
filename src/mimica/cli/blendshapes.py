"""`mimica blendshapes`: the 52 ARKit blendshapes on any head mesh, as one GLB."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import MimicaError
from ._common import QUANTIZE_HELP, UNITS_HELP, FILE_FORMATS, _quantized_line, _units_line, _say
from ._heads import _correspondence_line, _head_options, _say_uncut_mouth, _warn_sealed_eyes
from ..pipeline import BlendshapesOptions as D


def _sparse_line(path, info: dict, n: int) -> str:
    """'34 of 52 morph targets sparse (moves under 0.01 mm left out), 4.2 MB'."""
    from ..mesh.io import SPARSE_TOLERANCE
    return (f"{info['sparse']} of {n} morph targets sparse (moves under {SPARSE_TOLERANCE * 1e3:g} mm left out), "
            + _quantized_line(info) + f"{Path(path).stat().st_size / 1e6:.1f} MB")


def _say_written(out: Path, r, units: str, name: str) -> None:
    """What the writer did, in a line (or two: a glTF's writing notes)."""
    from ..export import ARKIT_52
    from ..mesh.io import SPARSE_TOLERANCE
    info, mesh = r.written, r.shapes.mesh
    added = f" ({info['appended']} vertices added by the cuts)" if info.get("appended") else ""
    if info["kind"] == "fbx":
        _say(f"written into {name}'s own objects through Blender's FBX exporter{added}, {info['bytes'] / 1e6:.1f} MB")
    elif info["kind"] == "npz":
        _say(f"{out}: the rest and the 52 shapes' positions, {mesh.n_vertices} vertices in the head's order"
             + (f" ({info['appended']} added by the cuts after the head's own; cut_copies and cut_corners say where)"
                if info["appended"] else ""))
    elif info["kind"] == "usd":
        _say(f"units: {info['units']} (metersPerUnit set, y up); {info['bytes'] / 1e6:.1f} MB")
    elif info["kind"] == "gltf-layout":
        _say(f"written into {name}'s own nodes, materials and vertices{added}; units as the file's; "
             f"{info['sparse']} of {info['accessors']} morph target accessors sparse (moves under "
             f"{SPARSE_TOLERANCE * 1e3:g} mm left out), {info['bytes'] / 1e6:.1f} MB")
        for n in info["notes"]:
            _say(f"{out}: {n}")
    else:
        _say(_units_line(float(np.ptp(mesh.vertices[:, 1])), info["units"], units) + "; "
             + _sparse_line(out, info, len(ARKIT_52)))


def cmd_blendshapes(a):
    """`mimica blendshapes`: the 52 ARKit blendshapes on any head mesh, as one GLB
    (pipeline.make_blendshapes).

    Parameters
    ----------
    a : argparse.Namespace
        The command's options (its add_args).

    Returns
    -------
    int
        The exit status (0: done).
    """
    from ..export import ARKIT_52
    from ..pipeline import BlendshapesOptions, make_blendshapes
    out = Path(a.out)
    if a.format and not out.suffix:                       # `--format usd --out head`: head.usd
        out = out.with_suffix("." + a.format)
    elif a.format and out.suffix.lower() != "." + a.format:
        raise MimicaError(f"--format {a.format} with --out {out}: say the format once (the suffix, or --format)")
    opts = BlendshapesOptions(landmarks=a.landmarks, cut_mouth=a.cut_mouth == "auto", cut_eyes=a.cut_eyes == "auto",
                              match=a.match, units=a.units, quantize=a.quantize)
    r = make_blendshapes(a.head, out, opts, progress=_say)
    shapes, name = r.shapes, Path(a.head).name
    if line := _correspondence_line(shapes.transfer).lstrip("; "):
        _say(line)
    _say_uncut_mouth(shapes.transfer, a.head, "--landmarks")
    _warn_sealed_eyes(shapes.transfer, r.head, shapes.landmarks, a.head,
                      found_flag="--landmarks" if r.landmarks_found else None)
    _say_written(out, r, a.units, Path(a.head).name)
    if a.show:
        from ..render import save_png
        from ..render.diagnose import transfer_picture
        save_png(a.show, transfer_picture(shapes.transfer, f"{name} as the transfer sees it"))
        _say(f"picture -> {a.show}")
    _say(f"{out}: {len(ARKIT_52)} ARKit morph targets on {shapes.mesh.n_vertices} vertices "
         f"({r.seconds:.1f}s; tongueOut stays at rest: ICT-FaceKit has no tongue shape)")
    return 0


def add_args(sub) -> None:
    """Put `mimica blendshapes` and its options on the `mimica` parser.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The parser's commands (ArgumentParser.add_subparsers).
    """
    bs = sub.add_parser("blendshapes", help="the 52 ARKit blendshapes on any head mesh, as one GLB")
    bs.add_argument("head", help="head mesh (OBJ/PLY/glTF), any topology, neutral")
    bs.add_argument("--landmarks", help="68-point landmark JSON (found automatically otherwise)")
    _head_options(bs, "head")
    bs.add_argument("-o", "--out", required=True, help="head_arkit.glb (or .usd/.usda/.usdc: UsdSkel blend shapes)")
    bs.add_argument("--units", choices=["auto", "cm", "mm", "m"], default=D.units, help=UNITS_HELP)
    bs.add_argument("--quantize", action="store_true", help=QUANTIZE_HELP)
    bs.add_argument("--format", choices=FILE_FORMATS + ("npz",), help="the file's kind, where --out has no suffix")
    bs.set_defaults(func=cmd_blendshapes)


run = cmd_blendshapes
