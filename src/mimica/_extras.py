"""Optional parts of mimica (pyproject's extras): a missing one is a one-line error naming it."""

from __future__ import annotations

import importlib

from .errors import MimicaError


def require(module: str, extra: str, what: str):
    """Import an optional module, or raise MimicaError naming the extra that brings it."""
    try:
        return importlib.import_module(module)
    except ImportError:
        raise MimicaError(f"{what} needs the optional package {module!r}, which is not installed: "
                          f"pip install 'mimica[{extra}]'") from None
