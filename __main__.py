"""``python -m trustfg``: the same as the ``trustfg`` command."""

import sys

from .cli import main

sys.exit(main())
