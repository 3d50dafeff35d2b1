"""``python -m hikbench`` = the ``hikbench`` console script."""
import sys

from hikbench.bench.cli import main

sys.exit(main())
