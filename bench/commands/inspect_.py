"""``hikbench inspect FILE``: rows, ranks and conditioning per level."""

from __future__ import annotations

import json
import math

from hikbench.problems.analysis import level_structure
from hikbench.problems.files import load

HELP = "show rows, rank and conditioning of each level of a problem file"

_COLUMNS = (  # header, LevelStructure attribute, format
    ("level", "level", "d"), ("name", "name", "s"), ("rows", "rows", "d"), ("eq", "equalities", "d"),
    ("1-sided", "one_sided", "d"), ("2-sided", "two_sided", "d"), ("free", "free", "d"),
    ("rank", "rank", "d"), ("cond", "cond", ".3g"), ("proj rank", "projected_rank", "d"),
    ("proj sv min", "projected_sv_min", ".3g"), ("proj cond", "projected_cond", ".3g"),
    ("conflicts", "conflicts", "d"),
)


def add_arguments(p) -> None:
    p.add_argument("file", help="problem file (.npz or SOTH text)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of a table")


def _cell(value, fmt: str) -> str:
    if isinstance(value, float) and math.isnan(value):
        return "-"
    if isinstance(value, str):  # (a level name holding a line break or a control character: escaped, so
        # that it cannot start a line of its own in the table)
        return "".join(c if c.isprintable() else repr(c)[1:-1] for c in value)
    return format(value, fmt)


def run(args) -> int:
    h = load(args.file)
    levels = level_structure(h)
    if args.json:
        print(json.dumps({"file": args.file, "n": h.n, "depth": h.depth, "rows": h.rows, "levels": [
            {attr: (None if isinstance(v := getattr(L, attr), float) and math.isnan(v) else v)
             for _, attr, _ in _COLUMNS} for L in levels]}))
        return 0
    n_eq = int(h.is_equality.sum())
    n_free = int(h.is_free.sum())
    print(f"{args.file}: n = {h.n}, depth = {h.depth}, rows = {h.rows} "
          f"({n_eq} equality, {h.rows - n_eq - n_free} inequality, {n_free} free), "
          f"total rank = {sum(L.projected_rank for L in levels)}")
    table = [[head for head, _, _ in _COLUMNS]]
    table += [[_cell(getattr(L, attr), fmt) for _, attr, fmt in _COLUMNS] for L in levels]
    widths = [max(len(row[j]) for row in table) for j in range(len(_COLUMNS))]
    for row in table:
        print("  ".join(c.ljust(w) if j == 1 else c.rjust(w) for j, (c, w) in enumerate(zip(row, widths))))
    print("cond: largest / smallest nonzero singular value of the level's constraint rows; "
          "proj: of the level "
          "projected in the null space of all rows above; conflicts = rank - proj rank")
    if h.rows - n_eq - n_free:
        print("(inequality rows above a level count as active there: its proj rank is a lower bound, its "
              "conflicts an upper bound of what the optimum's active set leaves; a box on every "
              "variable makes every level below it 'conflicting')")
    return 0
