"""Saving a trained SB3 agent so that it loads and scores as trained, and loading it back.

``model.zip`` is self-contained: besides SB3's members it holds ``coop_gym/agent.json``
(algorithm, env id, observation feature names, coop_gym version, step count) and
``coop_gym/vecnormalize.pkl`` (the observation statistics, if observations were
normalised), so a lone copy of the file loads and scores as trained. The folder also gets
``vecnormalize.pkl`` and ``agent.json`` beside it (what older run folders hold; they still
load, as do RL Zoo's plain zips). :func:`load_agent` returns an :class:`SB3Agent`, which
follows the same ``predict`` protocol as the scripted agents and applies the saved
normalisation, so :func:`agents.evaluate.evaluate` scores it like any other agent.
RecurrentPPO's LSTM state travels in ``state`` and is reset by ``episode_start``. Every
file is written atomically (:mod:`coop_gym.io`).
"""

from __future__ import annotations

import json
import pickle
import warnings
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.vec_env import VecEnv, VecFrameStack, VecNormalize

import coop_gym
from agents.base import feature_mismatch
from agents.hyperparams import ALGORITHMS
from agents.pretrained import PREFIX, is_pretrained, pretrained_card, pretrained_model_path
from agents.rl.normalize import ObsNormalizer
from agents.rl.training import algorithm_class, find_frame_stack, find_vec_normalize, observation_features
from agents.run_folder import AGENT_FILE, MODEL_FILE, VECNORMALIZE_FILE
from coop_gym.io import atomic_path, write_bytes, write_json

__all__ = [
    "BUNDLE_INFO",
    "BUNDLE_VECNORMALIZE",
    "GreedyActor",
    "SB3Agent",
    "bundle_problem",
    "load_agent",
    "load_model",
    "load_to_continue",
    "read_bundle",
    "resolve_saved",
    "save_agent",
    "save_model_bundle",
    "saved_model_problem",
]

BUNDLE_INFO = "coop_gym/agent.json"
"""Member of ``model.zip`` with the metadata (SB3 ignores members it does not know)."""
BUNDLE_VECNORMALIZE = "coop_gym/vecnormalize.pkl"
"""Member of ``model.zip`` with the pickled ``VecNormalize`` (statistics only, no env)."""


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
        "n_envs": int(model.n_envs),
        "coop_gym_version": coop_gym.__version__,
        "normalized": vec_normalize is not None,
        "framework": getattr(model, "framework", "sb3"),
        "frame_stack": find_frame_stack(model.get_env()),
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


def resolve_saved(path: str | Path) -> tuple[Path, dict[str, Any]]:
    """The model file of a saved agent and its metadata: the bundle's, else the ``agent.json`` beside it (or empty).

    Raises:
        FileNotFoundError: nothing saved at ``path``.
        ValueError: a damaged model file or ``agent.json`` (the message names it).
    """
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


def bundle_problem(
    model_path: str | Path, info: dict[str, Any], expected: dict[str, Any] | None = None, source: str = "expected"
) -> str | None:
    """Where a model zip's metadata contradicts what the zip holds, or what ``source`` expects; None if nowhere.

    ``info`` is what the bundle says about itself (``coop_gym/agent.json``, or the ``agent.json``
    beside it): its step count, envs and algorithm are checked against SB3's own record in the
    zip (a foreign ``model.zip`` under a run's metadata), then every key of ``expected`` (e.g. a
    checkpoint's step count, a run's framework and envs; ``source`` names who expects them)
    against ``info``. A key one side does not record (an older bundle) is not checked.
    """
    model_path = Path(model_path)
    try:
        with zipfile.ZipFile(model_path) as archive:
            data = json.loads(archive.read("data"))
    except (OSError, KeyError, ValueError, zipfile.BadZipFile):
        return None  # unreadable: the loader names that itself
    held = {"num_timesteps": data.get("num_timesteps"), "n_envs": data.get("n_envs")}
    held["algo"] = _algo_from_zip(model_path)
    for key, value in held.items():
        if value is not None and info.get(key) is not None and info[key] != value:
            return f"{model_path}: its metadata says {key} {info[key]!r}, but the model it holds has {value!r}"
    for key, value in (expected or {}).items():
        if value is not None and info.get(key) is not None and info[key] != value:
            return f"{model_path} holds a model of {key} {info[key]!r}, but {source} has {value!r}"
    return None


def _algo_from_zip(model_path: Path) -> str | None:
    """The algorithm of an SB3 zip without ``agent.json`` (e.g. RL Zoo's), from its policy class's module.

    Trying the classes in turn is not enough: ``PPO.load`` accepts a RecurrentPPO file.
    """
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
    """Load a saved model as its SB3 class (algorithm from ``agent.json``, else tried in turn) and its metadata.

    A JAX learner's model (``framework`` ``"jax"``) is SB3's PPO or sb3-contrib's RecurrentPPO, its framework kept.
    """
    model_path, info = resolve_saved(path)
    if problem := bundle_problem(model_path, info):
        raise ValueError(problem)
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
        if info.get("framework") == "jax":
            model.framework = "jax"  # type: ignore[attr-defined]  # who trained it, kept when it is saved again
        return model, info | {"algo": algo}
    raise ValueError(f"could not load {model_path} as any of {algos}: {'; '.join(errors)}")


class GreedyActor:
    """SB3's ``policy.predict(obs, deterministic=True)`` of an MLP actor-critic, without its per-call overhead.

    The same torch modules on the same tensors, then what SB3's categorical distributions do
    for their mode: each head's logits normalised by their ``logsumexp`` (``Categorical``),
    ``softmax`` into probabilities, the ``argmax`` of the probabilities. So the actions are
    SB3's, bit for bit; what is left out is the per-call work around them (building a torch
    ``Distribution`` per head and validating its arguments, switching every module to eval
    mode, checking the observation's shape), which costs several times the forward pass on
    an evaluation's batch of envs.

    :meth:`of` gives one for a policy it covers (SB3's ``ActorCriticPolicy`` itself, a flat
    ``Box`` observation, a ``Discrete`` or ``MultiDiscrete`` action), else None.
    """

    def __init__(self, policy: Any, heads: list[int] | None) -> None:
        """The actor of ``policy`` with action heads of sizes ``heads`` (None: one ``Discrete`` action)."""
        self.policy = policy
        self.heads = heads  # None: one Discrete action

    @classmethod
    def of(cls, policy: Any) -> GreedyActor | None:
        """The greedy actor of ``policy``, or None where SB3's own ``predict`` must answer."""
        from stable_baselines3.common.distributions import CategoricalDistribution, MultiCategoricalDistribution
        from stable_baselines3.common.policies import ActorCriticPolicy
        from stable_baselines3.common.preprocessing import is_image_space
        from stable_baselines3.common.torch_layers import FlattenExtractor

        space = policy.observation_space
        if type(policy) is not ActorCriticPolicy or not isinstance(space, spaces.Box) or is_image_space(space):
            return None
        if not isinstance(policy.pi_features_extractor, FlattenExtractor) or len(space.shape) != 1:
            return None
        if type(policy.action_dist) is CategoricalDistribution:
            return cls(policy, None)
        if type(policy.action_dist) is MultiCategoricalDistribution:
            return cls(policy, [int(n) for n in policy.action_dist.action_dims])
        return None

    def head_logits(self, obs: NDArray[Any]) -> list[Any]:
        """Each action head's logits (torch tensors, ``(N, n_head)``) for a batch of (normalised) observations."""
        import torch

        policy = self.policy
        if policy.training:
            policy.set_training_mode(False)
        with torch.inference_mode():
            features = policy.pi_features_extractor(torch.as_tensor(np.asarray(obs)).float())
            logits = policy.action_net(policy.mlp_extractor.forward_actor(features))
        return [logits] if self.heads is None else list(torch.split(logits, self.heads, dim=1))

    def __call__(self, obs: NDArray[Any]) -> NDArray[np.int64]:
        """Actions ``(N,)`` or ``(N, heads)`` for a batch of (normalised) observations ``(N, D)``."""
        import torch

        modes = [_mode(head) for head in self.head_logits(obs)]
        return (modes[0] if self.heads is None else torch.stack(modes, dim=1)).numpy()  # type: ignore[no-any-return]


def _mode(logits: Any) -> Any:
    """``argmax`` of ``Categorical(logits=logits).probs``, as SB3's distributions take their mode."""
    import torch

    normalised = logits - logits.logsumexp(dim=-1, keepdim=True)
    return torch.argmax(torch.nn.functional.softmax(normalised, dim=-1), dim=1)


class SB3Agent:
    """A trained SB3 model behind the common ``predict`` protocol, with its observation normalisation.

    Args:
        model: The SB3 model.
        algo: Algorithm name.
        env_id: Env id it was trained on (None if unknown).
        obs_normalizer: The observation normalisation the model was trained with (or None).
        features: The observation feature names it was trained on (None if unknown).
        env_kwargs: Env kwargs beyond the env id's own that it plays with (a pretrained
            model's card says, e.g. the switching filter's estimate in the observation).
        name: Its name in an evaluation (default: ``algo``).
        frame_stack: Observations stacked into one policy input, as SB3's ``VecFrameStack``
            stacked them in training (the newest last; zeros before an episode's first). The
            stack travels in ``state`` and restarts where ``episode_start`` is set (or, for a
            caller that passes ``state=None``, where ``elapsed_s`` is 0).
    """

    def __init__(
        self,
        model: BaseAlgorithm,
        algo: str,
        env_id: str | None = None,
        obs_normalizer: ObsNormalizer | None = None,
        features: tuple[str, ...] | None = None,
        env_kwargs: dict[str, Any] | None = None,
        name: str | None = None,
        frame_stack: int = 1,
    ) -> None:
        """Wrap the model."""
        if isinstance(frame_stack, bool) or not isinstance(frame_stack, int) or frame_stack < 1:
            raise ValueError(f"frame_stack must be an int >= 1, got {frame_stack!r}")
        self.model = model
        self.frame_stack = frame_stack
        self._stack: NDArray[np.float32] | None = None  # the stack of a caller passing state=None
        self.features = features
        self.algo = algo
        self.env_id = env_id
        self.env_kwargs = dict(env_kwargs or {})
        self.name = name or algo
        self.obs_normalizer = obs_normalizer
        self.observation_space = model.observation_space  # what one env step gives (one frame of a stack)
        if frame_stack > 1:
            space = model.observation_space
            if not isinstance(space, spaces.Box) or space.shape is None or space.shape[-1] % frame_stack:
                raise ValueError(f"frame_stack {frame_stack} does not divide the model's observation space {space}")
            d = space.shape[-1] // frame_stack
            self.observation_space = spaces.Box(space.low[..., -d:], space.high[..., -d:], dtype=space.dtype)
        self.action_space = model.action_space
        self._greedy: tuple[Any, GreedyActor | None] = (None, None)  # (the policy, its greedy actor)

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
        """SB3's ``predict`` on normalised observations; ``state`` is the LSTM state or the frame stack."""
        obs = self.normalize(observation)
        if episode_start is not None:
            episode_start = np.asarray(episode_start, dtype=bool).reshape(-1)
        greedy = self._greedy_actor() if deterministic else None
        if self.frame_stack == 1:
            if greedy is not None and obs.ndim == 2 and obs.shape[1:] == self.observation_space.shape:
                return greedy(obs), state
            return self.model.predict(obs, state=state, episode_start=episode_start, deterministic=deterministic)
        single = obs.ndim == 1
        stack = self._push(obs.reshape(1, -1) if single else obs, np.asarray(observation), state, episode_start)
        if greedy is not None and not single:
            return greedy(stack), stack
        actions, _ = self.model.predict(stack[0] if single else stack, deterministic=deterministic)
        return actions, stack

    def _greedy_actor(self) -> GreedyActor | None:
        """The :class:`GreedyActor` of the model's current policy (None: SB3's ``predict`` answers)."""
        policy = self.model.policy
        if self._greedy[0] is not policy:
            self._greedy = (policy, GreedyActor.of(policy))
        return self._greedy[1]

    def _push(
        self,
        obs: NDArray[np.float32],
        observation: NDArray[Any],
        state: Any,
        episode_start: NDArray[np.bool_] | None,
    ) -> NDArray[np.float32]:
        """The (N, frame_stack * D) stack with ``obs`` (N, D) pushed in, as ``VecFrameStack`` builds it."""
        n, d = obs.shape
        previous = self._stack if state is None else np.asarray(state, dtype=np.float32)
        if previous is None or previous.shape != (n, self.frame_stack * d):
            if state is not None:
                raise ValueError(f"state must be the ({n}, {self.frame_stack * d}) frame stack predict returned")
            stack = np.zeros((n, self.frame_stack * d), dtype=np.float32)
        else:
            stack = np.roll(previous, -d, axis=1)  # a new array: the caller's state is not changed
            fresh = np.zeros(n, dtype=bool) if episode_start is None else episode_start.copy()
            if state is None and self.features and "elapsed_s" in self.features:
                fresh |= observation.reshape(n, -1)[:, self.features.index("elapsed_s")] == 0
            stack[fresh] = 0.0
        stack[:, -d:] = obs
        if state is None:
            self._stack = stack
        return stack


def load_agent(path: str | Path) -> SB3Agent:
    """Load a saved agent (a model folder, its ``model.zip``, or ``pretrained:NAME``) for evaluation.

    ``pretrained:NAME`` is a model shipped in :mod:`agents.pretrained`; its card's env kwargs
    come along (``agent.env_kwargs``) and its name is ``pretrained:NAME``. (``agents.rl.load_agent`` is
    :func:`agents.rl.ensemble.load_agent`, which also loads a run folder kept as an ensemble.)

    Returns:
        An :class:`SB3Agent` with the model's algorithm, env id and normalisation.

    Raises:
        FileNotFoundError: nothing saved at ``path``.
        ValueError: the file is not a loadable SB3 model, or an unknown pretrained name
            (the message lists the known ones).
    """
    if is_pretrained(path):
        assert isinstance(path, str)
        card = pretrained_card(path)
        agent = load_agent(pretrained_model_path(path))
        agent.name = PREFIX + card["name"]
        agent.env_kwargs = dict(card.get("env_kwargs") or {})
        return agent
    model_path, saved_info = resolve_saved(path)
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
    if normalizer is None and saved_info.get("normalized"):  # it would score observations it never saw
        raise ValueError(
            f"{model_path} was trained on normalised observations (its metadata says so), but neither "
            f"{BUNDLE_VECNORMALIZE} inside it nor {VECNORMALIZE_FILE} beside it holds the statistics; restore one"
        )
    features = info.get("features")
    frame_stack = info.get("frame_stack", 1)
    return SB3Agent(
        model, info["algo"], info.get("env_id"), normalizer, tuple(features) if features else None,
        frame_stack=frame_stack,
    )  # fmt: skip


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


def load_to_continue(path: str | Path, env: VecEnv) -> tuple[BaseAlgorithm, VecEnv]:
    """A saved model (a folder or its zip) on a training ``env``, to train further; ``(model, env)``.

    The model's own observation statistics come along (from inside the zip, else the
    ``vecnormalize.pkl`` beside it) and keep updating: ``env`` comes back wrapped in them
    (and in a ``VecFrameStack`` of the model's ``frame_stack``, if it stacked frames).
    """
    model_path = Path(path)
    model_path = model_path / MODEL_FILE if model_path.is_dir() else model_path
    info, stats = read_bundle(model_path)
    beside = model_path.parent / VECNORMALIZE_FILE
    if stats is None and beside.exists():
        stats = VecNormalize.load(str(beside), env)
    if stats is not None:
        stats.set_venv(env)
        stats.training = True
        env = stats
    if info.get("frame_stack", 1) > 1:
        env = VecFrameStack(env, int(info["frame_stack"]))
    model, _ = load_model(model_path, env=env)
    return model, env


def saved_model_problem(flag: str, path: str | Path, env_id: str, agent: SB3Agent | None = None) -> str | None:
    """Why the model saved at ``path`` (already loaded: ``agent``) cannot play ``env_id``; None if it can.

    The message starts with ``flag``, the command-line flag that named the model.
    """
    if agent is None:
        try:
            _, info = load_model(path)
        except (OSError, ValueError) as exc:
            return f"{flag}: {exc}"
        features = info.get("features")
    else:
        features = agent.features
    env_features = observation_features(env_id)
    if features is not None:
        problem = feature_mismatch(features, env_features, env_id)
        return f"{flag}: {problem}" if problem else None
    shape = agent.observation_space.shape if agent is not None else None
    if shape is not None and shape != (len(env_features),):  # an older model without feature names
        return f"{flag}: the model observes shape {shape} but {env_id} gives ({len(env_features)},)"
    return None
