"""Tools around an episode: play it, record it, plot it.

Play it yourself (:mod:`agents.tools.play`), record it as a video and a timeline
(:mod:`agents.tools.record`), and draw the figures of an evaluation or a run
(:mod:`agents.tools.plots`).
"""

__all__: list[str] = []
