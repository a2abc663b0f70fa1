"""``python -m agents.evaluate``: the command line of :mod:`agents.evaluate.cli`."""

from agents.evaluate.cli import main

raise SystemExit(main())
