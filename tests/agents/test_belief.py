import re
from dataclasses import replace

import numpy as np
import pytest

from agents.base import LIFT, PUSH_NONE, PUSH_SOFT, VERBAL_FORWARD, VERBAL_NONE
from agents.caregivers.belief import BeliefCaregiver, BeliefSettings
from coop_gym.envs.contract import observation_features

FEATURES = observation_features("belief", "switching")


def _obs(now, p_cooperative, x_hat_m=0.0):
    obs = np.zeros((1, len(FEATURES)))
    obs[0, FEATURES.index("elapsed_s")] = now
    obs[0, FEATURES.index("p_cooperative")] = p_cooperative
    obs[0, FEATURES.index("x_hat_m")] = x_hat_m
    return obs


def _play(agent, p_cooperative, x_hat_m=0.0, steps=40):
    state, actions = None, []
    for k in range(steps):
        action, state = agent.predict(_obs(round(0.1 * k, 1), p_cooperative, x_hat_m), state)
        actions.append(action[0].tolist())
    return actions


def test_recruits_settles_then_probes_with_words_alone():
    settings = BeliefSettings(burst_s=0.5, settle_s=0.3, window_s=1.0, reprobe_p=0.5)
    actions = _play(BeliefCaregiver(FEATURES, settings=settings), p_cooperative=0.1)
    push = [a[0] for a in actions]
    verbal = [a[1] for a in actions]
    assert push[:5] == [PUSH_SOFT] * 5 and verbal[0] == VERBAL_FORWARD  # recruit: guided push
    assert push[5:8] == [PUSH_NONE] * 3 and verbal[5:8] == [VERBAL_NONE] * 3  # settle: silence
    assert push[8] == PUSH_NONE and verbal[8] == VERBAL_FORWARD  # probe: words alone
    assert push[9:18] == [PUSH_NONE] * 9  # no push while the answer is watched
    assert push[18] == PUSH_SOFT  # no answer (P(+1) low): recruit again
    assert all(a[2] != LIFT for a in actions)


def test_holding_the_words_asks_on_every_step_of_the_probe_window():
    once = BeliefSettings(burst_s=0.5, settle_s=0.3, window_s=1.0)
    held = BeliefSettings(burst_s=0.5, settle_s=0.3, window_s=1.0, hold_words=True)
    verbal = {
        s.hold_words: [a[1] for a in _play(BeliefCaregiver(FEATURES, settings=s), 0.1, steps=20)] for s in (once, held)
    }
    # Probe asked at step 8, watched to step 17; step 18 recruits again (P(+1) low).
    assert verbal[False][8:18] == [VERBAL_FORWARD] + [VERBAL_NONE] * 9
    assert verbal[True][8:18] == [VERBAL_FORWARD] * 10
    assert verbal[True][:8] == verbal[False][:8] and verbal[True][18] == verbal[False][18] == VERBAL_FORWARD
    lifts = _play(BeliefCaregiver(FEATURES, settings=held), 0.9, 0.2, steps=12)
    assert lifts[9][2] == LIFT and lifts[9][1] == VERBAL_NONE  # a lift is a lift, held words or not


def test_probes_again_without_pushing_while_cooperation_is_likely():
    settings = BeliefSettings(lift_p=0.9, burst_s=0.5, recruited_p=1.0, settle_s=0.3, window_s=1.0, reprobe_p=0.5)
    actions = _play(BeliefCaregiver(FEATURES, settings=settings), p_cooperative=0.7)
    assert [a[0] for a in actions[8:]] == [PUSH_NONE] * 32
    assert [a[1] for a in actions[8:40:10]] == [VERBAL_FORWARD] * 4


def test_ends_the_burst_once_the_person_is_likely_recruited():
    settings = BeliefSettings(lift_p=0.9, burst_s=2.0, recruited_p=0.5, settle_s=0.3, window_s=1.0)
    pushes = {p: [a[0] for a in _play(BeliefCaregiver(FEATURES, settings=settings), p, steps=10)] for p in (0.4, 0.6)}
    assert pushes[0.4] == [PUSH_SOFT] * 10  # not yet likely: the whole burst
    assert pushes[0.6] == [PUSH_NONE] * 10  # likely recruited: no push, settle then probe


def test_a_push_limit_ends_the_burst_once_the_shoulder_is_that_far_forward():
    settings = BeliefSettings(lift_p=0.9, burst_s=2.0, recruited_p=1.0, settle_s=0.3, recruit_until_m=0.3)
    pushes = {
        x: [a[0] for a in _play(BeliefCaregiver(FEATURES, settings=settings), 0.1, x, steps=10)] for x in (0.2, 0.3)
    }
    assert pushes[0.2] == [PUSH_SOFT] * 10  # short of the limit: the whole burst
    assert pushes[0.3] == [PUSH_NONE] * 10  # at the limit: no push, settle then probe
    unlimited = BeliefSettings(lift_p=0.9, burst_s=2.0, recruited_p=1.0, settle_s=0.3)
    assert [a[0] for a in _play(BeliefCaregiver(FEATURES, settings=unlimited), 0.1, 0.3, steps=10)] == [PUSH_SOFT] * 10


@pytest.mark.parametrize(("p", "x", "lifts"), [(0.9, 0.2, True), (0.9, 0.1, False), (0.5, 0.3, False)])
def test_lifts_on_the_estimate_and_the_posture_while_watching_a_probe(p, x, lifts):
    settings = BeliefSettings(lift_p=0.85, lean_m=0.16, burst_s=0.5, recruited_p=1.0, settle_s=0.3)
    actions = _play(BeliefCaregiver(FEATURES, settings=settings), p, x, steps=20)
    lifted = [k for k, a in enumerate(actions) if a[2] == LIFT]
    # Not in the burst (steps 0-4) nor the settle (5-7), whatever the estimate: the probe is asked at
    # step 8 and its answer watched from step 9.
    assert lifted == (list(range(9, 20)) if lifts else [])
    for k in lifted:
        assert actions[k][0] == PUSH_NONE and actions[k][1] == VERBAL_NONE


def test_needs_the_filter_and_checks_its_settings():
    with pytest.raises(ValueError, match="p_cooperative"):
        BeliefCaregiver(observation_features("belief", "kalman"))
    with pytest.raises(ValueError, match="lift_p"):
        BeliefSettings(lift_p=1.5)
    with pytest.raises(ValueError, match="recruited_p"):
        BeliefSettings(recruited_p=-0.1)
    with pytest.raises(ValueError, match="window_s"):
        BeliefSettings(window_s=-1.0)
    with pytest.raises(ValueError, match="recruit_until_m"):
        BeliefSettings(recruit_until_m=-0.1)
    with pytest.raises(ValueError, match="hold_words"):
        BeliefSettings(hold_words="yes")


def test_the_chosen_settings_are_the_search_grids_and_differ_only_where_chosen():
    # TUNED_BELIEF holds winners of agents.tune.belief's grid; the levels it was not run on keep the
    # defaults.
    from agents.caregivers.belief import TUNED_BELIEF
    from agents.tune.belief import settings_grid

    grid = settings_grid()
    assert TUNED_BELIEF["hard"] in grid and TUNED_BELIEF["hard-v2"] in grid
    assert {TUNED_BELIEF[level] for level in ("v0", "easy", "medium")} == {BeliefSettings()}
    # The two hard levels differ only in the gate that ends a burst (-v2's guided push recruits slower).
    hard, hard_v2 = TUNED_BELIEF["hard"], TUNED_BELIEF["hard-v2"]
    differ = [f for f in BeliefSettings.__dataclass_fields__ if getattr(hard, f) != getattr(hard_v2, f)]
    assert differ == ["recruited_p"]
    assert TUNED_BELIEF["hard-v2"].recruited_p < TUNED_BELIEF["hard"].recruited_p


def test_the_search_can_read_another_estimator_and_score_its_winner_held_out(capsys):
    # The same grid on the IMM's P(xi = +1), with lift gates, and its winner on held-out episodes.
    from agents.tune.belief import leave_one_out, main, settings_grid

    grid = settings_grid((0.8, 0.9))
    assert len(grid) == 24 and {s.lift_p for s in grid} == {0.8, 0.9}
    held = settings_grid((0.8, 0.9), hold_words=True)
    assert [s.hold_words for s in held] == [True] * 24 and [replace(s, hold_words=False) for s in held] == grid
    success, unsafe = leave_one_out(grid[0], "CoopGym/SitToStandHard-v2", 2, estimator="imm")
    assert 0.0 <= unsafe <= success + unsafe <= 1.0
    with pytest.raises(ValueError, match=r"estimator must be one of \['switching', 'imm', 'multiple_model'\]"):
        leave_one_out(grid[0], "CoopGym/SitToStandHard-v2", 2, estimator="kalman")
    assert main(["--estimator", "imm", "--episodes", "1", "--held-out", "3", "--hold-words"]) == 0
    out = capsys.readouterr().out
    assert "best on the training personas (imm): BeliefSettings(" in out and "hold_words=True)" in out
    assert re.search(r"held out \(3 episodes, seeds 0\.\.2\): success \d\.\d{3} \[", out)
    bad = ((["--lift-p", "1.5"], "--lift-p: BeliefSettings.lift_p"), (["--held-out", "-1"], "--held-out must be"))
    for argv, message in bad:
        with pytest.raises(SystemExit):
            main(argv)
        assert message in capsys.readouterr().err
