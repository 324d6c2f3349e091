"""`mimica batch`: many heads x many performances from a manifest (TOML), resumable, on this machine's cores or a Ray cluster."""

from __future__ import annotations

import sys
from pathlib import Path

from ..errors import MimicaError
from ._common import _say


def _print_status(out: Path) -> int:
    """`--status`: what is done, pending and failed, and why."""
    from ..batch import batch_status
    st = batch_status(out)
    print(f"{out}: {len(st['done'])} done, {len(st['pending'])} pending, {len(st['failed'])} failed")
    for s in ("failed", "pending", "done"):
        for r in st[s]:
            why = f": {r['error']}" if s == "failed" else (
                f" ({r['seconds']:.1f}s on {r['machine']})" if s == "done" and r.get("seconds") is not None else "")
            print(f"  {s:8s}{r['id']}{why}")
    return 0


def cmd_batch(a):
    """`mimica batch`: many heads x many performances from a manifest, resumable (batch.run_batch),
    or its status.

    Parameters
    ----------
    a : argparse.Namespace
        The command's options (its add_args).

    Returns
    -------
    int
        The exit status (0: done; 1: a job failed).
    """
    from ..batch import run_batch
    out = Path(a.out)
    if a.status:
        if a.manifest:
            raise MimicaError("--status reads the batch's folder alone; leave the manifest out")
        return _print_status(out)
    if not a.manifest:
        raise MimicaError("batch: name the manifest (jobs.toml), or ask --status")
    bar, progress = _job_bar()
    try:
        rep = run_batch(a.manifest, out, workers=a.workers, ray=a.ray, retry=a.retry, progress=progress)
    finally:
        if bar is not None:
            bar.close()
    c = rep["counts"]
    _say(f"batch: {c['done']} done, {c['skipped']} skipped (finished before, inputs unchanged), {c['failed']} failed "
         f"in {rep['seconds']:.1f}s on {rep['engine']}; report {out / 'batch.json'}")
    for r in rep["jobs"]:
        if r["status"] == "failed":
            _say(f"  failed {r['id']}: {r.get('error', '')}")
    return 1 if c["failed"] else 0


def _job_bar():
    """(a job bar on a terminal or None, the batch's progress callback feeding it)."""
    bar = None
    if sys.stderr.isatty():
        from tqdm import tqdm
        bar = tqdm(total=0, desc="batch", unit="job", leave=False)

    def progress(ev):
        if bar is not None:
            bar.total = ev["total"]
            if ev["status"] == "started":
                bar.refresh()
                return
            bar.set_postfix_str(ev["job"][-40:])
            bar.update(1)
    return bar, progress


def add_args(sub) -> None:
    """Put `mimica batch` and its options on the `mimica` parser.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The parser's commands (ArgumentParser.add_subparsers).
    """
    bt = sub.add_parser("batch", help="many heads x many performances from a manifest (TOML), resumable, "
                        "on this machine's cores or a Ray cluster",
                        description="Jobs whose inputs and options did not change since they finished are skipped; "
                                    "a bad input fails its own jobs and the rest go on (exit 1 if any failed).")
    bt.add_argument("manifest", nargs="?", help="jobs.toml: [heads], [performances], [jobs.NAME] (see mimica.batch.manifest)")
    bt.add_argument("--workers", type=int, help="worker processes (default: the core count)")
    bt.add_argument("--ray", metavar="ADDRESS", help="run on Ray: a cluster's address, or auto (a running cluster, "
                    "else a local one); pip install 'mimica[ray]'")
    bt.add_argument("--retry", type=int, default=2, help="times a job is retried when its worker dies")
    bt.add_argument("--status", action="store_true", help="say what is done, pending and failed in --out, and why")
    bt.add_argument("-o", "--out", required=True, help="the batch's folder")
    bt.set_defaults(func=cmd_batch)


run = cmd_batch
