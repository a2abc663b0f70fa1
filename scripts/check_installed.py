"""Check a non-editable install of coop_gym from outside the checkout (scripts/test_other_installs.sh).

Run from a folder that is not the checkout, with the venv's Python: the installed packages
(not the sources beside them) must import, make an env and step it, and the wheel must install
no top-level name but ``coop_gym``, ``agents`` and ``estimator`` (a generic name such as
``compiled`` or ``train`` would shadow, or be shadowed by, a user's own module).
"""

from __future__ import annotations

import sys
from importlib import metadata
from pathlib import Path

EXPECTED_TOP_LEVEL = {"coop_gym", "agents", "estimator"}


def installed_top_level() -> set[str]:
    """Top-level importable names the ``coop_gym`` distribution put into site-packages."""
    names = set()
    for file in metadata.distribution("coop_gym").files or []:
        first = file.parts[0]
        if first.endswith((".dist-info", ".egg-info")) or first == ".." or first.startswith("__"):
            continue
        names.add(first.removesuffix(".py"))
    return names


def main() -> None:
    """Exit non-zero, naming what is wrong, unless the install from site-packages works."""
    checkout = Path(__file__).resolve().parents[1]
    if Path.cwd().resolve() == checkout:
        sys.exit("run from outside the checkout, so the installed packages are the ones imported")
    import gymnasium as gym

    import agents
    import coop_gym
    import estimator

    for module in (coop_gym, agents, estimator):
        if Path(module.__file__ or "").resolve().parent == checkout / module.__name__:  # the venv may sit inside
            sys.exit(f"{module.__name__} was imported from the checkout ({module.__file__}), not the install")
    top = installed_top_level()
    if top != EXPECTED_TOP_LEVEL:
        sys.exit(f"installed top-level names {sorted(top)}, expected {sorted(EXPECTED_TOP_LEVEL)}")
    env = gym.make("CoopGym/SitToStandHard-v2")
    env.reset(seed=0)
    env.action_space.seed(0)
    for _ in range(10):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            env.reset()
    print(f"installed: {sorted(top)} from {Path(coop_gym.__file__).parent.parent}; 10 steps ok")


if __name__ == "__main__":
    main()
