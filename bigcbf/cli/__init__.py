"""The ``bigcbf`` command line: one console script with subcommands.

Each subcommand is a module in this package with ``HELP`` (one line), ``add_arguments(parser)`` and
``run(args) -> int``. Modules import their heavy dependencies inside ``run`` so that ``bigcbf --help``
stays fast. User mistakes (``UserError``) print one clear line and exit 2; no traceback.
"""
from __future__ import annotations

import argparse
import importlib
import sys

from ..errors import UserError

#: Subcommands, in the order ``bigcbf --help`` lists them.
COMMANDS = ["scenarios", "methods", "run", "demo", "perf", "record", "calibrate", "replay", "profile", "bench"]


def build_parser() -> argparse.ArgumentParser:
    from .. import __version__

    parser = argparse.ArgumentParser(prog="bigcbf", description="BIG-CBF navigation in MuJoCo, with a digital twin.")
    parser.add_argument("--version", action="version", version=f"bigcbf {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in COMMANDS:
        mod = importlib.import_module(f"{__name__}.{name}")
        p = sub.add_parser(name, help=mod.HELP, description=mod.HELP)
        mod.add_arguments(p)
        p.set_defaults(_run=mod.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point; ``main([...])`` is testable without a subprocess. Returns the exit status."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse already printed the usage error
        return int(exc.code or 0)
    try:
        return int(args._run(args) or 0)
    except UserError as err:
        print(f"bigcbf {args.command}: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"bigcbf {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:              # the reader went away (e.g. `bigcbf run ... | head`): stop quietly
        import os
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141


if __name__ == "__main__":
    sys.exit(main())
