"""The paper's experiment as a protocol: determinism, tables, CLI, figures and the estimator comparison."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from coop_gym.envs.core import nominal_model_for
from coop_gym.experiment import calibrate, protocol
from coop_gym.experiment.protocol import (
    PAPER_RESULTS,
    ProtocolConfig,
    TrialSpec,
    balanced_accuracy,
    confusion_matrix,
    estimate,
    run_experiment,
    run_protocol,
)
from coop_gym.model.personas import PERSONAS
from estimator import metrics
from estimator.judgment import JUDGMENT_COLUMNS, judgment_substep
from estimator.kalman import PaperKalmanFilter
from estimator.nominal import NominalModel

SMALL = ProtocolConfig(n_subjects=2, n_trials=9)


@pytest.fixture(scope="module")
def small_data() -> protocol.ExperimentData:
    return run_experiment(SMALL, seed=3)


# --------------------------------------------------------------------------- the paper's numbers


def test_paper_table_reproduces_every_number_stated_in_the_text() -> None:
    m = PAPER_RESULTS.matrix
    assert m.sum() == 100
    # Requested: 32 uncooperative, 24 unresponsive, 44 cooperative.
    assert m.sum(axis=1).tolist() == [32, 24, 44]
    given_req, given_est = protocol.conditional_tables(m)
    assert np.diag(given_req).round(3).tolist() == [0.344, 0.792, 0.523]
    assert given_est[2, 2] == pytest.approx(0.92)  # 23 / 25
    assert given_est[0, 0] == pytest.approx(0.6875)  # 11 / 16
    assert PAPER_RESULTS.accuracy == pytest.approx(0.53)
    # Uncooperative trials were most often judged unresponsive.
    assert m[0].argmax() == 1


def test_scores_on_a_hand_made_table() -> None:
    conf = confusion_matrix([-1, -1, 0, 1, 1, 1], [-1, 0, 0, 1, 1, 0])
    assert conf.tolist() == [[1, 1, 0], [0, 1, 0], [0, 1, 2]]
    assert protocol.accuracy(conf) == pytest.approx(4 / 6)
    assert balanced_accuracy(conf) == pytest.approx((0.5 + 1.0 + 2 / 3) / 3)
    with pytest.raises(ValueError, match="-1, 0 or 1"):
        confusion_matrix([2], [0])


def test_summary_scores_use_the_shared_metrics(small_data: protocol.ExperimentData) -> None:
    result = estimate(small_data, "persona_bank")
    summary = protocol.summarize(small_data, result)
    probs, labels = result.probabilities.reshape(-1, 3), small_data.requested.ravel()
    assert summary["log_loss"] == pytest.approx(metrics.log_loss(probs, labels))
    assert summary["brier"] == pytest.approx(metrics.brier_score(probs, labels))
    assert summary["ece"] == pytest.approx(metrics.expected_calibration_error(probs, labels))
    assert summary["log_loss"] < np.log(3)  # better than guessing on this data


def test_gaussian_mapping_of_the_kf_is_a_distribution_centred_on_its_mean() -> None:
    p = protocol.gaussian_xi_probabilities(np.array([-1.0, 0.0, 0.9]), np.array([0.1, 0.1, 0.1]))
    assert np.allclose(p.sum(axis=-1), 1.0)
    assert p.argmax(axis=-1).tolist() == [0, 1, 2]


# --------------------------------------------------------------------------- trials


def test_trial_cues_follow_the_relative_timing() -> None:
    cfg = ProtocolConfig()
    dt = cfg.timing.dt_s
    push, verbal = TrialSpec(1, "hard", "back", relative_timing_s=2).cues(cfg)
    push_on = np.flatnonzero(push > 0)
    verbal_on = np.flatnonzero(verbal != 0)
    assert push_on[0] == cfg.onset_step and push.max() == cfg.cues.firm_push_n
    assert verbal_on[0] == cfg.onset_step + round(2 / dt) and verbal.min() == -1.0
    assert len(push_on) == round(cfg.physical_duration_s / dt)
    assert len(verbal_on) == round(cfg.cues.verbal_duration_s / dt)
    # Negative timing: the verbal cue comes first, the push 3 s later.
    push, verbal = TrialSpec(0, "soft", "forward", relative_timing_s=-3).cues(cfg)
    assert np.flatnonzero(verbal)[0] == cfg.onset_step
    assert np.flatnonzero(push)[0] == cfg.onset_step + round(3 / dt)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"requested_xi": 2, "physical_cue": "soft", "verbal_cue": "none"}, "requested_xi"),
        ({"requested_xi": 0, "physical_cue": "medium", "verbal_cue": "none"}, "physical_cue"),
        ({"requested_xi": 0, "physical_cue": "none", "verbal_cue": "none"}, "at least one cue"),
        ({"requested_xi": 0, "physical_cue": "soft", "verbal_cue": "none", "relative_timing_s": 2}, "both cues"),
        ({"requested_xi": 0, "physical_cue": "soft", "verbal_cue": "back", "relative_timing_s": 7}, "relative"),
    ],
)
def test_bad_trial_specs_are_rejected(kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        TrialSpec(**kwargs)


def test_bad_configs_are_rejected() -> None:
    with pytest.raises(ValueError, match="n_subjects"):
        ProtocolConfig(n_subjects=0)
    with pytest.raises(ValueError, match="requested_mix"):
        ProtocolConfig(requested_mix="mostly")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="persona"):
        ProtocolConfig(personas="nobody")
    with pytest.raises(ValueError, match="unknown difficulty 'harder'"):
        ProtocolConfig(difficulty="harder")
    with pytest.raises(ValueError, match="seed"):
        run_experiment(SMALL, seed=-1)


def test_paper_mix_requests_the_papers_proportions() -> None:
    trials = protocol.draw_trials(ProtocolConfig(), np.random.default_rng(0))
    counts = [sum(t.requested_xi == xi for t in trials) for xi in (-1, 0, 1)]
    assert counts == [8, 6, 11]  # 32 / 24 / 44 of 100, four subjects


def test_judgment_lands_on_the_environments_tracker_step(small_data: protocol.ExperimentData) -> None:
    cfg = small_data.config
    for k in range(len(small_data.trials)):
        row = np.zeros(len(JUDGMENT_COLUMNS))
        row[0] = cfg.timing.episode_s
        fired = [
            t
            for t in range(cfg.n_steps)
            if judgment_substep(
                row,
                bool(small_data.push_force_n[k, t] > 0 or small_data.verbal_cue[k, t] != 0),
                0.0,
                cfg.judgment.delay_s,
                cfg.judgment.threshold,
                cfg.timing.dt_s,
            )
        ]
        assert fired[0] == small_data.judgment_step[k]
    delay = (small_data.judgment_step - cfg.onset_step) * cfg.timing.dt_s
    assert np.allclose(delay, 0.74)  # 37 steps: the tracker's half-step slack on 0.75 s


# --------------------------------------------------------------------------- the experiment


def test_requested_xi_is_held_for_the_whole_trial(small_data: protocol.ExperimentData) -> None:
    xi = small_data.true_state[..., 3]
    assert np.array_equal(xi, np.broadcast_to(small_data.requested[..., None], xi.shape))
    assert set(np.unique(small_data.requested)) <= {-1, 0, 1}


def test_every_subject_gets_the_same_trials_but_its_own_responses(small_data: protocol.ExperimentData) -> None:
    assert small_data.measured_position_m.shape == (2, 9, SMALL.n_steps)
    assert not np.allclose(small_data.measured_position_m[0], small_data.measured_position_m[1])
    # The persona's typical gains, varied per subject.
    for persona, person in zip(small_data.personas, small_data.subjects, strict=True):
        assert person.biomechanics.push_compliance_m_per_s2_n != persona.params.biomechanics.push_compliance_m_per_s2_n


def test_protocol_is_deterministic_per_seed() -> None:
    a = run_protocol(SMALL, seed=11)
    b = run_protocol(SMALL, seed=11)
    assert a == b
    data_a, data_b = run_experiment(SMALL, 11), run_experiment(SMALL, 12)
    assert not np.array_equal(data_a.measured_position_m, data_b.measured_position_m)
    # Asking for the calibration session does not change the test data.
    data_c = run_experiment(SMALL, 11, with_calibration=True)
    assert np.array_equal(data_a.measured_position_m, data_c.measured_position_m)
    assert data_c.calibration is not None and len(data_c.calibration) == SMALL.n_subjects


def test_protocol_kf_is_the_paper_filter_on_measured_force(small_data: protocol.ExperimentData) -> None:
    """The batched KF inside the protocol equals filterpy's filter fed the same measurements."""
    result = estimate(small_data, "kalman")
    s, k = 1, 4
    model = nominal_model_for(small_data.personas[s].params, small_data.config.timing)
    kf = PaperKalmanFilter(model, first_position_m=small_data.measured_position_m[s, k, 0])
    xs = [
        kf.step(f, v, y)[3]
        for f, v, y in zip(
            small_data.measured_force_n[s, k],
            small_data.verbal_cue[k],
            small_data.measured_position_m[s, k],
            strict=True,
        )
    ]
    assert np.allclose(result.xi_trace[s, k], xs, atol=1e-9)
    step = small_data.judgment_step[k]
    assert result.judgment[s, k] == small_data.config.judgment.judge(xs[step])


def test_intention_drive_is_the_delayed_cue_input() -> None:
    model = NominalModel()
    force = np.zeros((1, 50))
    force[0, 10:20] = 10.0
    verbal = np.zeros((1, 50))
    verbal[0, 30:35] = 1.0
    drive = protocol.intention_drive(force, verbal, model, delay_s=0.1, touch_threshold_n=2.0)
    expected = np.zeros(50)
    expected[15:25] = model.push_gain_m_per_s_n * 10.0
    expected[35:40] = model.verbal_gain_m_per_s
    assert np.allclose(drive[0], expected)


@pytest.mark.parametrize(
    "name", ["kalman", "multiple_model", "imm", "delay_aware", "persona_bank", "switching", "oracle"]
)
def test_every_estimator_gives_judgments_and_distributions(small_data: protocol.ExperimentData, name: str) -> None:
    result = estimate(small_data, name)
    assert result.judgment.shape == (2, 9)
    assert set(np.unique(result.judgment)) <= {-1, 0, 1}
    assert np.allclose(result.probabilities.sum(axis=-1), 1.0)
    assert np.all(result.latency_s <= small_data.config.judgment.delay_s + 1e-9)


def test_sequential_decisions_are_never_later_than_the_paper(small_data: protocol.ExperimentData) -> None:
    late = estimate(small_data, "persona_bank")
    early = estimate(small_data, "persona_bank", decision="sequential", error_rate=0.2)
    assert np.all(early.latency_s <= late.latency_s + 1e-12)
    assert early.latency_s.mean() < late.latency_s.mean()


def test_bank_estimators_need_their_inputs(small_data: protocol.ExperimentData) -> None:
    with pytest.raises(ValueError, match="with_calibration"):
        estimate(small_data, "calibrated")
    with pytest.raises(ValueError, match="unknown estimator"):
        estimate(small_data, "crystal_ball")
    with pytest.raises(ValueError, match="3 models"):
        estimate(small_data, "persona_bank", banks=[()])


def test_multiple_model_estimators_beat_the_thresholded_kf() -> None:
    """On the calibrated defaults, per seed and on average (paired, same trials)."""
    seeds = range(4)
    ba: dict[str, list[float]] = {"kalman": [], "delay_aware": [], "persona_bank": []}
    for seed in seeds:
        data = run_experiment(ProtocolConfig(), seed)
        for name in ba:
            ba[name].append(balanced_accuracy(confusion_matrix(data.requested, estimate(data, name).judgment)))
    kf = np.array(ba["kalman"])
    for name in ("delay_aware", "persona_bank"):
        gain = np.array(ba[name]) - kf
        assert gain.mean() > 0.03, (name, gain)
    assert np.all(np.array(ba["persona_bank"]) > kf)


def test_calibrated_and_identified_estimators_run_from_the_calibration_session() -> None:
    cfg = dataclasses.replace(SMALL, n_subjects=1, calibration_trials=6)
    data = run_experiment(cfg, seed=5, with_calibration=True)
    result = estimate(data, "calibrated")
    assert np.allclose(result.probabilities.sum(axis=-1), 1.0)
    theta = protocol.fit_recalibration(np.array([[0.0, -5.0, -5.0], [-5.0, 0.0, -5.0]]), np.array([-1, 0]))
    assert np.all(np.isfinite(theta))


@pytest.mark.slow
def test_identified_banks_fit_each_subject_and_mode() -> None:
    cfg = dataclasses.replace(SMALL, n_subjects=1, calibration_trials=9)
    data = run_experiment(cfg, seed=5, with_calibration=True)
    banks = protocol.identified_banks(data)
    assert len(banks) == 1 and len(banks[0]) == 3
    result = estimate(data, "identified", banks=banks)
    assert set(np.unique(result.judgment)) <= {-1, 0, 1}


# --------------------------------------------------------------------------- command line and figures


def test_cli_json_has_the_tables_and_counts_every_trial(capsys: pytest.CaptureFixture[str]) -> None:
    assert protocol.main(["--subjects", "2", "--trials", "7", "--seed", "4", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    for key in ("confusion", "accuracy", "balanced_accuracy", "p_estimated_given_requested", "log_loss", "paper"):
        assert key in out
    assert np.array(out["confusion"]).shape == (3, 3)
    assert np.array(out["confusion"]).sum() == 2 * 7
    assert 0.0 <= out["balanced_accuracy"] <= 1.0


def test_cli_over_seeds_reports_spread(capsys: pytest.CaptureFixture[str]) -> None:
    assert protocol.main(["--subjects", "1", "--trials", "6", "--seeds", "3", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["seeds"] == [0, 1, 2]
    assert np.array(out["confusion"]).sum() == 3 * 6
    assert out["balanced_accuracy_std"] >= 0.0
    assert protocol.main(["--subjects", "1", "--trials", "6", "--seeds", "2"]) == 0
    text = capsys.readouterr().out
    assert "+/-" in text and "Table III" in text


def test_cli_prints_the_three_tables_beside_the_paper(capsys: pytest.CaptureFixture[str]) -> None:
    assert protocol.main(["--subjects", "1", "--trials", "6"]) == 0
    text = capsys.readouterr().out
    for title in ("Table I", "Table II", "Table III", "balanced accuracy", "paper"):
        assert title in text
    assert "52.3%" in text  # the paper's cooperative correct rate, printed beside ours


def test_cli_writes_the_figures(tmp_path, capsys: pytest.CaptureFixture[str]) -> None:
    trace, conf = tmp_path / "fig6.png", tmp_path / "confusion.png"
    args = ["--subjects", "1", "--trials", "6", "--plot", str(trace), "--plot-confusion", str(conf)]
    assert protocol.main([*args, "--estimator", "persona_bank"]) == 0
    capsys.readouterr()
    for path in (trace, conf):
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert path.stat().st_size > 10_000


@pytest.mark.parametrize(
    "args",
    [
        ["--subjects", "0"],
        ["--trials", "abc"],
        ["--seed", "-1"],
        ["--seeds", "0"],
        ["--estimator", "crystal_ball"],
        ["--personas", "nobody"],
        ["--plot", "trace.txt"],
        ["--decision", "guess"],
        ["--unknown-flag"],
    ],
)
def test_cli_usage_errors_exit_2(args: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        protocol.main(args)
    assert info.value.code == 2
    assert "usage" in capsys.readouterr().err


def test_calibration_report_runs_and_rejects_bad_arguments(capsys: pytest.CaptureFixture[str]) -> None:
    assert calibrate.main(["--seeds", "1", "--estimators", "kalman,delay_aware", "--no-sweep", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out["estimators"]) >= {"kalman", "delay_aware", "delay_aware+early"}
    assert np.array(out["estimators"]["kalman"]["confusion"]).sum() == 100
    for bad in (["--seeds", "0"], ["--estimators", "nope"]):
        with pytest.raises(SystemExit) as info:
            calibrate.main(bad)
        assert info.value.code == 2


def test_subjects_at_a_level_have_its_people_and_the_switching_filter_is_seeded_by_the_run() -> None:
    from coop_gym.model.difficulty import get_difficulty

    at_hard = dataclasses.replace(SMALL, difficulty="hard")
    data = run_experiment(at_hard, seed=3)
    level = get_difficulty("hard")
    assert all(p.params == level.apply(PERSONAS[p.name].params) for p in data.personas)
    first, again = estimate(data, "switching"), estimate(data, "switching")
    assert np.array_equal(first.probabilities, again.probabilities)  # same run, same particles
    other = estimate(run_experiment(at_hard, seed=4), "switching")
    assert not np.array_equal(first.probabilities, other.probabilities)
