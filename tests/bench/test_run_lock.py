"""One run per output directory: a second ``hikbench run`` on an OUT that a
running run holds is refused with a one-line error naming the holder (two
runs appending to, or compacting, one results.csv would mix or drop rows);
the lock (flock on OUT/run.lock) dies with its process, so a killed run
leaves nothing stale behind."""

import os
import signal
import subprocess
import sys

from doubles import spec, write_suite

from hikbench.bench.cli import main
from hikbench.bench.harness.results import read_results

SLEEP = spec("SleepSolver")
HOLD = ("import sys, time; from pathlib import Path; from hikbench.bench.harness.runner import out_lock; "
        "Path(sys.argv[1]).mkdir(exist_ok=True); f = out_lock(sys.argv[1]); print('held', flush=True); "
        "time.sleep(120)")


def _holder(out):
    """A process holding OUT's lock as a run does (hikbench.bench.harness.runner.out_lock), until killed."""
    p = subprocess.Popen([sys.executable, "-c", HOLD, str(out)], stdout=subprocess.PIPE, text=True,
                         cwd=os.getcwd(), env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    assert p.stdout.readline().strip() == "held"
    return p


def test_a_second_run_on_a_held_out_is_refused_and_a_killed_holder_leaves_no_lock(tmp_path, capsys):
    suite = write_suite(tmp_path / "s.toml", [SLEEP], modes=("cold",))
    out = tmp_path / "out"
    holder = _holder(out)
    try:
        assert main(["run", "--quiet", "--suite", str(suite), "--out", str(out)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        started = err[0].split("started ")[1].split(")")[0]  # (the holder's clock)
        expect = (f"hikbench run: error: --out {out}: another hikbench run is writing to this directory "
                  f"(pid {holder.pid} on {os.uname().nodename}, started {started}); "
                  "wait for it to finish, or give this run another --out")
        assert err == [expect], err
        assert not (out / "results.csv").exists()  # nothing written by the refused run
    finally:
        holder.send_signal(signal.SIGKILL)
        holder.wait()
    # killed by a signal, the holder left run.lock behind but not its lock
    assert (out / "run.lock").exists()
    assert main(["run", "--quiet", "--suite", str(suite), "--out", str(out)]) == 0
    assert len(read_results(out)) == 4
    assert (out / "run.lock").read_text().startswith(f"pid {os.getpid()} on ")


def test_runs_one_after_the_other_share_an_out(tmp_path):
    # the lock is released when a run returns: resuming (and re-running) in the same process works
    suite = write_suite(tmp_path / "s.toml", [SLEEP], modes=("cold",))
    out = tmp_path / "out"
    assert main(["run", "--quiet", "--suite", str(suite), "--out", str(out), "--limit", "1"]) == 0
    assert main(["run", "--quiet", "--suite", str(suite), "--out", str(out)]) == 0
    assert main(["run", "--quiet", "--suite", str(suite), "--out", str(out), "--rerun", "--limit", "1"]) == 0
    assert len(read_results(out)) == 4
