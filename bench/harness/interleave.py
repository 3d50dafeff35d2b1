"""The two sides of ``hikbench regress`` run and timed:

* :class:`Rounds`: the suite run on each side (a plain ``hikbench run`` into
  ``OUT/rounds/<side>-<r>``, the order alternating): statuses, verification and
  the problem files of every case. The second side of a round starts with a
  copy of the first's yardsticks (``OUT/yardstick/`` of a run: each file keyed
  by the problem's content and the yardstick code's version, so a side whose
  yardstick code differs computes its own): about 10 s less on the ``ci`` suite;
* :class:`PairedTimer`: every case timed on both sides back to back, job by job,
  in fresh workers each round, both on one CPU: the times the decision compares.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import time
from pathlib import Path

import pandas as pd

from hikbench.bench.harness.revisions import RevisionError, Side
from hikbench.solvers.base import UNSUPPORTED

__all__ = ["Rounds"]

class Rounds:
    """Runs rounds of ``suite`` on ``base`` and ``change``; ``frames[side]`` holds one
    results DataFrame per finished round of that side."""

    def __init__(self, base: Side, change: Side, suite: str, out: Path, repeat: int | None = None,
                 timeout: float = 1800.0):
        self.sides = {"base": base, "change": change}
        self.suite, self.out, self.repeat, self.timeout = suite, out, repeat, timeout
        self.frames: dict[str, list[pd.DataFrame]] = {"base": [], "change": []}
        self.seconds: dict[str, float] = {"base": 0.0, "change": 0.0}

    @property
    def done(self) -> int:
        return min(len(f) for f in self.frames.values())

    def run_side(self, name: str) -> None:
        """The next full run of side ``name`` (``base`` or ``change``)."""
        self.frames[name].append(self._run(name, len(self.frames[name])))

    def run_round(self) -> None:
        """A full run of each side, the order alternating from round to round."""
        r = self.done
        for name in (("base", "change") if r % 2 == 0 else ("change", "base")):
            self.run_side(name)

    def _run(self, name: str, r: int) -> pd.DataFrame:
        side = self.sides[name]
        target = self.out / "rounds" / f"{name}-{r + 1}"
        shutil.rmtree(target, ignore_errors=True)
        other = self.out / "rounds" / f"{'change' if name == 'base' else 'base'}-{r + 1}" / "yardstick"
        if other.is_dir():  # (keyed by problem and yardstick code: a side whose code differs computes its own)
            shutil.copytree(other, target / "yardstick")
        args = ["run", "--suite", self.suite, "--out", str(target), "--quiet"]
        if self.repeat:
            args += ["--repeat", str(self.repeat)]
        t0 = time.perf_counter()
        try:
            done = subprocess.run(side.command(*args), env=side.env, cwd=side.cwd, capture_output=True,
                                  timeout=self.timeout, check=False)
        except subprocess.TimeoutExpired:
            raise RevisionError(f"`hikbench run --suite {self.suite}` on {side.label} took more than "
                                f"{self.timeout:g} s (round {r + 1})") from None
        self.seconds[name] += time.perf_counter() - t0
        if done.returncode:
            lines = [ln for ln in done.stderr.decode(errors="replace").splitlines() if ln.strip()]
            raise RevisionError(f"`hikbench run --suite {self.suite}` failed on {side.label} (exit "
                                f"{done.returncode}, round {r + 1}): {lines[-1].strip() if lines else ''}")
        csv = target / "results.csv"
        if not csv.exists():
            raise RevisionError(f"`hikbench run --suite {self.suite}` on {side.label} wrote no {csv}")
        return pd.read_csv(csv)


class PairedTimer:
    """Times every case of a finished round on both sides **alternately, job by job**:
    an isolated worker per side (the base's runs the base's code: its
    install first on PYTHONPATH), and for each case a job on one side then at once
    the same job on the other, the order alternating. The machine's speed drifts
    within a second on a shared VM (hcod's 12 us solve read 5.7-12.8 us in blocks
    0.2 s apart in one process): measured milliseconds apart, both sides of a pair see
    the same speed, and the ratio of the pair cancels it.

    **Both sides of a pair run on one CPU, and each round starts fresh workers.**
    On a VM, one vCPU can run 1.5x slower than the other for minutes (its
    physical core shared with work outside the VM: throughput-bound loops slow
    down, a latency-bound chain does not): two persistent workers, one per vCPU,
    once put the sides of an A/A gate 1.5x apart on hcod's n=120 case in all 20
    rounds. So after the two fresh workers have loaded their solvers at once,
    one per core, both are pinned to the same CPU for the round's timed jobs,
    the CPU taking turns from round to round (``cpus``); whatever a process
    keeps for its life (its memory layout, where its compiled code lies) is a
    round-to-round variation, inside the paired rounds' interval.

    Only registry solvers are timed (a case's ``solver`` column names them), and not a
    case that a side's solver declines (status ``unsupported``); the
    problems are the change's round-1 files (``OUT/rounds/change-1/problems``)."""

    def __init__(self, base: Side, change: Side, rounds: Rounds, repeat: int = 15, timeout: float = 60.0):
        from hikbench.bench.harness.isolation import IsolatedWorker

        self.repeat, self.timeout = repeat, timeout
        self.workers = {name: IsolatedWorker(log=rounds.out / f"worker-{name}.log", path_first=side.path_first,
                                             cwd=side.cwd)
                        for name, side in (("base", base), ("change", change))}
        self.labels = {"base": base.label, "change": change.label}
        self.verified = {name: frames[0] for name, frames in rounds.frames.items()}
        self.cases, self.skipped = self._cases(rounds.out / "rounds" / "change-1")
        self.frames: dict[str, list[pd.DataFrame]] = {"base": [], "change": []}
        self.pids: dict[str, list[int]] = {"base": [], "change": []}  # (each round's worker, per side)
        self.cpus: list[int] = []  # (the CPU of each round's timed jobs, both sides)
        self.done = 0

    def _cases(self, run_dir: Path):
        import json

        from hikbench.bench.harness.columns import KEY
        from hikbench.bench.suites.problemset import file_stem
        from hikbench.problems.files import load
        from hikbench.solvers import registry

        known = registry.available()
        base_rows = self.verified["base"].drop_duplicates(list(KEY)).set_index(list(KEY))
        cases, skipped = [], []
        for row in self.verified["change"].drop_duplicates(list(KEY)).itertuples(index=False):
            key = tuple(getattr(row, k) for k in KEY)
            if row.solver not in known or key not in base_rows.index:
                skipped.append(key)
                continue
            if str(base_rows.loc[key].get("problem_hash")) != str(getattr(row, "problem_hash", None)):
                skipped.append(key)
                continue
            if UNSUPPORTED in (row.status, base_rows.loc[key].get("status")):
                continue  # a decline is not a timing case (the decision says so: "not timed")
            h = load(run_dir / "problems" / f"{file_stem(row.problem)}.npz")
            cases.append((key, {"kind": "solve", "hierarchy": h, "solver": row.solver,
                                "options": json.loads(row.options) if isinstance(row.options, str) else {},
                                "mode": row.mode, "repeat": self.repeat, "warmup": 1, "samples": None}))
        return cases, skipped

    def run_round(self) -> None:
        """Fresh workers, then one job per case and side, each case's pair back to back,
        the order alternating."""
        import numpy as np

        from hikbench.bench.harness.columns import KEY

        self._fresh_workers()
        rows = {"base": [], "change": []}
        for i, (key, job) in enumerate(self.cases):
            order = ("base", "change") if (i + self.done) % 2 == 0 else ("change", "base")
            for name in order:
                samples = self._samples(name, key, job)
                rows[name].append(dict(zip(KEY, key), time_median_s=float(np.median(samples)) * 1e-9
                                       if samples else float("nan")))
        for name in rows:  # (the side's round-1 rows, with this round's paired times; NaN where untimed)
            timed = pd.DataFrame(rows[name], columns=[*KEY, "time_median_s"])
            first = self.verified[name].drop_duplicates(list(KEY)).drop(columns=["time_median_s"])
            self.frames[name].append(first.merge(timed, on=list(KEY), how="left"))
        self.done += 1

    def _fresh_workers(self) -> None:
        """Both sides' workers restarted and loaded at once (one untimed solve of every
        case: hcod loads its equality and its inequality kernel), then both pinned to
        this round's CPU."""
        from concurrent.futures import ThreadPoolExecutor

        def prime(name):
            for key, job in self.cases:
                self._samples(name, key, {**job, "repeat": 1, "warmup": 0})

        for name, worker in self.workers.items():  # (here: a child dies with the thread that started it)
            worker.start()
            self.pids[name].append(worker.proc.pid)
        with ThreadPoolExecutor(max_workers=2) as pool:
            for done in [pool.submit(prime, name) for name in self.workers]:
                done.result()
        if not hasattr(os, "sched_setaffinity"):  # (macOS: the scheduler places them; `cpus` stays empty)
            return
        allowed = sorted(os.sched_getaffinity(0))
        cpu = allowed[self.done % len(allowed)]
        for worker in self.workers.values():
            os.sched_setaffinity(worker.proc.pid, {cpu})
        self.cpus.append(cpu)

    def _samples(self, name: str, key: tuple, job: dict) -> list:
        """The samples (ns) of ``job`` on side ``name``; a RevisionError when it times out or crashes."""
        res = self.workers[name].run(job, self.timeout, first_timeout=max(self.timeout, 300.0))
        if res.get("status") in ("timeout", "crashed"):
            raise RevisionError(f"a timing job of {key[1]} on {key[0]} ({key[3]}) ended {res['status']} on "
                                f"{self.labels[name]}: {res.get('reason', '')}")
        return res.get("samples_ns") or []

    def close(self) -> None:
        for w in self.workers.values():
            w.close()
