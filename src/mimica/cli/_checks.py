"""Checks of every command's arguments before any work: numbers in range, no output that destroys an input."""

from __future__ import annotations

from pathlib import Path


from ..validate import number_in


# options that name what a command writes; every other path-like argument is an input
OUTPUT_OPTIONS = ("out", "show")


def _writes_folder(a) -> bool:
    """Whether --out is a folder (replaced whole when the run completes) or one file."""
    suffix = Path(a.out).suffix.lower()
    return (a.cmd in ("transfer", "simulate", "demo")
            or (a.cmd == "transfer-image" and suffix != ".mp4")
            or (a.cmd == "export" and suffix not in (".glb", ".gltf")))


def _inputs(a) -> list[Path]:
    """Every argument that names an existing file or folder and is not an output."""
    found = []
    for k, v in vars(a).items():
        if k in OUTPUT_OPTIONS or k == "func":
            continue
        for x in v if isinstance(v, list) else [v]:
            if isinstance(x, str) and x and "\0" not in x:
                try:
                    if Path(x).exists():
                        found.append(Path(x))
                except (OSError, ValueError):
                    pass
    return found


# numeric options: (command, option) -> (low, high, integer?); NaN and infinities never pass
LIMITS = {
    ("simulate", "fps"): (1.0, 1000.0, False), ("simulate", "duration"): (1e-3, 3600.0, False),
    ("simulate", "age"): (0.0, 150.0, False), ("simulate", "gravity"): (-1e4, 1e4, False),
    ("simulate", "maps"): (16, 8192, True),
    ("rig", "alpha"): (1e-3, 1e3, False), ("rig", "modes"): (1, 200, True),
    ("render", "size"): (16, 4096, True), ("render", "frames"): (1, 100_000, True),
    ("render", "fps"): (0.1, 240.0, False),
    ("export", "fps"): (0.1, 1000.0, False),
    ("age", "size"): (16, 4096, True),
    ("batch", "workers"): (1, 256, True), ("batch", "retry"): (0, 100, True),
}


def check_numbers(a) -> None:
    """Every numeric option finite and in its range, before any work."""
    for (cmd, opt), (lo, hi, integer) in LIMITS.items():
        v = getattr(a, opt, None) if a.cmd == cmd else None
        if v is not None:
            number_in(v, lo, hi, "--" + opt.replace("_", "-"), integer)


def check_paths(a) -> None:
    """Before any work: no output may destroy an input; a folder output must be replaceable."""
    from ..outputs import check_output_dir, guard_outputs
    outs = []
    if getattr(a, "out", None):
        outs.append((a.out, _writes_folder(a)))
    if getattr(a, "show", None):
        outs.append((a.show, False))
    guard_outputs(_inputs(a), outs)
    for o, folder in outs:
        if folder:
            check_output_dir(o)
