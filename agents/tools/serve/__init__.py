"""People in the loop, in a browser: ``python -m agents.tools.serve`` (extra ``[web]``).

A local web app with two roles -- play the caregiver on the evaluation's own episodes, or be
the person of the paper's experiment -- every finished trial stored in a database
(:mod:`agents.tools.serve.store`), exported as the played-episodes CSV ``agents.evaluate
--human`` scores and as recordings ``python -m estimator.estimate`` reads. See ``docs/web.md``.
"""

from agents.tools.serve.cli import main

__all__ = ["main"]
