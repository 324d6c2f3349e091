"""Batches at studio scale: many heads x many performances, on this machine's
cores or a Ray cluster.

    report = run_batch("jobs.toml", "out/", workers=2)          # or ray="auto" / "host:port"
    state = batch_status("out/")                                 # the folder alone: done, pending, failed

The manifest (batch.manifest) becomes a plan of jobs, each keyed by a hash of its inputs'
contents and its options; a job whose key matches a finished one's in the folder is skipped,
so a rerun does only what changed.  All the jobs of one head go to one worker, in order, so
the head's landmarks, its correspondences and factorizations are made once and kept
(batch.work).  A bad input fails its own jobs (and those that read their results) with the
usual one-line error and the rest go on; a worker that dies has its job retried on a fresh
one (`retry` times).  Each finished job's outputs are written atomically, then its marker
(.batch/done/), so a killed batch loses no finished job.  The end writes batch.json: every
job's status, time, machine and error.

Engines: a local pool of single-process workers (concurrent.futures, one process each so a
worker keeps its head's state), or Ray actors (`pip install 'mimica[ray]'`), which fit a
worker that keeps state; the scheduling is the same for both.
"""

from __future__ import annotations

import json
import os
import time
from collections import deque
from concurrent.futures import FIRST_COMPLETED, wait
from pathlib import Path

from ..errors import MimicaError
from ..parallel import cores
from .manifest import FileHashes, Job, key_jobs, plan
from .work import marker_path, run_job, watch_parent

__all__ = ["run_batch", "batch_status", "plan"]

META = ".batch"


def _check_out(out: Path) -> None:
    """The batch's folder: new, empty, or a batch's own (it holds .batch/); never a folder of
    the user's files."""
    if out.exists() and not out.is_dir():
        raise MimicaError(f"{out}: is a file; name a folder for the batch's outputs")
    if out.is_dir() and any(out.iterdir()) and not (out / META).is_dir():
        raise MimicaError(f"{out}: holds files of its own and no earlier batch; name a new or empty folder")


def _inputs_inside(jobs: list[Job], out: Path) -> None:
    o = out.resolve()
    for j in jobs:
        for p in j.input_files():
            if p.resolve() == o or o in p.resolve().parents:
                raise MimicaError(f"{p}: an input lies inside the batch's output folder {out}; "
                                  "choose another --out")


def _done(job: Job, out: Path) -> bool:
    m = marker_path(out, job.id)
    try:
        rec = json.loads(m.read_text())
    except (OSError, ValueError):
        return False
    return rec.get("key") == job.key and job.outputs(out).exists()


class LocalEngine:
    """Jobs in `workers` local processes, each its own single-process pool: jobs sent to worker w
    always run in the same process (and find its caches) until it dies.

    Parameters
    ----------
    workers : int
    """

    def __init__(self, workers: int):
        import multiprocessing as mp
        self.n = workers
        self.ctx = mp.get_context("spawn")          # no fork of a parent holding BLAS threads
        self.pools = [None] * workers
        self.name = f"local pool of {workers}"

    def _pool(self, w):
        from concurrent.futures import ProcessPoolExecutor
        if self.pools[w] is None:
            self.pools[w] = ProcessPoolExecutor(1, mp_context=self.ctx, initializer=watch_parent,
                                                initargs=(os.getpid(),))
        return self.pools[w]

    def submit(self, w, job: dict, root: str):
        return self._pool(w).submit(run_job, job, root)

    @staticmethod
    def died(exc) -> bool:
        from concurrent.futures.process import BrokenProcessPool
        return isinstance(exc, BrokenProcessPool)

    def restart(self, w, kill=False):
        """A fresh process for worker w from its next job on; kill: stop the running one now."""
        pool = self.pools[w]
        if pool is not None:
            if kill:
                for proc in list(getattr(pool, "_processes", {}).values()):
                    proc.kill()
            pool.shutdown(wait=False, cancel_futures=True)
        self.pools[w] = None

    def close(self):
        for p in self.pools:
            if p is not None:
                p.shutdown(wait=True, cancel_futures=True)


class RayEngine:
    """Jobs on Ray actors, one per worker.

    Parameters
    ----------
    workers : int
    address : str
        A Ray cluster's address; "auto" joins a running cluster or starts a local one.
    """

    def __init__(self, workers: int, address: str):
        from .._extras import require
        ray = require("ray", "ray", "running a batch on Ray")
        self.ray = ray
        if not ray.is_initialized():
            if address == "auto":
                try:
                    ray.init(address="auto", include_dashboard=False, log_to_driver=False)
                except (ConnectionError, RuntimeError):
                    ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False)
            else:
                try:
                    ray.init(address=address, include_dashboard=False, log_to_driver=False)
                except (ConnectionError, RuntimeError, ValueError) as e:
                    raise MimicaError(f"--ray {address}: cannot reach the Ray cluster ({' '.join(str(e).split())[:200]})") from None

        @ray.remote(num_cpus=1, max_restarts=0)
        class _Worker:
            def run(self, job, root):
                return run_job(job, root)

        self.cls = _Worker
        self.n = workers
        self.actors = [None] * workers
        self.name = f"Ray ({workers} actors)"

    def submit(self, w, job: dict, root: str):
        if self.actors[w] is None:
            self.actors[w] = self.cls.remote()
        return self.actors[w].run.remote(job, root).future()

    def died(self, exc) -> bool:
        return isinstance(exc, (self.ray.exceptions.RayActorError, self.ray.exceptions.WorkerCrashedError))

    def restart(self, w, kill=False):
        if self.actors[w] is not None:
            try:
                self.ray.kill(self.actors[w])
            except Exception:              # already gone
                pass
        self.actors[w] = None

    def close(self):
        for a in self.actors:
            if a is not None:
                self.ray.kill(a)


def run_batch(manifest, out, workers: int | None = None, ray: str | None = None, retry: int = 2,
              progress=None) -> dict:
    """Run a manifest's jobs into a folder, in-process through the pipeline; a job whose inputs and
    options have not changed since it last succeeded is not run again.

    Parameters
    ----------
    manifest : str or Path
        The manifest (TOML).
    out : str or Path
        The batch's folder.
    workers : int or None
        Processes (1 to 256; None: the CPU count).
    ray : str or None
        A Ray cluster's address to run on instead ("auto": join or start one).
    retry : int
        Times a job whose worker died is tried again.
    progress : callable, optional
        Called with {"done": k, "total": n, "job": id, "status": ...} once at the start (status
        "started", done 0) and as jobs finish.

    Returns
    -------
    dict
        The report, also written to out/batch.json.
    """
    out = Path(out)
    if workers is not None and not 1 <= workers <= 256:
        raise MimicaError(f"--workers {workers}: expected 1 to 256")
    if not 0 <= retry <= 100:
        raise MimicaError(f"--retry {retry}: expected 0 to 100")
    jobs = plan(manifest)
    if ray:                                         # a missing extra: said before anything is written
        from .._extras import require
        require("ray", "ray", "running a batch on Ray")
    _check_out(out)
    _inputs_inside(jobs, out)
    meta = out / META
    try:
        (meta / "done").mkdir(parents=True, exist_ok=True)
        (meta / "cache").mkdir(exist_ok=True)
    except OSError as e:
        from ..outputs import os_error
        raise os_error(out, e) from None
    hashes = FileHashes(meta / "hashes.json")
    key_jobs(jobs, hashes)
    hashes.save()
    t0 = time.time()
    records: dict[str, dict] = {}
    todo = []
    for j in jobs:
        if _done(j, out):
            records[j.id] = {"id": j.id, "key": j.key, "status": "skipped", "seconds": 0.0}
        else:
            todo.append(j)
    _write_json(meta / "plan.json", {"manifest": str(Path(manifest).resolve()), "planned": t0,
                                     "jobs": [{"id": j.id, "key": j.key, "kind": j.kind, "after": j.after,
                                               "output": str(j.outputs(out))} for j in jobs]})
    workers = workers or cores()
    by_id = {j.id: j for j in jobs}
    groups: dict[str, deque] = {}
    for j in todo:                                  # a head's jobs, in the plan's order
        groups.setdefault(j.head.name, deque()).append(j)
    engine = None
    if todo:
        n = min(workers, len(groups))
        engine = RayEngine(n, ray) if ray else LocalEngine(n)
    total = len(todo)
    finished = 0
    if progress:
        progress({"done": 0, "total": total, "job": "", "status": "started"})

    def record(job: Job, rec: dict):
        nonlocal finished
        records[job.id] = rec
        finished += 1
        if progress:
            progress({"done": finished, "total": total, "job": job.id, "status": rec["status"]})

    def failed_upstream(job: Job):
        for a in job.after:
            if records.get(a, {}).get("status") == "failed":
                return a
        return None

    attempts: dict[str, int] = {}
    queue = deque(groups.values())
    running = {}                                    # future -> (worker, group, job)
    idle = list(range(engine.n)) if engine else []

    def submit_next(w, group) -> bool:
        while group:
            job = group.popleft()
            bad = failed_upstream(job)
            if bad is not None:
                record(job, {"id": job.id, "key": job.key, "status": "failed", "seconds": 0.0,
                             "error": f"not run: it reads the results of {bad}, which failed"})
                continue
            d = job.to_dict()
            d["inputs"] = [str(by_id[a].outputs(out)) for a in job.after]
            # the inputs' hashes the plan took (by size and time): the worker need not read them twice
            d["hashes"] = {str(f): hashes.known[str(f)] for f in job.input_files() if str(f) in hashes.known}
            running[engine.submit(w, d, str(out))] = (w, group, job)
            return True
        return False

    try:
        while queue or running:
            while idle and queue:
                w = idle.pop()
                if not submit_next(w, queue.popleft()):
                    idle.append(w)
            if not running:
                continue
            done, _ = wait(list(running), timeout=1.0, return_when=FIRST_COMPLETED)
            for fut in done:
                w, group, job = running.pop(fut)
                try:
                    rec = fut.result()
                except Exception as e:                          # the worker died under the job
                    if not engine.died(e):
                        raise
                    engine.restart(w)
                    attempts[job.id] = attempts.get(job.id, 0) + 1
                    if attempts[job.id] <= retry:
                        group.appendleft(job)                   # again, on a fresh worker
                        if not submit_next(w, group):
                            idle.append(w)
                        continue
                    rec = {"id": job.id, "key": job.key, "status": "failed", "seconds": 0.0,
                           "error": f"the worker running it died {attempts[job.id]} times"}
                if attempts.get(job.id):
                    rec["retries"] = attempts[job.id]
                record(job, rec)
                if not submit_next(w, group):
                    idle.append(w)
    finally:
        if engine is not None:
            if running:                                         # interrupted: stop the workers
                for w in range(engine.n):
                    engine.restart(w, kill=True)
            engine.close()
        report = {"manifest": str(Path(manifest).resolve()), "engine": engine.name if engine else "none",
                  "started": t0, "seconds": round(time.time() - t0, 3),
                  "counts": {s: sum(r["status"] == s for r in records.values()) for s in ("done", "skipped", "failed")},
                  "jobs": [records.get(j.id, {"id": j.id, "key": j.key, "status": "pending"}) for j in jobs]}
        _write_json(out / "batch.json", report)
    return report


def _write_json(path: Path, data) -> None:
    from ..outputs import atomic_path
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(data, indent=1))


def batch_status(out) -> dict:
    """What a folder says of its batch, read from the folder alone: each planned job done (its marker
    holds the planned key and its output exists), failed (the last report says so, with why), or
    pending.

    Parameters
    ----------
    out : str or Path
        The batch's folder.

    Returns
    -------
    dict
        {"done": [{"id", "seconds", "machine"}, ...], "failed": [{"id", "error"}, ...],
        "pending": [{"id"}, ...]}.
    """
    out = Path(out)
    try:
        planned = json.loads((out / META / "plan.json").read_text())
    except FileNotFoundError:
        raise MimicaError(f"{out}: no batch has run into this folder (no {META}/plan.json)") from None
    except (OSError, ValueError) as e:
        raise MimicaError(f"{out}/{META}/plan.json: cannot read it ({e})") from None
    try:
        last = {r["id"]: r for r in json.loads((out / "batch.json").read_text())["jobs"]}
    except (OSError, ValueError, KeyError):
        last = {}
    state = {"done": [], "pending": [], "failed": []}
    for j in planned["jobs"]:
        try:
            rec = json.loads(marker_path(out, j["id"]).read_text())
        except (OSError, ValueError):
            rec = None
        if rec is not None and rec.get("key") == j["key"] and Path(j["output"]).exists():
            state["done"].append({"id": j["id"], "seconds": rec.get("seconds"), "machine": rec.get("machine")})
        elif last.get(j["id"], {}).get("status") == "failed":
            state["failed"].append({"id": j["id"], "error": last[j["id"]].get("error", "")})
        else:
            state["pending"].append({"id": j["id"]})
    return state
