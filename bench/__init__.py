"""How it is measured: CLI, runner, timing, verification, suites, report,
claims, regression compare, executors. Imports ``problems`` and ``solvers``."""
