"""The `eas-vo` command: its parser (one module a command, each `add_parser(subparsers)` and
`run(args)`) and the one boundary where errors and interrupts become a line and an exit code.

User errors (bad data, bad config) end in one line on stderr and exit code 2; Ctrl-C and
SIGTERM in one line saying what was kept, and exit code 130 / 143. Heavy modules are imported
inside the commands, so `--help` is instant."""

from __future__ import annotations

import argparse
import importlib
import os
import sys

from eas_vo import __version__
from eas_vo.errors import EasVoError, Interrupted, UsageError, sigterm_as_interrupt
from eas_vo.logs import to_stderr

#: The commands, in the order `eas-vo --help` lists them: each a module of this package.
COMMANDS = (
    "run",
    "compare",
    "list",
    "info",
    "render",
    "export",
    "slam",
    "vocabulary",
    "convert",
    "evaluate",
    "view",
    "reproduce",
    "fetch",
    "cache",
    "simulate",
)


def main(argv: list[str] | None = None) -> int:
    """The `eas-vo` command on `argv` (default: the process's); returns the exit status: 0, 1 for
    an error in the data, the configuration or the machine's answer (one line on stderr), 2 for a
    usage error (options that cannot be read or go together), 130 / 143 for Ctrl-C / SIGTERM,
    141 for a closed pipe."""
    to_stderr()  # the library's log records reach stderr here, and only here
    args = build_parser().parse_args(argv)
    try:
        with sigterm_as_interrupt():
            return args.func(args)
    except EasVoError as exc:
        print(f"eas-vo: error: {exc}", file=sys.stderr)
        return 2 if isinstance(exc, UsageError) else 1
    except BrokenPipeError:  # `eas-vo list | head`: the reader left; say nothing more
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
    except OSError as exc:  # the machine's answer to a user's request (a full disk, a path in the way)
        where = f" ({exc.filename})" if exc.filename else ""
        print(f"eas-vo: error: {exc.strerror or exc}{where}", file=sys.stderr)
        return 1
    except KeyboardInterrupt as exc:  # the one place: a command says what it kept in Interrupted
        kept = exc.kept if isinstance(exc, Interrupted) and exc.kept else "nothing was written"
        print(f"eas-vo {args.command}: interrupted; {kept}", file=sys.stderr)
        return 143 if isinstance(exc, Interrupted) and exc.sigterm else 130


class _OneLineParser(argparse.ArgumentParser):
    """A usage error is one line on stderr (with where to read more) and exit status 2."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    """The command line's parser: a subcommand a module of COMMANDS."""
    parser = _OneLineParser(
        prog="eas-vo",
        description="3-DoF rotation estimation from event cameras fused with frames (EAS and peers).",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=_OneLineParser)
    for name in COMMANDS:
        importlib.import_module(f"eas_vo.cli.{name}").add_parser(sub)
    return parser
