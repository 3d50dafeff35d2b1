"""A scenario run's recorded steps: each control step's hierarchy and the controller's u, written
beside the run's per-step CSV by ``hikbench scenario`` so that ``hikbench certify RUN`` can
certify them after the fact (bench/scenarios/certify_run.py).

For a run ``<stem>`` (:func:`hikbench.bench.scenarios.rows.run_stem`) the folder ``<stem>_steps/``
holds ``step=KKKK.npz``, the hierarchy of step k (the problem-file format of
docs/problem-files.md, deflated), for every step with a finite u, and ``u.npz``: ``step`` (S,),
the recorded steps in order, and ``u`` (S, n), their u (float64, as the solver returned it).
"""

from __future__ import annotations

import os
import shutil
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hikbench.problems.errors import HikbenchError

__all__ = ["RecordedRun", "read_runs", "step_file", "write_steps"]

SUFFIX = "_steps"  #: ``<stem>_steps/``: the folder of a run's recorded steps
U_FILE = "u.npz"


def step_file(folder: Path, k: int) -> Path:
    """The hierarchy file of step k in a run's steps folder."""
    return folder / f"step={k:04d}.npz"


def write_steps(out: Path, stem: str, steps: list) -> Path:
    """Write ``steps`` (``[(k, hierarchy, u)]``, ScenarioRun.steps) to ``out/<stem>_steps/``
    (module docstring), replacing what an earlier run of the same stem left there; returns
    the folder."""
    from hikbench.problems.files import save_npz

    folder = Path(out) / f"{stem}{SUFFIX}"
    if folder.is_dir():
        shutil.rmtree(folder)
    try:
        folder.mkdir(parents=True)
    except OSError as err:
        raise HikbenchError(f"{folder}: cannot create the directory: {err.strerror or err}") from err
    for k, h, _ in steps:
        save_npz(h, step_file(folder, k), compressed=True)
    n = steps[0][1].n if steps else 0
    np.savez(folder / U_FILE, step=np.array([k for k, _, _ in steps], dtype=np.int64),
             u=np.array([u for _, _, u in steps], dtype=np.float64).reshape(len(steps), n))
    return folder


@dataclass
class RecordedRun:
    """One run's recorded steps: its ``stem``, its steps ``folder``, the ``steps`` (S,) and their
    ``u`` (S, n)."""

    stem: str
    folder: Path
    steps: np.ndarray
    u: np.ndarray

    def hierarchy_file(self, k: int) -> Path:
        return step_file(self.folder, int(k))


def read_runs(run: str | os.PathLike) -> list[RecordedRun]:
    """The recorded runs of the folder ``run`` (what ``hikbench scenario --out RUN`` writes), in
    name order. HikbenchError, naming the path and what was expected, where ``run`` is not a
    folder, holds no recorded steps, or a run's ``u.npz`` or a step's file is missing or
    unreadable (a step file's content is read, and checked, where it is certified)."""
    path = Path(run)
    if not path.exists():
        raise HikbenchError(f"{path}: no such folder; expected the --out folder of `hikbench scenario`")
    if not path.is_dir():
        raise HikbenchError(f"{path}: is a file; expected the --out folder of `hikbench scenario`")
    folders = sorted(p for p in path.iterdir() if p.is_dir() and p.name.endswith(SUFFIX))
    if not folders:
        csvs = sorted(p.name for p in path.glob("*.csv") if p.name != "summary.csv"
                      and not p.name.endswith("_certificates.csv"))
        hint = (f" (its {', '.join(csvs[:3])} were written without them: run the scenario again with this "
                f"hikbench)") if csvs else ""
        raise HikbenchError(f"{path}: no recorded steps (<run>{SUFFIX}/ folders, written by `hikbench scenario "
                            f"--out {path}`){hint}")
    return [_read_run(f) for f in folders]


def _read_run(folder: Path) -> RecordedRun:
    stem = folder.name[: -len(SUFFIX)]
    ufile = folder / U_FILE
    if not ufile.is_file():
        raise HikbenchError(f"{ufile}: missing; expected the recorded u of run {stem} (arrays step, u)")
    try:
        with np.load(ufile, allow_pickle=False) as z:
            missing = [k for k in ("step", "u") if k not in z.files]
            if missing:
                raise HikbenchError(f"{ufile}: missing array(s) {missing}; expected step (S,) and u (S, n)")
            steps, u = z["step"], z["u"]
    except (OSError, EOFError, ValueError, zipfile.BadZipFile) as err:
        raise HikbenchError(f"{ufile}: not a valid .npz file ({err}); expected arrays step (S,) and u (S, n)") \
            from err
    if steps.ndim != 1 or steps.dtype.kind not in "iu" or u.ndim != 2 or u.dtype.kind != "f" \
            or u.shape[0] != steps.shape[0]:
        raise HikbenchError(f"{ufile}: step has shape {steps.shape} ({steps.dtype}) and u {u.shape} ({u.dtype}); "
                            f"expected step (S,) integers and u (S, n) float64")
    if len(set(steps.tolist())) != len(steps):
        raise HikbenchError(f"{ufile}: step lists a step twice; expected each recorded step once")
    for k in steps.tolist():
        if not step_file(folder, k).is_file():
            raise HikbenchError(f"{step_file(folder, k)}: missing; expected the hierarchy of step {k} of run {stem} "
                                f"(listed in {ufile})")
    return RecordedRun(stem, folder, steps.astype(np.int64), u.astype(np.float64))
