"""Scripted caregivers: one base class, the baselines, the belief caregiver and their commands.

:class:`~agents.caregivers.scripted_base.ScriptedAgent` is the base; the registry is
:data:`agents.caregivers.scripted.SCRIPTED_AGENTS`; ``tune_baselines`` / ``tune_belief`` tune them and
``reading`` scores the estimators under their cues.

A new caregiver is a module here, subclassing ``ScriptedAgent``, registered in ``SCRIPTED_AGENTS``.
No torch or Stable-Baselines3 is loaded from here.
"""

__all__: list[str] = []
