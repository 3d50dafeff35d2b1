"""Reading a run folder's own files as regular files of bounded size: a FIFO, a
device, a directory or a socket where a file is expected is refused in one
line (a FIFO is never waited on: opened without blocking), and so is a file
larger than what it can hold."""

from __future__ import annotations

import os
import stat
from pathlib import Path

from hikbench.problems.errors import HikbenchError

__all__ = ["kind", "read_regular", "regular_or_absent"]


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


def read_regular(path, limit: int, expected: str) -> bytes:
    """The bytes of the regular file ``path``, at most ``limit`` of them; HikbenchError
    naming the path and ``expected`` when it is another kind of file, larger, or unreadable."""
    path = Path(path)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except OSError as err:
        raise HikbenchError(f"{path}: cannot be read ({err.strerror or err}); expected {expected}") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise HikbenchError(f"{path}: is {kind(st.st_mode)}; expected {expected}")
        if st.st_size > limit:
            raise HikbenchError(f"{path}: {st.st_size} bytes, more than the {limit} expected of {expected}")
        chunks, got = [], 0
        while got <= limit and (chunk := os.read(fd, min(1 << 24, limit + 1 - got))):
            chunks.append(chunk)
            got += len(chunk)
    except OSError as err:
        raise HikbenchError(f"{path}: cannot be read ({err.strerror or err}); expected {expected}") from None
    finally:
        os.close(fd)
    if got > limit:
        raise HikbenchError(f"{path}: more than the {limit} bytes expected of {expected}")
    return b"".join(chunks)
