"""agents.tools.play driven headless by scripted key presses; the played-episodes CSV and its score."""

from __future__ import annotations

import json

import pytest

pytest.importorskip("pygame")

import pygame

from agents.base import LIFT, PUSH_FIRM, PUSH_SOFT, VERBAL_FORWARD, VERBAL_NONE, WAIT
from agents.tools.play import Controls, main, play, pygame_keys, score_played, scripted_keys
from agents.tools.play_log import PLAYED_COLUMNS, PlayedEpisode, append_played, next_seed, read_played

ENV_ID = "CoopGym/SitToStandHard-v1"
# Paused at the start; Space and a firm push, "lean forward" at 1.0 s, soft push from 2.0 s, lift at 4.0 s, Enter.
SCRIPT = [[], ["space", "3"], *[[]] * 9, ["f"], *[[]] * 9, ["2"], *[[]] * 19, ["l"], ["return"]]


@pytest.fixture(autouse=True)
def _headless(monkeypatch):
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    monkeypatch.setenv("SDL_AUDIODRIVER", "dummy")


def test_controls_hold_the_push_and_use_words_and_lift_once():
    controls = Controls()
    assert controls.press("3") is None and controls.press("f") == "act"
    assert controls.take() == (PUSH_FIRM, VERBAL_FORWARD, WAIT)
    assert controls.take() == (PUSH_FIRM, VERBAL_NONE, WAIT)
    controls.press("2")
    controls.press("l")
    assert controls.take() == (PUSH_SOFT, VERBAL_NONE, LIFT)
    assert controls.press("escape") == "quit" and controls.press("space") == "space"


def test_a_scripted_episode_is_played_headless_appended_once_and_scored(tmp_path):
    csv_path = tmp_path / "played.csv"
    frames = []
    played = play(ENV_ID, 5, "test", csv_path, fps=0, episodes=1, keys=scripted_keys(SCRIPT), on_frame=frames.append)
    assert len(played) == 1
    episode = played[0]
    assert episode.steps == 41 and episode.actions[0] == (PUSH_FIRM, 0, 0) and episode.actions[-1] == (1, 0, 1)
    assert episode.actions[10] == (PUSH_FIRM, VERBAL_FORWARD, 0)
    assert episode.outcome in ("success", "unsafe", "premature") and episode.lift_time_s == pytest.approx(4.0)
    # One frame per step, the first after the reset, and the summary.
    assert len(frames) == 1 + 41 + 1 and frames[0].shape == (610, 600, 3)

    lines = csv_path.read_text().splitlines()
    assert lines[0] == ",".join(PLAYED_COLUMNS) and len(lines) == 2
    (read,) = read_played(csv_path)
    assert read.actions == episode.actions and read.seed == 5 and read.outcome == episode.outcome

    result = score_played(csv_path, ENV_ID)
    assert result.agent == "human" and result.episodes == 1 and result.env_id == ENV_ID
    assert result.count(episode.outcome) == 1
    assert result.records[0].duration_s == pytest.approx(4.0)
    assert result.records[0].episode_return == pytest.approx(episode.episode_return)
    assert set(result.summary()) >= {"success_rate", "success_rate_ci95", "unsafe_rate_ci95", "mean_return"}
    # Without --seed the next session starts one past the CSV's seeds.
    assert next_seed(csv_path, ENV_ID) == 6 and next_seed(csv_path, "CoopGym/SitToStand-v0") == 0


def test_keys_come_through_pygames_event_queue_in_turns_pace(tmp_path):
    """The real key path: KEYDOWN events posted to pygame's queue, read by the default key source."""
    script = iter([["3"], ["space"], ["space"], ["f"], ["l"], ["return"]])

    def keys():
        for name in next(script, ["escape"]):
            pygame.event.post(pygame.event.Event(pygame.KEYDOWN, key=pygame.key.key_code(name)))
        return pygame_keys()

    (episode,) = play(ENV_ID, 9, "test", tmp_path / "p.csv", pace="turns", episodes=1, keys=keys)
    # In turns pace only Space, words and lift advance time: four steps.
    assert episode.actions == ((2, 0, 0), (2, 0, 0), (2, 2, 0), (2, 0, 1))


def test_quitting_mid_episode_records_nothing(tmp_path):
    csv_path = tmp_path / "p.csv"
    assert play(ENV_ID, 1, "test", csv_path, fps=0, keys=scripted_keys([["space", "3"], [], ["q"]])) == []
    assert not csv_path.exists()


def test_appending_keeps_earlier_lines_byte_for_byte(tmp_path):
    csv_path = tmp_path / "p.csv"
    first = PlayedEpisode(ENV_ID, 1, "test", "frail", "timeout", None, -1.5, ((0, 0, 0),) * 3)
    append_played(csv_path, first)
    before = csv_path.read_bytes()
    append_played(csv_path, PlayedEpisode(ENV_ID, 2, "test", "frail", "unsafe", 0.0, -10.0, ((0, 0, 1),)))
    after = csv_path.read_bytes()
    assert after.startswith(before) and after.count(b"\n") == 3


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("name,score\nalice,3\n", "not a played-episodes CSV"),
        (",".join(PLAYED_COLUMNS) + "\n2026-01-01,x,1,test,frail,success,1.0,1,0.5,001", "incomplete line"),
    ],
)
def test_a_foreign_or_truncated_csv_is_refused_and_left_untouched(tmp_path, content, message, capsys):
    csv_path = tmp_path / "p.csv"
    csv_path.write_text(content)
    episode = PlayedEpisode(ENV_ID, 1, "test", "frail", "timeout", None, -1.5, ((0, 0, 0),))
    with pytest.raises(ValueError, match=message):
        append_played(csv_path, episode)
    with pytest.raises(ValueError, match=message):
        score_played(csv_path, ENV_ID)
    assert main(["--csv", str(csv_path)]) == 2  # refused before the window opens
    assert message in capsys.readouterr().err
    assert csv_path.read_text() == content


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("actions", "201 3x0", "bad action '3x0'"),
        ("outcome", "won", "unknown outcome 'won'"),
        ("steps", "7", "steps is 7 but 2 actions"),
        ("seed", "-1", "outside"),
        ("episode_return", "nan", "finite"),
    ],
)
def test_a_corrupt_line_is_named(tmp_path, field, value, message):
    csv_path = tmp_path / "p.csv"
    append_played(csv_path, PlayedEpisode(ENV_ID, 1, "test", "frail", "unsafe", 0.1, -10.0, ((2, 0, 0), (2, 0, 1))))
    header, line = csv_path.read_text().splitlines()
    cells = line.split(",")
    cells[PLAYED_COLUMNS.index(field)] = value
    csv_path.write_text(f"{header}\n{','.join(cells)}\n")
    with pytest.raises(ValueError, match=rf"p\.csv:2: .*{message}"):
        score_played(csv_path, ENV_ID)


def test_a_line_that_no_longer_replays_is_refused(tmp_path):
    csv_path = tmp_path / "p.csv"
    (episode,) = play(ENV_ID, 3, "test", csv_path, fps=0, episodes=1, keys=scripted_keys(SCRIPT), window=False)
    other = "timeout" if episode.outcome != "timeout" else "success"
    csv_path.write_text(csv_path.read_text().replace(f",{episode.outcome},", f",{other},"))
    with pytest.raises(ValueError, match="replays as"):
        score_played(csv_path, ENV_ID)
    with pytest.raises(ValueError, match="no played episode of CoopGym/SitToStand-v0"):
        score_played(csv_path, "CoopGym/SitToStand-v0")


def test_evaluate_human_adds_the_played_csv_as_the_human_row(tmp_path, capsys):
    from agents.tools.evaluate_cli import main as evaluate

    csv_path = tmp_path / "played.csv"
    (episode,) = play(ENV_ID, 5, "test", csv_path, fps=0, episodes=1, keys=scripted_keys(SCRIPT))
    argv = ["--compare", "blind,oracle", "--env", ENV_ID, "--episodes", "8", "--human", str(csv_path)]
    assert evaluate(argv) == 0
    table = capsys.readouterr().out
    assert any(line.lstrip("│┃ ").startswith("human ") for line in table.splitlines())
    assert "best non-oracle (blind)" in table and "human: mind-reading score" in table
    # Alone, on the CSV's own env id; its outcome is the one played.
    assert evaluate(["--human", str(csv_path), "--json"]) == 0
    row = json.loads(capsys.readouterr().out)
    assert row["agent"] == "human" and row["env_id"] == ENV_ID and row["episodes"] == 1
    assert row[f"{episode.outcome}_rate"] == 1.0
    with pytest.raises(SystemExit) as exc:
        evaluate(["--agent", "blind", "--human", str(tmp_path / "none.csv")])
    assert exc.value.code == 2 and "--human: no played-episodes CSV" in capsys.readouterr().err
