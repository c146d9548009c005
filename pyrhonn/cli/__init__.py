"""The ``pyrhonn`` command line.

Each subcommand lives in its own module of this package and provides
``register(subparsers)``, which adds its parser and sets ``func`` to a
function ``(args) -> int`` (the exit code). Packages built on pyrhonn add
commands the same way through the entry-point group ``pyrhonn.commands``
(the ``hil`` harness registers ``pyrhonn hil`` so), which keeps the
dependencies pointing inward: pyrhonn never imports them by name. Errors the user can fix (bad
files, bad options) are reported as one line on stderr with exit code 2;
nothing is printed as a traceback.
"""
from __future__ import annotations

import argparse
import importlib
import os
import sys
from importlib.metadata import entry_points
from typing import Sequence

__all__ = ["main", "COMMANDS"]

# Subcommand modules, in the order ``pyrhonn --help`` lists them.
COMMANDS = ("info", "show_config", "identify", "reproduce", "tune", "select", "validate", "export")


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The parser of every command; with ``only`` (one of :data:`COMMANDS`), of that command alone:
    its module is the only one imported (the others, and the commands of installed packages, can take
    a second to import, more than a short run itself)."""
    parser = argparse.ArgumentParser(
        prog="pyrhonn",
        description="Real-time RHONN identifier trained by a per-neuron EKF (Alanis et al.).",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in COMMANDS if only is None else (only,):
        importlib.import_module(f"{__name__}.{name}").register(sub)
    for ep in sorted(entry_points(group="pyrhonn.commands"), key=lambda e: e.name) if only is None else ():
        ep.load().register(sub)
    return parser


def _version() -> str:
    from .. import __version__

    return __version__


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    module = argv[0].replace("-", "_") if argv else ""  # a command's module: show-config in show_config
    parser = build_parser(module if module in COMMANDS and argv[0] == module.replace("_", "-") else None)
    args = parser.parse_args(argv)
    try:
        return int(args.func(args))
    except BrokenPipeError:
        # the reader went away (``pyrhonn show-config x | head``): stop quietly, as a shell tool does,
        # and keep Python from failing again on flushing stdout at exit
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 128 + 13  # as if killed by SIGPIPE
    except (ValueError, OSError) as exc:
        print(f"pyrhonn {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"pyrhonn {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
