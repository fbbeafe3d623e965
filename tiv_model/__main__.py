"""``python -m tiv_model ...`` runs the command line (see :mod:`tiv_model.cli`)."""

import sys

from .cli import main

sys.exit(main())
