"""The one evaluation path: same seeded episodes for every agent, metrics, CLI, files."""

from __future__ import annotations

import dataclasses
import json
import shutil
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import coop_gym  # noqa: F401
from agents.caregivers.scripted import HandbookCaregiver, OracleAgent
from agents.evaluate import (
    OUTCOMES,
    TABLE_COLUMNS,
    EpisodeRecord,
    EvaluationResult,
    env_kwargs_for,
    evaluate,
    headroom,
    iqm_across_runs,
    results_json,
    table_rows,
    wilson_interval,
    write_csv,
)
from agents.tools.evaluate_cli import main


def test_wilson_interval_known_values():
    assert wilson_interval(0, 10) == pytest.approx((0.0, 0.2775), abs=1e-4)
    assert wilson_interval(10, 10) == pytest.approx((0.7225, 1.0), abs=1e-4)
    low, high = wilson_interval(30, 100)
    assert low == pytest.approx(0.2189, abs=1e-4) and high == pytest.approx(0.3958, abs=1e-4)
    assert wilson_interval(0, 0) == (0.0, 1.0)


def test_episode_k_is_the_env_seeded_seed_plus_k():
    result = evaluate("handbook", personas="test", episodes=12, seed=40, n_envs=5)
    assert [r.episode for r in result.records] == list(range(12))
    assert [r.seed for r in result.records] == list(range(40, 52))
    env = gym.make("CoopGym/SitToStand-v0", personas=["frail", "forgetful"])
    assert [r.persona for r in result.records] == [env.reset(seed=40 + k)[1]["persona"] for k in range(12)]
    assert sum(result.count(o) for o in OUTCOMES) == 12


def test_same_episodes_whatever_the_agent_or_batch():
    a = evaluate("handbook", personas="all", episodes=14, seed=3, n_envs=1)
    b = evaluate("handbook", personas="all", episodes=14, seed=3, n_envs=6)
    assert a.records == b.records  # n_envs only changes speed
    oracle = evaluate("oracle", personas="all", episodes=14, seed=3, n_envs=4)
    assert [r.persona for r in oracle.records] == [r.persona for r in a.records]
    assert oracle.env_kwargs["observation_mode"] == "oracle"


def test_oracle_variant_plays_the_same_episodes():
    """The oracle's env differs only in what it observes: same seed and actions, same person and truth."""
    belief = gym.make("CoopGym/SitToStand-v0", personas="test")
    oracle = gym.make("CoopGym/SitToStand-v0", personas="test", observation_mode="oracle")
    rng = np.random.default_rng(0)
    for seed in range(3):
        b_obs, b_info = belief.reset(seed=seed)
        o_obs, o_info = oracle.reset(seed=seed)
        assert b_info["persona"] == o_info["persona"] and b_info["true_xi"] == o_info["true_xi"]
        for _ in range(40):
            action = [int(rng.integers(3)), int(rng.integers(3)), 0]
            b_obs, _, _, _, b_info = belief.step(action)
            o_obs, _, _, _, o_info = oracle.step(action)
            assert np.array_equal(b_obs, o_obs[:-1]) and o_obs[-1] == o_info["true_xi"]
            assert b_info["true_x_m"] == o_info["true_x_m"] and b_info["true_xi"] == o_info["true_xi"]


def test_vector_and_single_env_backends_agree():
    for name in ("handbook", "push_then_lift"):
        single = evaluate(name, personas="test", episodes=20, seed=5, n_envs=8, backend="single")
        vector = evaluate(name, personas="test", episodes=20, seed=5, n_envs=8, backend="vector")
        assert vector.backend == "vector" and single.backend == "single"
        assert single.records == vector.records


def test_metrics_of_known_agents():
    lift = evaluate("lift_at_once", personas="test", episodes=10, seed=0)
    assert lift.unsafe_rate == 1.0 and lift.mean_time_to_lift_s == 0.0 and lift.mean_cues == 0.0
    assert lift.mean_return == pytest.approx(-2.0) and lift.std_return == pytest.approx(0.0)
    hb = evaluate("handbook", personas="test", episodes=10, seed=0)
    assert hb.success_rate >= 0.9 and hb.unsafe_rate == 0.0
    assert hb.peak_force_n == pytest.approx(10.0)  # gentle pushes only
    assert 0.0 < hb.mean_force_n < 10.0 and hb.mean_cues >= 2  # an explanation and a push at least
    assert hb.mean_time_to_lift_s > 1.0
    summary = hb.summary()
    for key in ("success_rate", "unsafe_rate", "premature_rate", "timeout_rate", "mean_return", "mean_time_to_lift_s"):
        assert key in summary
    json.dumps(summary)
    split = hb.by_persona()
    assert sum(s.episodes for s in split.values()) == 10 and set(split) <= {"frail", "forgetful"}


def test_records_match_a_hand_rollout():
    result = evaluate("handbook", personas="typical", episodes=1, seed=7)
    env = gym.make("CoopGym/SitToStand-v0", personas="typical")
    agent = HandbookCaregiver.for_env(env)
    obs, _ = env.reset(seed=7)
    total, steps, forces = 0.0, 0, []
    while True:
        action, _ = agent.predict(obs)
        obs, reward, terminated, truncated, info = env.step(action)
        total += reward
        steps += 1
        forces.append(info["push_force_n"])
        if terminated or truncated:
            break
    record = result.records[0]
    assert record.outcome == info["outcome"] and record.steps == steps
    assert record.episode_return == pytest.approx(total)
    assert record.peak_force_n == max(forces)
    assert record.duration_s == pytest.approx(info["elapsed_s"])


def _hand_return(env_id: str, personas: str, seed: int) -> float:
    env = gym.make(env_id, personas=personas)
    agent = HandbookCaregiver.for_env(env)
    obs, _ = env.reset(seed=seed)
    total, done = 0.0, False
    while not done:
        obs, reward, terminated, truncated, _ = env.step(agent.predict(obs)[0])
        total, done = total + float(reward), terminated or truncated
    return total


def test_train_wide_plays_the_wider_spread_not_just_the_names():
    """``personas="train_wide"`` is the training personas with a wider spread, as the env plays it."""
    env_id = "CoopGym/SitToStandHard-v1"
    wide = evaluate("handbook", env_id, "train_wide", episodes=24, seed=5, n_envs=8)
    narrow = evaluate("handbook", env_id, "train", episodes=24, seed=5, n_envs=8)
    assert wide.personas == narrow.personas  # the same names ...
    assert [r.episode_return for r in wide.records] != [r.episode_return for r in narrow.records]  # ... other people
    for k in range(3):
        assert wide.records[k].episode_return == pytest.approx(_hand_return(env_id, "train_wide", 5 + k))


def test_agent_objects_and_mismatches():
    env = gym.make("CoopGym/SitToStandOracle-v0")
    oracle = OracleAgent.for_env(env)
    result = evaluate(oracle, personas="test", episodes=4, env_kwargs={"observation_mode": "oracle"}, name="o")
    assert result.agent == "o" and result.success_rate == 1.0
    with pytest.raises(ValueError, match="features"):
        evaluate(oracle, personas="test", episodes=2)  # belief env: no true_xi column
    with pytest.raises(ValueError, match="unknown agent"):
        evaluate("nurse", episodes=2)
    with pytest.raises(ValueError, match="episodes"):
        evaluate("handbook", episodes=0)
    with pytest.raises(ValueError, match="persona"):
        evaluate("handbook", personas="grumpy", episodes=2)
    assert env_kwargs_for("handbook", "CoopGym/SitToStandRaw-v0") == {"observation_mode": "belief"}
    assert env_kwargs_for("handbook", "CoopGym/SitToStand-v0") == {}


def test_cli_json_has_the_keys(capsys):
    assert main(["--agent", "handbook", "--episodes", "6", "--json", "--personas", "frail"]) == 0
    payload = json.loads(capsys.readouterr().out)
    for key in ("success_rate", "unsafe_rate", "premature_rate", "timeout_rate", "mean_return", "mean_time_to_lift_s"):
        assert key in payload
    assert payload["episodes"] == 6 and payload["personas"] == ["frail"]


def test_cli_compare_writes_csv_json_and_plot(tmp_path, capsys):
    csv_path, plot_path, json_path = tmp_path / "r.csv", tmp_path / "r.png", tmp_path / "r.json"
    argv = ["--compare", "lift_at_once,handbook,oracle", "--episodes", "5", "--csv", str(csv_path)]
    argv += ["--plot", str(plot_path), "--json-out", str(json_path), "--by-persona"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "handbook" in out and "oracle" in out and "by persona" in out
    lines = csv_path.read_text().splitlines()
    assert len(lines) == 4 and lines[0].startswith("agent,")
    assert plot_path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    saved = json.loads(json_path.read_text())
    assert [r["agent"] for r in saved["results"]] == ["lift_at_once", "handbook", "oracle"]
    assert len(saved["results"][0]["episode_records"]) == 5


@pytest.mark.parametrize(
    "argv",
    [
        [],
        ["--agent", "nurse"],
        ["--agent", "handbook", "--episodes", "0"],
        ["--agent", "handbook", "--personas", "grumpy"],
        ["--agent", "handbook", "--env", "CoopGym/Nope-v0"],
        ["--agent", "handbook", "--seed", "-1"],
        ["--agent", "handbook", "--episodes", "many"],
    ],
)
def test_cli_usage_errors_exit_2(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    assert "error" in capsys.readouterr().err


def test_cli_subprocess_json_and_bad_flag():
    ok = subprocess.run(
        [sys.executable, "-m", "agents.evaluate", "--agent", "oracle", "--episodes", "3", "--json"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert ok.returncode == 0, ok.stderr
    assert json.loads(ok.stdout)["success_rate"] == 1.0
    bad = subprocess.run(
        [sys.executable, "-m", "agents.evaluate", "--agent", "handbook", "--bogus"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert bad.returncode == 2 and "--bogus" in bad.stderr


def test_write_csv_and_empty_rates(tmp_path):
    record = EpisodeRecord(0, 0, "frail", "timeout", -0.4, 300, 30.0, 0.0, 0.0, 0.0, 0, 0)
    result = EvaluationResult("idle", "CoopGym/SitToStand-v0", ("frail",), 0, (record,))
    assert result.timeout_rate == 1.0 and np.isnan(result.mean_time_to_lift_s)
    assert result.summary()["mean_time_to_lift_s"] is None
    path = write_csv([result], tmp_path / "x.csv")
    assert "timeout_rate" in path.read_text().splitlines()[0]
    with pytest.raises(ValueError, match="outcome"):
        result.rate("crashed")


def test_cli_unwritable_output_exits_2_before_the_work(tmp_path, capsys):
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    for flag in ("--csv", "--json-out", "--plot"):
        with pytest.raises(SystemExit) as exc:
            main(["--agent", "handbook", flag, str(blocker / "sub" / "out.x")])
        assert exc.value.code == 2
        assert "a_file is not a folder" in capsys.readouterr().err


# --- the mind-reading score ----------------------------------------------------------


def _result(name: str, successes: int, n: int = 40, first_seed: int = 0) -> EvaluationResult:
    records = tuple(
        EpisodeRecord(
            k, first_seed + k, "typical", "success" if k < successes else "premature", 0.0, 1, 1.0, 0, 0, 0, 0, 0
        )
        for k in range(n)
    )
    return EvaluationResult(name, "CoopGym/SitToStandHard-v1", ("typical",), first_seed, records)


def test_mind_reading_score_is_0_for_blind_1_for_the_oracle_and_between_for_a_reader():
    room = headroom([_result("oracle", 40), _result("blind", 20), _result("prober", 30), _result("handbook", 16)])
    assert room is not None
    scores = {s.agent: s for s in room.scores}
    assert scores["oracle"].score == pytest.approx(1.0) and scores["blind"].score == pytest.approx(0.0)
    assert scores["prober"].score == pytest.approx(0.5)  # (0.75 - 0.5) / (1.0 - 0.5)
    assert scores["handbook"].score == pytest.approx(-0.2)  # worse than ignoring the mind
    low, high = scores["prober"].ci95
    assert low < 0.5 < high and 0.0 <= low and high <= 1.0  # a paired bootstrap interval around the point
    assert room.value_ci95[0] <= room.value_of_reading_the_mind <= room.value_ci95[1]
    assert any("mind-reading score" in line and "prober 0.50" in line for line in room.lines())


def test_no_score_without_the_same_episodes_or_without_anchors():
    assert headroom([_result("oracle", 40), _result("blind", 20, first_seed=1000)]) is None  # different seeds
    assert headroom([_result("prober", 30), _result("blind", 20)]) is None  # no oracle
    room = headroom([_result("oracle", 20), _result("blind", 20), _result("prober", 10)])
    assert room is not None and np.isnan(room.score_of("prober").score)  # nothing to read: undefined


def test_a_human_row_is_scored_on_its_own_episodes_and_is_never_the_best_reader():
    # The person played seeds 0, 1, 2 and 30 (first_seed 0, 40 anchors' episodes) and succeeded in all.
    human = _result("human", 4, n=4)
    human = dataclasses.replace(human, records=(*human.records[:3], dataclasses.replace(human.records[3], seed=30)))
    room = headroom([_result("oracle", 40), _result("blind", 20), _result("prober", 30), human])
    assert room is not None and room.best_reader_agent == "prober"  # not the human's 100 %
    # Blind succeeds in 3 of the 4 seeds (0-2, not 30), the oracle in 4: the human scores 1.
    assert room.score_of("human").score == pytest.approx(1.0)
    assert any(line.startswith("human: mind-reading score 1.00") for line in room.lines())
    # Seeds the comparison did not play (or another persona set): no score, the rest unchanged.
    elsewhere = _result("human", 4, n=4, first_seed=500)
    room = headroom([_result("oracle", 40), _result("blind", 20), elsewhere])
    assert room is not None and room.best_reader_agent == "blind" and np.isnan(room.score_of("human").score)


def test_table_csv_and_json_carry_the_score(tmp_path):
    results = [_result("prober", 30), _result("blind", 20), _result("oracle", 40)]
    assert TABLE_COLUMNS[6] == "mind-reading [95% CI]"
    assert table_rows(results, headroom(results))[0][6].startswith("0.50 [")
    header, first, *_ = write_csv(results, tmp_path / "c.csv").read_text().splitlines()
    column = header.split(",").index("mind_reading_score")
    assert float(first.split(",")[column]) == pytest.approx(0.5)
    payload = results_json(results)
    assert payload["results"][0]["mind_reading_score"] == pytest.approx(0.5)
    assert payload["headroom"]["mind_reading_score"]["prober"]["score"] == pytest.approx(0.5)
    json.dumps(payload)


def test_iqm_across_seeds_is_rliables_stratified_bootstrap():
    scores = {"hard": [0.2, 0.8, 0.85, 0.9, 1.5], "medium": [0.6, 0.7, 0.75]}
    agg = iqm_across_runs(scores)
    pooled = np.sort(np.concatenate([np.array(v) for v in scores.values()]))
    assert agg.iqm == pytest.approx(np.mean(pooled[2:6]))  # the middle half of the 8 pooled scores
    assert agg.ci95[0] <= agg.iqm <= agg.ci95[1] and agg.runs == {"hard": 5, "medium": 3}
    one = iqm_across_runs({"hard": [0.8]})
    assert one.iqm == pytest.approx(0.8) and np.isnan(one.ci95[0])  # nothing to resample
    with pytest.raises(ValueError, match="no finite"):
        iqm_across_runs({"hard": [float("nan")]})


def _write_run(parent: Path, seed: int, score: float | None, episodes: int = 1000) -> Path:
    """A run folder as train.py leaves it scored (results.json; no COMPLETE marker, as older runs)."""
    run = parent / f"CoopGym-SitToStandHard-v1__ppo__{seed}__0"
    run.mkdir(parents=True)
    results = {
        "algo": "ppo",
        "env_id": "CoopGym/SitToStandHard-v1",
        "evaluation": {
            "personas": "test",
            "episodes": episodes,
            "seed": 0,
            "results": [{"mind_reading_score": score}],
        },
    }
    (run / "results.json").write_text(json.dumps(results))
    return run


def test_cli_runs_reports_the_iqm_across_training_runs(tmp_path, capsys):
    for seed, score in enumerate([0.7, 0.8, 0.9]):
        _write_run(tmp_path, seed, score)
    assert main(["--runs", str(tmp_path), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)["sb3:ppo"]
    assert report["iqm"] == pytest.approx(0.8) and report["runs"] == {"CoopGym/SitToStandHard-v1": 3}
    with pytest.raises(SystemExit):
        main(["--runs", str(tmp_path / "nothing")])


def _usage_error(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    """The one error line of a command line that must exit 2 before printing any result."""
    with pytest.raises(SystemExit) as exc:
        main(argv)
    out, err = capsys.readouterr()
    assert exc.value.code == 2 and out == ""
    lines = [line for line in err.splitlines() if "error" in line]
    assert len(lines) == 1, err
    return lines[0]


def _interrupted(run: Path) -> None:
    (run / "results.json").unlink()
    (run / "args.json").write_text("{}")
    (run / "INTERRUPTED").write_text("stopped by SIGTERM; resume with python train.py --resume RUN")


def _truncated(run: Path) -> None:
    (run / "results.json").write_text((run / "results.json").read_text()[:40])
    (run / "COMPLETE").write_text("")


def _missing(run: Path) -> None:
    (run / "results.json").unlink()
    (run / "args.json").write_text("{}")


def _scoreless(run: Path) -> None:
    (run / "results.json").write_text((run / "results.json").read_text().replace("0.5", "null"))


@pytest.mark.parametrize(
    ("damage", "why"),
    [
        (_interrupted, "interrupted, not finished"),
        (_truncated, "results.json is not valid JSON"),
        (_missing, "no results.json and no COMPLETE marker: not finished"),
        (_scoreless, "results.json holds no mind-reading score"),
    ],
)
def test_cli_runs_refuses_a_run_without_a_score_naming_it(tmp_path, capsys, damage, why):
    good = _write_run(tmp_path / "out", 0, 0.8)
    bad = _write_run(tmp_path / "out", 1, 0.5)
    damage(bad)
    for argv in (["--runs", str(good), str(bad)], ["--runs", str(tmp_path / "out")]):
        line = _usage_error(argv, capsys)  # never an IQM "over 1 run"
        assert f"--runs: {bad}: {why}" in line, line


def test_cli_runs_refuses_a_run_counted_twice_or_runs_scored_on_other_episodes(tmp_path, capsys):
    good = _write_run(tmp_path / "out", 0, 0.8)
    _write_run(tmp_path / "out", 1, 0.7)
    assert f"--runs: {good} is given twice" in _usage_error(["--runs", str(tmp_path / "out"), str(good)], capsys)
    other = _write_run(tmp_path / "elsewhere", 2, 0.9, episodes=200)
    line = _usage_error(["--runs", str(good), str(other)], capsys)
    assert "the sb3:ppo runs were scored on different episodes" in line and str(other) in line, line
    no_runs = tmp_path / "empty"
    no_runs.mkdir()
    assert "is neither a train.py run folder nor a folder of them" in _usage_error(["--runs", str(no_runs)], capsys)


def test_cli_compare_names_two_models_of_one_file_name_apart(tmp_path, capsys):
    from agents.pretrained import pretrained_model_path

    full, other = tmp_path / "a" / "seed.zip", tmp_path / "b" / "seed.zip"
    for path in (full, other):
        path.parent.mkdir()
        shutil.copyfile(pretrained_model_path("hard-v2-ppo"), path)
    assert main(["--compare", f"{full},{other},blind,oracle", "--episodes", "2", "--json"]) == 0
    payload = json.loads(capsys.readouterr().out)
    labels = [f"ppo:{full}", f"ppo:{other}", "blind", "oracle"]  # not "ppo:seed" twice
    assert [r["agent"] for r in payload["results"]] == labels
    assert list(payload["headroom"]["mind_reading_score"]) == labels  # no score overwrote another
    line = _usage_error(["--model", str(full), "--compare", f"blind,{tmp_path}/a/../a/seed.zip"], capsys)
    assert f"'{full}' and '{tmp_path}/a/../a/seed.zip' are one model" in line and "list each agent once" in line
    assert "'blind' is given twice" in _usage_error(["--compare", "blind,oracle,blind"], capsys)


def test_cli_human_csv_of_several_envs_needs_env(tmp_path, capsys, monkeypatch):
    from agents.tools.play_log import PlayedEpisode, append_played

    csv_path = tmp_path / "played.csv"
    for env_id in ("CoopGym/SitToStandHard-v2", "CoopGym/SitToStand-v0"):
        append_played(csv_path, PlayedEpisode(env_id, 1, "test", "frail", "unsafe", 0.1, -10.0, ((2, 0, 1),)))
    monkeypatch.setattr("agents.tools.evaluate_cli.evaluate", None)  # the error comes before any episode is played
    for agents in ([], ["--compare", "blind,oracle"]):
        line = _usage_error([*agents, "--human", str(csv_path)], capsys)  # not the default env's row alone
        expected = "holds episodes of 2 env ids (CoopGym/SitToStand-v0, CoopGym/SitToStandHard-v2): give --env ID"
        assert f"--human: {csv_path} {expected}" in line, line


def test_selection_study_keeps_each_rules_best_and_correlates_it_with_the_target():
    """Per rule: the kept policy (ties to the later), r over runs, and the better run of each pair."""
    from agents.evaluate.headroom import selection_study

    def point(step, train, validation, test):
        rates = {"train": train, "validation": validation, "test": test}
        return {"timesteps": step, **{k: {"success_rate": v, "unsafe_rate": 0.0} for k, v in rates.items()}}

    runs = [
        [point(1, 0.9, 0.5, 0.6), point(2, 0.8, 0.7, 0.8)],
        [point(1, 0.7, 0.6, 0.7), point(2, 0.7, 0.6, 0.75)],
        [point(1, 0.95, 0.4, 0.5), point(2, 0.6, 0.8, 0.9)],
        [point(1, 0.85, 0.65, 0.7), point(2, 0.5, 0.3, 0.4)],
    ]
    study = selection_study(runs, ("train", "validation"))
    assert study["train"]["kept_timesteps"] == [1, 2, 1, 1]  # run 2 ties: the later
    assert study["train"]["kept_target_success"] == [0.6, 0.75, 0.5, 0.7]
    assert study["validation"]["kept_target_success"] == [0.8, 0.75, 0.9, 0.7]
    assert study["validation"]["pearson_r"] > 0.8 > study["train"]["pearson_r"]
    assert study["validation"]["best_of_pairs_target_success"] == [0.9, 0.7]  # runs (0, 2) and (1, 3)
    with pytest.raises(ValueError, match="selection_study needs >= 3 runs"):
        selection_study(runs[:2], ("train",))


def test_persona_rates_split_an_evaluation_and_average_over_runs():
    """Each persona's rates weigh back to the whole; over runs, the mean and the range of each persona's success."""
    from agents.evaluate.results import persona_rates_over_runs

    result = evaluate("blind", env_id="CoopGym/SitToStandHard-v2", personas="test", episodes=40, seed=0)
    rates = result.persona_rates()
    assert set(rates) == {"frail", "forgetful"} and sum(r["episodes"] for r in rates.values()) == 40
    for outcome in OUTCOMES:
        whole = sum(r["episodes"] * r[f"{outcome}_rate"] for r in rates.values()) / 40
        assert whole == pytest.approx(result.rate(outcome))
    other = {p: {**r, "success_rate": r["success_rate"] / 2} for p, r in rates.items()}
    over = persona_rates_over_runs([rates, other])
    frail = rates["frail"]["success_rate"]
    assert over["frail"]["success_rate"] == pytest.approx(0.75 * frail)
    assert over["frail"]["success_rate_range"] == [frail / 2, frail]
    assert over["frail"]["unsafe_rate"] == pytest.approx(rates["frail"]["unsafe_rate"])
