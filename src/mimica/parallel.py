"""Independent jobs in fresh Python worker processes, for work that holds the GIL (scikit-sparse's
CHOLMOD factorization does: two threads run it no faster than one).

Written here rather than taken from multiprocessing or concurrent.futures: their fork start
is unsafe once GNU OpenMP (loaded with CHOLMOD) or BLAS threads have run in the parent, and
their spawn start imports the caller's main script again in every worker, so a plain script
without an `if __name__ == "__main__"` guard would fail.  A worker here is
`python -c` importing mimica alone: it gets the shared state once, then jobs one at a time
(the largest first, as the workers free up), each answered with its result or its exception,
all pickled over the worker's pipes; its BLAS and OpenMP run one thread each.  Where a worker
cannot start or dies, the jobs it did not answer run in the caller's process.
"""

from __future__ import annotations

import os
import pickle
import queue
import subprocess
import sys
import threading
from pathlib import Path

_ONE_THREAD = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "OMP_THREAD_LIMIT": "1", "MKL_NUM_THREADS": "1"}


def cores() -> int:
    """The CPU cores this process may run on.

    Returns
    -------
    int
    """
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:                             # not Linux
        return os.cpu_count() or 1


_BLAS = None


def one_blas_thread():
    """A context in which the BLAS libraries run on one thread (where the work is spread over
    the cores otherwise, or must come out the same in this process and in a worker), from a
    controller made once: threadpoolctl's threadpool_limits looks the loaded libraries up on
    every call (1 ms, against 0.04 ms).  Made on first use, after numpy, SciPy and CHOLMOD have
    loaded their BLAS.

    Returns
    -------
    context manager
    """
    global _BLAS
    if _BLAS is None:
        from threadpoolctl import ThreadpoolController   # here: its import sets KMP_DUPLICATE_LIB_OK
        _BLAS = ThreadpoolController()
    return _BLAS.limit(limits=1, user_api="blas")


def run_jobs(func, shared, jobs: list, workers: int):
    """func(shared, job) for every job, in `workers` worker processes.

    Parameters
    ----------
    func : callable
        A module-level function, found again by its module and name in a worker (which imports
        mimica's library, nothing of the caller's).
    shared : object
        Picklable; sent once to each worker.
    jobs : list
        Picklable, the costliest first (handed out in this order).
    workers : int
        Worker processes (at least 1).

    Yields
    ------
    (int, object)
        A job's index in `jobs` and func's result, in the order they finish.  A job's exception
        is raised here as it arrives.
    """
    if not Path(sys.executable or "").name.lower().startswith("python"):
        # an embedding program (Blender, a server) is not a Python to start workers with
        yield from ((i, func(shared, job)) for i, job in enumerate(jobs))
        return
    todo = queue.SimpleQueue()
    for i in range(len(jobs)):
        todo.put(i)
    done = queue.SimpleQueue()
    root = str(Path(__file__).resolve().parents[1])
    env = {**os.environ, **_ONE_THREAD}
    # `python -c` puts the working directory first on the path: mimica's own place instead
    code = f"import sys; sys.path[0] = {root!r}; from mimica.parallel import _serve; _serve()"
    head = pickle.dumps((func.__module__, func.__qualname__, shared), protocol=pickle.HIGHEST_PROTOCOL)
    threads = [threading.Thread(target=_feed, args=(code, env, head, jobs, todo, done), daemon=True)
               for _ in range(workers)]
    for t in threads:
        t.start()
    left = len(jobs)
    try:
        while left:
            i, ok, value = done.get()
            if i is None:                               # a worker gone: its job back to the caller
                value = func(shared, jobs[ok])
                i, ok = ok, True
            left -= 1
            if not ok:
                raise value
            yield i, value
    finally:                                            # a job failed or the caller stopped: no more handed out
        while True:
            try:
                todo.get_nowait()
            except queue.Empty:
                break
        for t in threads:
            t.join()


def _feed(code, env, head, jobs, todo: queue.SimpleQueue, done: queue.SimpleQueue):
    """One worker's thread: start it, hand it jobs while any are left, pass on its answers; where
    it cannot start or dies, each job it holds or would take is done by the caller instead."""
    proc = None
    try:
        proc = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                stderr=subprocess.DEVNULL, env=env)
        proc.stdin.write(head)
        proc.stdin.flush()
    except OSError:                                     # not started, or gone at once
        proc = _gone(proc)
    try:
        while True:
            try:
                i = todo.get_nowait()
            except queue.Empty:
                break
            if proc is None:
                done.put((None, i, None))
                continue
            try:
                pickle.dump((i, jobs[i]), proc.stdin, protocol=pickle.HIGHEST_PROTOCOL)
                proc.stdin.flush()
                k, ok, value = pickle.load(proc.stdout)
            except Exception:                           # gone, or an answer that does not read back
                proc = _gone(proc)
                done.put((None, i, None))
                continue
            done.put((k, ok, value))
    finally:
        if proc is not None:
            proc.stdin.close()
            proc.wait()


def _gone(proc):
    """A worker that will not answer, ended (None: none was started)."""
    if proc is not None:
        proc.kill()
        proc.wait()


def _serve():
    """A worker's loop: the shared state, then (index, job) -> (index, ok, result or exception)
    until its input closes.  Its own stdout is the answers' pipe; anything printed goes to
    stderr."""
    import importlib
    out = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)
    inp = sys.stdin.buffer
    module, name, shared = pickle.load(inp)
    func = getattr(importlib.import_module(module), name)
    while True:
        try:
            i, job = pickle.load(inp)
        except EOFError:
            return
        try:
            answer = (i, True, func(shared, job))
        except Exception as e:                          # the caller raises it
            answer = (i, False, e)
        pickle.dump(answer, out, protocol=pickle.HIGHEST_PROTOCOL)
        out.flush()
