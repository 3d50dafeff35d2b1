"""Sub-commands of ``hikbench``; see ``bench.cli``."""
