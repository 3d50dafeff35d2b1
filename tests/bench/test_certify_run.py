"""``hikbench certify RUN``: a scenario run's recorded steps certified after the fact, resumable;
bad run folders refused in one line (exit 2)."""

import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pandas as pd
import pytest

from hikbench.bench.cli import main
from hikbench.bench.scenarios.certify_run import CERT_COLUMNS

STEPS = 3
STEM = "reach_talos_hcod_time"


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """A 3-step run of reach with hcod, written by `hikbench scenario --out`."""
    out = tmp_path_factory.mktemp("reach")
    assert main(["scenario", "reach", "--steps", str(STEPS), "--repeat", "1", "--out", str(out)]) == 0
    return out


@pytest.fixture
def run_dir(recorded, tmp_path):
    dst = tmp_path / "run"
    shutil.copytree(recorded, dst)
    return dst


def _certificates(run_dir):
    return pd.read_csv(run_dir / f"{STEM}_certificates.csv", keep_default_na=False)


def test_scenario_records_each_steps_problem_and_u(recorded):
    from hikbench.bench.scenarios.recorded import read_runs
    from hikbench.problems.files import load_npz
    from hikbench.problems.verify import level_norms

    (run,) = read_runs(recorded)
    assert run.stem == STEM and run.steps.tolist() == list(range(STEPS)) and run.u.shape == (STEPS, 38)
    df = pd.read_csv(recorded / f"{STEM}.csv")
    h = load_npz(run.hierarchy_file(1))
    # the recorded u gives the CSV's level norms (written with every digit)
    np.testing.assert_allclose(level_norms(h, run.u[1]), df.filter(like="level_norm_").iloc[1].to_numpy(),
                               rtol=0, atol=0)


def test_certify_certifies_every_step_then_resumes_with_nothing_to_do(run_dir, capsys):
    assert main(["certify", str(run_dir), "--workers", "1"]) == 0
    out = capsys.readouterr().out
    assert f"{STEPS} of {STEPS} steps certified, x attains the exact optimum on {STEPS}" in out, out
    assert f"{STEPS} certified now, 0 before" in out
    df = _certificates(run_dir)
    assert list(df.columns) == list(CERT_COLUMNS) and df["step"].tolist() == list(range(STEPS))
    assert df["certified"].tolist() == [True] * STEPS and df["x_attains"].tolist() == [True] * STEPS
    norms = [[float(v) for v in s.split()] for s in df["level_norms"]]
    assert all(len(v) == 5 and v[0] == 0.0 for v in norms)
    assert main(["certify", str(run_dir)]) == 0
    assert f"0 certified now, {STEPS} before" in capsys.readouterr().out


def test_certify_resumes_an_interrupted_file(run_dir, capsys):
    """A run killed mid-way leaves rows and maybe a row cut short: only the missing steps are certified."""
    assert main(["certify", str(run_dir), "--quiet"]) == 0
    path = run_dir / f"{STEM}_certificates.csv"
    lines = path.read_text().splitlines()
    path.write_text("\n".join(lines[:2]) + "\n" + lines[2][:30])  # step 0 whole, step 1 cut short, step 2 gone
    capsys.readouterr()
    assert main(["certify", str(run_dir), "--quiet"]) == 0
    assert f"{STEPS - 1} certified now, 1 before" in capsys.readouterr().out
    again = path.read_text().splitlines()
    drop = CERT_COLUMNS.index("seconds")  # (the time of a step certified again differs)
    assert [r.split(",")[:drop] for r in again] == [r.split(",")[:drop] for r in lines]


def test_certify_redoes_a_step_recorded_again(run_dir, capsys):
    """A row of another recording of the step (its hierarchy or u changed) is certified again."""
    assert main(["certify", str(run_dir), "--quiet"]) == 0
    z = dict(np.load(run_dir / f"{STEM}_steps" / "u.npz"))
    z["u"][2] = z["u"][2] * (1 + 5e-9 * np.sign(np.sin(np.arange(z["u"].shape[1]) + 1)))
    np.savez(run_dir / f"{STEM}_steps" / "u.npz", **z)
    capsys.readouterr()
    # the optimum perturbed by 5e-9 relative (its rows within the reading of 1e-8: hcod's active set):
    # certified, above the optimum beyond the high profile -> exit 1
    assert main(["certify", str(run_dir), "--quiet"]) == 1
    out = capsys.readouterr().out
    assert "1 certified now, 2 before" in out and "above it on 1 (first: reach_talos_hcod_time step 2" in out, out
    df = _certificates(run_dir)
    assert df["x_attains"].tolist() == [True, True, False] and df["certified"].all()


@pytest.mark.parametrize("damage, message", [
    ("missing", "no such folder"),
    ("file", "is a file; expected the --out folder of `hikbench scenario`"),
    ("no_steps", "no recorded steps (<run>_steps/ folders"),
    ("u_missing", "u.npz: missing; expected the recorded u of run reach_talos_hcod_time"),
    ("u_damaged", "u.npz: not a valid .npz file"),
    ("step_missing", "step=0001.npz: missing; expected the hierarchy of step 1 of run reach_talos_hcod_time"),
    ("step_damaged", "step=0002.npz: not a valid .npz file"),
    ("workers", "--workers must be >= 1; got 0"),
], ids=lambda v: v if " " not in v else None)
def test_certify_refuses_a_bad_run_folder(run_dir, capsys, damage, message):
    steps = run_dir / f"{STEM}_steps"
    arg, extra = str(run_dir), []
    if damage == "missing":
        arg = str(run_dir / "nowhere")
    elif damage == "file":
        arg = str(run_dir / f"{STEM}.csv")
    elif damage == "no_steps":
        shutil.rmtree(steps)
    elif damage == "u_missing":
        (steps / "u.npz").unlink()
    elif damage == "u_damaged":
        (steps / "u.npz").write_bytes(b"not a zip")
    elif damage == "step_missing":
        (steps / "step=0001.npz").unlink()
    elif damage == "step_damaged":
        (steps / "step=0002.npz").write_text("garbage")
    elif damage == "workers":
        extra = ["--workers", "0"]
    assert main(["certify", arg, "--quiet", *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1, err


@pytest.mark.slow
def test_certify_killed_then_run_again_finishes_the_steps_left(tmp_path):
    """SIGTERM mid-way keeps the rows written; run again, the rest is certified."""
    out = tmp_path / "run"
    assert main(["scenario", "reach", "--steps", "40", "--repeat", "1", "--out", str(out)]) == 0
    path = out / f"{STEM}_certificates.csv"
    cmd = [sys.executable, "-m", "hikbench.bench.cli", "certify", str(out), "--workers", "2", "--quiet"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    t0 = time.monotonic()
    while time.monotonic() - t0 < 120 and (not path.exists() or len(path.read_text().splitlines()) < 6):
        time.sleep(0.2)
    proc.send_signal(signal.SIGTERM)
    proc.communicate(timeout=60)
    kept = len(pd.read_csv(path))
    assert 5 <= kept < 40, kept
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    assert "40 of 40 steps certified" in done.stdout and f"{40 - kept} certified now, {kept} before" in done.stdout
    assert _certificates(out)["step"].tolist() == list(range(40))
