"""A batch manifest (TOML) made into a plan: heads x performances x jobs, each job keyed by
the contents of its inputs and its options.

    [heads]
    alice = "heads/alice.obj"                                  # a file
    bob = { mesh = "heads/bob.ply", landmarks = "heads/bob.json" }
    cast = { glob = "cast/*.obj" }                             # every file a head: cast/STEM

    [performances]
    talk = { neutral = "ict/neutral.obj", frames = "takes/talk" }   # expression meshes of that neutral
    take1 = { arkit = "takes/take1.csv" }                      # an ARKit take (Live Link CSV or JSON)
    smile = { timeline = "smile.json" }                        # muscle activations for `simulate`

    [jobs.arkit]
    run = "blendshapes"                  # heads = [...] and performances = [...] narrow a job down
    [jobs.talk]
    run = "transfer"
    [jobs.take]
    run = "animate"
    from = "arkit"                       # the head's blendshapes that job made
    [jobs.preview]
    run = "render"
    from = "talk"

Paths are relative to the manifest's folder.  Every job's output lands under the batch's
folder at <job>/<head>[/<performance>] (see `Job.outputs`).  A manifest with an unknown key,
a missing file, a name that is not defined or jobs that depend on each other in a circle is
refused in one line before anything runs.
"""

from __future__ import annotations

import glob as _glob
import hashlib
import json
import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import MimicaError
from ..mesh import MESH_SUFFIXES
from ..pipeline import (AgeOptions, AnimateOptions, BlendshapesOptions, ExportOptions, RenderOptions, RigOptions,
                        SimulateOptions, TransferOptions)



def _auto(on: bool) -> str:
    return "auto" if on else "off"


_B, _T, _R, _S = BlendshapesOptions(), TransferOptions(), RigOptions(), SimulateOptions()
_A, _N, _V, _E = AgeOptions(), AnimateOptions(), RenderOptions(), ExportOptions()
# job kind -> (what it runs on, the options it takes with their defaults: the pipeline's own)
KINDS = {
    "blendshapes": ("head", {"quantize": _B.quantize, "cut_mouth": _auto(_B.cut_mouth), "cut_eyes": _auto(_B.cut_eyes),
                             "match": _B.match}),
    "transfer": ("frames", {"method": _T.method, "cut_mouth": _auto(_T.cut_mouth), "cut_eyes": _auto(_T.cut_eyes),
                            "match": _T.match}),
    "animate": ("arkit", {"head_rotation": _N.head_rotation}),
    "simulate": ("timeline", {"muscles": _R.muscles, "fps": _S.fps}),
    "age": ("head", {"ages": list(_A.ages), "expression": _A.expression, "size": _A.size}),
    "render": ("from", {"view": _V.view, "size": _V.size}),
    "export": ("from", {"fps": _E.fps, "format": "glb"}),          # a batch exports one clip file
}
# which kinds a `from` may name, per kind
FROM = {"animate": ("blendshapes",), "render": ("transfer", "simulate"), "export": ("transfer", "simulate")}
PERFORMANCE_KINDS = {"frames": ("neutral", "frames"), "arkit": ("arkit",), "timeline": ("timeline",)}
JOB_KEYS = {"run", "heads", "performances", "from"}


@dataclass
class Head:
    """A head of the manifest.

    Attributes
    ----------
    name : str
        Its name in the manifest (a folder of the results).
    mesh : Path
        Its mesh file.
    landmarks : Path or None
        Its landmark file, where given.
    """
    name: str
    mesh: Path
    landmarks: Path | None = None


@dataclass
class Performance:
    """A performance of the manifest: what drives the heads.

    Attributes
    ----------
    name : str
    kind : str
        "frames", "arkit" or "timeline".
    files : dict
        role -> Path: neutral, frames (a folder or a list), arkit, timeline.
    """
    name: str
    kind: str                      # frames | arkit | timeline
    files: dict                    # role -> Path (neutral, frames (a folder or a list), arkit, timeline)


@dataclass
class Job:
    """One job of a batch: a kind of work on one head (and one performance).

    Attributes
    ----------
    id : str
        "<job>/<head>[/<performance>]".
    name : str
        The manifest's job name.
    kind : str
        blendshapes, transfer, rig, simulate, age, animate or render.
    head : Head
    performance : Performance or None
    options : dict
        The job's options, the pipeline's defaults filled in.
    after : list of str
        The ids of the jobs whose outputs it reads.
    key : str
        A hash of what it depends on (key_jobs); equal keys: nothing to redo.
    """
    id: str                        # <job>/<head>[/<performance>]
    name: str                      # the manifest's job name
    kind: str
    head: Head
    performance: Performance | None
    options: dict
    after: list = field(default_factory=list)      # ids of the jobs whose outputs it reads
    key: str = ""

    def outputs(self, root: Path) -> Path:
        """Where the job writes: a file or a folder under the batch's folder."""
        base = root / self.name / self.head.name
        p = self.performance.name if self.performance is not None else None
        return {"blendshapes": base / "arkit.glb", "transfer": base / str(p), "animate": base / f"{p}.glb",
                "simulate": base / str(p), "age": base / "age.png", "render": base / f"{p}.png",
                "export": base / f"{p}.{self.options.get('format', 'glb')}"}[self.kind]

    def input_files(self) -> list[Path]:
        """The files the job reads from the user: its head, landmarks and performance's files
        (a folder of frames as its frames; render and export read the jobs they come from)."""
        out = [self.head.mesh] + ([self.head.landmarks] if self.head.landmarks else [])
        if self.performance is not None and KINDS[self.kind][0] != "from":
            for role, v in self.performance.files.items():
                out += frame_files(self.performance) if role == "frames" else [v]
        return out

    def to_dict(self) -> dict:
        return {"id": self.id, "name": self.name, "kind": self.kind, "head": _plain(self.head.__dict__),
                "performance": None if self.performance is None else _plain(
                    {k: getattr(self.performance, k) for k in ("name", "kind", "files")}),
                "options": self.options, "after": self.after, "key": self.key}

    @classmethod
    def from_dict(cls, d: dict) -> "Job":
        h = d["head"]
        head = Head(h["name"], Path(h["mesh"]), Path(h["landmarks"]) if h.get("landmarks") else None)
        p = d["performance"]
        perf = None if p is None else Performance(p["name"], p["kind"], {
            k: ([Path(x) for x in v] if isinstance(v, list) else Path(v)) for k, v in p["files"].items()})
        return cls(d["id"], d["name"], d["kind"], head, perf, d["options"], list(d["after"]), d["key"])


def _plain(x):
    if isinstance(x, dict):
        return {k: _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    return str(x) if isinstance(x, Path) else x


def read_manifest(path) -> dict:
    """A batch manifest's TOML, parsed; a missing or malformed file is one MimicaError.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    dict
    """
    path = Path(path)
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise MimicaError(f"{path}: no such manifest") from None
    except (OSError, UnicodeDecodeError) as e:
        raise MimicaError(f"{path}: cannot read it ({e})") from None
    except tomllib.TOMLDecodeError as e:
        raise MimicaError(f"{path}: not valid TOML ({e})") from None


def plan(path) -> list[Job]:
    """The manifest made into jobs, in an order where every job comes after those it reads from;
    keys not yet computed (key_jobs).

    Parameters
    ----------
    path : str or Path
        The manifest (TOML); its relative paths are taken from its folder.

    Returns
    -------
    list of Job
    """
    path = Path(path)
    m = read_manifest(path)
    base = path.resolve().parent
    where = str(path)
    unknown = sorted(set(m) - {"heads", "performances", "jobs"})
    if unknown:
        raise MimicaError(f"{where}: unknown section {unknown[0]!r} (a manifest has [heads], [performances], [jobs])")
    heads = _heads(m.get("heads"), base, where)
    perfs = _performances(m.get("performances", {}), base, where)
    jobs = m.get("jobs")
    if not isinstance(jobs, dict) or not jobs:
        raise MimicaError(f"{where}: no [jobs.NAME] tables; name at least one job with its run = \"...\"")
    order = _job_order(jobs, where)
    out: list[Job] = []
    made: dict[str, list[Job]] = {}
    for name in order:
        spec = jobs[name]
        kind = spec["run"]
        on, defaults = KINDS[kind]
        options = dict(defaults)
        for k, v in spec.items():
            if k in JOB_KEYS:
                continue
            if k not in defaults:
                raise MimicaError(f"{where}: jobs.{name}: unknown option {k!r} for {kind} "
                                  f"(its options: {', '.join(defaults) or 'none'})")
            if type(v) is not type(defaults[k]) and not (isinstance(defaults[k], float) and isinstance(v, int)):
                raise MimicaError(f"{where}: jobs.{name}.{k} = {v!r}: expected {type(defaults[k]).__name__}")
            if isinstance(v, list) and not (v and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                      for x in v)):
                raise MimicaError(f"{where}: jobs.{name}.{k} = {v!r}: expected a list of numbers")
            options[k] = v
        chosen_heads = _pick(spec.get("heads"), heads, f"{where}: jobs.{name}.heads", "head")
        made[name] = []
        if on == "head":
            for h in chosen_heads:
                made[name].append(Job(f"{name}/{h.name}", name, kind, h, None, options))
        elif on == "from":
            for up in made[spec["from"]]:
                if up.head.name in {h.name for h in chosen_heads}:
                    made[name].append(Job(f"{name}/{up.head.name}/{up.performance.name}", name, kind, up.head,
                                          up.performance, options, [up.id]))
        else:
            wanted = spec.get("performances")
            pool = [p for p in perfs.values() if p.kind == on] if wanted is None else \
                _pick(wanted, perfs, f"{where}: jobs.{name}.performances", "performance")
            for p in pool:
                if p.kind != on:
                    raise MimicaError(f"{where}: jobs.{name}: performance {p.name!r} is {_a(p.kind)}; {kind} takes "
                                      f"{_a(on)} ({' + '.join(PERFORMANCE_KINDS[on])})")
            if not pool:
                raise MimicaError(f"{where}: jobs.{name}: no performance of the kind {kind} takes ({_a(on)}: "
                                  f"{' + '.join(PERFORMANCE_KINDS[on])})")
            for h in chosen_heads:
                for p in pool:
                    after = []
                    if kind == "animate":
                        up = [j for j in made[spec["from"]] if j.head.name == h.name]
                        if not up:
                            raise MimicaError(f"{where}: jobs.{name}: head {h.name!r} has no job in "
                                              f"jobs.{spec['from']} to take its blendshapes from")
                        after = [up[0].id]
                    made[name].append(Job(f"{name}/{h.name}/{p.name}", name, kind, h, p, options, after))
        out += made[name]
    return out


def _a(kind):
    return {"frames": "a folder of frames", "arkit": "an ARKit take", "timeline": "a timeline"}.get(
        kind, ("an " if kind[0] in "aeiou" else "a ") + kind)


def _pick(wanted, pool: dict, where: str, what: str):
    if wanted is None:
        return list(pool.values())
    if isinstance(wanted, str):
        wanted = [wanted]
    if not isinstance(wanted, list) or not all(isinstance(w, str) for w in wanted):
        raise MimicaError(f"{where}: expected a list of {what} names")
    out = []
    for w in wanted:
        hits = [v for k, v in pool.items() if k == w or k.startswith(w + "/")]
        if not hits:
            raise MimicaError(f"{where}: no {what} named {w!r} (defined: {', '.join(sorted(pool)) or 'none'})")
        out += hits
    return out


def _file(base: Path, value, where: str, folder_ok=False) -> Path:
    if not isinstance(value, str) or not value:
        raise MimicaError(f"{where}: expected a path (a string)")
    p = (base / value).resolve() if not Path(value).is_absolute() else Path(value)
    if not p.exists():
        raise MimicaError(f"{where} = {value!r}: no such file ({p})")
    if p.is_dir() and not folder_ok:
        raise MimicaError(f"{where} = {value!r}: is a folder; name a file")
    return p


def _heads(spec, base: Path, where: str) -> dict[str, Head]:
    if not isinstance(spec, dict) or not spec:
        raise MimicaError(f"{where}: no [heads]; name at least one head mesh (name = \"path.obj\")")
    out = {}
    for name, v in spec.items():
        at = f"{where}: heads.{name}"
        _check_name(name, at)
        if isinstance(v, str):
            v = {"mesh": v}
        if not isinstance(v, dict):
            raise MimicaError(f"{at}: expected a path or a table (mesh = ..., landmarks = ... or glob = ...)")
        bad = sorted(set(v) - {"mesh", "landmarks", "glob"})
        if bad:
            raise MimicaError(f"{at}: unknown key {bad[0]!r} (a head has mesh, landmarks, or glob)")
        if ("glob" in v) == ("mesh" in v):
            raise MimicaError(f"{at}: give either mesh = \"file\" or glob = \"pattern\"")
        if "glob" in v:
            if "landmarks" in v:
                raise MimicaError(f"{at}: landmarks belong to one mesh; give each head of the glob its own table")
            pattern = v["glob"] if Path(v["glob"]).is_absolute() else str(base / v["glob"])
            files = sorted(Path(f) for f in _glob.glob(pattern) if Path(f).suffix.lower() in MESH_SUFFIXES)
            if not files:
                raise MimicaError(f"{at}: glob = {v['glob']!r} matches no mesh file")
            for f in files:
                out[f"{name}/{f.stem}"] = Head(f"{name}/{f.stem}", f.resolve())
        else:
            lm = _file(base, v["landmarks"], f"{at}.landmarks") if "landmarks" in v else None
            out[name] = Head(name, _file(base, v["mesh"], f"{at}.mesh"), lm)
    return out


def _performances(spec, base: Path, where: str) -> dict[str, Performance]:
    if not isinstance(spec, dict):
        raise MimicaError(f"{where}: [performances] must be a table of named performances")
    out = {}
    for name, v in spec.items():
        at = f"{where}: performances.{name}"
        _check_name(name, at)
        if not isinstance(v, dict):
            raise MimicaError(f"{at}: expected a table (neutral + frames, arkit, or timeline)")
        kinds = [k for k, need in PERFORMANCE_KINDS.items() if need[-1] in v]
        if len(kinds) != 1 or set(v) - set(PERFORMANCE_KINDS[kinds[0]]):
            raise MimicaError(f"{at}: expected exactly one of: neutral + frames (expression meshes), "
                              "arkit (a take), timeline (muscle activations)")
        kind = kinds[0]
        files = {}
        for role in PERFORMANCE_KINDS[kind]:
            if role not in v:
                raise MimicaError(f"{at}: frames need the neutral they are expressions of (neutral = \"file\")")
            if role == "frames" and isinstance(v[role], list):
                files[role] = [_file(base, f, f"{at}.frames") for f in v[role]]
            else:
                files[role] = _file(base, v[role], f"{at}.{role}", folder_ok=role == "frames")
        out[name] = Performance(name, kind, files)
    return out


def _check_name(name: str, where: str):
    if not name or any(c in name for c in "/\\\0") or name.startswith("."):
        raise MimicaError(f"{where}: {name!r} cannot name a folder; use letters, digits, - and _")


def _job_order(jobs: dict, where: str) -> list[str]:
    """Job names with every job after the one it reads from; unknown names, kinds and keys
    and circles refused."""
    for name, spec in jobs.items():
        at = f"{where}: jobs.{name}"
        _check_name(name, at)
        if not isinstance(spec, dict):
            raise MimicaError(f"{at}: expected a table with run = \"...\"")
        kind = spec.get("run")
        if kind not in KINDS:
            raise MimicaError(f"{at}: run = {kind!r}: expected one of {', '.join(KINDS)}")
        if kind in FROM:
            src = spec.get("from")
            if src is None:
                raise MimicaError(f"{at}: {kind} reads another job's results; say which with from = "
                                  f"\"JOB\" (a {' or '.join(FROM[kind])} job)")
            if src not in jobs:
                raise MimicaError(f"{at}: from = {src!r}: no such job (defined: {', '.join(sorted(jobs))})")
        elif "from" in spec:
            raise MimicaError(f"{at}: {kind} does not read another job's results (no from)")
        if kind in ("render", "export") and "performances" in spec:
            raise MimicaError(f"{at}: {kind} takes the performances of its from job (no performances)")
    order, state = [], {}

    def visit(n, trail):
        if state.get(n) == "done":
            return
        if state.get(n) == "open":
            cycle = trail[trail.index(n):] + [n]
            raise MimicaError(f"{where}: jobs depend on each other in a circle: {' -> '.join(cycle)}")
        state[n] = "open"
        src = jobs[n].get("from")
        if src is not None:
            visit(src, trail + [n])
        state[n] = "done"
        order.append(n)

    for n in jobs:
        visit(n, [])
    for name, spec in jobs.items():                 # what a from names must make what it reads
        src = spec.get("from")
        if src is not None and jobs[src]["run"] not in FROM[spec["run"]]:
            raise MimicaError(f"{where}: jobs.{name}: from = {src!r} is {_a(jobs[src]['run'])} job; "
                              f"{spec['run']} reads {' or '.join(FROM[spec['run']])} results")
    return order


class FileHashes:
    """sha256 of files, remembered by (path, size, mtime) in a JSON file, so that a rerun with nothing
    changed reads no input again.

    Parameters
    ----------
    path : Path or None
        The JSON file (None: remember nothing).
    """

    def __init__(self, path: Path | None):
        self.path = path
        self.known = {}
        if path is not None and path.is_file():
            try:
                self.known = json.loads(path.read_text())
            except (OSError, ValueError):
                self.known = {}

    def of(self, p: Path) -> str:
        st = p.stat()
        k = str(p)
        stamp = [st.st_size, st.st_mtime_ns]
        hit = self.known.get(k)
        if hit and hit[0] == stamp:
            return hit[1]
        h = hashlib.sha256()
        with open(p, "rb") as fh:
            for chunk in iter(lambda: fh.read(1 << 20), b""):
                h.update(chunk)
        self.known[k] = [stamp, h.hexdigest()]
        return self.known[k][1]

    def save(self):
        if self.path is None:
            return
        from ..outputs import atomic_path
        with atomic_path(self.path) as tmp:
            tmp.write_text(json.dumps(self.known))


def key_jobs(jobs: list[Job], hashes: FileHashes) -> None:
    """Set each job's key: a hash of its kind, options, mimica's version, its inputs' contents and
    the keys of the jobs it reads from.

    Parameters
    ----------
    jobs : list of Job
        In plan's order; changed in place.
    hashes : FileHashes
    """
    from .. import __version__
    keys = {}
    for j in jobs:
        parts = {"kind": j.kind, "options": j.options, "version": __version__,
                 "inputs": [hashes.of(f) for f in j.input_files()], "after": [keys[a] for a in j.after]}
        j.key = hashlib.sha256(json.dumps(parts, sort_keys=True).encode()).hexdigest()
        keys[j.id] = j.key


def frame_files(perf: Performance) -> list[Path]:
    """The expression meshes of a frames performance (as the `transfer` command takes a folder:
    natural order, one format).

    Parameters
    ----------
    perf : Performance

    Returns
    -------
    list of Path
        Its list, or its folder's frames.
    """
    from ..mesh.io import sequence_files
    if getattr(perf, "_listed", None) is None:          # listed once per plan
        f = perf.files["frames"]
        perf._listed = f if isinstance(f, list) else sequence_files(f)[0]
    return perf._listed


def environment() -> dict:
    """What a job's result records of where it ran.

    Returns
    -------
    dict
        {"machine": the host's name, "pid": the process}.
    """
    import platform
    return {"machine": platform.node(), "pid": os.getpid()}
