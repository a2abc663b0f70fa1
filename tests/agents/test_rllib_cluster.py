"""A real two-node Ray cluster on one machine: ``train.py --framework rllib --address`` runs on it.

The test starts a head node and a second node with ``ray start`` (each ``--num-cpus=1``,
each its own temp dir), runs ``train.py --framework rllib --address 127.0.0.1:<port>
--num-env-runners 2`` to its end, checks in the cluster's actor table (kept by the GCS
after the job ends) that the env runners ran one on each node, scores the checkpoint with
``python -m agents.evaluate --model``, and stops both nodes in a ``finally``.

Skipped without the ``[rllib]`` extra, so the README's test command runs it in the
``[rllib]`` venv of ``scripts/test_other_installs.sh``; marked ``slow`` (node start-up,
actor start-up and the node drain take minutes).

Addresses: every command is given ``127.0.0.1``. Ray itself replaces a loopback address
by the machine's own outward IP (``ray._private.services.resolve_ip_for_localhost``, by
design, ray-project/ray#59110), so the nodes register under that IP; both are on this
machine. Ray's single-machine mode (``RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0``) would keep
``127.0.0.1`` but refuses a second node. The nodes are stopped by their process groups,
not ``ray stop --force``, which would kill every Ray process of the user on the machine
(other jobs' clusters too).

Authentication: the cluster uses Ray's token auth with a token of its own, given to every
process it starts through ``RAY_AUTH_MODE=token`` and ``RAY_AUTH_TOKEN``. Left unset, a
``~/.ray/auth_token`` written by any earlier Ray use turns token auth on for ``ray start``
but not for the drivers, which are then refused (``InvalidAuthToken``).
"""

from __future__ import annotations

import json
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

pytest.importorskip("ray.rllib")


ROOT = Path(__file__).resolve().parents[2]
ENV_ID = "CoopGym/SitToStandHard-v1"
RUNNER_CLASS = "SingleAgentEnvRunner"


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def _ray_start(args: list[str], log: Path, env: dict[str, str]) -> subprocess.Popen[bytes]:
    """``ray start ... --block`` in a session of its own, so the node's processes share one group to stop."""
    ray_cli = str(Path(sys.executable).with_name("ray"))
    common = ["--num-cpus=1", "--object-store-memory=100000000", "--disable-usage-stats", "--block"]
    with log.open("wb") as out:
        return subprocess.Popen(
            [ray_cli, "start", *args, *common], stdout=out, stderr=subprocess.STDOUT, env=env, start_new_session=True
        )


def _stop(node: subprocess.Popen[bytes], timeout_s: float = 90.0) -> None:
    """SIGTERM the node's process group (``ray start --block`` drains, stops its processes), SIGKILL what is left."""
    try:
        os.killpg(node.pid, signal.SIGTERM)
    except ProcessLookupError:
        return
    try:
        node.wait(timeout_s)
    except subprocess.TimeoutExpired:
        pass
    try:
        os.killpg(node.pid, signal.SIGKILL)  # workers the node spawned into its group, if any survived
    except ProcessLookupError:
        pass
    node.wait(30)


_STATE_SCRIPT = """
import json, sys
import ray
from ray._private.state import actors

ray.init(address=sys.argv[1], log_to_driver=False, logging_level="ERROR")
nodes = [{"id": n["NodeID"], "ip": n["NodeManagerAddress"]} for n in ray.nodes() if n["Alive"]]
runners = [a["Address"]["NodeID"] for a in actors().values() if a["ActorClassName"] == sys.argv[2]]
print(json.dumps({"nodes": nodes, "runners": runners}))
"""


def _cluster_state(address: str, env: dict[str, str]) -> dict:
    """Alive nodes and the node of every env runner ever started, from the GCS (a driver of its own).

    The actor table outlives the job, so the runners of a finished ``train.py`` are still
    listed (DEAD, with the node they ran on). Ray's public state API (``ray list actors``)
    needs the dashboard, which ``ray[rllib]`` does not install.
    """
    proc = subprocess.run(
        [sys.executable, "-c", _STATE_SCRIPT, address, RUNNER_CLASS],
        capture_output=True,
        text=True,
        timeout=300,
        env=env,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.mark.slow
def test_train_py_on_a_two_node_cluster():
    started = time.perf_counter()
    port = _free_port()
    address = f"127.0.0.1:{port}"
    # Short paths: Ray's unix sockets live under the temp dir (108-byte limit on socket paths).
    root = Path(tempfile.mkdtemp(prefix="rc", dir="/tmp"))
    env = os.environ | {"RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN": secrets.token_hex(32)}
    nodes: list[subprocess.Popen[bytes]] = []
    try:
        head_args = ["--head", f"--port={port}", "--include-dashboard=false", f"--temp-dir={root / 'h'}"]
        nodes.append(_ray_start(head_args, root / "head.log", env))
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline and "Ray runtime started" not in (root / "head.log").read_text():
            assert nodes[0].poll() is None, (root / "head.log").read_text()[-3000:]
            time.sleep(1)
        nodes.append(_ray_start([f"--address={address}", f"--temp-dir={root / 'w'}"], root / "node.log", env))
        alive: list[dict] = []
        while time.monotonic() < deadline and len(alive) < 2:
            assert nodes[1].poll() is None, (root / "node.log").read_text()[-3000:]
            time.sleep(2)
            alive = _cluster_state(address, env)["nodes"]
        assert len(alive) == 2, (root / "node.log").read_text()[-3000:]
        assert len({n["ip"] for n in alive}) == 1  # two nodes, one machine
        up_s = time.perf_counter() - started

        out = root / "runs"
        argv = [sys.executable, str(ROOT / "train.py"), "--framework", "rllib", "--address", address]
        argv += ["--env", ENV_ID, "--num-env-runners", "2", "--n-envs", "8", "--timesteps", "4096"]
        argv += ["--eval-episodes", "20", "--eval-points", "0", "--baselines", "", "--out", str(out)]
        proc = subprocess.run(argv, capture_output=True, text=True, timeout=1800, cwd=ROOT, env=env)
        assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-4000:]
        (run_dir,) = out.iterdir()
        assert (run_dir / "COMPLETE").exists()
        results = json.loads((run_dir / "results.json").read_text())
        assert results["training"]["address"] == address and results["training"]["num_env_runners"] == 2
        train_s = time.perf_counter() - started - up_s

        # The env runners' nodes, from the cluster's actor table: one runner on each node.
        runner_nodes = _cluster_state(address, env)["runners"]
        assert sorted(runner_nodes) == sorted(n["id"] for n in alive), (runner_nodes, alive)

        # The checkpoint scored by the one evaluation path, as a user would.
        score = subprocess.run(
            [sys.executable, "-m", "agents.evaluate", "--model", str(run_dir), "--episodes", "50", "--json"],
            capture_output=True,
            text=True,
            timeout=900,
            cwd=ROOT,
            env=env,
        )
        assert score.returncode == 0, score.stderr[-3000:]
        summary = json.loads(score.stdout)
        assert summary["episodes"] == 50 and summary["env_id"] == ENV_ID
        assert sum(summary[f"{o}_count"] for o in ("success", "unsafe", "premature", "timeout")) == 50
        print(f"\ncluster up {up_s:.0f} s, train.py {train_s:.0f} s, total {time.perf_counter() - started:.0f} s")
    finally:
        for node in reversed(nodes):  # the second node first: its drain needs the head's GCS
            _stop(node)
        shutil.rmtree(root, ignore_errors=True)
