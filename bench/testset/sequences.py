"""The sequences of a test set, solved in order on one solver object (docs/testset.md, "Ranking").

A suite's ``sequences = ["hlsp-1"]`` runs, after its problems, every sequence of consecutive
control steps of the set with every solver of the run that supports a warm start (its default
settings; ``warm_start = "time"`` for a solver with that option, hcod's and the peers'): one
object solves step 0, 1, ... in order, as a controller's would, each call timed
(``perf_counter_ns``, GC off, BLAS threads = 1), each x judged against the step's stored
certified optimum at the suite's accuracy profile (verified: not lexicographically worse, as
in results.csv). One job per (sequence, solver) in the
isolated worker: a solver that hangs or crashes costs its row. Rows go to ``OUT/sequences.csv``
(:data:`COLUMNS`); a finished (sequence, solver, warm start) is skipped unless ``--rerun``.
"""

from __future__ import annotations

import gc
import os
import socket
import sys
import time
import traceback
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["COLUMNS", "SequenceTask", "execute_sequence", "run_sequences", "sequence_tasks"]

COLUMNS = ("set", "sequence", "steps", "solver", "warm_start", "status", "reason", "verified_steps",
           "failed_steps", "time_median_s", "time_p99_s", "time_min_s", "time_max_s", "iterations_mean",
           "finished_at")
TIMEOUT_S = 120.0  #: seconds for one sequence job (50 steps of under 10 ms each, with room)


@dataclass(frozen=True)
class SequenceTask:
    set: str
    sequence: str
    solver: str
    spec: str
    options: tuple  # sorted (name, value) pairs
    warm_start: str

    @property
    def key(self) -> tuple[str, str, str, str]:
        return (self.sequence, self.solver, self.warm_start, self.set)


def sequence_tasks(sets, entries) -> list[SequenceTask]:
    """One task per (sequence of each set, solver entry that supports warm start, default settings)."""
    from hikbench.bench.specs import EXTERNAL, REGISTRY
    from hikbench.problems.testset import TestSet
    from hikbench.solvers import registry

    tasks = []
    for name in sets:
        ts = TestSet.read(name)
        for e in entries:
            if not e.warm or e.settings != "default" or e.spec.kind == EXTERNAL:
                continue
            opts = dict(e.options)
            info = e.spec.info() if e.spec.kind == REGISTRY else None
            if info is not None and "warm_start" in (registry.option_names(info) or ()):
                opts["warm_start"] = "time"
            mode = str(opts.get("warm_start", "warm"))
            for sid in ts.sequences:
                tasks.append(SequenceTask(name, sid, e.solver, e.spec.text, tuple(sorted(opts.items())), mode))
    return tasks


def execute_sequence(job: dict, notify=None) -> dict:
    """Worker side: the solver's warm-up and one untimed solve of step 0 on another object, then
    ``notify()``; then every step in order on one object, timed. Never raises."""
    from threadpoolctl import threadpool_limits

    from hikbench.bench.specs import solver_info
    from hikbench.solvers import registry
    from hikbench.solvers.base import ERROR

    base = {"host": socket.gethostname(), "pid": os.getpid()}
    try:
        info = solver_info(job["solver"])
        first = registry.build(info, **job["options"])
        if callable(getattr(first, "warmup", None)):
            first.warmup()
        first.solve(job["hierarchies"][0])
        if notify is not None:
            notify()
        slv = registry.build(info, **job["options"])
        xs, statuses, iters, ns = [], [], [], []
        with threadpool_limits(limits=1):
            gc.collect()
            gc.disable()
            try:
                for h in job["hierarchies"]:
                    t0 = time.perf_counter_ns()
                    res = slv.solve(h)
                    ns.append(time.perf_counter_ns() - t0)
                    xs.append(None if res.x is None else np.asarray(res.x, dtype=float))
                    statuses.append(res.status)
                    iters.append(int(res.iterations))
            finally:
                gc.enable()
        return {**base, "status": "finished", "reason": "", "x": xs, "statuses": statuses, "iterations": iters,
                "ns": ns}
    except Exception as err:  # noqa: BLE001 - a failing job costs its row (status error + reason)
        tb = traceback.extract_tb(err.__traceback__)
        where = f" at {os.path.basename(tb[-1].filename)}:{tb[-1].lineno}" if tb else ""
        return {**base, "status": ERROR, "reason": f"{type(err).__name__}: {err}{where}"}


def _path(out: Path) -> Path:
    return Path(out) / "sequences.csv"


def _done(out: Path) -> set:
    import pandas as pd

    p = _path(out)
    if not p.is_file():
        return set()
    df = pd.read_csv(p, dtype=str, keep_default_na=False)
    return {(r["sequence"], r["solver"], r["warm_start"], r["set"]) for _, r in df.iterrows()}


def _write(out: Path, row: dict) -> None:
    """Append ``row`` to sequences.csv, replacing a row of the same key."""
    import pandas as pd

    p = _path(out)
    new = pd.DataFrame([row], columns=list(COLUMNS))
    if p.is_file():
        old = pd.read_csv(p, dtype=str, keep_default_na=False)
        same = (old["sequence"] == row["sequence"]) & (old["solver"] == row["solver"]) & \
            (old["warm_start"] == row["warm_start"]) & (old["set"] == row["set"])
        new = pd.concat([old[~same], new.astype(str)], ignore_index=True)
    tmp = p.with_suffix(".tmp")
    new.to_csv(tmp, index=False)
    tmp.replace(p)


def run_sequences(tasks: list[SequenceTask], out: Path, executor, first_timeout: float, rtol: float,
                  *, rerun: bool = False, progress=None) -> int:
    """Run ``tasks`` through ``executor`` into ``OUT/sequences.csv``, each step judged against its stored
    optimum at ``rtol`` (the run's headline profile: hikbench.problems.verify.judge); returns the rows
    written."""
    from hikbench.bench.harness.environment import utc_now
    from hikbench.problems.testset import TestSet
    from hikbench.problems.verify import judge

    done = set() if rerun else _done(out)
    todo = [t for t in tasks if t.key not in done]
    sets = {t.set: TestSet.read(t.set) for t in todo}
    steps = {(t.set, t.sequence): [sets[t.set].entry(pid) for pid in sets[t.set].sequences[t.sequence]]
             for t in todo}
    hs = {k: [sets[k[0]].load(e) for e in v] for k, v in steps.items()}
    tid = progress.add("sequences", len(todo)) if progress is not None and todo else None
    items = ((i, {"kind": "sequence", "hierarchies": hs[(t.set, t.sequence)], "solver": t.spec,
                  "options": dict(t.options), "first_timeout": first_timeout}, TIMEOUT_S)
             for i, t in enumerate(todo))
    written = 0
    for i, res in executor.map(items):
        t = todo[i]
        entries, hh = steps[(t.set, t.sequence)], hs[(t.set, t.sequence)]
        row = {"set": t.set, "sequence": t.sequence, "steps": len(entries), "solver": t.solver,
               "warm_start": t.warm_start, "status": res["status"], "reason": res.get("reason", ""),
               "finished_at": utc_now()}
        if res["status"] == "finished":
            failed = []  # (verified: no level above the stored optimum beyond its tolerance, as results.csv's)
            for k, (e, h, x) in enumerate(zip(entries, hh, res["x"])):
                v = None if x is None or not np.all(np.isfinite(x)) else judge(h, x, e.x, rtol)
                if v is None or not (v.equal or v.lower == "a"):
                    failed.append(k)
            s = np.array(res["ns"], dtype=float) * 1e-9
            row.update(verified_steps=len(entries) - len(failed), failed_steps=" ".join(map(str, failed[:20])),
                       time_median_s=float(np.median(s)), time_p99_s=float(np.percentile(s, 99)),
                       time_min_s=float(s.min()), time_max_s=float(s.max()),
                       iterations_mean=float(np.mean(res["iterations"])))
        else:
            print(f"hikbench run: sequence {t.sequence}, {t.solver}: {res['status']}: {res.get('reason', '')}",
                  file=sys.stderr)
        _write(out, row)
        written += 1
        if tid is not None:
            progress.advance(tid, f"sequences: {t.solver}")
    return written


TITLE = "Sequences"  #: report.md's section (bench/analysis/report.py)


def sequence_rows(run_dir: Path) -> list[dict]:
    """The rows of ``RUN/sequences.csv`` (empty when the run has none)."""
    import pandas as pd

    p = _path(run_dir)
    if not p.is_file():
        return []
    df = pd.read_csv(p)
    return [{k: (None if isinstance(v, float) and v != v else v) for k, v in r.items()} for r in df.to_dict("records")]


def sequence_section(doc, run_dir: Path) -> list[dict]:
    """Write the section into ``doc`` (report.py's _Doc) when the run has sequence rows; returns them."""
    rows = sequence_rows(run_dir)
    if not rows:
        return rows

    def us(v) -> str:
        return "-" if v is None else f"{float(v) * 1e6:.1f}"

    doc.section(TITLE)
    doc.text("Each sequence of consecutive control steps of the test set solved in order on one solver object, "
             "as a controller's would be (sequences.csv; docs/testset.md, \"Ranking on it\"): one timed call per "
             "step, each x judged against the step's stored certified optimum (verified: not lexicographically "
             "worse). The first step's call, on a fresh object, is in the times (p99 of 25-50 steps is their "
             "maximum).")
    doc.table("sequences", "Sequences (steps verified of the sequence's; times over its steps)",
              ["sequence", "solver", "warm start", "verified", "median [us]", "p99 [us]", "min [us]",
               "mean iterations", "status"],
              [[r["sequence"], r["solver"], r["warm_start"],
                "-" if r.get("verified_steps") is None else f"{int(r['verified_steps'])}/{int(r['steps'])}",
                us(r.get("time_median_s")), us(r.get("time_p99_s")), us(r.get("time_min_s")),
                "-" if r.get("iterations_mean") is None else f"{float(r['iterations_mean']):.2f}",
                r["status"] + (f": {r['reason']}" if r.get("reason") else "")] for r in rows])
    return rows
