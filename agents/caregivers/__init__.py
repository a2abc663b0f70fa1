"""Scripted caregivers: one base class, the baselines, the belief caregiver.

:class:`~agents.caregivers.scripted_base.ScriptedAgent` is the base; the registry is
:data:`agents.caregivers.scripted.SCRIPTED_AGENTS`; ``reading`` scores the estimators under their
cues. The searches that chose their settings are commands of :mod:`agents.tune`.

A new caregiver is a module here, subclassing ``ScriptedAgent``, registered in ``SCRIPTED_AGENTS``.
No torch or Stable-Baselines3 is loaded from here.
"""

__all__: list[str] = []
