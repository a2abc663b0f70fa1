"""Bad command-line flags: exit status 2 and a message naming the problem on stderr.

Covers the command lines that exist: ``python train.py`` and the package's ``python -m`` commands
(:data:`PACKAGE_CLIS`: typed arguments parsed by :func:`coop_gym.cli.parse`), and the ``bench/``
scripts (``run.py``, ``cold_start.py``, ``render.py``, ``cleanrl_defaults.py``, ``time_to_quality.py``).
A command line that no longer imports, or has lost its ``main(argv)``, fails. Cases call
``main(argv)`` in-process (a usage error exits through ``SystemExit``) under an alarm, so a bad flag
that is wrongly accepted fails the test in seconds instead of starting a training run; one real
subprocess per command line checks the exit status and stderr end to end.
"""

from __future__ import annotations

import contextlib
import errno
import importlib
import importlib.util
import io
import os
import re
import signal
import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[1]
ALARM_S = 120  # a cold numba compile on a loaded machine takes tens of s; an accepted bad flag runs for minutes


def _load(name: str) -> Any:
    """The module of a command line: a script path under the checkout, or a module name."""
    if name.endswith(".py"):
        path = ROOT / name
        assert path.exists(), f"{name} is listed as a command line but does not exist"
        name = f"_cli_{path.stem}"
        if name in sys.modules:
            return sys.modules[name]
        spec = importlib.util.spec_from_file_location(name, path)
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module  # dataclasses look their module up while the file runs
        spec.loader.exec_module(module)
        return module
    return importlib.import_module(name)


@contextlib.contextmanager
def alarm(seconds: int) -> Iterator[None]:
    def fail(*_: Any) -> None:
        raise TimeoutError(f"still running after {seconds} s: the bad flag was accepted")

    previous = signal.signal(signal.SIGALRM, fail)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def run_main(main: Callable[[list[str]], Any], argv: list[str]) -> tuple[Any, str]:
    """``(exit status, stderr)`` of ``main(argv)``; the status is main's return value or SystemExit's code."""
    err = io.StringIO()
    with alarm(ALARM_S), contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            code = main(argv)
        except SystemExit as exc:
            code = exc.code
    return code, err.getvalue()


def assert_exit_2_naming(code: Any, err: str, match: str) -> None:
    """Exit status 2, and ``match`` found in stderr."""
    assert code == 2, f"exit status {code!r}, stderr: {err}"
    assert re.search(match, err), f"stderr does not name the problem: {err!r}"


def _params(cases: list[tuple[str, str, list[str], str]]) -> list[Any]:
    """``(cli, argv, match)`` of each case, its id ``"cli: case"``."""
    return [pytest.param(cli, argv, match, id=f"{cli}: {case}") for cli, case, argv, match in cases]


# (command line, case id, argv, regex the stderr must match)
CASES: list[tuple[str, str, list[str], str]] = [
    ("train.py", "unknown flag", ["--bogus"], r"Unrecognized options: --bogus"),
    ("train.py", "unknown algo", ["--algo", "a2c"], r"invalid choice 'a2c' for argument '--algo'"),
    ("train.py", "unknown env", ["--env", "Nope-v0"], r"--env: unknown env id 'Nope-v0'"),
    ("train.py", "timesteps 0", ["--timesteps", "0"], r"--timesteps must be >= 1, got 0"),
    ("train.py", "timesteps not a number", ["--timesteps", "many"], r"--timesteps:(?s:.*)int.*'many'"),
    ("train.py", "n-envs 0", ["--n-envs", "0"], r"--n-envs must be >= 1, got 0"),
    ("train.py", "negative seed", ["--seed", "-1"], r"--seed and --eval-seed must be >= 0"),
    ("train.py", "eval-episodes 0", ["--eval-episodes", "0"], r"--eval-episodes must be >= 1"),
    ("train.py", "unknown eval persona", ["--eval-personas", "nobody"], r"--eval-personas: unknown persona 'nobody'"),
    ("train.py", "unknown baseline", ["--baselines", "random,nobody"], r"--baselines: unknown agent\(s\) \['nobody'\]"),
    ("train.py", "eval-only without model", ["--eval-only"], r"--eval-only needs --model"),
    ("train.py", "model without eval-only", ["--model", "x.zip"], r"--model is for --eval-only"),
    ("train.py", "resume nothing", ["--resume", "/nonexistent/run"], r"--resume: nothing saved at /nonexistent/run"),
    ("train.py", "threads 0", ["--threads", "0"], r"--threads >= 1"),
    ("train.py", "eval-points < 0", ["--eval-points", "-1"], r"--eval-points must be >= 0"),
    ("agents.evaluate", "no agent", [], r"give --agent NAME, --model PATH, --compare NAME,NAME,\.\.\. or --human CSV"),
    ("agents.evaluate", "unknown flag", ["--agent", "random", "--bogus"], r"Unrecognized options: --bogus"),
    ("agents.evaluate", "unknown agent", ["--agent", "nobody"], r"'nobody' is neither a scripted agent"),
    ("agents.evaluate", "missing model", ["--model", "/nonexistent/model.zip"], r"neither a scripted agent .* model"),
    ("agents.evaluate", "episodes 0", ["--agent", "random", "--episodes", "0"], r"--episodes must be >= 1, got 0"),
    ("agents.evaluate", "episodes not a number", ["--agent", "random", "--episodes", "x"], r"--episodes: .*int.*'x'"),
    ("agents.evaluate", "n-envs 0", ["--agent", "random", "--n-envs", "0"], r"--n-envs must be >= 1, got 0"),
    ("agents.evaluate", "threads 0", ["--agent", "random", "--threads", "0"], r"--threads must be >= 1, got 0"),
    ("agents.evaluate", "negative seed", ["--agent", "random", "--seed", "-3"], r"--seed must be >= 0, got -3"),
    ("agents.evaluate", "unknown persona", ["--agent", "random", "--personas", "nobody"], r"--personas: unknown"),
    ("agents.evaluate", "unknown env", ["--agent", "random", "--env", "Nope-v0"], r"--env: unknown env id 'Nope-v0'"),
    (
        "agents.evaluate",
        "unknown backend",
        ["--agent", "random", "--backend", "gpu"],
        r"invalid choice 'gpu' for argument '--backend'",
    ),
    ("coop_gym.experiment.protocol", "unknown flag", ["--bogus"], r"Unrecognized options: --bogus"),
    (
        "coop_gym.experiment.protocol",
        "subjects 0",
        ["--subjects", "0"],
        r"--subjects: expected a positive integer, got 0",
    ),
    (
        "coop_gym.experiment.protocol",
        "trials not a number",
        ["--trials", "x"],
        r"--trials: expected a positive integer, got 'x'",
    ),
    (
        "coop_gym.experiment.protocol",
        "negative seed",
        ["--seed", "-1"],
        r"--seed: expected a non-negative integer seed",
    ),
    ("coop_gym.experiment.protocol", "seeds 0", ["--seeds", "0"], r"--seeds: expected a positive integer, got 0"),
    (
        "coop_gym.experiment.protocol",
        "unknown estimator",
        ["--estimator", "particle"],
        r"invalid choice 'particle' for argument '--estimator'",
    ),
    (
        "coop_gym.experiment.protocol",
        "unknown decision",
        ["--decision", "vote"],
        r"invalid choice 'vote' for argument '--decision'",
    ),
    ("coop_gym.experiment.protocol", "unknown persona", ["--personas", "nobody"], r"nobody"),
    ("coop_gym.experiment.protocol", "plot not png", ["--plot", "trace.txt"], r"plot paths must end in \.png"),
    # Issue #13's table: a non-coop_gym env id, seeds outside [0, 2**32), plot types, checkpoints.
    (
        "train.py",
        "env not a coop_gym id",
        ["--env", "CartPole-v1"],
        r"--env: unknown env id 'CartPole-v1' \(not a coop_gym",
    ),
    ("train.py", "seed 2**64", ["--seed", str(2**64)], r"--seed 18446744073709551616: seeds .* must be below 2\*\*32"),
    ("train.py", "seed 2**63-1", ["--seed", str(2**63 - 1)], r"--seed 9223372036854775807: .* below 2\*\*32"),
    ("train.py", "eval-seed 2**64", ["--eval-seed", str(2**64)], r"--eval-seed 18446744073709551616: .* below 2\*\*32"),
    ("train.py", "checkpoint-every < 0", ["--checkpoint-every", "-5"], r"--checkpoint-every must be >= 0, got -5"),
    ("train.py", "eval-only with resume", ["--eval-only", "--resume", "x"], r"--eval-only and --resume exclude"),
    (
        "agents.evaluate",
        "env not a coop_gym id",
        ["--agent", "random", "--env", "CartPole-v1"],
        r"--env: unknown env id 'CartPole-v1' \(not a coop_gym env\)",
    ),
    (
        "agents.evaluate",
        "seed 2**64",
        ["--agent", "random", "--seed", str(2**64)],
        r"--seed 18446744073709551616: seeds",
    ),
    ("agents.evaluate", "seed 2**63-1", ["--agent", "random", "--seed", str(2**63 - 1)], r"must be below 2\*\*32"),
    (
        "agents.evaluate",
        "seed + episodes past 2**32",
        ["--agent", "random", "--seed", str(2**32 - 5), "--episodes", "10"],
        r"seeds 4294967291..4294967300 must be below 2\*\*32 \(here at most 4294967286\)",
    ),
    (
        "agents.evaluate",
        "plot x.txt",
        ["--agent", "random", "--plot", "x.txt"],
        r"--plot: unsupported file type '.txt'",
    ),
    (
        "agents.tools.record",
        "env not a coop_gym id",
        ["--agent", "handbook", "--env", "CartPole-v1", "--out", "videos"],
        r"unknown env id 'CartPole-v1' \(not a coop_gym env\)",
    ),
    (
        "agents.tools.record",
        "seed 2**64",
        ["--agent", "handbook", "--seed", str(2**64), "--out", "v"],
        r"--seed: seeds must be below 2\*\*32",
    ),
    (
        "agents.tools.record",
        "seed 2**63-1",
        ["--agent", "handbook", "--seed", str(2**63 - 1), "--out", "v"],
        r"below 2\*\*32",
    ),
    ("coop_gym.experiment.protocol", "seed 2**64", ["--seed", str(2**64)], r"--seed: seeds must be below 2\*\*32"),
    # Issue #13: numbers that are not integers where counts and seeds are expected.
    (
        "coop_gym.experiment.protocol",
        "subjects 2.5",
        ["--subjects", "2.5"],
        r"--subjects: expected a positive integer, got '2\.5'",
    ),
    (
        "coop_gym.experiment.protocol",
        "trials 1e3",
        ["--trials", "1e3"],
        r"--trials: expected a positive integer, got '1e3'",
    ),
    (
        "coop_gym.experiment.protocol",
        "seed nan",
        ["--seed", "nan"],
        r"--seed: expected a non-negative integer seed, got 'nan'",
    ),
    (
        "coop_gym.experiment.protocol",
        "seeds True",
        ["--seeds", "True"],
        r"--seeds: expected a positive integer, got 'True'",
    ),
    ("coop_gym.experiment.protocol", "seed 2**32", ["--seed", str(2**32)], r"--seed: seeds must be below 2\*\*32"),
    ("bench/run.py", "repeats inf", ["--repeats", "inf"], r"--repeats: expected a positive integer, got 'inf'"),
    ("bench/run.py", "unknown flag", ["--bogus"], r"unrecognized arguments: --bogus"),
    ("bench/run.py", "repeats 0", ["--repeats", "0"], r"--repeats: expected a positive integer, got 0"),
    ("bench/cold_start.py", "repeats 0", ["--repeats", "0"], r"--repeats: must be a positive integer, got 0"),
    ("bench/render.py", "repeats 0", ["--repeats", "0"], r"--repeats: expected a positive integer, got 0"),
    ("bench/cold_start.py", "unknown env", ["--env", "CartPole-v1"], r"--env: unknown env id 'CartPole-v1'"),
    ("bench/cold_start.py", "negative env count", ["--num-envs", "-1"], r"--num-envs: must be >= 0, got \[-1\]"),
    ("bench/cleanrl_defaults.py", "missing script", ["--script", "/nonexistent/ppo.py"], r"--script: no such file"),
    ("bench/cleanrl_defaults.py", "timesteps 0", ["--script", __file__, "--total-timesteps", "0"], r"positive"),
    ("bench/time_to_quality.py", "budget 0", ["--budget-s", "0"], r"--budget-s: must be a positive number, got '0'"),
    ("bench/time_to_quality.py", "steps 0", ["--budget-steps", "0"], r"--budget-steps: expected a positive integer"),
    ("bench/time_to_quality.py", "budget nan", ["--budget-s", "nan"], r"--budget-s: must be a positive number"),
    ("bench/time_to_quality.py", "episodes 0", ["--episodes", "0"], r"--episodes: expected a positive integer, got 0"),
    ("bench/time_to_quality.py", "unknown contender", ["--contenders", "x"], r"--contenders: unknown contender 'x'"),
    ("bench/time_to_quality.py", "contender size 5", ["--contenders", "default@5"], r"N must divide the 4096-step"),
    ("bench/time_to_quality.py", "contender 0 epochs", ["--contenders", "jax@64-e0"], r"unknown contender 'jax@64-e0'"),
    ("bench/time_to_quality.py", "unknown env", ["--env", "CartPole-v1"], r"--env: unknown env id 'CartPole-v1'"),
    ("bench/learners.py", "unknown row", ["--rows", "ppo-x"], r"--rows: unknown row\(s\) \['ppo-x'\]"),
    ("bench/learners.py", "seed twice", ["--seeds", "1,1"], r"--seeds: seeds must be distinct and >= 0"),
    ("bench/learners.py", "seed not a number", ["--seeds", "a"], r"--seeds: seeds are whole numbers"),
    ("bench/learners.py", "timesteps 0", ["--timesteps", "0"], r"--timesteps: expected a positive integer, got 0"),
    ("bench/learners.py", "cleanrl row at 8 envs", ["--rows", "cleanrl-ppo@8"], r"--rows: unknown row\(s\)"),
    ("bench/learners.py", "0 epochs", ["--rows", "jax-kalman@16-e0"], r"--rows: unknown row\(s\) \['jax-kalman@16-e0"),
    ("bench/learners.py", "epochs without envs", ["--rows", "jax-kalman@-e4"], r"--rows: unknown row\(s\)"),
    (
        "bench/learners.py",
        "cleanrl row without the script",
        ["--rows", "cleanrl-ppo", "--seeds", "4294967295"],
        r"--cleanrl-script: the cleanrl-\* rows need CleanRL's ppo.py, got None",
    ),
    ("coop_gym.experiment.calibrate", "unknown estimator", ["--estimators", "nope"], r"--estimators must name some"),
    ("coop_gym.experiment.calibrate", "seeds 0", ["--seeds", "0"], r"--seeds: expected a positive integer, got 0"),
    ("coop_gym.experiment.calibrate", "unknown flag", ["--bogus"], r"Unrecognized options: --bogus"),
    ("agents.tools.play", "unknown env", ["--env", "Nope-v0"], r"--env: unknown env id 'Nope-v0'"),
    ("agents.tools.play", "fps 0", ["--fps", "0"], r"--fps must be >= 1"),
    ("agents.tools.serve", "port out of range", ["--port", "70000"], r"--port must be in 0..65535"),
    ("agents.tools.serve", "unknown persona", ["--personas", "nobody"], r"--personas: .*nobody"),
    ("agents.tools.serve", "unknown database", ["--database", "nope://x"], r"--database nope://x: cannot open it"),
    ("agents.tools.serve", "not a database URL", ["--database", "not a url"], r"--database not a url: cannot open it"),
    ("agents.tools.play", "unknown pace", ["--pace", "slow"], r"invalid choice 'slow' for argument '--pace'"),
    ("agents.caregivers.reading", "episodes 0", ["--episodes", "0"], r"--episodes must be positive, got 0"),
    ("agents.tune.baselines", "no family", [], r"\{blind,prober\}"),
    ("agents.tune.baselines", "unknown family", ["nope"], r"invalid choice 'nope' for argument 'family'"),
    (
        "agents.tune.baselines",
        "unknown level",
        ["blind", "--level", "x"],
        r"invalid choice 'x' for argument '--level'",
    ),
    ("agents.tune.belief", "episodes 0", ["--episodes", "0"], r"--episodes must be positive, got 0"),
    ("agents.tune.belief", "held-out -1", ["--held-out", "-1"], r"--held-out must be 0 or more, got -1"),
    ("agents.tune.belief", "lift-p 2", ["--lift-p", "2"], r"--lift-p: .*lift_p must be in \[0\.0, 1\.0\]"),
    ("agents.tune.belief", "lift-p empty", ["--lift-p"], r"--lift-p: expected at least one argument"),
    (
        "bench/run.py",
        "repeats not a number",
        ["--repeats", "few"],
        r"--repeats: expected a positive integer, got 'few'",
    ),
]

# Bad output paths: found only when the results are written, unless checked up front. The
# argv keeps the work tiny, so a late failure shows as a traceback, not a long run.
# {blocked} is a folder that cannot exist: its parent is a regular file.
LATE_CASES: list[tuple[str, str, list[str], str]] = [
    ("coop_gym.experiment.protocol", "export in a folder that cannot be created", ["--export", "{blocked}"], r"a_file"),
    ("agents.tools.serve", "export in a folder that cannot be created", ["--export", "{blocked}"], r"a_file"),
    (
        "train.py",
        "out in a folder that cannot be created",
        ["--out", "{blocked}", "--timesteps", "64", "--eval-episodes", "1", "--eval-points", "0", "--baselines", ""],
        r"a_file",
    ),
    (
        "agents.evaluate",
        "csv in a folder that cannot be created",
        ["--agent", "random", "--episodes", "1", "--n-envs", "1", "--csv", "{blocked}/out.csv"],
        r"a_file",
    ),
    (
        "agents.evaluate",
        "plot in a folder that cannot be created",
        ["--agent", "random", "--episodes", "1", "--n-envs", "1", "--plot", "{blocked}/rates.png"],
        r"--plot: .*a_file",
    ),
    (
        "agents.evaluate",
        "json-out in a folder that cannot be created",
        ["--agent", "random", "--episodes", "1", "--n-envs", "1", "--json-out", "{blocked}/out.json"],
        r"--json-out: .*a_file",
    ),
    (
        "agents.tools.record",
        "out in a folder that cannot be created",
        ["--agent", "handbook", "--max-steps", "3", "--out", "{blocked}"],
        r"--out: .*a_file is not a folder",
    ),
    (
        "coop_gym.experiment.protocol",
        "plot in a folder that cannot be created",
        ["--subjects", "1", "--trials", "1", "--plot", "{blocked}/trace.png"],
        r"a_file",
    ),
]


def make_artifacts(folder: Path) -> dict[str, str]:
    """Saved models for the bad-model cases: one good PPO on SitToStand-v0, and damaged ones.

    ``bad_agent_json`` and ``bad_vecnormalize`` are older-style folders (a plain SB3 zip with the
    metadata and statistics beside it), where those side files are what is read.
    """
    import zipfile

    import torch

    from agents.hyperparams import hyperparams_for
    from agents.rl import make_model, make_train_env, save_agent

    torch.set_num_threads(1)
    config = hyperparams_for("ppo")
    env = make_train_env(config.env_id, 1, 0, normalize=True, backend="dummy")
    good = folder / "good"
    save_agent(make_model(config, env, 0), good, algo="ppo", env_id=config.env_id)
    env.close()
    paths = {"model": good / "model.zip", "blocked": folder / "a_file" / "sub"}
    (folder / "a_file").write_text("not a folder")
    paths["empty"] = folder / "empty" / "model.zip"
    paths["truncated"] = folder / "truncated" / "model.zip"
    paths["text"] = folder / "text" / "model.zip"
    for name in ("empty", "truncated", "text"):
        paths[name].parent.mkdir()
    paths["empty"].write_bytes(b"")
    paths["truncated"].write_bytes(paths["model"].read_bytes()[:3000])
    paths["text"].write_text("this is not a model")
    for name in ("bad_agent_json", "bad_vecnormalize"):
        old = folder / name
        old.mkdir()
        with zipfile.ZipFile(paths["model"]) as src, zipfile.ZipFile(old / "model.zip", "w") as dst:
            for item in src.infolist():
                if not item.filename.startswith("coop_gym/"):
                    dst.writestr(item, src.read(item.filename))
        (old / "agent.json").write_text((good / "agent.json").read_text())
        (old / "vecnormalize.pkl").write_bytes((good / "vecnormalize.pkl").read_bytes())
        paths[name] = old
    (paths["bad_agent_json"] / "agent.json").write_text('{"algo": "ppo", ')
    (paths["bad_vecnormalize"] / "vecnormalize.pkl").write_bytes(b"\x80\x04 not a pickle")
    paths["out"] = folder / "out"
    paths["out"].mkdir()
    return {k: str(v) for k, v in paths.items()}


# Saved models that are damaged or belong to another env id ({name} from make_artifacts).
_E = ["--eval-only", "--eval-episodes", "1", "--baselines", "", "--out", "{out}"]
_ORACLE = "CoopGym/SitToStandOracle-v0"
_DIFFER = r"the model's 11 observation features differ from CoopGym/SitToStandOracle-v0's 12: .* extra \['true_xi'\]"
MODEL_CASES: list[tuple[str, str, list[str], str]] = [
    (
        "train.py",
        "eval-only: empty model.zip",
        [*_E, "--model", "{empty}"],
        r"--model: could not load .*: the file is empty",
    ),
    ("train.py", "eval-only: truncated model.zip", [*_E, "--model", "{truncated}"], r"not a complete zip archive"),
    ("train.py", "eval-only: text as model.zip", [*_E, "--model", "{text}"], r"not a complete zip archive"),
    ("train.py", "eval-only: bad agent.json", [*_E, "--model", "{bad_agent_json}"], r"agent.json: not valid JSON"),
    ("train.py", "eval-only: bad vecnormalize.pkl", [*_E, "--model", "{bad_vecnormalize}"], r"vecnormalize.pkl: not a"),
    ("train.py", "eval-only: model of another id", [*_E, "--model", "{model}", "--env", _ORACLE], _DIFFER),
    (
        "train.py",
        "resume: model of another id",
        ["--resume", "{model}", "--env", _ORACLE, "--out", "{out}"],
        r"--env 'CoopGym/SitToStandOracle-v0' \(the run has 'CoopGym/SitToStandHard-v2'\) contradict the saved run",
    ),
    ("train.py", "resume: empty model.zip", ["--resume", "{empty}", "--out", "{out}"], r"--resume: could not load"),
    ("agents.evaluate", "empty model.zip", ["--model", "{empty}", "--episodes", "1"], r"--model .*: the file is empty"),
    ("agents.evaluate", "truncated model.zip", ["--model", "{truncated}", "--episodes", "1"], r"not a complete zip"),
    ("agents.evaluate", "bad agent.json", ["--model", "{bad_agent_json}", "--episodes", "1"], r"agent.json: not valid"),
    ("agents.evaluate", "bad vecnormalize.pkl", ["--model", "{bad_vecnormalize}"], r"vecnormalize.pkl: not a readable"),
    ("agents.evaluate", "model of another id", ["--model", "{model}", "--env", _ORACLE, "--episodes", "1"], _DIFFER),
    ("agents.tools.record", "empty model.zip", ["--model", "{empty}", "--out", "{out}"], r"--model .*could not load"),
    (
        "agents.tools.record",
        "bad agent.json",
        ["--model", "{bad_agent_json}", "--out", "{out}"],
        r"agent.json: not valid",
    ),
    ("agents.tools.record", "model of another id", ["--model", "{model}", "--env", _ORACLE, "--out", "{out}"], _DIFFER),
]


@pytest.fixture(scope="module")
def artifacts(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    return make_artifacts(tmp_path_factory.mktemp("artifacts"))


@pytest.mark.parametrize(("cli", "argv", "match"), _params(MODEL_CASES))
def test_bad_model_exits_2_with_one_line_before_any_work(
    cli: str, argv: list[str], match: str, artifacts: dict[str, str]
) -> None:
    argv = [a.format(**artifacts) for a in argv]
    code, err = run_main(_main_of(cli), argv)
    assert_exit_2_naming(code, err, match)
    assert "Traceback" not in err
    message = [line for line in err.splitlines() if "error" in line]
    assert len(message) == 1, err  # one line names the problem (argparse may add its usage above it)
    assert not any(Path(artifacts["out"]).iterdir()), "nothing is written for a bad model"


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into a read-only folder anyway")
def test_record_into_a_read_only_folder_exits_2(tmp_path: Path) -> None:
    out = tmp_path / "videos"
    out.mkdir()
    out.chmod(0o500)
    try:
        code, err = run_main(_main_of("agents.tools.record"), ["--agent", "handbook", "--out", str(out)])
    finally:
        out.chmod(0o700)
    assert code == 2 and re.search(r"--out: .* is not writable", err), err


def test_read_only_check_names_the_folder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """What a non-root user sees for a read-only --out (root can write anywhere, so access is faked)."""
    out = tmp_path / "videos"
    out.mkdir()
    monkeypatch.setattr(os, "access", lambda path, mode: Path(path) != out)
    code, err = run_main(_main_of("agents.tools.record"), ["--agent", "handbook", "--out", str(out)])
    assert code == 2 and re.search(rf"--out: cannot create {re.escape(str(out))}: .* is not writable", err), err


# Where a command line's main(argv) lives when it is not the module ``python -m`` names (that one's
# __main__ calls it): agents.evaluate keeps its CLI apart so that its imports run one way.
_MAIN_MODULE = {"agents.evaluate": "agents.tools.evaluate_cli"}


def _main_of(cli: str) -> Callable[[list[str]], Any]:
    module = _load(_MAIN_MODULE.get(cli, cli))
    main = getattr(module, "main", None)
    assert callable(main), f"{cli} has no main(argv)"
    return main  # type: ignore[no-any-return]


@pytest.mark.parametrize(("cli", "argv", "match"), _params(CASES))
def test_bad_flag_exits_2_naming_the_problem(cli: str, argv: list[str], match: str) -> None:
    assert_exit_2_naming(*run_main(_main_of(cli), argv), match)


PACKAGE_CLIS = (
    "coop_gym.experiment.protocol",
    "coop_gym.experiment.calibrate",
    "agents.evaluate",
    "agents.tools.record",
    "agents.tools.play",
    "agents.tools.serve",
    "agents.caregivers.reading",
    "agents.tune.baselines",
    "agents.tune.belief",
)
"""The package's ``python -m`` command lines: each parses its typed ``Args`` with :func:`coop_gym.cli.parse`."""


@pytest.mark.parametrize("cli", PACKAGE_CLIS)
def test_package_cli_prints_its_help_and_one_line_usage_errors(cli: str) -> None:
    """``--help`` exits 0 with the usage; an unknown flag is the usage line and one error line naming it."""
    out = io.StringIO()
    with alarm(ALARM_S), contextlib.redirect_stdout(out), pytest.raises(SystemExit) as exc:
        _main_of(cli)(["--help"])
    assert exc.value.code == 0 and f"usage: python -m {cli}" in out.getvalue()
    given = ["blind"] if cli == "agents.tune.baselines" else []  # its positional family
    code, err = run_main(_main_of(cli), [*given, "--bogus"])
    assert_exit_2_naming(code, err, r"Unrecognized options: --bogus")
    lines = err.splitlines()
    assert len(lines) == 2 and lines[0] == f"usage: python -m {cli} [-h] [OPTIONS]", err
    assert lines[1].startswith(f"python -m {cli}: error: "), err


# Every CLI checks its output paths before any work (train.py --out, evaluate --csv/--json-out/--plot,
# protocol --plot/--plot-confusion).
@pytest.mark.parametrize(("cli", "argv", "match"), _params(LATE_CASES))
def test_bad_output_path_exits_2_before_the_work(cli: str, argv: list[str], match: str, tmp_path: Path) -> None:
    (tmp_path / "a_file").write_text("not a folder")
    argv = [a.replace("{blocked}", str(tmp_path / "a_file" / "sub")) for a in argv]
    try:
        code, err = run_main(_main_of(cli), argv)
    except OSError as exc:  # the path was only tried after the work was done
        pytest.fail(f"{cli} {' '.join(argv)}: raised {exc!r} after the work instead of exiting 2 up front")
    assert_exit_2_naming(code, err, match)


END_TO_END = {
    "train.py": ([sys.executable, str(ROOT / "train.py"), "--timesteps", "0"], r"--timesteps must be >= 1"),
    "agents.evaluate": ([sys.executable, "-m", "agents.evaluate", "--agent", "nobody"], r"neither a scripted agent"),
    "coop_gym.experiment.protocol": (
        [sys.executable, "-m", "coop_gym.experiment.protocol", "--subjects", "0"],
        r"positive integer",
    ),
    "bench/run.py": ([sys.executable, str(ROOT / "bench" / "run.py"), "--bogus"], r"unrecognized arguments"),
}


@pytest.mark.parametrize("cli", END_TO_END)
def test_bad_flag_end_to_end(cli: str) -> None:
    """A real process: exit status 2, usage and the message on stderr, nothing on stdout."""
    argv, match = END_TO_END[cli]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=120, cwd=ROOT, check=False)
    assert done.returncode == 2, done.stderr
    assert "usage:" in done.stderr
    assert re.search(match, done.stderr), done.stderr
    assert done.stdout == ""


# --- a full disk -----------------------------------------------------------------
# The disk is "full" after the bytes are written and before they are flushed (coop_gym.io._fsync
# raises ENOSPC), the moment a real ENOSPC strikes: each file then exists only as a temporary,
# and must be gone afterwards; the command exits 1 with one line.


@pytest.fixture
def full_disk(monkeypatch: pytest.MonkeyPatch) -> list[Path]:
    """Every atomic write fails with ENOSPC once its temporary file holds the data; the files tried."""
    from coop_gym import io as atomic_io

    tried: list[Path] = []

    def no_space(path: Path) -> None:
        assert path.exists()  # the partial file is on disk now
        tried.append(path)
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))

    monkeypatch.setattr(atomic_io, "_fsync", no_space)
    return tried


def _left(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file())


@pytest.mark.parametrize(
    ("cli", "argv"),
    [
        (
            "agents.evaluate",
            ["--agent", "random", "--episodes", "2", "--n-envs", "2", "--csv", "{out}/a.csv",
             "--json-out", "{out}/a.json", "--plot", "{out}/a.png"],
        ),
        ("coop_gym.experiment.protocol", ["--subjects", "1", "--trials", "1", "--plot", "{out}/trace.png"]),
        ("agents.tools.record", ["--agent", "handbook", "--max-steps", "5", "--out", "{out}"]),
        ("train.py", ["--timesteps", "64", "--eval-episodes", "1", "--baselines", "", "--out", "{out}"]),
    ],
)  # fmt: skip
def test_a_full_disk_leaves_no_partial_file(cli, argv, tmp_path, full_disk):
    if cli == "agents.tools.record" and importlib.util.find_spec("pygame") is None:
        pytest.skip("rendering needs pygame")
    out = tmp_path / "out"
    out.mkdir()
    code, err = run_main(_main_of(cli), [a.format(out=out) for a in argv])
    assert code == 1, err
    assert full_disk, "nothing was written through coop_gym.io"
    assert "No space left on device" in err and "Traceback" not in err
    assert _left(out) == [], "a file was left behind"
    assert not any(out.iterdir()), "a folder was left behind"


def bad_input_table() -> list[tuple[str, str, Any, str]]:
    """Run every case above; ``(command, case, exit status, the error line)`` for each."""
    import tempfile

    rows = []
    with tempfile.TemporaryDirectory() as folder:
        paths = make_artifacts(Path(folder))
        for cli, case, argv, _ in [*CASES, *LATE_CASES, *MODEL_CASES]:
            code, err = run_main(_main_of(cli), [a.format(**paths) for a in argv])
            lines = [line for line in err.splitlines() if "error" in line] or err.splitlines()[-1:] or [""]
            rows.append((cli, case, code, lines[-1].replace(folder, "<tmp>")))
    return rows


if __name__ == "__main__":
    # python tests/test_cli_bad_input.py: the bad-input table (case -> message -> exit status).
    # Run as a script, sys.path starts with tests/, whose coop_gym/ folder would shadow the package.
    sys.path[:] = [str(ROOT)] + [p for p in sys.path if Path(p).resolve() != ROOT / "tests"]
    print("| command | case | message | exit |")
    print("|---|---|---|---|")
    for cli, case, code, message in bad_input_table():
        print(f"| {cli} | {case} | {message.replace('|', '/')} | {code} |")
