"""``python -m orchestrator``: see :mod:`orchestrator.cli`."""

import sys

from .cli import main

sys.exit(main())
