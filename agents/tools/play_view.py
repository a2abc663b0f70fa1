"""The window of :mod:`agents.tools.play`: the env's rgb frame with a control panel below it.

The scene itself is the env's own ``rgb_array`` frame (:mod:`coop_gym.envs.render.renderer`);
this module only draws around it, on one off-screen surface that the window shows and a
recorder can copy (:meth:`PlayView.pixels`). While an episode runs the frame's "true
cooperativeness" face is covered, so the player reads the person as an agent must (from
the body and the filter's gauge); the summary after the episode reveals it.

pygame is imported when a view is built, never at module import.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from coop_gym.envs.contract import PUSH_BY_NAME, PUSH_FIRM, VERBAL_BACK, VERBAL_FORWARD
from coop_gym.envs.render.renderer import SitToStandRenderer

__all__ = ["KEY_HELP", "PlayView", "Summary"]

KEY_HELP = "1/2/3 push none/soft/firm (held)   B lean back   F lean forward   L lift   Space pause   Esc quit"
"""One line of key help, shown under the scene (the keys are :data:`agents.tools.play.KEYS`)."""

_PANEL_H = 210
_BG = (248, 248, 245)
_INK = (40, 44, 52)
_MUTED = (120, 126, 136)
_PUSH = (214, 96, 20)
_LIFT = (128, 60, 170)
_XI_COLOURS = {-1: (207, 52, 52), 0: (140, 140, 140), 1: (46, 160, 67)}
_OUTCOME_COLOURS = {
    "success": (46, 160, 67),
    "unsafe": (207, 52, 52),
    "premature": (224, 130, 20),
    "timeout": (110, 116, 128),
}


@dataclass(frozen=True)
class Summary:
    """What the end-of-episode panel shows.

    Attributes:
        outcome: The episode's outcome label.
        lift_time_s: Time of the player's lift, None without one [s].
        episode_return: The player's return.
        persona: The persona the person was drawn from (revealed at the end).
        times_s: Episode time of each entry of ``true_xi`` [s] (the reset first).
        true_xi: The person's true cooperativeness after the reset and after each step.
        actions: The player's ``(push, verbal, lift)`` per step.
        others: ``(agent, outcome, lift time or None)`` of the scripted agents on the same seed.
        episode_s: Length of the time axis [s].
        next_hint: The last line (e.g. which keys continue).
    """

    outcome: str
    lift_time_s: float | None
    episode_return: float
    persona: str
    times_s: Sequence[float]
    true_xi: Sequence[int]
    actions: Sequence[tuple[int, int, int]]
    others: Sequence[tuple[str, str, float | None]]
    episode_s: float
    next_hint: str


def _lift_text(lift_time_s: float | None) -> str:
    return "no lift" if lift_time_s is None else f"lift at {lift_time_s:.1f} s"


class PlayView:
    """One surface: the env frame on top, the control or summary panel below.

    Args:
        frame_size: ``(width, height)`` of the env's rgb frames [px].
        window: Open a pygame window (False: draw off-screen only, e.g. to record).
    """

    def __init__(self, frame_size: tuple[int, int] = (600, 400), window: bool = True) -> None:
        """Create the surface (and the window when asked)."""
        os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
        import pygame

        self._pg = pygame
        pygame.font.init()
        self.width, self.frame_h = frame_size
        self.size = (self.width, self.frame_h + _PANEL_H)
        self.surface = pygame.Surface(self.size)
        # The renderer's own layout names where the true-xi face is drawn in a frame of this size.
        self._face = SitToStandRenderer(*frame_size).regions["face"]
        self._fonts: dict[int, Any] = {}
        self._screen: Any = None
        if window:
            pygame.display.init()
            pygame.display.set_caption("coop_gym - play the caregiver")
            self._screen = pygame.display.set_mode(self.size)

    def _text(self, text: str, pos: tuple[int, int], size: int = 20, colour: tuple[int, int, int] = _INK) -> None:
        if size not in self._fonts:
            self._fonts[size] = self._pg.font.Font(None, size)
        self.surface.blit(self._fonts[size].render(text, True, colour), pos)

    def _frame(self, frame: NDArray[np.uint8], hide_true_xi: bool) -> None:
        pg = self._pg
        self.surface.fill(_BG)
        self.surface.blit(pg.surfarray.make_surface(np.ascontiguousarray(frame.transpose(1, 0, 2))), (0, 0))
        if hide_true_xi:
            left, top, w, h = self._face
            pg.draw.rect(self.surface, (236, 239, 243), (left, top, w, h))
            self._text("?", (left + w // 2 - 8, top + h // 2 - 22), 48, _MUTED)
            self._text("hidden", (left + w // 2 - 20, top + h - 18), 18, _MUTED)

    def show_playing(
        self, frame: NDArray[np.uint8], push: int, said: str, time_s: float, seed: int, status: str
    ) -> None:
        """Draw a running episode: the frame (true xi hidden) and the held controls."""
        self._frame(frame, hide_true_xi=True)
        y = self.frame_h + 12
        self._text(f"seed {seed}   t = {time_s:4.1f} s   {status}", (12, y), 24)
        self._text("push:", (12, y + 36), 24)
        for level, name in enumerate(PUSH_BY_NAME):
            colour = _PUSH if level == push else _MUTED
            self._text(f"[{level + 1}] {name}", (80 + 90 * level, y + 36), 24, colour)
        self._text(f"last words: {said or '-'}", (12, y + 68), 24)
        self._text(KEY_HELP, (12, self.size[1] - 26), 17, _MUTED)

    def show_summary(self, frame: NDArray[np.uint8], summary: Summary) -> None:
        """Draw the end of an episode: outcome, the true mental state over time, the scripted agents."""
        pg = self._pg
        self._frame(frame, hide_true_xi=False)
        y = self.frame_h + 6
        colour = _OUTCOME_COLOURS.get(summary.outcome, _INK)
        self._text(
            f"you: {summary.outcome.upper()}, {_lift_text(summary.lift_time_s)}, return {summary.episode_return:+.2f}"
            f"   (persona {summary.persona})",
            (12, y),
            24,
            colour,
        )
        # The chart: true xi as a step line over three rows, the player's cues beneath it.
        left, right, top = 70, self.width - 14, y + 28
        row_h = 16
        # The axis ends a little after the last event worth seeing (the episode, or a scripted lift).
        ends = [summary.times_s[-1]] + [t for _, _, t in summary.others if t is not None]
        span = min(summary.episode_s, max(5.0, float(np.ceil(max(ends) + 0.5))))

        def x_of(t: float) -> int:
            return int(left + (right - left) * min(max(t / span, 0.0), 1.0))

        for xi, name in ((1, "coop"), (0, "unresp"), (-1, "uncoop")):
            yy = top + (1 - xi) * row_h
            self._text(name, (12, yy), 16, _XI_COLOURS[xi])
            pg.draw.line(self.surface, (225, 225, 225), (left, yy + 6), (right, yy + 6))
        for k in range(len(summary.true_xi) - 1):
            xi = int(summary.true_xi[k])
            x0, x1 = x_of(summary.times_s[k]), x_of(summary.times_s[k + 1])
            yy = top + (1 - xi) * row_h + 6
            pg.draw.rect(self.surface, _XI_COLOURS[xi], (x0, yy - 2, max(x1 - x0, 1), 5))
            if k + 1 < len(summary.true_xi) and summary.true_xi[k + 1] != xi:  # the switch, as a riser
                y_next = top + (1 - int(summary.true_xi[k + 1])) * row_h + 6
                pg.draw.line(self.surface, _MUTED, (x1, yy), (x1, y_next), 1)
        cue_y = top + 3 * row_h + 4
        self._text("you", (12, cue_y), 16)
        for k, (push, verbal, lift) in enumerate(summary.actions):
            x0, x1 = x_of(summary.times_s[k]), max(x_of(summary.times_s[k + 1]), x_of(summary.times_s[k]) + 1)
            if push:
                h = 5 if push < PUSH_FIRM else 10
                pg.draw.rect(self.surface, _PUSH, (x0, cue_y + 12 - h, x1 - x0, h))
            if verbal in (VERBAL_BACK, VERBAL_FORWARD):
                self._text("B" if verbal == VERBAL_BACK else "F", (x0 - 3, cue_y - 2), 16, (40, 90, 200))
            if lift:
                pg.draw.line(self.surface, _LIFT, (x0, top), (x0, cue_y + 12), 2)
        axis_y = cue_y + 16
        pg.draw.line(self.surface, _MUTED, (left, axis_y), (right, axis_y))
        for t in range(0, int(span) + 1, 1 if span <= 12 else 5):
            self._text(f"{t}s", (x_of(t) - 6, axis_y + 2), 14, _MUTED)
        # Where the scripted agents lifted on the same person, as ticks on the axis.
        y = axis_y + 18
        for k, (agent, outcome, lift_time) in enumerate(summary.others):
            mark = (0, 120, 200) if k == 0 else (200, 120, 0)
            if lift_time is not None:
                pg.draw.line(self.surface, mark, (x_of(lift_time), top), (x_of(lift_time), axis_y), 1)
            line = f"{agent}: {outcome}, {_lift_text(lift_time)}"
            self._text(line, (12 + 290 * k, y), 20, _OUTCOME_COLOURS.get(outcome, _INK))
            pg.draw.rect(self.surface, mark, (2 + 290 * k, y + 4, 7, 7))
        self._text(summary.next_hint, (12, self.size[1] - 22), 18, _MUTED)

    def present(self) -> None:
        """Show the surface in the window (if one is open)."""
        if self._screen is not None:
            self._screen.blit(self.surface, (0, 0))
            self._pg.display.flip()

    def pixels(self) -> NDArray[np.uint8]:
        """A copy of the surface as an ``(H, W, 3)`` array (for recordings)."""
        return np.array(self._pg.surfarray.pixels3d(self.surface).transpose(1, 0, 2), dtype=np.uint8, order="C")

    def close(self) -> None:
        """Close the window, if one is open; safe to call twice."""
        if self._screen is not None:
            self._pg.display.quit()
            self._screen = None
