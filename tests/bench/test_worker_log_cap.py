"""A solver writing to fd 1 without end cannot grow worker.log without bound: each
worker process's stderr keeps its head and its tail (bench/harness/isolation.py)."""

from __future__ import annotations

from pathlib import Path

from doubles import tiny
from noisy_doubles import FLOOD_BYTES

from hikbench.bench.harness.isolation import LOG_KEEP_BYTES, IsolatedWorker

FLOOD = f"{Path(__file__).with_name('noisy_doubles.py')}:FloodSolver"


def test_a_solver_flooding_fd_1_leaves_a_capped_worker_log(tmp_path):
    log = tmp_path / "worker.log"
    job = {"kind": "solve", "hierarchy": tiny(), "solver": FLOOD, "mode": "cold", "repeat": 1, "warmup": 0}
    with IsolatedWorker(log=log) as w:
        res = w.run(job, timeout=120)
    assert res["status"] == "optimal", res.get("reason")
    size = log.stat().st_size
    assert size < 2 * LOG_KEEP_BYTES + 4096 < FLOOD_BYTES, size
    text = log.read_bytes()
    assert b"FLOOD START" in text[:LOG_KEEP_BYTES]
    assert text.rstrip().endswith(b"FLOOD END"), text[-200:]
    assert b"bytes omitted ...]" in text


def test_a_quiet_worker_log_is_kept_whole(tmp_path):
    log = tmp_path / "worker.log"
    log.write_bytes(b"earlier run\n")
    with IsolatedWorker(log=log) as w:
        w.run({"kind": "yardstick", "hierarchy": tiny()}, timeout=120)
    assert log.read_bytes().startswith(b"earlier run\n") and b"omitted" not in log.read_bytes()


def test_a_solver_flooding_fd_1_on_a_dask_worker_leaves_a_capped_log_in_its_folder():
    """On a Dask worker the isolated process's stderr goes to ``hikbench-worker.log`` in the
    Dask worker's own folder, capped as OUT/worker.log is (its head as it comes; the tail is
    written when the process ends, with the cluster)."""
    from hikbench.bench.harness.executors import DaskExecutor

    job = {"kind": "solve", "hierarchy": tiny(), "solver": FLOOD, "mode": "cold", "repeat": 1, "warmup": 0}
    ex = DaskExecutor(workers=1)
    try:
        ((_, res),) = list(ex.map([(0, job, 120.0)]))
        (folder,) = ex.client.run(lambda dask_worker: dask_worker.local_directory).values()
        text = (Path(folder) / "hikbench-worker.log").read_bytes()
    finally:
        ex.close()
    assert res["status"] == "optimal", res.get("reason")
    assert b"FLOOD START" in text and len(text) <= LOG_KEEP_BYTES < FLOOD_BYTES
