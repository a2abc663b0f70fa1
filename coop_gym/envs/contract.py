"""The env contract at one import path, for the agents and adapters that read it.

Each name is defined once, in the module that owns it: actions in :mod:`coop_gym.envs.actions`,
arguments in :mod:`coop_gym.envs.arguments`, infos in :mod:`coop_gym.envs.info`, observations in
:mod:`coop_gym.envs.observation`, the report row and the episode end in :mod:`coop_gym.envs.report`.
"""

from __future__ import annotations

from coop_gym.envs.actions import (
    ACTION_SHAPE,
    CMD,
    CMD_COLUMNS,
    LIFT,
    N_FLAT_ACTIONS,
    PUSH_FIRM,
    PUSH_NONE,
    PUSH_SOFT,
    VERBAL_BACK,
    VERBAL_FORWARD,
    VERBAL_NONE,
    WAIT,
    ActionDecoder,
    action_space_for,
    command_table,
    decode_actions,
    encode_actions,
)
from coop_gym.envs.arguments import (
    EnvArguments,
    SitToStandConfig,
    parse_reset_options,
)
from coop_gym.envs.config import INFO_MODES
from coop_gym.envs.info import (
    NUMERIC_INFO_KEYS,
    InfoBuilder,
    report_info,
)
from coop_gym.envs.observation import (
    FEATURE_BOUNDS,
    FEATURE_SCALES,
    FEATURES,
    OBSERVATION_SCALES,
    observation_features,
    observation_scaler,
    observation_scales,
    observation_space_for,
    scaled_feature_names,
    unit_observation_space,
)
from coop_gym.envs.report import (
    EPISODE_END,
    REPORT,
    REPORT_COLUMNS,
    REWARD_TERMS,
    TERMINATES,
    TRUNCATES,
    check_outcome_codes,
    count_steps_and_end_episodes,
)

__all__ = [
    "ACTION_SHAPE",
    "CMD",
    "CMD_COLUMNS",
    "EPISODE_END",
    "FEATURES",
    "FEATURE_BOUNDS",
    "FEATURE_SCALES",
    "INFO_MODES",
    "LIFT",
    "NUMERIC_INFO_KEYS",
    "N_FLAT_ACTIONS",
    "OBSERVATION_SCALES",
    "PUSH_FIRM",
    "PUSH_NONE",
    "PUSH_SOFT",
    "REPORT",
    "REPORT_COLUMNS",
    "REWARD_TERMS",
    "TERMINATES",
    "TRUNCATES",
    "VERBAL_BACK",
    "VERBAL_FORWARD",
    "VERBAL_NONE",
    "WAIT",
    "ActionDecoder",
    "EnvArguments",
    "InfoBuilder",
    "SitToStandConfig",
    "action_space_for",
    "check_outcome_codes",
    "command_table",
    "count_steps_and_end_episodes",
    "decode_actions",
    "encode_actions",
    "observation_features",
    "observation_scaler",
    "observation_scales",
    "observation_space_for",
    "parse_reset_options",
    "report_info",
    "scaled_feature_names",
    "unit_observation_space",
]
