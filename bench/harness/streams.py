"""What a process writes, kept in bounded memory (:class:`HeadTail`), and the end of the
processes a solve started (:func:`kill_session`: a process group; :func:`kill_descendants`:
every process below one, found in /proc, those that left its session included when it is a
subreaper, :func:`become_subreaper`): shared by the isolated worker
(bench/harness/isolation.py), ``hikbench solve`` and the external programs' runner (external.py)."""

from __future__ import annotations

import os
import signal
import sys

__all__ = ["HeadTail", "become_subreaper", "children", "descendants", "kill_descendants", "kill_session",
           "reap_children"]


class HeadTail:
    """The first ``head`` bytes and the last ``tail`` bytes of a stream read in
    chunks, and how many bytes came between them: what a process writes is kept
    in bounded memory however much it writes."""

    def __init__(self, head: int, tail: int):
        self.head_cap, self.tail_cap = int(head), int(tail)
        self.head = bytearray()
        self._tail = bytearray()  # up to twice tail_cap between trims (amortized)
        self.total = 0

    def add(self, chunk: bytes) -> bytes:
        """Keep ``chunk``'s share; returns the part of it that went to the head."""
        to_head = chunk[: max(self.head_cap - len(self.head), 0)]
        self.head += to_head
        rest = memoryview(chunk)[len(to_head):]
        if len(rest) >= self.tail_cap:
            self._tail = bytearray(rest[len(rest) - self.tail_cap:])
        elif rest:
            self._tail += rest
            if len(self._tail) > 2 * self.tail_cap:
                del self._tail[: len(self._tail) - self.tail_cap]
        self.total += len(chunk)
        return to_head

    @property
    def tail(self) -> bytes:
        return bytes(self._tail[-self.tail_cap:]) if self.tail_cap else b""

    @property
    def omitted(self) -> int:
        """Bytes neither in the head nor in the tail."""
        return self.total - len(self.head) - len(self.tail)

    def marker(self) -> bytes:
        """The line standing for the omitted bytes (empty when none was)."""
        return f"\n[... {self.omitted} bytes omitted ...]\n".encode() if self.omitted else b""

    def text(self) -> str:
        """Head, the omitted-bytes marker and tail, decoded (undecodable bytes replaced)."""
        return (bytes(self.head) + self.marker() + self.tail).decode(errors="replace")


def kill_session(pid: int) -> None:
    """SIGKILL the process group led by ``pid`` (a process started in a session of its own:
    the group holds it and the processes it started); nothing when none is left."""
    try:
        os.killpg(pid, signal.SIGKILL)
    except ProcessLookupError:
        return  # the whole group has ended: nothing left to kill


LINUX = sys.platform.startswith("linux")
_PR_SET_CHILD_SUBREAPER = 36


def become_subreaper() -> str:
    """Linux: make this process a child subreaper (``prctl(PR_SET_CHILD_SUBREAPER)``): the
    orphans of the processes it starts, a grandchild that called ``setsid`` included, are
    re-parented to it, so that :func:`kill_descendants` finds them. Returns why it could not
    ("" when it is one; elsewhere than on Linux, what is missing)."""
    if not LINUX:
        return "not Linux: only the process group is ended"
    import ctypes

    try:
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.prctl(_PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0) != 0:
            return f"prctl(PR_SET_CHILD_SUBREAPER) failed, errno {ctypes.get_errno()}"
    except (OSError, AttributeError) as err:  # no libc with prctl
        return f"{type(err).__name__}: {err}"
    return ""


def children(pid: int) -> list[int]:
    """The pids of the children of ``pid`` (of all its threads), from /proc (Linux; [] elsewhere,
    or when ``pid`` has ended)."""
    out = []
    try:
        tasks = os.listdir(f"/proc/{pid}/task")
    except OSError:  # (not Linux, or the process has ended: no children to list)
        return []
    for tid in tasks:
        try:
            with open(f"/proc/{pid}/task/{tid}/children") as f:
                out += [int(p) for p in f.read().split()]
        except OSError:  # the thread ended while it was listed
            continue
    return out


def descendants(pid: int) -> list[int]:
    """Every process below ``pid`` in the process tree (children first), from /proc."""
    found, todo = [], children(pid)
    while todo:
        p = todo.pop()
        found.append(p)
        todo += children(p)
    return found


def kill_descendants(pid: int, passes: int = 5) -> None:
    """SIGKILL every descendant of ``pid`` (those started by a killed one too, over a few passes)."""
    for _ in range(passes):
        below = descendants(pid)
        if not below:
            return
        for p in below:
            _kill(p)


def reap_children() -> None:
    """Collect every child of this process that has ended (zombies), without waiting."""
    while True:
        try:
            pid, _ = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:  # no child left
            return
        if pid == 0:  # children left, all still running
            return


def _kill(pid: int) -> None:
    try:
        os.kill(pid, signal.SIGKILL)
    except ProcessLookupError:
        return  # it has ended already
