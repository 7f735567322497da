"""``python -m millfmu``: the ``millfmu`` command (where the environment's scripts folder is
not on the PATH)."""

import sys

from millfmu.cli import main

sys.exit(main())
