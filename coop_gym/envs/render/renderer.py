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
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from coop_gym.envs.render.canvas import (
    ARC,
    ARC_RADIUS,
    BANNERS,
    BASE_H,
    BASE_W,
    BG,
    BLUE,
    CHAIR,
    CHAIR_DARK,
    CUE_NAMES,
    CUE_TEXT,
    FLOOR,
    FLOOR_Y,
    GAUGE_BOTTOM,
    GAUGE_TOP,
    GAUGE_W,
    GAUGE_X,
    GREEN,
    HIP,
    INK,
    KNEE,
    LIFT,
    MAX_ARROW_FORCE_N,
    MAX_LEAN_SIN,
    MUTED,
    PANEL_BG,
    PROB_BOTTOM,
    PROB_TOP,
    PROB_X,
    PUSH,
    REGIONS,
    TORSO_LENGTH_M,
    TORSO_PX,
    XI_COLOURS,
    XI_NAMES,
    XI_RANGE,
    arrow,
    capsule,
    circle,
    draw_person,
    finite,
    import_pygame,
    polygon,
    rounded_rect,
)
from coop_gym.envs.render.state import OUTCOMES, RenderState
from estimator.validate import is_integer

if TYPE_CHECKING:  # pragma: no cover - typing only
    import pygame

__all__ = ["OUTCOMES", "RenderState", "SitToStandRenderer"]


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
        self._scale = min(self.width / BASE_W, self.height / BASE_H)
        scaled_w, scaled_h = round(BASE_W * self._scale), round(BASE_H * self._scale)
        self._offset = ((self.width - scaled_w) // 2, (self.height - scaled_h) // 2)
        self._scaled_size = (scaled_w, scaled_h)
        self.regions: dict[str, tuple[int, int, int, int]] = {
            name: self._to_frame_rect(rect) for name, rect in REGIONS.items()
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
            self._pg = import_pygame()
        pg = self._pg
        if not pg.font.get_init():
            # Someone (e.g. another env's close() calling pygame.quit()) shut fonts down:
            # every cached Font and text surface is stale.
            pg.font.init()
            self._fonts = {}
            self._text_cache = {}
            self._background = None
        if self._background is None:
            self._canvas = pg.Surface((BASE_W, BASE_H))
            self._background = self._build_background()
            if (self.width, self.height) != (BASE_W, BASE_H):
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

    def _text(self, text: str, size: int, colour: tuple[int, int, int] = INK) -> Any:
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
        colour: tuple[int, int, int] = INK,
        anchor: str = "topleft",
    ) -> None:
        """Blit ``text`` with the named rect ``anchor`` (e.g. ``"center"``, ``"midleft"``) at ``pos``."""
        rendered = self._text(text, size, colour)
        rect = rendered.get_rect(**{anchor: (round(pos[0]), round(pos[1]))})
        surf.blit(rendered, rect)

    # ----------------------------------------------------------------------------------------
    # Static layer
    # ----------------------------------------------------------------------------------------
    def _build_background(self) -> pygame.Surface:
        """Draw everything that never changes: backdrop, floor, chair, robot, panel and gauge scale."""
        pg = self._pg
        bg = pg.Surface((BASE_W, BASE_H))
        bg.fill(BG)

        # Floor and the strip under it (status line / banner).
        pg.draw.rect(bg, FLOOR, (0, FLOOR_Y, BASE_W, BASE_H - FLOOR_Y))
        pg.draw.line(bg, (150, 140, 125), (0, FLOOR_Y), (BASE_W, FLOOR_Y), 2)

        # Estimator panel.
        panel = REGIONS["panel"]
        pg.draw.rect(bg, PANEL_BG, panel)
        pg.draw.line(bg, (205, 210, 218), (panel[0], 0), (panel[0], panel[3]), 2)

        self._draw_chair(bg)
        self._draw_robot(bg)
        self._draw_lean_arc_static(bg)
        self._draw_gauge_static(bg)

        self._blit_text(bg, "true \u03be", 20, (555, 44), MUTED, "midtop")
        return bg

    def _draw_chair(self, surf: pygame.Surface) -> None:
        """Draw the chair: seat, two visible legs, a low reclined backrest."""
        seat_top = HIP[1] + 14
        seat_left, seat_right = HIP[0] - 40, KNEE[0] - 10
        pg = self._pg
        # Back leg and a slightly reclined, low backrest: the upper back stays free for the push.
        capsule(self._pg, surf, (seat_left + 6, FLOOR_Y - 3), (seat_left + 6, seat_top), 8, CHAIR_DARK)
        capsule(self._pg, surf, (seat_left + 6, seat_top + 4), (seat_left - 8, HIP[1] - 82), 9, CHAIR_DARK)
        rounded_rect(self._pg, surf, (seat_left - 14, HIP[1] - 86, 18, 64), CHAIR, 6)
        capsule(self._pg, surf, (seat_right - 8, FLOOR_Y - 3), (seat_right - 8, seat_top), 8, CHAIR_DARK)
        # Seat with a cushion.
        rounded_rect(self._pg, surf, (seat_left - 2, seat_top, seat_right - seat_left + 4, 10), CHAIR, 4)
        pg.draw.line(surf, CHAIR_DARK, (seat_left + 2, seat_top + 10), (seat_right - 2, seat_top + 10), 2)

    def _draw_robot(self, surf: pygame.Surface) -> None:
        """Draw a small robot head at the top left: the speaker of the verbal cue."""
        x, y = 18, 34
        pg = self._pg
        pg.draw.line(surf, MUTED, (x + 17, y - 4), (x + 17, y + 4), 2)
        circle(self._pg, surf, (x + 17, y - 6), 3, PUSH)
        rounded_rect(self._pg, surf, (x, y + 4, 34, 28), (95, 105, 120), 7)
        rounded_rect(self._pg, surf, (x + 4, y + 9, 26, 14), (30, 35, 45), 4)
        circle(self._pg, surf, (x + 11, y + 16), 3, (90, 220, 240))
        circle(self._pg, surf, (x + 23, y + 16), 3, (90, 220, 240))
        self._blit_text(surf, "robot", 16, (x + 17, y + 35), MUTED, "midtop")

    def _draw_lean_arc_static(self, surf: pygame.Surface) -> None:
        """Draw the dotted arc, centred on the hip, along which the head travels as the torso leans."""
        pg = self._pg
        for deg in range(-14, 61, 3):
            a = math.radians(deg)
            p = (HIP[0] + ARC_RADIUS * math.sin(a), HIP[1] - ARC_RADIUS * math.cos(a))
            pg.draw.circle(surf, ARC, (round(p[0]), round(p[1])), 2)

    def _gauge_y(self, xi: float) -> float:
        """Vertical pixel of a cooperativeness value on the gauge (+1.5 at the top)."""
        xi = min(max(xi, -XI_RANGE), XI_RANGE)
        frac = (xi + XI_RANGE) / (2 * XI_RANGE)
        return GAUGE_BOTTOM - frac * (GAUGE_BOTTOM - GAUGE_TOP)

    def _draw_gauge_static(self, surf: pygame.Surface) -> None:
        """Draw the gauge title, scale, ticks and labels (the threshold band is dynamic)."""
        pg = self._pg
        self._blit_text(surf, "estimate of cooperativeness \u03be", 19, (REGIONS["panel"][0] + 8, 10), INK)
        pg.draw.rect(surf, (255, 255, 255), (GAUGE_X, GAUGE_TOP, GAUGE_W, GAUGE_BOTTOM - GAUGE_TOP))
        ticks = ((1.5, "+1.5"), (1.0, "+1 coop."), (0.0, "0 unresp."), (-1.0, "-1 uncoop."), (-1.5, "-1.5"))
        for value, label in ticks:
            y = round(self._gauge_y(value))
            pg.draw.line(surf, MUTED, (GAUGE_X + GAUGE_W, y), (GAUGE_X + GAUGE_W + 5, y), 1)
            colour = XI_COLOURS.get(int(value), MUTED) if value in (-1.0, 1.0) else MUTED
            self._blit_text(surf, label, 16, (GAUGE_X + GAUGE_W + 8, y), colour, "midleft")

    # ----------------------------------------------------------------------------------------
    # Dynamic layer
    # ----------------------------------------------------------------------------------------
    def _draw(self, state: RenderState) -> pygame.Surface:
        """Compose one frame and return the surface holding it at the requested size."""
        self._ensure_ready()
        canvas = self._canvas
        assert canvas is not None and self._background is not None
        canvas.blit(self._background, (0, 0))

        lean_sin = float(np.clip(finite(state.shoulder_position_m) / TORSO_LENGTH_M, -MAX_LEAN_SIN, MAX_LEAN_SIN))
        angle = math.asin(lean_sin)
        self._draw_success_marker(canvas, state)
        draw_person(self._pg, canvas, angle)
        self._draw_push(canvas, angle, finite(state.push_force_n))
        if state.verbal_cue != 0:
            self._draw_bubble(canvas, state.verbal_cue)
        if state.lift:
            self._draw_lift(canvas)
        self._draw_gauge(canvas, state)
        self._draw_face(canvas, state.true_xi)
        if state.probabilities is not None:
            self._draw_probabilities(canvas, state.probabilities)
        self._blit_text(canvas, f"t = {finite(state.time_s):5.2f} s", 22, (10, 8))
        if state.outcome is None:
            self._draw_status(canvas, state)
        else:
            self._draw_banner(canvas, state.outcome)

        if self._frame is None:
            return canvas
        # Letterbox: scale the base canvas uniformly into the requested frame size.
        self._frame.fill(BG)
        scaled = self._pg.transform.smoothscale(canvas, self._scaled_size)
        self._frame.blit(scaled, self._offset)
        return self._frame

    def _draw_success_marker(self, surf: pygame.Surface, state: RenderState) -> None:
        """Draw a marker on the lean arc at the lean needed for a safe lift, green once it is reached."""
        lean_sin = float(np.clip(finite(state.success_lean_m) / TORSO_LENGTH_M, -MAX_LEAN_SIN, MAX_LEAN_SIN))
        a = math.asin(lean_sin)
        reached = finite(state.shoulder_position_m, -math.inf) >= finite(state.success_lean_m)
        colour = GREEN if reached else (150, 160, 175)
        ux, uy = math.sin(a), -math.cos(a)
        r_in, r_out = ARC_RADIUS - 9, ARC_RADIUS + 7
        base = (HIP[0] + r_out * ux, HIP[1] + r_out * uy)
        tip = (HIP[0] + r_in * ux, HIP[1] + r_in * uy)
        px, py = -uy * 7, ux * 7
        polygon(self._pg, surf, [tip, (base[0] + px, base[1] + py), (base[0] - px, base[1] - py)], colour)
        label = (HIP[0] + ARC_RADIUS * ux + 12, HIP[1] + ARC_RADIUS * uy + 2)
        self._blit_text(surf, f"lean for lift {finite(state.success_lean_m):.2f} m", 16, label, colour, "midleft")

    def _draw_push(self, surf: pygame.Surface, angle: float, force_n: float) -> None:
        """Draw a horizontal arrow onto the upper back, its length growing with force; nothing at 0 N."""
        if force_n <= 0.0:
            return
        ux, uy = math.sin(angle), -math.cos(angle)
        # Contact point: 80 % up the torso, on the back surface (torso half-width 20 px).
        contact = (
            HIP[0] + 0.8 * TORSO_PX * ux - 21 * math.cos(angle),
            HIP[1] + 0.8 * TORSO_PX * uy - 21 * math.sin(angle),
        )
        length = 18.0 + 100.0 * min(force_n, MAX_ARROW_FORCE_N) / MAX_ARROW_FORCE_N
        tail = (contact[0] - length, contact[1])
        shaft = 6.0 + 6.0 * min(force_n, MAX_ARROW_FORCE_N) / MAX_ARROW_FORCE_N
        arrow(self._pg, surf, tail, contact, shaft, 16.0 + shaft, PUSH)
        label_pos = (tail[0] + length / 2 - 6, contact[1] - 16)
        self._blit_text(surf, f"push {force_n:.0f} N", 18, label_pos, PUSH, "midbottom")

    def _draw_bubble(self, surf: pygame.Surface, cue: int) -> None:
        """Draw the speech bubble from the robot with the verbal cue's words."""
        left, top, w, h = REGIONS["bubble"]
        colour = GREEN if cue > 0 else (224, 130, 20)
        # Tail towards the robot head on the left.
        polygon(self._pg, surf, [(left + 2, top + 20), (left - 10, top + 34), (left + 16, top + 32)], colour)
        rounded_rect(self._pg, surf, (left, top, w, h - 6), (255, 255, 255), 14)
        rounded_rect(self._pg, surf, (left, top, w, h - 6), colour, 14, border=3)
        polygon(self._pg, surf, [(left + 4, top + 22), (left - 5, top + 32), (left + 14, top + 30)], (255, 255, 255))
        self._blit_text(surf, CUE_TEXT[cue], 28, (left + w / 2, top + (h - 6) / 2 + 1), colour, "center")

    def _draw_lift(self, surf: pygame.Surface) -> None:
        """Draw an upward arrow beside the knees on the frame where the robot lifts."""
        left, top, w, h = REGIONS["lift"]
        x = left + w / 2
        arrow(self._pg, surf, (x, top + h - 4), (x, top + 22), 14, 30, LIFT)
        self._blit_text(surf, "LIFT", 24, (x, top + 2), LIFT, "midtop")

    def _draw_gauge(self, surf: pygame.Surface, state: RenderState) -> None:
        """Draw the threshold band, the estimate marker with a ±1 std bar, and the judgment."""
        pg = self._pg
        threshold = abs(finite(state.threshold))
        y_hi, y_lo = self._gauge_y(threshold), self._gauge_y(-threshold)
        # Tint the three judgment zones: cooperative above +threshold, uncooperative below -threshold.
        pg.draw.rect(surf, (214, 240, 219), (GAUGE_X, GAUGE_TOP, GAUGE_W, round(y_hi - GAUGE_TOP)))
        pg.draw.rect(surf, (226, 226, 226), (GAUGE_X, round(y_hi), GAUGE_W, max(1, round(y_lo - y_hi))))
        pg.draw.rect(surf, (246, 214, 214), (GAUGE_X, round(y_lo), GAUGE_W, round(GAUGE_BOTTOM - y_lo)))
        for y in (y_hi, y_lo):
            pg.draw.line(surf, MUTED, (GAUGE_X - 3, round(y)), (GAUGE_X + GAUGE_W, round(y)), 1)
        if threshold < XI_RANGE - 0.15:  # label the band edges unless they crowd the scale ends
            for value, y in ((threshold, y_hi), (-threshold, y_lo)):
                pg.draw.line(surf, MUTED, (GAUGE_X + GAUGE_W, round(y)), (GAUGE_X + GAUGE_W + 3, round(y)), 1)
                self._blit_text(surf, f"{value:+.2f}", 14, (GAUGE_X + GAUGE_W + 6, y), MUTED, "midleft")
        pg.draw.rect(surf, MUTED, (GAUGE_X, GAUGE_TOP, GAUGE_W, GAUGE_BOTTOM - GAUGE_TOP + 1), 1)

        estimate = float(state.xi_estimate)
        judgment_colour = XI_COLOURS[state.judgment]
        if math.isfinite(estimate):
            std = max(finite(state.xi_std), 0.0)
            y = self._gauge_y(estimate)
            # ±1 std as an error bar left of the gauge (clipped to the scale).
            y_top, y_bot = self._gauge_y(estimate + std), self._gauge_y(estimate - std)
            bar_x = GAUGE_X - 12
            pg.draw.line(surf, BLUE, (bar_x, round(y_top)), (bar_x, round(y_bot)), 3)
            pg.draw.line(surf, BLUE, (bar_x - 4, round(y_top)), (bar_x + 4, round(y_top)), 2)
            pg.draw.line(surf, BLUE, (bar_x - 4, round(y_bot)), (bar_x + 4, round(y_bot)), 2)
            pg.draw.line(surf, INK, (GAUGE_X - 2, round(y)), (GAUGE_X + GAUGE_W + 1, round(y)), 3)
            polygon(self._pg, surf, [(GAUGE_X - 3, y), (GAUGE_X - 14, y - 7), (GAUGE_X - 14, y + 7)], BLUE)
            clipped = " (clipped)" if abs(estimate) > XI_RANGE else ""
            text = f"\u03be estimate {estimate:+.2f} \u00b1 {std:.2f}{clipped}"
        else:
            text = "\u03be estimate n/a"
        self._blit_text(surf, text, 18, (REGIONS["panel"][0] + 8, GAUGE_BOTTOM + 14), INK)

        left, top, w, h = REGIONS["judgment"]
        rounded_rect(self._pg, surf, (left, top, w, h), judgment_colour, 6)
        self._blit_text(
            surf, f"judged: {XI_NAMES[state.judgment]}", 22, (left + w / 2, top + h / 2 + 1), (255, 255, 255), "center"
        )

    def _draw_face(self, surf: pygame.Surface, true_xi: int) -> None:
        """Draw the person's true cooperativeness: red frown, grey neutral face or green smile."""
        pg = self._pg
        cx, cy, r = 555, 84, 24
        colour = XI_COLOURS[true_xi]
        circle(self._pg, surf, (cx, cy), r, colour)
        circle(self._pg, surf, (cx - 8, cy - 6), 3, (255, 255, 255))
        circle(self._pg, surf, (cx + 8, cy - 6), 3, (255, 255, 255))
        if true_xi > 0:
            pg.draw.arc(surf, (255, 255, 255), (cx - 12, cy - 8, 24, 20), math.pi * 1.1, math.pi * 1.9, 3)
        elif true_xi < 0:
            pg.draw.arc(surf, (255, 255, 255), (cx - 12, cy + 5, 24, 18), math.pi * 0.1, math.pi * 0.9, 3)
        else:
            pg.draw.line(surf, (255, 255, 255), (cx - 9, cy + 9), (cx + 9, cy + 9), 3)
        self._blit_text(surf, XI_NAMES[true_xi], 15, (cx, cy + r + 4), colour, "midtop")

    def _draw_probabilities(self, surf: pygame.Surface, probabilities: tuple[float, float, float]) -> None:
        """Draw three vertical bars for ``P(xi = -1), P(xi = 0), P(xi = +1)``."""
        pg = self._pg
        height = PROB_BOTTOM - PROB_TOP
        self._blit_text(surf, "P(\u03be = k)", 18, (PROB_X + 43, PROB_TOP - 16), MUTED, "midbottom")
        for i, (p, xi, label) in enumerate(zip(probabilities, (-1, 0, 1), ("-1", "0", "+1"), strict=True)):
            p = min(max(finite(p), 0.0), 1.0)
            x = PROB_X + 4 + i * 26
            pg.draw.rect(surf, (255, 255, 255), (x, PROB_TOP, 20, height))
            bar = round(p * height)
            if bar > 0:
                pg.draw.rect(surf, XI_COLOURS[xi], (x, PROB_BOTTOM - bar, 20, bar))
            pg.draw.rect(surf, MUTED, (x, PROB_TOP, 20, height), 1)
            self._blit_text(surf, label, 16, (x + 10, PROB_BOTTOM + 3), INK, "midtop")
            self._blit_text(surf, f"{p:.2f}", 13, (x + 10, PROB_TOP - 2), MUTED, "midbottom")

    def _draw_status(self, surf: pygame.Surface, state: RenderState) -> None:
        """Draw the status line under the floor while the episode runs."""
        left, top, _, h = REGIONS["banner"]
        text = (
            f"shoulder x = {finite(state.shoulder_position_m):+.3f} m    "
            f"push = {finite(state.push_force_n):4.1f} N    cue: {CUE_NAMES[state.verbal_cue]}"
        )
        self._blit_text(surf, text, 22, (left + 12, top + h / 2), (70, 62, 50), "midleft")

    def _draw_banner(self, surf: pygame.Surface, outcome: str) -> None:
        """Draw the outcome banner across the bottom strip at the end of an episode."""
        left, top, w, h = REGIONS["banner"]
        text, colour = BANNERS[outcome]
        self._pg.draw.rect(surf, colour, (left, top, w, h))
        self._blit_text(surf, text, 36, (left + w / 2, top + h / 2 + 1), (255, 255, 255), "center")
