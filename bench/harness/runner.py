"""``hikbench run``: expand a suite, generate and save its problems, compute
(and cache) the yardstick of each problem, run every (problem, solver,
settings, mode) not already in OUT/results.csv, verify each x against the
yardstick, and append one row per job as it finishes (with rounds: after its
last round).

Layout of OUT::

    results.csv           one row per job (bench/harness/columns.py)
    run.json              environment, suite, calibration, sessions
    summary.json          rows, solvers, problems, verified counts, statuses, wall time (bench/harness/summary.py)
    problems/<id>.npz     every problem of the suite (and .soth.txt if exported); a file
                          whose content is not its problem's is written again
    yardstick/<problem_hash>.npz  cached yardstick of the problem of that content (x, status,
                          reason, kind, kind_reason, certify_budget), by yardstick code
                          version ``code`` (hikbench.bench.harness.cache)
    worker.log            stderr of the isolated worker processes
    scenarios.csv         one row per run of the suite's [[scenarios]] (hikbench.bench.scenarios.rows)
    scenarios/<scenario>/ each run's per-step CSV and trajectory, as `hikbench scenario` writes them
    run.lock              held (flock) by the run writing to OUT: a second run on
                          the same OUT is refused; the OS releases it when the
                          run's process ends, however it ends
"""

from __future__ import annotations

import fcntl
import json
import math
import os
import socket
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hikbench.bench.harness.cache import (
    CERTIFIED,
    NO_YARDSTICK,
    REFERENCE_ONLY,
    load_yardstick,
    problem_hash,
    save_yardstick,
    yardstick_code,
    yardstick_path,
)
from hikbench.bench.harness.calibration import KERNEL, calibrate
from hikbench.bench.harness.columns import KEY
from hikbench.bench.harness.environment import environment, read_run_json, utc_now, write_run_json
from hikbench.bench.suites.problemset import generate, problem_columns, save_problems
from hikbench.bench.harness.regular import check_run_folder
from hikbench.bench.harness.results import ResultsWriter, backup, compact, finished_rows, one_line
from hikbench.bench.harness.summary import write_summary
from hikbench.bench.harness.timing import tail_columns
from hikbench.bench.suites import Suite, SuiteError, Task, expand
from hikbench.problems.errors import HikbenchError
from hikbench.problems.hierarchy import row_normalised
from hikbench.problems.verify import PROFILES, judge, level_gaps, level_norms, verify
from hikbench.bench.harness.statuses import CRASHED, TIMEOUT
from hikbench.solvers.base import ERROR

__all__ = ["RunSummary", "out_lock", "run_suite"]


@dataclass
class RunSummary:
    total: int = 0
    skipped_finished: int = 0
    written: int = 0
    statuses: dict = field(default_factory=dict)
    skipped_solvers: dict = field(default_factory=dict)
    scenario_runs: int = 0             # runs of the suite's [[scenarios]]
    scenario_skipped_finished: int = 0
    scenario_written: int = 0
    scenario_statuses: dict = field(default_factory=dict)
    sequence_written: int = 0          # rows of the suite's sequences (hikbench.bench.testset.sequences)


def _finite(v):
    return None if v is None or (isinstance(v, float) and not math.isfinite(v)) else v


def _json_floats(a) -> str:
    return json.dumps([None if not math.isfinite(float(v)) else float(v) for v in a])


#: verdict_side of a row whose yardstick is not certified (x equal to its point; else a suffix says how)
NO_CERTIFIED = "no certified yardstick"


def make_row(task: Task, pcols: dict, h, ref, res: dict, accuracy: str = "default") -> dict:
    """One results.csv row from a job result (hikbench.bench.harness.worker) and the yardstick
    ``ref`` (:func:`_yardsticks`' tuple). Against a certified yardstick (the exact optimum) the
    row is judged at every profile of hikbench.problems.verify.PROFILES (``verified_<profile>``,
    hikbench.problems.verify.judge), ``verified`` and the verdict columns at ``accuracy``, the
    headline profile; ``level_gaps`` holds what the verdicts read. A row is verified only
    against a certified yardstick: against a reference-only one ``verified`` is empty and
    ``verdict_side`` says ``no certified yardstick`` when x is not above its point at any
    level, with ``; worse than its point`` or ``; better than its point`` (and
    ``verdict_level``) when it is. ``h`` and ``ref``
    are those of the hierarchy the solver's levels are (``task.entry.judged_on``: for
    ``row-normalised``, :func:`hikbench.problems.hierarchy.row_normalised` of the problem and
    its own yardstick), and so are the row's norms; ``yardstick_reason`` then starts with
    ``judged on the row-normalised hierarchy (the solver's claim):``."""
    x_ref, ref_status, ref_reason, kind, kind_reason = ref[:5]
    x = res.get("x")
    has_x = x is not None and np.shape(x) == (h.n,)
    samples = np.asarray(res.get("samples_ns") or [], dtype=np.int64)
    row = dict(pcols)
    e = task.entry
    row.update(solver=e.solver, settings=e.settings, options=e.options_json(),
               solver_settings=json.dumps(res["settings"]) if res.get("settings") else None, strict=e.strict,
               mode=task.mode,
               repeat=len(samples), status=res["status"], reason=res.get("reason", ""))
    if has_x:
        norms = level_norms(h, x)
        row["level_norms"] = _json_floats(norms)
        row["x_norm"] = float(np.linalg.norm(x))
    if x_ref is not None:
        row["ref_level_norms"] = _json_floats(level_norms(h, x_ref))
        if has_x:
            row["level_gaps"] = _json_floats(level_gaps(h, x, x_ref))
    if e.judged_on != "rows":
        kind_reason = f"judged on the {e.judged_on} hierarchy (the solver's claim): {kind_reason}"
    row.update(yardstick=kind, yardstick_reason=kind_reason)
    rtol = PROFILES[accuracy].rtol
    if x_ref is None:
        row["verified"] = None
        row["verdict_side"] = "no yardstick"
        row["reason"] = (row["reason"] + "; " if row["reason"] else "") + f"yardstick {ref_status}: {ref_reason}"
    elif kind != CERTIFIED:
        row["verified"] = None
        row["verdict_side"] = NO_CERTIFIED
        if has_x:  # (how x compares with the uncertified point, said apart)
            v = judge(h, x, x_ref, rtol)
            if not v.equal:
                row.update(verdict_level=v.level, verdict_diff=_finite(float(v.difference)),
                           verdict_side=f"{NO_CERTIFIED}; {'better' if v.lower == 'a' else 'worse'} than its point")
    elif not has_x:
        row.update(verified=False, verdict_side="no x", **{f"verified_{p}": False for p in PROFILES})
    else:
        verdicts = {p: judge(h, x, x_ref, prof.rtol) for p, prof in PROFILES.items()}
        row.update({f"verified_{p}": v.lower != "b" for p, v in verdicts.items()})
        v = verdicts[accuracy]
        row["verified"] = row[f"verified_{accuracy}"]
        if not v.equal:
            row.update(verdict_level=v.level, verdict_side="better" if v.lower == "a" else "worse",
                       verdict_diff=_finite(float(v.difference)))
    for k in ("iterations", "activations", "deactivations", "flops"):
        row[k] = res.get(k)
    if res.get("iterations_per_level"):
        row["iterations_per_level"] = json.dumps(res["iterations_per_level"])
    if samples.size:
        row.update(tail_columns(samples), samples_ns=json.dumps(samples.tolist()))
    row["build_time_s"] = _finite(res.get("build_time_s"))
    row["solve_time_s"] = _finite(res.get("solve_time_s"))
    row.update(calib_ns=res.get("calib_ns"), host=res.get("host"), worker=res.get("worker"),
               wall_s=res.get("wall_s"), finished_at=utc_now())
    return row


class _Progress:
    """rich progress bar (done/total, rate, ETA), or nothing with --quiet."""

    def __init__(self, quiet: bool):
        self.p = None
        if not quiet:
            from rich.progress import (
                BarColumn,
                MofNCompleteColumn,
                Progress,
                TextColumn,
                TimeElapsedColumn,
                TimeRemainingColumn,
            )
            self.p = Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                              TextColumn("{task.fields[rate]}"), TimeElapsedColumn(), TextColumn("ETA"),
                              TimeRemainingColumn(), transient=False)

    def __enter__(self):
        if self.p:
            self.p.start()
        return self

    def __exit__(self, *exc):
        if self.p:
            self.p.stop()

    def add(self, description: str, total: int):
        return self.p.add_task(description, total=total, rate="") if self.p else None

    def advance(self, tid, label: str = "", steps: int = 1):
        if self.p is not None:
            self.p.advance(tid, steps)
            speed = self.p.tasks[tid].speed if tid < len(self.p.tasks) else None
            self.p.update(tid, rate=f"{speed:.1f}/s" if speed else "", description=label or
                          self.p.tasks[tid].description)


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


def run_suite(suite: Suite, out, *, solvers=None, repeat=None, timeout=None, rerun=False, executor=None,
              quiet=False, limit=None, rounds=None, accuracy=None, log=print) -> RunSummary:
    """Run ``suite`` into directory ``out`` (see the module docstring).

    ``solvers`` (patterns) replaces the suite's solver lists; ``repeat``,
    ``rounds`` and ``timeout`` override the suite's (``repeat`` fixes the
    count: no extra ``samples``), ``accuracy`` the suite's headline profile (column ``verified``;
    every row records each profile's verdict); ``limit`` stops after
    that many new rows (the run resumes later). With ``rounds`` R > 1 the
    ``repeat`` timed solves of a row are split over R rounds, each round
    running every job of the run once (:func:`_merge_rounds`), each round in
    fresh worker processes (``executor.renew()``): a slow window of the machine
    then shifts a part of every row's samples, not all the samples of the rows
    it happens to meet, and a row's samples come from R processes (whatever a
    process keeps for its life, such as the vCPU it settled on, varies); a row is written after its last
    round (a run stopped in between has not written it: a plain run of the
    same OUT runs it again, unless ``rerun`` left its old row). ``rerun``
    runs finished rows again: each new row replaces its old one, the other
    rows are kept, and results.csv is first backed up without overwriting an older backup (hikbench.bench.harness.results.backup); a
    finished row whose settings' options changed is run again the same way.
    A suite that selects no job raises SuiteError. ``executor`` defaults to a
    SerialExecutor. The suite's ``[[scenarios]]`` run after the problems
    (:func:`hikbench.bench.scenarios.suite.run_scenarios`; ``limit`` counts their rows too)."""
    from hikbench.bench.harness.executors import SerialExecutor

    out = Path(out)
    samples = None if repeat else suite.samples  # (--repeat: exactly that many)
    repeat = int(repeat or suite.repeat)
    if rounds is None and suite.rounds > repeat:  # (a smaller --repeat than the suite's)
        print(f"hikbench run: the suite's rounds = {suite.rounds} lowered to repeat = {repeat}: each round "
              "times at least one solve of every row", file=sys.stderr)
        rounds = repeat
    rounds = int(rounds or suite.rounds)
    if rounds > repeat:
        raise HikbenchError(f"rounds = {rounds} (--rounds or the suite's): expected at most repeat = {repeat} "
                            "(--repeat or the suite's): each round times at least one solve of every row")
    timeout = float(timeout or suite.timeout)
    accuracy = accuracy or suite.accuracy
    if accuracy not in PROFILES:
        raise HikbenchError(f"--accuracy {accuracy}: expected one of {', '.join(PROFILES)}")
    tasks, skipped = expand(suite, solvers)  # checks solvers and settings before anything is written
    scenarios = []
    if suite.scenarios:  # (pinocchio and the robots only for a suite that has scenarios)
        from hikbench.bench.scenarios.suite import expand_scenarios, run_scenarios
        scenarios, more = expand_scenarios(suite, solvers)
        skipped = {**skipped, **more}
    summary = RunSummary(total=len(tasks), skipped_solvers=skipped, scenario_runs=len(scenarios))
    problems, pcols, families = {}, {}, {}
    try:
        for spec in [t.problem for t in tasks] if tasks else [sp for sp, _ in suite.problems()]:
            if spec.id not in problems:  # every problem is generated (and checked) before anything is written
                problems[spec.id] = _generate(suite, spec, families)
                pcols[spec.id] = problem_columns(spec, problems[spec.id])
    finally:
        if "worker" in families:
            families["worker"].close()
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise HikbenchError(f"--out {out}: cannot create the output directory: {err.strerror or err}") from err
    check_run_folder(out)  # (an entry of the wrong kind, a FIFO at run.lock or worker.log, is one line, not a hang)
    lock = out_lock(out)  # released on return or raise, and by the OS when the process dies
    try:
        export, export_skipped = _export_formats(suite.export)
        for name, why in skipped.items():
            print(f"hikbench run: skipping solver {name}: {why}", file=sys.stderr)
        save_problems(problems, out / "problems", export)
        if not tasks:  # e.g. every solver's backend missing: the problems are still exported, then fail
            why = "; ".join(f"skipped solver {k}: {v}" for k, v in skipped.items()) or (
                f"none of its solvers runs in its modes {list(suite.modes)}: warm needs supports_warm_start")
            raise SuiteError(f"suite {suite.source or suite.name} selects no job to run ({why}); "
                             f"its problems were written to {out / 'problems'}")

        compact(out)  # a run killed while replacing rows left old rows behind
        done = finished_rows(out)
        todo = list(tasks) if rerun else _todo(tasks, done, pcols)
        summary.skipped_finished = len(tasks) - len(todo)
        if limit is not None:
            todo = todo[: max(int(limit), 0)]
        replaced = sum(_written(t.key) in done for t in todo)
        if replaced:
            bak = backup(out)
            print(f"hikbench run: {replaced} finished row(s) will be replaced as they are run again; "
                  f"the previous results.csv is kept as {bak}", file=sys.stderr)

        meta = read_run_json(out)
        before = (meta.get("accuracy") or {}).get("profile")
        if done and before and before != accuracy:
            raise HikbenchError(f"--accuracy {accuracy}: the rows of {out / 'results.csv'} have the headline "
                                f"profile {before} (run.json; `verified` is its verdict); every row records each "
                                f"profile's (verified_{'/'.join(PROFILES)}): run with --accuracy {before}, or "
                                f"give this run another --out")
        session = {"started": utc_now(), "calibration_start_ns": calibrate(), "todo": len(todo),
                   "repeat": repeat, "samples": samples, "sample_time": suite.sample_time, "rounds": rounds,
                   "timeout": timeout}
        # (the solvers this directory's runs selected, skipped ones included: compare expects their cases)
        selected = sorted({t.entry.solver for t in tasks} | set(skipped) | set(meta.get("selected_solvers", [])))
        meta.update({"suite": suite.to_dict(), "suite_rows": len(tasks), "suite_scenario_runs": len(scenarios),
                     "selected_solvers": selected,
                     "calibration_kernel": KERNEL, "key": list(KEY), "yardstick_code": yardstick_code(),
                     "accuracy": {"profile": accuracy, "rtol": PROFILES[accuracy].rtol,
                                  "profiles": {p: prof.rtol for p, prof in PROFILES.items()}},
                     "skipped_solvers": skipped, "export_skipped": export_skipped, "environment": environment()})
        meta.setdefault("created", session["started"])
        meta.setdefault("sessions", []).append(session)
        write_run_json(out, meta)

        own_executor = executor is None
        executor = executor or SerialExecutor(log=out / "worker.log")
        session["executor"] = getattr(executor, "name", type(executor).__name__)
        failure = None
        try:
            with _Progress(quiet) as progress:
                judged, jcols = _judged_problems(todo, problems, pcols)
                refs = _yardsticks([_judged_id(t) for t in todo], todo, judged, jcols, out, executor,
                                   max(timeout, suite.first_solve_timeout), suite.certify_timeout, progress)
                tid = progress.add("solves", len(todo) * rounds)
                earlier = {i: [] for i in range(len(todo))}  # results of the rounds before, per job
                alive = list(earlier)  # jobs still to run in the next round
                with ResultsWriter(out) as writer:
                    for rnd in range(rounds):
                        if rnd:  # (each round in fresh worker processes: see the docstring)
                            executor.renew()
                        share = (_share(repeat, rounds, rnd), _share(samples, rounds, rnd),
                                 suite.sample_time / rounds)
                        items = ((i, _job(suite, todo[i], problems, *share), timeout) for i in alive)
                        again = []
                        for i, res in executor.map(items):
                            t = todo[i]
                            label = f"solves: {t.entry.solver} {t.mode}" + (
                                f" (round {rnd + 1}/{rounds})" if rounds > 1 else "")
                            if rnd < rounds - 1 and not _ends_rounds(res):
                                earlier[i].append({k: res.get(k) for k in ("status", "samples_ns", "wall_s",
                                                                           "calib_ns", "host")})
                                again.append(i)
                                progress.advance(tid, label)
                                continue
                            res = _merge_rounds(earlier.pop(i), res, rounds)
                            pid, jid = t.problem.id, _judged_id(t)
                            row = make_row(t, pcols[pid], judged[jid], refs[jid], res, accuracy)
                            writer.write(row)
                            summary.written += 1
                            summary.statuses[row["status"]] = summary.statuses.get(row["status"], 0) + 1
                            progress.advance(tid, label, rounds - rnd)
                        alive = sorted(again)  # (the suite's order, whatever order the executor finished in)
                if scenarios:
                    left = None if limit is None else max(int(limit) - summary.written, 0)
                    (summary.scenario_skipped_finished, summary.scenario_written,
                     summary.scenario_statuses) = run_scenarios(scenarios, out, executor, suite.first_solve_timeout,
                                                                rerun=rerun, limit=left, progress=progress)
                if suite.sequences:
                    from hikbench.bench.testset.sequences import run_sequences, sequence_tasks
                    entries = list({(t.entry.solver, t.entry.settings): t.entry for t in tasks}.values())
                    summary.sequence_written = run_sequences(
                        sequence_tasks(suite.sequences, entries), out, executor, suite.first_solve_timeout,
                        PROFILES[accuracy].rtol, rerun=rerun, progress=progress)
        except BaseException as err:
            failure = err
            raise
        finally:
            if own_executor:
                executor.close()
            session["finished"] = utc_now()
            session["calibration_end_ns"] = calibrate()
            session["written"] = summary.written
            if scenarios:
                session["scenario_written"] = summary.scenario_written
            cal = [s[k] for s in meta["sessions"] for k in ("calibration_start_ns",
                                                            "calibration_end_ns") if k in s]
            meta["calibration_ns"] = int(np.median(cal))
            _close_files(out, meta, replaced, failure)
        write_summary(out)
        return summary
    finally:
        lock.close()


def _close_files(out: Path, meta: dict, replaced: int, failure: BaseException | None) -> None:
    """Drop the old rows of the keys run again (results.compact) and write run.json. When the run
    is already failing (a full disk that stopped a row's write, an interrupt), an error of these is
    not raised over that failure, the one reported: results.csv keeps its finished rows (a replaced
    row's old copy is read as replaced) and run.json its previous sessions, each whole."""
    steps = ([lambda: compact(out)] if replaced else []) + [lambda: write_run_json(out, meta)]
    for step in steps:
        try:
            step()
        except HikbenchError:
            if failure is None:
                raise


def _share(count: int | None, rounds: int, rnd: int) -> int | None:
    """Round ``rnd``'s share of ``count`` repetitions (None: none asked)."""
    return None if count is None else count // rounds + (rnd < count % rounds)


def _job(suite: Suite, t: Task, problems: dict, repeat: int, samples: int | None = None,
         sample_time: float | None = None) -> dict:
    """The worker's job (hikbench.bench.harness.worker) timing ``repeat`` solves of task t,
    or more up to ``samples`` within ``sample_time`` s (hikbench.bench.harness.timing)."""
    return {"kind": "external" if t.entry.spec.startswith("external:") else "solve",
            "hierarchy": problems[t.problem.id], "solver": t.entry.spec, "options": t.entry.options,
            "mode": t.mode, "repeat": repeat, "samples": samples,
            "sample_time": suite.sample_time if sample_time is None else sample_time, "warmup": suite.warmup,
            "first_timeout": suite.first_solve_timeout,
            "calibrate": suite.calibrate_each_job}


def _ends_rounds(res: dict) -> bool:
    """A job that ends so in a round is not run in the later ones (its row is
    written at once): the harness killed it (timeout), its worker died
    (crashed), or an exception escaped (error without samples; a solver that
    reports ``error`` itself, with its timed solves, goes on)."""
    return res["status"] in (TIMEOUT, CRASHED) or (res["status"] == ERROR and not res.get("samples_ns"))


def _merge_rounds(earlier: list[dict], res: dict, rounds: int) -> dict:
    """The result of a job run in rounds: the last round's result (x, status,
    counters) with the timed samples of every round (``wall_s`` their sum,
    ``calib_ns`` the median of the rounds'); a round that ended the job's
    rounds (:func:`_ends_rounds`) is the row, its reason naming the round (no
    samples: like a run without rounds). Rounds whose statuses differ, or that
    ran on different hosts, are named in the reason."""
    if not earlier:
        if rounds > 1 and _ends_rounds(res):
            res = {**res, "reason": f"{res.get('reason', '')} (in round 1 of {rounds})".lstrip()}
        return res
    rnd = len(earlier) + 1
    if _ends_rounds(res):
        return {**res, "reason": f"{res.get('reason', '')} (in round {rnd} of {rounds}; the earlier rounds "
                                 f"ended {', '.join(r['status'] for r in earlier)})".lstrip()}
    every = (*earlier, res)
    out = {**res, "samples_ns": [s for r in every for s in r.get("samples_ns") or []]}
    if all(r.get("wall_s") is not None for r in every):
        out["wall_s"] = sum(r["wall_s"] for r in every)
    if all(r.get("calib_ns") is not None for r in every):
        out["calib_ns"] = int(np.median([r["calib_ns"] for r in every]))
    notes = [res.get("reason") or ""]
    statuses = [r["status"] for r in every]
    if len(set(statuses)) > 1:
        notes.append(f"statuses differ across the rounds: {', '.join(statuses)}")
    hosts = list(dict.fromkeys(r.get("host") for r in every if r.get("host")))
    if len(hosts) > 1:  # (a Dask cluster: each round's jobs go to whichever worker is free)
        notes.append(f"rounds ran on hosts {', '.join(hosts)} (calib_ns: their median)")
    out["reason"] = "; ".join(filter(None, notes))
    return out


def _generate(suite: Suite, spec, families: dict):
    """generate(spec), a bad family or parameter reported with the suite file and the problem. A
    user's ``module:function`` family runs in an isolated worker (``families["worker"]``, started
    for the first one), under the suite's ``first_solve_timeout``: one that hangs or crashes is the
    run's one-line error, not a hang of this process."""
    where = f"suite {suite.source or suite.name}: problem {spec.id}"
    if ":" not in spec.family:
        try:
            return generate(spec)
        except HikbenchError as err:
            raise SuiteError(f"{where}: {err}") from err
    from hikbench.bench.harness.isolation import IsolatedWorker

    worker = families.get("worker") or families.setdefault("worker", IsolatedWorker())
    res = worker.run({"kind": "generate", "spec": spec, "hierarchy": None}, suite.first_solve_timeout)
    if res.get("status") == "optimal":
        return res["hierarchy"]
    if res.get("user_error"):
        raise SuiteError(f"{where}: {res['reason']}")
    if res.get("status") == TIMEOUT:
        raise SuiteError(f"{where}: family {spec.family!r}, seed {spec.seed} gave no problem within the "
                         f"suite's first_solve_timeout of {suite.first_solve_timeout:g} s (does it hang?)")
    raise SuiteError(f"{where}: family {spec.family!r}, seed {spec.seed}: {res.get('status')}: "
                     f"{res.get('reason')}")


def _export_formats(formats) -> tuple[tuple, dict]:
    """The suite's export formats that this tree can write, and the others
    with the reason (reported on stderr and in run.json, not silently)."""
    keep, skipped = [], {}
    for fmt in formats:
        if fmt == "soth":
            try:
                import hikbench.problems.soth  # noqa: F401
            except ModuleNotFoundError:
                skipped[fmt] = "hikbench.problems.soth is not available in this tree; only npz was written"
                print(f"hikbench run: not exporting SOTH text: {skipped[fmt]}", file=sys.stderr)
                continue
        keep.append(fmt)
    return tuple(keep), skipped


def _written(key: tuple) -> tuple:
    """A task's key as its row holds it (hikbench.bench.harness.results.one_line)."""
    return tuple(one_line(k) for k in key)


def _todo(tasks: list[Task], done: dict, pcols: dict) -> list[Task]:
    """The tasks to run when resuming: those without a finished row, and those
    whose finished row was run with other settings' options or on another
    problem content (``problem_hash``: a family's parameters or code changed
    since); each such reason is one line on stderr."""
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
        print(f"hikbench run: {options} finished row(s) run again: their settings' options changed",
              file=sys.stderr)
    if content:
        print(f"hikbench run: {content} finished row(s) run again: their problem's content changed (its "
              f"problem_hash differs: the family's parameters or code changed); each new row replaces its old one",
              file=sys.stderr)
    return todo


def _judged_id(t: Task) -> str:
    """The id of the hierarchy task t's x is judged on: its problem's, or for a solver whose
    levels are row-normalised (``judged_on``), that of the problem's row-normalised hierarchy."""
    return t.problem.id if t.entry.judged_on == "rows" else f"{t.problem.id} ({t.entry.judged_on})"


def _judged_problems(todo, problems: dict, pcols: dict) -> tuple[dict, dict]:
    """``problems`` and ``pcols`` with the row-normalised hierarchy of each problem a task of
    ``todo`` is judged on (:func:`_judged_id`), its ``problem_hash`` its own (its yardstick is
    cached apart)."""
    judged, jcols = dict(problems), dict(pcols)
    for t in todo:
        jid = _judged_id(t)
        if jid not in judged:
            judged[jid] = row_normalised(problems[t.problem.id])
            jcols[jid] = {**pcols[t.problem.id], "problem_hash": problem_hash(judged[jid])}
    return judged, jcols


def _yardsticks(pids, todo, problems, pcols, out: Path, executor, timeout, certify_timeout, progress) -> dict:
    """The yardstick of each problem id of ``pids``, (x, status, reason, kind, kind_reason, certify_budget),
    from ``OUT/yardstick/<problem_hash>.npz`` or computed through the executor (isolated), each
    step its own job with its own timeout (one that fails costs its step, never a point already
    found nor the run; ``timeout``: the larger of the job timeout and the first-solve allowance):

    1. the independent yardstick's point, and its exact certificate (:func:`_certify_all`);
       certified, it is the lexicographic optimum and the yardstick;
    2. otherwise ``hcod``'s point too: the lexicographically lowest of the two
       (:func:`_lowest`), certified in turn where the independent one was refused or missing
       (a certificate stopped by its budget is not tried again on the other point).

    A problem of a test set (family ``testset``, docs/testset.md) has its stored certified optimum
    as its yardstick, computed by none of these. Problems of the same content share one. A cached file of other yardstick code
    (:func:`hikbench.bench.harness.cache.yardstick_code`) is computed again, which one line on
    stderr says. A yardstick whose step a killed or lost worker ended is not cached: the next
    run tries again."""
    code = yardstick_code()
    refs, need, recertify, first_of, twins, stale = {}, [], [], {}, {}, 0
    specs = {t.problem.id: t.problem for t in todo}  # (a row-normalised hierarchy's id is none of these)
    for pid in dict.fromkeys(pids):
        if pid in specs and specs[pid].family == "testset":  # a test set's problem: its stored certified optimum
            from hikbench.problems.testset import stored_optimum  # (read once: cached_set)
            x, note = stored_optimum(specs[pid].params.get("set", "hlsp-1"), specs[pid].params["problem"])
            refs[pid] = (x, "optimal", note, CERTIFIED, note, 0.0)
            continue
        phash = pcols[pid]["problem_hash"]
        if phash in first_of:
            twins[pid] = first_of[phash]
            continue
        first_of[phash] = pid
        path = yardstick_path(out, phash)
        cached = load_yardstick(path, problems[pid].n) if path.exists() else None
        if cached is not None and cached[1][0] != phash:  # (a file copied or renamed by hand)
            print(f"hikbench run: {path} holds the yardstick of problem_hash {cached[1][0]}, not {phash}; "
                  f"computing the yardstick again", file=sys.stderr)
            cached = None
        elif cached is not None and cached[1][1] != code:
            stale += 1
            cached = None
        if cached is None:
            need.append(pid)
            continue
        refs[pid] = cached[0]
        if cached[0][3] == REFERENCE_ONLY and 0 < cached[0][5] < certify_timeout:  # (a larger budget: again)
            recertify.append(pid)
    if stale:
        print(f"hikbench run: {stale} cached yardstick(s) computed again: the yardstick's code changed "
              f"(hikbench.bench.harness.cache.YARDSTICK_MODULES, version {code})", file=sys.stderr)
    found, killed = {pid: {} for pid in need}, {}  # (killed: pid -> the status of a job a lost worker ended)

    def collect(kind: str, pids) -> None:
        """The candidate point ``kind`` (x: the independent yardstick's; x_hcod) of each of pids."""
        job = {"x": {"kind": "yardstick"}, "x_hcod": {"kind": "candidate", "solver": "hcod"}}[kind]
        tid = progress.add("yardstick" if kind == "x" else "yardstick: hcod's point", len(pids))
        for pid, res in executor.map(iter([(pid, {**job, "hierarchy": problems[pid]}, timeout) for pid in pids])):
            progress.advance(tid)
            if res["status"] in (TIMEOUT, CRASHED):
                killed[pid] = res["status"]
            ok = res["status"] == "optimal" and res.get("x") is not None
            found[pid][kind] = res["x"] if ok else None
            found[pid]["reason" if kind == "x" else "hcod_reason"] = "" if ok else (
                f"{'independent yardstick' if kind == 'x' else 'hcod'} {res['status']}: {res.get('reason', '')}")

    if need:
        collect("x", need)
    first = {pid: (found[pid]["x"], "the independent yardstick's point") for pid in need if found[pid]["x"] is not None}
    first.update({pid: (refs[pid][0], refs[pid][2]) for pid in recertify})
    refs.update(_certify_all(first, problems, executor, certify_timeout, progress))
    others = [pid for pid in need if pid not in refs or refs[pid][3] != CERTIFIED]
    if others:
        collect("x_hcod", others)
    second = {}
    for pid in others:
        x, note = _lowest(problems[pid], found[pid])
        if x is None:
            why = "; ".join(filter(None, (found[pid].get("reason"), found[pid].get("hcod_reason"))))
            refs[pid] = (None, killed.get(pid, ERROR), why, NO_YARDSTICK, "no candidate point", 0.0)
        elif pid not in refs or (x is not found[pid]["x"] and refs[pid][5] == 0):
            second[pid] = (x, note)  # (none certified yet, or hcod's point lower than a refused one)
        else:  # (the independent point stays; its certificate's outcome, with the candidates named)
            refs[pid] = (x, refs[pid][1], note, refs[pid][3],
                         note + refs[pid][4][refs[pid][4].index(";"):] if ";" in refs[pid][4] else note, refs[pid][5])
    refs.update(_certify_all(second, problems, executor, certify_timeout, progress))
    for pid in [*need, *recertify]:
        if pid not in killed:
            phash = pcols[pid]["problem_hash"]
            save_yardstick(yardstick_path(out, phash), refs[pid], phash, code)
    for pid, first in twins.items():
        refs[pid] = refs[first]
    return refs


def _lowest(h, res: dict):
    """The lexicographically lowest of the candidate points ``x`` (the independent yardstick's)
    and ``x_hcod`` (hikbench.problems.verify at 1e-9 of each level's scale; a tie keeps the
    independent yardstick's) and a note naming it; (None, "") when there is none."""
    x, xh = res.get("x"), res.get("x_hcod")
    if x is None and xh is None:
        return None, ""
    if xh is None:
        return x, "the independent yardstick's point" + (f" (no hcod point: {res['hcod_reason']})"
                                                          if res.get("hcod_reason") else "")
    if x is None:
        return xh, f"hcod's point (no independent point: {res.get('reason', '')})"
    v = verify(h, xh, x, rtol=1e-9)
    if not v.equal and v.lower == "a":
        return xh, f"hcod's point (the independent yardstick's is above it at level {v.level})"
    return x, "the independent yardstick's point" + ("" if v.equal else f" (hcod's is above it at level {v.level})")


def _certify_all(points: dict, problems: dict, executor, budget: float, progress) -> dict:
    """The exact certificate of each problem's chosen point (pid -> (x, note)), through the
    executor with ``budget`` seconds each; a problem whose estimated cost
    (:func:`hikbench.problems.exact.estimated_seconds`) exceeds twice the budget is not tried.
    Returns pid -> the yardstick tuple: ``certified`` (the certificate's exact optimum x*,
    rounded, whether x attains it or not), else ``reference-only`` with the reason (refused, timed out, not
    tried, failed), never losing the point."""
    from hikbench.problems.exact import estimated_seconds

    refs, items = {}, []
    for pid, (x, note) in points.items():
        est = estimated_seconds(problems[pid])
        if est > 2 * budget:
            refs[pid] = (x, "optimal", note, REFERENCE_ONLY,
                         f"{note}; not certified: the exact certificate was not tried, its estimated time "
                         f"({est:.0f} s) is beyond twice certify_timeout ({budget:g} s)", budget)
        else:
            items.append((pid, {"kind": "certify", "hierarchy": problems[pid], "x": x}, budget))
    if items:
        tid = progress.add("certificate", len(items))
        for pid, res in executor.map(iter(items)):
            progress.advance(tid)
            x, note = points[pid]
            if res["status"] == TIMEOUT:
                refs[pid] = (x, "optimal", note, REFERENCE_ONLY,
                             f"{note}; not certified: the exact certificate did not finish in certify_timeout "
                             f"({budget:g} s)", budget)
            elif res["status"] != "optimal":
                refs[pid] = (x, "optimal", note, REFERENCE_ONLY,
                             f"{note}; not certified: the exact certificate {res['status']}: {res.get('reason', '')}",
                             budget if res["status"] == CRASHED else 0.0)
            elif not res["certified"]:
                refs[pid] = (x, "optimal", note, REFERENCE_ONLY,
                             f"{note}; the exact certificate refused it: {res['reason']}", 0.0)
            elif res.get("x_cert") is None:  # (x* is not representable: no double reaches it)
                refs[pid] = (x, "optimal", note, CERTIFIED,
                             f"{note}; the certificate's exact optimum x* is not representable in double "
                             f"precision (rounded, it misses its exact level norms at level "
                             f"{res['unrepresentable_level']}): the point is the yardstick", 0.0)
            else:  # (certified: the exact optimum x* is the yardstick, never a point within a tolerance of it)
                refs[pid] = (res["x_cert"], "optimal", note, CERTIFIED,
                             f"the certificate's exact optimum x*, from {note}" + (
                                 "" if res["attains"] else f", which is above it at level {res['above_level']}"),
                             0.0)
    return refs
