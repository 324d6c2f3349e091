"""A sequence of meshes of one topology (a transfer's or a simulation's frames): read it, export
it (one clip file, or a folder of OBJ/PLY) and render it (views, a contact sheet, a video)."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import MimicaError

CLIP_SUFFIXES = (".glb", ".gltf", ".usd", ".usda", ".usdc")


def read_mesh_sequence(paths, progress=None):
    """The first mesh and every file's vertices, (F, n, 3) float64, and the frames' names.

    Parameters
    ----------
    paths : list of str or Path
        Mesh files of one topology (a folder's files: mesh.io.sequence_files).
    progress : callable, optional
        Called as progress(done, total).
    """
    from ..mesh import read_mesh, read_vertices
    paths = [Path(p) for p in paths]
    if not paths:
        raise MimicaError("no meshes in the sequence")
    mesh = read_mesh(paths[0])
    frames = np.empty((len(paths), mesh.n_vertices, 3))
    for i, p in enumerate(paths):
        v = mesh.vertices if i == 0 else read_vertices(p)
        if len(v) != mesh.n_vertices:
            raise MimicaError(f"{p}: {len(v)} vertices; {paths[0]} has {mesh.n_vertices} (one topology per sequence)")
        frames[i] = v
        if progress is not None:
            progress(i + 1, len(paths))
    return mesh, frames, [p.stem for p in paths]


@dataclass(frozen=True)
class ExportOptions:
    """How a sequence is exported; each default is the one every user of it gets.

    Attributes
    ----------
    fps : float
        The clip's rate.
    format : str
        For a folder: "obj" or "ply".
    units : str
        The meshes' unit: "auto", "m", "cm", "mm".
    compact : bool
        A clip as a few basis shapes and weights where that keeps every vertex within 0.1 mm.
    quantize : bool
        glTF targets as 16-bit moves (KHR_mesh_quantization).
    rest : str or Path or None
        The rest mesh the clip's shapes are relative to (default: the first frame).
    """
    fps: float = 30.0
    format: str = "obj"
    units: str = "auto"
    compact: bool = True
    quantize: bool = False
    rest: str | Path | None = None


def export_sequence(paths, out, options: ExportOptions | None = None, progress=None) -> dict:
    """Export a sequence: one clip (out's suffix .glb, .gltf, .usd, .usda, .usdc) or a folder of
    `options.format` files (out without a suffix), written whole or not at all.

    Parameters
    ----------
    paths : list of str or Path
        The frames, one mesh file each, one topology.
    out : str or Path
        The clip file or the folder.
    options : ExportOptions, optional
    progress : callable, optional
        Called as progress(done, total) while the frames are read.

    Returns
    -------
    dict
        {"kind": "glb" | "usd" | "folder", "frames", and the clip writer's figures
        (export.clip) or "files"}.
    """
    from ..mesh import atomic_path, read_mesh, write_mesh
    o = options or ExportOptions()
    out = Path(out)
    suf = out.suffix.lower()
    if suf and suf not in CLIP_SUFFIXES:
        raise MimicaError(f"{out}: export to .glb/.gltf, .usd/.usda/.usdc, or to a folder (of obj or ply files)")
    if not suf and o.format not in ("obj", "ply"):
        raise MimicaError(f"format {o.format!r}: obj or ply for a folder, or a clip file (.glb, .gltf, .usd, "
                          ".usda, .usdc)")
    mesh, frames, names = read_mesh_sequence(paths, progress)
    if suf:
        base = read_mesh(o.rest) if o.rest is not None else mesh
        if base.n_vertices != mesh.n_vertices:
            raise MimicaError(f"{o.rest}: not the sequence's topology")
        if suf in (".usd", ".usda", ".usdc"):
            from ..export.clip import write_clip_usd
            return {"kind": "usd", **write_clip_usd(out, base, names, frames, o.fps, o.units, o.compact)}
        from ..export.clip import write_clip
        with atomic_path(out) as tmp:
            info = write_clip(tmp, base, names, frames, o.fps, o.units, o.compact, binary=suf == ".glb",
                              quantize=o.quantize)
        return {"kind": "glb", **info}
    from ..outputs import staged_dir
    with staged_dir(out, {"command": "export"}) as d:
        for name, f in zip(names, frames):
            write_mesh(d / f"{name}.{o.format}", mesh.with_vertices(f))
    return {"kind": "folder", "frames": len(frames), "files": [out / f"{n}.{o.format}" for n in names]}


VIEW_CHOICES = ("all", "front", "three-quarter", "profile")


@dataclass(frozen=True)
class RenderOptions:
    """How a mesh or a sequence is drawn; each default is the one every user of it gets.

    Attributes
    ----------
    view : str
        "all", "front", "three-quarter" or "profile".
    turntable : bool
        Turn the face around (a picture: 8 angles; a video: `frames` frames).
    size : int
        Pixels a view.
    frames : int
        A turntable video's length in frames.
    fps : float
        A video's rate.
    heatmap : str or Path or None
        Colour by per-vertex values (.npy, .txt) or by the distance to a mesh of the same
        topology.
    """
    view: str = "all"
    turntable: bool = False
    size: int = 512
    frames: int = 120
    fps: float = 30.0
    heatmap: str | Path | None = None


def read_values(path, n: int):
    """Per-vertex values for a picture: from .npy, a text file (one number a line), or a mesh of the
    same topology.

    Parameters
    ----------
    path : str or Path
    n : int
        The mesh's vertices.

    Returns
    -------
    path : Path
    values : (n,) or (n, 3) float array
        Values, or positions (a mesh).
    """
    from ..mesh import MESH_SUFFIXES, read_vertices
    p = Path(path)
    if not p.is_file():
        raise MimicaError(f"{p}: no such file (per-vertex values)")
    if p.suffix.lower() in MESH_SUFFIXES:
        return p, read_vertices(p)
    try:
        vals = np.load(p) if p.suffix.lower() == ".npy" else np.loadtxt(p, ndmin=1)
    except (OSError, ValueError) as e:
        raise MimicaError(f"{p}: not a list of numbers ({e.__class__.__name__}); per-vertex values are .npy, .txt "
                          f"(one value per vertex) or a mesh of the same topology") from None
    vals = np.asarray(vals, float).ravel()
    if len(vals) != n or not np.isfinite(vals).all():
        raise MimicaError(f"{p}: {len(vals)} values{'' if np.isfinite(vals).all() else ' (some not finite)'}; "
                          f"the mesh has {n} vertices")
    return p, vals


def render_sequence(paths, out, options: RenderOptions | None = None, progress=None) -> dict:
    """Draw a mesh (one path) or a sequence into a PNG (views, turntable, or a contact sheet of up
    to 12 evenly spaced frames) or an MP4 (every frame, or a turntable).

    Parameters
    ----------
    paths : list of str or Path
        One mesh, or the frames of a sequence (one topology).
    out : str or Path
        .png or .mp4.
    options : RenderOptions, optional
    progress : callable, optional
        Called as progress(done, total) while a video's frames are drawn.

    Returns
    -------
    dict
        {"kind": "png" | "mp4", "frames": meshes read, "shown": frames shown, "size": (w, h) of a
        picture, "seconds"}.
    """
    from ..render import (VIEWS, contact_sheet, heat_colors, render_mesh, render_views, save_png,
                          turntable_angles, with_legend)
    from ..render.shots import shared_frame_all_views
    o = options or RenderOptions()
    out = Path(out)
    kind = out.suffix.lower()
    if kind not in (".png", ".mp4"):
        raise MimicaError(f"{out}: the output is a .png picture or an .mp4 video")
    if o.view not in VIEW_CHOICES:
        raise MimicaError(f"view {o.view!r}: one of {', '.join(VIEW_CHOICES)}")
    views = list(VIEWS) if o.view == "all" else [o.view]
    t0 = time.perf_counter()
    mesh, frames, names = read_mesh_sequence(paths)
    colors = legend = None
    if o.heatmap is not None:
        hp, vals = read_values(o.heatmap, mesh.n_vertices)
        if vals.ndim == 2:
            if len(vals) != mesh.n_vertices:
                raise MimicaError(f"{hp}: {len(vals)} vertices; the mesh has {mesh.n_vertices}")
            vals = np.linalg.norm(vals - frames[0], axis=1)
            label = f"distance to {hp.name}"
        else:
            label = hp.name
        vmax = float(np.max(vals)) if np.max(vals) > 0 else 1.0
        colors, legend = heat_colors(np.clip(vals, 0, None)), (0.0, vmax, label)
    frame = shared_frame_all_views(frames.reshape(-1, 3), views if not o.turntable else
                                   [(y, 0.0) for y in turntable_angles(8)])
    size = o.size
    if kind == ".png":
        shown = 1
        if o.turntable:
            tiles = [render_mesh(mesh, frames[0], size=(size, size), yaw=y, frame=frame, colors=colors)
                     for y in turntable_angles(8)]
            img = contact_sheet(tiles, labels=[f"{y:.0f}°" for y in turntable_angles(8)], columns=4)
        elif len(frames) == 1:
            tiles = render_views(mesh, frames[0], views, size, colors, frame)
            img = tiles[0] if len(tiles) == 1 else contact_sheet(tiles, labels=views)
        else:
            pick = np.unique(np.linspace(0, len(frames) - 1, min(len(frames), 12)).round().astype(int))
            shown = len(pick)
            tiles = [render_mesh(mesh, frames[i], size=(size, size), yaw=VIEWS[views[0]][0], frame=frame,
                                 colors=colors) for i in pick]
            img = contact_sheet(tiles, labels=[names[i] for i in pick], columns=min(len(pick), 4))
        if legend:
            img = with_legend(img, *legend)
        save_png(out, img)
        return {"kind": "png", "frames": len(frames), "shown": shown, "size": (img.shape[1], img.shape[0]),
                "seconds": time.perf_counter() - t0}
    from ..image.video import VideoWriter
    yaw0 = VIEWS[views[0]][0]
    jobs = ([(frames[0], y) for y in turntable_angles(o.frames)] if o.turntable or len(frames) == 1
            else [(f, yaw0) for f in frames])
    with VideoWriter(out, o.fps) as vw:
        for k, (v, yaw) in enumerate(jobs):
            img = render_mesh(mesh, v, size=(size, size), yaw=yaw, frame=frame, colors=colors)
            vw.write((with_legend(img, *legend) if legend else img) / 255.0)
            if progress is not None:
                progress(k + 1, len(jobs))
    return {"kind": "mp4", "frames": len(frames), "shown": len(jobs), "size": (size, size),
            "seconds": time.perf_counter() - t0}
