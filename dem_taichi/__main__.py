"""``python -m dem_taichi``: see :mod:`dem_taichi.cli`."""

import sys

from dem_taichi.cli import main

sys.exit(main())
