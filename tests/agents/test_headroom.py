"""The headroom claims of the difficulty levels, measured through the one evaluation path.

The hard level must make reading the mind necessary (the oracle beats every blind policy by
a wide margin) AND possible (a non-oracle caregiver that reads the answers to its cues beats
the best blind policy). The easy level is the paper's model: there, the lean gives it away.
"""

from __future__ import annotations

import numpy as np
import pytest

from agents.caregivers.belief import TUNED_BELIEF
from agents.caregivers.scripted import (
    TUNED_BLIND,
    TUNED_PROBER,
    BlindAgent,
    BlindSettings,
    ProbingCaregiver,
    make_scripted,
)
from agents.evaluate import OUTCOMES, EpisodeRecord, EvaluationResult, evaluate, headroom
from coop_gym.envs.sit_to_stand import observation_features
from coop_gym.model.difficulty import DIFFICULTIES

EPISODES = 400  # per agent; the 95 % CI half-width of a rate near 50 % is ~5 points


AGENTS = ("oracle", "blind", "prober", "belief", "handbook")


@pytest.fixture(scope="module")
def hard() -> dict[str, EvaluationResult]:
    return {name: evaluate(name, "CoopGym/SitToStandHard-v1", "test", EPISODES, 0) for name in AGENTS}


@pytest.fixture(scope="module")
def hard_v2() -> dict[str, EvaluationResult]:
    return {name: evaluate(name, "CoopGym/SitToStandHard-v2", "test", EPISODES, 0) for name in AGENTS}


def _needs_the_mind_and_lets_the_estimator_read_it(
    results: dict[str, EvaluationResult], value: float, insight: float, prober_lead: float, unsafe_slack: float
) -> None:
    """The level's headroom against the best blind policy, the belief caregiver the best reader."""
    room = headroom(list(results.values()))
    assert room is not None
    assert room.oracle >= 0.99
    assert room.value_of_reading_the_mind >= value
    # The estimator reads best: the caregiver that lifts on the switching filter's P(xi = +1).
    assert room.best_reader_agent == "belief"
    assert room.achieved_insight >= insight
    assert results["prober"].success_rate >= results["blind"].success_rate + prober_lead
    # Reading the mind is not bought with unsafe lifts.
    for reader in ("prober", "belief"):
        assert results[reader].unsafe_rate <= results["blind"].unsafe_rate + unsafe_slack


def test_hard_level_needs_the_mind_and_lets_it_be_read(hard: dict[str, EvaluationResult]) -> None:
    # Every caregiver with its settings chosen on the training personas (TUNED_BLIND, TUNED_PROBER,
    # the belief caregiver's leave-one-out choice). The thresholds sit below the 2000-episode figures
    # that `python bench/levels.py --save` writes to bench/results/levels.json ("hard"), by about the
    # sampling error of these 400 episodes.
    _needs_the_mind_and_lets_the_estimator_read_it(hard, value=0.18, insight=0.08, prober_lead=0.03, unsafe_slack=0.02)


def test_hard_v2_keeps_its_headroom_against_the_widest_blind_search(hard_v2: dict[str, EvaluationResult]) -> None:
    # The hard level's -v2 (recruiting slower, willingness steadier once won): the blind and probing
    # settings chosen again on its training personas are the -v1 ones (TUNED_BLIND, TUNED_PROBER).
    # The thresholds are the SPEC's headroom claim (oracle - best blind >= 30 points, a reader >= 15
    # over it); the 2000-episode figures are in bench/results/levels.json ("hard-v2",
    # `python bench/levels.py --save`).
    _needs_the_mind_and_lets_the_estimator_read_it(
        hard_v2, value=0.30, insight=0.15, prober_lead=0.10, unsafe_slack=0.01
    )


def test_easy_level_does_not_test_the_mind() -> None:
    # docs/environments.md, "Difficulty levels", measured: on the paper's model the lean is enough.
    results = [evaluate(name, "CoopGym/SitToStandEasy-v1", "test", 200, 0) for name in ("oracle", "blind")]
    room = headroom(results)
    assert room is not None and room.value_of_reading_the_mind <= 0.05


def _obs_pair(features: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(0)
    obs = rng.uniform(0.0, 0.4, size=(64, len(features)))
    obs[:, features.index("elapsed_s")] = rng.uniform(0.1, 29.0, 64)
    obs[:, features.index("verbal_cue")] = rng.choice([0.0, 1.0], 64)
    other = obs.copy()
    for name in ("xi_hat", "xi_std", "judgment", "eta_hat_m", "p_uncooperative", "p_unresponsive", "p_cooperative"):
        if name in features:
            other[:, features.index(name)] = rng.uniform(-1.0, 1.0, 64)
    return obs, other


@pytest.mark.parametrize("agent", ["blind", "prober"])
def test_blind_and_prober_never_read_the_estimators_mind(agent: str) -> None:
    # Both decide on the lean (and the prober on its answer); no xi estimate, judgment or P(xi).
    features = observation_features("belief", "imm")
    a, b = make_scripted(agent, features), make_scripted(agent, features)
    obs, other = _obs_pair(features)
    for _ in range(5):
        actions_a, _ = a.predict(obs)
        actions_b, _ = b.predict(other)
        assert np.array_equal(actions_a, actions_b)
        obs[:, features.index("elapsed_s")] += 0.1
        other[:, features.index("elapsed_s")] += 0.1


def test_blind_agent_lifts_on_lean_timer_and_hold() -> None:
    features = observation_features("belief", "kalman")
    agent = BlindAgent(features, settings=BlindSettings(lean_m=0.2, min_time_s=1.0, hold_s=0.3))
    obs = np.zeros((1, len(features)))
    col = {name: features.index(name) for name in ("x_hat_m", "elapsed_s")}
    lifts = []
    for t, x in enumerate([0.0, 0.25, 0.25, 0.25, 0.25, 0.25, 0.25, 0.25, 0.25, 0.25, 0.25, 0.25]):
        obs[0, col["elapsed_s"]] = 0.1 * (t + 1)
        obs[0, col["x_hat_m"]] = x
        action, _ = agent.predict(obs)
        lifts.append(int(action[0, 2]))
    # Leaning from 0.2 s; held 0.3 s by 0.5 s; but not before 1.0 s of the episode.
    assert lifts.index(1) == 9


def test_prober_lifts_only_on_a_forward_answer_to_its_probe() -> None:
    features = observation_features("belief", "kalman")
    agent = ProbingCaregiver(features)
    s = agent.settings
    obs = np.zeros((1, len(features)))
    ix, it = features.index("x_hat_m"), features.index("elapsed_s")

    def run(answer_m: float) -> list[np.ndarray]:
        agent.reset()
        actions = []
        for t in range(40):
            now = 0.1 * (t + 1)
            obs[0, it] = now
            probe_from = s.burst_s + s.settle_s + 0.05
            obs[0, ix] = 0.2 + (answer_m if now > probe_from + 0.5 else 0.0)
            action, _ = agent.predict(obs)
            actions.append(action[0].copy())
        return actions

    silent = run(0.0)
    assert not any(a[2] for a in silent)  # a lean without an answer is never lifted
    answered = run(0.05)
    lifted = [i for i, a in enumerate(answered) if a[2]]
    assert lifted and all(a[0] == 0 for a in answered[lifted[0] - 3 : lifted[0] + 1])  # no push while probing


def test_headroom_arithmetic() -> None:
    def result(name: str, successes: int, n: int = 10) -> EvaluationResult:
        records = tuple(
            EpisodeRecord(k, k, "typical", "success" if k < successes else "timeout", 0.0, 1, 0.1, 0.0, 0.0, 0.0, 0, 0)
            for k in range(n)
        )
        return EvaluationResult(name, "CoopGym/SitToStand-v0", ("typical",), 0, records)

    room = headroom([result("oracle", 10), result("blind", 4), result("push_then_lift", 6), result("ppo:run", 8)])
    assert room is not None
    assert (room.best_blind_agent, room.best_reader_agent) == ("push_then_lift", "ppo:run")
    assert room.value_of_reading_the_mind == pytest.approx(0.4)
    assert room.achieved_insight == pytest.approx(0.2)
    assert headroom([result("ppo:run", 8)]) is None


def test_the_tuned_settings_cover_every_level() -> None:
    assert set(TUNED_BLIND) == set(TUNED_PROBER) == set(TUNED_BELIEF) == {"v0", *DIFFICULTIES}


def test_the_blind_search_scores_candidates_as_the_evaluation_does() -> None:
    # play_population (many candidates in one batched env) gives each candidate the episodes
    # agents.evaluate gives it: same seeds, same people, same outcomes.
    from agents.caregivers.scripted import CuePhase
    from agents.tune.baselines import play_population

    env_id = "CoopGym/SitToStandHard-v1"
    candidates = [
        TUNED_BLIND["hard"],
        BlindSettings(
            lean_m=0.25,
            schedule=(CuePhase("soft", "forward", 1.0, lift=False), CuePhase("none", "forward", 2.0)),
            repeat=True,
        ),
    ]
    outcomes = play_population(candidates, env_id, "train", episodes=24, seed=5, batch=20)  # batches cut candidates
    for settings, row in zip(candidates, outcomes, strict=True):
        result = evaluate(BlindAgent(settings=settings), env_id, "train", 24, 5)
        assert [OUTCOMES[code - 1] for code in row] == [r.outcome for r in result.records]
