"""``python -m servosurf``."""

import sys

from .cli import main

sys.exit(main())
