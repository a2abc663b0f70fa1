"""Collection rules for the whole repository (doctests run over the packages)."""

import importlib.util

# agents/rllib.py imports ray at module level; without the [rllib] extra its doctests are skipped.
collect_ignore = [] if importlib.util.find_spec("ray") else ["agents/rllib.py"]
