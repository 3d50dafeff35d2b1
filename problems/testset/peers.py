"""The peers' own test problems, read from a peer's source folder (docs/testset.md, "Peers' cases").

* **LexLS** (jrl-umi3218/lexls, BSD-2-Clause): its hierarchy text format, as
  ``LexLS::tools::HierarchyFileProcessor::import`` (include/lexls/tools.h) reads it: header
  fields ``#nVar`` (n), ``#nObj`` (levels), ``#nCtr`` (rows per level, on the next line),
  ``#HierType`` (100: equalities, each row ``a_1 .. a_n b``; 200: inequalities, each row
  ``a_1 .. a_n lo up``; 210: the same and an activation code per row), ``#ObjType`` (per level
  200 general, 100 simple bounds: each row ``j lo up`` bounds ``x_j``, j from 1 as LexLS's
  interfaces/matlab-octave/tests/implementation/export_hierarchy.m writes Matlab's indices
  (tests/test_01.dat: 1 .. 88 for 88 variables), first level only), then one ``#OBJECTIVE`` line before each level's rows, and optionally ``#SolGuess`` /
  ``#Solution`` followed by n numbers. :func:`read_lexls` returns the hierarchy and the
  file's solution (or None).
* **NIPM-HLSP** (pfeiffer-kai/NIPM-HLSP, BSD-3-Clause, Copyright (c) 2022 Kai Pfeiffer): the 17
  cases of tests/test1.cpp. Their sizes (``nVar``, ``p`` levels, ``me[l]`` equality and
  ``mi[l]`` inequality rows per level, ``randomMatrix``) are read from that file; the rows are
  built as test1.cpp builds them: level l has ``Ae x = be`` and ``Ai x <= bi`` (its
  ``wi = Ai x - bi``, nipm_hlsp/level.cpp), identity blocks with the file's right-hand sides.
  For the cases with ``randomMatrix = true`` the file draws A with Eigen's
  ``MatrixXd::Random`` (``std::rand``, not reproducible here); :func:`nipm_cases` keeps the
  case's sizes, signs and right-hand sides and draws A uniformly from the multiples of 1/8 in
  [-1, 1] (``numpy.random.default_rng(case number)``), which its provenance says.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from hikbench.problems.errors import ProblemFileError
from hikbench.problems.hierarchy import Hierarchy, Level

__all__ = ["LEXLS_LICENCE", "NIPM_LICENCE", "lexls_cases", "nipm_cases", "read_lexls"]

LEXLS_LICENCE = "BSD-2-Clause (LexLS, jrl-umi3218/lexls, Copyright 2013-2021 INRIA)"
NIPM_LICENCE = "BSD-3-Clause (NIPM-HLSP, pfeiffer-kai/NIPM-HLSP, Copyright (c) 2022, Kai Pfeiffer)"

_HEADERS = ("#nVar", "#nObj", "#nCtr", "#HierType", "#ObjType")


def read_lexls(path: str | os.PathLike) -> tuple[Hierarchy, np.ndarray | None]:
    """A LexLS hierarchy file (module docstring) as a Hierarchy, and its ``#Solution`` (or None).
    ProblemFileError names the file, the line and what was expected."""
    p = Path(path)
    try:
        lines = p.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as err:
        raise ProblemFileError(f"{p}: cannot read ({err})") from err

    def fail(i: int, what: str):
        raise ProblemFileError(f"{p}: line {i + 1}: {what}")

    def numbers(i: int, count: int | None = None) -> list[float]:
        if i >= len(lines):
            fail(i - 1, "the file ends where numbers were expected")
        try:
            vals = [float(t) for t in lines[i].split()]
        except ValueError:
            fail(i, f"expected numbers; got {lines[i].strip()[:60]!r}")
        if count is not None and len(vals) < count:
            fail(i, f"expected {count} numbers; got {len(vals)}")
        return vals

    head, i = {}, 0
    while i < len(lines) and len(head) < len(_HEADERS):
        key = "".join(lines[i].split())
        if key in _HEADERS:
            if key in head:
                fail(i, f"duplicate header field {key}")
            head[key] = numbers(i + 1)
            i += 2
        else:
            i += 1
    missing = [k for k in _HEADERS if k not in head]
    if missing:
        raise ProblemFileError(f"{p}: header field(s) {missing} missing; expected {list(_HEADERS)}")
    n, depth, kind = int(head["#nVar"][0]), int(head["#nObj"][0]), int(head["#HierType"][0])
    rows, types = [int(v) for v in head["#nCtr"]], [int(v) for v in head["#ObjType"]]
    if kind not in (100, 200, 210):
        raise ProblemFileError(f"{p}: #HierType {kind}: expected 100, 200 or 210")
    if len(rows) != depth or len(types) != depth:
        raise ProblemFileError(f"{p}: #nCtr and #ObjType must have #nObj = {depth} values; "
                               f"got {len(rows)} and {len(types)}")
    bounds = 1 if kind == 100 else 2
    levels = []
    for k in range(depth):
        while i < len(lines) and not "".join(lines[i].split()).startswith("#OBJECTIVE"):
            i += 1
        if i >= len(lines):
            raise ProblemFileError(f"{p}: {depth} objectives announced, {k} found")
        i += 1
        if types[k] not in (100, 200):
            raise ProblemFileError(f"{p}: #ObjType of level {k}: {types[k]}: expected 100 or 200")
        if types[k] == 100 and k > 0:
            raise ProblemFileError(f"{p}: level {k}: simple bounds are allowed in the first objective only")
        cols = (1 if types[k] == 100 else n) + bounds
        data = np.array([numbers(i + r, cols)[:cols] for r in range(rows[k])]).reshape(rows[k], cols)
        if types[k] == 100:
            A = np.zeros((rows[k], n))
            for r, j in enumerate(data[:, 0]):
                if j != int(j) or not 1 <= j <= n:
                    fail(i + r, f"simple bound on variable {j:g}: expected an index in 1 .. {n}")
                A[r, int(j) - 1] = 1.0
        else:
            A = data[:, :n]
        lo, up = (data[:, -1], data[:, -1]) if bounds == 1 else (data[:, -2], data[:, -1])
        levels.append(Level(A, lo, up, f"objective {k}"))
        i += rows[k]
    solution = None
    for j in range(i, len(lines)):
        if lines[j].strip() == "#Solution":
            vals = " ".join(lines[j + 1:]).split()[:n]
            solution = np.array([float(v) for v in vals]) if len(vals) == n else fail(j, f"expected {n} numbers")
    return Hierarchy.from_levels(levels, n=n), solution


def _nipm_sizes(source: str, path: Path) -> dict[int, dict]:
    """{test number: {"nVar", "p", "me", "mi", "random"}} from test1.cpp's if-chain."""
    blocks = re.split(r"if\s*\(\s*testnr\s*==\s*(\d+)\s*\)", source)
    out = {}
    for num, body in zip(blocks[1::2], blocks[2::2]):
        body = body.split("}", 1)[0]
        if int(num) in out and "nVar" not in body:  # (the later `if (testnr == 3)` of the row building)
            continue
        get = {k: re.search(rf"\b{k}\s*=\s*([\w.]+)\s*;", body) for k in ("nVar", "p", "randomMatrix")}
        if any(v is None for v in get.values()):
            raise ProblemFileError(f"{path}: test {num}: nVar, p or randomMatrix not found")
        p = int(get["p"].group(1))
        me, mi = [0] * p, [0] * p
        for vec, l, v in re.findall(r"\b(me|mi)\[(\d+)\]\s*=\s*(\d+)\s*;", body):
            (me if vec == "me" else mi)[int(l)] = int(v)
        out[int(num)] = {"nVar": int(get["nVar"].group(1)), "p": p, "me": me, "mi": mi,
                         "random": get["randomMatrix"].group(1) == "true"}
    if not out:
        raise ProblemFileError(f"{path}: no `if (testnr == K)` case found")
    return out


#: right-hand sides of test1.cpp per level: (be, bi) with fixed rows, and with random rows
_RHS_FIXED = ((1.0, -1.0), (10.0, -2.0), (20.0, -3.0))
_RHS_RANDOM = ((10.0, -2.0), (20.0, -3.0), (30.0, -4.0))


def nipm_cases(source_folder: str | os.PathLike) -> list[tuple[int, Hierarchy, dict]]:
    """NIPM-HLSP's test cases (module docstring) from its source folder (tests/test1.cpp):
    ``[(case number, Hierarchy, provenance)]``."""
    path = Path(source_folder) / "tests" / "test1.cpp"
    try:
        source = path.read_text(encoding="utf-8")
    except OSError as err:
        raise ProblemFileError(f"{path}: cannot read ({err.strerror or err}); expected NIPM-HLSP's source "
                               f"folder") from err
    out = []
    for num, s in sorted(_nipm_sizes(source, path).items()):
        n, rng = s["nVar"], np.random.default_rng(num)
        levels = []
        for l in range(s["p"]):
            me, mi = s["me"][l], s["mi"][l]
            if l > 2 and (me or mi):
                raise ProblemFileError(f"{path}: test {num}: level {l} has rows; test1.cpp builds levels 0-2 only")
            be, bi = (_RHS_RANDOM if s["random"] else _RHS_FIXED)[min(l, 2)]
            if s["random"]:
                Ae = rng.integers(-8, 9, (me, n)) / 8.0
                Ai = rng.integers(-8, 9, (mi, n)) / 8.0 * (-1.0 if l == 0 else 1.0)
            elif num == 3 and l == 0:  # test1.cpp: A(0,0) = -1, b0 = 0; A(1,0) = 1, b1 = 0
                Ae, Ai, bi = np.zeros((me, n)), np.array([[-1.0], [1.0]]), 0.0
            else:
                Ae = np.eye(me, n)
                Ai = -np.eye(mi, n)
            A = np.vstack([Ae, Ai])
            lo = np.concatenate([np.full(me, be), np.full(mi, -np.inf)])
            up = np.concatenate([np.full(me, be), np.full(mi, bi)])
            levels.append(Level(A, lo, up, f"level {l}"))
        prov = {"source": "NIPM-HLSP tests/test1.cpp", "case": num, "licence": NIPM_LICENCE,
                "sizes": {"nVar": n, "p": s["p"], "me": s["me"], "mi": s["mi"]},
                "rows": ("A redrawn: multiples of 1/8 in [-1, 1], numpy.random.default_rng(case) (test1.cpp "
                         "draws Eigen's MatrixXd::Random)") if s["random"] else "as test1.cpp builds them"}
        out.append((num, Hierarchy.from_levels(levels, n=n), prov))
    return out


def lexls_cases(source_folder: str | os.PathLike) -> list[tuple[str, Hierarchy, np.ndarray | None, dict]]:
    """LexLS's test problems from its source folder (tests/*.dat, :func:`read_lexls`):
    ``[(name, Hierarchy, the file's #Solution or None, provenance)]``; ProblemFileError when the
    folder holds none (the release snapshots leave them out: a clone of the repository has them)."""
    folder = Path(source_folder) / "tests"
    files = sorted(folder.glob("*.dat"))
    if not files:
        raise ProblemFileError(f"{folder}: no LexLS hierarchy file (*.dat); expected LexLS's source folder, "
                               f"as a clone of jrl-umi3218/lexls has them")
    out = []
    for f in files:
        h, sol = read_lexls(f)
        out.append((f.stem, h, sol, {"source": f"LexLS tests/{f.name}", "licence": LEXLS_LICENCE,
                                      "rows": "as the file holds them"}))
    return out
