"""What a process writes, kept in bounded memory (:class:`HeadTail`), and the end of a
process group (:func:`kill_session`): shared by the isolated worker
(bench/harness/isolation.py) and the external programs' runner (external.py)."""

from __future__ import annotations

import os
import signal

__all__ = ["HeadTail", "kill_session"]


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
