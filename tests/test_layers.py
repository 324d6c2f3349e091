"""The package's layers (DESIGN.md, "The data flow"), checked from its module graph: every
import in every module (those inside functions too), no cycle, no stage importing a stage
above it, and no process-wide side effect on import."""

from __future__ import annotations

import ast
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import mimica

PACKAGE = Path(mimica.__file__).resolve().parent

# bottom to top; a stage may import its own modules and any stage on a lower line.  The
# foundations hold no method; the template store reads meshes, and data (the template's
# facts) reads through it; image is io for pictures
# (read, write, and the rasterizer every picture is drawn with); the users sit on top.
LAYERS = [
    {"errors", "_extras", "_memory", "outputs", "parallel", "solver", "validate", "facts"},
    {"mesh"},
    {"store"},
    {"data"},
    {"image"},
    {"landmarks"},
    {"align"},
    {"correspond"},
    {"rig"},
    {"anim"},
    {"physics"},
    {"wrinkles"},
    {"transfer"},
    {"render", "export"},
    {"pipeline"},
    {"cli", "viewer", "batch", "blender", "blender_addon", "demo", ""},   # "": the package's own __init__
]
LAYER = {stage: i for i, stages in enumerate(LAYERS) for stage in stages}
FOUNDATIONS, USERS = LAYERS[0], LAYERS[-1]


def module_name(path: Path) -> str:
    parts = ["mimica", *path.relative_to(PACKAGE).with_suffix("").parts]
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def modules() -> dict[str, Path]:
    return {module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def imports(name: str, path: Path, known) -> set[str]:
    """The mimica modules `name` imports anywhere in its file (a `from X import y` of a
    submodule y counts as importing X.y)."""
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    out = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names if a.name.split(".")[0] == "mimica"}
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target.split(".")[0] != "mimica":
                continue
            subs = {f"{target}.{a.name}" for a in node.names} & set(known)
            out |= subs
            if len(subs) < len(node.names):
                out.add(target)
    return out - {name}


def stage(name: str) -> str:
    parts = name.split(".")
    return parts[1] if len(parts) > 1 else ""


def graph() -> dict[str, set[str]]:
    mods = modules()
    return {n: imports(n, p, mods) for n, p in mods.items()}


def test_every_module_has_a_layer():
    unplaced = sorted({stage(n) for n in modules()} - set(LAYER))
    assert not unplaced, f"place these in DESIGN.md's layers (and in LAYERS here): {unplaced}"


def test_the_facts_the_blender_addon_ships_import_only_the_standard_library():
    """mimica.facts goes into the add-on's zip and runs in Blender's Python, where mimica (and
    numpy >= 2) cannot be imported: it imports the standard library only."""
    tree = ast.parse((PACKAGE / "facts.py").read_text(encoding="utf-8"))
    names = {a.name.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    names |= {(n.module or "").split(".")[0] or "." for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    assert names <= set(sys.stdlib_module_names) | {"__future__"}, names


def test_the_graph_sees_the_imports():
    """The check itself: the edges it must find are found (lazy and relative imports too)."""
    g = graph()
    assert "mimica.correspond.remesh" in g["mimica.demo"]                 # `from .correspond.remesh import`
    assert "mimica.landmarks.detect2d" in g["mimica.landmarks.detect3d"]   # `from . import detect2d`
    assert "mimica.physics.systems" in g["mimica.physics.fullface"]
    assert "mimica.landmarks.detect3d" in g["mimica.landmarks.auto"]
    assert "mimica.store" in g["mimica.data"]
    assert any(t.startswith("mimica.pipeline") for t in g["mimica.cli.simulate"])    # inside functions


def test_no_stage_imports_a_stage_above_it():
    bad = []
    for src, targets in graph().items():
        for t in targets:
            a, b = stage(src), stage(t)
            if a == b:
                continue
            # siblings on one line stay apart, but for the foundations and the users
            if LAYER[b] > LAYER[a] or (LAYER[b] == LAYER[a] and a not in FOUNDATIONS | USERS):
                bad.append(f"{src} -> {t}")
    assert not bad, "imports against DESIGN.md's layers:\n" + "\n".join(sorted(bad))


def test_no_import_cycles():
    g = graph()
    index, low, on, stack, cycles = {}, {}, set(), [], []

    def visit(v):                                   # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in g.get(v, ()):
            if w not in g:
                continue
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            # a package importing its own submodule, which imports a sibling, is no cycle;
            # a component of two or more modules is
            if len(comp) > 1:
                cycles.append(sorted(comp))

    for v in sorted(g):
        if v not in index:
            visit(v)
    assert not cycles, f"import cycles: {cycles}"


def test_importing_mimica_changes_nothing_process_wide():
    """Every module imported: the allocator (mallopt), signal handlers, numpy's error state and
    huge-page advice, warning filters and the environment are as before (threadpoolctl's import
    sets an environment variable: it is imported where it is used) but for the one setting
    mimica.solver makes on purpose: OpenMP's thread limit 1 on a machine of under 4 cores, unless
    the user set one (CHOLMOD's threads wait on one another there); keep_memory() then turns the
    advice off.  Run in a process whose environment holds no thread limit (a test before may have
    imported the solver into this one)."""
    from mimica.parallel import cores
    names = sorted(n for n in modules() if not n.endswith("__main__"))
    code = f"""
import json, os, signal, sys, warnings
import numpy as np
import scipy.sparse, scipy.spatial, scipy.special, scipy.linalg  # their own filters, set on their import
before = (dict(os.environ), signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM), np.geterr(),
          len(warnings.filters), np._core.multiarray._get_madvise_hugepage())
import importlib
for n in {names!r}:
    importlib.import_module(n)
import mimica._memory as m
limit = os.environ.pop("OMP_THREAD_LIMIT", None)
after = (dict(os.environ), signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM), np.geterr(),
         len(warnings.filters), np._core.multiarray._get_madvise_hugepage())
done = m._done
m.keep_memory()                              # the command line's and the batch jobs' setting: the advice off
print(json.dumps({{"same": [a == b for a, b in zip(before, after)], "mallopt": done,
                  "advice": np._core.multiarray._get_madvise_hugepage(), "limit": limit}}))
"""
    env = {k: v for k, v in os.environ.items() if k != "OMP_THREAD_LIMIT"}
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, env=env)
    assert r.returncode == 0, r.stderr[-2000:]
    got = json.loads(r.stdout.strip().splitlines()[-1])
    assert got == {"same": [True] * 6, "mallopt": False, "advice": False,
                   "limit": "1" if 0 < cores() < 4 else None}, got


# the package's own child processes, each with its reason: the Blender add-on runs inside Blender,
# whose Python cannot import mimica (numpy < 2), so it calls the `mimica` command; FBX is read and
# written by Blender's own importer and exporter, in Blender's Python; mimica.parallel's workers
# are Python importing mimica's library alone (no command): CHOLMOD's factorization holds the GIL,
# so only processes overlap a rig's systems
CHILD_PROCESSES = {"mimica.blender_addon", "mimica.mesh.io.fbx", "mimica.parallel"}


# the command line starts the other front ends (`mimica batch`, `mimica view`, `mimica demo`):
# the one way between users, and never the other way
LAUNCHES = {"cli": {"batch", "viewer", "demo"}}


def test_no_user_calls_another_and_nothing_runs_mimica_in_a_child():
    """The users of the pipeline (the CLI, batch, viewer, add-on, demo) do not import each other
    (but the command line starts the others), and no module but those named (with their reason)
    runs a command in a child process (the batch's pool workers run the pipeline in-process)."""
    g = graph()
    users = {u for u in USERS if u}
    for v, deps in g.items():
        if stage(v) in users:
            wrong = sorted(d for d in deps if stage(d) in users and stage(d) != stage(v)
                           and stage(d) not in LAUNCHES.get(stage(v), ()))
            assert not wrong, f"{v} imports another user of the pipeline: {wrong}"
    spawning = set()
    for name, path in modules().items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        names = {a.name for n in ast.walk(tree) if isinstance(n, (ast.Import, ast.ImportFrom)) for a in n.names}
        mods = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
        if "subprocess" in names or "subprocess" in mods:          # a pool's workers run library code
            spawning.add(name)
    assert spawning <= CHILD_PROCESSES, f"modules that start processes: {sorted(spawning - CHILD_PROCESSES)}"


def test_the_command_line_only_parses_calls_and_prints():
    """Each command's module stays small (<= 120 lines, no function over 40 lines of code, its
    docstring not counted): the work is the pipeline's."""
    for path in sorted((PACKAGE / "cli").glob("*.py")):
        text = path.read_text(encoding="utf-8")
        assert text.count("\n") <= 120, f"{path.name}: {text.count(chr(10))} lines"
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.FunctionDef):
                doc = node.body[0]
                has_doc = isinstance(doc, ast.Expr) and isinstance(doc.value, ast.Constant) and len(node.body) > 1
                length = node.end_lineno - node.lineno + 1 - ((doc.end_lineno - doc.lineno + 1) if has_doc else 0)
                assert length <= 40, f"{path.name}: {node.name} is too long"


def test_public_definitions_carry_numpydoc_sections():
    """At least 95 % of the package's public functions and classes (module level, no leading
    underscore, in modules without one) have numpydoc sections: Parameters, Returns or
    Attributes (a function of no arguments: Returns)."""
    total, missing = 0, []
    for name, path in modules().items():
        if any(p.startswith("_") for p in name.split(".")[1:]):
            continue
        for node in ast.parse(path.read_text(encoding="utf-8")).body:
            if isinstance(node, (ast.FunctionDef, ast.ClassDef)) and not node.name.startswith("_"):
                total += 1
                doc = ast.get_docstring(node) or ""
                if not any(f"{s}\n---" in doc for s in ("Parameters", "Returns", "Attributes", "Yields")):
                    missing.append(f"{name}.{node.name}")
    assert len(missing) <= 0.05 * total, f"{len(missing)} of {total} without numpydoc sections: {missing}"


def test_the_tests_are_laid_out_by_module():
    """Each folder of tests is named for the package or module of mimica it tests (the command
    line's own tests, parsing, messages and exit codes, under cli/); project-wide checks, like
    this one, sit at the top."""
    tests = Path(__file__).resolve().parent
    modules = {p.stem for p in PACKAGE.iterdir() if p.suffix == ".py" or (p / "__init__.py").is_file()}
    folders = {p.name for p in tests.iterdir() if p.is_dir() and not p.name.startswith((".", "_"))}
    assert folders and folders <= modules, sorted(folders - modules)
    names = [p.name for p in tests.rglob("test_*.py")]
    assert len(names) == len(set(names)), "two test files of one name (pytest imports them by name)"


# folders whose tests drive the command line for what they test, not for the command: the
# pipeline's parity with the command, the batch's killed worker (a process to kill) and the
# add-on's own `mimica` executable
DRIVE_THE_COMMAND = {"cli", "pipeline", "batch", "blender_addon"}


# the command reached: its module (in process or `python -m`), or the installed `mimica` script
DRIVES = re.compile(r'mimica\.cli|with_name\("mimica"\)|/ "mimica"')


def test_only_the_command_line_tests_drive_the_command_line():
    """A library's tests call the library: the command line (`mimica.cli` in process or as a
    child, or the installed `mimica` script) is driven from tests/cli/ and the folders
    DRIVE_THE_COMMAND names."""
    tests = Path(__file__).resolve().parent
    bad = [str(p.relative_to(tests)) for p in tests.rglob("test_*.py")
           if p.parent != tests and p.relative_to(tests).parts[0] not in DRIVE_THE_COMMAND
           and DRIVES.search(p.read_text(encoding="utf-8"))]
    assert not bad, f"drive the command line from tests/cli/: {bad}"
    assert DRIVES.search('exe = Path(sys.executable).with_name("mimica")') and DRIVES.search('venv / "bin" / "mimica"')


def test_no_module_takes_another_modules_private_names():
    """A name with a leading underscore stays in its module: what another module needs is public
    (with its docstring), or lives in a private helper module (cli._common) made to be shared."""
    bad = []
    for path in PACKAGE.rglob("*.py"):
        for n in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(n, ast.ImportFrom) or not (n.level or (n.module or "").startswith("mimica")):
                continue
            if (n.module or "").rsplit(".", 1)[-1].startswith("_"):
                continue                                     # a private helper module's names
            taken = [a.name for a in n.names if a.name.startswith("_") and not a.name.startswith("__")]
            if taken:
                where = f"{path.relative_to(PACKAGE)}:{n.lineno}"
                bad.append(f"{where} takes {', '.join(taken)} from {'.' * n.level}{n.module or ''}")
    assert not bad, "\n".join(bad)
