"""``python -m agents.evaluate``: the command line of :mod:`agents.evaluate.cli`."""

from agents.evaluate.cli import main
from coop_gym.cli import exit_status

raise SystemExit(exit_status(main))
