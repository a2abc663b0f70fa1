"""What one rendered frame shows: the env's state as the renderer needs it, checked."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

from coop_gym.envs.config import Outcome

__all__ = ["OUTCOMES", "RenderState"]

OUTCOMES: Final[tuple[str, ...]] = tuple(o.label for o in Outcome if o is not Outcome.NONE)
"""Episode outcomes the renderer can show as a banner."""


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
