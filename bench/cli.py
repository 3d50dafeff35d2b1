"""The ``hikbench`` command line.

One module per sub-command in ``bench/commands/``; each defines ``HELP``,
``add_arguments(parser)`` and ``run(args) -> int``. User mistakes
(:class:`~problems.errors.HikbenchError`) print one line on stderr and exit 2;
anything else is a bug and keeps its traceback.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from problems.errors import HikbenchError

# sub-command name -> module in bench.commands
COMMANDS: dict[str, str] = {
    "solve": "solve",
    "list": "list_",
    "scenario": "scenario",
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="hikbench", description="Benchmark of hierarchized (prioritized) inverse kinematics solvers.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, modname in COMMANDS.items():
        mod = importlib.import_module(f"bench.commands.{modname}")
        p = sub.add_parser(name, help=mod.HELP, description=mod.HELP)
        mod.add_arguments(p)
        p.set_defaults(_run=mod.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code (0 ok, 1 a check failed, 2 user error)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args._run(args) or 0)
    except HikbenchError as err:
        print(f"hikbench {args.command}: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"hikbench {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
