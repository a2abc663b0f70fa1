"""Learned agents: SB3 PPO, sb3-contrib RecurrentPPO and SB3 DQN on the coop_gym envs.

* :func:`make_train_env` -- the training ``VecEnv`` (batched env through the SB3 adapter
  when available, else one Gymnasium env per slot), with episode statistics
  (``VecMonitor``) and optional observation normalisation (``VecNormalize``).
* :func:`make_model` -- the algorithm with the defaults of :mod:`agents.hyperparams`.
* :func:`save_agent` / :func:`load_agent` -- ``model.zip`` is self-contained: besides SB3's
  members it holds ``coop_gym/agent.json`` (algorithm, env id, observation feature names,
  coop_gym version, step count) and ``coop_gym/vecnormalize.pkl`` (the observation
  statistics, if observations were normalised), so a lone copy of the file loads and scores
  as trained. The folder also gets ``vecnormalize.pkl`` and ``agent.json`` beside it (what
  older run folders hold; they still load). :func:`load_agent` returns an :class:`SB3Agent`,
  which follows the same ``predict`` protocol as the scripted agents and applies the saved
  normalisation, so :func:`agents.evaluate.evaluate` scores it like any other agent.
  RecurrentPPO's LSTM state travels in ``state`` and is reset by ``episode_start``. Every
  file is written atomically (:mod:`coop_gym.io`).

Example:
    >>> from agents.rl import make_train_env, make_model
    >>> from agents.hyperparams import hyperparams_for
    >>> config = hyperparams_for("ppo")
    >>> env = make_train_env(config.env_id, n_envs=2, seed=0, normalize=True)
    >>> model = make_model(config, env, seed=0)
    >>> type(model).__name__
    'PPO'
    >>> env.close()
"""

from __future__ import annotations

import json
import pickle
import random
import shutil
import warnings
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray
from stable_baselines3 import DQN, PPO
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import KVWriter, Logger, TensorBoardOutputFormat
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv, VecMonitor, VecNormalize

import coop_gym  # registers the env ids
from agents.hyperparams import ALGORITHMS, TrainingConfig
from coop_gym.envs.config import Outcome
from coop_gym.io import atomic_path, write_bytes, write_json

__all__ = [
    "AGENT_FILE",
    "BUNDLE_INFO",
    "BUNDLE_VECNORMALIZE",
    "CHECKPOINTS_DIR",
    "MODEL_FILE",
    "VECNORMALIZE_FILE",
    "CheckpointCallback",
    "CleanRLTensorBoard",
    "LinearDecay",
    "ObsNormalizer",
    "OutcomeStatsCallback",
    "PeriodicEvalCallback",
    "SB3Agent",
    "TrainingInterrupted",
    "algorithm_class",
    "cleanrl_logger",
    "find_vec_normalize",
    "latest_checkpoint",
    "load_agent",
    "load_model",
    "make_model",
    "make_train_env",
    "observation_features",
    "read_bundle",
    "restore_checkpoint",
    "save_agent",
    "save_checkpoint",
    "save_model_bundle",
    "vec_env_backend",
]

MODEL_FILE = "model.zip"
VECNORMALIZE_FILE = "vecnormalize.pkl"
AGENT_FILE = "agent.json"
CHECKPOINTS_DIR = "checkpoints"
BUNDLE_INFO = "coop_gym/agent.json"
"""Member of ``model.zip`` with the metadata (SB3 ignores members it does not know)."""
BUNDLE_VECNORMALIZE = "coop_gym/vecnormalize.pkl"
"""Member of ``model.zip`` with the pickled ``VecNormalize`` (statistics only, no env)."""


def algorithm_class(algo: str) -> type[BaseAlgorithm]:
    """The SB3 class of an algorithm name (:data:`agents.hyperparams.ALGORITHMS`)."""
    if algo == "ppo":
        return PPO
    if algo == "dqn":
        return DQN
    if algo == "recurrent_ppo":
        from sb3_contrib import RecurrentPPO

        return RecurrentPPO  # type: ignore[no-any-return]
    raise ValueError(f"unknown algorithm {algo!r}; known: {', '.join(ALGORITHMS)}")


def vec_env_backend() -> Callable[..., VecEnv] | None:
    """``agents.sb3_vec.make_sb3_vec_env`` when the batched adapter is installed, else None."""
    try:
        from agents.sb3_vec import make_sb3_vec_env
    except ImportError:
        return None
    return make_sb3_vec_env  # type: ignore[no-any-return]


def make_train_env(
    env_id: str,
    n_envs: int,
    seed: int,
    *,
    personas: str = "train",
    normalize: bool = False,
    monitor_file: str | Path | None = None,
    monitor_append: bool = False,
    env_kwargs: dict[str, Any] | None = None,
    backend: str = "auto",
) -> VecEnv:
    """The training ``VecEnv``: ``n_envs`` envs seeded ``seed, seed + 1, ...``.

    Args:
        env_id: Registered env id.
        n_envs: Parallel envs.
        seed: Seed of env 0.
        personas: Persona set (``"train"`` by default; never train on ``"test"``).
        normalize: Wrap in ``VecNormalize`` (observations only).
        monitor_file: Write SB3's ``monitor.csv`` episode log here (for learning curves).
        monitor_append: Append to an existing ``monitor_file`` (a resumed run) instead of replacing it.
        env_kwargs: Extra env kwargs.
        backend: ``"batched"`` (the native vector env through ``agents.sb3_vec``),
            ``"dummy"`` (SB3 ``DummyVecEnv`` of single envs) or ``"auto"`` (batched when
            available).

    Returns:
        The ``VecEnv`` (``VecMonitor``-wrapped; ``VecNormalize`` outermost if asked).
    """
    if isinstance(n_envs, bool) or not isinstance(n_envs, int) or n_envs < 1:
        raise ValueError(f"n_envs must be a positive int, got {n_envs!r}")
    if backend not in ("auto", "batched", "dummy"):
        raise ValueError(f"backend must be 'auto', 'batched' or 'dummy', got {backend!r}")
    kwargs = {"personas": personas, **(env_kwargs or {})}
    batched = vec_env_backend() if backend != "dummy" else None
    if backend == "batched" and batched is None:
        raise ValueError("backend='batched' needs agents.sb3_vec (SB3VecEnvAdapter), which is not available")
    venv: VecEnv
    if batched is not None:
        venv = batched(env_id, n_envs, seed, kwargs)
    else:
        venv = DummyVecEnv([_env_factory(env_id, kwargs) for _ in range(n_envs)])
        venv.seed(seed)
    filename = None
    if monitor_file is not None:
        Path(monitor_file).parent.mkdir(parents=True, exist_ok=True)
        filename = str(monitor_file)
    append = monitor_append and filename is not None and Path(str(filename)).exists()
    venv = VecMonitor(venv, filename=None if append else filename, info_keywords=("outcome",))
    if append:
        from stable_baselines3.common.monitor import ResultsWriter

        # VecMonitor always starts a new file; a resumed run keeps its episodes and adds rows.
        venv.results_writer = ResultsWriter(str(filename), extra_keys=("outcome",), override_existing=False)
    if normalize:
        venv = VecNormalize(venv, norm_obs=True, norm_reward=False)
    return venv


def _env_factory(env_id: str, kwargs: dict[str, Any]) -> Callable[[], gym.Env[Any, Any]]:
    return lambda: gym.make(env_id, **kwargs)


class LinearDecay:
    """A value falling linearly from ``initial`` to 0 over training (RL Zoo's ``lin_<value>``).

    A class rather than a lambda so saved models pickle and load cleanly.
    """

    def __init__(self, initial: float) -> None:
        """Start at ``initial``."""
        self.initial = float(initial)

    def __call__(self, progress_remaining: float) -> float:
        """SB3 passes the fraction of training left (1 -> 0)."""
        return progress_remaining * self.initial

    def __repr__(self) -> str:
        """As RL Zoo writes it."""
        return f"lin_{self.initial:g}"


def _schedules(kwargs: dict[str, Any]) -> dict[str, Any]:
    """Turn RL Zoo schedule strings (``"lin_3e-4"``) into :class:`LinearDecay` objects."""
    out = dict(kwargs)
    for key in ("learning_rate", "clip_range", "clip_range_vf"):
        value = out.get(key)
        if isinstance(value, str):
            kind, _, number = value.partition("_")
            if kind != "lin":
                raise ValueError(f"{key}={value!r}: only linear schedules 'lin_<value>' are supported")
            out[key] = LinearDecay(float(number))
    return out


def make_model(
    config: TrainingConfig,
    env: VecEnv,
    seed: int,
    *,
    tensorboard_log: str | Path | None = None,
    verbose: int = 0,
    overrides: dict[str, Any] | None = None,
) -> BaseAlgorithm:
    """Build ``config.algo`` on ``env`` with the config's hyperparameters (plus ``overrides``)."""
    cls = algorithm_class(config.algo)
    kwargs = _schedules(config.model_kwargs() | dict(overrides or {}))
    return cls(
        config.policy,
        env,
        seed=seed,
        verbose=verbose,
        device="cpu",
        tensorboard_log=str(tensorboard_log) if tensorboard_log is not None else None,
        **kwargs,
    )


def find_vec_normalize(env: VecEnv | None) -> VecNormalize | None:
    """The ``VecNormalize`` layer of a wrapped ``VecEnv`` (None if there is none)."""
    while env is not None:
        if isinstance(env, VecNormalize):
            return env
        env = getattr(env, "venv", None)
    return None


def observation_features(env_id: str, env: VecEnv | None = None) -> list[str]:
    """The observation feature names of ``env`` (a training ``VecEnv``) or of a fresh ``env_id`` env."""
    from agents.base import features_of

    if env is not None:
        try:
            return [str(f) for f in env.get_attr("features", indices=[0])[0]]
        except (AttributeError, IndexError):
            pass
    single = gym.make(env_id)
    try:
        return list(features_of(single))
    finally:
        single.close()


def save_model_bundle(
    model: BaseAlgorithm,
    path: str | Path,
    *,
    algo: str,
    env_id: str,
    vec_normalize: VecNormalize | None = None,
) -> dict[str, Any]:
    """Save ``model`` to ``path`` (a zip) with its metadata and normaliser inside; returns the metadata.

    The file appears only once complete (written under a temporary name, then renamed).
    """
    info = {
        "algo": algo,
        "env_id": env_id,
        "features": observation_features(env_id, model.get_env()),
        "num_timesteps": int(model.num_timesteps),
        "coop_gym_version": coop_gym.__version__,
        "normalized": vec_normalize is not None,
    }
    with atomic_path(path) as temp:
        model.save(temp)
        with zipfile.ZipFile(temp, "a", compression=zipfile.ZIP_DEFLATED) as archive:
            archive.writestr(BUNDLE_INFO, json.dumps(info, indent=2) + "\n")
            if vec_normalize is not None:
                archive.writestr(BUNDLE_VECNORMALIZE, pickle.dumps(vec_normalize))
    return info


def save_agent(model: BaseAlgorithm, folder: str | Path, *, algo: str, env_id: str) -> Path:
    """Save ``model`` (its ``VecNormalize`` statistics and metadata inside) into ``folder``; returns the model path.

    ``vecnormalize.pkl`` and ``agent.json`` are also written beside ``model.zip``, as older
    versions did (``VecNormalize.load`` reads the former when training resumes).
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    model_path = folder / MODEL_FILE
    vec_normalize = find_vec_normalize(model.get_env())
    info = save_model_bundle(model, model_path, algo=algo, env_id=env_id, vec_normalize=vec_normalize)
    if vec_normalize is not None:
        write_bytes(folder / VECNORMALIZE_FILE, pickle.dumps(vec_normalize))
    info |= {"model": MODEL_FILE, "vecnormalize": VECNORMALIZE_FILE if vec_normalize is not None else None}
    write_json(folder / AGENT_FILE, info)
    return model_path


def read_bundle(model_path: str | Path) -> tuple[dict[str, Any], VecNormalize | None]:
    """The metadata and normaliser stored inside a model zip (``({}, None)`` for a plain SB3 zip).

    Raises:
        ValueError: the file is not a zip archive (empty, truncated, another format) or its
            members are unreadable.
    """
    model_path = Path(model_path)
    try:
        with zipfile.ZipFile(model_path) as archive:
            names = set(archive.namelist())
            if "data" not in names:
                raise ValueError(f"could not load {model_path}: a zip but not a Stable-Baselines3 model (no 'data')")
            info = json.loads(archive.read(BUNDLE_INFO)) if BUNDLE_INFO in names else {}
            stats = pickle.loads(archive.read(BUNDLE_VECNORMALIZE)) if BUNDLE_VECNORMALIZE in names else None
    except zipfile.BadZipFile as exc:
        size = model_path.stat().st_size
        what = "the file is empty" if size == 0 else f"not a complete zip archive ({size} bytes: {exc})"
        raise ValueError(f"could not load {model_path}: {what}") from None
    except (OSError, EOFError, json.JSONDecodeError, pickle.UnpicklingError, zipfile.LargeZipFile) as exc:
        raise ValueError(f"could not load {model_path}: damaged archive ({type(exc).__name__}: {exc})") from None
    if not isinstance(info, dict):
        raise ValueError(f"{model_path}: {BUNDLE_INFO} is not a JSON object")
    if stats is not None and not isinstance(stats, VecNormalize):
        raise ValueError(f"{model_path}: {BUNDLE_VECNORMALIZE} holds a {type(stats).__name__}, not a VecNormalize")
    return info, stats


def _resolve(path: str | Path) -> tuple[Path, dict[str, Any]]:
    """The model file and its metadata: the bundle's, else the ``agent.json`` beside it (empty if neither)."""
    path = Path(path)
    if path.is_dir():
        path = path / MODEL_FILE
    if not path.exists() and path.with_suffix(".zip").exists():
        path = path.with_suffix(".zip")
    if not path.exists():
        raise FileNotFoundError(f"no saved model at {path}")
    info, _ = read_bundle(path)
    if info:
        return path, info
    info_path = path.parent / AGENT_FILE
    if not info_path.exists():
        return path, {}
    try:
        info = json.loads(info_path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"{info_path}: not valid JSON ({exc})") from None
    if not isinstance(info, dict) or not isinstance(info.get("algo", ""), str):
        raise ValueError(f"{info_path}: expected a JSON object with a string 'algo'")
    if info.get("algo") and info["algo"] not in ALGORITHMS:
        raise ValueError(f"{info_path}: unknown algo {info['algo']!r}; known: {', '.join(ALGORITHMS)}")
    return path, info


def _algo_from_zip(model_path: Path) -> str | None:
    """The algorithm of an SB3 zip without ``agent.json`` (e.g. RL Zoo's), from its policy class's module.

    Trying the classes in turn is not enough: ``PPO.load`` accepts a RecurrentPPO file.
    """
    import zipfile

    try:
        with zipfile.ZipFile(model_path) as archive:
            data = json.loads(archive.read("data"))
        module = str(data["policy_class"]["__module__"])
    except (OSError, KeyError, ValueError, zipfile.BadZipFile):
        return None
    if module.startswith("sb3_contrib.common.recurrent"):
        return "recurrent_ppo"
    if module.startswith("stable_baselines3.dqn"):
        return "dqn"
    if module.startswith("stable_baselines3.common.policies"):
        return "ppo"
    return None


def load_model(path: str | Path, env: VecEnv | None = None, **kwargs: Any) -> tuple[BaseAlgorithm, dict[str, Any]]:
    """Load a saved model (algorithm from ``agent.json``, else tried in turn) and its metadata."""
    model_path, info = _resolve(path)
    guess = info.get("algo") or _algo_from_zip(model_path)
    algos = [guess] if guess else list(ALGORITHMS)
    errors = []
    for algo in algos:
        try:
            with warnings.catch_warnings():
                # A saved n-step DQN reloads its NStepReplayBuffer with n_steps and gamma in
                # replay_buffer_kwargs; SB3 still warns that n_steps "is ignored" (it is not).
                warnings.filterwarnings("ignore", message=r"`n_steps=\d+` is ignored", category=UserWarning)
                model = algorithm_class(algo).load(model_path, env=env, device="cpu", **kwargs)
        except Exception as exc:  # a wrong class fails in many ways; try the next
            errors.append(f"{algo}: {exc}")
            continue
        return model, info | {"algo": algo}
    raise ValueError(f"could not load {model_path} as any of {algos}: {'; '.join(errors)}")


@dataclass(frozen=True)
class ObsNormalizer:
    """A snapshot of ``VecNormalize``'s observation statistics: ``clip((obs - mean) / sqrt(var + eps))``.

    Attributes:
        mean: Running mean of each observation feature.
        var: Running variance of each observation feature.
        epsilon: Added to the variance.
        clip_obs: Normalised values are clipped to ``[-clip_obs, clip_obs]``.
    """

    mean: NDArray[np.float64]
    var: NDArray[np.float64]
    epsilon: float
    clip_obs: float

    @classmethod
    def from_vec_normalize(cls, vec_normalize: VecNormalize | None) -> ObsNormalizer | None:
        """Copy the statistics (None when there is nothing to normalise)."""
        if vec_normalize is None or not vec_normalize.norm_obs:
            return None
        rms: Any = vec_normalize.obs_rms  # a RunningMeanStd for Box observations
        return cls(
            np.array(rms.mean, dtype=np.float64),
            np.array(rms.var, dtype=np.float64),
            float(vec_normalize.epsilon),
            float(vec_normalize.clip_obs),
        )

    def __call__(self, observation: NDArray[Any]) -> NDArray[np.float32]:
        """Normalise a single observation or a batch, exactly as ``VecNormalize`` does."""
        scaled = (np.asarray(observation, dtype=np.float64) - self.mean) / np.sqrt(self.var + self.epsilon)
        return np.clip(scaled, -self.clip_obs, self.clip_obs).astype(np.float32)


class SB3Agent:
    """A trained SB3 model behind the common ``predict`` protocol, with its observation normalisation.

    Args:
        model: The SB3 model.
        algo: Algorithm name.
        env_id: Env id it was trained on (None if unknown).
        obs_normalizer: The observation normalisation the model was trained with (or None).
        features: The observation feature names it was trained on (None if unknown).
    """

    def __init__(
        self,
        model: BaseAlgorithm,
        algo: str,
        env_id: str | None = None,
        obs_normalizer: ObsNormalizer | None = None,
        features: tuple[str, ...] | None = None,
    ) -> None:
        """Wrap the model."""
        self.model = model
        self.features = features
        self.algo = algo
        self.env_id = env_id
        self.name = algo
        self.obs_normalizer = obs_normalizer
        self.observation_space = model.observation_space
        self.action_space = model.action_space

    def normalize(self, observation: NDArray[Any]) -> NDArray[np.float32]:
        """Apply the saved observation normalisation (identity without one)."""
        if self.obs_normalizer is None:
            return np.asarray(observation, dtype=np.float32)
        return self.obs_normalizer(observation)

    def predict(
        self,
        observation: Any,
        state: Any = None,
        episode_start: Any = None,
        deterministic: bool = True,
    ) -> tuple[NDArray[Any], Any]:
        """SB3's ``predict`` on normalised observations; ``state`` is the LSTM state (recurrent only)."""
        obs = self.normalize(observation)
        if episode_start is not None:
            episode_start = np.asarray(episode_start, dtype=bool).reshape(-1)
        return self.model.predict(obs, state=state, episode_start=episode_start, deterministic=deterministic)


def load_agent(path: str | Path) -> SB3Agent:
    """Load a saved agent (a model folder or its ``model.zip``) for evaluation.

    Returns:
        An :class:`SB3Agent` with the model's algorithm, env id and normalisation.

    Raises:
        FileNotFoundError: nothing saved at ``path``.
        ValueError: the file is not a loadable SB3 model.
    """
    model_path, saved_info = _resolve(path)
    model, info = load_model(model_path)
    _, bundled = read_bundle(model_path)
    normalizer = ObsNormalizer.from_vec_normalize(bundled)
    if bundled is None and saved_info.get("normalized", True):  # not in the bundle: look beside the model
        if saved_info:
            name = saved_info.get("vecnormalize")
            candidates = [model_path.parent / name] if name else []
        else:
            # No agent.json: a vecnormalize.pkl beside the model, or in RL Zoo's layout
            # (logs/ppo/<env>_1/<env>.zip with <env>_1/<env>/vecnormalize.pkl).
            candidates = [model_path.parent / VECNORMALIZE_FILE, model_path.with_suffix("") / VECNORMALIZE_FILE]
        for candidate in candidates:
            if candidate.exists():
                normalizer = ObsNormalizer.from_vec_normalize(_load_vec_normalize(candidate))
                break
    features = info.get("features")
    return SB3Agent(model, info["algo"], info.get("env_id"), normalizer, tuple(features) if features else None)


def _load_vec_normalize(path: Path) -> VecNormalize:
    """A pickled ``VecNormalize`` (saved without its venv); ValueError naming the file if it is not one."""
    try:
        with path.open("rb") as handle:
            stats = pickle.load(handle)
    except (OSError, EOFError, pickle.UnpicklingError, AttributeError, ImportError, ValueError) as exc:
        raise ValueError(f"{path}: not a readable VecNormalize pickle ({type(exc).__name__}: {exc})") from None
    if not isinstance(stats, VecNormalize):
        raise ValueError(f"{path}: holds a {type(stats).__name__}, not a VecNormalize")
    return stats


# --- logging ------------------------------------------------------------------

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

    def _on_step(self) -> bool:
        if self.num_timesteps >= self._next:
            self._next = (self.num_timesteps // self.every + 1) * self.every
            self.evaluate_now()
        return True

    def evaluate_now(self) -> dict[str, Any]:
        """Run one evaluation and log it."""
        from agents.evaluate import evaluate

        normalizer = ObsNormalizer.from_vec_normalize(find_vec_normalize(self.model.get_env()))
        agent = SB3Agent(self.model, self.algo, self.env_id, normalizer)
        result = evaluate(agent, self.env_id, self.personas, self.episodes, self.seed, n_envs=min(64, self.episodes))
        point = {"timesteps": int(self.num_timesteps), **result.summary()}
        self.history.append(point)
        for key in ("success_rate", "unsafe_rate", "premature_rate", "timeout_rate", "mean_return"):
            self.logger.record(f"eval/{key}", point[key])
        if point["mean_time_to_lift_s"] is not None:
            self.logger.record("eval/mean_time_to_lift_s", point["mean_time_to_lift_s"])
        return point


# --- checkpoints -------------------------------------------------------------------


class TrainingInterrupted(Exception):
    """Training stopped on request (SIGINT/SIGTERM) at a rollout boundary, after a checkpoint."""

    def __init__(self, checkpoint: Path | None) -> None:
        """Remember where the last checkpoint went."""
        super().__init__(f"training interrupted; last checkpoint {checkpoint}")
        self.checkpoint = checkpoint


def _monitor_of(env: VecEnv) -> VecMonitor | None:
    layer: Any = env
    while layer is not None:
        if isinstance(layer, VecMonitor):
            return layer
        layer = getattr(layer, "venv", None)
    return None


def save_checkpoint(
    model: BaseAlgorithm,
    run_dir: str | Path,
    *,
    algo: str,
    env_id: str,
    extra: dict[str, Any] | None = None,
    keep: int = 2,
) -> Path:
    """Write everything needed to continue training exactly into ``run_dir/checkpoints/step_N/``.

    Taken at a rollout boundary, so nothing half-collected is lost: the model zip (policy,
    optimiser state, schedules, last observation -- as SB3 saves it -- with the
    ``VecNormalize`` statistics inside), the replay buffer of off-policy algorithms, and
    ``state.pkl`` with the RNG states (Python, NumPy, torch, action space), the pickled
    training envs (mid-episode state), the episode counters of ``VecMonitor``, the size of
    ``monitor.csv`` and ``extra`` (the caller's own state). The folder appears under its final
    name only when complete; only the newest ``keep`` are kept.

    Returns:
        The checkpoint folder.
    """
    import torch

    checkpoints = Path(run_dir) / CHECKPOINTS_DIR
    checkpoints.mkdir(parents=True, exist_ok=True)
    target = checkpoints / f"step_{int(model.num_timesteps):012d}"
    env = model.get_env()
    monitor = _monitor_of(env) if env is not None else None
    monitor_csv = None
    if monitor is not None and monitor.results_writer is not None:
        monitor.results_writer.file_handler.flush()
        monitor_csv = Path(monitor.results_writer.file_handler.name).stat().st_size
    state = {
        "num_timesteps": int(model.num_timesteps),
        "rng": {
            "python": random.getstate(),
            "numpy": np.random.get_state(),
            "torch": torch.get_rng_state(),
            "action_space": model.action_space.np_random.bit_generator.state,
        },
        "envs": pickle.dumps(monitor.venv) if monitor is not None else None,
        "monitor": None
        if monitor is None
        else {
            "episode_returns": monitor.episode_returns,
            "episode_lengths": monitor.episode_lengths,
            "episode_count": monitor.episode_count,
            "csv_bytes": monitor_csv,
        },
        "extra": dict(extra or {}),
        # RecurrentPPO's load rebuilds its LSTM state as zeros; the real one is kept here.
        "lstm_states": getattr(model, "_last_lstm_states", None),
    }
    if target.exists():  # the same step again (e.g. the final checkpoint right after a periodic one)
        shutil.rmtree(target)
    with atomic_path(target) as temp:
        temp.mkdir()
        save_model_bundle(model, temp / MODEL_FILE, algo=algo, env_id=env_id, vec_normalize=find_vec_normalize(env))
        if getattr(model, "replay_buffer", None) is not None:
            model.save_replay_buffer(temp / "replay_buffer.pkl")  # type: ignore[attr-defined]
        (temp / "state.pkl").write_bytes(pickle.dumps(state))
    for old in sorted(checkpoints.glob("step_*"))[:-keep]:
        shutil.rmtree(old, ignore_errors=True)
    return target


def latest_checkpoint(run_dir: str | Path) -> Path | None:
    """The newest complete checkpoint folder of a run (None if there is none)."""
    found = sorted(p for p in (Path(run_dir) / CHECKPOINTS_DIR).glob("step_*") if (p / "state.pkl").exists())
    return found[-1] if found else None


def restore_checkpoint(checkpoint: str | Path, env: VecEnv) -> tuple[BaseAlgorithm, dict[str, Any]]:
    """Load a :func:`save_checkpoint` folder onto a freshly built training ``env`` (``VecMonitor`` inside).

    The model continues exactly where it stopped: same envs mid-episode, same normaliser,
    same optimiser, same RNG streams. ``monitor.csv`` (if ``env`` writes one, in append
    mode) is cut back to its size at the checkpoint, dropping episodes logged after it.

    Returns:
        ``(model, extra)``: the model on ``env`` (wrapped in the saved ``VecNormalize`` if
        there was one) and the caller's ``extra`` state.
    """
    import torch

    folder = Path(checkpoint)
    try:
        state = pickle.loads((folder / "state.pkl").read_bytes())
    except (OSError, EOFError, pickle.UnpicklingError) as exc:
        raise ValueError(f"{folder}: unreadable checkpoint state ({exc})") from None
    _, stats = read_bundle(folder / MODEL_FILE)
    monitor = _monitor_of(env)
    if monitor is not None and state["monitor"] is not None:
        writer = monitor.results_writer
        if writer is not None and state["monitor"]["csv_bytes"] is not None:
            writer.file_handler.flush()
            writer.file_handler.truncate(state["monitor"]["csv_bytes"])
            writer.file_handler.seek(0, 2)
        for key in ("episode_returns", "episode_lengths", "episode_count"):
            setattr(monitor, key, state["monitor"][key])
    if stats is not None:
        stats.set_venv(env)
        env = stats
    # force_reset=False keeps the saved last observation: the envs are restored mid-episode below.
    model, _ = load_model(folder / MODEL_FILE, env=env, force_reset=False)
    if (folder / "replay_buffer.pkl").exists():
        model.load_replay_buffer(folder / "replay_buffer.pkl")  # type: ignore[attr-defined]
    if monitor is not None and state["envs"] is not None:
        monitor.venv.close()
        monitor.venv = pickle.loads(state["envs"])
    if state.get("lstm_states") is not None:
        model._last_lstm_states = state["lstm_states"]  # type: ignore[attr-defined]
    # After load: SB3's load re-seeds the global RNGs and the action space from the model's seed.
    rng = state["rng"]
    random.setstate(rng["python"])
    np.random.set_state(rng["numpy"])
    torch.set_rng_state(rng["torch"])
    model.action_space.np_random.bit_generator.state = rng["action_space"]
    return model, dict(state["extra"])


class CheckpointCallback(BaseCallback):
    """Checkpoints every ``every`` env steps and stops cleanly when asked, both at rollout boundaries.

    A checkpoint taken when a rollout starts holds no half-collected data, so training
    resumed from it follows the same path as training that never stopped.

    Args:
        run_dir: The run folder (checkpoints go to ``run_dir/checkpoints``).
        every: Env steps between checkpoints (0: only when stopping).
        algo: Algorithm name (stored in the checkpoint's model zip).
        env_id: Env id (stored likewise).
        stop_requested: Returns True once training should stop (e.g. a signal arrived).
        extra: Returns the caller's state to store with each checkpoint.
        start_steps: Step count training starts from.
    """

    def __init__(
        self,
        run_dir: str | Path,
        every: int,
        *,
        algo: str,
        env_id: str,
        stop_requested: Callable[[], bool] = lambda: False,
        extra: Callable[[], dict[str, Any]] = dict,
        start_steps: int = 0,
    ) -> None:
        """Store the settings; checkpoints happen during ``learn``."""
        super().__init__()
        self.run_dir, self.every, self.algo, self.env_id = Path(run_dir), every, algo, env_id
        self.stop_requested, self.extra = stop_requested, extra
        self._next = (start_steps // every + 1) * every if every > 0 else None
        self.last: Path | None = None

    def save(self) -> Path:
        """Write a checkpoint now."""
        self.last = save_checkpoint(self.model, self.run_dir, algo=self.algo, env_id=self.env_id, extra=self.extra())
        return self.last

    def _on_rollout_start(self) -> None:
        stop = self.stop_requested()
        if stop or (self._next is not None and self.num_timesteps >= self._next):
            self.save()
            if self._next is not None:
                self._next = (self.num_timesteps // self.every + 1) * self.every
        if stop:
            raise TrainingInterrupted(self.last)

    def _on_step(self) -> bool:
        return True
