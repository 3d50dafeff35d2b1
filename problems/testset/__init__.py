"""Versioned test sets of hierarchical least-squares problems (docs/testset.md).

A set is one folder (``hlsp-1/``): one ``.npz`` per problem in the project's problem-file
contract (:mod:`hikbench.problems.files`: ``A`` (rows, n), ``lower``, ``upper`` (rows,),
``level`` (rows,), ``n``, ``names`` (levels,)) and ``manifest.json``, which holds for each
problem its id, family, sizes, kinds of rows, provenance, the SHA-256 of its file and its
certified optimum: the level norms ``||v_k(x*)||`` and x* of the exact certificate
(:mod:`hikbench.problems.exact`), rounded to float64 (JSON numbers, written with Python's
shortest round-trip repr, so they read back bit for bit). Consecutive control steps of one
closed-loop run are listed as a sequence.

The shipped sets are package data of this package (``hikbench.problems.testset``):
``hikbench run --suite hlsp-1`` must find them from an installed wheel, not only a checkout.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hikbench.problems.errors import HikbenchError
from hikbench.problems.hierarchy import Hierarchy

__all__ = ["FORMAT", "MANIFEST", "SETS_DIR", "Entry", "TestSet", "TestSetError", "cached_set", "entry_family",
           "file_sha256", "row_kinds", "set_folder", "shipped_sets", "stored_optimum", "testset_families",
           "testset_problem"]

#: the manifest's ``format`` value; a reader refuses another
FORMAT = "hikbench-testset-1"
MANIFEST = "manifest.json"
SETS_DIR = Path(__file__).resolve().parent


class TestSetError(HikbenchError):
    """A test set folder or manifest that does not follow docs/testset.md."""

    __test__ = False  # (not a pytest class)


def shipped_sets() -> list[str]:
    """The names of the sets shipped with hikbench (folders holding a manifest)."""
    return sorted(p.parent.name for p in SETS_DIR.glob(f"*/{MANIFEST}"))


def set_folder(name_or_path: str | os.PathLike) -> Path:
    """The folder of a shipped set by name (``hlsp-1``), or a folder path holding a manifest."""
    p = Path(name_or_path)
    if (p / MANIFEST).is_file():
        return p
    if (SETS_DIR / str(name_or_path) / MANIFEST).is_file():
        return SETS_DIR / str(name_or_path)
    raise TestSetError(f"test set {os.fspath(name_or_path)!r}: no such folder with a {MANIFEST} "
                       f"(shipped sets: {', '.join(shipped_sets()) or 'none'})")


def file_sha256(path: str | os.PathLike) -> str:
    """Hex SHA-256 of a file's bytes."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def row_kinds(h: Hierarchy) -> dict[str, int]:
    """Counts of the rows by kind: ``equality`` (lower = upper), ``two_sided``, ``lower_only``,
    ``upper_only`` and ``free`` (both bounds infinite)."""
    lo, up = np.isfinite(h.lower), np.isfinite(h.upper)
    eq = h.lower == h.upper
    return {"equality": int(eq.sum()), "two_sided": int((lo & up & ~eq).sum()),
            "lower_only": int((lo & ~up).sum()), "upper_only": int((~lo & up).sum()),
            "free": int((~lo & ~up).sum())}


#: keys every manifest entry has (docs/testset.md, "The manifest")
ENTRY_KEYS = ("id", "file", "sha256", "family", "n", "rows", "depth", "rows_per_level", "kinds",
              "optimum", "provenance", "sequence")


@dataclass
class Entry:
    """One problem of a set, as its manifest entry says (docs/testset.md)."""

    id: str
    file: str
    sha256: str
    family: str
    n: int
    rows: int
    depth: int
    rows_per_level: list
    kinds: dict
    optimum: dict  # {"level_norms": [...], "x": [...], "certificate": str}
    provenance: dict
    sequence: dict | None = None  # {"id": str, "index": int} for a step of a sequence

    def to_dict(self) -> dict:
        return {k: getattr(self, k) for k in ENTRY_KEYS}

    @property
    def level_norms(self) -> np.ndarray:
        return np.array(self.optimum["level_norms"], dtype=float)

    @property
    def x(self) -> np.ndarray:
        return np.array(self.optimum["x"], dtype=float)


@dataclass
class TestSet:
    """A set read from its folder: the manifest's header and its entries, in order."""

    __test__ = False

    folder: Path
    name: str
    header: dict
    entries: list = field(default_factory=list)
    sequences: dict = field(default_factory=dict)  # sequence id -> its problem ids in order

    @classmethod
    def read(cls, name_or_path: str | os.PathLike) -> TestSet:
        """Read a set's manifest (no problem file is opened); TestSetError names the file and key."""
        folder = set_folder(name_or_path)
        path = folder / MANIFEST
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
            raise TestSetError(f"{path}: cannot be read as JSON ({err})") from err
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise TestSetError(f"{path}: format {data.get('format') if isinstance(data, dict) else None!r}: "
                               f"expected {FORMAT!r}")
        entries, seen = [], set()
        for i, e in enumerate(data.get("problems", ())):
            missing = [k for k in ENTRY_KEYS if k not in e] if isinstance(e, dict) else list(ENTRY_KEYS)
            if missing:
                raise TestSetError(f"{path}: problems[{i}] lacks {missing}")
            if e["id"] in seen:
                raise TestSetError(f"{path}: problems[{i}]: id {e['id']!r} appears twice")
            seen.add(e["id"])
            entry = Entry(**{k: e[k] for k in ENTRY_KEYS})
            if len(entry.optimum.get("level_norms", ())) != entry.depth or len(entry.optimum.get("x", ())) != entry.n:
                raise TestSetError(f"{path}: problems[{i}] ({entry.id}): optimum must hold depth = {entry.depth} "
                                   f"level_norms and n = {entry.n} values of x")
            entries.append(entry)
        sequences = {}
        for e in entries:
            if e.sequence is not None:
                sequences.setdefault(e.sequence["id"], []).append((e.sequence["index"], e.id))
        sequences = {s: [pid for _, pid in sorted(v)] for s, v in sequences.items()}
        header = {k: v for k, v in data.items() if k != "problems"}
        return cls(folder, str(data.get("name", folder.name)), header, entries, sequences)

    def __len__(self) -> int:
        return len(self.entries)

    def entry(self, problem_id: str) -> Entry:
        if not hasattr(self, "_by_id"):
            self._by_id = {e.id: e for e in self.entries}
        if problem_id not in self._by_id:
            raise TestSetError(f"test set {self.name}: no problem {problem_id!r}")
        return self._by_id[problem_id]

    def load(self, entry: Entry) -> Hierarchy:
        """The problem of ``entry`` (:func:`hikbench.problems.files.load_npz`)."""
        from hikbench.problems.files import load_npz

        return load_npz(self.folder / entry.file)

    def check_hashes(self) -> list[str]:
        """One line per problem file that is missing or whose SHA-256 differs from the manifest's,
        and per ``.npz`` of the folder the manifest does not list; empty when all agree."""
        bad = []
        for e in self.entries:
            p = self.folder / e.file
            if not p.is_file():
                bad.append(f"{p}: missing (problem {e.id})")
            elif file_sha256(p) != e.sha256:
                bad.append(f"{p}: SHA-256 {file_sha256(p)[:16]}... differs from the manifest's {e.sha256[:16]}... "
                           f"(problem {e.id})")
        listed = {e.file for e in self.entries}
        bad += [f"{p}: not in the manifest" for p in sorted(self.folder.glob("*.npz")) if p.name not in listed]
        return bad


@functools.lru_cache(maxsize=8)
def _read(folder: str, mtime_ns: int) -> TestSet:
    return TestSet.read(folder)


def cached_set(name_or_path) -> TestSet:
    """:meth:`TestSet.read`, kept while the manifest is unchanged (a suite reads it per problem)."""
    folder = set_folder(name_or_path)
    return _read(str(folder), (folder / MANIFEST).stat().st_mtime_ns)


def testset_problem(seed: int = 0, set: str = "hlsp-1", problem: str = "") -> Hierarchy:  # noqa: A002
    """The problem ``problem`` (its id) of the test set ``set`` (a shipped name or a folder); the
    family ``testset`` of suites (``seed`` is not used: a set's problems are fixed data)."""
    ts = cached_set(set)
    return ts.load(ts.entry(problem))


def stored_optimum(set: str, problem: str) -> tuple[np.ndarray, str]:  # noqa: A002
    """The certified x* of a set's problem and a note naming the set and its certificate."""
    ts = cached_set(set)
    return ts.entry(problem).x, f"the certified optimum stored in test set {ts.name} ({ts.header.get('certificate', '')})"


def entry_family(set: str, problem: str) -> str:  # noqa: A002
    """``<set>:<family>`` of a set's problem (``hlsp-1:robot:reach``): results.csv's family column."""
    ts = cached_set(set)
    return f"{ts.name}:{ts.entry(problem).family}"


def testset_families() -> dict:
    """The families ``testset`` (a problem of a shipped set) and ``hard`` (the hard cases on exact
    data, :mod:`hikbench.problems.testset.cases`), for :func:`hikbench.problems.generators.all_families`."""
    from hikbench.problems.family import Family
    from hikbench.problems.testset.cases import CASES, hard_case

    return {"testset": Family("testset", "a problem of a test set (docs/testset.md): params set, problem (its id)",
                              testset_problem, {"set": "hlsp-1", "problem": "hard/rank_deficient/n=3/seed=0"}),
            "hard": Family("hard", "hard cases on exact (dyadic) data: " + ", ".join(CASES),
                           lambda seed=0, case="rank_deficient", n=6: hard_case(case, n, seed),
                           {"case": "rank_deficient", "n": 6}, sweep={"case": list(CASES)})}
