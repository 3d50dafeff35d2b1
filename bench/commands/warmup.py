"""``hikbench warmup``: compile hcod's numba kernels into numba's cache once,
with the elapsed time shown, so that no benchmark pays for it (``make bench``
and ``make test`` run it after the install)."""

from __future__ import annotations

import sys
import threading
import time

HELP = "compile hcod's numba kernels into numba's cache (once per machine and source; 1-4 min)"

#: seconds between two progress lines while the kernels compile
TICK_S = 10.0


def add_arguments(p) -> None:
    p.add_argument("--quiet", action="store_true", help="print only the closing line")


def run(args) -> int:
    from hikbench.solvers import hcod

    t0 = time.perf_counter()
    done = threading.Event()
    if not args.quiet:
        print("hikbench warmup: loading hcod's kernels from numba's cache, or compiling them "
              "(1-4 min, once per machine and source)", flush=True)
        threading.Thread(target=_tick, args=(t0, done), daemon=True).start()
    try:
        how = hcod.warmup()
    finally:
        done.set()
    print(f"hikbench warmup: hcod's kernels {how} in {time.perf_counter() - t0:.1f} s", flush=True)
    return 0


def _tick(t0: float, done: threading.Event) -> None:
    """A line every TICK_S seconds until ``done``: the compile's progress."""
    while not done.wait(TICK_S):
        print(f"hikbench warmup: ... {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
