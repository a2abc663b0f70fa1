"""The batched simulation shared by the single env and the vector env: ``N`` episodes as arrays.

:class:`SitToStandCore` holds ``N`` independent episodes and advances them one agent action at a
time with one compiled call (:func:`coop_gym.envs.kernels.step.step_env` per env) that writes the reward
terms, the info values (:data:`~coop_gym.envs.contract.REPORT_COLUMNS`) and the clipped float32
observation into preallocated arrays; another call resets any set of envs
(:mod:`coop_gym.envs.kernels.reset`). The single env is this core with ``N = 1``; the vector env is the
same core with ``N`` envs, so the two cannot drift. Per-env state lives in one packed float row
(:mod:`coop_gym.envs.kernels.layout`; ``m``, ``P``, ``params`` ... are views into it).

Randomness: env ``i`` draws only from its own ``numpy.random.Generator`` -- at reset in the
order of :func:`coop_gym.envs.kernels.reset.draw_reset`, then ``substeps x NORMALS_PER_SUBSTEP``
standard normals per non-lift step. So env ``i`` of a vector env seeded ``s`` and a single env
seeded ``s + i`` see identical streams. The kernels draw through the generator's own C
functions with NumPy's algorithms (:mod:`estimator.compiled.rng`), so the ``Generator`` object stays the
single source of truth. Envs seeded together (:meth:`SitToStandCore.seed_envs`, the vector
env's ``reset(seed=...)``) keep that ``Generator``'s PCG64 state in arrays instead
(:mod:`coop_gym.envs.kernels.seeding`) until ``rngs[i]`` asks for the object. A batch of at least 2 x
:data:`~coop_gym.envs.kernels.threads.MIN_ENVS_PER_THREAD` envs steps on several threads
(:mod:`coop_gym.envs.kernels.threads`), with the same numbers.

What the single and the vector env share around the core lives here too, so that neither imports
the other: :func:`make_core` (a core of a config's envs), :class:`ConfiguredEnv` (the settings and
step helpers both hold) and :func:`render_state_for` (one env's frame to draw).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
from numpy.typing import NDArray

from coop_gym.envs.actions import CMD, CMD_COLUMNS, ActionDecoder
from coop_gym.envs.arguments import SitToStandConfig
from coop_gym.envs.config import LiftCriteria, Outcome, RewardWeights
from coop_gym.envs.info import InfoBuilder
from coop_gym.envs.kernels.layout import (
    BLOCKS,
    CONSTS,
    CUE_COLUMNS,
    DRAWS,
    NO_OVERRIDE,
    Settings,
    nominal_model_for,
    pack_consts,
    pack_personas,
)
from coop_gym.envs.kernels.report import REPORT, REPORT_COLUMNS, REWARD_TERMS
from coop_gym.envs.kernels.reset import draw_reset, start_episodes
from coop_gym.envs.kernels.seeding import EnvGenerators
from coop_gym.envs.kernels.step import first_unready, observe, step_all
from coop_gym.envs.kernels.threads import available_threads, check_threads, plan_threads, step_threaded
from coop_gym.envs.observation import FEATURES
from coop_gym.model.dynamics import DELAY_LINE_LENGTH, PARAM_COLUMNS, STATE_COLUMNS
from coop_gym.model.params import Cues, Realism, Timing
from coop_gym.model.personas import Persona
from estimator.compiled.rng import G_STATE
from estimator.judgment import JUDGMENT_COLUMNS, ThresholdJudgment
from estimator.kalman import NOMINAL_COLUMNS
from estimator.nominal import STATE_DIM, NominalModel
from estimator.validate import is_integer

__all__ = [
    "FEATURES",  # the env contract's (coop_gym.envs.contract), for the importers of this module
    "REPORT",
    "REPORT_COLUMNS",
    "REWARD_TERMS",
    "ConfiguredEnv",
    "SitToStandCore",
    "available_threads",  # the threaded step's (coop_gym.envs.kernels.threads), for the importers of this module
    "check_threads",
    "make_core",
    "nominal_model_for",  # the packing's (coop_gym.envs.kernels.layout), for the importers of this module
    "render_state_for",
]


def _no_generator_message(i: int) -> str:
    return f"env {i} has no random generator; call reset_env(i, rng) or set_rng first"


class SitToStandCore:
    """``N`` sit-to-stand episodes stepped together (see module docstring).

    Args:
        n_envs: Number of parallel episodes.
        personas: Personas to draw each episode's person from (uniformly).
        timing, cues, realism, lift, reward, judgment: Settings (see their classes).
        estimator: ``"kalman"``, ``"multiple_model"`` or ``"imm"``.
        multiple_model_options: Keyword arguments of the multiple-model estimator.
        observation_index: Indices into :data:`FEATURES` that make the observation
            (default: all of them, unclipped).
        observation_low, observation_high: Bounds the observation is clipped into.

    Attributes:
        state: (N, W) packed per-env state; ``person``, ``m``, ``P``, ``judge``, ``nominal``,
            ``params``, ``delay_push``, ``delay_verbal`` and ``report`` are views into it.
        report: (N, len(REPORT_COLUMNS)) what the last step or reset of each env produced.
        obs: (N, len(observation_index)) float32 observation of the last step or reset.
        cmd: (N, 4) command rows (columns :data:`~coop_gym.envs.contract.CMD`) for :meth:`step_commands`.
        generators: (N, 4) uint64 addresses of each env's bit generator (0: none yet).
    """

    def __init__(
        self,
        n_envs: int,
        personas: tuple[Persona, ...],
        timing: Timing,
        cues: Cues,
        realism: Realism,
        lift: LiftCriteria,
        reward: RewardWeights,
        judgment: ThresholdJudgment,
        estimator: str = "kalman",
        multiple_model_options: dict[str, Any] | None = None,
        observation_index: tuple[int, ...] | None = None,
        observation_low: NDArray[np.float64] | None = None,
        observation_high: NDArray[np.float64] | None = None,
    ) -> None:
        """Allocate the arrays; every env must be reset before it is stepped."""
        # Kept to rebuild the arrays and their views when unpickled (see __setstate__).
        self._init_args = (n_envs, personas, timing, cues, realism, lift, reward, judgment, estimator,
                           multiple_model_options, observation_index, observation_low, observation_high)  # fmt: skip
        if not is_integer(n_envs) or n_envs < 1:
            raise ValueError(f"n_envs must be a positive int, got {n_envs!r}")
        n = int(n_envs)
        self.n_envs = n
        self.personas = personas
        self.timing = timing
        self.cues = cues
        self.realism = realism
        self.lift = lift
        self.reward_weights = reward
        self.judgment = judgment
        self.estimator = estimator
        personas_packed = pack_personas(personas, timing, realism)
        self.persona_table = personas_packed.table
        self._persona_nominal = personas_packed.nominal_rows
        self._variation_std = personas_packed.variation_std
        self._persona_variation_std = personas_packed.persona_variation_std
        varied = personas_packed.varied_columns
        index = tuple(range(len(FEATURES))) if observation_index is None else tuple(observation_index)
        settings = Settings(timing, cues, realism, lift, reward, judgment, prior=NominalModel())
        self.consts = pack_consts(settings, index, observation_low, observation_high, varied)
        self._allocate(n, len(index), len(varied))
        self.mm = self._make_multiple_model(multiple_model_options or {}) if estimator != "kalman" else None
        self.threads = available_threads()
        self._chunks = 0  # threads a step uses; 0: plan again (plan_threads)
        self._control = np.zeros(2, dtype=np.int64)  # a threaded step's claim word and blocks done
        # With a multiple-model estimator the observation waits for its probabilities.
        self.consts[CONSTS.build_obs] = 1.0 if self.mm is None else 0.0

    def _allocate(self, n: int, n_obs: int, n_varied: int) -> None:
        """The packed per-env state with its views, the command rows and the output buffers."""
        substeps = self.timing.substeps
        self.state = st = np.zeros((n, BLOCKS.end + 3 * substeps))
        self.person = st[:, BLOCKS.person : BLOCKS.person + len(STATE_COLUMNS)]
        self.cue_state = st[:, BLOCKS.cues : BLOCKS.cues + len(CUE_COLUMNS)]
        self.m = st[:, BLOCKS.mean : BLOCKS.mean + STATE_DIM]
        self.P = st[:, BLOCKS.cov : BLOCKS.cov + STATE_DIM * STATE_DIM].reshape(n, STATE_DIM, STATE_DIM)
        self.judge = st[:, BLOCKS.judge : BLOCKS.judge + len(JUDGMENT_COLUMNS)]
        self.nominal = st[:, BLOCKS.nominal : BLOCKS.nominal + len(NOMINAL_COLUMNS)]
        self.params = st[:, BLOCKS.params : BLOCKS.params + len(PARAM_COLUMNS)]
        self.delay_push = st[:, BLOCKS.delay_push : BLOCKS.delay_push + DELAY_LINE_LENGTH]
        self.delay_verbal = st[:, BLOCKS.delay_verbal : BLOCKS.delay_verbal + DELAY_LINE_LENGTH]
        self.report = st[:, BLOCKS.report : BLOCKS.report + len(REPORT_COLUMNS)]
        # The multiple-model bank's inputs of each substep, written by the step kernel.
        self._bank_force = st[:, BLOCKS.end : BLOCKS.end + substeps]
        self._bank_verbal = st[:, BLOCKS.end + substeps : BLOCKS.end + 2 * substeps]
        self._bank_position = st[:, BLOCKS.end + 2 * substeps : BLOCKS.end + 3 * substeps]
        # Each env's generator: a Generator object, or NumPy's PCG64 state in arrays for envs seeded
        # in a batch (seed_envs); rngs[i] gives env i's Generator either way.
        self.rngs = EnvGenerators(n)
        self.generators = self.rngs.rows
        self.cmd = np.zeros((n, len(CMD_COLUMNS)))
        self.cmd[:, CMD.active] = 1.0
        self.obs = np.zeros((n, n_obs), dtype=np.float32)
        self._all = np.arange(n, dtype=np.int64)
        self._draws = np.zeros((n, DRAWS.normals + n_varied))

    def _make_multiple_model(self, options: dict[str, Any]) -> Any:
        if self.estimator == "switching":
            from coop_gym.envs.switching import SwitchingEstimator

            # rngs: indexable as the list it types (EnvGenerators gives each env's Generator).
            rngs: Any = self.rngs
            return SwitchingEstimator(self.n_envs, self.timing, self.realism, self.params, rngs, options)
        from estimator.multiple_model import IMMEstimator, MultipleModelEstimator

        cls = IMMEstimator if self.estimator == "imm" else MultipleModelEstimator
        try:
            return cls(np.tile(self._persona_nominal[0], (self.n_envs, 1)), np.zeros(self.n_envs), **options)
        except TypeError as exc:  # an unknown option name
            raise ValueError(f"estimator_options for {self.estimator!r}: {exc}") from None

    @property
    def persona_index(self) -> NDArray[np.int64]:
        """(N,) index into ``personas`` of each env's current persona."""
        return self.report[:, REPORT.persona_index].astype(np.int64)

    # --- episodes -------------------------------------------------------------

    def set_threads(self, threads: int | None) -> None:
        """Step on up to ``threads`` threads (``None``: :func:`available_threads`); results do not depend on it."""
        self.threads = check_threads(threads)
        self._chunks = 0

    def _plan_chunks(self) -> int:
        """Threads per step (:func:`~coop_gym.envs.kernels.threads.plan_threads`), kept until they may change."""
        self._chunks = plan_threads(self.threads, self.n_envs, self.generators)
        return self._chunks

    def set_rng(self, i: int, rng: np.random.Generator) -> None:
        """Make ``rng`` env ``i``'s source of randomness (kept for its following episodes)."""
        if not self.rngs.is_object(i, rng):
            self.rngs.set(i, rng)
            self._chunks = 0

    def seed_envs(self, indices: NDArray[np.int64], seeds: NDArray[np.uint64]) -> None:
        """Env ``indices[r]`` draws from ``Generator(PCG64(seeds[r]))`` from now on, all seeded in one call.

        The same numbers as :meth:`set_rng` with those generators (``coop_gym.envs.kernels.seeding``); seeds up to
        ``coop_gym.envs.kernels.seeding.MAX_BATCH_SEED``.
        """
        self.rngs.seed(indices, seeds)
        self._chunks = 0

    def reset_env(
        self, i: int, rng: np.random.Generator, persona_index: int | None = None, initial_xi: int | None = None
    ) -> None:
        """Start a new episode in env ``i``, drawing its person from ``rng``.

        Args:
            i: Env index.
            rng: The env's generator; kept for the episode's step noise.
            persona_index: Use this persona (index into ``personas``) instead of drawing one.
            initial_xi: Start at this cooperativeness instead of drawing it.
        """
        self.set_rng(i, rng)
        self.reset_envs(self._all[i : i + 1], persona_index, initial_xi)

    def reset_envs(
        self, indices: NDArray[np.int64], persona_index: int | None = None, initial_xi: int | None = None
    ) -> None:
        """Start new episodes in envs ``indices`` (int64 array), each drawing from its own generator.

        The same draws happen whatever is fixed, so fixing the persona or ``initial_xi``
        shifts nothing else in the random stream.
        """
        count = indices.shape[0]
        if count == 0:
            return
        draws = self._draws[:count]
        override = NO_OVERRIDE if persona_index is None else persona_index
        failed = draw_reset(indices, self.generators, len(self.personas), override, draws)
        if failed >= 0:
            raise RuntimeError(_no_generator_message(failed))
        # The variation factors exp(std * z) with NumPy's exp, not a compiled one: NumPy's SIMD
        # exp can differ in the last bit, and the person must equal sample_person's exactly.
        factors = draws[:, DRAWS.normals :]
        std = self._variation_std
        if std is None:
            std = self._persona_variation_std[draws[:, DRAWS.persona].astype(np.int64)][:, None]
        np.multiply(factors, std, out=factors)
        np.exp(factors, out=factors)
        start_episodes(
            indices,
            NO_OVERRIDE if initial_xi is None else initial_xi,
            draws,
            self.persona_table,
            self.state,
            self.obs,
            self.consts,
        )
        if self.mm is not None:
            # The persona (and so the nominal model) may change from episode to episode.
            self.mm.nominal[indices] = self.nominal[indices]
            self.mm.reset(indices, draws[:, DRAWS.lean])
            self.report[indices, REPORT.p_uncooperative : REPORT.p_cooperative + 1] = self.mm.probabilities[indices]
            observe(indices, self.state, self.obs, self.consts)

    # --- stepping -------------------------------------------------------------

    def step_commands(self, cmd: NDArray[np.float64], reset: NDArray[np.int64] | None = None) -> None:
        """Advance the active envs by one agent action; results land in ``report`` and ``obs``.

        Args:
            cmd: (N, 4) float64 C-contiguous rows ``[push_force_n, verbal_cue, lift, active]``
                (decoded and validated); envs with ``active == 0`` are left untouched.
            reset: Envs to start new episodes in during the same call (int64 indices, none of
                them active in ``cmd``): the same as :meth:`reset_envs` after the step, since the
                two touch different envs and each env draws from its own generator, but on a
                threaded step the reset overlaps the workers' stepping.
        """
        chunks = self._chunks or self._plan_chunks()
        if reset is not None:
            # Checked before anything changes.
            if (cmd[reset, CMD.active] > 0.5).any():
                raise ValueError("step_commands: an env can't be both stepped and reset in one call")
            missing = reset[self.generators[reset, G_STATE] == 0]
            if missing.shape[0]:
                raise RuntimeError(_no_generator_message(int(missing[0])))
            if reset.shape[0] == 0:
                reset = None
            elif self.mm is not None:
                chunks = 1  # the bank's reset must follow its run over the stepped envs' inputs
        if chunks > 1:
            failed = first_unready(cmd, self.generators)
            if failed < 0:
                arrays = (cmd, self.state, self.generators, self.obs, self.consts)
                resets = reset
                step_threaded(
                    chunks, self._control, arrays, None if resets is None else lambda: self.reset_envs(resets)
                )
                reset = None
        else:
            failed = step_all(cmd, self.state, self.generators, self.obs, self.consts)
        if failed >= 0:
            raise RuntimeError(f"env {failed} was stepped before it was reset")
        if self.mm is not None:
            probabilities = self.mm.run(self._bank_force, self._bank_verbal, self._bank_position)
            self.report[:, REPORT.p_uncooperative : REPORT.p_cooperative + 1] = probabilities[:, -1]
            observe(self._all, self.state, self.obs, self.consts)
        if reset is not None:
            self.reset_envs(reset)

    # --- pickling -----------------------------------------------------------------
    # ``generators`` holds raw addresses of the generators' C states and ``person``, ``P``,
    # ``report`` ... are views into ``state``: a pickled copy would go on drawing from (and
    # advancing) the original's generators -- or freed memory in another process -- and its
    # views would no longer alias ``state``. So a copy is rebuilt by the constructor and
    # refilled with the saved values (tests/coop_gym/test_determinism.py).

    def __getstate__(self) -> dict[str, Any]:
        """The saved values; ``generators`` is left out (rebuilt from ``rngs``, saved as Generator objects)."""
        saved = {k: v for k, v in self.__dict__.items() if k not in ("generators", "rngs")}
        saved["rngs"] = list(self.rngs)
        return saved

    def __setstate__(self, saved: dict[str, Any]) -> None:
        """Rebuild the arrays and their views, then copy the saved values into them."""
        saved = dict(saved)
        rngs = saved.pop("rngs")
        self.__init__(*saved["_init_args"])  # type: ignore[misc]
        for name, value in saved.items():
            current = self.__dict__.get(name)
            if isinstance(value, np.ndarray) and isinstance(current, np.ndarray) and current.shape == value.shape:
                np.copyto(current, value)
            elif not (dataclasses.is_dataclass(current) and not isinstance(current, type)):
                self.__dict__[name] = value  # dataclasses (the settings) are rebuilt equal by __init__
        for i, rng in enumerate(rngs):
            if rng is not None:
                self.rngs.set(i, rng)
        self._chunks = 0


_OUTCOME_LABELS: tuple[str, ...] = tuple(o.label for o in Outcome)


def make_core(config: SitToStandConfig, n_envs: int) -> SitToStandCore:
    """The batched simulation of ``n_envs`` envs of ``config``, building its physical observation.

    The core's ``obs`` holds the features in their units; the envs scale them with ``config.observer()``.
    """
    space = config.physical_observation_space()
    return SitToStandCore(
        n_envs,
        config.personas,
        config.timing,
        config.cues,
        config.realism,
        config.lift,
        config.reward,
        config.judgment,
        config.estimator,
        config.estimator_options,
        observation_index=tuple(FEATURES.index(f) for f in config.physical_features),
        observation_low=space.low.astype(np.float64),
        observation_high=space.high.astype(np.float64),
    )


def render_state_for(core: SitToStandCore, i: int, outcome: int, lift: bool, stepped: bool) -> Any:
    """A :class:`coop_gym.envs.render.renderer.RenderState` of env ``i`` of ``core``.

    Args:
        core: The simulation.
        i: Env index.
        outcome: The env's current :class:`Outcome` code.
        lift: Whether the env's last action lifted.
        stepped: False right after a reset (no push is drawn then).
    """
    from coop_gym.envs.render.renderer import RenderState

    r = core.report[i]
    probs = None
    if core.mm is not None:
        probs = (
            float(r[REPORT.p_uncooperative]),
            float(r[REPORT.p_unresponsive]),
            float(r[REPORT.p_cooperative]),
        )
    return RenderState(
        time_s=float(r[REPORT.elapsed_s]),
        shoulder_position_m=float(r[REPORT.true_x_m]),
        push_force_n=float(r[REPORT.push_force_n]) if stepped else 0.0,
        verbal_cue=int(r[REPORT.verbal_cue]),
        xi_estimate=float(r[REPORT.xi_hat]),
        xi_std=float(r[REPORT.xi_std]),
        threshold=float(core.judgment.threshold),
        judgment=int(r[REPORT.judgment]),
        true_xi=int(r[REPORT.info_true_xi]),
        outcome=_OUTCOME_LABELS[outcome] if outcome != Outcome.NONE else None,
        probabilities=probs,
        lift=lift,
        success_lean_m=float(core.lift.success_lean_m),
    )


class ConfiguredEnv:
    """What the single and the vector env take from their :class:`~coop_gym.envs.arguments.SitToStandConfig`.

    The settings clients read (``config``, ``render_mode``, ``observation_mode``, ``action_type``,
    ``personas``, ``timing``, ``cues``, ``features``), the simulation ``core`` of the batch, and the
    action decoder, observer and info builder every step calls.
    """

    config: SitToStandConfig
    render_mode: str | None
    observation_mode: str
    action_type: str
    personas: tuple[Persona, ...]
    timing: Timing
    cues: Cues
    features: tuple[str, ...]
    core: SitToStandCore

    def _take_config(self, config: SitToStandConfig, n_envs: int) -> None:
        """Hold ``config``'s settings and build a core of ``n_envs`` envs and the step's helpers."""
        self.config = config
        self.render_mode = config.render_mode
        self.observation_mode = config.observation_mode
        self.action_type = config.action_type
        self.personas = config.personas
        self.timing = config.timing
        self.cues = config.cues
        self.features = config.features
        self.core = make_core(config, n_envs)
        self._actions = ActionDecoder(config.action_type, config.cues)
        self._observe = config.observer()
        self._info = InfoBuilder(config)
