"""A run's folder OUT (``hikbench run --out``): created, checked and locked for the
run's life (``run.lock``), its finished rows read to resume (``results.csv``), and one
session of ``run.json`` per run (bench/harness/runner.py holds the layout of OUT).

Resuming: a task whose row is finished is skipped unless ``--rerun``; a finished row
whose settings' options changed, or whose problem's content did (``problem_hash``), is
run again, its new row replacing the old one (results.csv backed up first).
"""

from __future__ import annotations

import fcntl
import os
import socket
from pathlib import Path

import numpy as np

from hikbench.bench.harness.cache import yardstick_code
from hikbench.bench.harness.calibration import KERNEL, calibrate
from hikbench.bench.harness.columns import KEY
from hikbench.bench.harness.environment import environment, read_run_json, utc_now, write_run_json
from hikbench.bench.harness.regular import check_run_folder
from hikbench.bench.harness.results import backup, compact, finished_rows, one_line
from hikbench.problems.errors import HikbenchError
from hikbench.problems.verify import PROFILES

__all__ = ["RunFolder", "out_lock"]


def out_lock(out: Path):
    """Take the exclusive lock of a run directory, ``OUT/run.lock`` (an
    ``flock``: a run killed by any signal leaves no stale lock). Returns the
    open lock file; closing it releases the lock. Raises HikbenchError,
    naming the holder, when another run holds it: two runs appending to one
    results.csv (or compacting it) would mix or drop rows."""
    path = Path(out) / "run.lock"
    try:
        f = open(path, "a+")  # noqa: SIM115 - held open for the run, closed by the caller
    except OSError as err:
        raise HikbenchError(f"--out {out}: cannot create {path.name}: {err.strerror or err}") from err
    try:
        fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        f.seek(0)
        holder = f.read().strip() or "a process that has not written its name yet"
        f.close()
        raise HikbenchError(f"--out {out}: another hikbench run is writing to this directory ({holder}); "
                            "wait for it to finish, or give this run another --out") from None
    f.seek(0)
    f.truncate()
    f.write(f"pid {os.getpid()} on {socket.gethostname()}, started {utc_now()}\n")
    f.flush()
    return f


class RunFolder:
    """OUT, held for a run: ``with RunFolder(out) as folder`` creates it, refuses an entry
    of the wrong kind (a FIFO at run.lock or worker.log: one line, not a hang) and takes
    its lock (:func:`out_lock`, released on leaving, and by the OS when the process dies)."""

    def __init__(self, out):
        self.out = Path(out)
        self._lock = None
        self._done: dict = {}

    def __enter__(self) -> RunFolder:
        try:
            self.out.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise HikbenchError(f"--out {self.out}: cannot create the output directory: {err.strerror or err}") \
                from err
        check_run_folder(self.out)
        self._lock = out_lock(self.out)
        return self

    def __exit__(self, *exc) -> None:
        self._lock.close()

    def resume(self, tasks: list, pcols: dict, *, rerun: bool, limit: int | None, say) -> tuple[list, int, int]:
        """``(todo, finished, replaced)``: the tasks to run (``rerun``: every one; ``limit``: at
        most that many), how many of ``tasks`` are finished and skipped, and how many of
        ``todo`` replace a finished row (results.csv is then backed up, which ``say`` tells).
        A run killed while replacing rows left old rows behind: they are dropped first."""
        compact(self.out)
        self._done = finished_rows(self.out)
        todo = list(tasks) if rerun else _todo(tasks, self._done, pcols, say)
        finished = len(tasks) - len(todo)
        if limit is not None:
            todo = todo[: max(int(limit), 0)]
        replaced = sum(_written(t.key) in self._done for t in todo)
        if replaced:
            bak = backup(self.out)
            say(f"{replaced} finished row(s) will be replaced as they are run again; "
                f"the previous results.csv is kept as {bak}")
        return todo, finished, replaced

    def open_session(self, plan, todo: list, export_skipped: dict) -> tuple[dict, dict]:
        """run.json with this run's session appended (``plan``: the run's
        :class:`hikbench.bench.harness.runner.RunPlan`), written; ``(meta, session)``.
        HikbenchError when the finished rows have another headline accuracy profile."""
        meta = read_run_json(self.out)
        before = (meta.get("accuracy") or {}).get("profile")
        accuracy, suite = plan.accuracy, plan.suite
        if self._done and before and before != accuracy:
            raise HikbenchError(f"--accuracy {accuracy}: the rows of {self.out / 'results.csv'} have the headline "
                                f"profile {before} (run.json; `verified` is its verdict); every row records each "
                                f"profile's (verified_{'/'.join(PROFILES)}): run with --accuracy {before}, or "
                                f"give this run another --out")
        session = {"started": utc_now(), "calibration_start_ns": calibrate(), "todo": len(todo),
                   "repeat": plan.repeat, "samples": plan.samples, "sample_time": suite.sample_time,
                   "rounds": plan.rounds, "timeout": plan.timeout}
        # (the solvers this directory's runs selected, skipped ones included: compare expects their cases)
        selected = sorted({t.entry.solver for t in plan.tasks} | set(plan.skipped)
                          | set(meta.get("selected_solvers", [])))
        meta.update({"suite": suite.to_dict(), "suite_rows": len(plan.tasks),
                     "suite_scenario_runs": len(plan.scenarios), "selected_solvers": selected,
                     "calibration_kernel": KERNEL, "key": list(KEY), "yardstick_code": yardstick_code(),
                     "accuracy": {"profile": accuracy, "rtol": PROFILES[accuracy].rtol,
                                  "profiles": {p: prof.rtol for p, prof in PROFILES.items()}},
                     "skipped_solvers": plan.skipped, "export_skipped": export_skipped,
                     "environment": environment()})
        meta.setdefault("created", session["started"])
        meta.setdefault("sessions", []).append(session)
        write_run_json(self.out, meta)
        return meta, session

    def close_session(self, meta: dict, session: dict, summary, replaced: int,
                      failure: BaseException | None) -> None:
        """The session's end (time, calibration, rows written) in run.json, and the old rows of
        the keys run again dropped (results.compact). When the run is already failing (a full
        disk that stopped a row's write, an interrupt), an error of these is not raised over
        that failure, the one reported: results.csv keeps its finished rows (a replaced row's
        old copy is read as replaced) and run.json its previous sessions, each whole."""
        session["finished"] = utc_now()
        session["calibration_end_ns"] = calibrate()
        session["written"] = summary.written
        if summary.scenario_runs:
            session["scenario_written"] = summary.scenario_written
        cal = [s[k] for s in meta["sessions"] for k in ("calibration_start_ns", "calibration_end_ns") if k in s]
        meta["calibration_ns"] = int(np.median(cal))
        steps = ([lambda: compact(self.out)] if replaced else []) + [lambda: write_run_json(self.out, meta)]
        for step in steps:
            try:
                step()
            except HikbenchError:
                if failure is None:
                    raise


def _written(key: tuple) -> tuple:
    """A task's key as its row holds it (hikbench.bench.harness.results.one_line)."""
    return tuple(one_line(k) for k in key)


def _todo(tasks: list, done: dict, pcols: dict, say) -> list:
    """The tasks to run when resuming: those without a finished row, and those
    whose finished row was run with other settings' options or on another
    problem content (``problem_hash``: a family's parameters or code changed
    since); each such reason is one line (``say``)."""
    todo, options, content = [], 0, 0
    for t in tasks:
        if _written(t.key) not in done:
            todo.append(t)
            continue
        opts, phash = done[_written(t.key)]
        if opts != t.entry.options_json():
            options += 1
        elif phash != pcols[t.problem.id]["problem_hash"]:
            content += 1
        else:
            continue
        todo.append(t)
    if options:
        say(f"{options} finished row(s) run again: their settings' options changed")
    if content:
        say(f"{content} finished row(s) run again: their problem's content changed (its "
            f"problem_hash differs: the family's parameters or code changed); each new row replaces its old one")
    return todo
