"""train.py --framework: usage errors exit 2 before anything starts (no Ray needed)."""

from __future__ import annotations

import importlib.util

import pytest

import train


@pytest.mark.parametrize(
    "argv",
    [
        ["--framework", "tf"],
        ["--framework", "rllib", "--algo", "dqn"],
        ["--framework", "rllib", "--num-env-runners", "-1"],
        ["--framework", "jax", "--algo", "dqn"],
        ["--policy-lag", "1", "--framework", "sb3"],
        ["--policy-lag", "1", "--algo", "recurrent_ppo"],
        ["--policy-lag", "2"],
    ],
)
def test_bad_framework_arguments_exit_2(argv):
    with pytest.raises(SystemExit) as info:
        train.parse_args(argv)
    assert info.value.code == 2


def test_ppo_trains_with_jax_unless_told_and_other_algorithms_with_sb3():
    from agents.trainer.train_args import learner_framework

    assert learner_framework(train.parse_args([])) == "jax"
    assert learner_framework(train.parse_args(["--framework", "sb3"])) == "sb3"
    assert learner_framework(train.parse_args(["--algo", "dqn"])) == "sb3"


def test_rllib_flags_parse():
    if importlib.util.find_spec("ray") is None:
        with pytest.raises(SystemExit):
            train.parse_args(["--framework", "rllib"])
        return
    args = train.parse_args(["--framework", "rllib", "--num-env-runners", "3", "--address", "ray://head:10001"])
    assert (args.framework, args.num_env_runners, args.address) == ("rllib", 3, "ray://head:10001")


def test_rllib_samples_in_the_driver_by_default():
    # On one machine the driver samples fastest (no episodes crossing processes every iteration;
    # measure with train.py --framework rllib --num-env-runners N); a cluster passes its own count.
    if importlib.util.find_spec("ray") is None:
        pytest.skip("needs the [rllib] extra")
    assert train.parse_args(["--framework", "rllib"]).num_env_runners == 0
