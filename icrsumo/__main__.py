"""``python -m icrsumo`` is the ``icrsumo`` command."""

import sys

from icrsumo.app.cli.main import main

sys.exit(main())
