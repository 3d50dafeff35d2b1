"""The command-line reference, generated from the argparse parser.

:func:`markdown` walks :func:`hikbench.bench.cli.build_parser`: the program's
description, then every sub-command with its help, its usage line and a table
of its arguments (help, default). ``docs/cli.md`` is its output, verbatim::

    python -m hikbench.bench.clidoc > docs/cli.md

(``tests/test_docs.py`` checks that the two agree.) The text depends on the
parser alone, not on the terminal's width.
"""

from __future__ import annotations

import argparse

from hikbench.bench.cli import build_parser

__all__ = ["markdown"]

_WIDE = 10_000  # a usage line never wraps

_EXIT_CODES = """\
## Exit codes

| code | meaning |
|---|---|
| 0 | success |
| 1 | a command's verdict: `solve` (the solver ended in status `error`, `crashed` or `timeout`), `compare` (a case SLOWER, NEWLY FAILING or MISSING), `claims` (a claim FAIL, or MISSING without `--allow-missing`) |
| 2 | a user error: one line on stderr, `hikbench COMMAND: error: ...`, no traceback (a bad command line, a missing or malformed file, an unknown solver, family, option or parameter, a missing optional dependency: the line names the extra to install, a size beyond the machine's memory) |
| 130 | `run` interrupted (Ctrl-C); the rows written so far are kept; `solve` interrupted, its worker process killed |
| 143 | `run` terminated (SIGTERM); the rows written so far are kept; `solve` terminated, its worker process killed |

Any other code, or a traceback, is a bug in hikbench."""


def _formatter(prog: str) -> argparse.HelpFormatter:
    return argparse.HelpFormatter(prog, width=_WIDE, max_help_position=_WIDE)


def _cell(text: str) -> str:
    """One table cell: one line, ``|`` escaped."""
    return " ".join(str(text).split()).replace("|", "\\|")


def _usage(parser: argparse.ArgumentParser) -> str:
    fmt = _formatter(parser.prog)
    fmt.add_usage(parser.usage, parser._actions, parser._mutually_exclusive_groups, prefix="")
    return " ".join(fmt.format_help().split())


def _default(action: argparse.Action) -> str:
    if action.required or (not action.option_strings and action.nargs not in ("?", "*")):
        return "required"
    if isinstance(action, (argparse._StoreTrueAction, argparse._StoreFalseAction)):
        return "off"
    if action.default is None or action.default == [] or action.default is argparse.SUPPRESS:
        return "-"
    return f"`{action.default}`"


def _arguments(parser: argparse.ArgumentParser) -> list[str]:
    fmt = _formatter(parser.prog)
    lines = ["| argument | meaning | default |", "|---|---|---|"]
    for action in parser._actions:
        if isinstance(action, argparse._HelpAction):
            continue
        invocation = fmt._format_action_invocation(action)
        help_text = fmt._expand_help(action) if action.help else ""
        lines.append(f"| `{_cell(invocation)}` | {_cell(help_text)} | {_default(action)} |")
    return lines


def _subcommands(parser: argparse.ArgumentParser) -> list[tuple[str, str, argparse.ArgumentParser]]:
    """(name, help, parser) of every sub-command, in the parser's order."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {a.dest: a.help for a in action._choices_actions}
            return [(name, helps.get(name, ""), p) for name, p in action.choices.items()]
    return []


def markdown() -> str:
    """The command-line reference as markdown (the text of ``docs/cli.md``)."""
    parser = build_parser()
    subs = _subcommands(parser)
    out = [
        "# Command-line reference",
        "",
        "<!-- Generated from the argparse parser: `python -m hikbench.bench.clidoc > docs/cli.md`."
        " Do not edit by hand; tests/test_docs.py checks it. -->",
        "",
        _cell(parser.description or ""),
        "",
        f"    {_usage(parser)}",
        "",
        "`hikbench --version` prints the version; `hikbench COMMAND --help` prints a command's options."
        " `python -m hikbench` is the same program.",
        "",
        "| command | what it does |",
        "|---|---|",
    ]
    out += [f"| [`{name}`](#hikbench-{name}) | {_cell(help_text)} |" for name, help_text, _ in subs]
    for name, help_text, sub in subs:
        out += ["", f"## hikbench {name}", "", _cell(sub.description or help_text), "", f"    {_usage(sub)}", ""]
        out += _arguments(sub)
    out += ["", _EXIT_CODES]
    return "\n".join(out) + "\n"


if __name__ == "__main__":  # pragma: no cover
    print(markdown(), end="")
