"""The renderer's canvas: the fixed 600x400 layout, the palette, the labels and pygame's drawing primitives.

Everything is drawn at the base size and letterboxed into other sizes by
:class:`~coop_gym.envs.render.renderer.SitToStandRenderer`; pygame is imported lazily
(:func:`import_pygame`), so the package imports without it.
"""

from __future__ import annotations

import math
import os
from typing import TYPE_CHECKING, Any, Final

from gymnasium.error import DependencyNotInstalled

if TYPE_CHECKING:  # pragma: no cover - typing only
    import pygame

__all__ = [
    "ANKLE",
    "ARC",
    "ARC_RADIUS",
    "BANNERS",
    "BASE_H",
    "BASE_W",
    "BG",
    "BLUE",
    "CHAIR",
    "CHAIR_DARK",
    "CUE_NAMES",
    "CUE_TEXT",
    "FLOOR",
    "FLOOR_Y",
    "FOREARM_PX",
    "GAUGE_BOTTOM",
    "GAUGE_TOP",
    "GAUGE_W",
    "GAUGE_X",
    "GREEN",
    "GREY",
    "HAIR",
    "HAND_PATH",
    "HIP",
    "INK",
    "KNEE",
    "LIFT",
    "MAX_ARROW_FORCE_N",
    "MAX_LEAN_SIN",
    "MUTED",
    "PANEL_BG",
    "PIXELS_PER_M",
    "PROB_BOTTOM",
    "PROB_TOP",
    "PROB_X",
    "PUSH",
    "RED",
    "REGIONS",
    "SHIRT",
    "SHIRT_DARK",
    "SHOE",
    "SKIN",
    "SKIN_DARK",
    "TORSO_LENGTH_M",
    "TORSO_PX",
    "TROUSERS",
    "UPPER_ARM_PX",
    "XI_COLOURS",
    "XI_NAMES",
    "XI_RANGE",
    "arrow",
    "capsule",
    "circle",
    "draw_arm",
    "draw_person",
    "finite",
    "import_pygame",
    "polygon",
    "rounded_rect",
]

# ---------------------------------------------------------------------------------------------
# Geometry of the base canvas (pixels). Everything is drawn at this size and scaled if needed.
# ---------------------------------------------------------------------------------------------
BASE_W: Final = 600
BASE_H: Final = 400
PIXELS_PER_M: Final = 250.0
TORSO_LENGTH_M: Final = 0.5  # hip to shoulder; the lean angle is asin(x / this)
MAX_LEAN_SIN: Final = 0.95  # keeps asin defined and the drawing sane for any x
XI_RANGE: Final = 1.5  # the gauge spans [-1.5, 1.5]
MAX_ARROW_FORCE_N: Final = 60.0

FLOOR_Y: Final = 350
HIP: Final = (165.0, 262.0)
TORSO_PX: Final = TORSO_LENGTH_M * PIXELS_PER_M
KNEE: Final = (HIP[0] + 105.0, HIP[1])
ANKLE: Final = (KNEE[0] + 4.0, FLOOR_Y - 10.0)
ARC_RADIUS: Final = TORSO_PX + 60  # lean arc drawn just beyond the top of the head
# Where a hand may rest: along the top of the thigh, then down the front of the shin.
HAND_PATH: Final = tuple(
    [(HIP[0] + 30.0 + 2.0 * i, HIP[1] - 17.0) for i in range(int((KNEE[0] + 14.0 - HIP[0] - 30.0) / 2))]
    + [(KNEE[0] + 14.0 + 0.05 * j, HIP[1] - 17.0 + float(j)) for j in range(0, 70, 2)]
)
UPPER_ARM_PX: Final = 78.0
FOREARM_PX: Final = 74.0

GAUGE_X: Final = 414  # left edge of the gauge bar
GAUGE_W: Final = 22
GAUGE_TOP: Final = 50
GAUGE_BOTTOM: Final = 284

PROB_X: Final = 515
PROB_TOP: Final = 180
PROB_BOTTOM: Final = 270

# Colours (RGB).
BG = (248, 248, 245)
PANEL_BG = (236, 239, 243)
INK = (40, 44, 52)
MUTED = (120, 126, 136)
FLOOR = (196, 186, 170)
CHAIR = (139, 94, 60)
CHAIR_DARK = (105, 70, 45)
SKIN = (238, 196, 160)
SKIN_DARK = (200, 150, 115)
HAIR = (205, 205, 210)
SHIRT = (70, 110, 170)
SHIRT_DARK = (50, 82, 130)
TROUSERS = (82, 84, 96)
SHOE = (45, 45, 50)
PUSH = (214, 96, 20)
LIFT = (128, 60, 170)
GREEN = (46, 160, 67)
RED = (207, 52, 52)
GREY = (140, 140, 140)
BLUE = (40, 90, 200)
ARC = (185, 190, 200)

XI_COLOURS: Final = {-1: RED, 0: GREY, 1: GREEN}
XI_NAMES: Final = {-1: "uncooperative", 0: "unresponsive", 1: "cooperative"}
CUE_TEXT: Final = {-1: "Please lean back.", 1: "Please lean forward."}
CUE_NAMES: Final = {-1: "lean back", 0: "none", 1: "lean forward"}
BANNERS: Final = {
    "success": ("SUCCESS \u2013 safe lift", GREEN),
    "unsafe": ("UNSAFE LIFT", RED),
    "premature": ("PREMATURE LIFT", (224, 130, 20)),
    "timeout": ("TIMEOUT \u2013 no lift", (110, 116, 128)),
}

# Screen regions in base-canvas pixels, (left, top, width, height). Kept in one place so the
# drawing code and the tests (via ``SitToStandRenderer.regions``) agree.
REGIONS: Final[dict[str, tuple[int, int, int, int]]] = {
    "scene": (0, 0, 380, FLOOR_Y + 2),
    "torso": (110, 60, 230, 215),
    "arrow": (20, 130, 240, 70),
    "bubble": (62, 26, 238, 52),
    "lift": (300, 180, 75, 110),
    "time": (8, 4, 140, 22),
    "panel": (380, 0, 220, FLOOR_Y + 2),
    "gauge": (386, 40, 120, 276),
    "judgment": (386, 320, 208, 26),
    "face": (515, 40, 80, 90),
    "probabilities": (508, 150, 88, 140),
    "banner": (0, FLOOR_Y + 4, BASE_W, BASE_H - FLOOR_Y - 4),
}


def finite(value: float, default: float = 0.0) -> float:
    """Return ``value`` as a float, or ``default`` if it is NaN or infinite."""
    value = float(value)
    return value if math.isfinite(value) else default


def import_pygame() -> Any:
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


def polygon(pg: Any, surf: pygame.Surface, points: list[tuple[float, float]], colour: tuple[int, int, int]) -> None:
    """Draw a filled anti-aliased polygon."""
    gfx = pg.gfxdraw
    gfx.aapolygon(surf, points, colour)
    gfx.filled_polygon(surf, points, colour)


def circle(
    pg: Any, surf: pygame.Surface, centre: tuple[float, float], radius: float, colour: tuple[int, int, int]
) -> None:
    """Draw a filled anti-aliased circle."""
    gfx = pg.gfxdraw
    x, y, r = round(centre[0]), round(centre[1]), max(1, round(radius))
    gfx.aacircle(surf, x, y, r, colour)
    gfx.filled_circle(surf, x, y, r, colour)


def capsule(
    pg: Any,
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
    polygon(
        pg,
        surf,
        [
            (start[0] + nx, start[1] + ny),
            (end[0] + nx, end[1] + ny),
            (end[0] - nx, end[1] - ny),
            (start[0] - nx, start[1] - ny),
        ],
        colour,
    )
    circle(pg, surf, start, width / 2, colour)
    circle(pg, surf, end, width / 2, colour)


def arrow(
    pg: Any,
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
    polygon(
        pg,
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


def rounded_rect(
    pg: Any,
    surf: pygame.Surface,
    rect: tuple[float, float, float, float],
    colour: tuple[int, int, int],
    radius: int,
    border: int = 0,
) -> None:
    """Draw a rounded rectangle, filled (``border=0``) or outlined."""
    pg.draw.rect(surf, colour, pg.Rect(rect), border, border_radius=radius)


def draw_person(pg: Any, surf: pygame.Surface, angle: float) -> None:
    """Draw the seated older adult facing right; the torso pivots at the hip by ``angle`` (forward +)."""
    ux, uy = math.sin(angle), -math.cos(angle)  # hip -> shoulder direction
    shoulder = (HIP[0] + TORSO_PX * ux, HIP[1] + TORSO_PX * uy)

    # Legs first (behind the arm), thigh on the seat and shin down to the floor.
    capsule(pg, surf, HIP, KNEE, 30, TROUSERS)
    capsule(pg, surf, KNEE, ANKLE, 24, TROUSERS)
    polygon(
        pg,
        surf,
        [
            (ANKLE[0] - 13, ANKLE[1] - 4),
            (ANKLE[0] + 26, ANKLE[1] + 1),
            (ANKLE[0] + 28, FLOOR_Y - 1),
            (ANKLE[0] - 13, FLOOR_Y - 1),
        ],
        SHOE,
    )

    # Torso and neck.
    capsule(pg, surf, (HIP[0] + 4 * ux, HIP[1] + 4 * uy), shoulder, 40, SHIRT)
    neck = (shoulder[0] + 16 * ux, shoulder[1] + 16 * uy)
    capsule(pg, surf, shoulder, neck, 12, SKIN_DARK)

    # Head: a circle with grey hair on the back and top, an eye and a nose facing forward.
    head = (shoulder[0] + 36 * ux, shoulder[1] + 36 * uy)
    circle(pg, surf, head, 20, SKIN)
    fx, fy = -uy, ux  # facing direction (forward, perpendicular to the torso)
    hair = [head]
    for k in range(13):  # from the back of the head over the crown
        a = math.atan2(uy, ux) - math.pi * 0.75 + k * (math.pi * 1.05 / 12)
        hair.append((head[0] + 21 * math.cos(a), head[1] + 21 * math.sin(a)))
    polygon(pg, surf, hair, HAIR)
    circle(pg, surf, head, 13, SKIN)
    eye = (head[0] + 9 * fx + 4 * ux, head[1] + 9 * fy + 4 * uy)
    circle(pg, surf, eye, 2, INK)
    nose_base = (head[0] + 17 * fx, head[1] + 17 * fy)
    polygon(
        pg,
        surf,
        [
            (nose_base[0] + 3 * ux, nose_base[1] + 3 * uy),
            (nose_base[0] + 6 * fx - 3 * ux, nose_base[1] + 6 * fy - 3 * uy),
            (nose_base[0] - 6 * ux, nose_base[1] - 6 * uy),
        ],
        SKIN,
    )

    # Arm: two-link reach from the shoulder to the hands resting near the knees,
    # elbow bent backwards as when pushing off the thighs.
    draw_arm(pg, surf, shoulder)


def draw_arm(pg: Any, surf: pygame.Surface, shoulder: tuple[float, float]) -> None:
    """Draw upper arm and forearm by two-link inverse kinematics; the hand slides along the leg."""
    a, b = UPPER_ARM_PX, FOREARM_PX
    # The hand rests on the first point of the thigh-knee-shin path that the arm reaches
    # comfortably (85 % of full length): on the thigh when upright, down the shin when leaning far.
    comfortable = 0.85 * (a + b)
    hand = HAND_PATH[-1]
    for point in HAND_PATH:
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
    capsule(pg, surf, shoulder, elbow, 15, SHIRT_DARK)
    capsule(pg, surf, elbow, hand, 12, SHIRT_DARK)
    circle(pg, surf, hand, 8, SKIN)
