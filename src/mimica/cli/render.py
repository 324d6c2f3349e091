"""`mimica render`: pictures and videos of a face or a sequence (no GPU needed)."""

from __future__ import annotations

from pathlib import Path

from ._common import _bar, _say, _expand_frames
from ..pipeline.sequence import RenderOptions as D, VIEW_CHOICES


def cmd_render(a):
    """`mimica render`: pictures and videos of a face or a sequence (pipeline.render_sequence).

    Parameters
    ----------
    a : argparse.Namespace
        The command's options (its add_args).

    Returns
    -------
    int
        The exit status (0: done).
    """
    from ..pipeline import RenderOptions, render_sequence
    src = Path(a.face)
    paths = _expand_frames([src]) if src.is_dir() else [src]
    opts = RenderOptions(view=a.view, turntable=a.turntable, size=a.size, frames=a.frames, fps=a.fps,
                         heatmap=a.heatmap)
    with _bar("rendering") as progress:
        r = render_sequence(paths, a.out, opts, progress=progress)
    if r["kind"] == "png":
        if r["shown"] < r["frames"] and not a.turntable:
            _say(f"{src}: {r['frames']} meshes; the sheet shows {r['shown']} of them, evenly spaced "
                 "(first and last included; an .mp4 output shows every one)")
        _say(f"{a.out} ({r['size'][0]}x{r['size'][1]}, {r['seconds']:.2f}s)")
    else:
        _say(f"{a.out}: {r['shown']} frames at {a.fps:g} fps in {r['seconds']:.1f}s")
    return 0


def add_args(sub) -> None:
    """Put `mimica render` and its options on the `mimica` parser.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The parser's commands (ArgumentParser.add_subparsers).
    """
    rd = sub.add_parser("render", help="pictures and videos of a face or a sequence (no GPU needed)")
    rd.add_argument("face", help="a mesh, or a folder of meshes (a sequence)")
    rd.add_argument("-o", "--out", required=True, help=".png (views, contact sheet) or .mp4 (sequence or turntable)")
    rd.add_argument("--view", choices=list(VIEW_CHOICES), default=D.view)
    rd.add_argument("--turntable", action="store_true", help="turn the face around (PNG: 8 angles; MP4: --frames)")
    rd.add_argument("--heatmap", metavar="VALUES", help="colour by per-vertex values (.npy, .txt) or by the "
                    "distance to a mesh of the same topology; a legend is added")
    rd.add_argument("--size", type=int, default=D.size, help="pixels per view")
    rd.add_argument("--frames", type=int, default=D.frames, help="turntable video length in frames")
    rd.add_argument("--fps", type=float, default=D.fps)
    rd.set_defaults(func=cmd_render)


run = cmd_render
