"""Transfer a sequence (Song et al.): source neutral S and its expressions S'_i, target neutral
T -> T'_i, written as files.  `prepare_transfer` builds the (S, T) transfer once -- the
correspondence and the factorization -- so that a caller with many sequences for one pair (the
batch runner) reuses it; `transfer_sequence` is the whole job."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import MimicaError, NeedsLandmarks
from ..mesh import Mesh


@dataclass(frozen=True)
class TransferOptions:
    """How a sequence is transferred; each default is the one every user of it gets.

    Attributes
    ----------
    method : str
        "vtc" (Song et al.'s vertex-tent coordinates) or "dt" (Sumner and Popović's deformation
        transfer).
    match : str
        Across topologies, how the target's vertices find their source partners: "nicp" or
        "cylinder".
    cut_mouth, cut_eyes : bool
        Cut a target's sealed lips apart, and eyes that are one surface with their lids loose
        from them (transfer.ExpressionTransfer).
    """
    method: str = "vtc"
    match: str = "nicp"
    cut_mouth: bool = True
    cut_eyes: bool = True

    def settings(self):
        """The transfer.TransferSettings these options ask for (the others at their defaults)."""
        from ..transfer import TransferSettings
        return TransferSettings(method=self.method, match=self.match, cut_mouth=self.cut_mouth,
                                cut_eyes=self.cut_eyes)


@dataclass
class TransferResult:
    """What `transfer_sequence` made.

    Attributes
    ----------
    out : Path
        The folder written (whole, or not at all).
    files : list of Path
        The results in it, one per source expression, named as they were (a glTF target's
        results as its own kind of file).
    transfer : ExpressionTransfer
        The transfer (its correspondence, parts, cuts and reports).
    target : Mesh
        The target as read (`layout`: the file it came from, and what reading it noted).
    target_landmarks : Landmarks or None
        Its landmarks as used (None on one topology without any given).
    target_landmarks_found : bool
        The target's landmarks were found on renders (neither given nor built in).
    seconds : dict
        {"read", "precompute", "transfer", "write"}: wall time of each step.
    """
    out: Path
    files: list
    transfer: object
    target: Mesh
    target_landmarks: object
    target_landmarks_found: bool
    seconds: dict = field(default_factory=dict)


def read_sequence(paths, source: Mesh, progress=None) -> np.ndarray:
    """Expression meshes of the source's topology, (F, n, 3) float64.

    Parameters
    ----------
    paths : list of str or Path
        One mesh file per expression.  Two of one file name are refused (their results would
        overwrite each other).
    source : Mesh
        The source neutral, (n, 3) vertices.
    progress : callable, optional
        Called with (done, total) as files are read.
    """
    from ..mesh import read_vertices
    names = [Path(p).name for p in paths]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise MimicaError(f"{dup[0]}: two source expressions share this file name; outputs would overwrite each other")
    frames = np.empty((len(paths), source.n_vertices, 3))
    for i, p in enumerate(paths):
        v = read_vertices(p)
        if len(v) != source.n_vertices:
            raise MimicaError(f"{p}: has {len(v)} vertices but the source neutral has "
                              f"{source.n_vertices}; an expression must share the neutral's topology")
        frames[i] = v
        if progress is not None:
            progress(i + 1, len(paths))
    return frames


def prepare_transfer(source: Mesh, target: Mesh, frames: np.ndarray, options: TransferOptions | None = None,
                     source_landmarks=None, target_landmarks=None, what=("source", "target")):
    """The (source, target) ExpressionTransfer for these frames (their static vertices).

    Parameters
    ----------
    source, target : Mesh
        The source neutral (n_S vertices) and the target neutral (n_T vertices).
    frames : (F, n_S, 3) array
        The source expressions (their still vertices are held still on the target).
    options : TransferOptions, optional
    source_landmarks, target_landmarks : str or Path or Landmarks or None
        Landmark files or Landmarks; None: built in for ICT-FaceKit's topology, else found on
        renders -- needed only across topologies (or where either is given).
    what : (str, str)
        How errors name the two meshes.

    Returns
    -------
    (ExpressionTransfer, Landmarks or None, bool)
        The transfer, the target's landmarks (None on one topology without any given), and
        whether they were found on renders.
    """
    from ..data import is_ict_topology
    from ..landmarks import Landmarks, landmarks_for
    from ..transfer import ExpressionTransfer, static_vertices
    o = options or TransferOptions()

    def marks(mesh, given, name, which):
        if isinstance(given, Landmarks):
            return given
        try:
            return landmarks_for(mesh, given, name)
        except NeedsLandmarks as e:
            e.which = which
            raise
    ls = lt = None
    found = False
    if not source.same_topology(target) or source_landmarks is not None or target_landmarks is not None:
        ls = marks(source, source_landmarks, what[0], "source")
        lt = marks(target, target_landmarks, what[1], "target")
        found = target_landmarks is None and not is_ict_topology(target)
    xfer = ExpressionTransfer(source, target, ls, lt, o.settings(), static=static_vertices(source.vertices, frames))
    return xfer, lt, found


def result_names(names, target: Mesh, target_path=None) -> list[str]:
    """The results' file names: the source expressions' own, or, for a target read from glTF (written
    back into its own file), with the target's suffix.

    Parameters
    ----------
    names : list of str
        The source expressions' file names.
    target : Mesh
    target_path : str or Path or None

    Returns
    -------
    list of str
    """
    from ..mesh.io import GltfLayout
    if isinstance(target.layout, GltfLayout) and target_path is not None:
        suffix = Path(target_path).suffix.lower()
        return [str(Path(n).with_suffix(suffix)) for n in names]
    return [str(n) for n in names]


def write_results(out, names, mesh: Mesh, results: np.ndarray, about: dict | None = None) -> list[Path]:
    """Each result as the mesh with those vertices, into a folder written whole beside it and then put
    in its place (a failure leaves no half-written folder).

    Parameters
    ----------
    out : str or Path
        The folder.
    names : list of str
        A file name a result (its suffix chooses the format).
    mesh : Mesh
    results : (F, n, 3) float array
    about : dict or None
        Recorded in the folder's .mimica-run.json.

    Returns
    -------
    list of Path
    """
    from ..mesh import write_mesh
    from ..outputs import staged_dir
    with staged_dir(out, about or {"command": "transfer"}) as d:
        for name, v in zip(names, results):
            write_mesh(d / name, mesh.with_vertices(v))
    return [Path(out) / n for n in names]


def transfer_sequence(source, expressions, target, out, options: TransferOptions | None = None,
                      source_landmarks=None, target_landmarks=None, progress=None) -> TransferResult:
    """Transfer a sequence of expressions onto a target and write them.

    Parameters
    ----------
    source : str or Path or Mesh
        The source neutral.
    expressions : list of str or Path
        The source's expressions, one mesh file each (its topology).
    target : str or Path or Mesh
        The target neutral (any topology; glTF and FBX heads are read whole).
    out : str or Path
        The folder to write the results into.
    options : TransferOptions, optional
    source_landmarks, target_landmarks : str or Path or Landmarks or None
        See `prepare_transfer`.
    progress : callable, optional
        Called with one line of text at each step (and with what reading the target noted).

    Returns
    -------
    TransferResult
    """
    from ..mesh import read_mesh
    from ..outputs import check_output_dir
    say = progress or (lambda m: None)
    check_output_dir(out)                       # a folder it may not replace: said before the work
    t0 = time.perf_counter()
    src = source if isinstance(source, Mesh) else read_mesh(source)
    tgt = target if isinstance(target, Mesh) else read_mesh(target)
    what = (tgt.name or "the target") if isinstance(target, Mesh) else target
    for note in (tgt.layout.notes if tgt.layout is not None else []):
        say(f"{what}: {note}")
    paths = [Path(p) for p in expressions]
    frames = read_sequence(paths, src)
    t1 = time.perf_counter()
    src_what = (src.name or "the source") if isinstance(source, Mesh) else str(source)
    xfer, lt, found = prepare_transfer(src, tgt, frames, options, source_landmarks, target_landmarks,
                                       what=(src_what, str(what)))
    t2 = time.perf_counter()
    results = xfer.apply(frames)            # through the sequence's basis where it holds (apply's rule)
    t3 = time.perf_counter()
    names = result_names([p.name for p in paths], tgt, None if isinstance(target, Mesh) else target)
    files = write_results(out, names, xfer.output_mesh, results)
    t4 = time.perf_counter()
    return TransferResult(Path(out), files, xfer, tgt, lt, found,
                          {"read": t1 - t0, "precompute": t2 - t1, "transfer": t3 - t2, "write": t4 - t3})
