"""``python -m agents.evaluate``: the command line of :mod:`agents.tools.evaluate_cli`."""

from agents.tools.evaluate_cli import main
from coop_gym.cli import exit_status

raise SystemExit(exit_status(main))
