"""Every registered id's keywords are the env's (checked here, since registering no longer builds them)."""

from __future__ import annotations

import pytest

from coop_gym.envs.arguments import EnvArguments, SitToStandConfig
from coop_gym.registration import ENV_IDS


@pytest.mark.parametrize("env_id", sorted(ENV_IDS))
def test_every_registered_id_has_valid_keywords(env_id: str) -> None:
    keywords = ENV_IDS[env_id]
    arguments = EnvArguments.from_keywords(env_id, keywords)
    assert {k: getattr(arguments, k) for k in keywords} == keywords
    assert isinstance(arguments.resolve(), SitToStandConfig)  # every value passes the env's own checks


def test_a_misspelt_keyword_is_refused() -> None:
    with pytest.raises((TypeError, ValueError), match="difficulty"):
        EnvArguments.from_keywords("CoopGym/Made-Up-v0", {"dificulty": "hard"})
