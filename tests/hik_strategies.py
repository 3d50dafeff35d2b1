"""Hypothesis strategies for random hierarchies (imported by the tests as
``hik_strategies``; pytest puts ``tests/`` on sys.path through conftest.py)."""

import numpy as np
from hypothesis import strategies as st

from hikbench.problems import Hierarchy

ROW_KINDS = ("equality", "lower only", "upper only", "two-sided", "free")

#: any finite double (exact round-trips must survive 1e-308 and 1e308 alike)
any_finite = st.floats(allow_nan=False, allow_infinity=False, width=64)
#: bounds the SOTH format can hold (|bound| < 1e25, see hikbench.problems.soth)
soth_bound = st.floats(min_value=-1e24, max_value=1e24, allow_nan=False)
moderate = st.floats(min_value=-10.0, max_value=10.0, allow_nan=False)
#: level names that numpy's unicode arrays keep unchanged (no control characters: a
#: trailing NUL would be stripped by the .npz format)
name_text = st.text(alphabet=st.characters(blacklist_categories=("Cs", "Cc")), max_size=12)


@st.composite
def hierarchies(draw, max_n=5, max_depth=4, max_rows=3, coefficients=any_finite, bounds=soth_bound,
                kinds=ROW_KINDS, names=True, x0=True, min_n=0, equalities_first=False):
    """A valid Hierarchy with every row kind, empty levels, optional names and x0."""
    n = draw(st.integers(min_n, max_n))
    depth = draw(st.integers(0, max_depth))
    A, lower, upper, level = [], [], [], []
    for k in range(depth):
        m_k = draw(st.integers(0, max_rows))
        row_kinds = [draw(st.sampled_from(kinds)) for _ in range(m_k)]
        rows = []
        for kind in row_kinds:
            a_row = draw(st.lists(coefficients, min_size=n, max_size=n))
            a, b = sorted(draw(st.lists(bounds, min_size=2, max_size=2)))
            if kind == "two-sided" and a == b:
                kind = "equality"
            lo, up = {"equality": (a, a), "lower only": (a, np.inf), "upper only": (-np.inf, b),
                      "two-sided": (a, b), "free": (-np.inf, np.inf)}[kind]
            rows.append((a_row, lo, up))
        if equalities_first:  # on the final bounds: a two-sided row may have become an equality
            rows.sort(key=lambda r: r[1] != r[2])
        for a_row, lo, up in rows:
            A.append(a_row)
            lower.append(lo)
            upper.append(up)
            level.append(k)
    level_names = (draw(st.lists(name_text, min_size=depth, max_size=depth)) if names and draw(st.booleans())
                   else None)
    start = (np.array(draw(st.lists(any_finite, min_size=n, max_size=n)))
             if x0 and draw(st.booleans()) else None)
    return Hierarchy(np.array(A, dtype=float).reshape(len(A), n), lower, upper, np.array(level, dtype=int),
                     n=n, depth=depth, names=level_names, x0=start)
