"""What a user of an outside library meets: SB3's settings dict, RL Zoo's module, error messages, row names."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import gymnasium as gym
import pytest
import yaml

import coop_gym  # noqa: F401 -- registers the ids
from agents.caregivers.scripted import BlindAgent
from agents.evaluate import evaluate
from agents.hyperparams import hyperparams_for
from agents.tools.evaluate_cli import main
from agents.zoo import HARD_TRAINING_IDS, zoo_hyperparams
from coop_gym.registration import ENV_IDS, HARD_ENV_ID, unit_twin

pytest.importorskip("stable_baselines3")

ROOT = Path(__file__).resolve().parents[2]


def test_sb3_settings_are_a_dict_ppo_takes_with_its_wrappers_named():
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecNormalize

    from agents.rl import VEC_NORMALIZE_KWARGS, LinearDecay, sb3_settings

    settings = sb3_settings(HARD_ENV_ID)
    config = hyperparams_for("ppo", HARD_ENV_ID)
    assert settings.vec_normalize == VEC_NORMALIZE_KWARGS and settings.wrappers == ("VecMonitor", "VecNormalize")
    assert settings.env_kwargs == {"personas": "train_wide"} and settings.total_timesteps == config.total_timesteps
    assert isinstance(settings.hyperparams["learning_rate"], LinearDecay)
    env = settings.make_env(seed=0)
    try:
        assert isinstance(env, VecNormalize) and not env.norm_reward and env.num_envs == config.n_envs
        model = PPO(settings.policy, env, seed=0, device="cpu", **settings.hyperparams)
        assert (model.n_steps, model.batch_size, model.n_epochs, model.ent_coef) == (512, 512, 10, 0.02)
        assert model.lr_schedule(1.0) == pytest.approx(3e-4) and model.policy.net_arch == [64, 64]
    finally:
        env.close()


def test_rl_zoos_entry_for_the_hard_level_is_the_sb3_settings():
    """docs/integrations.md: RL Zoo with ``-conf agents.zoo.ppo`` and ``--seed S`` trains what ``sb3_settings`` does."""
    from agents.rl import sb3_settings
    from agents.zoo import ppo

    settings = sb3_settings(HARD_ENV_ID)
    entry = dict(ppo.hyperparams[HARD_ENV_ID])
    assert entry.pop("n_envs") == settings.n_envs and entry.pop("n_timesteps") == settings.total_timesteps
    assert entry.pop("policy") == settings.policy and entry.pop("env_kwargs") == settings.env_kwargs
    assert entry.pop("normalize") == settings.vec_normalize
    learning_rate = entry.pop("learning_rate")
    hyperparams = dict(settings.hyperparams)
    schedule = hyperparams.pop("learning_rate")
    assert learning_rate == "lin_3e-4" and [schedule(p) for p in (1.0, 0.5, 0.0)] == pytest.approx([3e-4, 1.5e-4, 0])
    assert entry == hyperparams


def test_zoo_module_holds_every_hard_training_id_and_the_generated_yaml_entries():
    from agents.zoo import ppo

    hard = [i for i, kw in ENV_IDS.items() if str(kw.get("difficulty", "")).startswith("hard")]
    assert set(HARD_TRAINING_IDS) == {i for i in hard if "HeldOut" not in i} and len(HARD_TRAINING_IDS) == 11
    assert set(HARD_TRAINING_IDS) <= set(ppo.hyperparams)
    for env_id in HARD_TRAINING_IDS:
        assert ppo.hyperparams[env_id]["ent_coef"] == 0.02 and ppo.hyperparams[env_id]["env_kwargs"] == {
            "personas": "train_wide"
        }
    for algo, name in (("ppo", "ppo"), ("recurrent_ppo", "ppo_lstm"), ("dqn", "dqn")):
        generated = yaml.safe_load((ROOT / "agents" / "zoo" / f"{name}.yml").read_text())
        module = zoo_hyperparams(algo)
        for env_id, entry in generated.items():
            # The YAML writes dicts as strings RL Zoo evaluates ("dict(norm_obs=True, ...)").
            read = {k: eval(v, {}) if isinstance(v, str) and v.startswith("dict(") else v for k, v in entry.items()}
            assert read == {**module[env_id], "n_timesteps": float(module[env_id]["n_timesteps"])}, env_id


def test_scripted_agents_on_a_unit_id_name_the_twin_id_they_play():
    for env_id, kwargs in ENV_IDS.items():
        assert (unit_twin(env_id) is None) == (kwargs.get("observation_scale") != "unit"), env_id
    with pytest.raises(ValueError, match=r"play them on its twin CoopGym/SitToStandHard-v2 "):
        evaluate("blind", "CoopGym/SitToStandHardUnit-v2", "test", episodes=1)
    with gym.make("CoopGym/SitToStandHardDiscreteUnit-v2") as env:
        with pytest.raises(ValueError, match=r"its twin CoopGym/SitToStandHardDiscrete-v2 "):
            BlindAgent.for_env(env)
    evaluate("blind", unit_twin("CoopGym/SitToStandHardDiscreteUnit-v2"), "test", episodes=1)  # the twin plays


def test_model_rows_are_named_after_their_file_and_a_run_folder_after_the_folder(tmp_path, capsys):
    from agents.pretrained import pretrained_model_path

    seed3, run = tmp_path / "logs" / "seed3.zip", tmp_path / "Hard-v2__ppo__0__1" / "model.zip"
    for path in (seed3, run):
        path.parent.mkdir()
        shutil.copyfile(pretrained_model_path("hard-v2-ppo"), path)
    assert main(["--compare", f"{seed3},{run.parent},blind", "--episodes", "2", "--json"]) == 0
    rows = [r["agent"] for r in json.loads(capsys.readouterr().out)["results"]]
    assert rows == ["ppo:seed3", "ppo:Hard-v2__ppo__0__1", "blind"]  # not "ppo:logs"
