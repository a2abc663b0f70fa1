"""agents.caregivers.reading: the estimator tables, on a few episodes, at the level of the env they are read on."""

from __future__ import annotations

import json

import numpy as np
import pytest

from agents.caregivers.reading import ESTIMATORS, collect, main, summarise


@pytest.mark.parametrize("env_id", ["CoopGym/SitToStandHard-v2", "CoopGym/SitToStandHard-v1"])
def test_every_estimator_is_read_on_the_same_steps_and_summarised(env_id: str) -> None:
    data = collect("prober", 6, env_id)
    steps, envs = data["live"].shape
    assert envs == 6 and steps > 10
    assert set(np.unique(data["true_xi"][data["live"]])) <= {-1.0, 0.0, 1.0}
    for name in ESTIMATORS:
        assert data[name].shape == (steps, envs)
        assert np.all((data[f"p_up_{name}"] >= 0.0) & (data[f"p_up_{name}"] <= 1.0))
    summary = summarise(data)
    assert summary["steps"] == int(data["live"].sum())
    for name in ESTIMATORS:
        assert 0.0 <= summary[name]["balanced_accuracy"] <= 1.0
        assert 0.0 <= summary[name]["ece"] <= 1.0
        assert len(summary[name]["latency_accuracy"]) == len(summary["lags_s"])
        assert sum(row[3] for row in summary[name]["reliability"]) == summary["steps"]


@pytest.mark.parametrize(
    ("env_id", "level"), [("CoopGym/SitToStandHard-v2", "hard-v2"), ("CoopGym/SitToStand-v0", None)]
)
def test_the_level_of_the_env_sets_the_caregiver_and_the_true_person_filter(monkeypatch, env_id, level) -> None:
    import agents.caregivers.reading as reading

    seen: dict[str, object] = {}
    real_make, real_options = reading.make_scripted, reading.SwitchingOptions

    def make_scripted(policy, **kwargs):
        seen["caregiver"] = kwargs["level"]
        return real_make(policy, **kwargs)

    def switching_options(**kwargs):
        seen["filter"] = kwargs["difficulty"]
        return real_options(**kwargs)

    monkeypatch.setattr(reading, "make_scripted", make_scripted)
    monkeypatch.setattr(reading, "SwitchingOptions", switching_options)
    collect("prober", 2, env_id)
    assert seen == {"caregiver": level, "filter": level}


def test_command_line_writes_the_summary(tmp_path, capsys) -> None:
    out = tmp_path / "reading.json"
    assert main(["--episodes", "4", "--json-out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert printed.startswith("CoopGym/SitToStandHard-v2, prober cues, 4 episodes")
    assert set(json.loads(out.read_text())) >= {*ESTIMATORS, "steps", "lags_s"}
    with pytest.raises(SystemExit):
        main(["--episodes", "0"])


def test_a_lag_with_too_few_steps_is_left_out_of_the_latency_curve() -> None:
    from agents.caregivers.reading import MIN_STEPS_PER_LAG

    many, few = MIN_STEPS_PER_LAG, MIN_STEPS_PER_LAG - 1
    # Steps 0.1 s after a probe's onset (lag 0.0) and 0.6 s after (lag 0.5); every estimator right.
    age = np.r_[np.full(many, 0.1), np.full(few, 0.6)][:, None]
    truth = np.ones_like(age)
    data = {"live": np.ones(age.shape, dtype=bool), "true_xi": truth, "probe_age": age}
    for name in ESTIMATORS:
        data[name], data[f"p_up_{name}"] = truth, np.full(age.shape, 0.9)
    latency = summarise(data)["kalman"]["latency_accuracy"]
    assert latency[0] == 1.0
    assert np.isnan(latency[5])  # 99 steps: left out
