"""One job of a batch, run in a worker process (a local pool's or a Ray actor's).

A worker keeps what its jobs share in memory for its whole life: a head's
landmarks (detected once, also kept in the batch's cache folder), the meshes and frames it has
read, and every ExpressionTransfer it has built -- the correspondence and the factorization of
a (source neutral, head) pair -- so that all the performances of one source onto one head pay
for it once.  The scheduler sends all the jobs of a head to the same worker.  Every kind runs
in-process through the pipeline (mimica.pipeline), as the command line does, so a batch's
outputs are the commands' outputs.
"""

from __future__ import annotations

import hashlib
import json
import time
from pathlib import Path

import numpy as np

from ..errors import MimicaError
from .manifest import FileHashes, Job, environment, frame_files

_hashes = FileHashes(None)
_meshes: dict = {}
_frames: dict = {}
_transfers: dict = {}
_source_landmarks: dict = {}
CACHE_TRANSFERS = 8                 # ExpressionTransfers a worker keeps (oldest dropped first)


def watch_parent(pid: int) -> None:
    """In a local pool's worker: leave as soon as the batch that started it is gone (killed with
    SIGKILL it cannot stop its workers, which would wait for jobs forever).

    Parameters
    ----------
    pid : int
        The batch's process.
    """
    import os
    import threading

    def watch():
        while os.getppid() == pid:
            time.sleep(0.5)
        os._exit(1)
    threading.Thread(target=watch, daemon=True, name="mimica-batch-parent").start()


def marker_path(root: Path, job_id: str) -> Path:
    """Where a job's done-marker lives in the batch's folder.

    Parameters
    ----------
    root : Path
        The batch's folder.
    job_id : str

    Returns
    -------
    Path
    """
    return root / ".batch" / "done" / (job_id.replace("/", "__") + ".json")


def run_job(job: dict, root: str) -> dict:
    """Run one job in-process through the pipeline; its outputs are written whole, then its marker.

    Parameters
    ----------
    job : dict
        Job.to_dict(), with its upstream outputs under "inputs".
    root : str
        The batch's folder.

    Returns
    -------
    dict
        Its record: status done or failed, the one line of a failure, seconds, where it ran, what
        it said.
    """
    from .._memory import keep_memory
    keep_memory()                                  # a worker is mimica's process, as the command line's
    root = Path(root)
    t = time.perf_counter()
    said: list[str] = []
    rec = {"id": job["id"], "key": job["key"], **environment()}
    _hashes.known.update(job.get("hashes", {}))        # the plan's, still checked by size and time
    try:
        j = Job.from_dict(job)
        out = j.outputs(root)
        _RUN[j.kind](j, root, out, [Path(p) for p in job.get("inputs", [])], said)
        rec.update(status="done", seconds=round(time.perf_counter() - t, 3), said=said[-20:])
        from ..outputs import atomic_path
        with atomic_path(marker_path(root, j.id)) as tmp:
            tmp.write_text(json.dumps({**rec, "output": str(out), "finished": time.time()}, indent=1))
        return rec
    except MimicaError as e:
        rec.update(status="failed", error=" ".join(str(e).split()))
    except Exception as e:                      # a bug, not the user's input: said as such
        rec.update(status="failed", error=f"internal error: {type(e).__name__}: {' '.join(str(e).split())}")
    rec.update(seconds=round(time.perf_counter() - t, 3), said=said[-20:])
    return rec


def _head_mesh(job: Job):
    k = _hashes.of(job.head.mesh)
    if k not in _meshes:
        from ..mesh import read_mesh
        if len(_meshes) > 16:                      # a worker holds a few heads at a time
            _meshes.clear()
        _meshes[k] = read_mesh(job.head.mesh)
    return _meshes[k], k


def _landmark_file(job: Job, root: Path) -> Path | None:
    """The head's landmark file: the manifest's, else the one detected once for this head in the
    batch's cache (None for ICT-FaceKit's topology: built in)."""
    if job.head.landmarks is not None:
        return job.head.landmarks
    mesh, k = _head_mesh(job)
    from ..data import is_ict_topology
    from ..landmarks import landmarks_for, write_landmarks
    if is_ict_topology(mesh):
        return None
    p = root / ".batch" / "cache" / f"{k[:24]}.landmarks.json"
    if not p.is_file():
        lm = landmarks_for(mesh, None, f"head {job.head.name} ({job.head.mesh})")
        write_landmarks(p, lm.positions(mesh))
    return p


def _blendshapes(job, root, out, inputs, said):
    from ..pipeline import BlendshapesOptions, make_blendshapes
    o = job.options
    opts = BlendshapesOptions(landmarks=_landmark_file(job, root), cut_mouth=o["cut_mouth"] == "auto",
                              cut_eyes=o["cut_eyes"] == "auto", match=o["match"], quantize=o["quantize"])
    mesh, _ = _head_mesh(job)
    r = make_blendshapes(mesh, out, opts, progress=said.append)
    said.append(f"{out}: 52 ARKit morph targets on {r.shapes.mesh.n_vertices} vertices")


def _transfer(job, root, out, inputs, said):
    """Song et al.'s transfer of a performance's frames onto the head; the (neutral, head) pair's
    ExpressionTransfer built once per worker and reused by every performance it fits."""
    from ..landmarks import landmarks_for
    from ..mesh import read_mesh
    from ..pipeline import TransferOptions, prepare_transfer, read_sequence, result_names, write_results
    from ..transfer import static_vertices
    o = job.options
    opts = TransferOptions(method=o["method"], match=o["match"], cut_mouth=o["cut_mouth"] == "auto",
                           cut_eyes=o["cut_eyes"] == "auto")
    perf = job.performance
    nk = _hashes.of(perf.files["neutral"])
    if nk not in _meshes:
        _meshes[nk] = read_mesh(perf.files["neutral"])
    source = _meshes[nk]
    files = frame_files(perf)
    fk = hashlib.sha256("".join(_hashes.of(f) for f in files).encode()).hexdigest()
    if fk not in _frames:
        if len(_frames) > 4:
            _frames.pop(next(iter(_frames)))
        _frames[fk] = read_sequence(files, source)
    frames = _frames[fk]
    target, hk = _head_mesh(job)
    static = static_vertices(source.vertices, frames)
    key = (nk, hk, str(job.head.landmarks), opts, hashlib.sha1(np.packbits(static).tobytes()).hexdigest())
    xfer = _transfers.get(key)
    if xfer is None:
        ls = lt = None
        if not source.same_topology(target) or job.head.landmarks is not None:
            if nk not in _source_landmarks:
                _source_landmarks[nk] = landmarks_for(source, None, f"performance {perf.name}'s neutral "
                                                                    f"({perf.files['neutral']})")
            ls = _source_landmarks[nk]
            lt = landmarks_for(target, _landmark_file(job, root), f"head {job.head.name} ({job.head.mesh})")
        xfer, _, _ = prepare_transfer(source, target, frames, opts, ls, lt)
        if len(_transfers) >= CACHE_TRANSFERS:
            _transfers.pop(next(iter(_transfers)))
        _transfers[key] = xfer
        said.append(f"{job.head.name}: correspondence and factorization made")
    else:
        said.append(f"{job.head.name}: correspondence and factorization reused")
    result = xfer.apply(frames)
    names = result_names([f.name for f in files], target, job.head.mesh)
    write_results(out, names, xfer.output_mesh, result, {"command": "batch transfer", "job": job.id})
    said.append(f"{len(files)} frames -> {out}")


def _animate(job, root, out, inputs, said):
    from ..pipeline import AnimateOptions, animate
    r = animate(inputs[0], out, take=job.performance.files["arkit"],
                options=AnimateOptions(head_rotation=job.options["head_rotation"]))
    said.append(f"{len(r.times)} frames drive {r.driven} morph targets -> {out}")


def _simulate(job, root, out, inputs, said):
    from ..pipeline import RigOptions, SimulateOptions, make_rig, simulate
    o = job.options
    mesh, hk = _head_mesh(job)
    rig = root / ".batch" / "cache" / f"{hk[:24]}-{o['muscles']}.rig"
    if not rig.is_file():                         # one rig per head and muscle set
        make_rig(mesh, _landmark_file(job, root), RigOptions(muscles=o["muscles"]), out=rig)   # saved whole
        said.append(f"rig ({o['muscles']}) made for {job.head.name}")
    r = simulate(rig, out, SimulateOptions(timeline=job.performance.files["timeline"], fps=o["fps"]))
    said.append(f"{r.frames} frames -> {out}")


def _age(job, root, out, inputs, said):
    from ..pipeline import AgeOptions, age_sheet
    o = job.options
    mesh, _ = _head_mesh(job)
    n = age_sheet(mesh, out, _landmark_file(job, root),
                  AgeOptions(ages=tuple(o["ages"]), expression=o["expression"], size=o["size"]))
    said.append(f"{n} renders -> {out}")


def _frames_of(folder: Path) -> list[Path]:
    """An upstream job's frames: the folder's meshes of its main format (mesh.io.sequence_files)."""
    from ..mesh.io import sequence_files
    return sequence_files(folder)[0] if Path(folder).is_dir() else [Path(folder)]


def _render(job, root, out, inputs, said):
    from ..pipeline import RenderOptions, render_sequence
    r = render_sequence(_frames_of(inputs[0]), out, RenderOptions(view=job.options["view"], size=job.options["size"]))
    said.append(f"{r['shown']} of {r['frames']} frames -> {out}")


def _export(job, root, out, inputs, said):
    from ..pipeline import ExportOptions, export_sequence
    r = export_sequence(_frames_of(inputs[0]), out, ExportOptions(fps=job.options["fps"]))
    said.append(f"{r['frames']} frames -> {out}")


_RUN = {"blendshapes": _blendshapes, "transfer": _transfer, "animate": _animate, "simulate": _simulate,
        "age": _age, "render": _render, "export": _export}
