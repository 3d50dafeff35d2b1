"""Building, checking and ranking on the test sets of hikbench.problems.testset (docs/testset.md)."""
