"""``python -m bench`` = the ``hikbench`` console script."""
import sys

from bench.cli import main

sys.exit(main())
