"""What a problem file's numbers decide is bounded before it is allocated: the
npz loader reads shapes and dtypes from the .npy headers before any data
(problems/files.py), and the n x n work of the yardstick and of ``inspect``
is checked against the machine's memory (problems/hierarchy.check_fits_in_memory)."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from hikbench.problems.errors import ProblemFileError, ProblemTooLargeError
from hikbench.problems.files import load_npz
from hikbench.problems.hierarchy import MEMORY_BYTES

TESTS = Path(__file__).resolve().parents[1] / "bench"


def _npy_header(shape, dtype="<f8") -> bytes:
    """A .npy version 1.0 header for an array of ``shape`` (no data)."""
    import io

    f = io.BytesIO()
    np.lib.format.write_array_header_1_0(f, {"descr": dtype, "fortran_order": False, "shape": tuple(shape)})
    return f.getvalue()


def _write(path, members: dict) -> None:
    """An npz whose members are raw .npy bytes (headers free to lie about the data)."""
    with zipfile.ZipFile(path, "w", zipfile.ZIP_STORED) as zf:
        for name, data in members.items():
            zf.writestr(name + ".npy", data)


def _npy(a) -> bytes:
    import io

    f = io.BytesIO()
    np.save(f, a)
    return f.getvalue()


def _small(n=4, rows=1) -> dict:
    return {"A": _npy(np.zeros((rows, n))), "lower": _npy(np.zeros(rows)), "upper": _npy(np.ones(rows)),
            "level": _npy(np.zeros(rows, dtype=np.int64)), "n": _npy(np.int64(n))}


def test_a_compressed_array_wider_than_n_is_refused_before_it_is_decompressed(tmp_path):
    """A 2 MB file made inspect allocate 2.1 GB before refusing it."""
    cols = 50_000_000  # 400 MB of zeros, a few hundred KB compressed
    path = tmp_path / "wide.npz"
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED, compresslevel=1) as zf:
        for name, data in _small().items():
            if name != "A":
                zf.writestr(name + ".npy", data)
        with zf.open("A.npy", "w", force_zip64=True) as f:  # streamed: nothing large in memory here
            f.write(_npy_header((1, cols)))
            chunk = bytes(1 << 24)
            for _ in range(8 * cols >> 24):
                f.write(chunk)
            f.write(bytes(8 * cols % (1 << 24)))
    code = (f"import resource, sys\nsys.path.insert(0, {str(TESTS)!r})\n"
            "from hikbench.problems.files import load_npz\nfrom hikbench.problems.errors import ProblemFileError\n"
            "before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss\n"
            f"try:\n    load_npz({str(path)!r})\nexcept ProblemFileError as err:\n    msg = str(err)\n"
            "print(msg); print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    msg, grew_kib = out.stdout.strip().splitlines()[-2:]
    assert f"A has shape (1, {cols}): expected (1, 4)" in msg, msg
    assert int(grew_kib) * 1024 < 100 << 20, grew_kib


@pytest.mark.parametrize("change, fragment", [
    ({"lower": _npy_header((3,))}, "lower has shape (3,): expected (1,)"),
    ({"x0": _npy_header((7,))}, "x0 has shape (7,): expected (4,)"),
    ({"A": _npy_header((1, 2, 2))}, "A has shape (1, 2, 2): expected (rows, n)"),
    ({"A": _npy_header((1, 4), "|O")}, "A must be a numeric array; it holds Python objects"),
    ({"A": _npy_header((1, 4), "<c16")}, "A must be a numeric array (float64); got dtype complex128"),
    ({"n": _npy_header((2,), "<i8")}, "n must be a scalar integer"),
], ids=["lower length", "x0 length", "A 3-d", "objects", "complex", "n not scalar"])
def test_a_header_that_disagrees_is_refused_before_its_data_is_read(tmp_path, change, fragment):
    path = tmp_path / "p.npz"
    _write(path, {**_small(), **change})  # the changed members have a header and no data
    with pytest.raises(ProblemFileError) as err:
        load_npz(path)
    assert fragment in str(err.value), str(err.value)


def test_arrays_larger_than_the_machine_are_refused_from_their_headers(tmp_path):
    rows = MEMORY_BYTES // (8 * 4)  # A alone: all the memory
    path = tmp_path / "p.npz"
    _write(path, {**_small(), "A": _npy_header((rows, 4)), "lower": _npy_header((rows,)),
                  "upper": _npy_header((rows,)), "level": _npy_header((rows,), "<i8")})
    with pytest.raises(ProblemTooLargeError, match="more than half of this machine's"):
        load_npz(path)


def _no_rows(tmp_path, n: int) -> Path:
    path = tmp_path / "big.npz"
    with open(path, "wb") as f:
        np.savez(f, A=np.zeros((0, n)), lower=np.zeros(0), upper=np.zeros(0), level=np.zeros(0, dtype=np.int64),
                 n=np.int64(n), names=np.array(["empty"]))
    return path


# n whose three n x n matrices exceed the memory, one not (the check before: one)
N_BIG = int((MEMORY_BYTES / 8 / 2) ** 0.5) + 1


@pytest.mark.parametrize("argv", [["inspect"], ["solve", "--solver", "yardstick"]], ids=["inspect", "yardstick"])
def test_n_x_n_work_beyond_the_memory_is_a_one_line_error(tmp_path, argv):
    """n = 50000 and no rows passed the size check (one matrix, 18.6 GiB of
    23); the yardstick and inspect then allocated several."""
    path = _no_rows(tmp_path, N_BIG)
    cmd = [sys.executable, "-c", "import runpy; runpy.run_module('hikbench', run_name='__main__')",
           argv[0], str(path), *argv[1:]]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert out.returncode == 2, (out.returncode, out.stdout[-500:], out.stderr[-2000:])
    assert len(out.stderr.strip().splitlines()) == 1, out.stderr
    assert f"n = {N_BIG} variables: one n x n matrix of doubles needs" in out.stderr, out.stderr
    assert "this work holds 3 at once" in out.stderr, out.stderr


def test_a_run_with_such_a_problem_writes_an_error_row_for_its_yardstick():
    from hikbench.bench.harness.worker import execute
    from hikbench.problems.hierarchy import Hierarchy

    h = Hierarchy(np.zeros((0, N_BIG)), np.zeros(0), np.zeros(0), np.zeros(0, dtype=int), n=N_BIG)
    res = execute({"kind": "yardstick", "hierarchy": h})
    assert res["status"] == "error" and "holds 3 at once" in res["reason"], res


@pytest.mark.parametrize("name, hint", [("x_0", " (did you mean 'x0'?)"), ("weights", "")],
                         ids=["misspelt", "unknown"])
def test_an_array_the_format_does_not_have_is_named(tmp_path, name, hint):
    """An npz member the format does not have is refused, named with the closest known name,
    not silently left unread."""
    path = tmp_path / "p.npz"
    np.savez(path, A=np.eye(2), lower=np.zeros(2), upper=np.ones(2), level=np.zeros(2, dtype=int), n=np.array(2),
             **{name: np.zeros(2)})
    with pytest.raises(ProblemFileError, match=f"^{re.escape(str(path))}: unknown array '{name}'{re.escape(hint)}; "
                                               r"expected some of \['A', 'lower'"):
        load_npz(path)
