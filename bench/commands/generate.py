"""``hikbench generate FAMILY [--seed S] [--seeds N] [--param KEY=VALUE ...] --out DIR
[--format npz|soth]``: write problems of a named family to files."""

from __future__ import annotations

import json
import os
import re

from hikbench.problems.errors import HikbenchError, ProblemFileError, UnknownFamilyError
from hikbench.problems.files import save_npz
from hikbench.problems.generators import all_families, generate
from hikbench.problems.soth import save_soth

HELP = "generate problems of a named family (see `hikbench list families`) into files"

_EXT = {"npz": ".npz", "soth": ".soth"}


def add_arguments(p) -> None:
    p.add_argument("family", help="family name (see `hikbench list families`)")
    p.add_argument("--seed", type=int, default=0, help="first seed (default 0)")
    p.add_argument("--seeds", type=int, default=1, metavar="N",
                   help="number of problems, seeds S .. S+N-1 (default 1)")
    p.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                   help="family parameter (repeatable); VALUE is parsed as JSON when it can be "
                        "(3, 1e-3, [2, 3], true, null), else taken as a string")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory (created if missing)")
    p.add_argument("--format", choices=sorted(_EXT), default="npz", help="file format (default npz)")


def parse_params(items: list[str], defaults: dict) -> dict:
    """``["n=20", "inequality=mixed"]`` -> ``{"n": 20, "inequality": "mixed"}``: each
    VALUE read as JSON where it parses, else as a string; an integer given for a
    parameter whose default is a float becomes that float (``cond=2`` is ``cond=2.0``,
    in the file name too). The names and the values are the family's to check
    (:meth:`hikbench.problems.family.Family.check_params`, its generator)."""
    out = {}
    for item in items:
        key, sep, text = item.partition("=")
        if not sep or not key:
            raise HikbenchError(f"--param {item!r}: expected KEY=VALUE")
        try:
            value = json.loads(text)
        except json.JSONDecodeError:
            value = text
        if isinstance(defaults.get(key), float) and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        out[key] = value
    return out


def _tag(v) -> str:
    if isinstance(v, (list, tuple)):
        return ",".join(_tag(e) for e in v)
    return v if isinstance(v, str) else json.dumps(v)


def file_name(family: str, params: dict, seed: int, fmt: str) -> str:
    """``<family>[-<key>=<value>...]-seed<seed>.<ext>``, parameters sorted, a
    list written ``a,b,c``, characters other than letters, digits and
    ``._=+,-`` replaced by ``_``."""
    tag = "".join(f"-{k}={_tag(v)}" for k, v in sorted(params.items()))
    return re.sub(r"[^A-Za-z0-9._=+,-]", "_", f"{family}{tag}-seed{seed}") + _EXT[fmt]


def run(args) -> int:
    families = all_families()
    if args.family not in families:
        raise UnknownFamilyError(f"unknown family {args.family!r}; expected one of {', '.join(families)}")
    if args.seed < 0:
        raise HikbenchError(f"--seed must be an integer >= 0; got {args.seed}")
    if args.seeds < 1:
        raise HikbenchError(f"--seeds must be >= 1; got {args.seeds}")
    params = families[args.family].check_params(parse_params(args.param, families[args.family].defaults))
    try:
        os.makedirs(args.out, exist_ok=True)
    except OSError as err:
        why = err.strerror or err
        raise ProblemFileError(f"--out {args.out}: cannot create the directory ({why})") from err
    save = save_npz if args.format == "npz" else save_soth
    for seed in range(args.seed, args.seed + args.seeds):
        h = generate(args.family, seed=seed, **params)
        path = os.path.join(args.out, file_name(args.family, params, seed, args.format))
        save(h, path)
        print(path)
    return 0
