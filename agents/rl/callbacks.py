"""What SB3 training reports while it runs: TensorBoard under CleanRL's names, outcome rates, evaluations.

* :class:`CleanRLTensorBoard` / :func:`cleanrl_logger` -- SB3's scalars filed under
  ``charts/`` and ``losses/`` (the house style, as CleanRL names them).
* :class:`OutcomeStatsCallback` -- outcome rates of recent training episodes.
* :class:`PeriodicEvalCallback` -- the current policy scored through the one evaluation
  path every so many env steps (the learning curve; it never selects a model).
* :class:`SelectionCallback` -- the policy scored on validation episodes (the training personas'
  or the validation people's) in the last half of training; the best-scoring policy becomes the saved model.
"""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import KVWriter, Logger, TensorBoardOutputFormat

from agents.rl.bundle import SB3Agent, read_bundle, save_model_bundle
from agents.rl.normalize import ObsNormalizer
from agents.rl.training import find_frame_stack, find_vec_normalize
from coop_gym.envs.config import Outcome

__all__ = [
    "SELECTION_PERSONAS",
    "VALIDATION_PERSONAS",
    "VALIDATION_SEED",
    "CleanRLTensorBoard",
    "OutcomeStatsCallback",
    "PeriodicEvalCallback",
    "SelectionCallback",
    "cleanrl_logger",
]

VALIDATION_PERSONAS = "train"
"""The people a policy is selected on by default: the training personas (never the held-out ones)."""
SELECTION_PERSONAS: tuple[str, ...] = ("train", "validation")
"""The people a policy may be selected on: the training personas' validation episodes, or the
validation people (:func:`coop_gym.model.personas.validation_people`), whom no training episode shows."""
VALIDATION_SEED = 2_000_000
"""Seed of validation episode 0: episodes apart from the evaluation's (``--eval-seed`` 0 ..)."""


# SB3 logs under rollout/, train/, time/; the house style (CleanRL) puts scalars under
# charts/ and losses/. Keys not listed are kept as they are (e.g. eval/...).
_RENAMES = {
    "rollout/ep_rew_mean": "charts/episodic_return",
    "rollout/ep_len_mean": "charts/episodic_length",
    "rollout/exploration_rate": "charts/exploration_rate",
    "time/fps": "charts/SPS",
    "train/learning_rate": "charts/learning_rate",
}
_DROPPED = {"time/iterations", "time/time_elapsed", "time/total_timesteps", "time/episodes"}


def _renamed(key: str) -> str | None:
    if key in _DROPPED:
        return None
    if key in _RENAMES:
        return _RENAMES[key]
    if key.startswith("train/"):
        return "losses/" + key.removeprefix("train/")
    if key.startswith("rollout/"):
        return "charts/" + key.removeprefix("rollout/")
    return key


class CleanRLTensorBoard(TensorBoardOutputFormat):
    """TensorBoard writer that files SB3's scalars under ``charts/`` and ``losses/`` (CleanRL names)."""

    def write(self, key_values: dict[str, Any], key_excluded: dict[str, tuple[str, ...]], step: int = 0) -> None:
        """Rename the keys, then write as SB3 does."""
        values: dict[str, Any] = {}
        excluded: dict[str, tuple[str, ...]] = {}
        for key, value in key_values.items():
            new = _renamed(key)
            if new is not None:
                values[new] = value
                excluded[new] = key_excluded.get(key, ())
        super().write(values, excluded, step)


def cleanrl_logger(folder: str | Path, extra: list[KVWriter] | None = None) -> Logger:
    """An SB3 ``Logger`` writing TensorBoard events (CleanRL key names) into ``folder``."""
    Path(folder).mkdir(parents=True, exist_ok=True)
    return Logger(str(folder), [CleanRLTensorBoard(str(folder)), *(extra or [])])


class OutcomeStatsCallback(BaseCallback):
    """Logs the outcome rates of recent training episodes (``charts/success_rate`` ...).

    Args:
        window: Number of most recent finished episodes the rates are computed over.
    """

    def __init__(self, window: int = 200) -> None:
        """Keep a window of recent outcomes."""
        super().__init__()
        self.window = window
        self.outcomes: list[str] = []

    def _on_step(self) -> bool:
        dones = self.locals.get("dones")
        infos = self.locals.get("infos", [])
        if dones is None:
            return True
        for done, info in zip(dones, infos, strict=False):
            if done and "outcome" in info:
                self.outcomes.append(str(info["outcome"]))
        del self.outcomes[: -self.window]
        return True

    def _on_rollout_end(self) -> None:
        if not self.outcomes:
            return
        for outcome in (o.label for o in Outcome if o is not Outcome.NONE):
            self.logger.record(f"charts/{outcome}_rate", self.outcomes.count(outcome) / len(self.outcomes))


class PeriodicEvalCallback(BaseCallback):
    """Scores the current policy with :func:`agents.evaluate.evaluate` every ``every`` env steps.

    The scores feed the learning curve and TensorBoard (``eval/...``); they never select
    a model, so evaluating on held-out personas here does not leak into training.

    Args:
        algo: Algorithm name (for the agent wrapper).
        env_id: Env id to evaluate on.
        personas: Persona set.
        episodes: Episodes per evaluation.
        seed: Seed of episode 0 of every evaluation (the same episodes each time).
        every: Evaluate whenever this many env steps have passed.
        start_steps: Step count training starts from (a resumed model's).
    """

    def __init__(
        self, algo: str, env_id: str, personas: Any, episodes: int, seed: int, every: int, start_steps: int = 0
    ) -> None:
        """Store the settings; evaluations happen during ``learn``."""
        super().__init__()
        self.algo, self.env_id, self.personas = algo, env_id, personas
        self.episodes, self.seed, self.every = episodes, seed, max(1, every)
        self.history: list[dict[str, Any]] = []
        self._next = start_steps + self.every

    def state(self) -> dict[str, Any]:
        """The scores so far and the step the next evaluation is due (what a checkpoint keeps)."""
        return {"history": copy.deepcopy(self.history), "next": self._next}

    def restore(self, state: dict[str, Any]) -> None:
        """Continue from :meth:`state`."""
        self.history, self._next = copy.deepcopy(state["history"]), state["next"]

    def due(self, num_timesteps: int) -> bool:
        """Whether an evaluation is due at ``num_timesteps``."""
        return num_timesteps >= self._next

    def _on_step(self) -> bool:
        if self.due(self.num_timesteps):
            self._next = (self.num_timesteps // self.every + 1) * self.every
            self.evaluate_now()
        return True

    def evaluate_now(self) -> dict[str, Any]:
        """Run one evaluation and log it."""
        from agents.evaluate import evaluate

        agent = _current_policy(self.model, self.algo, self.env_id)
        result = evaluate(agent, self.env_id, self.personas, self.episodes, self.seed, n_envs=min(64, self.episodes))
        point = {"timesteps": int(self.num_timesteps), **result.summary()}
        self.history.append(point)
        for key in ("success_rate", "unsafe_rate", "premature_rate", "timeout_rate", "mean_return"):
            self.logger.record(f"eval/{key}", point[key])
        if point["mean_time_to_lift_s"] is not None:
            self.logger.record("eval/mean_time_to_lift_s", point["mean_time_to_lift_s"])
        return point


class SelectionCallback(BaseCallback):
    """Keeps the policy that scores best on validation episodes.

    From half-way through training, at ``points`` rollout starts ``every`` env steps apart
    (and once more on the final policy, :meth:`finish`), the policy plays the same
    ``episodes`` validation episodes: of ``personas`` (the training personas, or the
    validation people), seeds :data:`VALIDATION_SEED` onwards -- never the held-out personas. Each policy that scores at
    least as well as the best so far is saved to ``folder/best_step_N.zip`` (with its
    observation statistics). PPO's held-out success moves between policies of one run a few
    hundred thousand steps apart, its success on the training personas by less (docs/agents.md,
    "Which policy is saved"; every candidate's scores: ``python bench/learners.py --people``,
    ``bench/results/selection_people.json``); the best validated one is the saved model.

    Scoring does not touch training: the episodes run in their own envs and the policy acts
    deterministically, so the weights trained are those of a run without selection.

    Args:
        folder: Where the best policies are saved (the run's checkpoints folder).
        algo: Algorithm name (stored in the saved zips).
        env_id: Env id trained on and validated on.
        episodes: Validation episodes per score.
        points: Scores before the final policy's.
        start: Env step of the first score.
        every: Env steps between scores.
        env_kwargs: Env kwargs the policy is trained with beyond the id's own (e.g.
            ``estimator="switching"``): the validation episodes are played with them.
        personas: The people selected on: :data:`VALIDATION_PERSONAS`, or ``"validation"``,
            the validation people (:func:`coop_gym.model.personas.validation_people`); never the held-out ones.
        recorded: ``{name: (personas, episodes, seed)}``: sets every scored policy also plays,
            their rates recorded in its score under ``name`` and never used to select (a
            benchmark measures how well the selecting set predicts them).
    """

    def __init__(
        self,
        folder: str | Path,
        algo: str,
        env_id: str,
        episodes: int,
        points: int,
        start: int,
        every: int,
        env_kwargs: dict[str, Any] | None = None,
        personas: str = VALIDATION_PERSONAS,
        recorded: dict[str, tuple[str, int, int]] | None = None,
    ):
        """Store the settings; scores happen during ``learn`` and in :meth:`finish`."""
        super().__init__()
        if personas not in SELECTION_PERSONAS:
            raise ValueError(f"SelectionCallback.personas must be one of {list(SELECTION_PERSONAS)}, got {personas!r}")
        self.env_kwargs, self.personas, self.recorded = dict(env_kwargs or {}), personas, dict(recorded or {})
        self.folder, self.algo, self.env_id = Path(folder), algo, env_id
        self.episodes, self.points, self.every = episodes, points, max(1, every)
        self.history: list[dict[str, Any]] = []
        self._next = start

    def state(self) -> dict[str, Any]:
        """What a checkpoint keeps to continue the selection (:meth:`restore`)."""
        return {"history": copy.deepcopy(self.history), "next": self._next}

    def restore(self, state: dict[str, Any]) -> None:
        """Continue the selection a checkpoint's :meth:`state` describes."""
        self.history, self._next = copy.deepcopy(state["history"]), state["next"]

    def due(self, num_timesteps: int) -> bool:
        """Whether a rollout starting at ``num_timesteps`` is scored."""
        return len(self.history) < self.points and num_timesteps >= self._next

    def _on_rollout_start(self) -> None:
        if self.due(self.num_timesteps):
            self._next = self.num_timesteps + self.every
            self._score(save=True)

    def _on_step(self) -> bool:
        return True

    def _score(self, save: bool) -> dict[str, Any]:
        """Play the validation episodes with the current policy; save it if it is the best so far."""
        from agents.evaluate import evaluate

        agent = _current_policy(self.model, self.algo, self.env_id)
        result = evaluate(agent, self.env_id, self.personas, self.episodes, VALIDATION_SEED, env_kwargs=self.env_kwargs)
        point: dict[str, Any] = {"timesteps": int(self.num_timesteps), "success_rate": result.success_rate}
        for name, (personas, episodes, seed) in self.recorded.items():
            other = evaluate(agent, self.env_id, personas, episodes, seed, env_kwargs=self.env_kwargs)
            point[name] = {"success_rate": other.success_rate, "unsafe_rate": other.unsafe_rate}
        if save and all(point["success_rate"] >= p["success_rate"] for p in self.history):
            vec_normalize = find_vec_normalize(self.model.get_env())
            path = self.saved_path(point["timesteps"])
            save_model_bundle(self.model, path, algo=self.algo, env_id=self.env_id, vec_normalize=vec_normalize)
        self.history.append(point)
        self.logger.record("eval/validation_success_rate", point["success_rate"])
        return point

    def finish(self, model: Any) -> dict[str, Any]:
        """Score the final policy; if an earlier one scored higher, load it into ``model``.

        Returns the selection's record: the policy kept (its step), every score, and where
        the validation episodes come from. Ties go to the later policy.
        """
        self.model = model
        self.num_timesteps = int(model.num_timesteps)
        final = self._score(save=False)
        best = max(reversed(self.history), key=lambda p: p["success_rate"])
        if best is not final:
            _load_policy(model, self.saved_path(best["timesteps"]))  # the best so far when scored: saved
        return {
            "timesteps": best["timesteps"],
            "validation_success_rate": best["success_rate"],
            "final_timesteps": final["timesteps"],
            "personas": self.personas,
            "episodes": self.episodes,
            "seed": VALIDATION_SEED,
            "scores": [dict(p) for p in self.history],
        }

    def saved_path(self, timesteps: int) -> Path:
        """Where the policy scored at ``timesteps`` was saved (if it was the best so far)."""
        return self.folder / f"best_step_{timesteps:012d}.zip"


def _current_policy(model: Any, algo: str, env_id: str) -> SB3Agent:
    """The model's policy as it is now, with the training env's current observation statistics."""
    env = model.get_env()
    normalizer = ObsNormalizer.from_vec_normalize(find_vec_normalize(env))
    return SB3Agent(model, algo, env_id, normalizer, frame_stack=find_frame_stack(env))


def _load_policy(model: Any, path: Path) -> None:
    """Load the policy (weights, observation statistics, step count) saved at ``path`` into ``model``."""
    info, stats = read_bundle(path)
    model.set_parameters(str(path), exact_match=True, device="cpu")
    vec_normalize = find_vec_normalize(model.get_env())
    if vec_normalize is not None and stats is not None:
        vec_normalize.obs_rms = stats.obs_rms
    model.num_timesteps = int(info["num_timesteps"])
