"""``hikbench export FILE --format soth|npz [--out PATH]``."""

from __future__ import annotations

import os
import sys

import numpy as np

from hikbench.problems.errors import HikbenchError, ProblemFileError
from hikbench.problems.files import load, save_npz
from hikbench.problems.soth import SOTH_NO_BOUND, soth_order, to_soth_text, write_soth_text

HELP = "convert a problem file to SOTH text or .npz"

_EXT = {"npz": ".npz", "soth": ".soth"}


def add_arguments(p) -> None:
    p.add_argument("file", help="problem file (.npz or SOTH text)")
    p.add_argument("--format", required=True, choices=sorted(_EXT), help="output format")
    p.add_argument("--out", metavar="PATH",
                   help="output file (default: FILE with the extension .soth or .npz; "
                        "'-' prints SOTH text on stdout)")


def default_out(path: str, fmt: str) -> str:
    root, ext = os.path.splitext(path)
    return (root if ext in (".npz", ".soth", ".txt") else path) + _EXT[fmt]


def soth_losses(h) -> list[str]:
    """What a SOTH export of h drops or changes, and what SOTH's own reader
    would refuse (see hikbench.problems.soth)."""
    notes = []
    if h.names != tuple(f"level {k}" for k in range(h.depth)):
        notes.append("level names are dropped")
    if h.x0 is not None:
        notes.append("x0 is dropped")
    if soth_order(h) != h:
        notes.append("rows are reordered (equality rows first in each level)")
    if h.is_free.any():
        notes.append(f"{int(h.is_free.sum())} free row(s), which SOTH's own reader refuses")
    if (h.rows_per_level == 0).any():
        notes.append("empty level(s), which SOTH's own reader refuses")
    ineq = ~h.is_equality
    dropped = int(np.sum(ineq & np.isfinite(h.lower) & (h.lower < -SOTH_NO_BOUND))
                  + np.sum(ineq & np.isfinite(h.upper) & (h.upper > SOTH_NO_BOUND)))
    if dropped:
        notes.append(f"{dropped} finite inequality bound(s) beyond +-{SOTH_NO_BOUND:g}, "
                     "which SOTH's own reader takes as no bound")
    return notes


def run(args) -> int:
    h = load(args.file)
    text = ""
    if args.format == "soth":
        try:
            text = to_soth_text(h)  # (a finite bound beyond +-1e25 cannot be written)
        except ProblemFileError as err:
            raise ProblemFileError(f"{args.file}: cannot be written as SOTH text: {err}") from err
    out = args.out or default_out(args.file, args.format)
    if out == "-":
        if args.format != "soth":
            raise HikbenchError("--out - (stdout) is only for --format soth")
        sys.stdout.write(text)
        _note(h)
        return 0
    if os.path.exists(out) and os.path.samefile(out, args.file):
        raise HikbenchError(f"--out {out} is the input file; choose another path")
    if args.format == "npz":
        if not out.endswith(".npz"):
            raise HikbenchError(f"--out {out}: an .npz problem file must end in .npz "
                                "(files are read by extension)")
        save_npz(h, out)
    else:
        if out.endswith(".npz"):
            raise HikbenchError(f"--out {out}: a SOTH text file must not end in .npz "
                                "(files are read by extension)")
        write_soth_text(text, out)
        _note(h)
    print(out)
    return 0


def _note(h) -> None:
    """After a successful SOTH export: one line on stderr saying what changed."""
    notes = soth_losses(h)
    if notes:
        print(f"hikbench export: note: {'; '.join(notes)}", file=sys.stderr)
