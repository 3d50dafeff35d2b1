"""The columns of ``results.csv``, documented once (``hikbench columns``).

One tidy row per (problem, solver, settings, mode). JSON columns hold a JSON
string (lists of per-level values, dicts of parameters); empty cells mean "not
applicable / not reported".
"""

from __future__ import annotations

from hikbench.problems.verify import PROFILES


def _e(v: float) -> str:
    """1e-09 as 1e-9."""
    return f"{v:.0e}".replace("e-0", "e-")


__all__ = ["COLUMNS", "JSON_COLUMNS", "KEY", "VERIFIED_COLUMNS", "markdown", "names"]

#: (name, description), in CSV order
COLUMNS: tuple[tuple[str, str], ...] = (
    ("problem", ("problem id: family/param=value,.../seed=S (the file OUT/problems/<id>.npz, each / of the "
                 "id written __)")),
    ("problem_hash", ("the problem's content: 16 hex digits of the SHA-256 of its arrays A, lower, upper, level, "
                      "n, depth (hikbench.bench.harness.cache.problem_hash); its yardstick is cached as "
                      "OUT/yardstick/<problem_hash>.npz. A finished row whose problem_hash differs from its "
                      "problem's now (a family's parameters or code changed) is run again")),
    ("family", "problem family (a `hikbench list families` name, or module:function)"),
    ("params", "JSON dict of the family parameters given by the suite (defaults not repeated)"),
    ("seed", "generator seed"),
    ("n", "number of variables (DOF)"),
    ("depth", "number of levels"),
    ("rows", "total number of rows"),
    ("eq_rows", "rows with lower == upper"),
    ("ineq_rows", "rows with lower < upper (one- or two-sided inequalities, free rows excluded)"),
    ("rows_per_level", "JSON list: rows of each level"),
    ("ranks", "JSON list: rank of each level's A_k alone (numpy.linalg.matrix_rank)"),
    ("rank", "rank of the whole stacked A"),
    ("solver", "solver name (registry name; the class's `name` for module:Class and file.py:Class; external:NAME)"),
    ("settings", "settings name from the suite ('default' = the solver's own defaults)"),
    ("options", "JSON dict of the solver options of these settings"),
    ("solver_settings", ("JSON dict: the settings the solver ran with, its defaults resolved (Solver.settings); "
                         "for a cascade its accuracy profile, backend tolerance preset, freeze mode, "
                         "regularization, iteration cap, relax_delta and slack_tol: the swept defaults of "
                         "`hikbench list solvers --settings` where options do not set them; empty for "
                         "solvers that report none")),
    ("strict", ("the solver's claim: True for a strict-hierarchy solver (judged against the lexicographic optimum: "
                "verified), False for a weighted or damped one (judged by its real times, per-level gaps and "
                "level 0 met); from Solver.strict / SolverInfo.strict, or external:NAME[strict=false]=CMD")),
    ("mode", "cold (fresh solver object per repetition) or warm (re-solve on one object)"),
    ("repeat", ("timed repetitions (after the discarded warm-up; with rounds, over all of them): the suite's "
                "`repeat`, or more, up to its `samples`, for a fast solve (docs/running.md, Timing); external "
                "programs: exactly `repeat`")),
    ("status", ("solver status (optimal, max_iterations, infeasible_level, numerical_failure, "
                "unsupported, error) or harness status (timeout: killed after --timeout; "
                "crashed: the worker process died, e.g. segfault)")),
    ("reason", ("detail for any status other than optimal; also, when the row reports a timed "
                "repetition other than the last, which one and why (see verified)")),
    ("verified", ("the verdict at the run's headline accuracy profile (`hikbench run --accuracy`, the suite's "
                  "`accuracy`, run.json `accuracy.profile`): its column verified_<profile>. True when no level "
                  "norm recomputed from x is above the certified yardstick's (the exact optimum) beyond the "
                  "level's tolerance, rtol x the level's own terms (hikbench.problems.verify.judge, "
                  "docs/verification.md); False otherwise; "
                  "empty when the yardstick is not certified (see yardstick): a row is never verified "
                  "against an uncertified point. x, status and the counts are those of the "
                  "last timed repetition unless an earlier one was worse: a status other than optimal "
                  "beside the last's optimal, or an x above the last's at some level beyond 1e-9 of its "
                  "scale (hikbench.bench.harness.timing.reported_result); the row then reports that one")),
    *((f"verified_{p}", (f"the verdict at the `{p}` profile (rtol {_e(prof.rtol)} of each level's own terms): "
                         f"True, False, or empty as verified. A row verified at a profile is verified at every "
                         f"looser one (high, then default, then low)")) for p, prof in PROFILES.items()),
    ("verdict_level", ("at the headline profile, the first level whose norm is above the yardstick's beyond its "
                       "tolerance (verified False), else the first below it beyond it (empty: none)")),
    ("verdict_side", ("at verdict_level: 'worse' (solver higher than the yardstick), 'better', "
                      "'no x' (no solution), 'no yardstick', 'no certified yardstick' (yardstick "
                      "reference-only, x equal to its point; '...; worse than its point' or '...; better "
                      "than its point' with verdict_level when not: not a verdict, verified stays empty); "
                      "empty when equal")),
    ("verdict_diff", "solver norm - yardstick norm at verdict_level"),
    ("yardstick", ("what the problem's yardstick is: 'certified' (the lexicographically lowest of the "
                   "independent yardstick's and hcod's points, accepted by the exact certificate "
                   "hikbench.problems.exact.certify: the exact optimum), 'reference-only' (a point the certificate refused, "
                   "or did not reach within the suite's certify_timeout: rows are not verified against "
                   "it), 'none' (no candidate gave a point)")),
    ("yardstick_reason", ("which candidate the yardstick is (the independent yardstick's point or "
                          "hcod's) and, when not certified, why; for a solver whose levels are row-normalised "
                          "(Solver.judged_on, DAQP's hierarchical QP) it starts with 'judged on the "
                          "row-normalised hierarchy (the solver's claim):': the row's verdict and norms are "
                          "then those of hikbench.problems.hierarchy.row_normalised(problem), against its own "
                          "yardstick")),
    ("level_norms", "JSON list: ||v_k(x)||_2 per level, recomputed from x (hikbench.problems.verify.level_norms)"),
    ("ref_level_norms", "JSON list: the same for the yardstick's solution (hikbench.solvers.yardstick)"),
    ("level_gaps", ("JSON list: per level, (||v_k(x)|| - ||v_k(x_ref)||) / t_k, x's level norm above the "
                    "yardstick's relative to the level's own terms t_k = || |A_k| |x_ref| + |b_k| || "
                    "(hikbench.problems.verify.level_gaps; < 0: below it; null: the terms vanish and the "
                    "norms differ, or a norm is NaN). A row is verified at a profile when every gap is at "
                    "most its rtol (up to the round-off floor, docs/verification.md); against a "
                    "reference-only yardstick the gaps are to its point, not a verdict")),
    ("x_norm", "||x||_2 of the solution (minimum-norm solvers match the yardstick's)"),
    ("iterations", "iterations reported by the solver (last timed repetition)"),
    ("iterations_per_level", "JSON list: iterations of each level, if reported"),
    ("activations", "active-set activations (last timed repetition)"),
    ("deactivations", "active-set deactivations (last timed repetition)"),
    ("flops", "multiply-adds counted by the solver, if it counts"),
    ("time_median_s", ("p50 (the median) over the timed repetitions of the wall time of the solve call, "
                       "seconds: the time the ranking, compare and the figures use")),
    ("time_p90_s", "p90 of the same samples (numpy.percentile, linear interpolation), seconds"),
    ("time_p99_s", ("p99 of the same samples, seconds (with fewer than 100 samples it lies between the two "
                    "largest: see `repeat`)")),
    ("time_max_s", "maximum of the same samples (the worst timed solve), seconds"),
    ("time_min_s", "minimum of the same samples, seconds"),
    ("build_time_s", "time the solver reports for assembling matrices (last repetition), seconds"),
    ("solve_time_s", "time the solver (or an external program) reports for itself, seconds"),
    ("samples_ns", "JSON list: every timed repetition, nanoseconds (used by compare)"),
    ("calib_ns", ("calibration kernel time, ns (bench/harness/calibration.py): around this row's timed solves when "
                  "the suite sets calibrate_each_job, else at the start of the worker process (with rounds, "
                  "the median of the rounds'); compare divides times by it")),
    ("host", "host name of the worker"),
    ("worker", "worker id (pid@host serial, dask worker address with --workers/--scheduler)"),
    ("wall_s", "wall time of the whole job (warm-up + repetitions + transport; with rounds, their sum), seconds"),
    ("finished_at", "UTC time the row was written (ISO 8601)"),
)

#: the verdict columns (True, False or empty): the headline's, then each profile's
VERIFIED_COLUMNS = ("verified", *(f"verified_{p}" for p in PROFILES))
KEY = ("problem", "solver", "settings", "mode")  #: a row's identity; resuming skips finished keys
JSON_COLUMNS = ("params", "rows_per_level", "ranks", "options", "solver_settings", "level_norms", "ref_level_norms", "level_gaps",
                "iterations_per_level", "samples_ns")
NUMBER_COLUMNS = ("seed", "n", "depth", "rows", "eq_rows", "ineq_rows", "rank", "repeat", "verdict_level",
                  "verdict_diff", "x_norm", "iterations", "activations", "deactivations", "flops", "time_median_s",
                  "time_p90_s", "time_p99_s", "time_max_s", "time_min_s", "build_time_s", "solve_time_s",
                  "calib_ns", "wall_s")


def names() -> list[str]:
    return [c for c, _ in COLUMNS]


def markdown() -> str:
    """The table as markdown (docs/columns.md holds it)."""
    lines = ["| column | meaning |", "|---|---|"]
    lines += [f"| `{c}` | {d} |" for c, d in COLUMNS]
    return "\n".join(lines)
