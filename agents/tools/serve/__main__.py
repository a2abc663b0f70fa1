"""``python -m agents.tools.serve``: see :mod:`agents.tools.serve.cli`."""

import sys

from agents.tools.serve.cli import main

sys.exit(main())
