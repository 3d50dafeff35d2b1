"""results.csv: rows appended as they finish (one write + fsync per row), read
back for resuming, reporting and comparing.

Each row is one line: a line break in a field is written as the two characters
``\\n`` (:func:`one_line`), so a row cut anywhere lacks its final newline. A run
killed in the middle of writing a row leaves at most one partial last row (also
one cut inside a quoted field holding a line break, as earlier versions wrote
them: :func:`_scan`); :class:`ResultsWriter` cuts it off before appending (that
row was not finished, so it is run again), and readers leave it out. A row
whose write fails (a full disk) is cut off again at once. A line holding more or
fewer fields than the header, results.csv that is no regular file, or one
larger than 2 GiB, is an error naming it.

Finished rows are never rewritten, except when a row is run again (``--rerun``,
or its settings' options changed): the old file is first copied to a new
backup (``results.csv.bak``, then ``results.csv.bak.1``, ``.bak.2``, ...; an
existing backup is never overwritten), the new row is appended, and the old
row of the same key is removed by :func:`compact` once the run stops (the last
row of a key wins, also for readers of a file left with both by a kill).
"""

from __future__ import annotations

import codecs
import csv
import io
import json
import os
import shutil
from pathlib import Path

import pandas as pd

from hikbench.bench.harness.columns import JSON_COLUMNS, KEY, NUMBER_COLUMNS, VERIFIED_COLUMNS, names
from hikbench.bench.harness.regular import check_run_folder, read_regular, regular_or_absent
from hikbench.problems.errors import HikbenchError

__all__ = ["RESULTS", "ResultsWriter", "backup", "compact", "finished_keys", "finished_rows", "one_line",
           "parse_json_column", "read_results"]

RESULTS = "results.csv"


_MAX_BYTES = 1 << 31  # a results.csv larger than this is refused unread (some 10 million rows)
_EXPECTED = f"the {RESULTS} written by hikbench run"


def one_line(value):
    """``value`` with each line break (CR, LF, CRLF) written as the two characters
    ``\\n`` when it is a string: a row is one line, so that a row cut anywhere lacks
    its final newline (:func:`_scan`)."""
    if isinstance(value, str) and ("\n" in value or "\r" in value):
        return value.replace("\r\n", "\\n").replace("\r", "\\n").replace("\n", "\\n")
    return value


def _scan(data: bytes) -> tuple[list[tuple[int, int, int]], int]:
    """The complete records of the CSV bytes ``data``: (line number, start, end) of each,
    and the offset where the incomplete rest starts. A record ends at a newline outside
    quotes: with an even count of ``"`` since its start (a quote inside a quoted field is
    doubled), so that a record cut inside a quoted field holding a line break (written by
    an earlier version) is incomplete too."""
    records, pos, line = [], 0, 1
    while pos < len(data):
        i, quotes, lines = pos, 0, 0
        while True:
            j = data.find(b"\n", i)
            if j < 0:
                return records, pos
            quotes += data.count(b'"', i, j + 1)
            lines += 1
            if quotes % 2 == 0:
                break
            i = j + 1
        records.append((line, pos, j + 1))
        line, pos = line + lines, j + 1
    return records, pos


class _Csv:
    """results.csv parsed and checked: ``header`` (None: empty), ``rows`` (lists of
    strings, with ``lines``: their first line numbers), ``text`` (the complete records)
    and ``end`` (the byte offset after them: what follows is a partial row)."""

    def __init__(self, path: Path):
        self.path = path
        data = read_regular(path, _MAX_BYTES, _EXPECTED)
        records, self.end = _scan(data)
        try:  # (the partial row too, but for a character cut at its end: a binary file is no results.csv)
            codecs.getincrementaldecoder("utf-8")().decode(data, final=False)
        except UnicodeDecodeError as err:
            raise HikbenchError(f"{path}: not a text file ({err.reason} at byte {err.start}); expected "
                                f"{_EXPECTED}") from err
        self.text, tail = data[: self.end].decode("utf-8"), data[self.end:].decode("utf-8", errors="replace")
        self.header, self.rows, self.lines = None, [], []
        for line, a, b in records:
            fields = list(csv.reader(io.StringIO(data[a:b].decode("utf-8"), newline="")))
            if self.header is None:
                self.header = fields[0] if fields else []
                continue
            if len(fields) != 1 or len(fields[0]) != len(self.header):
                got = sum(map(len, fields))
                raise HikbenchError(f"{path}: line {line} holds {got} fields, expected {len(self.header)}: a "
                                    f"damaged row (remove that line: its row runs again; or write to a new --out)")
            self.rows.append(fields[0])
            self.lines.append(line)
        first = records[-1][0] + data[records[-1][1]:records[-1][2]].count(b"\n") if records else 1
        self._check_tail(tail, first)

    def _check_tail(self, tail: str, line: int) -> None:
        """A partial last row is expected (a run killed while writing it); a quote opened on
        line ``line`` and never closed, with complete rows after it, is a damaged file."""
        width = len(self.header) if self.header else len(names())
        for k, text in enumerate(tail.split("\n")[1:-1], start=1):
            row = next(csv.reader([text]), [])
            if len(row) == width:
                raise HikbenchError(f"{self.path}: line {line} opens a quoted field that is never closed (line "
                                    f"{line + k}, a complete row, would be read into it): a damaged row (remove "
                                    f"line {line}, or write to a new --out)")


def _cut_partial_line(path: Path) -> None:
    """Cut a partial last row (a run killed while writing it: it runs again)."""
    parsed = _Csv(path)
    if parsed.end < path.stat().st_size:
        with open(path, "rb+") as f:
            f.truncate(parsed.end)


def _check_header(path: Path) -> list | None:
    """The header of ``path`` (None: an empty file); HikbenchError unless it holds this version's columns."""
    return _checked(_Csv(path)).header


#: the columns this version added to results.csv: a file of the version before lacks them (read, with
#: them empty, by ``report`` and ``compare``; never appended to)
ADDED_COLUMNS = frozenset({"level_gaps", "verified_high", "verified_default", "verified_low", "solver_settings"})


def _checked(parsed: _Csv, earlier: bool = False) -> _Csv:
    """``parsed``, whose header must be this version's columns; with ``earlier``, also those of the
    version before: this version's without some of :data:`ADDED_COLUMNS`."""
    header = parsed.header
    if (earlier and header is not None and header == [c for c in names() if c in set(header)]
            and set(names()) - set(header) <= ADDED_COLUMNS):
        return parsed
    if header is not None and header != names():
        raise HikbenchError(f"{parsed.path}: its columns differ from this version's ({len(header)} vs "
                            f"{len(names())} columns); expected a results.csv written by this version of "
                            f"hikbench run (write to a new --out directory)")
    return parsed


class ResultsWriter:
    """Appends rows (dicts keyed by hikbench.bench.harness.columns names) to OUT/results.csv,
    one line each (:func:`one_line`), each written whole or not at all: a write that fails
    (a full disk) is cut off again and raises :class:`HikbenchError` naming the file and the
    cause, the finished rows kept."""

    def __init__(self, out_dir: str | os.PathLike):
        self.path = Path(out_dir) / RESULTS
        self.path.parent.mkdir(parents=True, exist_ok=True)
        exists = regular_or_absent(self.path, _EXPECTED)
        if exists:
            _cut_partial_line(self.path)  # (a header cut off by a kill leaves an empty file: new)
        new = not (exists and self.path.stat().st_size)
        if not new:
            _check_header(self.path)
        try:
            self._fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | getattr(os, "O_CLOEXEC", 0),
                               0o666)
        except OSError as err:
            raise HikbenchError(f"{self.path}: cannot be opened for writing ({err.strerror or err})") from None
        if new:
            self._append(names())

    def _append(self, fields: list) -> None:
        """Write one CSV line and fsync it; on failure cut the file back to where it was."""
        buf = io.StringIO()
        csv.writer(buf).writerow([one_line(v) for v in fields])
        data = memoryview(buf.getvalue().encode("utf-8"))
        size = os.fstat(self._fd).st_size
        try:
            while data:
                data = data[os.write(self._fd, data):]
            os.fsync(self._fd)
        except OSError as err:
            os.ftruncate(self._fd, size)  # (frees blocks: it works on a full disk too)
            raise HikbenchError(f"{self.path}: cannot write a row ({err.strerror or err}); the rows "
                                f"finished before it are kept: free space and run the same command again "
                                f"to resume") from None

    def write(self, row: dict) -> None:
        self._append(["" if row.get(k) is None else row.get(k) for k in names()])

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def finished_keys(out_dir) -> set[tuple]:
    """Keys (hikbench.bench.harness.columns.KEY) of the complete rows of OUT/results.csv."""
    return set(finished_rows(out_dir))


def finished_rows(out_dir) -> dict[tuple, tuple[str, str]]:
    """Key (hikbench.bench.harness.columns.KEY) -> (``options`` JSON, ``problem_hash``) of the
    complete rows of OUT/results.csv (the last row of a key wins): what a finished row
    was run with, for resuming (hikbench.bench.harness.runner). Keys as written
    (:func:`one_line`)."""
    path = Path(out_dir) / RESULTS
    if not regular_or_absent(path, _EXPECTED):
        return {}
    return {tuple(r[k] for k in KEY): (r.get("options") or "{}", r.get("problem_hash") or "")
            for r in _complete_rows(path)}


def _complete_rows(path: Path) -> list[dict]:
    """The complete rows of results.csv as dicts of strings; a HikbenchError
    for a header line among them (rows appended after it, or kept by
    :func:`compact`, would be read back as strings: refused, not grown)."""
    parsed = _checked(_Csv(path))
    rows = [dict(zip(parsed.header, r)) for r in parsed.rows]
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
    if not regular_or_absent(path, _EXPECTED):
        return None
    i = 0
    while True:
        dest = path.with_name(RESULTS + ".bak" + (f".{i}" if i else ""))
        try:
            with open(path, "rb") as src, open(dest, "xb") as dst:  # "x": fails rather than overwrite
                try:
                    shutil.copyfileobj(src, dst)
                    dst.flush()
                    os.fsync(dst.fileno())
                except OSError as err:
                    dest.unlink()  # (no half backup left)
                    raise HikbenchError(f"{dest}: cannot write the backup of {path} ({err.strerror or err}); "
                                        f"nothing was changed") from None
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
    if not regular_or_absent(path, _EXPECTED) or not path.stat().st_size:
        return 0
    rows = _complete_rows(path)
    last = {tuple(r[k] for k in KEY): i for i, r in enumerate(rows)}
    if len(last) == len(rows):
        return 0
    keep = [r for i, r in enumerate(rows) if last[tuple(r[k] for k in KEY)] == i]
    tmp = path.with_suffix(".csv.tmp")
    try:
        with open(tmp, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(names())
            w.writerows([one_line(r[k]) for k in names()] for r in keep)
            f.flush()
            os.fsync(f.fileno())
    except OSError as err:
        tmp.unlink(missing_ok=True)  # (results.csv itself is untouched: the old rows are read as replaced)
        raise HikbenchError(f"{path}: cannot rewrite it without its replaced rows ({err.strerror or err}); "
                            f"it is left as it was") from None
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
    check_run_folder(run_dir)  # (report writes report.md and plots/, compare reads run.json: none of them a FIFO)
    if not regular_or_absent(path, _EXPECTED):
        raise HikbenchError(f"{run_dir}: no {RESULTS} (run `hikbench run --out {run_dir}` first)")
    parsed = _checked(_Csv(path), earlier=True)  # (a run of an earlier version is read: report, compare)
    if parsed.header is None:  # killed before its header was written: no rows
        return pd.DataFrame(columns=names())
    dtype = {"problem": str, "solver": str, "settings": str, "mode": str, "reason": str, "verdict_side": str,
             "family": str, "host": str, "worker": str, **{c: str for c in JSON_COLUMNS}}
    # complete lines only: a run still writing (or killed mid-row) leaves a partial last row
    df = pd.read_csv(io.StringIO(parsed.text), dtype=dtype, keep_default_na=True)
    missing = [c for c in names() if c not in df]  # (an earlier version's run: the columns it did not record, empty)
    df = df.reindex(columns=names())
    for c in missing:
        df[c] = df[c].astype(object)
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
