"""``python -m icrsumo`` is the ``icrsumo`` command."""

import sys

from .cli import main

sys.exit(main())
