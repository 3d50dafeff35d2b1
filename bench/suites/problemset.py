"""Problems of a suite: deterministic generation from (family, params, seed),
ids, files under OUT/problems/, and the descriptive columns of a problem.

A family is a name of ``hikbench.problems.generators.all_families()`` or a ``module:function``
path (``function(seed=..., **params) -> Hierarchy``; also ``path/to/file.py:function``),
so a user or a test can bring its own generator without touching the library.
"""

from __future__ import annotations

import json
import os
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hikbench.bench.harness.cache import problem_hash
from hikbench.bench.specs import load_object, raised_text
from hikbench.problems.errors import HikbenchError
from hikbench.problems.hierarchy import Hierarchy

__all__ = ["ProblemSpec", "file_stem", "generate", "load_object", "problem_columns", "save_problem", "save_problems"]


def _fmt(v) -> str:
    if isinstance(v, float) and v.is_integer():
        return str(v)
    if isinstance(v, (list, tuple)):
        return "[" + ";".join(_fmt(u) for u in v) + "]"
    return str(v)


@dataclass(frozen=True)
class ProblemSpec:
    """One problem of a suite: ``generate(family, seed, **params)``."""

    family: str
    params: dict = field(default_factory=dict)
    seed: int = 0

    @property
    def family_name(self) -> str:
        """The family as shown in ids: a ``dir/file.py:func`` path loses its directory."""
        mod, sep, attr = self.family.rpartition(":")
        return f"{os.path.basename(mod)}:{attr}" if sep and mod.endswith(".py") else self.family

    @property
    def id(self) -> str:
        """``family/k=v,k=v/seed=S`` with the parameters sorted by name;
        ``family/seed=S`` without parameters (the family's defaults)."""
        p = ",".join(f"{k}={_fmt(self.params[k])}" for k in sorted(self.params))
        return f"{self.family_name}/{p}/seed={self.seed}" if p else f"{self.family_name}/seed={self.seed}"

    def params_json(self) -> str:
        return json.dumps(self.params, sort_keys=True)


def file_stem(problem_id: str) -> str:
    """A file name for a problem id (no directory separators)."""
    return re.sub(r"[^\w=,.;\[\]+-]", "_", problem_id.replace("/", "__"))


def generate(spec: ProblemSpec) -> Hierarchy:
    """The hierarchy of ``spec``; same (family, params, seed), same problem."""
    if ":" in spec.family:
        return _user_family(spec)
    try:
        from hikbench.problems import generators
    except ModuleNotFoundError as err:
        raise HikbenchError(f"family {spec.family!r}: hikbench.problems.generators is not available ({err})") from err
    families = generators.all_families()
    if spec.family not in families:
        from hikbench.problems.errors import UnknownFamilyError
        raise UnknownFamilyError(f"unknown problem family {spec.family!r} "
                                 f"(known: {', '.join(families)})")
    try:
        return generators.generate(spec.family, seed=spec.seed, **spec.params)
    except TypeError as err:
        raise HikbenchError(f"problem {spec.id}: bad parameters for family {spec.family!r} ({err})") from err


def _user_family(spec: ProblemSpec) -> Hierarchy:
    """The hierarchy of a ``module:function`` family; a function that is not one,
    raises, or returns anything but a Hierarchy is a HikbenchError naming the
    family, the seed and what it did."""
    func = load_object(spec.family)
    where = f"family {spec.family!r}, seed {spec.seed}"
    if not callable(func):
        raise HikbenchError(f"{where}: {type(func).__name__} is not a function; expected "
                            "function(seed=..., **params) -> Hierarchy")
    try:
        h = func(seed=spec.seed, **spec.params)
    except Exception as err:  # noqa: BLE001 - the user's generator failed: name it, no traceback
        raise HikbenchError(f"{where}: calling it raised {raised_text(err)}") from err
    if not isinstance(h, Hierarchy):
        raise HikbenchError(f"{where}: returned {type(h).__name__}; expected a "
                            "hikbench.problems.hierarchy.Hierarchy")
    return h


def _family(spec: ProblemSpec) -> str:
    """The family column: the family's name; for a test set's problem, ``<set>:<its family>``
    (``hlsp-1:robot:reach``), so that a report ranks per family of the set."""
    if spec.family == "testset":
        from hikbench.problems.testset import entry_family
        return entry_family(spec.params.get("set", "hlsp-1"), spec.params.get("problem", ""))
    return spec.family_name


def problem_columns(spec: ProblemSpec, h: Hierarchy) -> dict:
    """The problem's descriptive columns of results.csv (see hikbench.bench.harness.columns)."""
    rows_per_level = np.diff(h.starts).tolist()
    eq = h.lower == h.upper
    free = ~np.isfinite(h.lower) & ~np.isfinite(h.upper)
    ranks = []
    for k in range(h.depth):
        Ak = h.A[h.level_rows(k)]
        ranks.append(int(np.linalg.matrix_rank(Ak)) if Ak.size else 0)
    return {
        "problem": spec.id,
        "problem_hash": problem_hash(h),
        "family": _family(spec),
        "params": spec.params_json(),
        "seed": spec.seed,
        "n": h.n,
        "depth": h.depth,
        "rows": h.rows,
        "eq_rows": int(eq.sum()),
        "ineq_rows": int((~eq & ~free).sum()),
        "rows_per_level": json.dumps(rows_per_level),
        "ranks": json.dumps(ranks),
        "rank": int(np.linalg.matrix_rank(h.A)) if h.A.size else 0,
    }


def _stored(path: Path):
    """The hierarchy in the problem file ``path``, or None when it cannot be
    read, which a line on stderr says (it will be written again)."""
    from hikbench.problems.files import load_npz

    try:
        return load_npz(path)
    except HikbenchError as err:
        print(f"hikbench run: {path} cannot be read ({' '.join(str(err).split())}); writing it again",
              file=sys.stderr)
        return None


def _same(a: Hierarchy, b: Hierarchy) -> bool:
    """Whether two hierarchies are the same problem file: same content hash, names and x0."""
    x0_same = (a.x0 is None and b.x0 is None) or (
        a.x0 is not None and b.x0 is not None and np.array_equal(a.x0, b.x0))
    return problem_hash(a) == problem_hash(b) and list(a.names) == list(b.names) and x0_same


def save_problems(problems: dict, directory: str | os.PathLike, formats=("npz",)) -> None:
    """:func:`save_problem` of every ``{problem id: Hierarchy}``; the files
    written again because their content was another problem's (a family's
    parameters or code changed since they were written) are counted in one
    line on stderr."""
    changed = sum(save_problem(h, directory, pid, formats)[1] for pid, h in problems.items())
    if changed:
        print(f"hikbench run: {changed} problem file(s) in {directory} written again: their content changed "
              f"(the family's parameters or code)", file=sys.stderr)


def save_problem(h: Hierarchy, directory: str | os.PathLike, problem_id: str,
                 formats=("npz",)) -> tuple[dict, bool]:
    """Write h as OUT/problems/<stem>.<ext> for each format (npz, soth);
    returns ({format: path}, whether a file of other content was replaced).
    An existing .npz holding h (same content hash, names and x0) is kept; one
    that cannot be read (a damaged file of an earlier run: a line on stderr
    says so) or that holds another problem is written again, and so is the
    SOTH text beside it."""
    from hikbench.problems.files import save_npz

    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    out, replaced, fresh = {}, False, "npz" not in formats  # (SOTH alone: written every run, never stale)
    for fmt in sorted(formats, key=lambda f: f != "npz"):  # (the .npz first: it tells whether h changed)
        if fmt == "npz":
            path = d / (file_stem(problem_id) + ".npz")
            old = _stored(path) if path.exists() else None
            if old is None or not _same(old, h):
                replaced, fresh = old is not None, True
                tmp = path.with_suffix(".npz.tmp")
                save_npz(h, tmp)
                os.replace(tmp, path)
        elif fmt == "soth":
            path = d / (file_stem(problem_id) + ".soth.txt")
            if not path.exists() or fresh:
                try:
                    from hikbench.problems.soth import save_soth
                except ModuleNotFoundError as err:
                    raise HikbenchError("SOTH export needs hikbench.problems.soth (not installed in this tree); "
                                        "use export = ['npz']") from err
                tmp = d / (file_stem(problem_id) + ".soth.tmp")
                save_soth(h, tmp)
                os.replace(tmp, path)
        else:
            raise HikbenchError(f"unknown export format {fmt!r}: expected 'npz' or 'soth'")
        out[fmt] = path
    return out, replaced
