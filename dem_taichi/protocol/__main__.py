"""``python -m dem_taichi.protocol SCENE --out DIR`` (same as ``python -m dem_taichi protocol``)."""

import sys

from dem_taichi.protocol.runner import main

if __name__ == "__main__":  # guarded: spawned worker processes import this module
    sys.exit(main())
