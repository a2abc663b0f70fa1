"""Videos and timelines: RecordVideo / VecVideoRecorder over our env, agents.tools.record, agents.tools.timeline."""

from __future__ import annotations

import os

os.environ.setdefault("SDL_VIDEODRIVER", "dummy")  # no screen on CI; the human-mode test needs it
os.environ.setdefault("SDL_AUDIODRIVER", "dummy")

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.wrappers import RecordVideo

import coop_gym  # noqa: F401  (registers the ids)
from agents.tools import record
from agents.tools.timeline import OUTCOME_COLOURS, Trace, TraceBuilder, judgment_events, plot_timeline

pytest.importorskip("moviepy")
PIL = pytest.importorskip("PIL.Image")

ENV_ID = "CoopGym/SitToStand-v0"
REPO = Path(__file__).resolve().parents[2]
SOFT_PUSH_FORWARD = np.array([1, 2, 0])  # soft push, "lean forward", wait
LIFT = np.array([0, 0, 1])


def count_video_frames(path: Path) -> int:
    imageio = pytest.importorskip("imageio.v2")
    pytest.importorskip("imageio_ffmpeg")
    with imageio.get_reader(path, "ffmpeg") as reader:
        return int(reader.count_frames())


def test_record_video_wrapper_writes_an_mp4_of_the_episode(tmp_path):
    folder = tmp_path / "videos"
    env = RecordVideo(gym.make(ENV_ID, render_mode="rgb_array"), str(folder), episode_trigger=lambda _: True)
    env.reset(seed=0)
    steps = 1
    for _ in range(11):
        _, _, terminated, truncated, _ = env.step(SOFT_PUSH_FORWARD)
        assert not (terminated or truncated)
        steps += 1
    _, _, terminated, _, info = env.step(LIFT)  # the lift ends the episode
    steps += 1
    assert terminated and info["outcome"] != "none"
    env.close()
    videos = list(folder.glob("*.mp4"))
    assert len(videos) == 1 and videos[0].stat().st_size > 1000
    # One frame per reset/step (moviepy 2 drops at most the final one when encoding).
    assert steps - 1 <= count_video_frames(videos[0]) <= steps


def test_sb3_vec_video_recorder_over_dummy_vec_env(tmp_path):
    vec_env_mod = pytest.importorskip("stable_baselines3.common.vec_env")
    venv = vec_env_mod.DummyVecEnv([lambda: gym.make(ENV_ID, render_mode="rgb_array")])
    venv = vec_env_mod.VecVideoRecorder(
        venv, str(tmp_path), record_video_trigger=lambda step: step == 0, video_length=12, name_prefix="vec"
    )
    venv.seed(0)
    venv.reset()
    for _ in range(15):
        venv.step(SOFT_PUSH_FORWARD[None])
    venv.close()
    videos = list(tmp_path.glob("vec*.mp4"))
    assert len(videos) == 1 and videos[0].stat().st_size > 1000
    assert count_video_frames(videos[0]) >= 10


def test_record_command_runs_headless_and_writes_video_and_timeline(tmp_path):
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY", "SDL_VIDEODRIVER")}
    env["MPLBACKEND"] = "TkAgg"  # would need a display if pyplot were used: the command must not use it
    proc = subprocess.run(
        [sys.executable, "-m", "agents.tools.record", "--agent", "handbook", "--seed", "0", "--out", "tmp"],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    out = tmp_path / "tmp"
    videos = list(out.glob("handbook-seed0-episode-0.*"))
    assert len(videos) == 1 and videos[0].stat().st_size > 1000
    assert videos[0].suffix == ".mp4", proc.stderr  # ffmpeg is installed here: no GIF fallback expected
    timeline = out / "handbook-seed0-timeline.png"
    assert timeline.stat().st_size > 10_000
    summary = re.search(r"handbook on CoopGym/SitToStand-v0, seed 0, persona \w+: (\w+) after (\d+) steps", proc.stdout)
    assert summary is not None, proc.stdout
    assert summary.group(1) in ("success", "unsafe", "premature", "timeout")  # the episode ran to its end
    # The video holds one frame per step plus the reset, then the end held for 1 s (10 frames at 10 fps).
    assert int(summary.group(2)) + 1 <= count_video_frames(videos[0]) <= int(summary.group(2)) + 11


def _short_trace() -> Trace:
    env = gym.make(ENV_ID)
    builder = TraceBuilder.for_env(env)
    obs, info = env.reset(seed=3)
    builder.append(obs, info)
    for k in range(30):
        obs, reward, *_, info = env.step([1, 2 if k < 10 else 0, 0])
        builder.append(obs, info, reward)
    obs, reward, *_, info = env.step(LIFT)
    builder.append(obs, info, reward)
    env.close()
    return builder.build(agent="manual", env_id=ENV_ID, seed=3)


def test_timeline_png_has_the_requested_size_and_is_a_picture(tmp_path):
    trace = _short_trace()
    path = plot_timeline(trace, tmp_path / "sub" / "t.png", width_px=640, height_px=480, dpi=80)
    with PIL.open(path) as image:
        assert image.size == (640, 480)
        pixels = np.asarray(image.convert("RGB")).astype(np.int16)
    blank = np.abs(pixels - pixels[0, 0]).max(axis=-1) < 10
    assert 0.03 < 1.0 - blank.mean() < 0.6  # drawn on, but not a solid fill
    assert len(np.unique(pixels.reshape(-1, 3), axis=0)) > 100
    # The push (orange) and the lift line in the outcome's colour are drawn.
    orange = (np.abs(pixels - np.array([214, 96, 20])).max(axis=-1) < 30).sum()  # antialiased line
    assert orange > 200
    colour = OUTCOME_COLOURS[trace.outcome]
    outcome_rgb = np.array([int(colour[i : i + 2], 16) for i in (1, 3, 5)])
    assert (np.abs(pixels - outcome_rgb).max(axis=-1) < 30).sum() > 200


def test_short_trace_follows_the_env():
    trace = _short_trace()
    assert trace.n_steps == 31 and trace.lifted  # the last action lifts: success, unsafe or premature
    assert trace.time_s[0] == 0.0 and trace.time_s[10] == pytest.approx(1.0)
    assert np.all(trace.push_force_n[1:31] == 10.0) and trace.push_force_n[0] == 0.0
    assert trace.verbal_cue[1] == 1.0
    assert np.all(np.isfinite(trace.x_hat_m)) and np.all(trace.xi_std > 0)


def test_judgment_events_are_placed_at_onset_plus_delay():
    n = 21
    time_s = np.round(np.arange(n) * 0.1, 10)
    since = np.full(n, 30.0)
    since[3:] = np.arange(n - 3) * 0.1 + 0.06  # a cue began at 0.24 s -> judged 0.75 s later, at 0.99 s
    judgment = np.where(time_s >= 0.95, 1.0, 0.0)  # first shows in the row of t = 1.0 s
    zeros = np.zeros(n)
    trace = Trace(time_s, zeros, zeros, zeros, zeros, zeros, zeros, zeros, zeros, zeros, zeros, judgment, since, zeros)
    times, values = judgment_events(trace)
    assert times == pytest.approx([0.99]) and values.tolist() == [1]


def test_oracle_gets_the_oracle_observation_on_the_default_id(tmp_path):
    result = record.record_episode("oracle", ENV_ID, 0, tmp_path, max_steps=3)
    assert result.steps == 3  # it would raise if the true xi were missing from its observation


def test_a_named_caregiver_is_recorded_with_the_settings_chosen_for_the_level():
    from agents.caregivers.scripted import TUNED_BLIND, TUNED_PROBER

    # As agents.evaluate plays them: the hard level's blind and probing settings on a hard id.
    for env_id, level in (("CoopGym/SitToStandHard-v1", "hard"), (ENV_ID, "v0")):
        env = gym.make(env_id)
        assert record._agent_for("blind", env, env_id, 0)[0].settings == TUNED_BLIND[level]
        assert record._agent_for("prober", env, env_id, 0)[0].settings == TUNED_PROBER[level]
        env.close()
    assert TUNED_BLIND["hard"] != TUNED_BLIND["v0"]


def test_record_episode_runs_a_persona_and_stops_at_max_steps(tmp_path):
    result = record.record_episode("handbook", ENV_ID, 1, tmp_path, persona="frail", max_steps=8)
    assert result.steps == 8 and result.outcome == "none"  # stopped by max_steps, not by the episode
    assert result.trace.persona == "frail"  # a held-out persona runs on the default (training) id
    assert result.video_path.is_file() and result.timeline_path.is_file()


def test_mp4_failure_falls_back_to_a_gif_and_says_so(tmp_path, monkeypatch, capsys):
    from moviepy.video.io.ImageSequenceClip import ImageSequenceClip

    def broken(self, *args, **kwargs):
        Path(args[0]).write_bytes(b"half")  # leave a broken file behind, as a crashed ffmpeg would
        raise OSError("ffmpeg exploded")

    monkeypatch.setattr(ImageSequenceClip, "write_videofile", broken)
    assert record.main(["--agent", "push_then_lift", "--out", str(tmp_path), "--max-steps", "6"]) == 0
    err = capsys.readouterr().err
    assert "MP4 writing failed (OSError: ffmpeg exploded); wrote a GIF instead" in err
    assert not list(tmp_path.glob("*.mp4"))
    gif = tmp_path / "push_then_lift-seed0-episode-0.gif"
    with PIL.open(gif) as image:
        assert image.format == "GIF" and image.size == (600, 400) and image.n_frames >= 2


def test_record_runs_a_saved_sb3_model(tmp_path, capsys):
    sb3 = pytest.importorskip("stable_baselines3")
    model = sb3.PPO("MlpPolicy", gym.make(ENV_ID), n_steps=32, batch_size=32, seed=0, device="cpu")
    path = tmp_path / "ppo_model.zip"
    model.save(path)
    assert record.main(["--model", str(path), "--out", str(tmp_path), "--max-steps", "5"]) == 0
    assert "ppo_model on CoopGym/SitToStand-v0" in capsys.readouterr().out
    assert (tmp_path / "ppo_model-seed0-timeline.png").is_file()
    # A model trained on another observation space is a usage error, not a crash mid-episode.
    with pytest.raises(SystemExit) as excinfo:
        record.main(["--model", str(path), "--env", "CoopGym/SitToStandOracle-v0", "--out", str(tmp_path)])
    assert excinfo.value.code == 2
    assert "pass the env id it was trained on" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--out", "o"], "Missing required argument group: • --agent, --model"),
        (["--agent", "handbook"], "--out"),
        (["--agent", "handbook", "--model", "m.zip", "--out", "o"], "--agent and --model are not allowed together"),
        (["--agent", "nurse", "--out", "o"], "invalid choice"),
        (["--agent", "handbook", "--out", "o", "--env", "CoopGym/Nope-v0"], "unknown env id"),
        (["--agent", "handbook", "--out", "o", "--persona", "nobody"], "unknown persona"),
        (["--agent", "handbook", "--out", "o", "--fps", "0"], "positive integer"),
        (["--agent", "handbook", "--out", "o", "--max-steps", "-3"], "positive integer"),
        (["--agent", "handbook", "--out", "o", "--seed", "x"], "expected a non-negative integer seed"),
        (["--model", "missing.zip", "--out", "o"], "no such file or folder"),
    ],
)
def test_bad_flags_exit_2_with_a_clear_message(argv, message, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as excinfo:
        record.main(argv)
    assert excinfo.value.code == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())


def test_bad_flag_exit_status_of_the_real_process(tmp_path):
    proc = subprocess.run(
        [sys.executable, "-m", "agents.tools.record", "--agent", "handbook", "--out", "o", "--fps", "-1"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2 and "--fps" in proc.stderr and "Traceback" not in proc.stderr


def test_human_render_mode_steps_headless_and_closes_twice():
    env = gym.make(ENV_ID, render_mode="human")
    env.reset(seed=0)
    for _ in range(3):
        env.step(SOFT_PUSH_FORWARD)
    assert env.render() is None
    env.close()
    env.close()


def test_readme_figure_script_makes_a_small_scene_png(tmp_path, capsys):
    spec = importlib.util.spec_from_file_location("make_readme_figures", REPO / "scripts" / "make_readme_figures.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    assert script.main(["--only", "scene", "--out", str(tmp_path)]) == 0
    path = tmp_path / "scene.png"
    with PIL.open(path) as image:
        assert image.size == (600, 400)
        pixels = np.asarray(image.convert("RGB"))
    assert path.stat().st_size < 150 * 1024 and pixels.std() > 20
    assert f"wrote {path}" in capsys.readouterr().out
    with pytest.raises(SystemExit) as excinfo:
        script.main(["--only", "scenery", "--out", str(tmp_path)])
    assert excinfo.value.code == 2
