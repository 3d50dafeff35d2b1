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
                          version ``code`` (hikbench.bench.harness.yardstick)
    worker.log            stderr of the isolated worker processes
    scenarios.csv         one row per run of the suite's [[scenarios]] (hikbench.bench.scenarios.rows)
    scenarios/<scenario>/ each run's per-step CSV and trajectory, as `hikbench scenario` writes them
    run.lock              held (flock) by the run writing to OUT: a second run on
                          the same OUT is refused; the OS releases it when the
                          run's process ends, however it ends

The run's phases (:func:`run_suite`): the plan (:func:`plan_run`), the run folder
(hikbench.bench.harness.runfolder: lock, resume, run.json), the yardsticks
(hikbench.bench.harness.yardstick), the rounds of solves (:func:`_rounds`), each row made
by :func:`make_row` and appended, then the suite's scenarios and sequences.
"""

from __future__ import annotations

import json
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hikbench.bench.harness.cache import problem_hash
from hikbench.bench.harness.environment import utc_now
from hikbench.bench.harness.results import ResultsWriter
from hikbench.bench.harness.runfolder import RunFolder, out_lock
from hikbench.bench.harness.statuses import CRASHED, TIMEOUT
from hikbench.bench.harness.summary import write_summary
from hikbench.bench.harness.timing import tail_columns
from hikbench.bench.harness.yardstick import CERTIFIED, yardsticks
from hikbench.bench.specs import EXTERNAL
from hikbench.bench.suites import Suite, SuiteError, Task, expand
from hikbench.bench.suites.problemset import generate, problem_columns, save_problems
from hikbench.problems.errors import HikbenchError
from hikbench.problems.hierarchy import row_normalised
from hikbench.problems.verify import PROFILES, judge, level_gaps, level_norms
from hikbench.solvers.base import ERROR

__all__ = ["RunPlan", "RunSummary", "out_lock", "plan_run", "run_suite"]


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
    """One results.csv row from a job result (hikbench.bench.harness.worker) and the
    :class:`~hikbench.bench.harness.yardstick.Yardstick` ``ref``. Against a certified yardstick (the exact optimum) the
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
    x_ref, kind, kind_reason = ref.x, ref.kind, ref.kind_reason
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
        row["reason"] = (row["reason"] + "; " if row["reason"] else "") + f"yardstick {ref.status}: {ref.reason}"
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


def _stderr(line: str) -> None:
    print(f"hikbench run: {line}", file=sys.stderr)


class _Progress:
    """The run's one progress and log callback: a rich progress bar (done/total, rate, ETA),
    or none with --quiet, and ``say(line)`` for its one-line notes (``log``)."""

    def __init__(self, quiet: bool, log=_stderr):
        self.p = None
        self.say = log
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


@dataclass(frozen=True)
class RunPlan:
    """What a run does, decided and checked before anything is written: the suite's jobs
    (``tasks``, ``scenarios``), the solvers ``skipped`` (name -> why), every problem
    generated (``problems``, id -> Hierarchy) with its columns (``pcols``), and the run's
    ``repeat`` (``samples`` None: exactly that many), ``rounds``, ``timeout`` (s) and headline
    ``accuracy`` profile."""

    suite: Suite
    tasks: list
    scenarios: list
    skipped: dict
    problems: dict
    pcols: dict
    repeat: int
    samples: int | None
    rounds: int
    timeout: float
    accuracy: str


def plan_run(suite: Suite, *, solvers=None, repeat=None, timeout=None, rounds=None, accuracy=None,
             say=_stderr) -> RunPlan:
    """The :class:`RunPlan` of ``suite`` with :func:`run_suite`'s overrides; HikbenchError (or
    SuiteError) for a bad override, solver, settings or problem."""
    samples = None if repeat else suite.samples  # (--repeat: exactly that many)
    repeat = int(repeat or suite.repeat)
    if rounds is None and suite.rounds > repeat:  # (a smaller --repeat than the suite's)
        say(f"the suite's rounds = {suite.rounds} lowered to repeat = {repeat}: each round "
            "times at least one solve of every row")
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
        from hikbench.bench.scenarios.suite import expand_scenarios
        scenarios, more = expand_scenarios(suite, solvers)
        skipped = {**skipped, **more}
    problems, pcols, families = {}, {}, {}
    try:
        for spec in [t.problem for t in tasks] if tasks else [sp for sp, _ in suite.problems()]:
            if spec.id not in problems:  # every problem is generated (and checked) before anything is written
                problems[spec.id] = _generate(suite, spec, families)
                pcols[spec.id] = problem_columns(spec, problems[spec.id])
    finally:
        if "worker" in families:
            families["worker"].close()
    return RunPlan(suite, tasks, scenarios, skipped, problems, pcols, repeat, samples, rounds, timeout, accuracy)


def run_suite(suite: Suite, out, *, solvers=None, repeat=None, timeout=None, rerun=False, executor=None,
              quiet=False, limit=None, rounds=None, accuracy=None, log=_stderr) -> RunSummary:
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
    (:func:`hikbench.bench.scenarios.suite.run_scenarios`; ``limit`` counts their rows too).
    ``log(line)`` takes each one-line note of the run (default: stderr, after ``hikbench run: ``).

    The phases: :func:`plan_run` (every job and problem, checked before anything is written),
    :class:`~hikbench.bench.harness.runfolder.RunFolder` (lock, resume, run.json), the
    yardsticks (hikbench.bench.harness.yardstick), :func:`_rounds` (the solves), then the
    scenarios and sequences."""
    from hikbench.bench.harness.executors import SerialExecutor

    out = Path(out)
    plan = plan_run(suite, solvers=solvers, repeat=repeat, timeout=timeout, rounds=rounds, accuracy=accuracy,
                    say=log)
    summary = RunSummary(total=len(plan.tasks), skipped_solvers=plan.skipped, scenario_runs=len(plan.scenarios))
    with RunFolder(out) as folder:
        export, export_skipped = _export_formats(suite.export, log)
        for name, why in plan.skipped.items():
            log(f"skipping solver {name}: {why}")
        save_problems(plan.problems, out / "problems", export)
        if not plan.tasks:  # e.g. every solver's backend missing: the problems are still exported, then fail
            why = "; ".join(f"skipped solver {k}: {v}" for k, v in plan.skipped.items()) or (
                f"none of its solvers runs in its modes {list(suite.modes)}: warm needs supports_warm_start")
            raise SuiteError(f"suite {suite.source or suite.name} selects no job to run ({why}); "
                             f"its problems were written to {out / 'problems'}")
        todo, summary.skipped_finished, replaced = folder.resume(plan.tasks, plan.pcols, rerun=rerun, limit=limit,
                                                                 say=log)
        meta, session = folder.open_session(plan, todo, export_skipped)

        own_executor = executor is None
        executor = executor or SerialExecutor(log=out / "worker.log")
        session["executor"] = getattr(executor, "name", type(executor).__name__)
        failure = None
        try:
            with _Progress(quiet, log) as progress:
                _solve(plan, todo, out, executor, progress, summary)
                if plan.scenarios:
                    from hikbench.bench.scenarios.suite import run_scenarios
                    left = None if limit is None else max(int(limit) - summary.written, 0)
                    (summary.scenario_skipped_finished, summary.scenario_written,
                     summary.scenario_statuses) = run_scenarios(plan.scenarios, out, executor,
                                                                suite.first_solve_timeout, rerun=rerun, limit=left,
                                                                progress=progress)
                if suite.sequences:
                    from hikbench.bench.testset.sequences import run_sequences, sequence_tasks
                    entries = list({(t.entry.solver, t.entry.settings): t.entry for t in plan.tasks}.values())
                    summary.sequence_written = run_sequences(
                        sequence_tasks(suite.sequences, entries), out, executor, suite.first_solve_timeout,
                        PROFILES[plan.accuracy].rtol, rerun=rerun, progress=progress)
        except BaseException as err:
            failure = err
            raise
        finally:
            if own_executor:
                executor.close()
            folder.close_session(meta, session, summary, replaced, failure)
        write_summary(out)
        return summary


def _solve(plan: RunPlan, todo: list[Task], out: Path, executor, progress, summary: RunSummary) -> None:
    """The yardstick of every problem ``todo`` is judged on, then every task of ``todo`` in
    :func:`_rounds`, one row appended to results.csv as each job's last round ends."""
    suite = plan.suite
    judged, jcols = _judged_problems(todo, plan.problems, plan.pcols)
    refs = yardsticks([_judged_id(t) for t in todo], {t.problem.id: t.problem for t in todo}, judged, jcols, out,
                      executor, max(plan.timeout, suite.first_solve_timeout), suite.certify_timeout, progress)
    with ResultsWriter(out) as writer:
        for t, res in _rounds(plan, todo, executor, progress):
            row = make_row(t, plan.pcols[t.problem.id], judged[_judged_id(t)], refs[_judged_id(t)], res,
                           plan.accuracy)
            writer.write(row)
            summary.written += 1
            summary.statuses[row["status"]] = summary.statuses.get(row["status"], 0) + 1


def _rounds(plan: RunPlan, todo: list[Task], executor, progress):
    """Yield ``(task, result)`` for each task of ``todo``, its result merged over the run's
    rounds (:func:`_merge_rounds`) as its last round ends: round r runs every job still alive
    once, in fresh worker processes (``executor.renew()``; see :func:`run_suite`), its share
    of the repetitions (:func:`_share`)."""
    suite, rounds = plan.suite, plan.rounds
    tid = progress.add("solves", len(todo) * rounds)
    earlier = {i: [] for i in range(len(todo))}  # results of the rounds before, per job
    alive = list(earlier)  # jobs still to run in the next round
    for rnd in range(rounds):
        if rnd:  # (each round in fresh worker processes: see run_suite's docstring)
            executor.renew()
        share = (_share(plan.repeat, rounds, rnd), _share(plan.samples, rounds, rnd), suite.sample_time / rounds)
        items = ((i, _job(suite, todo[i], plan.problems, *share), plan.timeout) for i in alive)
        again = []
        for i, res in executor.map(items):
            t = todo[i]
            label = f"solves: {t.entry.solver} {t.mode}" + (f" (round {rnd + 1}/{rounds})" if rounds > 1 else "")
            if rnd < rounds - 1 and not _ends_rounds(res):
                earlier[i].append({k: res.get(k) for k in ("status", "samples_ns", "wall_s", "calib_ns", "host")})
                again.append(i)
                progress.advance(tid, label)
                continue
            yield t, _merge_rounds(earlier.pop(i), res, rounds)
            progress.advance(tid, label, rounds - rnd)
        alive = sorted(again)  # (the suite's order, whatever order the executor finished in)


def _share(count: int | None, rounds: int, rnd: int) -> int | None:
    """Round ``rnd``'s share of ``count`` repetitions (None: none asked)."""
    return None if count is None else count // rounds + (rnd < count % rounds)


def _job(suite: Suite, t: Task, problems: dict, repeat: int, samples: int | None = None,
         sample_time: float | None = None) -> dict:
    """The worker's job (hikbench.bench.harness.worker) timing ``repeat`` solves of task t,
    or more up to ``samples`` within ``sample_time`` s (hikbench.bench.harness.timing)."""
    return {"kind": "external" if t.entry.spec.kind == EXTERNAL else "solve",
            "hierarchy": problems[t.problem.id], "solver": t.entry.spec.text, "options": t.entry.options,
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


def _export_formats(formats, say) -> tuple[tuple, dict]:
    """The suite's export formats that this tree can write, and the others
    with the reason (said, and kept in run.json: not silently)."""
    keep, skipped = [], {}
    for fmt in formats:
        if fmt == "soth":
            try:
                import hikbench.problems.soth  # noqa: F401
            except ModuleNotFoundError:
                skipped[fmt] = "hikbench.problems.soth is not available in this tree; only npz was written"
                say(f"not exporting SOTH text: {skipped[fmt]}")
                continue
        keep.append(fmt)
    return tuple(keep), skipped


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
