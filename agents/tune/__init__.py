"""The offline searches behind the scripted caregivers' settings, each a command of its own.

- ``python -m agents.tune.baselines {blind,prober} --level LEVEL`` (:mod:`agents.tune.baselines`): the
  blind family and the prober, searched on the training personas; the winners are kept in
  :data:`agents.caregivers.scripted.TUNED_BLIND` and :data:`agents.caregivers.scripted.TUNED_PROBER`.
- ``python -m agents.tune.belief --env ID`` (:mod:`agents.tune.belief`): the belief caregiver's grid; the
  winners are kept in :data:`agents.caregivers.belief.TUNED_BELIEF`.

Above the caregivers and the evaluation they tune with: nothing below imports this package.
"""

__all__: list[str] = []
