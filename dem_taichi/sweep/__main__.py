"""``python -m dem_taichi.sweep SWEEP.toml --out DIR`` (same as ``python -m dem_taichi sweep``)."""

import sys

from dem_taichi.sweep.command import main

if __name__ == "__main__":  # guarded: spawned worker processes import this module
    sys.exit(main())
