"""Calibration kernel: a fixed dense linear-algebra workload timed in the same
process as the solves, so that times from different machines (or a loaded CI
runner) compare as ratios (``hikbench compare`` divides by it).

The kernel: a fixed 64 x 64 matrix (seed 0), 20 times ``Q, R = qr(M); M = Q @ R + I*1e-3``
at one BLAS thread; the calibration is the minimum over 7 timings, in ns (load
from other processes only adds time, so the minimum is the machine's speed;
a median jumps 2x when a neighbour's job overlaps the few milliseconds of the
kernel).
"""

from __future__ import annotations

import time

import numpy as np
from threadpoolctl import threadpool_limits

__all__ = ["KERNEL", "calibrate"]

KERNEL = "qr+matmul 64x64, 20 iterations, minimum of 7 (ns)"


def _kernel(M: np.ndarray) -> float:
    I = np.eye(M.shape[0]) * 1e-3
    for _ in range(20):
        Q, R = np.linalg.qr(M)
        M = Q @ R + I
    return float(M[0, 0])


def calibrate(reps: int = 7) -> int:
    """Minimum wall time of the kernel over ``reps`` runs, ns."""
    M0 = np.random.default_rng(0).standard_normal((64, 64))
    samples = []
    with threadpool_limits(limits=1):
        _kernel(M0.copy())  # warm-up
        for _ in range(reps):
            t0 = time.perf_counter_ns()
            _kernel(M0.copy())
            samples.append(time.perf_counter_ns() - t0)
    return int(np.min(samples))
