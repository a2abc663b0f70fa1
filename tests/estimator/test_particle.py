import math

import gymnasium as gym
import numpy as np
import pytest

import coop_gym  # noqa: F401  (registers the ids)
from coop_gym.envs.switching import SwitchingOptions, hypothesis_bank, mode_prior, switching_filter
from coop_gym.model.difficulty import get_difficulty
from coop_gym.model.dynamics import person_substep, simulate
from coop_gym.model.params import Realism, Timing
from coop_gym.model.personas import PERSONAS, TRAIN_PERSONAS
from estimator.particle import reference_run

TIMING = Timing()
HARD = get_difficulty("hard")


def _filter(n_envs=2, seed=0, **options):
    opts = SwitchingOptions(difficulty="hard", **options)
    rows = hypothesis_bank(n_envs, HARD, Realism(), TIMING, opts)
    rngs = [np.random.default_rng(seed + i) for i in range(n_envs)]
    return switching_filter(rows, TIMING, rngs, opts)


def _trial(xi, steps=150, seed=3, push=10.0, words_from=40):
    # A guided push, then "lean forward" alone: the simulated person with the mode held.
    cp = np.zeros(steps)
    cp[:25] = push
    cv = np.zeros(steps)
    cv[:25] = 1.0
    cv[words_from : words_from + 50] = 1.0
    person = HARD.apply(PERSONAS["typical"].params)
    traj = simulate(person, cp, cv, np.random.default_rng(seed), initial_xi=xi, hold_xi=True)
    return cp, cv, traj


@pytest.mark.parametrize("jitter", [0.0, 0.5])
def test_kernel_equals_the_numpy_reference(jitter):
    cp, cv, traj = _trial(1, steps=60)
    y = np.stack([traj.measured_position_m, traj.measured_position_m + 0.01])
    a = _filter(n_particles=64, hypotheses=8, mode_jitter_per_s=jitter)
    b = _filter(n_particles=64, hypotheses=8, mode_jitter_per_s=jitter)
    a.reset(np.arange(2), y[:, 0])
    b.reset(np.arange(2), y[:, 0])
    probs = a.run(np.stack([cp[:60]] * 2), np.stack([cv[:60]] * 2), y)
    ref = reference_run(b, person_substep.py_func, np.stack([cp[:60]] * 2), np.stack([cv[:60]] * 2), y)
    np.testing.assert_allclose(probs, ref, rtol=0, atol=1e-12)
    np.testing.assert_allclose(a.particles, b.particles, rtol=0, atol=1e-12)
    np.testing.assert_allclose(a.log_w, b.log_w, rtol=0, atol=1e-9)
    # Both drew the same numbers from their generators.
    assert a.rngs[0].random() == b.rngs[0].random()


def test_hypothesis_posterior_sums_each_hypothesis_particles_weights():
    cp, cv, traj = _trial(1, steps=60)
    y = np.stack([traj.measured_position_m, traj.measured_position_m + 0.01])
    pf = _filter(n_particles=64, hypotheses=8)
    pf.reset(np.arange(2), y[:, 0])
    before = pf.hypothesis_posterior()
    np.testing.assert_allclose(before, 1.0 / 8, rtol=0, atol=1e-12)  # 8 particles each, equal weights
    pf.run(np.stack([cp[:60]] * 2), np.stack([cv[:60]] * 2), y)
    after = pf.hypothesis_posterior()
    for e in range(2):
        w = np.exp(pf.log_w[e]) / np.exp(pf.log_w[e]).sum()
        labels = pf.particles[e, :, -1]
        expected = [w[labels == h].sum() for h in range(8)]
        np.testing.assert_allclose(after[e], expected, rtol=1e-12, atol=1e-15)
    assert not np.allclose(after, before)  # the readings weighed the hypotheses


@pytest.mark.parametrize("xi", [-1, 0, 1])
def test_reads_the_answer_to_words_alone(xi):
    # The person's mode held through a guided push and a words-only probe: the filter's MAP
    # mode after the probe is the true one (typical person, nominal model).
    cp, cv, traj = _trial(xi)
    pf = _filter(n_envs=1, n_particles=512, hypotheses=1)
    pf.reset([0], traj.measured_position_m[0])
    probs = pf.run(cp[None], cv[None], traj.measured_position_m[None])
    assert int(np.argmax(probs[0, -1])) - 1 == xi
    assert probs[0, -1, xi + 1] > 0.6


def test_probabilities_are_distributions_and_deterministic():
    cp, cv, traj = _trial(0, steps=80)
    runs = []
    for _ in range(2):
        pf = _filter(n_envs=1)
        pf.reset([0], 0.0)
        runs.append(pf.run(cp[None], cv[None], traj.measured_position_m[None]))
    np.testing.assert_array_equal(runs[0], runs[1])
    np.testing.assert_allclose(runs[0].sum(axis=2), 1.0, atol=1e-12)
    assert np.all(runs[0] >= 0)


def test_reset_reseeds_in_place_and_takes_true_people():
    pf = _filter(n_envs=2)
    generators = pf.generators.copy()
    people = np.stack([pf.params[0, 0]] * 2) * 1.0
    pf.reset([1], 0.05, params=people[:1], seeds=[7])
    np.testing.assert_array_equal(pf.generators, generators)  # the kernel's generators stay the same objects
    assert np.all(pf.params[1] == people[0])
    np.testing.assert_allclose(pf.particles[1, :, 0].mean(), 0.05, atol=0.005)
    # The same seed gives the same particles; another seed others.
    twin = _filter(n_envs=2)
    twin.reset([1], 0.05, params=people[:1], seeds=[7])
    np.testing.assert_array_equal(twin.particles[1], pf.particles[1])
    twin.reset([1], 0.05, params=people[:1], seeds=[8])
    assert not np.array_equal(twin.particles[1], pf.particles[1])


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"n_particles": 0}, "n_particles"),
        ({"reading_std_m": 0.0}, "reading_std_m"),
        ({"hypotheses": 0}, "hypotheses"),
        ({"mode_jitter_per_s": math.nan}, "mode_jitter_per_s"),
        ({"personas": ()}, "personas"),
        ({"personas": "typical"}, "personas"),
        ({"personas": ["typical", "nobody"]}, "unknown persona 'nobody'"),
    ],
)
def test_bad_options_name_the_field(kwargs, message):
    with pytest.raises(ValueError, match=message):
        SwitchingOptions(**kwargs)


def test_hypotheses_are_drawn_around_the_named_personas():
    default = hypothesis_bank(1, HARD, Realism(), TIMING, SwitchingOptions())
    named = hypothesis_bank(1, HARD, Realism(), TIMING, SwitchingOptions(personas=list(TRAIN_PERSONAS)))
    np.testing.assert_array_equal(default, named)  # the default is the training personas
    stoic_out = [name for name in TRAIN_PERSONAS if name != "stoic"]
    without = hypothesis_bank(1, HARD, Realism(), TIMING, SwitchingOptions(personas=stoic_out))
    assert not np.array_equal(default, without)
    np.testing.assert_allclose(mode_prior(["anxious"]), (0.8, 0.2, 0.0))  # anxious people start uncooperative
    np.testing.assert_allclose(sum(mode_prior()), 1.0)


def test_a_single_env_takes_its_true_person():
    env = gym.make("CoopGym/SitToStandHard-v1", estimator="switching", estimator_options={"true_person": True})
    env.reset(seed=0)
    core = env.unwrapped.core
    np.testing.assert_array_equal(core.mm.filter.params[0, 0], core.params[0])
    assert np.isfinite(env.step(env.action_space.sample())[0]).all()


def test_bad_inputs_raise_and_change_nothing():
    pf = _filter(n_envs=2)
    pf.reset(np.arange(2), 0.0)
    before = pf.particles.copy()
    with pytest.raises(ValueError, match="must be finite"):
        pf.run(np.zeros((2, 3)), np.zeros((2, 3)), np.array([[0.0, np.nan, 0.0], [0.0, 0.0, 0.0]]))
    np.testing.assert_array_equal(pf.particles, before)
    with pytest.raises(ValueError, match="shape"):
        pf.run(np.zeros((2, 3)), np.zeros((2, 3)), np.zeros((3, 3)))
    with pytest.raises(ValueError, match="seeds"):
        pf.reset([0], 0.0, seeds=[-1])
    with pytest.raises(ValueError, match="seeds must be 1 non-negative ints, got an array of float64"):
        pf.reset([0], 0.0, seeds=np.array([2.0**63]))
    np.testing.assert_array_equal(pf.particles, before)
    # Seeds above 2**63 beside small ones stay exact: env 1 draws the same as when reset alone.
    pf.reset([1], 0.0, seeds=[2**63 + 5])
    alone = pf.particles[1].copy()
    pf.reset([0, 1], 0.0, seeds=[3, 2**63 + 5])
    np.testing.assert_array_equal(pf.particles[1], alone)
    with pytest.raises(ValueError, match="estimator_options for 'switching'"):
        switching_filter(hypothesis_bank(1, HARD, Realism(), TIMING), TIMING, [np.random.default_rng(0)], {"bogus": 1})


def _play(estimator, seed, steps=40, **kwargs):
    env = gym.make("CoopGym/SitToStandHard-v1", estimator=estimator, **kwargs)
    obs, info = env.reset(seed=seed)
    truth, observed = [info["true_x_m"]], [obs]
    for k in range(steps):
        action = np.array([1 if k % 10 < 5 else 0, 2 if k % 10 == 0 else 0, 0])
        obs, _, terminated, truncated, info = env.step(action)
        truth.append(info["true_x_m"])
        observed.append(obs)
        if terminated or truncated:
            break
    return np.array(truth), np.array(observed), env.unwrapped.features


def test_the_env_estimate_is_deterministic_and_leaves_the_person_alone():
    options = {"n_particles": 64, "hypotheses": 8}
    truth_kf, _, _ = _play("kalman", 5)
    truth_a, obs_a, features = _play("switching", 5, estimator_options=options)
    truth_b, obs_b, _ = _play("switching", 5, estimator_options=options)
    np.testing.assert_array_equal(truth_b, truth_a)
    # The particles draw from their own generator: the person moves exactly as with the paper's filter.
    np.testing.assert_array_equal(truth_a, truth_kf)
    np.testing.assert_array_equal(obs_a, obs_b)
    probs = obs_a[:, [features.index(f) for f in ("p_uncooperative", "p_unresponsive", "p_cooperative")]]
    np.testing.assert_allclose(probs.sum(axis=1), 1.0, atol=1e-5)
    _, obs_c, _ = _play("switching", 6, estimator_options=options)
    assert not np.array_equal(obs_a[1:], obs_c[1 : len(obs_a)])


def test_env_options_reach_the_filter_and_bad_ones_are_named():
    small = {"n_particles": 32, "hypotheses": 8}
    env = gym.make("CoopGym/SitToStandHard-v1", estimator="switching", estimator_options=small)
    env.reset(seed=0)
    bank = env.unwrapped.core.mm
    assert bank.filter.n_particles == 32
    assert bank.options.difficulty == "hard"
    with pytest.raises(ValueError, match="n_particles"):
        gym.make("CoopGym/SitToStandHard-v1", estimator="switching", estimator_options={"n_particles": 0}).reset(seed=0)
