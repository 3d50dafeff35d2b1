"""The README's Python example runs and prints what the README says it prints."""

import re
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_readme_python_example_prints_what_it_says():
    text = (ROOT / "README.md").read_text()
    section = text.split("### From Python\n", 1)[1].split("\n## ", 1)[0]
    code = textwrap.dedent(section.split("\nprints ", 1)[0])  # the indented block above "prints"
    said = re.search(r"prints `(.+?)` and `(.+?)`", section).groups()
    # (timeout: without a numba cache the first hcod solve compiles its kernels, 70-90 s here)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True,
                         timeout=600).stdout
    assert out.splitlines() == list(said)
