"""The compiled boundary: what every Numba kernel of the project relies on (the lowest layer).

- :mod:`compiled.cache`: Numba's on-disk cache keyed by every project source a kernel
  compiles in (:func:`~compiled.cache.guard_kernel_cache`).
- :mod:`compiled.checks`: what counts as a number (NumPy scalars yes, bools and arrays no) for
  every validator of the project.
- :mod:`compiled.rng`: NumPy's random streams inside kernels, number for number the
  ``Generator``'s.

Imports nothing of ``coop_gym``, ``estimator`` or ``agents``; both the model/env side and
the filters may import it.
"""

from compiled.cache import guard_kernel_cache

__all__ = ["guard_kernel_cache"]
