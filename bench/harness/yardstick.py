"""The yardstick of a run's problems: the point each row's x is judged against
(docs/verification.md), what it is (certified, reference-only, none), and its cache.

* :class:`Yardstick`: the point and its record (columns ``yardstick``, ``yardstick_reason``).
* :func:`yardsticks`: the yardstick of each problem of a run, from the cache or computed
  through the executor, each step an isolated job: the choice between the candidate points
  (:func:`lowest`) and their exact certificate (:func:`certify_all`).
* The cache: ``OUT/yardstick/<problem_hash>.npz`` (:func:`yardstick_path`) holds ``x``,
  ``status``, ``reason``, ``kind``, ``kind_reason``, ``certify_budget``, ``problem_hash``
  and ``code`` (:func:`hikbench.bench.harness.cache.yardstick_code`); a file that cannot be
  read, holds a yardstick of another size, of another problem or of other code is computed
  again (:func:`load_yardstick`).
"""

from __future__ import annotations

import dataclasses
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hikbench.bench.harness.cache import yardstick_code
from hikbench.bench.harness.regular import open_regular
from hikbench.bench.harness.statuses import CRASHED, TIMEOUT
from hikbench.problems.errors import HikbenchError
from hikbench.problems.files import check_zip_members
from hikbench.problems.verify import verify
from hikbench.solvers.base import ERROR

__all__ = ["CERTIFIED", "NO_YARDSTICK", "REFERENCE_ONLY", "Yardstick", "certify_all", "load_yardstick", "lowest",
           "save_yardstick", "yardstick_path", "yardsticks"]

#: what a row's yardstick is (column ``yardstick``): certified by the exact certificate, a
#: reference point the certificate did not accept (or did not reach in its budget), none at all
CERTIFIED, REFERENCE_ONLY, NO_YARDSTICK = "certified", "reference-only", "none"
KINDS = (CERTIFIED, REFERENCE_ONLY, NO_YARDSTICK)


@dataclass(frozen=True, eq=False)
class Yardstick:
    """The yardstick of one problem.

    x : ndarray, shape (n,), or None
        The point rows are judged against (None: no candidate point was found).
    status : str
        ``optimal`` where there is a point, else the status of the step that failed
        (error; timeout or crashed: a lost worker, not cached).
    reason : str
        The note naming the candidate point (``the independent yardstick's point``,
        ``hcod's point (...)``), or why there is none.
    kind : str
        :data:`CERTIFIED`, :data:`REFERENCE_ONLY` or :data:`NO_YARDSTICK` (column ``yardstick``).
    kind_reason : str
        Column ``yardstick_reason``: how the certificate decided, or why it did not.
    certify_budget : float
        > 0: its certificate stopped at this budget (s); a run with a larger
        ``certify_timeout`` tries again. 0: decided.
    """

    x: np.ndarray | None
    status: str
    reason: str
    kind: str
    kind_reason: str
    certify_budget: float = 0.0


def yardsticks(pids, specs: dict, problems: dict, pcols: dict, out: Path, executor, timeout: float,
               certify_timeout: float, progress) -> dict[str, Yardstick]:
    """The :class:`Yardstick` of each problem id of ``pids``, from ``OUT/yardstick/<problem_hash>.npz``
    or computed through the executor (isolated), each step its own job with its own timeout (one
    that fails costs its step, never a point already found nor the run; ``timeout``: the larger of
    the job timeout and the first-solve allowance):

    1. the independent yardstick's point, and its exact certificate (:func:`certify_all`);
       certified, it is the lexicographic optimum and the yardstick;
    2. otherwise ``hcod``'s point too: the lexicographically lowest of the two
       (:func:`lowest`), certified in turn where the independent one was refused or missing
       (a certificate stopped by its budget is not tried again on the other point).

    ``specs``: problem id -> ProblemSpec of the run's problems (a row-normalised hierarchy's id
    is none of these). A problem of a test set (family ``testset``, docs/testset.md) has its
    stored certified optimum as its yardstick, computed by none of these. Problems of the same
    content share one. A cached file of other yardstick code
    (:func:`hikbench.bench.harness.cache.yardstick_code`) is computed again, which one line
    (``progress.say``) says. A yardstick whose step a killed or lost worker ended is not cached:
    the next run tries again."""
    code = yardstick_code()
    refs, need, recertify, first_of, twins, stale = {}, [], [], {}, {}, 0
    for pid in dict.fromkeys(pids):
        if pid in specs and specs[pid].family == "testset":  # a test set's problem: its stored certified optimum
            from hikbench.problems.testset import stored_optimum  # (read once: cached_set)
            x, note = stored_optimum(specs[pid].params.get("set", "hlsp-1"), specs[pid].params["problem"])
            refs[pid] = Yardstick(x, "optimal", note, CERTIFIED, note)
            continue
        phash = pcols[pid]["problem_hash"]
        if phash in first_of:
            twins[pid] = first_of[phash]
            continue
        first_of[phash] = pid
        path = yardstick_path(out, phash)
        cached = load_yardstick(path, problems[pid].n, progress.say) if path.exists() else None
        if cached is not None and cached[1] != phash:  # (a file copied or renamed by hand)
            progress.say(f"{path} holds the yardstick of problem_hash {cached[1]}, not {phash}; "
                         f"computing the yardstick again")
            cached = None
        elif cached is not None and cached[2] != code:
            stale += 1
            cached = None
        if cached is None:
            need.append(pid)
            continue
        refs[pid] = cached[0]
        if cached[0].kind == REFERENCE_ONLY and 0 < cached[0].certify_budget < certify_timeout:  # (a larger budget)
            recertify.append(pid)
    if stale:
        progress.say(f"{stale} cached yardstick(s) computed again: the yardstick's code changed "
                     f"(hikbench.bench.harness.cache.YARDSTICK_MODULES, version {code})")
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
    first.update({pid: (refs[pid].x, refs[pid].reason) for pid in recertify})
    refs.update(certify_all(first, problems, executor, certify_timeout, progress))
    others = [pid for pid in need if pid not in refs or refs[pid].kind != CERTIFIED]
    if others:
        collect("x_hcod", others)
    second = {}
    for pid in others:
        x, note = lowest(problems[pid], found[pid])
        if x is None:
            why = "; ".join(filter(None, (found[pid].get("reason"), found[pid].get("hcod_reason"))))
            refs[pid] = Yardstick(None, killed.get(pid, ERROR), why, NO_YARDSTICK, "no candidate point")
        elif pid not in refs or (x is not found[pid]["x"] and refs[pid].certify_budget == 0):
            second[pid] = (x, note)  # (none certified yet, or hcod's point lower than a refused one)
        else:  # (the independent point stays; its certificate's outcome, with the candidates named)
            said = refs[pid].kind_reason
            refs[pid] = dataclasses.replace(refs[pid], x=x, reason=note,
                                            kind_reason=note + said[said.index(";"):] if ";" in said else note)
    refs.update(certify_all(second, problems, executor, certify_timeout, progress))
    for pid in [*need, *recertify]:
        if pid not in killed:
            phash = pcols[pid]["problem_hash"]
            save_yardstick(yardstick_path(out, phash), refs[pid], phash, code)
    for pid, first in twins.items():
        refs[pid] = refs[first]
    return refs


def lowest(h, res: dict):
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


def certify_all(points: dict, problems: dict, executor, budget: float, progress) -> dict[str, Yardstick]:
    """The exact certificate of each problem's chosen point (pid -> (x, note)), through the
    executor with ``budget`` seconds each; a problem whose estimated cost
    (:func:`hikbench.problems.exact.estimated_seconds`) exceeds twice the budget is not tried.
    Returns pid -> :class:`Yardstick`: ``certified`` (the certificate's exact optimum x*,
    rounded, whether x attains it or not), else ``reference-only`` with the reason (refused, timed out, not
    tried, failed), never losing the point."""
    from hikbench.problems.exact import estimated_seconds

    refs, items = {}, []
    for pid, (x, note) in points.items():
        est = estimated_seconds(problems[pid])
        if est > 2 * budget:
            refs[pid] = Yardstick(x, "optimal", note, REFERENCE_ONLY,
                                  f"{note}; not certified: the exact certificate was not tried, its estimated "
                                  f"time ({est:.0f} s) is beyond twice certify_timeout ({budget:g} s)", budget)
        else:
            items.append((pid, {"kind": "certify", "hierarchy": problems[pid], "x": x}, budget))
    if items:
        tid = progress.add("certificate", len(items))
        for pid, res in executor.map(iter(items)):
            progress.advance(tid)
            x, note = points[pid]
            if res["status"] == TIMEOUT:
                refs[pid] = Yardstick(x, "optimal", note, REFERENCE_ONLY,
                                      f"{note}; not certified: the exact certificate did not finish in "
                                      f"certify_timeout ({budget:g} s)", budget)
            elif res["status"] != "optimal":
                refs[pid] = Yardstick(x, "optimal", note, REFERENCE_ONLY,
                                      f"{note}; not certified: the exact certificate {res['status']}: "
                                      f"{res.get('reason', '')}", budget if res["status"] == CRASHED else 0.0)
            elif not res["certified"]:
                refs[pid] = Yardstick(x, "optimal", note, REFERENCE_ONLY,
                                      f"{note}; the exact certificate refused it: {res['reason']}")
            elif res.get("x_cert") is None:  # (x* is not representable: no double reaches it)
                refs[pid] = Yardstick(x, "optimal", note, CERTIFIED,
                                      f"{note}; the certificate's exact optimum x* is not representable in double "
                                      f"precision (rounded, it misses its exact level norms at level "
                                      f"{res['unrepresentable_level']}): the point is the yardstick")
            else:  # (certified: the exact optimum x* is the yardstick, never a point within a tolerance of it)
                refs[pid] = Yardstick(res["x_cert"], "optimal", note, CERTIFIED,
                                      f"the certificate's exact optimum x*, from {note}" + (
                                          "" if res["attains"] else f", which is above it at level "
                                                                    f"{res['above_level']}"))
    return refs


# ---- the cache: OUT/yardstick/<problem_hash>.npz ------------------------------------------------

_MEMBER_BYTES = 1 << 16  # of a cached yardstick's member beyond 8 bytes a variable (its header, a reason)


def yardstick_path(out: Path, phash: str) -> Path:
    """``OUT/yardstick/<problem_hash>.npz``."""
    return Path(out) / "yardstick" / f"{phash}.npz"


def load_yardstick(path: Path, n: int, say) -> tuple[Yardstick, str, str] | None:
    """``(yardstick, problem_hash, code)`` cached in ``path``, or None, said (``say``) in one
    line naming the file, when it cannot be read or holds no yardstick of ``n`` variables (a
    damaged file: the caller computes it again, as it does for a key other than its own). A
    file without ``kind`` (written before yardsticks were certified) has the code ``""``."""
    try:
        with open_regular(path) as f:  # (a FIFO is not waited on, a folder not read)
            with zipfile.ZipFile(f) as zf:  # (no member encrypted, compressed otherwise, or larger than x)
                check_zip_members(path, zf, 8 * int(n) + _MEMBER_BYTES)
            f.seek(0)
            with np.load(f, allow_pickle=False) as z:
                x, status, reason = z["x"], str(z["status"]), str(z["reason"])
                phash, code = str(z["problem_hash"]), str(z["code"]) if "kind" in z.files else ""
                kind = (str(z["kind"]), str(z["kind_reason"]), float(z["certify_budget"])) if "kind" in z.files \
                    else (NO_YARDSTICK, "", 0.0)
        if x.dtype.kind != "f" or x.shape not in ((0,), (n,)):
            raise ValueError(f"x of dtype {x.dtype} and shape {x.shape}: expected float64 of shape ({n},)")
        if kind[0] not in KINDS:
            raise ValueError(f"kind {kind[0]!r}: expected {CERTIFIED}, {REFERENCE_ONLY} or {NO_YARDSTICK}")
    except (OSError, EOFError, KeyError, ValueError, zipfile.BadZipFile, HikbenchError) as err:
        say(f"{path} cannot be read ({type(err).__name__}: {' '.join(str(err).split())}); "
            f"computing the yardstick again")
        return None
    return Yardstick(x if x.size else None, status, reason, *kind), phash, code


def save_yardstick(path: Path, ref: Yardstick, phash: str, code: str) -> None:
    """Write the yardstick ``ref`` of the problem ``phash`` computed by yardstick code ``code``
    (atomically)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    with open(tmp, "wb") as f:
        np.savez(f, x=np.zeros(0) if ref.x is None else np.asarray(ref.x, float), status=ref.status,
                 reason=ref.reason, kind=ref.kind, kind_reason=ref.kind_reason,
                 certify_budget=float(ref.certify_budget), problem_hash=phash, code=code)
    tmp.replace(path)
