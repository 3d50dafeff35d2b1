"""docs/python-api.md's control loop on a robot stack runs and prints what the page says it
prints (its numbers to the page's two digits: the last bits of a closed loop differ by CPU)."""

import ast
import re
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def _section() -> str:
    text = (ROOT / "docs" / "python-api.md").read_text()
    return text.split("## A control loop on a robot\n", 1)[1].split("\n## ", 1)[0]


def test_the_control_loop_prints_what_the_page_says():
    section = _section()
    code = re.search(r"```python\n(.+?)```", section, re.S).group(1)
    said = re.search(r"\nprints\n\n((?:    .+\n)+)", section).group(1).splitlines()
    said = [line[4:] for line in said]
    # (timeout: without a numba cache the first hcod solve compiles its kernels, 70-90 s here)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True,
                         timeout=600).stdout.splitlines()
    assert len(out) == len(said) == 2, out
    assert out[0] == said[0]
    got, page = ast.literal_eval(out[1]), ast.literal_eval(said[1])
    assert list(got) == list(page), (got, page)
    assert all(isinstance(v, float) for v in got.values()), got  # (velocity_limits measured at u, not None)
    np.testing.assert_allclose(list(got.values()), list(page.values()), rtol=0.05, atol=1e-12)


def test_the_page_names_the_decay_it_prints():
    """0.1 m x (1 - gain dt)^100, from the stack file's gain and dt: the printed ee error."""
    from hikbench.problems.robots.stacks import load_stack_spec

    spec = load_stack_spec("arm_reach")
    gain = next(t["gain"] for lv in spec.levels for t in lv if t.get("frame") == "ee")
    page = ast.literal_eval(re.search(r"\nprints\n\n(?:    .+\n)    (.+)\n", _section()).group(1))
    np.testing.assert_allclose(page["ee"], 0.1 * (1 - gain * spec.dt) ** 100, rtol=0.05)
