"""results.csv: rows appended as they finish (one flush + fsync per row), read
back for resuming, reporting and comparing.

A run killed in the middle of writing a row leaves at most one partial last
line; :class:`ResultsWriter` cuts it off before appending (that row was not
finished, so it is run again). Finished rows are never rewritten, except by
``--rerun``, which first copies the file to ``results.csv.bak``.
"""

from __future__ import annotations

import csv
import io
import json
import os
import shutil
from pathlib import Path

import pandas as pd

from bench.columns import JSON_COLUMNS, KEY, names
from problems.errors import HikbenchError

__all__ = ["ResultsWriter", "read_results", "finished_keys", "RESULTS", "parse_json_column"]

RESULTS = "results.csv"


def _cut_partial_line(path: Path) -> None:
    with open(path, "rb+") as f:
        data = f.read()
        if data and not data.endswith(b"\n"):
            f.truncate(data.rfind(b"\n") + 1)


def _check_header(path: Path) -> None:
    with open(path, newline="") as f:
        header = next(csv.reader(f), None)
    if header is not None and header != names():
        raise HikbenchError(f"{path}: its columns differ from this version's ({len(header)} vs {len(names())} "
                            f"columns); write to a new --out directory")


class ResultsWriter:
    """Appends rows (dicts keyed by bench.columns names) to OUT/results.csv."""

    def __init__(self, out_dir: str | os.PathLike):
        self.path = Path(out_dir) / RESULTS
        self.path.parent.mkdir(parents=True, exist_ok=True)
        if self.path.exists() and self.path.stat().st_size:
            _cut_partial_line(self.path)
            _check_header(self.path)
            new = False
        else:
            new = True
        self._f = open(self.path, "a", newline="")
        self._w = csv.DictWriter(self._f, fieldnames=names(), extrasaction="raise")
        if new:
            self._w.writeheader()
            self._sync()

    def _sync(self) -> None:
        self._f.flush()
        os.fsync(self._f.fileno())

    def write(self, row: dict) -> None:
        self._w.writerow({k: ("" if row.get(k) is None else row.get(k)) for k in names()})
        self._sync()

    def close(self) -> None:
        self._f.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def finished_keys(out_dir) -> set[tuple]:
    """Keys (bench.columns.KEY) of the complete rows of OUT/results.csv."""
    path = Path(out_dir) / RESULTS
    if not path.exists():
        return set()
    text = path.read_text()
    if text and not text.endswith("\n"):
        text = text[: text.rfind("\n") + 1]
    return {tuple(r[k] for k in KEY) for r in csv.DictReader(io.StringIO(text))}


def drop_keys(out_dir, keys: set[tuple]) -> int:
    """--rerun: back up results.csv to results.csv.bak, then remove the rows of
    ``keys`` (atomically); returns how many were removed."""
    path = Path(out_dir) / RESULTS
    if not path.exists() or not keys:
        return 0
    shutil.copy2(path, path.with_suffix(".csv.bak"))
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    keep = [r for r in rows if tuple(r[k] for k in KEY) not in keys]
    tmp = path.with_suffix(".csv.tmp")
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=names())
        w.writeheader()
        w.writerows(keep)
    os.replace(tmp, path)
    return len(rows) - len(keep)


def parse_json_column(series: pd.Series) -> pd.Series:
    return series.map(lambda s: json.loads(s) if isinstance(s, str) and s else None)


def read_results(run_dir) -> pd.DataFrame:
    """OUT/results.csv as a DataFrame (JSON columns left as strings)."""
    path = Path(run_dir) / RESULTS
    if not path.exists():
        raise HikbenchError(f"{run_dir}: no {RESULTS} (run `hikbench run --out {run_dir}` first)")
    dtype = {"problem": str, "solver": str, "settings": str, "mode": str, "reason": str, "verdict_side": str,
             "family": str, "host": str, "worker": str, **{c: str for c in JSON_COLUMNS}}
    df = pd.read_csv(path, dtype=dtype, keep_default_na=True)
    for c in JSON_COLUMNS:
        if c in df:
            df[c] = df[c].fillna("")
    df["reason"] = df["reason"].fillna("")
    df["verified"] = df["verified"].map({True: True, False: False, "True": True, "False": False})
    return df
