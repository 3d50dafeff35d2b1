"""Sub-commands of ``hikbench``; see ``hikbench.bench.cli``."""
