"""``python -m dem_taichi``: see :mod:`dem_taichi.cli.commands`."""

import sys

from dem_taichi.cli.commands import main

if __name__ == "__main__":  # guarded: spawned worker processes import this module
    sys.exit(main())
