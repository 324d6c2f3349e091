"""The `mimica` command line: one module a command (`add_args(sub)` puts its options on the
parser, `run(args)` parses nothing more, calls the pipeline and prints).  User errors print one
line and exit 2; nothing half-written."""

from __future__ import annotations

import argparse
import sys

from ..errors import MimicaError
from . import (age, animate, batch, blender_addon, blendshapes, demo, error, export, fit_muscles, landmarks, render, rig, simulate,
               transfer, transfer_image, view, wrinkle_mask)
from ._checks import check_numbers, check_paths

COMMANDS = (transfer, error, fit_muscles, rig, simulate, wrinkle_mask, age, transfer_image, landmarks, render, export,
            animate, blendshapes, blender_addon, view, batch, demo)


class _Parser(argparse.ArgumentParser):
    """argparse whose refusals are one line, like every other error of the command line."""

    def error(self, message):
        self.exit(2, f"mimica: error: {' '.join(message.split())} (see `{self.prog} --help`)\n")


def build_parser() -> argparse.ArgumentParser:
    """The parser of every command, in the order `mimica --help` lists them.

    Returns
    -------
    argparse.ArgumentParser
    """
    p = _Parser(prog="mimica", description="Anatomy-aware facial animation toolkit.")
    sub = p.add_subparsers(dest="cmd", required=True)
    for command in COMMANDS:
        command.add_args(sub)
    return p


def _terminate(signum, frame):
    raise KeyboardInterrupt          # SIGTERM unwinds like Ctrl-C: stages and temporary files go


def main(argv=None) -> int:
    """Run the `mimica` command line (a MimicaError: one line on stderr, exit status 2).

    Parameters
    ----------
    argv : list of str or None

    Returns
    -------
    int
    """
    import signal
    from .._memory import keep_memory
    from ..outputs import os_error
    args = build_parser().parse_args(argv)
    keep_memory()
    try:
        previous = signal.signal(signal.SIGTERM, _terminate)
    except ValueError:                                     # not the main thread (tests, embedding)
        previous = None
    try:
        check_numbers(args)
        check_paths(args)
        return int(args.func(args) or 0)
    except MimicaError as e:
        print(f"mimica: error: {_one_line(e)}", file=sys.stderr)
        return 2
    except OSError as e:                                   # an OS error no command turned into ours
        print(f"mimica: error: {_one_line(os_error(e.filename or '?', e, 'read or write'))}", file=sys.stderr)
        return 2
    except MemoryError:
        print("mimica: error: out of memory; the input is too large for this machine", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("mimica: interrupted; nothing of this run was kept", file=sys.stderr)
        return 130
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


def _one_line(e) -> str:
    return " ".join(str(e).split())


