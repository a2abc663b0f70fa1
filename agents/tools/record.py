"""Record one episode of any agent: a video of the rendered scene and a timeline plot.

Usage::

    python -m agents.tools.record --agent handbook --seed 0 --out videos/
    python -m agents.tools.record --model runs/ppo/model.zip --env CoopGym/SitToStandHeldOut-v0 \
        --persona frail --out videos/

writes ``{name}-seed{S}-episode-0.mp4`` (the env's ``rgb_array`` frames through
:class:`gymnasium.wrappers.RecordVideo`, which writes with moviepy) and
``{name}-seed{S}-timeline.png`` (:func:`agents.tools.timeline.plot_timeline`) into ``--out``. If
the MP4 cannot be written (moviepy or ffmpeg missing or failing) the same frames are
written as an animated GIF (Pillow) and the command says so. Runs headless: frames are
drawn off-screen by pygame and the plot on matplotlib's Agg canvas.

Agents: ``--agent NAME`` is a scripted caregiver (:data:`agents.caregivers.scripted.SCRIPTED_AGENTS`),
run on the observation it reads exactly as :mod:`agents.evaluate` does (the oracle gets the
oracle observation, see :func:`agents.evaluate.env_kwargs_for`); ``--model PATH`` is a saved
Stable-Baselines3 model (loaded with :func:`load_model`; its env id is the default ``--env``
when the loader knows it).
Every agent is driven through SB3's ``predict(obs, state, episode_start, deterministic)``,
so recurrent policies keep their state.

From Python, :func:`record_episode` does the same and returns a :class:`RecordResult`.
"""

from __future__ import annotations

import os
import sys
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

import gymnasium as gym
import numpy as np
import tyro
from gymnasium.wrappers import RecordVideo

import coop_gym
from agents.base import Agent, action_type_of, feature_mismatch, features_of, level_of
from agents.caregivers.scripted import SCRIPTED_AGENTS, ScriptedAgent, make_scripted
from agents.tools.timeline import Trace, TraceBuilder, plot_timeline
from coop_gym.cli import (
    SEED_LIMIT,
    BadArgs,
    PositiveIntOrNone,
    Seed,
    exit_status,
    fail,
    one_of,
    output_path_problem,
    parse,
)
from coop_gym.io import atomic_path
from estimator.validate import check_integer

__all__ = [
    "DEFAULT_ENV_ID",
    "PROG",
    "Args",
    "IncompatibleAgentError",
    "RecordResult",
    "args_problem",
    "load_model",
    "main",
    "play_episode",
    "record_episode",
]

DEFAULT_ENV_ID = "CoopGym/SitToStand-v0"
_HOLD_LAST_S = 1.0  # the outcome banner stays on screen this long at the end of the video


class IncompatibleAgentError(ValueError):
    """The agent cannot act in the env (missing observation features, other spaces)."""


@dataclass(frozen=True)
class RecordResult:
    """What :func:`record_episode` wrote and how the episode went.

    Attributes:
        video_path: The MP4 (or the GIF written instead).
        timeline_path: The timeline PNG.
        outcome: ``"success"``, ``"unsafe"``, ``"premature"``, ``"timeout"``, or ``"none"``
            when ``max_steps`` stopped the recording first.
        steps: Agent steps taken (0.1 s each).
        episode_return: Sum of the rewards.
        video_format: ``"mp4"`` or ``"gif"``.
        fallback_reason: Why the MP4 could not be written (empty when it was).
        trace: The recorded per-step trace (what the timeline shows).
    """

    video_path: Path
    timeline_path: Path
    outcome: str
    steps: int
    episode_return: float
    video_format: str
    fallback_reason: str
    trace: Trace


class _RecordVideoOrGif(RecordVideo):  # type: ignore[misc]
    """``RecordVideo`` that holds the last frame a moment and falls back to a GIF.

    Gymnasium's wrapper raises when moviepy is missing or ffmpeg fails; the frames it
    collected are still there then, so they go to an animated GIF instead.
    """

    def __init__(self, env: gym.Env[Any, Any], video_folder: str, name_prefix: str, fps: int | None) -> None:
        self.fallback_reason = ""
        self.written: list[Path] = []
        try:
            with warnings.catch_warnings():
                # Recording into an existing folder is the normal case here, not a surprise.
                warnings.filterwarnings("ignore", message=".*Overwriting existing videos")
                super().__init__(
                    env, video_folder, episode_trigger=lambda _: True, name_prefix=name_prefix, fps=fps, gc_trigger=None
                )
        except gym.error.DependencyNotInstalled as exc:
            # Raised last in RecordVideo.__init__ (moviepy missing): everything else is set up.
            self.fallback_reason = str(exc)

    def stop_recording(self) -> None:
        name = self._video_name
        if self.recorded_frames:
            hold = max(0, round(_HOLD_LAST_S * self.frames_per_sec) - 1)
            self.recorded_frames.extend([self.recorded_frames[-1]] * hold)
        mp4 = Path(self.video_folder) / f"{name}.mp4"
        try:
            if self.fallback_reason:
                raise gym.error.DependencyNotInstalled(self.fallback_reason)
            if not self.recorded_frames:
                super().stop_recording()  # nothing to write
            else:
                # moviepy writes {video_folder}/{_video_name}.mp4: point it at a temporary name
                # and rename when complete, so a failure never leaves half an MP4.
                with atomic_path(mp4) as temp:
                    self._video_name = temp.stem
                    super().stop_recording()
                self.written.append(mp4)
        except Exception as exc:
            self.fallback_reason = self.fallback_reason or f"{type(exc).__name__}: {exc}"
            if self.recorded_frames:
                gif = mp4.with_suffix(".gif")
                _write_gif(self.recorded_frames, gif, self.frames_per_sec)
                self.written.append(gif)
            self.recorded_frames = []
            self.recording = False
            self._video_name = None


def _write_gif(frames: Sequence[Any], path: Path, fps: int) -> None:
    """Write RGB frames as a looping animated GIF (Pillow, installed with matplotlib)."""
    from PIL import Image

    images = [Image.fromarray(np.asarray(frame, dtype=np.uint8)) for frame in frames]
    with atomic_path(path) as temp:
        images[0].save(temp, save_all=True, append_images=images[1:], duration=round(1000 / fps), loop=0, optimize=True)


def load_model(path: str | Path) -> Agent:
    """Load a saved Stable-Baselines3 agent (a model ``.zip`` or a model folder).

    Uses :func:`agents.rl.load_agent` (PPO, RecurrentPPO, DQN; restores the saved
    observation normalisation and knows the env id and algorithm); a model of another
    algorithm is tried as SB3's A2C, SAC, TD3 and sb3-contrib's MaskablePPO, QR-DQN, TRPO.

    Raises:
        FileNotFoundError: If nothing is saved at ``path``.
        ValueError: If no algorithm can load it.
    """
    from agents.rl import load_agent

    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no saved model at {path}")
    try:
        return load_agent(path)
    except ValueError as first:
        if path.is_dir():
            raise
        reason = str(first)
    # Not one of agents.rl's algorithms (e.g. an A2C or SAC model from elsewhere).
    import stable_baselines3 as sb3

    algorithms: list[Any] = [sb3.A2C, sb3.SAC, sb3.TD3]
    try:
        import sb3_contrib

        algorithms += [sb3_contrib.MaskablePPO, sb3_contrib.QRDQN, sb3_contrib.TRPO]
    except ImportError:
        pass
    for algorithm in algorithms:
        try:
            return algorithm.load(path, device="cpu")  # type: ignore[no-any-return]
        except Exception:
            continue
    raise ValueError(f"could not load {path} as a Stable-Baselines3 model: {reason}")


def _recording_name(model_path: Path) -> str:
    """File-name stem for a model: its folder's name for train.py-style ``run/model.zip``."""
    path = model_path.resolve()
    if path.is_dir():
        return path.name
    if path.stem in ("model", "best_model", "final_model"):
        return f"{path.parent.name}-{path.stem}"
    return path.stem


def record_episode(
    agent: Agent | str,
    env_id: str = DEFAULT_ENV_ID,
    seed: int | None = 0,
    out_dir: str | Path = "videos",
    *,
    persona: str | None = None,
    fps: int | None = None,
    max_steps: int | None = None,
    name: str | None = None,
    deterministic: bool = True,
    env_kwargs: dict[str, Any] | None = None,
) -> RecordResult:
    """Run one episode of ``agent`` and write its video and timeline into ``out_dir``.

    Args:
        agent: Anything with SB3's ``predict`` (a scripted agent, an SB3 model), or the name
            of a scripted agent (built for the env's features and action type, seeded, on the
            observation it reads: :func:`agents.evaluate.env_kwargs_for`).
        env_id: A registered coop_gym id.
        seed: Reset seed (also seeds a scripted agent built by name).
        out_dir: Output folder (created).
        persona: Run this persona (any of ``coop_gym.PERSONAS``, training or held-out).
        fps: Video frame rate; default the env's ``render_fps`` (10, real time).
        max_steps: Stop after this many steps even if the episode goes on.
        name: File-name stem; default the agent's name.
        deterministic: Passed to ``predict``.
        env_kwargs: Extra keyword arguments of ``gymnasium.make``.

    Returns: A :class:`RecordResult`.

    Raises:
        IncompatibleAgentError: If the agent cannot act in the env.
        ValueError: For a bad ``seed``, ``persona``, ``fps`` or ``max_steps``.
    """
    _check_recording(fps, max_steps, seed)
    kwargs = _env_kwargs(agent, env_id, persona, env_kwargs)
    out = Path(out_dir).resolve()
    out.mkdir(parents=True, exist_ok=True)
    recorder, agent, agent_name, stem = _open_recorder(agent, env_id, kwargs, seed, out, name, fps)
    try:
        settings: dict[str, Any] = {"deterministic": deterministic, "agent_name": agent_name, "env_id": env_id}
        trace = play_episode(recorder, agent, seed, max_steps=max_steps, **settings)
    finally:
        recorder.close()  # writes the video
    timeline = plot_timeline(trace, out / f"{stem}-timeline.png")
    if not recorder.written:
        raise RuntimeError(f"no video was written for {stem} ({recorder.fallback_reason or 'no frames'})")
    video = recorder.written[-1]
    return RecordResult(
        video_path=video,
        timeline_path=timeline,
        outcome=trace.outcome,
        steps=trace.n_steps,
        episode_return=trace.episode_return,
        video_format=video.suffix.lstrip("."),
        fallback_reason=recorder.fallback_reason,
        trace=trace,
    )


def _open_recorder(
    agent: Agent | str, env_id: str, kwargs: dict[str, Any], seed: int | None, out: Path, name: str | None, fps: Any
) -> tuple[_RecordVideoOrGif, Agent, str, str]:
    """``(recorder, agent, agent name, file stem)``: the env made, wrapped to record, the agent checked to fit it."""
    env = gym.make(env_id, render_mode="rgb_array", **kwargs)
    try:
        agent, agent_name = _agent_for(agent, env, env_id, seed)
        stem = f"{name or agent_name}" + (f"-seed{seed}" if seed is not None else "")
        _check_observation_space(agent, env)
        return _RecordVideoOrGif(env, str(out), name_prefix=stem, fps=fps), agent, agent_name, stem
    except BaseException:
        env.close()
        raise


def _check_recording(fps: Any, max_steps: Any, seed: Any) -> None:
    """ValueError naming a bad ``fps``, ``max_steps`` or ``seed`` of :func:`record_episode`."""
    for name, value, low, high in (
        ("fps", fps, 1, 1000),
        ("max_steps", max_steps, 1, SEED_LIMIT),
        ("seed", seed, 0, SEED_LIMIT - 1),
    ):
        if value is not None:
            check_integer(name, value, low, high)


def _env_kwargs(
    agent: Agent | str, env_id: str, persona: str | None, env_kwargs: dict[str, Any] | None
) -> dict[str, Any]:
    """The env kwargs of a recording: the observation a scripted agent reads, the persona asked for."""
    kwargs = dict(env_kwargs or {})
    if isinstance(agent, str):
        from agents.evaluate import env_kwargs_for

        kwargs = env_kwargs_for(agent, env_id, kwargs)  # e.g. the oracle needs the oracle observation
    if persona is not None:
        if persona not in coop_gym.PERSONAS:
            raise ValueError(f"unknown persona {persona!r}; known: {', '.join(coop_gym.PERSONAS)}")
        kwargs["personas"] = persona
    return kwargs


def _agent_for(agent: Agent | str, env: gym.Env[Any, Any], env_id: str, seed: int | None) -> tuple[Agent, str]:
    """``(agent, its name)``: a scripted agent built for ``env`` (and its level) by name, or ``agent`` as given."""
    if not isinstance(agent, str):
        return agent, getattr(agent, "name", None) or type(agent).__name__
    try:
        # The settings chosen for the env's level.
        return make_scripted(agent, features_of(env), action_type_of(env), seed=seed, level=level_of(env)), agent
    except ValueError as exc:
        raise IncompatibleAgentError(f"{exc} (env {env_id})") from None


def play_episode(
    env: gym.Env[Any, Any],
    agent: Agent,
    seed: int | None,
    *,
    max_steps: int | None = None,
    deterministic: bool = True,
    agent_name: str = "",
    env_id: str = "",
    on_step: Callable[[gym.Env[Any, Any], dict[str, Any]], None] | None = None,
) -> Trace:
    """Run one episode of ``agent`` in a single coop_gym env and return its :class:`Trace`.

    The agent is called with SB3's protocol on a batch of one (``episode_start`` True on
    the first call, the returned state passed back), so recurrent policies work.

    Args:
        env: A single (possibly wrapped) coop_gym env.
        agent: Anything with SB3's ``predict``.
        seed: Reset seed.
        max_steps: Stop after this many steps even if the episode goes on.
        deterministic: Passed to ``predict``.
        agent_name: Recorded in the trace.
        env_id: Recorded in the trace.
        on_step: Called as ``on_step(env, info)`` after the reset and after every step
            (e.g. to render frames).

    Returns:
        The trace (``outcome`` is ``"none"`` if ``max_steps`` stopped it first).
    """
    builder = TraceBuilder.for_env(env)
    obs, info = env.reset(seed=seed)
    builder.append(obs, info)
    if on_step is not None:
        on_step(env, info)
    state: Any = None
    episode_start = np.ones(1, dtype=bool)
    steps = 0
    while max_steps is None or steps < max_steps:
        actions, state = agent.predict(
            np.asarray(obs)[None], state=state, episode_start=episode_start, deterministic=deterministic
        )
        episode_start = np.zeros(1, dtype=bool)
        obs, reward, terminated, truncated, info = env.step(np.asarray(actions)[0])
        steps += 1
        builder.append(obs, info, float(reward))
        if on_step is not None:
            on_step(env, info)
        if terminated or truncated:
            break
    return builder.build(agent=agent_name, env_id=env_id, seed=seed)


def _check_observation_space(agent: Any, env: gym.Env[Any, Any]) -> None:
    """A clear error when a loaded model was trained on another observation or action space."""
    if not isinstance(agent, ScriptedAgent):
        problem = feature_mismatch(
            getattr(agent, "features", None), features_of(env), env.spec.id if env.spec else "the env"
        )
        if problem:
            raise IncompatibleAgentError(f"{problem}; pass the env id it was trained on")
    for attr in ("observation_space", "action_space"):
        expected = getattr(agent, attr, None)
        actual = getattr(env, attr)
        if expected is not None and getattr(expected, "shape", None) != getattr(actual, "shape", None):
            raise IncompatibleAgentError(
                f"the model's {attr} {expected} does not match the env's {actual}; pass the env id it was trained on"
            )


PROG = "python -m agents.tools.record"
DESCRIPTION = "Record one episode of an agent: a video (MP4, else GIF) and a timeline plot (PNG)."
_Agent = tyro.conf.create_mutex_group(required=True, title="agent (one of)")
_ENV_HELP = f"env id (default: the model's, else {DEFAULT_ENV_ID})"
_PERSONA_HELP = f"persona to run, one of: {', '.join(coop_gym.PERSONAS)}"


@dataclass
class Args:
    """The command line's arguments; each field's docstring (or ``help``) is its ``--help``."""

    out: Path
    """output folder"""
    agent: Annotated[str | None, one_of(sorted(SCRIPTED_AGENTS)), _Agent] = None
    """a scripted caregiver"""
    model: Annotated[Path | None, _Agent] = None
    """a saved Stable-Baselines3 model (.zip) or model folder"""
    env: Annotated[str | None, tyro.conf.arg(help=_ENV_HELP)] = None
    seed: Seed = 0
    """reset seed, 0 <= seed < 2**32"""
    persona: Annotated[str | None, tyro.conf.arg(help=_PERSONA_HELP)] = None
    fps: PositiveIntOrNone = None
    """video frame rate (None: 10 = real time)"""
    max_steps: PositiveIntOrNone = None
    """stop after this many 0.1 s steps"""
    stochastic: bool = False
    """sample the policy's actions (default greedy)"""

    def __post_init__(self) -> None:
        """The first value no recording can use is a usage error naming it, before the episode."""
        if problem := args_problem(self):
            raise BadArgs(problem)


def args_problem(args: Args) -> str | None:
    """The first value of ``args`` no recording can use (None if all are fine)."""
    env_id = args.env or DEFAULT_ENV_ID
    if env_id not in coop_gym.ENV_IDS:
        return f"unknown env id {env_id!r} (not a coop_gym env); coop_gym ids: {', '.join(coop_gym.ENV_IDS)}"
    if args.persona is not None and args.persona not in coop_gym.PERSONAS:
        return f"unknown persona {args.persona!r}; known: {', '.join(coop_gym.PERSONAS)}"
    problem = output_path_problem(args.out, folder=True)  # before the episode, not after it
    if problem:
        return f"--out: {problem}"
    if args.model is not None and not args.model.exists():
        return f"--model {args.model}: no such file or folder"
    return None


def main(argv: Sequence[str] | None = None) -> int:
    """Command-line entry point; usage errors exit with status 2."""
    args = parse(Args, argv, PROG, DESCRIPTION)
    env_id = args.env or DEFAULT_ENV_ID
    if args.model is not None:
        try:
            agent: Agent | str = load_model(args.model)
        except (FileNotFoundError, ValueError) as exc:
            fail(PROG, f"--model {args.model}: {exc}")
        model_env_id = getattr(agent, "env_id", None)
        if args.env is None and isinstance(model_env_id, str) and model_env_id in gym.registry:
            env_id = model_env_id
        name = _recording_name(args.model)
    else:
        assert args.agent is not None  # the required group: --agent or --model
        agent, name = args.agent, args.agent
    os.environ.setdefault("SDL_VIDEODRIVER", "dummy")  # never open a window
    try:
        result = record_episode(
            agent,
            env_id,
            args.seed,
            args.out,
            persona=args.persona,
            fps=args.fps,
            max_steps=args.max_steps,
            name=name,
            deterministic=not args.stochastic,
        )
    except IncompatibleAgentError as exc:
        fail(PROG, str(exc))
    except OSError as exc:  # e.g. a full disk: the file is not there (never half-written)
        print(f"error: could not write {exc.filename or 'output'}: {exc.strerror or exc}", file=sys.stderr)
        return 1
    if result.fallback_reason:
        print(f"MP4 writing failed ({result.fallback_reason}); wrote a GIF instead", file=sys.stderr)
    trace = result.trace
    print(f"video:    {result.video_path}")
    print(f"timeline: {result.timeline_path}")
    print(
        f"episode:  {name} on {env_id}, seed {args.seed}, persona {trace.persona}: {result.outcome} after "
        f"{result.steps} steps ({trace.time_s[-1]:.1f} s), return {result.episode_return:+.3f}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(exit_status(main))
