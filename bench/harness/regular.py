"""Reading a run folder's own files as regular files of bounded size: a FIFO, a
device, a directory or a socket where a file is expected is refused in one
line (a FIFO is never waited on: opened without blocking), and so is a file
larger than what it can hold."""

from __future__ import annotations

import os
import stat
from pathlib import Path

from hikbench.problems.errors import HikbenchError

__all__ = ["RUN_FOLDER", "NotRegular", "TooLarge", "bounded_bytes", "check_run_folder", "kind", "open_regular",
           "read_regular", "regular_or_absent"]


def kind(mode: int) -> str:
    """What a file of ``mode`` (st_mode) is, in words: ``a FIFO``, ``a directory``, ..."""
    for test, words in ((stat.S_ISREG, "a regular file"), (stat.S_ISFIFO, "a FIFO"),
                        (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                        (stat.S_ISDIR, "a directory"), (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return words
    return "no regular file"


def regular_or_absent(path, expected: str) -> bool:
    """True when ``path`` is a regular file (or a link to one), False when nothing is
    there; HikbenchError naming what is there instead and ``expected`` otherwise."""
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        if os.path.lexists(path):
            raise HikbenchError(f"{path}: a dangling symbolic link; expected {expected}") from None
        return False
    except OSError as err:
        raise HikbenchError(f"{path}: cannot be read ({err.strerror or err}); expected {expected}") from None
    if not stat.S_ISREG(mode):
        raise HikbenchError(f"{path}: is {kind(mode)}; expected {expected}")
    return True


def open_regular(path):
    """``path`` opened for reading in binary (a file object), when it is a regular file;
    HikbenchError naming what it is otherwise (opened without blocking: a FIFO is not waited on)."""
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    st = os.fstat(fd)
    if not stat.S_ISREG(st.st_mode):
        os.close(fd)
        raise HikbenchError(f"{path}: is {kind(st.st_mode)}; expected a regular file")
    return os.fdopen(fd, "rb")


class NotRegular(ValueError):
    """The file read by :func:`bounded_bytes` is not a regular file: ``what`` it is, in words."""

    def __init__(self, what: str):
        super().__init__(what)
        self.what = what


class TooLarge(ValueError):
    """The file read by :func:`bounded_bytes` holds more than its limit: ``size`` its size when
    known before reading (None: it grew while read)."""

    def __init__(self, size: int | None):
        super().__init__(size)
        self.size = size


def bounded_bytes(path, limit: int) -> bytes:
    """The bytes of the regular file ``path``, at most ``limit`` of them, opened without blocking
    (a FIFO is never waited on); :class:`NotRegular` or :class:`TooLarge` otherwise (unread), an
    OSError as the system raises it. Callers word these for their reader."""
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise NotRegular(kind(st.st_mode))
        if st.st_size > limit:
            raise TooLarge(st.st_size)
        chunks, got = [], 0
        while got <= limit and (chunk := os.read(fd, min(1 << 24, limit + 1 - got))):
            chunks.append(chunk)
            got += len(chunk)
    finally:
        os.close(fd)
    if got > limit:
        raise TooLarge(None)
    return b"".join(chunks)


def read_regular(path, limit: int, expected: str) -> bytes:
    """The bytes of the regular file ``path``, at most ``limit`` of them (:func:`bounded_bytes`);
    HikbenchError naming the path and ``expected`` when it is another kind of file, larger, or unreadable."""
    path = Path(path)
    try:
        return bounded_bytes(path, limit)
    except NotRegular as err:
        raise HikbenchError(f"{path}: is {err.what}; expected {expected}") from None
    except TooLarge as err:
        raise HikbenchError(f"{path}: {err.size} bytes, more than the {limit} expected of {expected}" if err.size
                            else f"{path}: more than the {limit} bytes expected of {expected}") from None
    except OSError as err:
        raise HikbenchError(f"{path}: cannot be read ({err.strerror or err}); expected {expected}") from None


#: the entries of a run folder (OUT) and the kind each must be when present: ``dir`` a folder of
#: regular files, ``file`` a regular file
RUN_FOLDER = {"results.csv": "file", "run.json": "file", "run.lock": "file", "summary.json": "file",
              "report.md": "file", "report.json": "file", "worker.log": "file", "scenarios.csv": "file",
              "yardstick": "dir", "problems": "dir", "plots": "dir", "scenarios": "dir"}
#: the folders whose entries are all regular files (scenarios/ holds a folder per scenario)
_FLAT = ("yardstick", "problems", "plots")


def check_run_folder(out) -> None:
    """HikbenchError naming the first entry of the run folder ``out`` that is of the wrong kind
    (:data:`RUN_FOLDER`: a FIFO, a directory or a device where a file is expected, a file where a
    folder is, an entry of a folder that is no regular file): checked before the run or the
    report opens any of them, so that none is waited on (a FIFO) or read as what it is not."""
    out = Path(out)
    for name, want in RUN_FOLDER.items():
        path = out / name
        try:
            mode = os.stat(path).st_mode
        except FileNotFoundError:
            if os.path.lexists(path):
                raise HikbenchError(f"{path}: a dangling symbolic link; expected {_wanted(want, name)} "
                                    f"(remove it)") from None
            continue
        except OSError as err:
            raise HikbenchError(f"{path}: cannot be read ({err.strerror or err})") from None
        ok = stat.S_ISDIR(mode) if want == "dir" else stat.S_ISREG(mode)
        if not ok:
            raise HikbenchError(f"{path}: is {kind(mode)}; expected {_wanted(want, name)} (remove it, or "
                                f"write to a new --out)")
        if name in _FLAT:
            _check_entries(path)


def _check_entries(folder: Path) -> None:
    """Every entry of a run's folder of files (yardstick/, problems/, plots/) a regular file."""
    try:
        entries = list(os.scandir(folder))
    except OSError as err:
        raise HikbenchError(f"{folder}: cannot be listed ({err.strerror or err})") from None
    for e in entries:
        try:
            mode = os.stat(e.path).st_mode
        except OSError as err:
            raise HikbenchError(f"{e.path}: cannot be read ({err.strerror or err}); expected a regular file "
                                f"(remove it)") from None
        if not stat.S_ISREG(mode):
            raise HikbenchError(f"{e.path}: is {kind(mode)}; expected a regular file written by hikbench "
                                f"(remove it)")


def _wanted(want: str, name: str) -> str:
    return f"the folder {name} written by hikbench" if want == "dir" else f"the regular file {name} written by hikbench"
