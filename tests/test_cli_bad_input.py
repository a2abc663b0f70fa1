"""Bad command-line flags: exit status 2 and a message naming the problem on stderr.

Covers the command lines that exist: ``python train.py``, ``python -m agents.evaluate``,
``python -m experiment.protocol`` and ``python bench/run.py`` (each skipped, naming the
missing module, until it is written). Cases call ``main(argv)`` in-process (argparse exits
through ``SystemExit``) under an alarm, so a bad flag that is wrongly accepted fails the test
in seconds instead of starting a training run; one real subprocess per command line checks
the exit status and stderr end to end.
"""

from __future__ import annotations

import contextlib
import importlib
import importlib.util
import io
import re
import signal
import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[1]
ALARM_S = 30  # a rejected flag exits at once; an accepted one would start the real work


def _load(name: str) -> Any:
    """The module of a command line, or skip naming it."""
    if name.endswith(".py"):
        path = ROOT / name
        if not path.exists():
            pytest.skip(f"{name} does not exist yet")
        name = f"_cli_{path.stem}"
        if name in sys.modules:
            return sys.modules[name]
        spec = importlib.util.spec_from_file_location(name, path)
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module  # dataclasses look their module up while the file runs
        spec.loader.exec_module(module)
        return module
    try:
        return importlib.import_module(name)
    except ModuleNotFoundError as exc:
        pytest.skip(f"{name} does not exist yet ({exc})")


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


# (command line, case id, argv, regex the stderr must match)
CASES: list[tuple[str, str, list[str], str]] = [
    ("train.py", "unknown flag", ["--bogus"], r"unrecognized arguments: --bogus"),
    ("train.py", "unknown algo", ["--algo", "a2c"], r"--algo must be one of .*'a2c'"),
    ("train.py", "unknown env", ["--env", "Nope-v0"], r"--env: unknown env id 'Nope-v0'"),
    ("train.py", "timesteps 0", ["--timesteps", "0"], r"--timesteps must be >= 1, got 0"),
    ("train.py", "timesteps not a number", ["--timesteps", "many"], r"--timesteps: invalid int value: 'many'"),
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
    ("agents.evaluate", "no agent", [], r"give --agent NAME, --model PATH or --compare"),
    ("agents.evaluate", "unknown flag", ["--agent", "random", "--bogus"], r"unrecognized arguments: --bogus"),
    ("agents.evaluate", "unknown agent", ["--agent", "nobody"], r"'nobody' is neither a scripted agent"),
    ("agents.evaluate", "missing model", ["--model", "/nonexistent/model.zip"], r"neither a scripted agent .* model"),
    ("agents.evaluate", "episodes 0", ["--agent", "random", "--episodes", "0"], r"--episodes must be >= 1, got 0"),
    ("agents.evaluate", "episodes not a number", ["--agent", "random", "--episodes", "x"], r"invalid int value: 'x'"),
    ("agents.evaluate", "n-envs 0", ["--agent", "random", "--n-envs", "0"], r"--n-envs must be >= 1, got 0"),
    ("agents.evaluate", "negative seed", ["--agent", "random", "--seed", "-3"], r"--seed must be >= 0, got -3"),
    ("agents.evaluate", "unknown persona", ["--agent", "random", "--personas", "nobody"], r"--personas: unknown"),
    ("agents.evaluate", "unknown env", ["--agent", "random", "--env", "Nope-v0"], r"--env: unknown env id 'Nope-v0'"),
    ("agents.evaluate", "unknown backend", ["--agent", "random", "--backend", "gpu"], r"--backend: invalid choice"),
    ("experiment.protocol", "unknown flag", ["--bogus"], r"unrecognized arguments: --bogus"),
    ("experiment.protocol", "subjects 0", ["--subjects", "0"], r"--subjects: expected a positive integer, got 0"),
    ("experiment.protocol", "trials not a number", ["--trials", "x"], r"--trials: expected a positive integer, got 'x'"),  # noqa: E501
    ("experiment.protocol", "negative seed", ["--seed", "-1"], r"--seed: expected a non-negative integer seed"),
    ("experiment.protocol", "seeds 0", ["--seeds", "0"], r"--seeds: expected a positive integer, got 0"),
    (
        "experiment.protocol",
        "unknown estimator",
        ["--estimator", "particle"],
        r"--estimator: invalid choice: 'particle'",
    ),
    ("experiment.protocol", "unknown decision", ["--decision", "vote"], r"--decision: invalid choice: 'vote'"),
    ("experiment.protocol", "unknown persona", ["--personas", "nobody"], r"nobody"),
    ("experiment.protocol", "plot not png", ["--plot", "trace.txt"], r"plot paths must end in \.png"),
    ("bench/run.py", "unknown flag", ["--bogus"], r"unrecognized arguments: --bogus"),
    ("bench/run.py", "repeats 0", ["--repeats", "0"], r"--repeats: expected a positive integer, got 0"),
    ("bench/run.py", "repeats not a number", ["--repeats", "few"], r"--repeats: expected a positive integer, got 'few'"),  # noqa: E501
]

# Bad output paths: found only when the results are written, unless checked up front. The
# argv keeps the work tiny, so a late failure shows as a traceback, not a long run.
# {blocked} is a folder that cannot exist: its parent is a regular file.
LATE_CASES: list[tuple[str, str, list[str], str]] = [
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
        "experiment.protocol",
        "plot in a folder that cannot be created",
        ["--subjects", "1", "--trials", "1", "--plot", "{blocked}/trace.png"],
        r"a_file",
    ),
]


def _main_of(cli: str) -> Callable[[list[str]], Any]:
    module = _load(cli)
    main = getattr(module, "main", None)
    if main is None:
        pytest.skip(f"{cli} has no main(argv) yet")
    return main  # type: ignore[no-any-return]


@pytest.mark.parametrize(
    ("cli", "argv", "match"), [(c[0], c[2], c[3]) for c in CASES], ids=[f"{c[0]}: {c[1]}" for c in CASES]
)
def test_bad_flag_exits_2_naming_the_problem(cli: str, argv: list[str], match: str) -> None:
    code, err = run_main(_main_of(cli), argv)
    assert code == 2, f"exit status {code!r}, stderr: {err}"
    assert re.search(match, err), f"stderr does not name the problem: {err!r}"


@pytest.mark.parametrize(
    ("cli", "argv", "match"),
    # Every CLI checks its output paths before any work (train.py --out, evaluate --csv/--json-out/--plot,
    # protocol --plot/--plot-confusion).
    [pytest.param(c[0], c[2], c[3]) for c in LATE_CASES],
    ids=[f"{c[0]}: {c[1]}" for c in LATE_CASES],
)
def test_bad_output_path_exits_2_before_the_work(cli: str, argv: list[str], match: str, tmp_path: Path) -> None:
    (tmp_path / "a_file").write_text("not a folder")
    argv = [a.replace("{blocked}", str(tmp_path / "a_file" / "sub")) for a in argv]
    try:
        code, err = run_main(_main_of(cli), argv)
    except OSError as exc:  # the path was only tried after the work was done
        pytest.fail(f"{cli} {' '.join(argv)}: raised {exc!r} after the work instead of exiting 2 up front")
    assert code == 2, f"exit status {code!r}, stderr: {err}"
    assert re.search(match, err), err


END_TO_END = {
    "train.py": ([sys.executable, str(ROOT / "train.py"), "--timesteps", "0"], r"--timesteps must be >= 1"),
    "agents.evaluate": ([sys.executable, "-m", "agents.evaluate", "--agent", "nobody"], r"neither a scripted agent"),
    "experiment.protocol": ([sys.executable, "-m", "experiment.protocol", "--subjects", "0"], r"positive integer"),
    "bench/run.py": ([sys.executable, str(ROOT / "bench" / "run.py"), "--bogus"], r"unrecognized arguments"),
}


@pytest.mark.parametrize("cli", END_TO_END)
def test_bad_flag_end_to_end(cli: str) -> None:
    """A real process: exit status 2, usage and the message on stderr, nothing on stdout."""
    if cli.endswith(".py") and not (ROOT / cli).exists():
        pytest.skip(f"{cli} does not exist yet")
    if not cli.endswith(".py") and importlib.util.find_spec(cli) is None:
        pytest.skip(f"{cli} does not exist yet")
    argv, match = END_TO_END[cli]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=120, cwd=ROOT, check=False)
    assert done.returncode == 2, done.stderr
    assert "usage:" in done.stderr
    assert re.search(match, done.stderr), done.stderr
    assert done.stdout == ""
