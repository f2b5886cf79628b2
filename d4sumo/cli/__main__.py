"""``python -m d4sumo.cli``."""

import sys

from . import main

sys.exit(main())
