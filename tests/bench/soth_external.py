"""An external solver reading the SOTH text export: ``soth_external.py PROBLEM.soth.txt OUT.json``."""

import json
import sys

from hikbench.problems.soth import load_soth
from hikbench.solvers.yardstick import nullspace_yardstick

h = load_soth(sys.argv[1])
with open(sys.argv[2], "w") as f:
    json.dump({"x": nullspace_yardstick(h).tolist()}, f)
