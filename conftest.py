"""Collection rules for the whole repository (doctests run over the packages), and NumPy's SIMD level."""

import importlib.util
import os
import platform

# NumPy chooses its SIMD kernels by CPU at import, and its AVX-512 exp differs from its AVX2 exp
# in the last bit. Each episode's person is drawn through np.exp (coop_gym/envs/kernels/reset.py,
# coop_gym.model.personas.sample_person), so the recorded trajectories
# (tests/coop_gym/test_recorded_trajectories.py, made at the AVX2 level X86_V3) replay bit for bit
# only at that level: every test runs NumPy there, on any x86 CPU. NumPy is not imported yet here.
if platform.machine().lower() in ("x86_64", "amd64"):
    os.environ.setdefault("NPY_DISABLE_CPU_FEATURES", "X86_V4 AVX512_ICL AVX512_SPR")

# agents/rl/rllib.py (and the run around it) import ray at module level; without the [rllib] extra
# their doctests are skipped.
collect_ignore = [] if importlib.util.find_spec("ray") else ["agents/rl/rllib.py", "agents/trainer/rllib_run.py"]
