"""`mimica export`: a sequence of meshes as one glTF animation, or as OBJ/PLY files."""

from __future__ import annotations

from pathlib import Path

from ..errors import MimicaError
from ._common import QUANTIZE_HELP, UNITS_HELP, FILE_FORMATS, _clip_how, _quantized_line, _units_line, _say, _expand_frames
from ..pipeline import ExportOptions as D


def _clip_line(info: dict, fps: float, units: str) -> str:
    """What export.clip.write_clip / write_clip_usd wrote, in one line."""
    how = _clip_how(info)
    if info["format"] == "usd":
        return (f"{how}, a SkelAnimation at {fps:g} fps; units: {info['unit']} (metersPerUnit "
                f"{info['metres_per_unit']:g}, y up); {info['bytes'] / 1e6:.1f} MB")
    return (f"{how}, one animation at {fps:g} fps; " + _units_line(info["height"], info["units"], units) + "; "
            + _quantized_line(info) + f"{info['bytes'] / 1e6:.1f} MB")


def cmd_export(a):
    """`mimica export`: a sequence of meshes as one glTF animation, or as OBJ/PLY files
    (pipeline.export_sequence).

    Parameters
    ----------
    a : argparse.Namespace
        The command's options (its add_args).

    Returns
    -------
    int
        The exit status (0: done).
    """
    from ..pipeline import ExportOptions, export_sequence
    paths = _expand_frames([Path(p) for p in a.frames])
    out = Path(a.out)
    suf = out.suffix.lower()
    fmt = a.format
    if not suf and a.format in FILE_FORMATS:             # `--format usd --out anim`: anim.usd
        out, suf = out.with_suffix("." + a.format), "." + a.format
    elif suf and a.format in FILE_FORMATS and suf != "." + a.format:
        raise MimicaError(f"--format {a.format} with --out {out}: say the format once (the suffix, or --format)")
    if not suf and fmt not in ("obj", "ply"):
        raise MimicaError(f"--format {a.format}: obj or ply for a folder, or {', '.join(FILE_FORMATS)} for one file")
    opts = ExportOptions(fps=a.fps, format=fmt if fmt in ("obj", "ply") else "obj", units=a.units,
                         compact=a.compact == "auto", quantize=a.quantize, rest=a.rest)
    r = export_sequence(paths, out, opts)
    if r["kind"] == "folder":
        _say(f"{out}/: {r['frames']} {opts.format.upper()} files")
    else:
        _say(f"{out}: " + _clip_line(r, a.fps, a.units))
    return 0


def add_args(sub) -> None:
    """Put `mimica export` and its options on the `mimica` parser.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The parser's commands (ArgumentParser.add_subparsers).
    """
    ex = sub.add_parser("export", help="a sequence of meshes as one glTF animation, or as OBJ/PLY files")
    ex.add_argument("frames", nargs="+", help="mesh files or a folder, one topology")
    ex.add_argument("-o", "--out", required=True, help="anim.glb / anim.gltf, anim.usd / .usda / .usdc (UsdSkel), or a folder")
    ex.add_argument("--rest", help="the rest mesh the morph targets are relative to (default: the first frame)")
    ex.add_argument("--fps", type=float, default=D.fps)
    ex.add_argument("--format", default=D.format, help="obj or ply, for a folder; glb, gltf, usd, usda or usdc "
                                                     "for one file (the same as --out's suffix)")
    ex.add_argument("--units", choices=["auto", "cm", "mm", "m"], default=D.units, help=UNITS_HELP)
    ex.add_argument("--compact", choices=["auto", "off"], default="auto",
                    help="auto: the clip as a few basis shapes and per-frame weights when that keeps every "
                         "vertex within 0.1 mm (far smaller files); off: one morph target per frame")
    ex.add_argument("--quantize", action="store_true", help=QUANTIZE_HELP)
    ex.set_defaults(func=cmd_export)


run = cmd_export
