"""The compiled boundary: what every Numba kernel of the project relies on (the lowest layer).

- :mod:`estimator.compiled.cache`: Numba's on-disk cache keyed by every project source a kernel
  compiles in (:func:`~estimator.compiled.cache.guard_kernel_cache`).
- :mod:`estimator.compiled.background`: a kernel missing from that cache runs as Python while a
  background process compiles it (a fresh install's first step without waiting for the compile).
- :mod:`estimator.compiled.rng`: NumPy's random streams inside kernels, number for number the
  ``Generator``'s.

Every kernel is ``@njit(cache=True, error_model="numpy")``: NumPy's error model leaves out the
ZeroDivisionError check (and its message formatting) that Python's model compiles into every
division (seconds of every cold compile) and changes no result of a division by a
non-zero number; where a divisor can be zero the kernels test it first
(``tests/test_style.py`` holds every kernel to it). The one kernel without ``cache=True`` is
the particle filter's, whose first-class function argument Numba cannot find in a disk
cache (``estimator/particle.py``).

Imports nothing else of the project: it sits in :mod:`estimator`, the lowest package, so the
filters import it without loading the envs, and the model and the envs (``coop_gym``, above)
import it too. The validators every layer shares (plain Python, nothing compiled) sit beside it
on the lowest layer, in :mod:`estimator.validate`.
"""

from estimator.compiled.cache import guard_kernel_cache

__all__ = ["guard_kernel_cache"]
