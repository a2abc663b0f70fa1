"""The env contract at one import path, for the agents and adapters that read it.

Each name is defined once, in the module that owns it: actions in :mod:`coop_gym.envs.actions`,
arguments in :mod:`coop_gym.envs.arguments`, infos in :mod:`coop_gym.envs.info`, observations in
:mod:`coop_gym.envs.observation`, the report row and the episode end in :mod:`coop_gym.envs.kernels.report`.
"""

from __future__ import annotations

from coop_gym.envs import actions, arguments, info, observation
from coop_gym.envs.actions import *  # noqa: F403
from coop_gym.envs.arguments import *  # noqa: F403
from coop_gym.envs.config import INFO_MODES
from coop_gym.envs.info import *  # noqa: F403
from coop_gym.envs.kernels import report
from coop_gym.envs.kernels.report import *  # noqa: F403
from coop_gym.envs.observation import *  # noqa: F403

__all__ = [
    "INFO_MODES",
    *actions.__all__,
    *arguments.__all__,
    *info.__all__,
    *observation.__all__,
    *report.__all__,
]
