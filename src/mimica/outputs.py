"""Writing outputs safely (DESIGN.md, Conventions: a failed run leaves no half-written file).

- `atomic_path(FILE)`: write to a temporary file beside FILE, moved into place on success.
- `staged_dir(DIR)`: build a whole output folder beside DIR, which then replaces DIR in one
  step (an atomic exchange on Linux), so that a run that fails or is killed leaves either the
  previous output or the complete new one, never a mix of two runs.  A completed folder holds
  `.mimica-run.json`; a folder without it that holds files is the user's and is never replaced.
- `guard_outputs(inputs, outputs)`: refuse, before any work, an output that would overwrite
  or swallow an input.
- Every OS error while writing becomes one MimicaError naming the user's path.

Written here (not with a library) because the exchange of two folders needs renameat2, and
the rules above are mimica's own.
"""

from __future__ import annotations

import ctypes
import errno
import json
import os
import shutil
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

from .errors import MimicaError

MARKER = ".mimica-run.json"
_STAGE = ".mimica-stage-"


def os_error(path, e: OSError, doing="write") -> MimicaError:
    """One line for an OS error on the user's path, with what to do.

    Parameters
    ----------
    path : str or Path
    e : OSError
    doing : str
        "write", "read", ...

    Returns
    -------
    MimicaError
        To raise.
    """
    hint = {errno.ENOSPC: "free some disk space", errno.EDQUOT: "free some disk space",
            errno.EROFS: "the file system is read-only; choose another place",
            errno.EACCES: "check the folder's permissions", errno.EPERM: "check the folder's permissions",
            errno.ENOTDIR: "a part of the path is a file, not a folder",
            errno.EISDIR: "it is a folder; name a file", errno.ENAMETOOLONG: "use a shorter name",
            }.get(e.errno, "check the path")
    return MimicaError(f"{path}: cannot {doing} ({e.strerror or type(e).__name__}); {hint}")


def make_parent(path: Path) -> None:
    """Make a file's folder (and its parents); a part of the path that is a file, or an OS error, is
    one MimicaError naming the path.

    Parameters
    ----------
    path : Path
    """
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise MimicaError(f"{path}: cannot write (a part of the path is a file, not a folder)") from None
    except OSError as e:
        raise os_error(path, e) from None


@contextmanager
def atomic_path(path):
    """A context manager: a temporary path beside `path`, moved into place only on success.

    Parameters
    ----------
    path : str or Path
        The file to write (not a folder); its folder is made.

    Yields
    ------
    Path
        Where to write.
    """
    path = Path(path)
    if path.is_dir():
        raise MimicaError(f"{path}: is a folder; name a file to write")
    make_parent(path)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent)
        os.close(fd)
    except OSError as e:
        raise os_error(path, e) from None
    try:
        try:
            yield Path(tmp)
            os.chmod(tmp, file_mode())           # mkstemp makes 0600 files; use the usual mode
            os.replace(tmp, path)
        except OSError as e:
            raise os_error(path, e) from None
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def _umask() -> int:
    m = os.umask(0)
    os.umask(m)
    return m


def file_mode() -> int:
    """The mode a new file gets here (0666 less the umask): what a file written through a
    temporary one (mkstemp's 0600) is given before it is moved into place."""
    return 0o666 & ~_umask()


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _sweep(parent: Path, name: str) -> None:
    """Remove stages of `name` left by killed runs (their process is gone)."""
    try:
        for p in parent.glob(f".{name}{_STAGE}*"):
            try:
                pid = int(p.name[len(f".{name}{_STAGE}"):].split("-", 1)[0])
            except ValueError:
                continue
            if pid != os.getpid() and not _alive(pid):
                shutil.rmtree(p, ignore_errors=True)
    except OSError:
        pass


def _exchange(a: Path, b: Path) -> bool:
    """Swap two paths in one step (Linux renameat2 RENAME_EXCHANGE); False where unsupported."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        f = libc.renameat2
    except (OSError, AttributeError):
        return False
    at_fdcwd, rename_exchange = -100, 2
    if f(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), rename_exchange) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.ENOSYS, errno.EINVAL, errno.ENOTSUP):
        return False
    raise OSError(err, os.strerror(err), str(b))


def check_output_dir(path) -> Path:
    """An output folder mimica may replace: absent, empty, or a complete earlier run's.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    Path
        A MimicaError for a file, or for a folder of the user's (files without `.mimica-run.json`).
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise MimicaError(f"{path}: exists and is not a folder; name a folder for the output")
    if path.is_dir() and not (path / MARKER).is_file():
        try:
            used = any(path.iterdir())
        except OSError as e:
            raise os_error(path, e, "read") from None
        if used:
            raise MimicaError(f"{path}: the folder holds files that mimica did not write; name a new "
                              "or empty folder (an earlier mimica output folder is replaced whole)")
    return path


@contextmanager
def staged_dir(path, about: dict | None = None):
    """A context manager: an empty temporary folder beside `path`, which replaces `path` whole on
    success (an atomic exchange on Linux).

    Parameters
    ----------
    path : str or Path
        Checked by check_output_dir.
    about : dict or None
        Recorded in the completed folder's `.mimica-run.json`.

    Yields
    ------
    Path
        The folder to write into.
    """
    path = check_output_dir(path)
    make_parent(path)
    _sweep(path.parent, path.name)
    try:
        tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}{_STAGE}{os.getpid()}-", dir=path.parent))
    except OSError as e:
        raise os_error(path, e) from None
    try:
        try:
            yield tmp
            (tmp / MARKER).write_text(json.dumps({"complete": True, "time": time.time(), **(about or {})}))
            os.chmod(tmp, 0o777 & ~_umask())
            if path.exists():
                check_output_dir(path)                  # still ours: replace it in one step
                if not _exchange(tmp, path):
                    old = path.with_name(f".{path.name}{_STAGE}{os.getpid()}-old")
                    os.rename(path, old)
                    os.rename(tmp, path)
                    tmp = old
            else:
                os.rename(tmp, path)
        except OSError as e:
            raise os_error(path, e) from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _same(a: Path, b: Path) -> bool:
    try:
        return a.resolve() == b.resolve() or (a.exists() and b.exists() and os.path.samefile(a, b))
    except OSError:
        return False


def _inside(p: Path, folder: Path) -> bool:
    try:
        return p.resolve().is_relative_to(folder.resolve())
    except OSError:
        return False


def guard_outputs(inputs, outputs) -> None:
    """Refuse, before any work, outputs that would destroy an input: the same file, or a folder to be
    replaced that holds an input.

    Parameters
    ----------
    inputs : list of str or Path or None
    outputs : list of tuple
        (path, is_folder) pairs.
    """
    ins = [Path(p) for p in inputs if p is not None]
    for out, is_folder in outputs:
        if out is None:
            continue
        out = Path(out)
        for i in ins:
            if _same(out, i) or (is_folder and _inside(i, out)):
                raise MimicaError(f"{out}: is also an input ({i}); writing there would destroy it, "
                                  "name another output")
