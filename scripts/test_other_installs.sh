#!/usr/bin/env bash
# The installs the default test venv (.venv, "[train,test]", the newest gymnasium) does not
# cover, each in its own venv beside it. Part of the README's test command, so CI runs it:
#   .venv-rllib   "[train,rllib,test]" in one pip command (ray 2.60 pins gymnasium 1.2.2):
#                 the RLlib tests, the end-to-end run (local Ray, 2 env runners) included, then a
#                 two-node cluster started inside the test (ray start --head, ray start --address,
#                 one CPU each) that train.py --framework rllib --address trains on, one env runner a node;
#   .venv-gymlow  gymnasium at the declared lower bound (1.1.1): both env checkers over every id;
#   .venv-wheel   `pip install .` (not editable), checked from another folder: imports, 10 steps,
#                 and no top-level name but coop_gym, agents, estimator (scripts/check_installed.py).
set -euo pipefail
cd "$(dirname "$0")/.."
python3 -m venv .venv-rllib
.venv-rllib/bin/pip install "torch==2.13.0" -e ".[train,rllib,test]"
.venv-rllib/bin/python -c "import ray.rllib"  # the tests skip without it: fail here instead
.venv-rllib/bin/python -m pytest -m "slow or not slow" tests/agents/test_rllib.py
.venv-rllib/bin/python -m pytest -m "slow or not slow" tests/agents/test_rllib_cluster.py
python3 -m venv .venv-gymlow
.venv-gymlow/bin/pip install "torch==2.13.0" "gymnasium==1.1.1" -e ".[train,test]"
.venv-gymlow/bin/python -c "import gymnasium; assert gymnasium.__version__ == '1.1.1', gymnasium.__version__"
.venv-gymlow/bin/python -m pytest tests/coop_gym/test_gymnasium_range.py
python3 -m venv .venv-wheel
.venv-wheel/bin/pip install .  # not editable: what a user of the wheel gets
(cd "$(mktemp -d)" && "$OLDPWD/.venv-wheel/bin/python" "$OLDPWD/scripts/check_installed.py")
