"""``hikbench certify RUN``: the exact certificate of every recorded step of a scenario run, after
the fact, in worker processes, resumable.

Each run of the folder (bench/scenarios/recorded.py: ``<stem>_steps/``) gets
``<stem>_certificates.csv`` beside its per-step CSV, one row per step as it finishes:

=============  ====================================================================
step           the control step k
certified      the exact certificate (hikbench.problems.exact) accepted the active set
               read off the recorded u: its x* is the step's exact lexicographic optimum
reason         why not (the first check that failed), else empty
x_attains      no level norm of u is above x*'s beyond the high profile's tolerance
               (hikbench.problems.verify.judge); empty where not certified
above_level    the first level of u above x*'s where u does not attain it, else empty
level_norms    x*'s level norms (exact, rounded to float64), space-separated; empty where
               not certified
seconds        the certificate's time in its worker process (s)
sha256         SHA-256 of the step's hierarchy file and u: a row whose step was recorded
               again (another run written to the same folder) is certified again
=============  ====================================================================

A run interrupted (Ctrl-C, SIGTERM, a killed process) keeps every row it wrote; run again, it
certifies only the steps without a row (a row cut short by the kill is dropped). When every step
has its row the file is rewritten in step order.
"""

from __future__ import annotations

import csv
import hashlib
import multiprocessing as mp
import os
import sys
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hikbench.bench.scenarios.recorded import RecordedRun, read_runs
from hikbench.problems.errors import HikbenchError

__all__ = ["CERT_COLUMNS", "CertifySummary", "certificates_file", "certify_run"]

CERT_COLUMNS = ("step", "certified", "reason", "x_attains", "above_level", "level_norms", "seconds", "sha256")
#: seconds between two progress lines
TICK_S = 10.0


def certificates_file(run: RecordedRun) -> Path:
    """``<RUN>/<stem>_certificates.csv``: beside the run's per-step CSV."""
    return run.folder.parent / f"{run.stem}_certificates.csv"


@dataclass
class CertifySummary:
    """What :func:`certify_run` did: steps in all, already certified before (resumed), certified
    now, and the outcomes: ``certified``, ``attains`` (x attains x*), ``not_optimal``
    ``[(stem, step, level)]``, ``refused`` ``[(stem, step, reason)]``, the files written."""

    steps: int = 0
    resumed: int = 0
    done_now: int = 0
    certified: int = 0
    attains: int = 0
    not_optimal: list = field(default_factory=list)
    refused: list = field(default_factory=list)
    files: list = field(default_factory=list)
    wall_s: float = 0.0


def _digest(path: Path, u: np.ndarray) -> str:
    h = hashlib.sha256(path.read_bytes())
    h.update(np.ascontiguousarray(u, dtype="<f8").tobytes())
    return h.hexdigest()


def _watch_parent(parent: int) -> None:
    """In a worker: end the process once its parent is gone (a SIGKILLed ``hikbench certify``
    leaves no worker behind; ProcessPoolExecutor's workers would wait for work forever)."""
    import threading

    def watch():
        while os.getppid() == parent:
            time.sleep(1.0)
        os._exit(1)

    threading.Thread(target=watch, daemon=True).start()


def _certify_step(path: str, u: np.ndarray) -> dict:
    """In a worker: load step ``path``, certify u (:func:`hikbench.bench.harness.worker.certify_point`);
    a bad file or u is ``{"error": message}`` (raised by the caller, one line)."""
    from hikbench.bench.harness.worker import certify_point
    from hikbench.problems.files import load_npz

    try:
        h = load_npz(path)
        t0 = time.process_time()
        res = certify_point(h, np.asarray(u, dtype=float))
        seconds = time.process_time() - t0
    except HikbenchError as err:
        return {"error": str(err)}
    norms = " ".join(repr(v) for v in res["level_norms"]) if res["certified"] else ""
    return {"certified": bool(res["certified"]), "reason": res["reason"],
            "x_attains": res.get("attains"), "above_level": res.get("above_level"),
            "level_norms": norms, "seconds": round(seconds, 4)}


def _read_done(path: Path, digests: dict) -> dict:
    """The rows of an earlier (maybe interrupted) certificates file whose step and digest match
    the run's: ``{step: row}``. A row cut short, unparsable or of another recording is dropped."""
    if not path.is_file():
        return {}
    done = {}
    try:
        with open(path, newline="", encoding="utf-8") as f:
            reader = csv.reader(f)
            header = next(reader, None)
            if header != list(CERT_COLUMNS):
                raise HikbenchError(f"{path}: its header is {header}; expected {list(CERT_COLUMNS)} (a certificates "
                                    f"file of `hikbench certify`; move it away to certify the run again)")
            for fields in reader:
                if len(fields) != len(CERT_COLUMNS) or len(fields[-1]) != 64:
                    continue
                row = dict(zip(CERT_COLUMNS, fields))
                try:
                    k = int(row["step"])
                except ValueError:
                    continue
                if digests.get(k) == row["sha256"] and row["certified"] in ("True", "False"):
                    done[k] = row
    except (OSError, UnicodeDecodeError, csv.Error) as err:
        raise HikbenchError(f"{path}: cannot read ({err}); expected a certificates file of `hikbench certify`") \
            from err
    return done


def _cell(v) -> str:
    return "" if v is None else str(v)


def _write_rows(path: Path, rows: list[dict]) -> None:
    """Write header and rows to ``path`` at once (a temporary file renamed over it)."""
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(CERT_COLUMNS)
        for row in rows:
            w.writerow([_cell(row.get(c)) for c in CERT_COLUMNS])
    os.replace(tmp, path)


def certify_run(run: str | os.PathLike, workers: int = 2, log=sys.stderr) -> CertifySummary:
    """Certify every recorded step of the scenario run folder ``run`` (module docstring) in
    ``workers`` fresh (spawned) processes; steps with a row already are not certified again.
    Progress lines go to ``log`` (None: quiet). HikbenchError on a bad folder or step file."""
    if workers < 1:
        raise HikbenchError(f"--workers must be >= 1; got {workers}")
    t0 = time.perf_counter()
    runs = read_runs(run)
    out = CertifySummary()
    plans = []  # (run, digests, done rows)
    for r in runs:
        digests = {int(k): _digest(r.hierarchy_file(k), u) for k, u in zip(r.steps, r.u)}
        done = _read_done(certificates_file(r), digests)
        _write_rows(certificates_file(r), [done[k] for k in sorted(done)])  # (without the cut or stale rows)
        plans.append((r, digests, done))
        out.steps += len(r.steps)
        out.resumed += len(done)
    todo = [(r, i) for r, _, done in plans for i, k in enumerate(r.steps.tolist()) if k not in done]
    if log is not None:
        print(f"hikbench certify: {len(runs)} run(s), {out.steps} steps, {out.resumed} certified before, "
              f"{len(todo)} to go in {workers} worker(s)", file=log, flush=True)
    sinks = {r.stem: open(certificates_file(r), "a", newline="", encoding="utf-8") for r in runs}  # noqa: SIM115
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn"), initializer=_watch_parent,
                               initargs=(os.getpid(),)) if todo else None
    try:
        pending = {pool.submit(_certify_step, str(r.hierarchy_file(r.steps[i])), r.u[i]): (r, i) for r, i in todo} \
            if todo else {}
        digests = {r.stem: d for r, d, _ in plans}
        last = time.perf_counter()
        while pending:
            finished, _ = wait(pending, timeout=TICK_S, return_when=FIRST_COMPLETED)
            for fut in finished:
                r, i = pending.pop(fut)
                res = fut.result()
                if "error" in res:
                    raise HikbenchError(res["error"])
                k = int(r.steps[i])
                row = {"step": k, **res, "sha256": digests[r.stem][k]}
                csv.writer(sinks[r.stem]).writerow([_cell(row.get(c)) for c in CERT_COLUMNS])
                sinks[r.stem].flush()
                out.done_now += 1
            if log is not None and (time.perf_counter() - last >= TICK_S or not pending):
                last = time.perf_counter()
                el = last - t0
                left = len(pending) * el / max(out.done_now, 1)
                print(f"hikbench certify: {out.resumed + out.done_now}/{out.steps} steps ({el:.0f} s"
                      + (f", ~{left:.0f} s left)" if pending else ")"), file=log, flush=True)
    finally:
        for f in sinks.values():
            f.close()
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)  # (an interrupt: the steps in flight finish, no more)
    for r, _, _ in plans:
        path = certificates_file(r)
        rows = _read_done(path, {int(k): v for k, v in zip(r.steps.tolist(), (_digest(r.hierarchy_file(k), u)
                                                                          for k, u in zip(r.steps, r.u)))})
        _write_rows(path, [rows[k] for k in sorted(rows)])
        out.files.append(path)
        for k in sorted(rows):
            row = rows[k]
            if row["certified"] == "True":
                out.certified += 1
                if row["x_attains"] == "True":
                    out.attains += 1
                else:
                    out.not_optimal.append((r.stem, k, row["above_level"]))
            else:
                out.refused.append((r.stem, k, row["reason"]))
    out.wall_s = time.perf_counter() - t0
    return out
