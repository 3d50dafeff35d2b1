"""Rounds of one suite run alternately on two sides (``hikbench regress``):
round r runs the suite once on each side, the order alternating ABBA (base,
change, change, base, ...) so that a drift of the machine's speed falls on both
sides alike. Each run is a plain ``hikbench run`` of that side into
``OUT/rounds/<side>-<r>``; a side's later rounds start from its first round's
problem files and yardsticks (copied), so they only time.
"""

from __future__ import annotations

import shutil
import subprocess
import time
from pathlib import Path

import pandas as pd

from hikbench.bench.harness.revisions import RevisionError, Side

__all__ = ["Rounds"]

#: folders of a run directory a later round of the same side reuses
_SEEDED = ("problems", "yardstick")


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

    def run_round(self) -> None:
        r = self.done
        order = ("base", "change") if r % 2 == 0 else ("change", "base")
        for name in order:
            self.frames[name].append(self._run(name, r))

    def _run(self, name: str, r: int) -> pd.DataFrame:
        side = self.sides[name]
        target = self.out / "rounds" / f"{name}-{r + 1}"
        shutil.rmtree(target, ignore_errors=True)
        first = self.out / "rounds" / f"{name}-1"
        if r:
            for folder in _SEEDED:
                if (first / folder).is_dir():
                    shutil.copytree(first / folder, target / folder)
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
