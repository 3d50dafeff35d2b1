"""results.csv: rows appended as they finish (one flush + fsync per row), read
back for resuming, reporting and comparing.

A run killed in the middle of writing a row leaves at most one partial last
line; :class:`ResultsWriter` cuts it off before appending (that row was not
finished, so it is run again).

Finished rows are never rewritten, except when a row is run again (``--rerun``,
or its settings' options changed): the old file is first copied to a new
backup (``results.csv.bak``, then ``results.csv.bak.1``, ``.bak.2``, ...; an
existing backup is never overwritten), the new row is appended, and the old
row of the same key is removed by :func:`compact` once the run stops (the last
row of a key wins, also for readers of a file left with both by a kill).
"""

from __future__ import annotations

import csv
import io
import json
import os
import shutil
from pathlib import Path

import pandas as pd

from hikbench.bench.harness.columns import JSON_COLUMNS, KEY, NUMBER_COLUMNS, VERIFIED_COLUMNS, names
from hikbench.problems.errors import HikbenchError

__all__ = ["RESULTS", "ResultsWriter", "backup", "compact", "finished_keys", "finished_rows",
           "parse_json_column", "read_results"]

RESULTS = "results.csv"


def _cut_partial_line(path: Path) -> None:
    with open(path, "rb+") as f:
        data = f.read()
        if data and not data.endswith(b"\n"):
            f.truncate(data.rfind(b"\n") + 1)


def _check_header(path: Path) -> list | None:
    """The header of ``path`` (None: an empty file); HikbenchError unless it holds this version's columns."""
    try:
        with open(path, newline="") as f:
            header = next(csv.reader(f), None)
    except UnicodeDecodeError as err:
        raise HikbenchError(f"{path}: not a text file ({err.reason} at byte {err.start}); expected the "
                            f"results.csv written by hikbench run") from err
    if header is not None and header != names():
        raise HikbenchError(f"{path}: its columns differ from this version's ({len(header)} vs {len(names())} "
                            f"columns); expected a results.csv written by this version of hikbench run "
                            f"(write to a new --out directory)")
    return header


class ResultsWriter:
    """Appends rows (dicts keyed by hikbench.bench.harness.columns names) to OUT/results.csv."""

    def __init__(self, out_dir: str | os.PathLike):
        self.path = Path(out_dir) / RESULTS
        self.path.parent.mkdir(parents=True, exist_ok=True)
        if self.path.exists():
            _cut_partial_line(self.path)  # (a header cut off by a kill leaves an empty file: new)
        new = not (self.path.exists() and self.path.stat().st_size)
        if not new:
            _check_header(self.path)
        self._f = open(self.path, "a", newline="")  # noqa: SIM115 - held open for the run, closed by close()
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


def _complete_text(path: Path) -> str:
    """The text of ``path`` without a partial last line."""
    text = path.read_text()
    if text and not text.endswith("\n"):
        text = text[: text.rfind("\n") + 1]
    return text


def finished_keys(out_dir) -> set[tuple]:
    """Keys (hikbench.bench.harness.columns.KEY) of the complete rows of OUT/results.csv."""
    return set(finished_rows(out_dir))


def finished_rows(out_dir) -> dict[tuple, tuple[str, str]]:
    """Key (hikbench.bench.harness.columns.KEY) -> (``options`` JSON, ``problem_hash``) of the
    complete rows of OUT/results.csv (the last row of a key wins): what a finished row
    was run with, for resuming (hikbench.bench.harness.runner)."""
    path = Path(out_dir) / RESULTS
    if not path.exists():
        return {}
    return {tuple(r[k] for k in KEY): (r.get("options") or "{}", r.get("problem_hash") or "")
            for r in _complete_rows(path)}


def _complete_rows(path: Path) -> list[dict]:
    """The complete rows of results.csv as dicts of strings; a HikbenchError
    for a header line among them (rows appended after it, or kept by
    :func:`compact`, would be read back as strings: refused, not grown)."""
    rows = list(csv.DictReader(io.StringIO(_complete_text(path))))
    for i, r in enumerate(rows, start=1):
        if tuple(r[k] for k in KEY) == KEY:
            raise _second_header(path, i)
    return rows


def _second_header(path: Path, row: int) -> HikbenchError:
    return HikbenchError(f"{path}: data row {row} is a second header line (two files concatenated?): remove it")


def backup(out_dir) -> Path | None:
    """Copy OUT/results.csv to the first free name of ``results.csv.bak``,
    ``results.csv.bak.1``, ``results.csv.bak.2``, ... (an existing backup is
    never overwritten); returns the backup's path (None: no results.csv)."""
    path = Path(out_dir) / RESULTS
    if not path.exists():
        return None
    i = 0
    while True:
        dest = path.with_name(RESULTS + ".bak" + (f".{i}" if i else ""))
        try:
            with open(path, "rb") as src, open(dest, "xb") as dst:  # "x": fails rather than overwrite
                shutil.copyfileobj(src, dst)
                dst.flush()
                os.fsync(dst.fileno())
        except FileExistsError:
            i += 1
            continue
        shutil.copystat(path, dest)
        return dest


def compact(out_dir) -> int:
    """Remove every row of OUT/results.csv that a later row of the same key
    replaces (a row run again), atomically; returns how many were removed.
    The file is left untouched when no key repeats."""
    path = Path(out_dir) / RESULTS
    if not path.exists() or not path.stat().st_size:
        return 0
    _check_header(path)
    rows = _complete_rows(path)
    last = {tuple(r[k] for k in KEY): i for i, r in enumerate(rows)}
    if len(last) == len(rows):
        return 0
    keep = [r for i, r in enumerate(rows) if last[tuple(r[k] for k in KEY)] == i]
    tmp = path.with_suffix(".csv.tmp")
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=names())
        w.writeheader()
        w.writerows(keep)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)
    return len(rows) - len(keep)


def parse_json_column(series: pd.Series) -> pd.Series:
    return series.map(lambda s: json.loads(s) if isinstance(s, str) and s else None)


def _check_numbers(df: pd.DataFrame, path: Path) -> None:
    """A number column holding anything but numbers (a file edited or two files
    concatenated, header and all) is an error naming its first such row, not a
    TypeError later in a median."""
    for c in NUMBER_COLUMNS:
        if c not in df or pd.api.types.is_numeric_dtype(df[c]):
            continue
        bad = pd.to_numeric(df[c], errors="coerce").isna() & df[c].notna()
        if not bad.any():
            continue
        i = int(bad.to_numpy().argmax())
        value = df[c].iloc[i]
        if value == c:
            raise _second_header(path, i + 1)
        raise HikbenchError(f"{path}: data row {i + 1}: column {c!r} holds {value!r}, not a number")


def _check_json(df: pd.DataFrame, path: Path) -> None:
    """A JSON column whose cell does not parse (a hand-edited file) is an error
    naming its first such row, not a JSONDecodeError traceback in compare or
    report."""
    for c in JSON_COLUMNS:
        if c not in df:
            continue
        for i, value in enumerate(df[c]):
            if not isinstance(value, str) or not value:
                continue
            try:
                json.loads(value)
            except ValueError:
                if value == c:
                    raise _second_header(path, i + 1) from None
                raise HikbenchError(f"{path}: data row {i + 1}: column {c!r} holds {value[:40]!r}, "
                                    f"not JSON") from None


def read_results(run_dir) -> pd.DataFrame:
    """OUT/results.csv as a DataFrame (JSON columns left as strings), its
    complete rows only (a row being written is not read half)."""
    path = Path(run_dir) / RESULTS
    if Path(run_dir).is_file():
        raise HikbenchError(f"{run_dir}: is a file; expected a run directory (the --out of `hikbench run`, "
                            f"which holds {RESULTS})")
    if not path.exists():
        raise HikbenchError(f"{run_dir}: no {RESULTS} (run `hikbench run --out {run_dir}` first)")
    if _check_header(path) is None:  # killed before its header was written: no rows
        return pd.DataFrame(columns=names())
    dtype = {"problem": str, "solver": str, "settings": str, "mode": str, "reason": str, "verdict_side": str,
             "family": str, "host": str, "worker": str, **{c: str for c in JSON_COLUMNS}}
    # complete lines only: a run still writing (or killed mid-row) leaves a partial last row
    df = pd.read_csv(io.StringIO(_complete_text(path)), dtype=dtype, keep_default_na=True)
    _check_numbers(df, path)
    _check_json(df, path)
    for c in JSON_COLUMNS:
        if c in df:
            df[c] = df[c].fillna("")
    df["reason"] = df["reason"].fillna("")
    for c in VERIFIED_COLUMNS:
        df[c] = df[c].map({True: True, False: False, "True": True, "False": False})
    # a run killed while replacing rows can leave an old row before its replacement
    df = df.drop_duplicates(subset=list(KEY), keep="last", ignore_index=True)
    return df
