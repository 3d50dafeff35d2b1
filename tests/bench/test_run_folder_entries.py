"""A run folder's entries of the wrong kind (a FIFO, a folder, a file where a
folder is), damaged cached npz files and a run.json of wrong field types are
one line each in run, report and compare: never a hang, a traceback, or a
file read whole (bench/harness/regular.py, cache.py, environment.py)."""

import json
import os
import shutil
import struct
import time
import zipfile

import pytest
from clitools import run
from doubles import spec, write_suite

SLEEP = spec("SleepSolver")


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory):
    d = tmp_path_factory.mktemp("entries")
    suite = write_suite(d / "s.toml", [SLEEP], grid={"n": [4], "depth": [1, 2]}, modes=("cold",), repeat=1)
    from hikbench.bench.cli import main
    assert main(["run", "--quiet", "--suite", str(suite), "--out", str(d / "o")]) == 0
    return d / "o", suite


def _copy(finished_run, tmp_path):
    out, suite = finished_run
    dest = tmp_path / "o"
    shutil.copytree(out, dest)
    return dest, suite


def _replace(path, kind: str) -> None:
    if path.is_dir():
        shutil.rmtree(path)
    elif path.exists():
        path.unlink()
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "dir":
        path.mkdir()
    else:
        path.write_text("not a folder\n")


ENTRIES = [("results.csv", "fifo"), ("results.csv", "dir"), ("run.json", "fifo"), ("run.json", "dir"),
           ("worker.log", "fifo"), ("run.lock", "fifo"), ("report.md", "fifo"), ("report.md", "dir"),
           ("yardstick", "file"), ("problems", "file"), ("plots", "file")]


@pytest.mark.parametrize("command", ["run", "report", "compare"])
@pytest.mark.parametrize("name, kind", ENTRIES, ids=[f"{n} {k}" for n, k in ENTRIES])
def test_an_entry_of_the_wrong_kind_is_one_line(finished_run, tmp_path, capsys, name, kind, command):
    out, suite = _copy(finished_run, tmp_path)
    _replace(out / name, kind)
    argv = {"run": ["run", "--quiet", "--suite", suite, "--out", out], "report": ["report", out],
            "compare": ["compare", finished_run[0], out]}[command]
    t0 = time.monotonic()
    code, _, err = run(capsys, *argv)
    assert time.monotonic() - t0 < 60
    assert code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    want = {"fifo": "is a FIFO", "dir": "is a directory", "file": "is a regular file"}[kind]
    assert f"{out / name}: {want}; expected" in err, err


@pytest.mark.parametrize("folder, kind", [("yardstick", "fifo"), ("problems", "fifo"), ("yardstick", "dir")],
                         ids=["yardstick fifo", "problems fifo", "yardstick dir"])
def test_an_entry_of_the_wrong_kind_inside_a_run_s_folder_is_one_line(finished_run, tmp_path, capsys, folder, kind):
    out, suite = _copy(finished_run, tmp_path)
    victim = sorted((out / folder).iterdir())[0]
    _replace(victim, kind)
    code, _, err = run(capsys, "run", "--quiet", "--rerun", "--suite", suite, "--out", out)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert f"{victim}: is a {'FIFO' if kind == 'fifo' else 'directory'}; expected a regular file" in err, err


def _patch_member_headers(path, edit) -> None:
    """Apply ``edit(bytearray, offset_of_local_header, offset_of_central_entry)`` to each member."""
    data = bytearray(path.read_bytes())
    with zipfile.ZipFile(path) as zf:
        infos = zf.infolist()
    central = data.find(b"PK\x01\x02")
    for info in infos:
        edit(data, info.header_offset, central)
        central = data.find(b"PK\x01\x02", central + 4)
    path.write_bytes(bytes(data))


def _encrypted(path):
    def edit(data, local, central):  # general purpose bit 0: encrypted
        data[local + 6] |= 1
        data[central + 8] |= 1
    _patch_member_headers(path, edit)


def _unknown_method(path):
    def edit(data, local, central):  # compression method 99 (AES, not readable here)
        data[local + 8:local + 10] = struct.pack("<H", 99)
        data[central + 10:central + 12] = struct.pack("<H", 99)
    _patch_member_headers(path, edit)


def _huge_member(path):
    with zipfile.ZipFile(path, "a", compression=zipfile.ZIP_DEFLATED) as zf:
        with zf.open("padding.npy", "w", force_zip64=True) as f:  # (64 MiB of zeros, 64 kB stored)
            for _ in range(64):
                f.write(bytes(1 << 20))


@pytest.mark.parametrize("damage, says", [
    (_encrypted, "is encrypted: expected the arrays numpy.savez writes"),
    (_unknown_method, "uses zip compression method 99: expected stored or deflated"),
    (_huge_member, "holds 67108864 bytes: expected at most"),
], ids=["encrypted", "unknown method", "64 MiB member"])
def test_a_damaged_cached_yardstick_is_computed_again_with_one_line(finished_run, tmp_path, capsys, damage, says):
    out, suite = _copy(finished_run, tmp_path)
    cached = sorted((out / "yardstick").glob("*.npz"))
    for p in cached:
        damage(p)
    code, _, err = run(capsys, "run", "--quiet", "--rerun", "--suite", suite, "--out", out)
    assert code == 0 and "Traceback" not in err, err
    lines = [ln for ln in err.splitlines() if "cannot be read" in ln]
    assert len(lines) == len(cached) and all(says in ln and "computing the yardstick again" in ln for ln in lines)


@pytest.mark.parametrize("field, value, says", [
    ("sessions", "many", "sessions is a str: expected a list"),
    ("sessions", [1], "sessions[0] is a int: expected an object"),
    ("selected_solvers", 5, "selected_solvers is a int: expected a list"),
    ("environment", [], "environment is a list: expected a dict"),
    ("calibration_ns", "fast", "calibration_ns is a str: expected a int or float"),
], ids=["sessions str", "session int", "selected int", "environment list", "calibration str"])
@pytest.mark.parametrize("command", ["run", "report", "compare"])
def test_a_run_json_field_of_the_wrong_type_is_one_line(finished_run, tmp_path, capsys, field, value, says, command):
    out, suite = _copy(finished_run, tmp_path)
    meta = json.loads((out / "run.json").read_text())
    meta[field] = value
    (out / "run.json").write_text(json.dumps(meta))
    argv = {"run": ["run", "--quiet", "--suite", suite, "--out", out], "report": ["report", out],
            "compare": ["compare", finished_run[0], out]}[command]
    code, _, err = run(capsys, *argv)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert f"{out / 'run.json'}: {says}" in err, err
