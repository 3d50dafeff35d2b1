"""The ``hikbench`` command line.

One module per sub-command in ``bench/commands/``; each defines ``HELP``,
``add_arguments(parser)`` and ``run(args) -> int``. User mistakes
(:class:`~hikbench.problems.errors.HikbenchError`, and command lines argparse rejects)
print one line on stderr and exit 2, as do a MemoryError (sizes beyond the
machine) and a missing optional dependency (the line names the extra that
installs it: :mod:`hikbench.extras`); ``--help`` and ``--version`` exit 0;
anything else is a bug and keeps its traceback.
"""

from __future__ import annotations

import argparse
import errno
import importlib
import os
import signal
import sys

from hikbench import __version__
from hikbench.bench.signals import Terminated, sigterm_as_interrupt
from hikbench.extras import extra_for, install_hint
from hikbench.problems.errors import HikbenchError

# sub-command name -> its module (each name written out: tests/test_layering.py sees these imports)
COMMANDS: dict[str, str] = {
    "solve": "hikbench.bench.commands.solve",
    "generate": "hikbench.bench.commands.generate",
    "inspect": "hikbench.bench.commands.inspect_",
    "export": "hikbench.bench.commands.export",
    "list": "hikbench.bench.commands.list_",
    "run": "hikbench.bench.commands.run",
    "report": "hikbench.bench.commands.report",
    "compare": "hikbench.bench.commands.compare",
    "regress": "hikbench.bench.commands.regress",
    "claims": "hikbench.bench.commands.claims",
    "columns": "hikbench.bench.commands.columns",
    "scenario": "hikbench.bench.commands.scenario",
    "certify": "hikbench.bench.commands.certify",
    "warmup": "hikbench.bench.commands.warmup",
    "testset": "hikbench.bench.commands.testset",
}


class UsageError(HikbenchError):
    """A command line argparse rejects (unknown option, missing argument);
    ``prog`` is the (sub-)command whose line it is: ``hikbench solve``."""

    def __init__(self, message: str, prog: str = "hikbench"):
        super().__init__(f"{message} (see `{prog} --help`)")
        self.prog = prog


class _Parser(argparse.ArgumentParser):
    """argparse that raises UsageError instead of printing usage and exiting,
    so that main() reports it like any user error: one line, exit code 2.
    No abbreviations: ``hikbench run --solver a`` read as ``--solvers a``
    while ``scenario`` has a ``--solver`` of its own; a misspelt option is
    named, not taken for another."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **{**kwargs, "allow_abbrev": False})

    def error(self, message: str):
        raise UsageError(message, self.prog)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="hikbench", description="Benchmark of hierarchized (prioritized) inverse kinematics solvers.")
    parser.add_argument("--version", action="version", version=f"hikbench {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, modname in COMMANDS.items():
        mod = importlib.import_module(modname)
        p = sub.add_parser(name, help=mod.HELP, description=mod.HELP)
        mod.add_arguments(p)
        p.set_defaults(_run=mod.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code (0 ok, 1 a check failed, 2 user error)."""
    parser = build_parser()
    try:
        args, extra = parser.parse_known_args(argv)
        if extra:  # (parse_args would name the top-level parser, not the sub-command)
            raise UsageError(f"unrecognized arguments: {' '.join(extra)}", f"hikbench {args.command}")
    except UsageError as err:
        print(f"{err.prog}: error: {_one_line(err)}", file=sys.stderr)
        return 2
    except SystemExit as stop:  # --help / --version print and stop
        return stop.code if isinstance(stop.code, int) else 0
    try:
        with sigterm_as_interrupt():
            code = int(args._run(args) or 0)
            sys.stdout.flush()  # (here, where a full device is one line, not at the interpreter's exit)
            return code
    except Terminated:
        print(f"hikbench {args.command}: terminated (SIGTERM)", file=sys.stderr)
        return 128 + signal.SIGTERM
    except HikbenchError as err:
        print(f"hikbench {args.command}: error: {_one_line(err)}", file=sys.stderr)
        return 2
    except ModuleNotFoundError as err:
        if extra_for(err.name) is None:  # not an optional dependency: a bug, with its traceback
            raise
        print(f"hikbench {args.command}: error: {install_hint(err.name)}", file=sys.stderr)
        return 2
    except MemoryError as err:  # sizes asked for beyond the machine (generate --param rows=1e12)
        print(f"hikbench {args.command}: error: out of memory ({_one_line(err) or 'MemoryError'}); "
              f"expected sizes this machine can hold", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"hikbench {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # output piped into `head`: stop quietly
        _stdout_to_devnull()
        return 0
    except OSError as err:
        if err.errno not in _NO_SPACE:  # a bug, with its traceback
            raise
        where = f" writing {err.filename}" if err.filename else " writing the output"
        if err.filename is None:  # (stdout itself: what is left in its buffer cannot be written either)
            _stdout_to_devnull()
        print(f"hikbench {args.command}: error: {err.strerror or 'no space left'}{where}; free space and "
              f"run it again", file=sys.stderr)
        return 2


#: errno values of a write that found no space: a full device, a quota, a file too large
_NO_SPACE = frozenset(getattr(errno, name) for name in ("ENOSPC", "EDQUOT", "EFBIG") if hasattr(errno, name))


def _stdout_to_devnull() -> None:
    """Point fd 1 at /dev/null: Python's flush of stdout at exit then finds nothing to fail on."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    os.close(devnull)


def _one_line(err: Exception) -> str:
    return " ".join(str(err).splitlines())


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
