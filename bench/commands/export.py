"""``hikbench export FILE --format soth|npz [--out PATH]``."""

from __future__ import annotations

import os
import sys

from problems.errors import HikbenchError
from problems.files import load, save_npz
from problems.soth import save_soth, to_soth_text

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


def run(args) -> int:
    h = load(args.file)
    out = args.out or default_out(args.file, args.format)
    if out == "-":
        if args.format != "soth":
            raise HikbenchError("--out - (stdout) is only for --format soth")
        sys.stdout.write(to_soth_text(h))
        return 0
    if os.path.exists(out) and os.path.samefile(out, args.file):
        raise HikbenchError(f"--out {out} is the input file; choose another path")
    if args.format == "npz":
        if not out.endswith(".npz"):
            raise HikbenchError(f"--out {out}: an .npz problem file must end in .npz (files are read by extension)")
        save_npz(h, out)
    else:
        if out.endswith(".npz"):
            raise HikbenchError(f"--out {out}: a SOTH text file must not end in .npz (files are read by extension)")
        save_soth(h, out)
    print(out)
    return 0
