"""Side-view rendering of the sit-to-stand scene for ``rgb_array`` and ``human`` render modes.

The renderer is independent of the environment: the env packs what is to be shown into a
:class:`RenderState` and calls :meth:`SitToStandRenderer.render_rgb` (a fresh ``(H, W, 3)``
``uint8`` frame, e.g. for ``gymnasium.wrappers.RecordVideo``) or
:meth:`SitToStandRenderer.render_human` (a pygame window).

The picture follows Gymnasium's ``classic_control`` pattern (pygame surfaces and
``pygame.gfxdraw``; pygame imported lazily so that the package imports without it):

* left, the scene: a chair, the seated person whose torso leans by
  ``asin(shoulder_position_m / torso_length)``, the shoulder's lean arc with the lean needed for a
  safe lift, the robot's push on the upper back as an arrow scaled by force, the robot's verbal cue
  as a speech bubble, and an upward arrow on the frame where the robot lifts;
* right, the estimator panel: a vertical gauge of the cooperativeness estimate on
  ``[-1.5, 1.5]`` with the ``±threshold`` band, the estimate with a ``±1 std`` bar, the
  thresholded judgment, the person's true cooperativeness as a small face, and ``P(xi = k)`` bars
  when a multiple-model estimator provides them;
* bottom, a status line (time, position, force, cue) replaced by a coloured banner when the
  episode ends.

Everything is drawn on a fixed 600x400 canvas; other sizes are letterboxed scalings of it.
Static parts (background, floor, chair, robot, gauge scale) are drawn once and cached.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Final

import numpy as np
from gymnasium.error import DependencyNotInstalled
from numpy.typing import NDArray

from compiled.checks import is_integer
from coop_gym.envs.config import Outcome

if TYPE_CHECKING:  # pragma: no cover - typing only
    import pygame

__all__ = ["OUTCOMES", "RenderState", "SitToStandRenderer"]

OUTCOMES: Final[tuple[str, ...]] = tuple(o.label for o in Outcome if o is not Outcome.NONE)
"""Episode outcomes the renderer can show as a banner."""

# ---------------------------------------------------------------------------------------------
# Geometry of the base canvas (pixels). Everything is drawn at this size and scaled if needed.
# ---------------------------------------------------------------------------------------------
_BASE_W: Final = 600
_BASE_H: Final = 400
_PIXELS_PER_M: Final = 250.0
_TORSO_LENGTH_M: Final = 0.5  # hip to shoulder; the lean angle is asin(x / this)
_MAX_LEAN_SIN: Final = 0.95  # keeps asin defined and the drawing sane for any x
_XI_RANGE: Final = 1.5  # the gauge spans [-1.5, 1.5]
_MAX_ARROW_FORCE_N: Final = 60.0

_FLOOR_Y: Final = 350
_HIP: Final = (165.0, 262.0)
_TORSO_PX: Final = _TORSO_LENGTH_M * _PIXELS_PER_M
_KNEE: Final = (_HIP[0] + 105.0, _HIP[1])
_ANKLE: Final = (_KNEE[0] + 4.0, _FLOOR_Y - 10.0)
_ARC_RADIUS: Final = _TORSO_PX + 60  # lean arc drawn just beyond the top of the head
# Where a hand may rest: along the top of the thigh, then down the front of the shin.
_HAND_PATH: Final = tuple(
    [(_HIP[0] + 30.0 + 2.0 * i, _HIP[1] - 17.0) for i in range(int((_KNEE[0] + 14.0 - _HIP[0] - 30.0) / 2))]
    + [(_KNEE[0] + 14.0 + 0.05 * j, _HIP[1] - 17.0 + float(j)) for j in range(0, 70, 2)]
)
_UPPER_ARM_PX: Final = 78.0
_FOREARM_PX: Final = 74.0

_GAUGE_X: Final = 414  # left edge of the gauge bar
_GAUGE_W: Final = 22
_GAUGE_TOP: Final = 50
_GAUGE_BOTTOM: Final = 284

_PROB_X: Final = 515
_PROB_TOP: Final = 180
_PROB_BOTTOM: Final = 270

# Colours (RGB).
_BG = (248, 248, 245)
_PANEL_BG = (236, 239, 243)
_INK = (40, 44, 52)
_MUTED = (120, 126, 136)
_FLOOR = (196, 186, 170)
_CHAIR = (139, 94, 60)
_CHAIR_DARK = (105, 70, 45)
_SKIN = (238, 196, 160)
_SKIN_DARK = (200, 150, 115)
_HAIR = (205, 205, 210)
_SHIRT = (70, 110, 170)
_SHIRT_DARK = (50, 82, 130)
_TROUSERS = (82, 84, 96)
_SHOE = (45, 45, 50)
_PUSH = (214, 96, 20)
_LIFT = (128, 60, 170)
_GREEN = (46, 160, 67)
_RED = (207, 52, 52)
_GREY = (140, 140, 140)
_BLUE = (40, 90, 200)
_ARC = (185, 190, 200)

_XI_COLOURS: Final = {-1: _RED, 0: _GREY, 1: _GREEN}
_XI_NAMES: Final = {-1: "uncooperative", 0: "unresponsive", 1: "cooperative"}
_CUE_TEXT: Final = {-1: "Please lean back.", 1: "Please lean forward."}
_CUE_NAMES: Final = {-1: "lean back", 0: "none", 1: "lean forward"}
_BANNERS: Final = {
    "success": ("SUCCESS \u2013 safe lift", _GREEN),
    "unsafe": ("UNSAFE LIFT", _RED),
    "premature": ("PREMATURE LIFT", (224, 130, 20)),
    "timeout": ("TIMEOUT \u2013 no lift", (110, 116, 128)),
}

# Screen regions in base-canvas pixels, (left, top, width, height). Kept in one place so the
# drawing code and the tests (via ``SitToStandRenderer.regions``) agree.
_REGIONS: Final[dict[str, tuple[int, int, int, int]]] = {
    "scene": (0, 0, 380, _FLOOR_Y + 2),
    "torso": (110, 60, 230, 215),
    "arrow": (20, 130, 240, 70),
    "bubble": (62, 26, 238, 52),
    "lift": (300, 180, 75, 110),
    "time": (8, 4, 140, 22),
    "panel": (380, 0, 220, _FLOOR_Y + 2),
    "gauge": (386, 40, 120, 276),
    "judgment": (386, 320, 208, 26),
    "face": (515, 40, 80, 90),
    "probabilities": (508, 150, 88, 140),
    "banner": (0, _FLOOR_Y + 4, _BASE_W, _BASE_H - _FLOOR_Y - 4),
}


@dataclass(frozen=True)
class RenderState:
    """Everything one frame shows; built by the environment at each render call.

    Attributes:
        time_s: Elapsed episode time [s].
        shoulder_position_m: True torso/shoulder displacement ``x`` [m], forward positive
            (typically -0.10..0.40). Sets the torso lean angle ``asin(x / 0.5 m)``.
        push_force_n: Push on the upper back [N], ``>= 0``; the arrow length scales with it
            (no arrow at 0, full length at 60 N).
        verbal_cue: Verbal cue playing: -1 "lean back", 0 none, +1 "lean forward".
        xi_estimate: The estimator's cooperativeness estimate (KF mean of ``xi`` or the expected
            ``xi``); any real, drawn clipped to ``[-1.5, 1.5]``. Not drawn if not finite.
        xi_std: Standard deviation of the estimate (``>= 0``), drawn as a ``±1 std`` bar.
        threshold: Judgment threshold (paper: 0.3); the ``±threshold`` band is shaded on the gauge.
        judgment: Latest thresholded judgment in {-1, 0, +1}.
        true_xi: The person's true cooperativeness in {-1, 0, +1}, drawn as a face (red frown,
            grey neutral, green smile).
        outcome: ``None`` while running; at the end one of ``"success"``, ``"unsafe"``,
            ``"premature"``, ``"timeout"``, shown as a banner.
        probabilities: ``(P(xi=-1), P(xi=0), P(xi=+1))`` from a multiple-model estimator, drawn
            as three bars when given.
        lift: ``True`` on the frame where the robot lifts (an upward arrow is drawn).
        success_lean_m: Lean needed for a safe lift [m], drawn as a marker on the shoulder's arc.
    """

    time_s: float
    shoulder_position_m: float
    push_force_n: float
    verbal_cue: int
    xi_estimate: float
    xi_std: float
    threshold: float
    judgment: int
    true_xi: int
    outcome: str | None = None
    probabilities: tuple[float, float, float] | None = None
    lift: bool = False
    success_lean_m: float = 0.15

    def __post_init__(self) -> None:
        """Reject discrete fields outside their sets, naming the field.

        Raises:
            ValueError: If ``verbal_cue``, ``judgment`` or ``true_xi`` is not in {-1, 0, 1},
                ``outcome`` is not ``None`` or one of :data:`OUTCOMES`, or ``probabilities`` does
                not have three entries.
        """
        for name in ("verbal_cue", "judgment", "true_xi"):
            value = getattr(self, name)
            if value not in (-1, 0, 1):
                raise ValueError(f"RenderState.{name} must be -1, 0 or 1, got {value!r}")
        if self.outcome is not None and self.outcome not in OUTCOMES:
            raise ValueError(f"RenderState.outcome must be None or one of {OUTCOMES}, got {self.outcome!r}")
        if self.probabilities is not None and len(self.probabilities) != 3:
            raise ValueError(
                f"RenderState.probabilities must have 3 entries (P(xi=-1), P(xi=0), P(xi=+1)), "
                f"got {len(self.probabilities)}"
            )


def _finite(value: float, default: float = 0.0) -> float:
    """Return ``value`` as a float, or ``default`` if it is NaN or infinite."""
    value = float(value)
    return value if math.isfinite(value) else default


def _import_pygame() -> Any:
    """Import pygame lazily, as Gymnasium's classic-control envs do.

    Returns:
        The ``pygame`` module (with ``pygame.gfxdraw`` loaded).

    Raises:
        DependencyNotInstalled: If pygame is missing.
    """
    # Keep training logs free of pygame's import banner.
    os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
    try:
        import pygame
        from pygame import gfxdraw  # noqa: F401  (loads the submodule used through pygame.gfxdraw)
    except ImportError as e:
        raise DependencyNotInstalled('pygame is not installed, run `pip install "gymnasium[classic-control]"`') from e
    return pygame


class SitToStandRenderer:
    """Draws :class:`RenderState` frames as RGB arrays or in a pygame window.

    The scene is laid out on a 600x400 canvas; other sizes are uniformly scaled and letterboxed.
    Only the pygame display is opened and closed by this class (in ``human`` mode); pygame's font
    module is initialised on first use and left running, so several renderers (e.g. one per
    env of a vector env) can coexist in one process.

    Attributes:
        width: Frame width [px].
        height: Frame height [px].
        regions: Named screen rectangles ``(left, top, width, height)`` in frame pixels, for
            slicing frames as ``frame[top:top + height, left:left + width]``. Keys: ``"scene"``,
            ``"torso"`` (person, all leans), ``"arrow"`` (push arrow), ``"bubble"`` (speech bubble),
            ``"lift"`` (lift arrow), ``"time"``, ``"panel"``, ``"gauge"`` (xi gauge with its
            estimate marker), ``"judgment"``, ``"face"`` (true xi), ``"probabilities"``,
            ``"banner"`` (status line / outcome banner).

    Example:
        >>> renderer = SitToStandRenderer()
        >>> frame = renderer.render_rgb(RenderState(time_s=1.0, shoulder_position_m=0.1, push_force_n=10.0,
        ...     verbal_cue=1, xi_estimate=0.4, xi_std=0.2, threshold=0.3, judgment=1, true_xi=1))
        >>> frame.shape, frame.dtype
        ((400, 600, 3), dtype('uint8'))
        >>> renderer.close()
    """

    def __init__(self, width: int = 600, height: int = 400) -> None:
        """Create a renderer; no pygame resources are allocated until the first frame.

        Args:
            width: Frame width [px], at least 60.
            height: Frame height [px], at least 40.

        Raises:
            ValueError: If ``width`` or ``height`` is not an integer of at least 60 / 40.
        """
        for name, value, minimum in (("width", width, 60), ("height", height, 40)):
            if not is_integer(value) or value < minimum:
                raise ValueError(f"SitToStandRenderer {name} must be an int >= {minimum}, got {value!r}")
        self.width = int(width)
        self.height = int(height)
        # Uniform scale of the base canvas into the requested size, centred (letterbox).
        self._scale = min(self.width / _BASE_W, self.height / _BASE_H)
        scaled_w, scaled_h = round(_BASE_W * self._scale), round(_BASE_H * self._scale)
        self._offset = ((self.width - scaled_w) // 2, (self.height - scaled_h) // 2)
        self._scaled_size = (scaled_w, scaled_h)
        self.regions: dict[str, tuple[int, int, int, int]] = {
            name: self._to_frame_rect(rect) for name, rect in _REGIONS.items()
        }

        self._pg: Any = None
        self._fonts: dict[int, Any] = {}
        self._text_cache: dict[tuple[str, int, tuple[int, int, int]], Any] = {}
        self._background: pygame.Surface | None = None
        self._canvas: pygame.Surface | None = None
        self._frame: pygame.Surface | None = None
        self._screen: pygame.Surface | None = None
        self._clock: Any = None

    # ----------------------------------------------------------------------------------------
    # Public API
    # ----------------------------------------------------------------------------------------
    def render_rgb(self, state: RenderState) -> NDArray[np.uint8]:
        """Draw ``state`` off-screen and return the frame.

        Args:
            state: What to draw.

        Returns:
            A new ``(height, width, 3)`` ``uint8`` C-contiguous array (never shared with the
            renderer or with earlier frames).
        """
        surface = self._draw(state)
        pg = self._pg
        pixels = pg.surfarray.pixels3d(surface)  # (W, H, 3) view that locks the surface
        try:
            frame = np.array(pixels.transpose(1, 0, 2), dtype=np.uint8, order="C")
        finally:
            del pixels  # release the surface lock
        return frame

    def render_human(self, state: RenderState, fps: int) -> None:
        """Draw ``state`` into a pygame window, pump window events and hold the frame rate.

        Args:
            state: What to draw.
            fps: Target frames per second for ``pygame.time.Clock.tick``; 0 means no limit.

        Raises:
            ValueError: If ``fps`` is negative.
        """
        if fps < 0:
            raise ValueError(f"fps must be >= 0, got {fps!r}")
        surface = self._draw(state)
        pg = self._pg
        if self._screen is None:
            pg.display.init()
            pg.display.set_caption("coop_gym - SitToStand")
            self._screen = pg.display.set_mode((self.width, self.height))
        if self._clock is None:
            self._clock = pg.time.Clock()
        self._screen.blit(surface, (0, 0))
        pg.event.pump()
        self._clock.tick(int(fps))
        pg.display.flip()

    def close(self) -> None:
        """Close the window (if one was opened) and drop cached surfaces; safe to call repeatedly."""
        if self._screen is not None and self._pg is not None:
            self._pg.display.quit()
        self._screen = None
        self._clock = None
        self._background = None
        self._canvas = None
        self._frame = None
        self._fonts = {}
        self._text_cache = {}

    # ----------------------------------------------------------------------------------------
    # Set-up and caches
    # ----------------------------------------------------------------------------------------
    def _to_frame_rect(self, rect: tuple[int, int, int, int]) -> tuple[int, int, int, int]:
        """Map a base-canvas rectangle to frame pixels (scaling and letterbox offset)."""
        left, top, w, h = rect
        s = self._scale
        return (
            self._offset[0] + int(left * s),
            self._offset[1] + int(top * s),
            max(1, int(w * s)),
            max(1, int(h * s)),
        )

    def _ensure_ready(self) -> None:
        """Import pygame, initialise fonts and build the cached static layer when needed."""
        if self._pg is None:
            self._pg = _import_pygame()
        pg = self._pg
        if not pg.font.get_init():
            # Someone (e.g. another env's close() calling pygame.quit()) shut fonts down:
            # every cached Font and text surface is stale.
            pg.font.init()
            self._fonts = {}
            self._text_cache = {}
            self._background = None
        if self._background is None:
            self._canvas = pg.Surface((_BASE_W, _BASE_H))
            self._background = self._build_background()
            if (self.width, self.height) != (_BASE_W, _BASE_H):
                self._frame = pg.Surface((self.width, self.height))
            else:
                self._frame = None

    def _font(self, size: int) -> Any:
        """Return pygame's default font at ``size`` (cached)."""
        font = self._fonts.get(size)
        if font is None:
            font = self._pg.font.Font(None, size)  # default font ships with pygame
            self._fonts[size] = font
        return font

    def _text(self, text: str, size: int, colour: tuple[int, int, int] = _INK) -> Any:
        """Return an anti-aliased text surface (cached; the cache is cleared when it grows large)."""
        key = (text, size, colour)
        surf = self._text_cache.get(key)
        if surf is None:
            if len(self._text_cache) > 2048:  # time/position strings are unbounded
                self._text_cache.clear()
            surf = self._font(size).render(text, True, colour)
            self._text_cache[key] = surf
        return surf

    def _blit_text(
        self,
        surf: pygame.Surface,
        text: str,
        size: int,
        pos: tuple[float, float],
        colour: tuple[int, int, int] = _INK,
        anchor: str = "topleft",
    ) -> None:
        """Blit ``text`` with the named rect ``anchor`` (e.g. ``"center"``, ``"midleft"``) at ``pos``."""
        rendered = self._text(text, size, colour)
        rect = rendered.get_rect(**{anchor: (round(pos[0]), round(pos[1]))})
        surf.blit(rendered, rect)

    # ----------------------------------------------------------------------------------------
    # Drawing primitives
    # ----------------------------------------------------------------------------------------
    def _polygon(self, surf: pygame.Surface, points: list[tuple[float, float]], colour: tuple[int, int, int]) -> None:
        """Draw a filled anti-aliased polygon."""
        gfx = self._pg.gfxdraw
        gfx.aapolygon(surf, points, colour)
        gfx.filled_polygon(surf, points, colour)

    def _circle(
        self, surf: pygame.Surface, centre: tuple[float, float], radius: float, colour: tuple[int, int, int]
    ) -> None:
        """Draw a filled anti-aliased circle."""
        gfx = self._pg.gfxdraw
        x, y, r = round(centre[0]), round(centre[1]), max(1, round(radius))
        gfx.aacircle(surf, x, y, r, colour)
        gfx.filled_circle(surf, x, y, r, colour)

    def _capsule(
        self,
        surf: pygame.Surface,
        start: tuple[float, float],
        end: tuple[float, float],
        width: float,
        colour: tuple[int, int, int],
    ) -> None:
        """Draw a thick segment with round ends (limbs, torso)."""
        dx, dy = end[0] - start[0], end[1] - start[1]
        length = math.hypot(dx, dy) or 1.0
        nx, ny = -dy / length * width / 2, dx / length * width / 2
        self._polygon(
            surf,
            [
                (start[0] + nx, start[1] + ny),
                (end[0] + nx, end[1] + ny),
                (end[0] - nx, end[1] - ny),
                (start[0] - nx, start[1] - ny),
            ],
            colour,
        )
        self._circle(surf, start, width / 2, colour)
        self._circle(surf, end, width / 2, colour)

    def _arrow(
        self,
        surf: pygame.Surface,
        tail: tuple[float, float],
        tip: tuple[float, float],
        shaft: float,
        head: float,
        colour: tuple[int, int, int],
    ) -> None:
        """Draw a filled arrow from ``tail`` to ``tip`` with a shaft width and head size in pixels."""
        dx, dy = tip[0] - tail[0], tip[1] - tail[1]
        length = math.hypot(dx, dy)
        if length < 1.0:
            return
        ux, uy = dx / length, dy / length
        px, py = -uy, ux
        head_len = min(head, length)
        bx, by = tip[0] - ux * head_len, tip[1] - uy * head_len
        s, h = shaft / 2, head / 2 + shaft / 2
        self._polygon(
            surf,
            [
                (tail[0] + px * s, tail[1] + py * s),
                (bx + px * s, by + py * s),
                (bx + px * h, by + py * h),
                tip,
                (bx - px * h, by - py * h),
                (bx - px * s, by - py * s),
                (tail[0] - px * s, tail[1] - py * s),
            ],
            colour,
        )

    def _rounded_rect(
        self,
        surf: pygame.Surface,
        rect: tuple[float, float, float, float],
        colour: tuple[int, int, int],
        radius: int,
        border: int = 0,
    ) -> None:
        """Draw a rounded rectangle, filled (``border=0``) or outlined."""
        self._pg.draw.rect(surf, colour, self._pg.Rect(rect), border, border_radius=radius)

    # ----------------------------------------------------------------------------------------
    # Static layer
    # ----------------------------------------------------------------------------------------
    def _build_background(self) -> pygame.Surface:
        """Draw everything that never changes: backdrop, floor, chair, robot, panel and gauge scale."""
        pg = self._pg
        bg = pg.Surface((_BASE_W, _BASE_H))
        bg.fill(_BG)

        # Floor and the strip under it (status line / banner).
        pg.draw.rect(bg, _FLOOR, (0, _FLOOR_Y, _BASE_W, _BASE_H - _FLOOR_Y))
        pg.draw.line(bg, (150, 140, 125), (0, _FLOOR_Y), (_BASE_W, _FLOOR_Y), 2)

        # Estimator panel.
        panel = _REGIONS["panel"]
        pg.draw.rect(bg, _PANEL_BG, panel)
        pg.draw.line(bg, (205, 210, 218), (panel[0], 0), (panel[0], panel[3]), 2)

        self._draw_chair(bg)
        self._draw_robot(bg)
        self._draw_lean_arc_static(bg)
        self._draw_gauge_static(bg)

        self._blit_text(bg, "true \u03be", 20, (555, 44), _MUTED, "midtop")
        return bg

    def _draw_chair(self, surf: pygame.Surface) -> None:
        """Draw the chair: seat, two visible legs, a low reclined backrest."""
        seat_top = _HIP[1] + 14
        seat_left, seat_right = _HIP[0] - 40, _KNEE[0] - 10
        pg = self._pg
        # Back leg and a slightly reclined, low backrest: the upper back stays free for the push.
        self._capsule(surf, (seat_left + 6, _FLOOR_Y - 3), (seat_left + 6, seat_top), 8, _CHAIR_DARK)
        self._capsule(surf, (seat_left + 6, seat_top + 4), (seat_left - 8, _HIP[1] - 82), 9, _CHAIR_DARK)
        self._rounded_rect(surf, (seat_left - 14, _HIP[1] - 86, 18, 64), _CHAIR, 6)
        self._capsule(surf, (seat_right - 8, _FLOOR_Y - 3), (seat_right - 8, seat_top), 8, _CHAIR_DARK)
        # Seat with a cushion.
        self._rounded_rect(surf, (seat_left - 2, seat_top, seat_right - seat_left + 4, 10), _CHAIR, 4)
        pg.draw.line(surf, _CHAIR_DARK, (seat_left + 2, seat_top + 10), (seat_right - 2, seat_top + 10), 2)

    def _draw_robot(self, surf: pygame.Surface) -> None:
        """Draw a small robot head at the top left: the speaker of the verbal cue."""
        x, y = 18, 34
        pg = self._pg
        pg.draw.line(surf, _MUTED, (x + 17, y - 4), (x + 17, y + 4), 2)
        self._circle(surf, (x + 17, y - 6), 3, _PUSH)
        self._rounded_rect(surf, (x, y + 4, 34, 28), (95, 105, 120), 7)
        self._rounded_rect(surf, (x + 4, y + 9, 26, 14), (30, 35, 45), 4)
        self._circle(surf, (x + 11, y + 16), 3, (90, 220, 240))
        self._circle(surf, (x + 23, y + 16), 3, (90, 220, 240))
        self._blit_text(surf, "robot", 16, (x + 17, y + 35), _MUTED, "midtop")

    def _draw_lean_arc_static(self, surf: pygame.Surface) -> None:
        """Draw the dotted arc, centred on the hip, along which the head travels as the torso leans."""
        pg = self._pg
        for deg in range(-14, 61, 3):
            a = math.radians(deg)
            p = (_HIP[0] + _ARC_RADIUS * math.sin(a), _HIP[1] - _ARC_RADIUS * math.cos(a))
            pg.draw.circle(surf, _ARC, (round(p[0]), round(p[1])), 2)

    def _gauge_y(self, xi: float) -> float:
        """Vertical pixel of a cooperativeness value on the gauge (+1.5 at the top)."""
        xi = min(max(xi, -_XI_RANGE), _XI_RANGE)
        frac = (xi + _XI_RANGE) / (2 * _XI_RANGE)
        return _GAUGE_BOTTOM - frac * (_GAUGE_BOTTOM - _GAUGE_TOP)

    def _draw_gauge_static(self, surf: pygame.Surface) -> None:
        """Draw the gauge title, scale, ticks and labels (the threshold band is dynamic)."""
        pg = self._pg
        self._blit_text(surf, "estimate of cooperativeness \u03be", 19, (_REGIONS["panel"][0] + 8, 10), _INK)
        pg.draw.rect(surf, (255, 255, 255), (_GAUGE_X, _GAUGE_TOP, _GAUGE_W, _GAUGE_BOTTOM - _GAUGE_TOP))
        ticks = ((1.5, "+1.5"), (1.0, "+1 coop."), (0.0, "0 unresp."), (-1.0, "-1 uncoop."), (-1.5, "-1.5"))
        for value, label in ticks:
            y = round(self._gauge_y(value))
            pg.draw.line(surf, _MUTED, (_GAUGE_X + _GAUGE_W, y), (_GAUGE_X + _GAUGE_W + 5, y), 1)
            colour = _XI_COLOURS.get(int(value), _MUTED) if value in (-1.0, 1.0) else _MUTED
            self._blit_text(surf, label, 16, (_GAUGE_X + _GAUGE_W + 8, y), colour, "midleft")

    # ----------------------------------------------------------------------------------------
    # Dynamic layer
    # ----------------------------------------------------------------------------------------
    def _draw(self, state: RenderState) -> pygame.Surface:
        """Compose one frame and return the surface holding it at the requested size."""
        self._ensure_ready()
        canvas = self._canvas
        assert canvas is not None and self._background is not None
        canvas.blit(self._background, (0, 0))

        lean_sin = float(np.clip(_finite(state.shoulder_position_m) / _TORSO_LENGTH_M, -_MAX_LEAN_SIN, _MAX_LEAN_SIN))
        angle = math.asin(lean_sin)
        self._draw_success_marker(canvas, state)
        self._draw_person(canvas, angle)
        self._draw_push(canvas, angle, _finite(state.push_force_n))
        if state.verbal_cue != 0:
            self._draw_bubble(canvas, state.verbal_cue)
        if state.lift:
            self._draw_lift(canvas)
        self._draw_gauge(canvas, state)
        self._draw_face(canvas, state.true_xi)
        if state.probabilities is not None:
            self._draw_probabilities(canvas, state.probabilities)
        self._blit_text(canvas, f"t = {_finite(state.time_s):5.2f} s", 22, (10, 8))
        if state.outcome is None:
            self._draw_status(canvas, state)
        else:
            self._draw_banner(canvas, state.outcome)

        if self._frame is None:
            return canvas
        # Letterbox: scale the base canvas uniformly into the requested frame size.
        self._frame.fill(_BG)
        scaled = self._pg.transform.smoothscale(canvas, self._scaled_size)
        self._frame.blit(scaled, self._offset)
        return self._frame

    def _draw_success_marker(self, surf: pygame.Surface, state: RenderState) -> None:
        """Draw a marker on the lean arc at the lean needed for a safe lift, green once it is reached."""
        lean_sin = float(np.clip(_finite(state.success_lean_m) / _TORSO_LENGTH_M, -_MAX_LEAN_SIN, _MAX_LEAN_SIN))
        a = math.asin(lean_sin)
        reached = _finite(state.shoulder_position_m, -math.inf) >= _finite(state.success_lean_m)
        colour = _GREEN if reached else (150, 160, 175)
        ux, uy = math.sin(a), -math.cos(a)
        r_in, r_out = _ARC_RADIUS - 9, _ARC_RADIUS + 7
        base = (_HIP[0] + r_out * ux, _HIP[1] + r_out * uy)
        tip = (_HIP[0] + r_in * ux, _HIP[1] + r_in * uy)
        px, py = -uy * 7, ux * 7
        self._polygon(surf, [tip, (base[0] + px, base[1] + py), (base[0] - px, base[1] - py)], colour)
        label = (_HIP[0] + _ARC_RADIUS * ux + 12, _HIP[1] + _ARC_RADIUS * uy + 2)
        self._blit_text(surf, f"lean for lift {_finite(state.success_lean_m):.2f} m", 16, label, colour, "midleft")

    def _draw_person(self, surf: pygame.Surface, angle: float) -> None:
        """Draw the seated older adult facing right; the torso pivots at the hip by ``angle`` (forward +)."""
        ux, uy = math.sin(angle), -math.cos(angle)  # hip -> shoulder direction
        shoulder = (_HIP[0] + _TORSO_PX * ux, _HIP[1] + _TORSO_PX * uy)

        # Legs first (behind the arm), thigh on the seat and shin down to the floor.
        self._capsule(surf, _HIP, _KNEE, 30, _TROUSERS)
        self._capsule(surf, _KNEE, _ANKLE, 24, _TROUSERS)
        self._polygon(
            surf,
            [
                (_ANKLE[0] - 13, _ANKLE[1] - 4),
                (_ANKLE[0] + 26, _ANKLE[1] + 1),
                (_ANKLE[0] + 28, _FLOOR_Y - 1),
                (_ANKLE[0] - 13, _FLOOR_Y - 1),
            ],
            _SHOE,
        )

        # Torso and neck.
        self._capsule(surf, (_HIP[0] + 4 * ux, _HIP[1] + 4 * uy), shoulder, 40, _SHIRT)
        neck = (shoulder[0] + 16 * ux, shoulder[1] + 16 * uy)
        self._capsule(surf, shoulder, neck, 12, _SKIN_DARK)

        # Head: a circle with grey hair on the back and top, an eye and a nose facing forward.
        head = (shoulder[0] + 36 * ux, shoulder[1] + 36 * uy)
        self._circle(surf, head, 20, _SKIN)
        fx, fy = -uy, ux  # facing direction (forward, perpendicular to the torso)
        hair = [head]
        for k in range(13):  # from the back of the head over the crown
            a = math.atan2(uy, ux) - math.pi * 0.75 + k * (math.pi * 1.05 / 12)
            hair.append((head[0] + 21 * math.cos(a), head[1] + 21 * math.sin(a)))
        self._polygon(surf, hair, _HAIR)
        self._circle(surf, head, 13, _SKIN)
        eye = (head[0] + 9 * fx + 4 * ux, head[1] + 9 * fy + 4 * uy)
        self._circle(surf, eye, 2, _INK)
        nose_base = (head[0] + 17 * fx, head[1] + 17 * fy)
        self._polygon(
            surf,
            [
                (nose_base[0] + 3 * ux, nose_base[1] + 3 * uy),
                (nose_base[0] + 6 * fx - 3 * ux, nose_base[1] + 6 * fy - 3 * uy),
                (nose_base[0] - 6 * ux, nose_base[1] - 6 * uy),
            ],
            _SKIN,
        )

        # Arm: two-link reach from the shoulder to the hands resting near the knees,
        # elbow bent backwards as when pushing off the thighs.
        self._draw_arm(surf, shoulder)

    def _draw_arm(self, surf: pygame.Surface, shoulder: tuple[float, float]) -> None:
        """Draw upper arm and forearm by two-link inverse kinematics; the hand slides along the leg."""
        a, b = _UPPER_ARM_PX, _FOREARM_PX
        # The hand rests on the first point of the thigh-knee-shin path that the arm reaches
        # comfortably (85 % of full length): on the thigh when upright, down the shin when leaning far.
        comfortable = 0.85 * (a + b)
        hand = _HAND_PATH[-1]
        for point in _HAND_PATH:
            if math.hypot(point[0] - shoulder[0], point[1] - shoulder[1]) >= comfortable:
                hand = point
                break
        dx, dy = hand[0] - shoulder[0], hand[1] - shoulder[1]
        dist = math.hypot(dx, dy)
        if dist >= a + b:  # out of reach: straight arm towards the hand point
            elbow = (shoulder[0] + a * dx / dist, shoulder[1] + a * dy / dist)
            hand = (shoulder[0] + (a + b) * dx / dist, shoulder[1] + (a + b) * dy / dist)
        else:
            reach = max(dist, abs(a - b) + 1e-6)
            base = math.atan2(dy, dx)
            offset = math.acos(min(1.0, (a * a + reach * reach - b * b) / (2 * a * reach)))  # law of cosines
            # Of the two elbow solutions take the rear one: upper arm along the torso, forearm forward.
            candidates = [
                (shoulder[0] + a * math.cos(base + sign * offset), shoulder[1] + a * math.sin(base + sign * offset))
                for sign in (1.0, -1.0)
            ]
            elbow = min(candidates, key=lambda p: p[0])
        self._capsule(surf, shoulder, elbow, 15, _SHIRT_DARK)
        self._capsule(surf, elbow, hand, 12, _SHIRT_DARK)
        self._circle(surf, hand, 8, _SKIN)

    def _draw_push(self, surf: pygame.Surface, angle: float, force_n: float) -> None:
        """Draw a horizontal arrow onto the upper back, its length growing with force; nothing at 0 N."""
        if force_n <= 0.0:
            return
        ux, uy = math.sin(angle), -math.cos(angle)
        # Contact point: 80 % up the torso, on the back surface (torso half-width 20 px).
        contact = (
            _HIP[0] + 0.8 * _TORSO_PX * ux - 21 * math.cos(angle),
            _HIP[1] + 0.8 * _TORSO_PX * uy - 21 * math.sin(angle),
        )
        length = 18.0 + 100.0 * min(force_n, _MAX_ARROW_FORCE_N) / _MAX_ARROW_FORCE_N
        tail = (contact[0] - length, contact[1])
        shaft = 6.0 + 6.0 * min(force_n, _MAX_ARROW_FORCE_N) / _MAX_ARROW_FORCE_N
        self._arrow(surf, tail, contact, shaft, 16.0 + shaft, _PUSH)
        label_pos = (tail[0] + length / 2 - 6, contact[1] - 16)
        self._blit_text(surf, f"push {force_n:.0f} N", 18, label_pos, _PUSH, "midbottom")

    def _draw_bubble(self, surf: pygame.Surface, cue: int) -> None:
        """Draw the speech bubble from the robot with the verbal cue's words."""
        left, top, w, h = _REGIONS["bubble"]
        colour = _GREEN if cue > 0 else (224, 130, 20)
        # Tail towards the robot head on the left.
        self._polygon(surf, [(left + 2, top + 20), (left - 10, top + 34), (left + 16, top + 32)], colour)
        self._rounded_rect(surf, (left, top, w, h - 6), (255, 255, 255), 14)
        self._rounded_rect(surf, (left, top, w, h - 6), colour, 14, border=3)
        self._polygon(surf, [(left + 4, top + 22), (left - 5, top + 32), (left + 14, top + 30)], (255, 255, 255))
        self._blit_text(surf, _CUE_TEXT[cue], 28, (left + w / 2, top + (h - 6) / 2 + 1), colour, "center")

    def _draw_lift(self, surf: pygame.Surface) -> None:
        """Draw an upward arrow beside the knees on the frame where the robot lifts."""
        left, top, w, h = _REGIONS["lift"]
        x = left + w / 2
        self._arrow(surf, (x, top + h - 4), (x, top + 22), 14, 30, _LIFT)
        self._blit_text(surf, "LIFT", 24, (x, top + 2), _LIFT, "midtop")

    def _draw_gauge(self, surf: pygame.Surface, state: RenderState) -> None:
        """Draw the threshold band, the estimate marker with a ±1 std bar, and the judgment."""
        pg = self._pg
        threshold = abs(_finite(state.threshold))
        y_hi, y_lo = self._gauge_y(threshold), self._gauge_y(-threshold)
        # Tint the three judgment zones: cooperative above +threshold, uncooperative below -threshold.
        pg.draw.rect(surf, (214, 240, 219), (_GAUGE_X, _GAUGE_TOP, _GAUGE_W, round(y_hi - _GAUGE_TOP)))
        pg.draw.rect(surf, (226, 226, 226), (_GAUGE_X, round(y_hi), _GAUGE_W, max(1, round(y_lo - y_hi))))
        pg.draw.rect(surf, (246, 214, 214), (_GAUGE_X, round(y_lo), _GAUGE_W, round(_GAUGE_BOTTOM - y_lo)))
        for y in (y_hi, y_lo):
            pg.draw.line(surf, _MUTED, (_GAUGE_X - 3, round(y)), (_GAUGE_X + _GAUGE_W, round(y)), 1)
        if threshold < _XI_RANGE - 0.15:  # label the band edges unless they crowd the scale ends
            for value, y in ((threshold, y_hi), (-threshold, y_lo)):
                pg.draw.line(surf, _MUTED, (_GAUGE_X + _GAUGE_W, round(y)), (_GAUGE_X + _GAUGE_W + 3, round(y)), 1)
                self._blit_text(surf, f"{value:+.2f}", 14, (_GAUGE_X + _GAUGE_W + 6, y), _MUTED, "midleft")
        pg.draw.rect(surf, _MUTED, (_GAUGE_X, _GAUGE_TOP, _GAUGE_W, _GAUGE_BOTTOM - _GAUGE_TOP + 1), 1)

        estimate = float(state.xi_estimate)
        judgment_colour = _XI_COLOURS[state.judgment]
        if math.isfinite(estimate):
            std = max(_finite(state.xi_std), 0.0)
            y = self._gauge_y(estimate)
            # ±1 std as an error bar left of the gauge (clipped to the scale).
            y_top, y_bot = self._gauge_y(estimate + std), self._gauge_y(estimate - std)
            bar_x = _GAUGE_X - 12
            pg.draw.line(surf, _BLUE, (bar_x, round(y_top)), (bar_x, round(y_bot)), 3)
            pg.draw.line(surf, _BLUE, (bar_x - 4, round(y_top)), (bar_x + 4, round(y_top)), 2)
            pg.draw.line(surf, _BLUE, (bar_x - 4, round(y_bot)), (bar_x + 4, round(y_bot)), 2)
            pg.draw.line(surf, _INK, (_GAUGE_X - 2, round(y)), (_GAUGE_X + _GAUGE_W + 1, round(y)), 3)
            self._polygon(surf, [(_GAUGE_X - 3, y), (_GAUGE_X - 14, y - 7), (_GAUGE_X - 14, y + 7)], _BLUE)
            clipped = " (clipped)" if abs(estimate) > _XI_RANGE else ""
            text = f"\u03be estimate {estimate:+.2f} \u00b1 {std:.2f}{clipped}"
        else:
            text = "\u03be estimate n/a"
        self._blit_text(surf, text, 18, (_REGIONS["panel"][0] + 8, _GAUGE_BOTTOM + 14), _INK)

        left, top, w, h = _REGIONS["judgment"]
        self._rounded_rect(surf, (left, top, w, h), judgment_colour, 6)
        self._blit_text(
            surf, f"judged: {_XI_NAMES[state.judgment]}", 22, (left + w / 2, top + h / 2 + 1), (255, 255, 255), "center"
        )

    def _draw_face(self, surf: pygame.Surface, true_xi: int) -> None:
        """Draw the person's true cooperativeness: red frown, grey neutral face or green smile."""
        pg = self._pg
        cx, cy, r = 555, 84, 24
        colour = _XI_COLOURS[true_xi]
        self._circle(surf, (cx, cy), r, colour)
        self._circle(surf, (cx - 8, cy - 6), 3, (255, 255, 255))
        self._circle(surf, (cx + 8, cy - 6), 3, (255, 255, 255))
        if true_xi > 0:
            pg.draw.arc(surf, (255, 255, 255), (cx - 12, cy - 8, 24, 20), math.pi * 1.1, math.pi * 1.9, 3)
        elif true_xi < 0:
            pg.draw.arc(surf, (255, 255, 255), (cx - 12, cy + 5, 24, 18), math.pi * 0.1, math.pi * 0.9, 3)
        else:
            pg.draw.line(surf, (255, 255, 255), (cx - 9, cy + 9), (cx + 9, cy + 9), 3)
        self._blit_text(surf, _XI_NAMES[true_xi], 15, (cx, cy + r + 4), colour, "midtop")

    def _draw_probabilities(self, surf: pygame.Surface, probabilities: tuple[float, float, float]) -> None:
        """Draw three vertical bars for ``P(xi = -1), P(xi = 0), P(xi = +1)``."""
        pg = self._pg
        height = _PROB_BOTTOM - _PROB_TOP
        self._blit_text(surf, "P(\u03be = k)", 18, (_PROB_X + 43, _PROB_TOP - 16), _MUTED, "midbottom")
        for i, (p, xi, label) in enumerate(zip(probabilities, (-1, 0, 1), ("-1", "0", "+1"), strict=True)):
            p = min(max(_finite(p), 0.0), 1.0)
            x = _PROB_X + 4 + i * 26
            pg.draw.rect(surf, (255, 255, 255), (x, _PROB_TOP, 20, height))
            bar = round(p * height)
            if bar > 0:
                pg.draw.rect(surf, _XI_COLOURS[xi], (x, _PROB_BOTTOM - bar, 20, bar))
            pg.draw.rect(surf, _MUTED, (x, _PROB_TOP, 20, height), 1)
            self._blit_text(surf, label, 16, (x + 10, _PROB_BOTTOM + 3), _INK, "midtop")
            self._blit_text(surf, f"{p:.2f}", 13, (x + 10, _PROB_TOP - 2), _MUTED, "midbottom")

    def _draw_status(self, surf: pygame.Surface, state: RenderState) -> None:
        """Draw the status line under the floor while the episode runs."""
        left, top, _, h = _REGIONS["banner"]
        text = (
            f"shoulder x = {_finite(state.shoulder_position_m):+.3f} m    "
            f"push = {_finite(state.push_force_n):4.1f} N    cue: {_CUE_NAMES[state.verbal_cue]}"
        )
        self._blit_text(surf, text, 22, (left + 12, top + h / 2), (70, 62, 50), "midleft")

    def _draw_banner(self, surf: pygame.Surface, outcome: str) -> None:
        """Draw the outcome banner across the bottom strip at the end of an episode."""
        left, top, w, h = _REGIONS["banner"]
        text, colour = _BANNERS[outcome]
        self._pg.draw.rect(surf, colour, (left, top, w, h))
        self._blit_text(surf, text, 36, (left + w / 2, top + h / 2 + 1), (255, 255, 255), "center")
