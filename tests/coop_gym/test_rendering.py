"""Tests for coop_gym.envs.render.renderer: frame format, and that each element shows up where documented."""

from __future__ import annotations

import dataclasses
import os

os.environ.setdefault("SDL_VIDEODRIVER", "dummy")  # no screen on CI; also used by the human-mode test
os.environ.setdefault("SDL_AUDIODRIVER", "dummy")

import numpy as np
import pytest

pytest.importorskip("pygame")

from coop_gym.envs.render.renderer import OUTCOMES, RenderState, SitToStandRenderer

BASE = RenderState(
    time_s=1.0,
    shoulder_position_m=0.0,
    push_force_n=0.0,
    verbal_cue=0,
    xi_estimate=0.0,
    xi_std=0.1,
    threshold=0.3,
    judgment=0,
    true_xi=0,
)


@pytest.fixture
def renderer():
    r = SitToStandRenderer()
    yield r
    r.close()


def crop(frame: np.ndarray, renderer: SitToStandRenderer, name: str) -> np.ndarray:
    left, top, width, height = renderer.regions[name]
    return frame[top : top + height, left : left + width].astype(np.int16)


def changed_pixels(a: np.ndarray, b: np.ndarray) -> int:
    """Number of pixels whose colour differs noticeably (any channel by more than 30)."""
    return int((np.abs(a - b).max(axis=-1) > 30).sum())


def render_pair(renderer: SitToStandRenderer, region: str, **changes) -> tuple[np.ndarray, np.ndarray]:
    before = crop(renderer.render_rgb(BASE), renderer, region)
    after = crop(renderer.render_rgb(dataclasses.replace(BASE, **changes)), renderer, region)
    return before, after


@pytest.mark.parametrize("size", [(600, 400), (320, 240), (640, 480)])
def test_frame_shape_and_dtype(size):
    r = SitToStandRenderer(*size)
    frame = r.render_rgb(BASE)
    r.close()
    assert frame.shape == (size[1], size[0], 3)
    assert frame.dtype == np.uint8
    assert frame.flags["C_CONTIGUOUS"]
    assert frame.std() > 10  # a picture, not a blank canvas


def test_regions_lie_inside_the_frame():
    for size in [(600, 400), (320, 240), (640, 480)]:
        r = SitToStandRenderer(*size)
        for name, (left, top, width, height) in r.regions.items():
            assert left >= 0 and top >= 0 and width > 0 and height > 0, name
            assert left + width <= size[0] and top + height <= size[1], name


def test_torso_region_changes_with_lean(renderer):
    before, after = render_pair(renderer, "torso", shoulder_position_m=0.25)
    assert changed_pixels(before, after) > 500
    # Leaning only moves the person; the estimator panel stays put.
    panel_before, panel_after = render_pair(renderer, "panel", shoulder_position_m=0.25)
    assert changed_pixels(panel_before, panel_after) == 0


def test_lean_direction_moves_the_head_forward(renderer):
    """Forward lean (x > 0) moves the figure to the right (the person faces +x)."""

    def centroid_x(frame: np.ndarray) -> float:
        left, top, width, height = renderer.regions["torso"]
        region = frame[top : top + height, left : left + width].astype(np.int16)
        # Hair and skin are light and warm; the shirt is blue: locate the shirt pixels.
        shirt = (region[..., 2] > region[..., 0] + 60) & (region[..., 2] > 120)
        return float(np.nonzero(shirt)[1].mean())

    upright = centroid_x(renderer.render_rgb(BASE))
    forward = centroid_x(renderer.render_rgb(dataclasses.replace(BASE, shoulder_position_m=0.3)))
    backward = centroid_x(renderer.render_rgb(dataclasses.replace(BASE, shoulder_position_m=-0.1)))
    assert backward < upright < forward


def test_push_arrow_only_when_pushing(renderer):
    before, after = render_pair(renderer, "arrow", push_force_n=10.0)
    assert changed_pixels(before, after) > 200
    # A larger force draws a larger arrow.
    _, firm = render_pair(renderer, "arrow", push_force_n=30.0)
    assert changed_pixels(before, firm) > changed_pixels(before, after)


def test_no_arrow_at_zero_force(renderer):
    before, after = render_pair(renderer, "arrow", push_force_n=0.0)
    assert changed_pixels(before, after) == 0


@pytest.mark.parametrize("cue", [-1, 1])
def test_speech_bubble_when_verbal_cue_plays(renderer, cue):
    before, after = render_pair(renderer, "bubble", verbal_cue=cue)
    assert changed_pixels(before, after) > 500


def test_lean_back_and_forward_bubbles_differ(renderer):
    back = crop(renderer.render_rgb(dataclasses.replace(BASE, verbal_cue=-1)), renderer, "bubble")
    forward = crop(renderer.render_rgb(dataclasses.replace(BASE, verbal_cue=1)), renderer, "bubble")
    assert changed_pixels(back, forward) > 100


def test_gauge_marker_follows_estimate(renderer):
    before, after = render_pair(renderer, "gauge", xi_estimate=0.9)
    assert changed_pixels(before, after) > 50


def test_estimate_beyond_gauge_is_clipped_not_lost(renderer):
    at_edge = crop(renderer.render_rgb(dataclasses.replace(BASE, xi_estimate=1.5, xi_std=0.0)), renderer, "gauge")
    beyond = crop(renderer.render_rgb(dataclasses.replace(BASE, xi_estimate=7.0, xi_std=0.0)), renderer, "gauge")
    middle = crop(renderer.render_rgb(dataclasses.replace(BASE, xi_estimate=0.0, xi_std=0.0)), renderer, "gauge")
    # Same marker position; only the printed value under the gauge may differ.
    height = renderer.regions["gauge"][3]
    marker_rows = slice(0, height - 30)
    assert changed_pixels(at_edge[marker_rows], beyond[marker_rows]) == 0
    assert changed_pixels(at_edge[marker_rows], middle[marker_rows]) > 50  # and the marker does move


def test_non_finite_values_do_not_crash(renderer):
    state = dataclasses.replace(
        BASE, xi_estimate=float("nan"), xi_std=float("inf"), shoulder_position_m=float("nan"), time_s=float("nan")
    )
    frame = renderer.render_rgb(state)
    assert frame.shape == (400, 600, 3)


def test_judgment_changes_its_box(renderer):
    before, after = render_pair(renderer, "judgment", judgment=1)
    assert changed_pixels(before, after) > 500


def test_true_xi_face_colour(renderer):
    def mean_colour(xi: int) -> np.ndarray:
        return crop(renderer.render_rgb(dataclasses.replace(BASE, true_xi=xi)), renderer, "face").reshape(-1, 3).mean(0)

    red, grey, green = mean_colour(-1), mean_colour(0), mean_colour(1)
    assert red[0] > red[1] + 10  # red dominates
    assert green[1] > green[0] + 10  # green dominates
    assert abs(grey[0] - grey[1]) < 10


def test_probability_bars_only_when_given(renderer):
    before, after = render_pair(renderer, "probabilities", probabilities=(0.1, 0.2, 0.7))
    assert changed_pixels(before, after) > 300
    _, other = render_pair(renderer, "probabilities", probabilities=(0.7, 0.2, 0.1))
    assert changed_pixels(after, other) > 100


def test_lift_arrow(renderer):
    before, after = render_pair(renderer, "lift", lift=True)
    assert changed_pixels(before, after) > 300


@pytest.mark.parametrize("outcome", OUTCOMES)
def test_outcome_banner(renderer, outcome):
    before, after = render_pair(renderer, "banner", outcome=outcome)
    assert changed_pixels(before, after) > 2000


def test_time_text_changes(renderer):
    before, after = render_pair(renderer, "time", time_s=12.5)
    assert changed_pixels(before, after) > 20


def test_frames_are_fresh_arrays(renderer):
    first = renderer.render_rgb(BASE)
    second = renderer.render_rgb(BASE)
    assert first is not second
    assert not np.shares_memory(first, second)
    assert np.array_equal(first, second)  # deterministic drawing
    snapshot = first.copy()
    renderer.render_rgb(dataclasses.replace(BASE, shoulder_position_m=0.3, outcome="success"))
    assert np.array_equal(first, snapshot)  # later frames don't write into earlier ones
    first[:] = 0  # writable, and writing doesn't affect the renderer
    assert np.array_equal(renderer.render_rgb(BASE), second)


def test_close_is_idempotent_and_safe_before_rendering():
    never_used = SitToStandRenderer()
    never_used.close()
    never_used.close()

    r = SitToStandRenderer()
    r.render_rgb(BASE)
    r.close()
    r.close()
    # Still usable after close: resources are re-created on demand.
    assert r.render_rgb(BASE).shape == (400, 600, 3)
    r.close()


def test_two_renderers_coexist():
    a, b = SitToStandRenderer(), SitToStandRenderer(300, 200)
    fa = a.render_rgb(BASE)
    a.close()  # closing one must not break the other (fonts stay initialised)
    fb = b.render_rgb(BASE)
    b.close()
    assert fa.shape == (400, 600, 3) and fb.shape == (200, 300, 3)


def test_human_mode_with_dummy_display():
    """The window shows the same picture as ``render_rgb``, and a new state redraws it."""
    import pygame

    r = SitToStandRenderer()
    leaning = dataclasses.replace(BASE, shoulder_position_m=0.2, push_force_n=10.0)
    shown = []
    for state, fps in ((BASE, 1000), (leaning, 0)):
        r.render_human(state, fps=fps)
        window = pygame.display.get_surface()
        assert window is not None and window.get_size() == (600, 400)
        shown.append(pygame.surfarray.array3d(window).transpose(1, 0, 2))
        np.testing.assert_array_equal(shown[-1], r.render_rgb(state))
    assert shown[0].std() > 10  # a picture, not a blank window
    assert changed_pixels(shown[0].astype(np.int16), shown[1].astype(np.int16)) > 500
    r.close()
    r.close()
    assert not pygame.display.get_init()  # closing twice leaves the display shut, without error


def test_render_state_rejects_bad_discrete_fields():
    with pytest.raises(ValueError, match="verbal_cue"):
        dataclasses.replace(BASE, verbal_cue=2)
    with pytest.raises(ValueError, match="judgment"):
        dataclasses.replace(BASE, judgment=-2)
    with pytest.raises(ValueError, match="true_xi"):
        dataclasses.replace(BASE, true_xi=5)
    with pytest.raises(ValueError, match="outcome"):
        dataclasses.replace(BASE, outcome="won")
    with pytest.raises(ValueError, match="probabilities"):
        dataclasses.replace(BASE, probabilities=(0.5, 0.5))


@pytest.mark.parametrize(("width", "height"), [(0, 400), (600, -1), (600.5, 400), (True, 400)])
def test_renderer_rejects_bad_sizes(width, height):
    with pytest.raises(ValueError):
        SitToStandRenderer(width, height)
