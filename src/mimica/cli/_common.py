"""What the commands share: progress, messages, option helps and parsers."""

from __future__ import annotations

import contextlib
import sys
from pathlib import Path

from ..errors import MimicaError


def _progress(iterable, total=None, desc=""):
    from tqdm import tqdm
    return tqdm(iterable, total=total, desc=desc, disable=not sys.stderr.isatty(), leave=False,
                unit="frame")


@contextlib.contextmanager
def _muscle_bar(desc):
    """A progress bar over the muscles' systems: yields progress(k, n, name)."""
    bar = _progress(range(1), 1, desc)

    def progress(k, n, name):                   # k of the n made
        bar.total = n
        bar.set_postfix_str(name)
        bar.update(k - bar.n)
    try:
        yield progress
    finally:
        bar.close()


@contextlib.contextmanager
def _bar(desc):
    """A progress bar for a progress(done, total) callback: yields the callback."""
    bar = _progress(range(1), None, desc)

    def progress(k, n):
        bar.total = n
        bar.update(1)
    try:
        yield progress
    finally:
        bar.close()


def _landmarks(mesh, path, flag, what):
    """A face's landmarks (landmarks_for); where none are found, the flag that gives them."""
    from ..landmarks import landmarks_for
    from ..errors import NeedsLandmarks
    try:
        return landmarks_for(mesh, path, what)
    except NeedsLandmarks as e:
        raise MimicaError(f"{e}; pass it with {flag} FILE") from None


QUANTIZE_HELP = ("glTF: morph targets as 16-bit moves and 8-bit normal changes (KHR_mesh_quantization, "
                 "within 0.015 mm; about half the size; the viewer must know the extension: three.js, "
                 "Blender and Babylon.js do)")


UNITS_HELP = ("the unit of the input's coordinates; glTF files are in metres (auto: a head up to 3 units "
              "tall is in metres, up to 100 in cm, taller in mm)")


MATCH_HELP = ("across topologies, how target vertices find their source partners: nicp, a non-rigid "
              "registration of the source onto the target (default); cylinder, Song et al.'s cylinder map")


DETECTOR_HELP = ("photos: the 68 points' detector: mediapipe (default: MediaPipe's face mesh at 68 of its points) "
                 "or dlib (its 68-point predictor); compared in docs/benchmarks.md")


FILE_FORMATS = ("glb", "gltf", "usd", "usda", "usdc")     # --format naming one file's kind


def _clip_how(info: dict) -> str:
    """'120 frames as 9 basis shapes and their weights (largest error ...)'."""
    n = info["frames"]
    if info["basis"]:
        how = (f"{n} frames as {info['shapes']} basis {'blend ' if info['format'] == 'usd' else ''}shapes and their weights "
               f"(largest error {info['max_error_m'] * 1e3:.3f} mm, bound 0.1 mm)")
    else:
        how = f"{n} frames as " + ("blend shapes" if info["format"] == "usd" else "morph targets" + (
            " (no smaller basis within 0.1 mm)" if info.get("compact") else ""))
    return how


def _quantized_line(info: dict) -> str:
    """'52 quantized (KHR_mesh_quantization, moves within 0.015 mm), ' or nothing."""
    from ..mesh.io import QUANTIZATION, QUANTIZE_ERROR
    return (f"{info['quantized']} quantized ({QUANTIZATION}, moves within {QUANTIZE_ERROR * 1e3:.3f} mm), "
            if info.get("quantized") else "")


def _units_line(height: float, unit: str, asked: str) -> str:
    """'units: cm (the head is 33.4 units tall; --units to say otherwise), written in metres'."""
    how = (f"the head is {height:.3g} units tall; --units to say otherwise"
           if asked == "auto" else "as --units says")
    return f"units: {unit} ({how}), written in metres as glTF wants"


def _say(msg):
    print(msg, file=sys.stderr)


def _expand_frames(items):
    from ..mesh.io import sequence_files
    out = []
    for it in items:
        p = Path(it)
        if p.is_dir():
            files, other = sequence_files(p)
            if other:                                  # said: a previous run's animation.glb ...
                _say(f"{p}: its {len(files)} {files[0].suffix.lower()} files are the frames; left out "
                     + (", ".join(other[:3]) + (f" and {len(other) - 3} more" if len(other) > 3 else "")))
            out += files
        else:
            out.append(p)
    return out
