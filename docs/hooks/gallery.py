"""MkDocs hook: the gallery, its pictures made by the build.

Each script in docs/gallery/ is an example a user can run (`python docs/gallery/NAME.py OUT.png`):
its docstring's first line is its title, the rest its caption.  Before the site is built, each
one runs with mimica's own Python (MIMICA_PYTHON; `make docs` sets it to the project's venv: the
docs' venv has no mimica) and writes its picture into docs/gallery/img/; docs/gallery.md is then
written from the scripts and their pictures.  Both are made here, never committed.  A script
that fails fails the build.  A picture newer than its script and than the installed mimica is
kept.  (A hook of a few lines rather than mkdocs-gallery: the pictures are mimica's own renders,
not matplotlib figures that plugin's scrapers collect.)
"""

from __future__ import annotations

import ast
import os
import subprocess
from pathlib import Path

from mkdocs.exceptions import PluginError

HEAD = """# Gallery

Each picture here is made by the documentation's build from the script under it, with the
installed mimica on the shared data (`MIMICA_DATA`): run one yourself with
`python docs/gallery/NAME.py out.png`.
"""


def _python(root: Path) -> str:
    exe = os.environ.get("MIMICA_PYTHON") or str(root / ".venv" / "bin" / "python")
    if not Path(exe).is_file():
        raise PluginError(f"the gallery needs mimica's Python ({exe}): run `make docs`, which sets MIMICA_PYTHON")
    return exe


def _made(script: Path, png: Path, python: str, root: Path) -> None:
    stamp = root / ".venv" / ".wheel"
    newest = max(script.stat().st_mtime, stamp.stat().st_mtime if stamp.is_file() else 0.0)
    if png.is_file() and png.stat().st_mtime > newest:
        return
    png.parent.mkdir(parents=True, exist_ok=True)
    run = subprocess.run([python, str(script), str(png)], capture_output=True, text=True, timeout=900,
                         cwd=root)
    if run.returncode or not png.is_file():
        raise PluginError(f"gallery: {script.name} failed (exit status {run.returncode}):\n{run.stderr[-2000:]}")


def _entry(script: Path) -> str:
    tree = ast.parse(script.read_text(encoding="utf-8"))
    doc = ast.get_docstring(tree) or script.stem
    title, _, caption = doc.partition("\n\n")
    first = tree.body[1].lineno if len(tree.body) > 1 else 1          # the code after the docstring
    code = "\n".join(script.read_text(encoding="utf-8").splitlines()[first - 1:])
    return (f"## {title.strip()}\n\n{caption.strip()}\n\n![{title.strip()}](gallery/img/{script.stem}.png)\n\n"
            f"```python\n{code.strip()}\n```\n")


def on_pre_build(config, **kwargs):
    docs = Path(config["docs_dir"])
    root = Path(config["config_file_path"]).resolve().parent
    scripts = sorted((docs / "gallery").glob("*.py"))
    python = _python(root)
    for s in scripts:
        _made(s, docs / "gallery" / "img" / f"{s.stem}.png", python, root)
    page = HEAD + "".join("\n" + _entry(s) for s in scripts)
    target = docs / "gallery.md"
    if not target.is_file() or target.read_text(encoding="utf-8") != page:     # unchanged: serve does not loop
        target.write_text(page, encoding="utf-8")
