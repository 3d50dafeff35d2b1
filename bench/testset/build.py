"""Building, checking and growing a test set (docs/testset.md): ``hikbench testset build|check|add``.

A candidate problem enters a set only with its certified optimum: the points tried are the
candidate's own (a scenario step's u), the independent yardstick's
(:func:`hikbench.solvers.yardstick.yardstick_solution`) and ``hcod``'s cold solve, each certified by
:func:`hikbench.problems.exact.certify` until one is; the exact x* (rounded) and its level norms
are stored. A candidate none of whose points certifies, or whose certificate's estimated time
(:func:`hikbench.problems.exact.estimated_seconds`) exceeds the budget, is left out and listed
under ``excluded`` in the manifest with the reason.
"""

from __future__ import annotations

import json
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

import hikbench
from hikbench.problems.errors import HikbenchError
from hikbench.problems.hierarchy import Hierarchy
from hikbench.problems.testset import FORMAT, MANIFEST, Entry, TestSet, file_sha256, row_kinds

__all__ = ["Candidate", "certify_candidates", "hard_candidates", "nipm_candidates", "problem_candidates",
           "recertify", "robot_candidates", "sweep_candidates", "write_set"]


@dataclass
class Candidate:
    """A problem proposed for a set: its id, family, hierarchy, provenance, the points to try
    certifying first, and its place in a sequence (``{"id", "index"}``) or None."""

    id: str
    family: str
    hierarchy: Hierarchy
    provenance: dict
    points: list = field(default_factory=list)
    sequence: dict | None = None


def _prov(**kw) -> dict:
    return {**kw, "hikbench": hikbench.__version__}


def hard_candidates(ns=(3, 6, 10), seeds=(0, 1, 2, 3)) -> list[Candidate]:
    """Every hard case of :mod:`hikbench.problems.testset.cases` at each n and seed."""
    from hikbench.problems.testset.cases import CASES, hard_case

    return [Candidate(f"hard/{case}/n={n}/seed={s}", f"hard:{case}", hard_case(case, n, s),
                      _prov(generator="hikbench.problems.testset.cases.hard_case",
                            params={"case": case, "n": n}, seed=s))
            for case in CASES for n in ns for s in seeds]


#: the sweeps of hlsp-1: (family, fixed parameters, swept parameter, its values, seeds)
SWEEPS = (("dof-sweep", {"depth": 3, "rows": 4}, "n", (4, 8, 12, 16, 20, 24), (0, 1)),
          ("depth-sweep", {"n": 12, "rows": 3}, "depth", (1, 2, 3, 4, 5, 6, 8, 10), (0, 1)),
          ("random", {"n": 10, "rows": 4, "inequality": "mixed"}, "depth", (2, 4, 6), (0, 1, 2)),
          ("ik-like", {}, "n", (8, 12), (0, 1, 2)))


def sweep_candidates(sweeps=SWEEPS) -> list[Candidate]:
    """The DOF and depth sweeps and the random and IK-like families of
    :mod:`hikbench.problems.generators` (:data:`SWEEPS`)."""
    from hikbench.problems.generators import generate

    out = []
    for family, fixed, key, values, seeds in sweeps:
        for v in values:
            for s in seeds:
                params = {**fixed, key: v}
                out.append(Candidate(f"sweep/{family}/{key}={v}/seed={s}", f"sweep:{family}",
                                     generate(family, seed=s, **params),
                                     _prov(generator="hikbench.problems.generators.generate",
                                           params={"family": family, **params}, seed=s)))
    return out


def nipm_candidates(source_folder) -> list[Candidate]:
    """NIPM-HLSP's test cases read from its source folder (:func:`hikbench.problems.testset.peers.nipm_cases`)."""
    from hikbench.problems.testset.peers import nipm_cases

    return [Candidate(f"peer/nipm-hlsp/test{num}", "peer:nipm-hlsp", h,
                      _prov(generator="hikbench.problems.testset.peers.nipm_cases", **prov))
            for num, h, prov in nipm_cases(source_folder)]


def lexls_candidates(source_folder) -> list[Candidate]:
    """LexLS's test problems read from its source folder (:func:`hikbench.problems.testset.peers.lexls_cases`),
    the file's #Solution tried first."""
    from hikbench.problems.testset.peers import lexls_cases

    return [Candidate(f"peer/lexls/{name}", "peer:lexls", h,
                      _prov(generator="hikbench.problems.testset.peers.lexls_cases", **prov),
                      [sol] if sol is not None else [])
            for name, h, sol, prov in lexls_cases(source_folder)]


def robot_candidates(scenario: str, robot: str, label: str | None = None, steps: int | None = None,
                     every: int = 10, sequence: int = 50, max_changes: int | None = None) -> list[Candidate]:
    """The selected control steps of one closed-loop run (bench/testset/record.py,
    :func:`~hikbench.bench.testset.record.select_steps`): each a candidate with the controller's
    u as its first point; the sequence's steps in order."""
    from hikbench.bench.testset.record import record_steps, select_steps

    label = label or Path(robot).stem
    recorded, sc = record_steps(scenario, robot=robot, steps=steps)
    single, run = select_steps(recorded, every, sequence, max_changes=max_changes)
    seq_id = f"robot/{scenario}/{label}/steps{run[0].step}-{run[-1].step}" if run else None
    out = []
    for s in sorted(single + run, key=lambda s: s.step):
        in_run = run and run[0].step <= s.step <= run[-1].step
        prov = _prov(generator="hikbench.bench.testset.record.record_steps", robot=label,
                     robot_source=robot, scenario=scenario, step=s.step, time_s=s.step * sc.dt,
                     solver="hcod", warm_start="time", active_set_changed=bool(s.changed),
                     selected="sequence" if in_run else ("active-set change" if s.changed else f"every {every}"))
        out.append(Candidate(f"robot/{scenario}/{label}/step={s.step:04d}", f"robot:{scenario}", s.hierarchy, prov,
                             [s.u] if s.u is not None else [],
                             {"id": seq_id, "index": s.step - run[0].step} if in_run else None))
    return out


def problem_candidates(paths, family: str = "user") -> list[Candidate]:
    """Problem files (``.npz``, SOTH text, or LexLS hierarchy text ``.dat``) as candidates;
    a LexLS file's ``#Solution`` is tried first."""
    from hikbench.problems.files import load
    from hikbench.problems.testset.peers import read_lexls

    out = []
    for p in map(Path, paths):
        if p.suffix == ".dat":
            h, sol = read_lexls(p)
            pts, fmt = ([sol] if sol is not None else []), "LexLS hierarchy text"
        else:
            h, pts, fmt = load(p), [], "hikbench problem file"
        out.append(Candidate(f"{family}/{p.stem}", family, h,
                             _prov(generator="hikbench testset add", source=str(p), format=fmt), pts))
    return out


def _certify_job(h: Hierarchy, points: list, budget: float) -> dict:
    """Certify h from each point in turn, then the yardstick's and hcod's (worker process)."""
    from hikbench.problems.exact import certify, estimated_seconds

    est = estimated_seconds(h)
    if est > budget:
        return {"certified": False, "reason": f"estimated certificate time {est:.0f} s beyond the budget {budget:g} s"}
    t0, reasons = time.perf_counter(), []

    def hcod_point():
        from hikbench.solvers import registry
        res = registry.create("hcod").solve(h)
        return res.x if res.status == "optimal" else None

    def yardstick_point():
        from hikbench.solvers.yardstick import yardstick_solution
        return yardstick_solution(h)

    tried = [("given", lambda p=p: p) for p in points] + [("yardstick", yardstick_point), ("hcod", hcod_point)]
    for name, get in tried:
        try:
            x = get()
        except HikbenchError as err:
            reasons.append(f"{name}: no point ({err})")
            continue
        if x is None or not np.all(np.isfinite(x)):
            reasons.append(f"{name}: no finite point")
            continue
        cert = certify(h, np.asarray(x, dtype=float))
        if cert.certified:
            return {"certified": True, "point": name, "x": cert.x, "level_norms": cert.level_norms,
                    "seconds": time.perf_counter() - t0}
        reasons.append(f"{name}: {cert.reason}")
    return {"certified": False, "reason": "; ".join(reasons)}


def _key(c: Candidate, code: str) -> str:
    """The cache key of a candidate's certificate: its problem's content, its points, the
    certificate's code (:func:`hikbench.bench.harness.cache.yardstick_code`)."""
    import hashlib

    from hikbench.bench.harness.cache import problem_hash

    d = hashlib.sha256(f"{problem_hash(c.hierarchy)}:{code}:".encode())
    for x in c.points:
        d.update(np.ascontiguousarray(x, dtype="<f8").tobytes())
    return d.hexdigest()


def default_cache() -> Path:
    """``$XDG_CACHE_HOME/hikbench/testset-certificates.jsonl`` (default ``~/.cache``)."""
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "hikbench" / "testset-certificates.jsonl"


def _read_cache(path: Path | None) -> dict:
    if path is None or not path.is_file():
        return {}
    out = {}
    for line in path.read_text(encoding="utf-8").splitlines():
        try:
            rec = json.loads(line)
            out[rec["key"]] = rec["outcome"]
        except (json.JSONDecodeError, KeyError, TypeError):
            continue  # (a line cut by an interrupted build: that certificate is computed again)
    return out


def certify_candidates(cands: list[Candidate], workers: int = 2, budget: float = 60.0, log="stderr",
                       cache: Path | None = None) -> list:
    """``[(candidate, outcome)]`` in order, each certified in one of ``workers`` processes.
    ``cache``: a JSON-lines file of earlier outcomes (key :func:`_key`), read and appended to, so
    that a build interrupted or run again certifies only what changed; an outcome left out for
    its budget is not cached."""
    from hikbench.bench.harness.cache import yardstick_code

    log = sys.stderr if log == "stderr" else log  # (the stream of the call, not of the import)
    t0, code = time.perf_counter(), yardstick_code()
    known = _read_cache(cache)
    keys = [_key(c, code) for c in cands]
    if cache is not None:
        cache.parent.mkdir(parents=True, exist_ok=True)
    sink = open(cache, "a", encoding="utf-8") if cache is not None else None  # noqa: SIM115
    try:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            futures = [None if k in known else pool.submit(_certify_job, c.hierarchy, c.points, budget)
                       for c, k in zip(cands, keys)]
            out = []
            for i, (c, k, f) in enumerate(zip(cands, keys, futures)):
                res = known[k] if f is None else _plain(f.result())
                if f is not None and sink is not None and "budget" not in res["reason"]:
                    sink.write(json.dumps({"key": k, "id": c.id, "outcome": res}) + "\n")
                    sink.flush()
                out.append((c, res))
                if log is not None and (i % 20 == 19 or i == len(cands) - 1 or not res["certified"]):
                    ok = sum(r["certified"] for _, r in out)
                    print(f"hikbench testset: {i + 1}/{len(cands)} tried, {ok} certified "
                          f"({time.perf_counter() - t0:.0f} s)" + ("" if res["certified"] else
                                                                  f"; {c.id} left out: {res['reason'][:160]}"),
                          file=log, flush=True)
    finally:
        if sink is not None:
            sink.close()
    return out


def _plain(res: dict) -> dict:
    """An outcome in JSON types (x and level_norms as lists of floats), ``reason`` always present."""
    out = {**res, "reason": res.get("reason", "")}
    for k in ("x", "level_norms"):
        if k in out:
            out[k] = [float(v) for v in out[k]]
    return out


def _stem(problem_id: str) -> str:
    return problem_id.replace("/", "__").replace("=", "")


def _cut_sequences(outcomes: list) -> list:
    """Each sequence cut to its longest run of consecutive certified steps (renumbered from 0, its
    id naming its first and last step); its other certified steps stay in the set as single steps."""
    runs: dict = {}
    for i, (c, res) in enumerate(outcomes):
        if c.sequence is not None:
            runs.setdefault(c.sequence["id"], []).append(i)
    outcomes = list(outcomes)
    for sid, idx in runs.items():
        best, cur = [], []
        for i in idx:
            cur = cur + [i] if outcomes[i][1]["certified"] else []
            best = cur if len(cur) > len(best) else best
        keep = set(best if len(best) >= 2 else [])
        head, sep, _ = sid.rpartition("/steps")
        new_id = f"{head}/steps{outcomes[best[0]][0].provenance['step']}-{outcomes[best[-1]][0].provenance['step']}" \
            if keep and sep else sid
        for t, i in enumerate(sorted(keep)):
            c, res = outcomes[i]
            outcomes[i] = (Candidate(c.id, c.family, c.hierarchy, c.provenance, c.points, {"id": new_id, "index": t}), res)
        for i in set(idx) - keep:
            c, res = outcomes[i]
            outcomes[i] = (Candidate(c.id, c.family, c.hierarchy, {**c.provenance, "selected": "sequence (cut)"},
                                     c.points, None), res)
    return outcomes


def write_set(folder, name: str, outcomes: list, description: str = "", extra_excluded=()) -> TestSet:
    """Write the certified candidates of ``outcomes`` as the set ``name`` in ``folder`` (one npz
    each, the manifest); the others are listed under ``excluded``. A file of the folder that the
    new manifest does not list is removed first (a set is written whole)."""
    from hikbench.problems.exact import __doc__ as exact_doc
    from hikbench.problems.files import save_npz

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    for old in folder.glob("*.npz"):
        old.unlink()
    entries, excluded = [], list(extra_excluded)
    outcomes = _cut_sequences(outcomes)
    for c, res in outcomes:
        if not res["certified"]:
            excluded.append({"id": c.id, "family": c.family, "reason": res["reason"], "provenance": c.provenance})
            continue
        h, fname = c.hierarchy, f"{_stem(c.id)}.npz"
        save_npz(Hierarchy(h.A, h.lower, h.upper, h.level, n=h.n, names=list(h.names)), folder / fname,
                 compressed=True)
        entries.append(Entry(c.id, fname, file_sha256(folder / fname), c.family, int(h.n), int(h.rows), int(h.depth),
                             [int(v) for v in h.rows_per_level], row_kinds(h),
                             {"level_norms": [float(v) for v in res["level_norms"]],
                              "x": [float(v) for v in res["x"]], "certified_from": res["point"]},
                             c.provenance, c.sequence))
    header = {"format": FORMAT, "name": name, "description": description, "hikbench": hikbench.__version__,
              "certificate": "hikbench.problems.exact.certify: " + (exact_doc or "").strip().splitlines()[0],
              "problems_count": len(entries)}
    data = {**header, "problems": [e.to_dict() for e in entries], "excluded": excluded}
    (folder / MANIFEST).write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")
    return TestSet.read(folder)


def recertify(ts: TestSet, entries: list[Entry], workers: int = 1, rtol: float = 1e-9) -> list[str]:
    """Certify each entry's problem again from its stored x*; one line per entry whose new
    certificate is refused or whose level norms differ from the stored ones beyond ``rtol`` of
    each level's scale (:func:`hikbench.problems.verify.compare_lexicographic`). Empty: all agree."""
    from hikbench.problems.verify import compare_lexicographic, level_scales

    bad = []
    hs = [ts.load(e) for e in entries]
    with ProcessPoolExecutor(max_workers=max(1, workers)) as pool:
        results = list(pool.map(_certify_job, hs, [[e.x] for e in entries], [float("inf")] * len(entries)))
    for e, h, res in zip(entries, hs, results):
        if not res["certified"]:
            bad.append(f"{e.id}: not certified again ({res['reason'][:200]})")
            continue
        v = compare_lexicographic(res["level_norms"], e.level_norms, level_scales(h, e.x), rtol=rtol)
        if not v.equal:
            bad.append(f"{e.id}: level {v.level}: certified norm {res['level_norms'][v.level]!r}, stored "
                       f"{e.level_norms[v.level]!r}")
    return bad


def default_folder() -> Path:
    """Where ``build`` writes by default: the shipped hlsp-1 folder of this tree."""
    from hikbench.problems.testset import SETS_DIR
    return SETS_DIR / "hlsp-1"

