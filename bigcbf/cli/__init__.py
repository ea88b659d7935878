"""The ``bigcbf`` command line: one console script with subcommands.

Each subcommand is a module in this package with ``HELP`` (one line), ``add_arguments(parser)`` and
``run(args) -> int``. Modules import their heavy dependencies inside ``run`` so that ``bigcbf --help``
stays fast. User mistakes (``UserError``) print one clear line and exit 2; no traceback.
"""
from __future__ import annotations

import argparse
import errno
import importlib
import os
import sys

from ..errors import UserError

#: Subcommands, in the order ``bigcbf --help`` lists them.
COMMANDS = ["scenarios", "methods", "run", "demo", "perf", "record", "calibrate", "replay", "profile", "bench", "sim",
            "filter", "tune"]


class _Parser(argparse.ArgumentParser):
    """argparse with a one-line usage error: ``bigcbf run: error: argument --seed: ... (see bigcbf run --help)``,
    exit status 2 (argparse's default prints the whole usage block first)."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    from .. import __version__

    parser = _Parser(prog="bigcbf", description="BIG-CBF navigation in MuJoCo, with a digital twin.")
    parser.add_argument("--version", action="version", version=f"bigcbf {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    for name in COMMANDS:
        mod = importlib.import_module(f"{__name__}.{name}")
        p = sub.add_parser(name, help=mod.HELP, description=mod.HELP)
        mod.add_arguments(p)
        p.set_defaults(_run=mod.run)
    return parser


#: errno values of an output or input the environment refuses (not a bug of bigcbf): one line, exit status 2
_ENVIRONMENT_ERRNOS = {errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EACCES, errno.EPERM, errno.EFBIG,
                       errno.ENAMETOOLONG, errno.ENOTDIR, errno.ELOOP, errno.EISDIR}

#: exit status after stdout was closed by the reader (``bigcbf scenarios | head -1``): 128 + SIGPIPE, what a
#: shell reports for a program that a closed pipe stopped
EXIT_CLOSED_PIPE = 141


def _stdout_closed() -> bool:
    """Whether stdout is a pipe whose reader has gone (poll reports an error on its write end)."""
    import select
    try:
        fd = sys.stdout.fileno()
        poller = select.poll()
        poller.register(fd, select.POLLOUT)
        return any(ev & (select.POLLERR | select.POLLHUP) for _, ev in poller.poll(0))
    except (AttributeError, ValueError, OSError):
        return False


def main(argv: list[str] | None = None) -> int:
    """Entry point; ``main([...])`` is testable without a subprocess. Returns the exit status.

    User mistakes (``UserError``) and an environment that refuses a file (a read-only or full file system, a
    missing permission) are one line on stderr and exit status 2; a reader that closes stdout early ends the
    command quietly (exit status 141)."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse already printed the usage error
        return int(exc.code or 0)
    from .run import flush_notes
    flush_notes(False)
    try:
        status = int(args._run(args) or 0)
        sys.stdout.flush()               # a closed pipe shows here, inside the handlers below
        flush_notes(status == 0)         # remarks after a success only: a failure's message stays one line
        return status
    except UserError as err:
        flush_notes(False)
        print(f"bigcbf {args.command}: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        flush_notes()
        print(f"bigcbf {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        if _stdout_closed():
            # nothing more can be printed; point stdout at /dev/null so that the interpreter's final flush is
            # quiet too (the recipe of the Python documentation, "Note on SIGPIPE")
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
            os.close(devnull)
            return EXIT_CLOSED_PIPE
        raise
    except OSError as exc:
        if exc.errno not in _ENVIRONMENT_ERRNOS:
            raise
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"bigcbf {args.command}: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
