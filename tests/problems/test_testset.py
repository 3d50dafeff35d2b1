"""The shipped test set hlsp-1 (docs/testset.md): its files against the manifest's SHA-256, the
documented plain-numpy reader on it, the stored optima re-certified (a small sample here, every
problem in the slow test), the hard cases' exact data, and the peers' importers."""

from __future__ import annotations

import json
import os
import random
import re
import shutil
import tarfile
from pathlib import Path

import numpy as np
import pytest
from hik_strategies import hierarchies
from hypothesis import HealthCheck, assume, given, settings

from hikbench.problems.errors import ProblemFileError
from hikbench.problems.exact import estimated_seconds
from hikbench.problems.files import load_npz
from hikbench.problems.testset import TestSet, TestSetError, set_folder
from hikbench.problems.testset.cases import CASES, hard_case
from hikbench.problems.testset.peers import nipm_cases, read_lexls
from hikbench.problems.verify import level_scales

ROOT = Path(__file__).resolve().parents[2]
#: the pinned peer sources (docs/peers.md): PEERS_SRC (as make peers), else ../shared/third_party of the checkout
#: (a worktree one level deeper: ../../shared)
THIRD_PARTY = next((p for p in (Path(os.environ.get("PEERS_SRC") or "/nonexistent"),
                                ROOT.parent / "shared" / "third_party", ROOT.parent.parent / "shared" / "third_party")
                    if p.is_dir()), ROOT.parent / "shared" / "third_party")


@pytest.fixture(scope="module")
def hlsp1() -> TestSet:
    return TestSet.read("hlsp-1")


def _reader() -> dict:
    """The python block of docs/testset.md, run as it is: its functions."""
    text = (ROOT / "docs" / "testset.md").read_text()
    (code,) = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    assert len(code.strip().splitlines()) <= 30, "the documented reader is meant to be short"
    namespace: dict = {}
    exec(compile(code, "docs/testset.md", "exec"), namespace)  # noqa: S102 - the doc's own code
    return namespace


def test_every_file_matches_the_manifests_sha256(hlsp1):
    assert len(hlsp1) > 0
    assert hlsp1.check_hashes() == []


def test_the_documented_reader_reads_the_set_and_its_optima_hold(hlsp1):
    """The doc's reader alone: every problem, arrays equal to hikbench's loader, and its level
    norms at the stored x* equal the stored certified norms (to 1e-9 of each level's scale:
    x* is the exact optimum rounded to float64)."""
    r = _reader()
    seen = 0
    for entry, arrays in r["read_set"](set_folder("hlsp-1")):
        h = load_npz(set_folder("hlsp-1") / entry["file"])
        np.testing.assert_array_equal(arrays["A"], h.A)
        np.testing.assert_array_equal(arrays["level"], h.level)
        x = np.array(entry["optimum"]["x"])
        got = r["level_norms"](arrays, x)
        stored = np.array(entry["optimum"]["level_norms"])
        assert got.shape == stored.shape == (entry["depth"],), entry["id"]
        np.testing.assert_allclose(got, stored, rtol=0, atol=1e-9 * float(max(level_scales(h, x).max(), 1e-300)),
                                   err_msg=entry["id"])
        seen += 1
    assert seen == len(hlsp1)


def test_the_set_meets_its_targets(hlsp1):
    """Every problem has its optimum and its provenance (hikbench version); the sequences are
    runs of consecutive steps; the share of robot control steps is at least 40 %."""
    robots = [e for e in hlsp1.entries if e.family.startswith("robot:")]
    assert len(robots) >= 0.4 * len(hlsp1), (len(robots), len(hlsp1))
    for e in hlsp1.entries:
        assert "hikbench" in e.provenance and np.all(np.isfinite(e.x)) and np.all(e.level_norms >= 0), e.id
    assert hlsp1.sequences
    for sid, ids in hlsp1.sequences.items():
        steps = [hlsp1.entry(pid).provenance["step"] for pid in ids]
        assert steps == list(range(steps[0], steps[0] + len(steps))), sid


def test_a_changed_byte_or_an_unlisted_file_is_named(tmp_path, hlsp1):
    folder = tmp_path / "set"
    shutil.copytree(set_folder("hlsp-1"), folder)
    victim = folder / hlsp1.entries[0].file
    data = bytearray(victim.read_bytes())
    data[-1] ^= 1
    victim.write_bytes(bytes(data))
    (folder / "stray.npz").write_bytes(b"")
    bad = TestSet.read(folder).check_hashes()
    assert len(bad) == 2 and hlsp1.entries[0].id in bad[0] and "SHA-256" in bad[0] and "stray.npz" in bad[1]


def test_a_manifest_of_another_format_is_refused(tmp_path):
    (tmp_path / "manifest.json").write_text(json.dumps({"format": "other", "problems": []}))
    with pytest.raises(TestSetError, match="format 'other': expected 'hikbench-testset-1'"):
        TestSet.read(tmp_path)
    with pytest.raises(TestSetError, match="no such folder"):
        TestSet.read(tmp_path / "none")


def _sample(hlsp1, k: int, cheap: float) -> list:
    small = [e for e in hlsp1.entries if estimated_seconds(hlsp1.load(e)) < cheap]
    return random.Random(0).sample(small, min(k, len(small)))


def test_a_sample_is_certified_again_with_the_stored_optimum(hlsp1):
    """Six problems of the set (seeded draw among those whose certificate is estimated under
    0.5 s): the exact certificate from the stored x* certifies it again, with the stored norms."""
    from hikbench.bench.testset.build import recertify

    sample = _sample(hlsp1, 6, 0.5)
    assert len(sample) == 6
    assert recertify(hlsp1, sample, workers=1) == []


@pytest.mark.slow
def test_every_problem_is_certified_again_with_the_stored_optimum(hlsp1):
    from hikbench.bench.testset.build import recertify

    assert recertify(hlsp1, hlsp1.entries, workers=2) == []


def _mantissa_bits(a: np.ndarray) -> int:
    """Bits of the widest mantissa among the finite entries (an integer times 2^e)."""
    a = a[np.isfinite(a) & (a != 0)]
    m, _ = np.frexp(np.abs(a))
    bits = 0
    for v in m:
        b = 0
        while v != int(v):
            v *= 2
            b += 1
        bits = max(bits, b)
    return bits


@pytest.mark.parametrize("case", sorted(CASES))
def test_the_hard_cases_are_exact_small_dyadic_data(case):
    """Every entry and bound is an integer times a power of two with a short mantissa (exact
    sums and products), and the same arguments give the same problem."""
    h = hard_case(case, 6, 1)
    for a in (h.A.ravel(), h.lower, h.upper):
        assert _mantissa_bits(a) <= 45, case
    assert hard_case(case, 6, 1) == h


def test_the_rank_deficient_case_has_the_rank_it_is_about():
    h = hard_case("rank_deficient", 6, 0)
    A1 = h.A[h.level_rows(1)]
    assert A1.shape[0] == 4 and np.linalg.matrix_rank(A1) == 2
    np.testing.assert_array_equal(A1[2], A1[0] + A1[1])  # exactly, in float64


LEXLS_FILE = """#nVar
3
#nObj
2
#nCtr
2 2
#HierType
200
#ObjType
100 200
#OBJECTIVE
1 -1 1
3 -0.5 0.5
#OBJECTIVE
1 1 0 2 2
0 1 1 -1e10 1
#Solution
1 0 0.5
"""


def test_a_lexls_hierarchy_file_is_read_as_lexls_reads_it(tmp_path):
    """A file in the layout LexLS's HierarchyFileProcessor reads (include/lexls/tools.h): simple
    bounds on x_0 and x_2 (Matlab's indices 1 and 3) in the first objective, general rows in the second."""
    p = tmp_path / "h.dat"
    p.write_text(LEXLS_FILE)
    h, sol = read_lexls(p)
    assert (h.n, h.depth, h.rows) == (3, 2, 4)
    np.testing.assert_array_equal(h.A, [[1, 0, 0], [0, 0, 1], [1, 1, 0], [0, 1, 1]])
    np.testing.assert_array_equal(h.lower, [-1, -0.5, 2, -1e10])
    np.testing.assert_array_equal(h.upper, [1, 0.5, 2, 1])
    np.testing.assert_array_equal(sol, [1, 0, 0.5])


@pytest.mark.parametrize("text, match", [
    (LEXLS_FILE.replace("#nVar\n3\n", ""), r"header field\(s\) \['#nVar'\] missing"),
    (LEXLS_FILE.replace("1 1 0 2 2", "1 1 zero 2 2"), "line 15: expected numbers"),
    (LEXLS_FILE.replace("3 -0.5 0.5", "4 -0.5 0.5"), r"line 13: simple bound on variable 4: expected an index in 1 \.\. 3"),
], ids=["no-nvar", "not-a-number", "bad-index"])
def test_a_bad_lexls_file_names_the_line(tmp_path, text, match):
    p = tmp_path / "h.dat"
    p.write_text(text)
    with pytest.raises(ProblemFileError, match=match):
        read_lexls(p)


@pytest.fixture(scope="module")
def nipm_source(tmp_path_factory):
    (tar,) = THIRD_PARTY.glob("nipm-hlsp-*.tar.gz") if THIRD_PARTY.is_dir() else (None,)
    if tar is None:
        pytest.skip(f"no NIPM-HLSP snapshot in {THIRD_PARTY}")
    d = tmp_path_factory.mktemp("nipm")
    with tarfile.open(tar) as t:
        t.extractall(d, filter="data")
    (src,) = [p for p in d.iterdir() if p.is_dir()]
    return src


def test_nipm_hlsps_cases_are_read_from_its_source(nipm_source):
    """The 17 cases of tests/test1.cpp with their sizes; case 3 is -x <= 0, x <= 0 and case 8
    three equality levels x = 1, x_0.1 = 10, x = 20 (the file's identity blocks)."""
    cases = {num: (h, prov) for num, h, prov in nipm_cases(nipm_source)}
    assert sorted(cases) == list(range(17))
    h3 = cases[3][0]
    np.testing.assert_array_equal(h3.A, [[-1.0], [1.0]])
    np.testing.assert_array_equal(h3.upper, [0.0, 0.0])
    assert np.all(np.isneginf(h3.lower))
    h8 = cases[8][0]
    assert list(h8.rows_per_level) == [1, 2, 3] and np.all(h8.lower == h8.upper)
    np.testing.assert_array_equal(h8.lower, [1, 10, 10, 20, 20, 20])
    assert all("BSD-3-Clause" in prov["licence"] for _, prov in cases.values())
    assert "redrawn" in cases[0][1]["rows"] and "as test1.cpp" in cases[2][1]["rows"]


def _lexls_text(h) -> str:
    """h in LexLS's hierarchy text layout (#HierType 200: every row ``a_1 .. a_n lo up``, general
    objectives), numbers as Python's round-trip repr."""
    lines = ["#nVar", str(h.n), "#nObj", str(h.depth), "#nCtr", " ".join(map(str, h.rows_per_level)),
             "#HierType", "200", "#ObjType", " ".join(["200"] * h.depth)]
    for k in range(h.depth):
        lines.append(f"#OBJECTIVE {k}")
        s = h.level_rows(k)
        lines += [" ".join(map(repr, [*map(float, a), float(lo), float(up)]))
                  for a, lo, up in zip(h.A[s], h.lower[s], h.upper[s])]
    return "\n".join(lines) + "\n"


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(h=hierarchies(min_n=1, names=False, x0=False))
def test_read_lexls_reads_back_any_hierarchy_exactly(tmp_path, h):
    assume(h.depth > 0)  # (the format has at least one objective)
    p = tmp_path / "h.dat"
    p.write_text(_lexls_text(h))
    got, sol = read_lexls(p)
    assert sol is None and got.depth == h.depth
    np.testing.assert_array_equal(got.A, h.A)
    np.testing.assert_array_equal(got.lower, h.lower)
    np.testing.assert_array_equal(got.upper, h.upper)
    np.testing.assert_array_equal(got.level, h.level)


def test_the_hard_cases_rebuild_bit_for_bit(hlsp1, tmp_path):
    """Each hard case of the set, generated again from its provenance and saved as the builder
    saves it, has the manifest's SHA-256 (integer data: no BLAS or CPU in the way)."""
    from hikbench.problems.files import save_npz
    from hikbench.problems.testset import file_sha256

    hard = [e for e in hlsp1.entries if e.family.startswith("hard:")]
    assert len(hard) == 96
    for e in hard:
        p = e.provenance["params"]
        save_npz(hard_case(p["case"], p["n"], e.provenance["seed"]), tmp_path / "h.npz", compressed=True)
        assert file_sha256(tmp_path / "h.npz") == e.sha256, e.id


def test_lexls_cases_reads_a_source_folders_tests(tmp_path):
    from hikbench.problems.testset.peers import lexls_cases

    with pytest.raises(ProblemFileError, match=r"tests: no LexLS hierarchy file \(\*\.dat\)"):
        lexls_cases(tmp_path)
    (tmp_path / "tests").mkdir()
    (tmp_path / "tests" / "t.dat").write_text(LEXLS_FILE)
    ((name, h, sol, prov),) = lexls_cases(tmp_path)
    assert name == "t" and h.rows == 4 and prov["source"] == "LexLS tests/t.dat" and "BSD-2-Clause" in prov["licence"]
    np.testing.assert_array_equal(sol, [1, 0, 0.5])
