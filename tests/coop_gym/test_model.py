"""The human model against closed-form cases and its own configuration."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from coop_gym.model.dynamics import (
    DELAY_LINE_LENGTH,
    NORMALS_PER_SUBSTEP,
    PARAM_COLUMNS,
    PERSON,
    PERSON_DERIVED_COLUMNS,
    STATE,
    cooperativeness_rates,
    initial_state_row,
    pack_person,
    person_substep,
    simulate,
)
from coop_gym.model.params import (
    Biomechanics,
    Cooperativeness,
    Intention,
    PersonParams,
    Realism,
    Sensors,
    Timing,
)
from coop_gym.model.personas import (
    PERSONAS,
    TEST_PERSONAS,
    TRAIN_PERSONAS,
    WIDE_VARIATION_STD,
    get_persona,
    resolve_personas,
    sample_person,
)
from estimator.compiled.schema import field_values

TIMING = Timing()
IDEAL = PersonParams().with_realism(Realism.off())


def _free_response(bio: Biomechanics, x0: float, eta: float, n_steps: int) -> np.ndarray:
    """Simulate the noise-free person with no cue from x0 toward a fixed intention."""
    person = dataclasses.replace(IDEAL, biomechanics=bio)
    p = pack_person(person, TIMING, hold_xi=True)
    s = initial_state_row(0, x0)
    s[STATE.eta_m] = eta
    xs = np.empty(n_steps)
    z = np.zeros(NORMALS_PER_SUBSTEP)
    dp, dv = np.zeros(DELAY_LINE_LENGTH), np.zeros(DELAY_LINE_LENGTH)
    for t in range(n_steps):
        person_substep(s, p, dp, dv, 0.0, 0.0, z)
        xs[t] = s[STATE.x_m]
    return xs


def test_critically_damped_torso_settles_on_intention_in_closed_form() -> None:
    # lambda1 = 6, k1 = 9: s^2 + 6 s + 9 = (s + 3)^2, critically damped with omega = 3.
    bio = dataclasses.replace(IDEAL.biomechanics, damping_rate_per_s=6.0, voluntary_gain_per_s2=9.0)
    x0, eta, n = 0.0, 0.2, 200
    xs = _free_response(bio, x0, eta, n)
    t = (np.arange(n) + 1) * TIMING.dt_s
    expected = eta + (x0 - eta) * (1.0 + 3.0 * t) * np.exp(-3.0 * t)
    assert xs == pytest.approx(expected, abs=1e-12)
    assert xs[-1] == pytest.approx(eta, abs=1e-3)


def test_underdamped_torso_overshoots_with_the_implied_frequency() -> None:
    lam, k1 = 2.0, 9.0
    bio = dataclasses.replace(IDEAL.biomechanics, damping_rate_per_s=lam, voluntary_gain_per_s2=k1)
    x0, eta, n = 0.05, 0.2, 400
    xs = _free_response(bio, x0, eta, n)
    t = (np.arange(n) + 1) * TIMING.dt_s
    sigma, omega_d = lam / 2.0, math.sqrt(k1 - lam**2 / 4.0)
    expected = eta - (eta - x0) * np.exp(-sigma * t) * (np.cos(omega_d * t) + sigma / omega_d * np.sin(omega_d * t))
    assert xs == pytest.approx(expected, abs=1e-12)
    assert xs.max() > eta  # underdamped: it overshoots


def test_push_moves_a_noise_free_unresponsive_person_by_k2_cp_over_k1() -> None:
    # xi = 0 holds the intention still, so the steady lean is the static compliance k2*c_p/k1.
    traj = simulate(IDEAL, np.full(1000, 10.0), np.zeros(1000), np.random.default_rng(0), initial_xi=0, hold_xi=True)
    bio = IDEAL.biomechanics
    assert traj.true_state[-1, 0] == pytest.approx(bio.push_compliance_m_per_s2_n * 10.0 / bio.voluntary_gain_per_s2)
    assert traj.true_state[-1, 2] == 0.0


@pytest.mark.parametrize("xi", [-1, 0, 1])
def test_intention_follows_eq6_with_the_sign_of_xi(xi: int) -> None:
    # eq. 6 with the realism off: eta rises by xi*k4*c_v*dt per step of "lean forward".
    n = 50
    traj = simulate(IDEAL, np.zeros(n), np.ones(n), np.random.default_rng(0), initial_xi=xi, hold_xi=True)
    k4 = IDEAL.intention.verbal_gain_m_per_s
    assert traj.true_state[-1, 2] == pytest.approx(xi * k4 * n * TIMING.dt_s, abs=1e-12)


def test_reaction_delay_postpones_the_intention() -> None:
    person = dataclasses.replace(IDEAL, intention=dataclasses.replace(IDEAL.intention, reaction_delay_s=0.3))
    cv = np.ones(40)
    traj = simulate(person, np.zeros(40), cv, np.random.default_rng(0), initial_xi=1, hold_xi=True)
    delay_steps = 15
    assert np.all(traj.true_state[:delay_steps, 2] == 0.0)
    assert traj.true_state[delay_steps, 2] > 0.0


def test_saturation_keeps_the_intention_in_the_anatomical_range() -> None:
    person = PersonParams().with_realism(dataclasses.replace(Realism.off(), saturation=True))
    traj = simulate(person, np.full(1500, 30.0), np.ones(1500), np.random.default_rng(1), initial_xi=1, hold_xi=True)
    assert traj.true_state[:, 2].max() == pytest.approx(person.intention.max_m)
    traj = simulate(person, np.full(1500, 30.0), np.ones(1500), np.random.default_rng(1), initial_xi=-1, hold_xi=True)
    assert traj.true_state[:, 2].min() == pytest.approx(person.intention.min_m)


def test_relaxation_returns_the_intention_toward_upright() -> None:
    person = PersonParams().with_realism(dataclasses.replace(Realism.off(), relaxation=True))
    cv = np.concatenate([np.ones(50), np.zeros(500)])
    traj = simulate(person, np.zeros_like(cv), cv, np.random.default_rng(0), initial_xi=1, hold_xi=True)
    peak = traj.true_state[49, 2]
    rate = person.intention.relaxation_rate_per_s
    assert traj.true_state[-1, 2] == pytest.approx(peak * (1 - rate * TIMING.dt_s) ** 500, rel=1e-9)


def test_uncooperative_person_stiffens_against_a_push() -> None:
    stiff = PersonParams().with_realism(dataclasses.replace(Realism.off(), state_dependent_stiffness=True))
    leans = {}
    for xi in (-1, 1):
        # Hold eta at 0 by giving no intention gain so only the direct push acts.
        person = dataclasses.replace(stiff, intention=dataclasses.replace(stiff.intention, push_gain_m_per_s_n=0.0))
        traj = simulate(
            person, np.full(500, 30.0), np.zeros(500), np.random.default_rng(0), initial_xi=xi, hold_xi=True
        )
        leans[xi] = traj.true_state[-1, 0]
    factor = stiff.biomechanics.stiffness_factor_uncooperative
    assert leans[-1] == pytest.approx(factor * leans[1], rel=1e-9)


def _transition_counts(xi: int, push: float, verbal: float, since_explain: float, n: int, seed: int) -> np.ndarray:
    person = PersonParams()
    p = pack_person(person, TIMING)
    rng = np.random.default_rng(seed)
    z = rng.standard_normal((n, NORMALS_PER_SUBSTEP))
    counts = np.zeros(3, dtype=np.int64)  # down, stay, up
    dp, dv = np.zeros(DELAY_LINE_LENGTH), np.zeros(DELAY_LINE_LENGTH)
    for k in range(n):
        s = initial_state_row(xi)
        s[STATE.since_explanation_s] = since_explain
        s[STATE.since_cue_s] = 0.0
        person_substep(s, p, dp, dv, push, verbal, z[k])
        counts[int(s[STATE.xi]) - xi + 1] += 1
    return counts


@pytest.mark.parametrize(
    ("xi", "push", "verbal", "since_explain"),
    [
        (0, 10.0, 0.0, 1.0),  # gentle push after an explanation: up only
        (0, 30.0, 0.0, 1e6),  # firm unprepared push: mostly startle down, a little up
        (-1, 0.0, 1.0, 0.0),  # explaining calms a resisting person
        (1, 0.0, -1.0, 1e6),  # "lean back" confuses
    ],
)
def test_chain_transition_frequencies_match_the_configured_rates(
    xi: int, push: float, verbal: float, since_explain: float
) -> None:
    n = 40_000
    counts = _transition_counts(xi, push, verbal, since_explain, n, seed=xi + 7)
    p = pack_person(PersonParams(), TIMING)
    # The person's memory is updated before the rates are read, as in person_substep.
    since = 0.0 if verbal > 0.5 else since_explain + TIMING.dt_s
    up, down = cooperativeness_rates(p, float(xi), push, verbal, since, 0.0)
    total = up + down
    assert total > 0.0
    leave = 1.0 - math.exp(-total * TIMING.dt_s)
    expected = np.array([leave * down / total, 1.0 - leave, leave * up / total])
    for k in (0, 2):
        sd = math.sqrt(n * expected[k] * (1 - expected[k])) + 1e-9
        assert abs(counts[k] - n * expected[k]) <= 4.5 * sd + 1, (counts, n * expected)


def test_chain_rates_encode_the_handbook_rules() -> None:
    p = pack_person(PersonParams(), TIMING)
    prepared_up, _ = cooperativeness_rates(p, 0.0, 10.0, 0.0, 1.0, 0.0)
    alone_up, _ = cooperativeness_rates(p, 0.0, 10.0, 0.0, 1e6, 0.0)
    words_up, _ = cooperativeness_rates(p, 0.0, 0.0, 1.0, 0.0, 0.0)
    assert prepared_up > 5 * alone_up  # a push after explaining is what works
    assert prepared_up > 5 * words_up  # people rarely act on words alone
    _, firm_unprepared_down = cooperativeness_rates(p, 0.0, 30.0, 0.0, 1e6, 0.0)
    _, firm_prepared_down = cooperativeness_rates(p, 0.0, 30.0, 0.0, 1.0, 0.0)
    assert firm_unprepared_down > 3 * firm_prepared_down  # an unprepared firm push startles
    up_at_top, _ = cooperativeness_rates(p, 1.0, 10.0, 1.0, 0.0, 0.0)
    _, down_at_bottom = cooperativeness_rates(p, -1.0, 30.0, -1.0, 1e6, 0.0)
    assert up_at_top == 0.0 and down_at_bottom == 0.0


def test_idle_person_drifts_to_baseline() -> None:
    coop = dataclasses.replace(Cooperativeness(), baseline=-1, drift_rate_per_s=5.0, idle_after_s=0.0)
    person = dataclasses.replace(PersonParams(), cooperativeness=coop)
    traj = simulate(person, np.zeros(500), np.zeros(500), np.random.default_rng(0), initial_xi=1)
    assert traj.true_state[-1, 3] == -1


def test_simulation_is_deterministic_per_generator_seed() -> None:
    cp = np.where(np.arange(300) % 100 < 50, 10.0, 0.0)
    a = simulate(PersonParams(), cp, np.zeros(300), np.random.default_rng(5), initial_xi=0)
    b = simulate(PersonParams(), cp, np.zeros(300), np.random.default_rng(5), initial_xi=0)
    c = simulate(PersonParams(), cp, np.zeros(300), np.random.default_rng(6), initial_xi=0)
    assert np.array_equal(a.true_state, b.true_state)
    assert np.array_equal(a.measured_position_m, b.measured_position_m)
    assert not np.array_equal(a.measured_position_m, c.measured_position_m)


def test_sensor_noise_has_the_configured_spread() -> None:
    person = PersonParams().with_realism(dataclasses.replace(Realism.off(), sensor_noise=True))
    traj = simulate(person, np.full(20000, 10.0), np.zeros(20000), np.random.default_rng(0), initial_xi=0, hold_xi=True)
    err = traj.measured_position_m - traj.true_state[:, 0]
    assert np.std(err) == pytest.approx(person.sensors.position_noise_std_m, rel=0.03)
    assert np.std(traj.measured_force_n - 10.0) == pytest.approx(person.sensors.force_noise_std_n, rel=0.03)


# --- parameters and personas ---------------------------------------------------


@pytest.mark.parametrize(
    ("cls", "field", "value"),
    [
        (Biomechanics, "damping_rate_per_s", -1.0),
        (Biomechanics, "voluntary_gain_per_s2", float("nan")),
        (Intention, "reaction_delay_s", 5.0),
        (Intention, "saturate", "yes"),
        (Cooperativeness, "hearing", 1.5),
        (Cooperativeness, "baseline", 2),
        (Timing, "substeps", 0),
        (Timing, "dt_s", float("inf")),
    ],
)
def test_out_of_range_parameter_raises_naming_the_field(cls: type, field: str, value: object) -> None:
    with pytest.raises(ValueError, match=f"{cls.__name__}.{field}"):
        cls(**{field: value})


def test_initial_probabilities_must_not_exceed_one() -> None:
    with pytest.raises(ValueError, match="initial_p_uncooperative"):
        Cooperativeness(initial_p_uncooperative=0.7, initial_p_cooperative=0.5)


def test_unknown_persona_raises_listing_known_ones() -> None:
    with pytest.raises(ValueError, match=r"unknown persona 'grumpy'.*typical"):
        get_persona("grumpy")
    with pytest.raises(ValueError, match="personas must be"):
        resolve_personas([])


def test_persona_sets_and_split() -> None:
    assert {"typical", "frail", "anxious", "hard_of_hearing", "cooperative"} <= set(PERSONAS)
    assert not set(TRAIN_PERSONAS) & set(TEST_PERSONAS)
    assert set(TRAIN_PERSONAS) | set(TEST_PERSONAS) == set(PERSONAS)
    assert [p.name for p in resolve_personas("test")] == list(TEST_PERSONAS)
    assert [p.name for p in resolve_personas(["frail", "typical"])] == ["frail", "typical"]


def test_train_wide_is_the_training_personas_with_a_wider_spread() -> None:
    wide = resolve_personas("train_wide")
    assert [p.name for p in wide] == list(TRAIN_PERSONAS)  # never a held-out persona
    assert all(p.variation_relative_std == WIDE_VARIATION_STD > 0.2 for p in wide)
    assert [p.params for p in wide] == [p.params for p in resolve_personas("train")]


def test_train_wide_people_spread_wider_in_the_env() -> None:
    # The compiled reset applies each persona's variation: the push compliance of the
    # people drawn spreads about WIDE_VARIATION_STD / 0.2 times wider (log-std).
    import gymnasium as gym

    import coop_gym  # noqa: F401
    from coop_gym.model.dynamics import PERSON

    def log_spread(personas: str) -> float:
        envs = gym.make_vec("CoopGym/SitToStandHard-v1", 1000, "vector_entry_point", personas=personas)
        envs.reset(seed=0)
        core = envs.unwrapped.core
        typical = core.persona_index == 0
        spread = float(np.std(np.log(core.params[typical, PERSON.push_compliance_m_per_s2_n])))
        envs.close()
        return spread

    narrow, wide = log_spread("train"), log_spread("train_wide")
    assert 0.17 < narrow < 0.23 and 0.44 < wide < 0.56


def test_frail_persona_is_moved_by_a_firm_push_whatever_they_think() -> None:
    # The paper's first failure scenario: leaning is no proof of cooperation.
    # Default realism (the anatomical range bounds how far a resisting person leans back), noise off.
    quiet = Realism(sensor_noise=False, process_noise=False)
    frail = get_persona("frail").params.with_realism(quiet)
    typical = PersonParams().with_realism(quiet)
    cp = np.full(250, 30.0)
    frail_lean = simulate(frail, cp, np.zeros(250), np.random.default_rng(0), initial_xi=-1, hold_xi=True)
    typical_lean = simulate(typical, cp, np.zeros(250), np.random.default_rng(0), initial_xi=-1, hold_xi=True)
    assert frail_lean.true_state[-1, 0] >= 0.15
    assert typical_lean.true_state[-1, 0] < 0.05


def test_person_variation_is_seeded_and_multiplicative() -> None:
    persona = get_persona("typical")
    a = sample_person(persona, np.random.default_rng(1))
    b = sample_person(persona, np.random.default_rng(1))
    c = sample_person(persona, np.random.default_rng(2))
    assert a == b and a != c
    ratio = a.biomechanics.voluntary_gain_per_s2 / persona.params.biomechanics.voluntary_gain_per_s2
    assert 0.3 < ratio < 3.0
    assert sample_person(persona, np.random.default_rng(1), vary=False) == persona.params


def test_state_columns_are_consistent() -> None:
    s = initial_state_row(1, 0.01)
    assert (s[STATE.x_m], s[STATE.xdot_m_per_s], s[STATE.eta_m], s[STATE.xi]) == (0.01, 0.0, 0.01, 1.0)


def test_parameter_row_is_every_person_field_then_the_derived_columns() -> None:
    # One schema: a new field of any level lands in the packed row under its own name.
    levels = (Biomechanics, Intention, Cooperativeness, Sensors)
    fields = tuple(f.name for level in levels for f in dataclasses.fields(level))
    assert PARAM_COLUMNS == fields + PERSON_DERIVED_COLUMNS
    assert PERSON._fields == PARAM_COLUMNS and tuple(PERSON) == tuple(range(len(PARAM_COLUMNS)))
    person = PersonParams(intention=Intention(saturate=False), cooperativeness=Cooperativeness(baseline=-1))
    row = pack_person(person, Timing(), hold_xi=True)
    assert row.shape == (len(PARAM_COLUMNS),)
    for name, value in field_values(person).items():
        assert row[getattr(PERSON, name)] == float(value), name
    assert row[PERSON.hold_xi] == 1.0 and row[PERSON.dt_s] == Timing().dt_s
