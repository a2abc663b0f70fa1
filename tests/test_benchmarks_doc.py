"""docs/BENCHMARKS.md is what bench/report.py renders from the committed results, and every bench script writes one.

The page's figures live in ``bench/results/*.json`` (each bench script's ``--save``); a page
edited by hand, or results rerun without rerendering, fails here. The writers are checked on
runs too small to measure anything: each script's report reaches its file with the command, the
date and the machine, and the page renders from those files. No speed is asserted.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "bench"


def _bench(name: str) -> Any:
    """A bench script as a module (bench/ on sys.path, as when it runs as a script)."""
    if str(BENCH) not in sys.path:
        sys.path.insert(0, str(BENCH))
    module_name = f"_bench_{name}"
    if module_name in sys.modules:
        return sys.modules[module_name]
    spec = importlib.util.spec_from_file_location(module_name, BENCH / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[module_name] = module
    spec.loader.exec_module(module)
    return module


def test_the_page_is_what_the_committed_results_render() -> None:
    report = _bench("report")
    committed = (ROOT / "docs" / "BENCHMARKS.md").read_text(encoding="utf-8")
    assert committed == report.render(), (
        "docs/BENCHMARKS.md differs from what bench/report.py renders from bench/results/*.json: "
        "rerun the benchmark with --save, then python bench/report.py (never edit the page by hand)"
    )


def test_every_committed_result_names_its_command_date_and_machine() -> None:
    files = sorted((BENCH / "results").glob("*.json"))
    assert files, "no results committed in bench/results"
    for path in files:
        record = json.loads(path.read_text(encoding="utf-8"))
        assert record["command"].startswith(f"python bench/{record['benchmark']}.py"), path
        assert record["date"] and record["results"], path
        for key in ("cpu_count", "python", "numpy", "numba"):
            assert record["machine"][key], (path, key)


_CLEANRL_STANDIN = """
import torch

class Agent(torch.nn.Module):
    def __init__(self):
        super().__init__()
        self.actor = torch.nn.Linear(11, 18)

agent = Agent()
"""


def _cases(tmp: Path) -> list[tuple[str, list[str], str, str]]:
    """(script, flags, --save PATH's name with the script's placeholders, the file it becomes)."""
    ttq = ["--env", "CoopGym/SitToStand-v0", "--budget-s", "0.3", "--eval-every-s", "0.3", "--episodes", "4"]
    ttq += ["--contenders", "default,jax,jax-lag"]
    return [
        ("run", ["--quick", "--repeats", "1"], "run.json", "run"),
        ("reset", ["--num-envs", "64", "--repeats", "1"], "reset.json", "reset"),
        ("render", ["--repeats", "1", "--frames", "10"], "render.json", "render"),
        ("soak", ["--steps", "640", "--num-envs", "8"], "soak.json", "soak"),
        ("levels", ["--episodes", "4", "--levels", "hard-v2", "--no-pretrained"], "levels.json", "levels"),
        (
            "papers_experiment",
            ["--seeds", "2", "--estimators", "kalman", "--difficulties", "hard"],
            "papers_experiment.json",
            "papers_experiment",
        ),
        (
            "time_to_quality",
            [*ttq, "--out", str(tmp / "ttq")],
            "time_to_quality_<env>.json",
            "time_to_quality_CoopGym-SitToStand-v0",
        ),
        (
            "library_defaults",
            ["--algo", "dqn", "--timesteps", "64", "--episodes", "4", "--out", str(tmp / "defaults")],
            "library_defaults_<algo>_<env>_<timesteps>.json",
            "library_defaults_dqn_SitToStandDiscrete-v0_64",
        ),
        (
            "library_defaults",
            ["--seeds", "0", "--timesteps", "64", "--episodes", "4", "--runs", str(tmp / "seeds")],
            "library_seeds_SitToStandHard-v2.json",
            "library_seeds_SitToStandHard-v2",
        ),
        (
            "library_defaults",
            [
                *["--study", "never-lift", "--seeds", "0", "--cells", "cleanrl-ppo,sb3-defaults", "--timesteps", "64"],
                *["--cleanrl-script", str(tmp / "standin.py"), "--episodes", "4", "--runs", str(tmp / "never_lift")],
            ],
            "never_lift_SitToStandHard-v2.json",
            "never_lift_SitToStandHard-v2",
        ),
        (
            "learners",
            [
                "--rows",
                "ppo-kalman,cleanrl-ppo,cleanrl-ppo-priced,cleanrl-ppo-ent02",
                "--cleanrl-script",
                str(tmp / "standin.py"),
                "--seeds",
                "0",
                "--timesteps",
                "64",
                "--episodes",
                "4",
                "--validation-episodes",
                "4",
                "--runs",
                str(tmp / "learners"),
            ],
            "learners.json",
            "learners",
        ),
        (
            "learners",
            [
                *["--rows", "jax-kalman-lag", "--seeds", "0", "--timesteps", "4096", "--episodes", "4"],
                *["--validation-episodes", "4", "--runs", str(tmp / "learners")],
            ],
            "learners_ppo.json",
            "learners_ppo",
        ),
        (
            "learners",
            [
                *["--rows", "jax-kalman-lag", "--seeds", "0", "--timesteps", "4096", "--episodes", "4"],
                *["--validation-episodes", "4", "--runs", str(tmp / "learners")],
            ],
            "learners_budget_4096.json",
            "learners_budget_4096",
        ),
        (
            "learners",
            [
                *["--rows", "jax-kalman-lag", "--seeds", "0,1,2", "--timesteps", "4096", "--episodes", "4"],
                *["--validation-episodes", "4", "--people", "--runs", str(tmp / "people")],
            ],
            "selection_people.json",
            "selection_people",
        ),
        (
            "ensembles",
            [
                *["--runs", str(tmp / "people"), "--runs-of", "2", "--sizes", "2", "--timesteps", "4096"],
                *["--episodes", "4", "--validation-episodes", "4"],
            ],
            "ensembles.json",
            "ensembles",
        ),
        (
            "learners",
            [
                *["--rows", "jax-switching-true-population", "--seeds", "0", "--timesteps", "4096", "--episodes", "4"],
                *["--validation-episodes", "4", "--runs", str(tmp / "learners")],
            ],
            "learners_bodies.json",
            "learners_bodies",
        ),
        (
            "learners",
            [
                *["--rows", "jax-lstm-kalman", "--seeds", "0", "--timesteps", "4096"],
                *["--episodes", "4", "--validation-episodes", "4", "--runs", str(tmp / "learners")],
            ],
            "learners_recurrent.json",
            "learners_recurrent",
        ),
        (
            "learners",
            [
                *["--rows", "jax-lstm-raw", "--seeds", "0", "--timesteps", "4096"],
                *["--episodes", "4", "--validation-episodes", "4", "--runs", str(tmp / "learners")],
            ],
            "learners_lstm.json",
            "learners_lstm",
        ),
        (
            "cleanrl_defaults",
            [
                "--script",
                str(tmp / "standin.py"),
                "--total-timesteps",
                "64",
                "--episodes",
                "4",
                "--out",
                str(tmp / "cleanrl"),
            ],
            "cleanrl_defaults_<script>_<env>_<timesteps>.json",
            "cleanrl_defaults_standin_SitToStandDiscreteUnit-v0_64",
        ),
    ]


def test_each_bench_script_writes_its_results_file_and_the_page_renders_from_them(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    torch = pytest.importorskip("torch")
    pytest.importorskip("stable_baselines3")
    threads = torch.get_num_threads()
    results = tmp_path / "results"
    (tmp_path / "standin.py").write_text(_CLEANRL_STANDIN)
    monkeypatch.chdir(tmp_path)  # CleanRL-style scripts log under ./runs
    cases = _cases(tmp_path)
    try:
        for script, flags, save_as, stem in cases:
            _bench(script).main([*flags, "--save", str(results / save_as)])
            assert (results / f"{stem}.json").is_file(), (script, sorted(p.name for p in results.iterdir()))
        # cold_start times fresh processes compiling the kernels (tens of seconds): its writer
        # is checked on stand-in timings.
        cold_start = _bench("cold_start")
        monkeypatch.setattr(cold_start, "_reference", lambda: 0.5)
        monkeypatch.setattr(
            cold_start,
            "_measure",
            lambda *args: {"first_step_s": 2.0, "compiled_s": 9.0, "import_s": 0.5, "total_s": 2.5, "compiles": []},
        )
        cold_start.main(["--num-envs", "0", "--repeats", "1", "--save", str(results / "cold_start.json")])
    finally:
        torch.set_num_threads(threads)
    assert {path.stem for path in results.glob("*.json")} == {stem for *_, stem in cases} | {"cold_start"}
    # A cleanrl row's own flags reach the script, after the common ones.
    ent02 = json.loads((tmp_path / "learners" / "cleanrl-ppo-ent02__0__64.json").read_text(encoding="utf-8"))
    assert ent02["script_command"][-2:] == ["--ent-coef", "0.02"]
    plain = json.loads((tmp_path / "learners" / "cleanrl-ppo__0__64.json").read_text(encoding="utf-8"))
    assert "--ent-coef" not in plain["script_command"]
    for path in results.glob("*.json"):
        record = json.loads(path.read_text(encoding="utf-8"))
        assert record["command"].startswith(f"python bench/{record['benchmark']}.py"), path
        assert record["machine"]["cpu_count"] and record["machine"]["numba"], path
    # Every contender's steps/s against each SB3 contender of the run, per seed.
    ttq = json.loads((results / "time_to_quality_CoopGym-SitToStand-v0.json").read_text(encoding="utf-8"))
    contenders = ttq["results"]["contenders"]
    assert list(contenders) == ["default", "jax", "jax-lag"]
    assert all(list(c["steps_per_s_ratio_to"]) == ["default"] for c in contenders.values())
    assert set(contenders["default"]["steps_per_s_ratio_to"]["default"]) == {1.0}
    page = _bench("report").render(results)
    assert "No results file yet" not in page


def test_a_learner_rows_sizing_reaches_the_model(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``ROW@N-eE``: N envs, the update's samples kept (n_steps scaled), E epochs; ``ROW@N``: the row's epochs.

    A ``jax-*`` row trains ``agents.ppo``; its ``normalize=False`` leaves the observation normaliser out, and an
    SB3 row's frames are stacked where a ``jax-*`` row's are refused.
    """
    pytest.importorskip("stable_baselines3")
    import agents.ppo.recurrent
    import agents.rl
    import agents.rl.ppo_run

    learners = _bench("learners")
    built: dict[str, Any] = {}

    class Built(Exception):
        pass

    def capture(env_id: str, config: Any, seed: int, env_kwargs: dict[str, Any]) -> Any:
        built.update(config=config, env_kwargs=env_kwargs, seed=seed)
        raise Built

    def capture_sb3(config: Any, env: Any, seed: int, **_: Any) -> Any:
        built.update(env=env, **config.algo_kwargs)
        raise Built

    monkeypatch.setattr(agents.rl.ppo_run, "PPO", capture)  # what make_learner builds
    monkeypatch.setattr(agents.rl.ppo_run, "RecurrentPPO", capture)
    monkeypatch.setattr(agents.rl, "make_model", capture_sb3)
    for name, expected in (("jax-kalman@64-e4", (64, 64, 4)), ("jax-kalman@64", (64, 64, 10))):
        with pytest.raises(Built):
            learners.train_one(name, 0, 64, 4, tmp_path, 4)
        config = built["config"]
        assert (config.n_envs, config.n_steps, config.n_epochs) == expected, name
    # A row's own learner settings reach the learner, over train.py's.
    with pytest.raises(Built):
        learners.train_one("jax-kalman-lag", 3, 64, 4, tmp_path, 4)
    assert built["config"].policy_lag == 1 and built["config"].ent_coef == 0.02 and built["seed"] == 3
    with pytest.raises(Built):
        learners.train_one("jax-kalman", 0, 64, 4, tmp_path, 4)
    assert built["config"].policy_lag == 0  # a jax row is sequential unless it says otherwise, whatever train.py's
    assert built["config"].normalize_obs and built["env_kwargs"] == {"personas": "train_wide"}
    # The switching rows across bodies: the light filter's hypotheses, or the filter given the true person.
    for name, options in (
        ("jax-switching-population", {"n_particles": 256, "hypotheses": 32}),
        ("jax-switching-true-population", {"n_particles": 256, "hypotheses": 1, "true_person": True}),
    ):
        with pytest.raises(Built):
            learners.train_one(name, 0, 64, 4, tmp_path, 4)
        kwargs = built["env_kwargs"]
        assert kwargs["personas"] == "train_population" and kwargs["estimator"] == "switching", name
        assert kwargs["estimator_options"] == options and built["config"].policy_lag == 1, name
    # A row without normalisation trains on its own env, as CleanRL's script would see it.
    with pytest.raises(Built):
        learners.train_one("jax-discreteunit", 0, 64, 4, tmp_path, 4)
    assert not built["config"].normalize_obs and built["env_kwargs"]["action_type"] == "discrete"
    # SB3 rows: VecNormalize, and frames stacked on request.
    from stable_baselines3.common.vec_env import VecFrameStack, VecNormalize

    with pytest.raises(Built):
        learners.train_one("ppo-raw-stack4", 0, 64, 4, tmp_path, 4)
    assert isinstance(built["env"], VecFrameStack) and isinstance(built["env"].venv, VecNormalize)
    with pytest.raises(argparse.ArgumentTypeError, match="jax-raw-stack4"):
        learners._rows("jax-raw-stack4")
    built.clear()  # the recurrent jax rows are agents.ppo's RecurrentPPO, on train.py's settings
    with pytest.raises(Built):
        learners.train_one("jax-lstm-kalman", 2, 64, 4, tmp_path, 4)
    assert isinstance(built["config"], agents.ppo.recurrent.RecurrentPPOConfig) and built["seed"] == 2
    assert built["config"].lstm_hidden_size == 64 and built["env_kwargs"] == {"personas": "train_wide"}
    # The same sizing names a time_to_quality contender.
    from agents.hyperparams import hyperparams_for

    ttq = _bench("time_to_quality")
    config = ttq.resized(hyperparams_for("ppo", "CoopGym/SitToStandHard-v2", "jax"), "64-e4")
    assert (config.n_envs, config.algo_kwargs["n_steps"], config.algo_kwargs["n_epochs"]) == (64, 64, 4)
    config = ttq.resized(hyperparams_for("ppo", "CoopGym/SitToStandHard-v2", "jax"), "64")
    assert (config.n_envs, config.algo_kwargs["n_epochs"]) == (64, 10)
    lagged = agents.ppo.PPOConfig.from_training(ttq._sized_config("jax-lag@32", "CoopGym/SitToStandHard-v2"))
    assert (lagged.policy_lag, lagged.n_envs, lagged.n_steps) == (1, 32, 128)
    assert ttq._sized_config("jax", "CoopGym/SitToStandHard-v2").algo_kwargs["policy_lag"] == 0


def test_time_to_quality_budget_steps_end_a_run_and_decay_its_learning_rate(monkeypatch: pytest.MonkeyPatch) -> None:
    """``--budget-steps``: training stops after that many steps, its learning rate decayed over them."""
    pytest.importorskip("jax")
    import agents.ppo

    ttq = _bench("time_to_quality")
    rates: list[float] = []
    build = ttq._build

    def recording_build(*args: Any) -> Any:
        model = build(*args)
        learn = model.learn

        def learn_and_record(*learn_args: Any, **kwargs: Any) -> Any:
            result = learn(*learn_args, **kwargs)
            rates.append(model.lr_schedule(model._current_progress_remaining))
            return result

        model.learn = learn_and_record
        return model

    monkeypatch.setattr(ttq, "_build", recording_build)
    config = ttq._sized_config("default", "CoopGym/SitToStand-v0")
    rollout = config.n_envs * config.algo_kwargs["n_steps"]
    run = ttq._train_with_clock("default", "CoopGym/SitToStand-v0", 0, 600.0, 600.0, 2, 0, {}, False, 2 * rollout)
    assert run["timesteps"] == 2 * rollout and run["curve"][-1]["timesteps"] == 2 * rollout
    assert rates == [pytest.approx(0.0, abs=1e-12)]  # linear decay to 0 at the budget's end
    # agents.ppo: its rate too falls to 0 over the budget.
    learners: list[Any] = []
    original = agents.ppo.PPO

    def recording_ppo(*args: Any, **kwargs: Any) -> Any:
        learners.append(original(*args, **kwargs))
        return learners[-1]

    monkeypatch.setattr(agents.ppo, "PPO", recording_ppo)
    rollout = 4096  # the jax sizing's 16 envs x 256 steps
    run = ttq._train_with_clock("jax", "CoopGym/SitToStand-v0", 0, 600.0, 600.0, 2, 0, {}, False, 2 * rollout)
    assert run["timesteps"] == 2 * rollout and run["curve"][-1]["timesteps"] == 2 * rollout
    assert learners[0].learning_rate == pytest.approx(0.0, abs=1e-12)


def test_cleanrl_rows_flags_are_train_pys_settings() -> None:
    """``TRAINPY_FLAGS`` say, in CleanRL's flags, what ``train.py`` trains the hard level with."""
    from agents.hyperparams import hyperparams_for

    learners = _bench("learners")
    config = hyperparams_for("ppo", learners.ENV_ID, "jax")
    kwargs = config.algo_kwargs
    flags = learners.TRAINPY_FLAGS
    assert flags[-1] == "--no-clip-vloss" and "clip_range_vf" not in kwargs  # SB3 clips no value by default
    given = dict(zip(flags[:-1:2], flags[1:-1:2], strict=True))
    assert int(given["--num-envs"]) == config.n_envs
    assert int(given["--num-steps"]) == kwargs["n_steps"]
    assert int(given["--num-minibatches"]) * kwargs["batch_size"] == config.n_envs * kwargs["n_steps"]
    assert int(given["--update-epochs"]) == kwargs["n_epochs"]
    assert kwargs["learning_rate"] == f"lin_{given['--learning-rate']}"  # CleanRL anneals linearly by default
    assert float(given["--gamma"]) == kwargs["gamma"]
    assert float(given["--ent-coef"]) == kwargs["ent_coef"]
    # The rest are CleanRL ppo.py's own defaults already.
    assert (kwargs["gae_lambda"], kwargs["clip_range"], kwargs["vf_coef"], kwargs["max_grad_norm"]) == (
        0.95, 0.2, 0.5, 0.5,
    )  # fmt: skip
    assert config.policy_kwargs == {"net_arch": [64, 64]}
    # The two halves are the rollout/update-size row and the loss row.
    assert learners.ROWS["cleanrl-ppo-rollout"].script_args + learners.ROWS["cleanrl-ppo-loss"].script_args == flags


def test_cleanrl_wide_row_trains_on_train_pys_personas() -> None:
    """The ``WidePersonas`` id is the CleanRL id on ``train_wide``, however CleanRL's ``gym.make`` calls it."""
    import gymnasium as gym

    from coop_gym.model.personas import resolve_personas

    learners = _bench("learners")
    defaults = _bench("cleanrl_defaults")
    assert learners.WIDE_TRAIN_ENV == f"cleanrl_defaults:{defaults.WIDE_ENV_ID}"
    assert learners.ROWS["cleanrl-ppo-wide"].train_env == learners.ROWS["cleanrl-ppo-trainpy-wide"].train_env
    assert learners.ROWS["cleanrl-ppo-wide"].train_env == learners.WIDE_TRAIN_ENV
    # The jax rows on CleanRL's interface make the same env from ENV_ID.
    assert gym.spec(learners.CLEANRL_ENV_ID).kwargs == {**gym.spec(learners.ENV_ID).kwargs, **learners.DISCRETE_UNIT}
    wide = gym.make(defaults.WIDE_ENV_ID).unwrapped
    own = gym.make(learners.CLEANRL_ENV_ID).unwrapped

    # The level sets its own person parameters; the set decides who and how widely they vary.
    def spread(personas: Any) -> list[tuple[str, float]]:
        return [(p.name, p.variation_relative_std) for p in personas]

    assert spread(wide.personas) == spread(resolve_personas("train_wide"))
    assert spread(own.personas) == spread(resolve_personas("train")) != spread(wide.personas)


def test_the_machine_record_names_the_cpu_and_its_widest_vector_extension(tmp_path: Path) -> None:
    result_files = _bench("result_files")
    info = tmp_path / "cpuinfo"
    processor = "processor\t: {n}\nmodel name\t: Some CPU\nflags\t\t: fpu sse4_2 avx avx2 fma{extra}\n\n"
    info.write_text(processor.format(n=0, extra="") + processor.format(n=1, extra=""), encoding="utf-8")
    assert result_files.cpu(info) == "Some CPU (avx2)"
    info.write_text(processor.format(n=0, extra=" avx512f avx512bw"), encoding="utf-8")
    assert result_files.cpu(info) == "Some CPU (avx512f)"
    assert result_files.cpu(tmp_path / "missing") is None
    assert "cpu" in result_files.machine()


def test_the_same_seeds_on_another_cpu_are_rendered_seed_by_seed(tmp_path: Path) -> None:
    report = _bench("report_learners")
    reference = json.loads((BENCH / "results" / "learners.json").read_text(encoding="utf-8"))
    # One machine: the section names the command that measures another.
    assert "bench/results/learners_<cpu>.json" in report.learners_across_cpus({"learners": reference})
    name = next(iter(reference["results"]["rows"]))
    other = json.loads(json.dumps(reference))
    other["machine"]["cpu"] = "Another CPU (avx2)"
    other["results"]["rows"] = {name: other["results"]["rows"][name]}
    runs = other["results"]["rows"][name]["per_seed"]
    for run, change in zip(runs, [0.02, -0.10] + [0.0] * (len(runs) - 2), strict=True):
        run["success_rate"] += change
    page = report.learners_across_cpus({"learners": reference, "learners_avx2": other})
    lines = [line for line in page.splitlines() if line.startswith(f"| `{name}` |")]
    assert len(lines) == 2, page  # one row per machine, the reference first
    assert "(reference)" in lines[0] and "Another CPU (avx2)" in lines[1]
    assert lines[1].endswith(" | 0.0 / 10.0 |"), lines[1]  # median and largest change per seed, in points


def test_training_budget_rows_are_one_cpus_budgets_and_not_another_cpu() -> None:
    """``learners_budget_*.json`` make the budget table with the same CPU's default row, and no CPU row."""
    report = _bench("report_learners")
    results = {
        stem: json.loads((BENCH / "results" / f"{stem}.json").read_text(encoding="utf-8"))
        for stem in ("learners", "learners_avx512", "learners_budget_2000000")
    }
    assert "No results file yet" in report.training_budget({"learners": results["learners"]})
    page = report.training_budget(results)
    rows = [line for line in page.splitlines() if line.startswith("| ") and "budget" not in line and "---" not in line]
    assert [row.split(" | ")[0] for row in rows] == ["| **1,000,000**", "| 2,000,000"], page
    cpus = report.learners_across_cpus(results)
    assert "2,000,000" not in cpus and cpus.count("| `jax-kalman-lag` |") == 2  # the two CPUs' 1M rows only


def test_other_sections_records_are_not_the_learners_rows_on_another_cpu() -> None:
    """``learners_ppo``/``learners_bodies`` hold ``jax-kalman-lag`` trained by another learner or on other people."""
    report = _bench("report_learners")
    results = {
        stem: json.loads((BENCH / "results" / f"{stem}.json").read_text(encoding="utf-8"))
        for stem in ("learners", "learners_ppo", "learners_bodies")
    }
    assert all("jax-kalman-lag" in record["results"]["rows"] for record in results.values())
    assert "No second machine yet" in report.learners_across_cpus(results)
    budgets = json.loads((BENCH / "results" / "learners_budget_2000000.json").read_text(encoding="utf-8"))
    for record in results.values():
        record["machine"]["cpu"] = budgets["machine"]["cpu"]
    page = report.training_budget({**results, "learners_budget_2000000": budgets})
    assert page.count("| **1,000,000** |") == 1, page  # learners.json's row alone


def test_outside_learners_take_the_cleanrl_seeds_record_over_the_learners_one() -> None:
    """``cleanrl_seeds_SitToStandHard-v2.json`` gives the CleanRL rows, every row of it, with its budget."""
    quality = _bench("report_quality")
    results = {
        stem: json.loads((BENCH / "results" / f"{stem}.json").read_text(encoding="utf-8"))
        for stem in ("library_seeds_SitToStandHard-v2", "learners")
    }
    before = quality.outside_learners(results)
    assert "| `cleanrl-ppo-trainpy`: " in before and "| `cleanrl-ppo-wide`: " not in before
    seeds = json.loads(json.dumps(results["learners"]))
    rows = seeds["results"]["rows"]
    seeds["results"]["rows"] = {"cleanrl-ppo-wide": rows["cleanrl-ppo-wide"]}
    longer = json.loads(json.dumps(seeds))
    longer["results"]["timesteps"] = 2_000_000
    longer["results"]["rows"] = {"cleanrl-ppo-trainpy": rows["cleanrl-ppo-trainpy"]}
    # Another budget's file renders after the first, each row with its budget and each file its provenance.
    page = quality.outside_learners(
        {**results, f"{quality.CLEANRL_SEEDS}_2000000": longer, quality.CLEANRL_SEEDS: seeds}
    )
    lines = [line for line in page.splitlines() if line.startswith("| `cleanrl-")]
    assert len(lines) == 2 and lines[0].startswith("| `cleanrl-ppo-wide`: "), page
    assert ", 1,000,000 steps | 5 | " in lines[0] and "/ 100.0" in lines[0]  # never lifts: the timeout rate
    assert lines[1].startswith("| `cleanrl-ppo-trainpy`: ") and ", 2,000,000 steps | 8 | " in lines[1]
    assert "rows of 1,000,000 steps: *Measured by*" in page and "rows of 2,000,000 steps: *Measured by*" in page


def test_a_cleanrl_runs_record_scores_the_validation_people(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """What a choice of flags is made on: the run's policy on ``personas="validation"``, beside the held-out score."""
    pytest.importorskip("torch")
    learners = _bench("learners")
    (tmp_path / "standin.py").write_text(_CLEANRL_STANDIN)
    monkeypatch.chdir(tmp_path)
    seen: list[str] = []
    evaluate = __import__("agents.evaluate", fromlist=["evaluate"]).evaluate

    def spy(agent: Any, env_id: str, personas: str, *args: Any, **kwargs: Any) -> Any:
        seen.append(personas)
        return evaluate(agent, env_id, personas, *args, **kwargs)

    monkeypatch.setattr("agents.evaluate.evaluate", spy)
    run = learners.train_cleanrl("cleanrl-ppo-trainpy", tmp_path / "standin.py", 0, 64, 4, tmp_path, 4)
    assert seen == ["train", "validation", "test"]
    rate_keys = _bench("result_files").RATE_KEYS
    assert set(run["validation_people"]) == set(rate_keys)
    assert sum(run["validation_people"][key] for key in rate_keys) == pytest.approx(1.0)
    assert tuple(run["script_command"][-len(learners.TRAINPY_FLAGS) :]) == learners.TRAINPY_FLAGS


def test_the_rl_zoo_learner_runs_the_documented_command_and_keeps_its_layout(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``library_defaults.py --learners rl-zoo``: the integrations page's command, a seed added; RL Zoo's files where
    the package's loader looks for them (a model ``X.zip`` with ``X/vecnormalize.pkl``)."""
    pytest.importorskip("stable_baselines3")
    from agents.run_folder import VECNORMALIZE_FILE

    defaults = _bench("library_defaults")
    page = (ROOT / "docs" / "integrations.md").read_text(encoding="utf-8")
    assert f"python {' '.join(defaults.ZOO_COMMAND)} -f logs/" in page
    commands: list[list[str]] = []

    def zoo(command: list[str], **kwargs: Any) -> None:  # what RL Zoo writes
        commands.append(command)
        run = Path(command[command.index("-f") + 1]) / "ppo" / "CoopGym-SitToStandHard-v2_1"
        (run / "CoopGym-SitToStandHard-v2").mkdir(parents=True)
        (run / "CoopGym-SitToStandHard-v2.zip").write_bytes(b"model")
        (run / "CoopGym-SitToStandHard-v2" / VECNORMALIZE_FILE).write_bytes(b"statistics")

    monkeypatch.setattr(defaults.subprocess, "run", zoo)
    model = tmp_path / "rl-zoo__3.zip"
    defaults._train_zoo(3, model, None)
    defaults._train_zoo(4, tmp_path / "rl-zoo__4.zip", 4096)
    assert commands[0][1:] == [*defaults.ZOO_COMMAND, "--seed", "3", "-f", str(tmp_path / "rl-zoo__3_logs")]
    assert commands[1][-2:] == ["-n", "4096"]
    assert model.read_bytes() == b"model"
    assert (model.with_suffix("") / VECNORMALIZE_FILE).read_bytes() == b"statistics"


def test_the_never_lift_studys_log_bins_each_training_episode_and_finds_where_lifting_stops() -> None:
    """``training_outcomes``: each episode in the bin of its global step; lifting stops at the first bin of timeouts."""
    defaults = _bench("library_defaults")
    log = [(5, "unsafe"), (9, "success"), (10, "unsafe"), (11, "timeout"), (19, "timeout"), (25, "success")]
    found = defaults.training_outcomes(log, 20, 10)
    assert [(b["to_step"], b["unsafe"], b["success"], b["timeout"]) for b in found["bins"]] == [
        (10, 2, 1, 0),
        (20, 0, 0, 2),
        (30, 0, 1, 0),  # past the budget: SB3 finishes its last rollout
    ]
    assert found["first_success_step"] == 9
    assert found["collapse_step"] == 20
    assert (found["successes_before_collapse"], found["unsafe_before_collapse"]) == (1, 2)
    assert defaults.training_outcomes([(3, "success")], 20, 10)["collapse_step"] is None


def test_the_never_lift_studys_envs_log_outcomes_and_start_mid_guidance_or_as_the_id() -> None:
    """``Logged/...`` plays the id's episodes and logs their outcomes; ``LoggedMidGuidance/...`` starts some
    episodes after the oracle's guidance (never a finished one) and the others exactly as the id."""
    import gymnasium as gym

    _bench("cleanrl_defaults")
    # The module whose registration made the ids (a test may have imported bench/ under another name first).
    cleanrl = sys.modules[gym.spec("Logged/SitToStandHardDiscreteUnit-v2").entry_point.__module__]
    plain = gym.make("CoopGym/SitToStandHardDiscreteUnit-v2")
    logged = gym.make("Logged/SitToStandHardDiscreteUnit-v2")
    cleanrl.clear_outcome_log()
    for env in (plain, logged):
        env.reset(seed=3)
    for step in range(4):
        a, b = plain.step(step * 2), logged.step(step * 2)  # cues, no lift
        assert np.array_equal(a[0], b[0]) and a[1] == b[1]
    assert logged.step(1)[4]["outcome"] == plain.step(1)[4]["outcome"]
    assert [steps for steps, _ in cleanrl.OUTCOME_LOG] == [5]
    mid = gym.make("LoggedMidGuidance/SitToStandHardDiscreteUnit-v2")
    guided = 0
    for seed in range(24):
        observation, info = mid.reset(seed=seed)
        if info["elapsed_s"] == 0.0:
            assert np.array_equal(observation, plain.reset(seed=seed)[0])
        else:
            guided += 1
            assert info["elapsed_s"] <= cleanrl.MID_GUIDANCE_MAX_S and info["outcome"] == "none"
    assert 0 < guided < 24


def test_the_curriculum_plays_the_easy_level_until_its_step_count_then_the_hard_one() -> None:
    """``LoggedCurriculum/...``: episodes of the paper's level, seeded as the hard id's, until the process's learner has
    taken ``CURRICULUM_STEPS`` steps; from the next reset on, exactly the hard id's episodes, their stream seeded by
    the run's first seeded reset."""
    import gymnasium as gym

    _bench("cleanrl_defaults")
    cleanrl = sys.modules[gym.spec("LoggedCurriculum/SitToStandHardDiscreteUnit-v2").entry_point.__module__]
    hard, easy = gym.make("CoopGym/SitToStandHardDiscreteUnit-v2"), gym.make(cleanrl.CURRICULUM_EASY_ENV_ID)
    curriculum = gym.make("LoggedCurriculum/SitToStandHardDiscreteUnit-v2")
    cleanrl.clear_outcome_log()

    def trace(env: Any, seed: int | None) -> list[Any]:
        observation, _ = env.reset(seed=seed)
        return [observation] + [env.step(2 * (k % 9))[:2] for k in range(60)]  # each cue in turn, no lift

    def same(a: list[Any], b: list[Any]) -> bool:
        return all(np.array_equal(np.asarray(x[0]), np.asarray(y[0])) for x, y in zip(a, b, strict=True))

    first = trace(curriculum, 5)
    assert same(first, trace(easy, 5)) and not same(first, trace(hard, 5))
    assert same(trace(curriculum, None), trace(easy, None))  # the easy env's own stream goes on
    cleanrl._STEPS_TAKEN[0] = cleanrl.CURRICULUM_STEPS  # the learner's budget for the easy level is spent
    hard.reset(seed=5)  # the hard level's stream, as the curriculum's first (seeded) reset left it
    assert same(trace(curriculum, None), trace(hard, None))
    assert same(trace(curriculum, 7), trace(hard, 7))
    defaults = _bench("library_defaults")
    assert f"{cleanrl.CURRICULUM_STEPS:,} steps" in defaults.NEVER_LIFT_CELLS["cleanrl-ppo-curriculum"].what
    cleanrl.clear_outcome_log()


def test_a_lift_hazard_policy_lifts_with_its_probability_and_cues_at_random() -> None:
    defaults = _bench("library_defaults")
    observations = np.zeros((4000, 11))
    never = defaults.LiftHazard(0.0).predict(observations)[0]
    always = defaults.LiftHazard(1.0).predict(observations)[0]
    assert set(never % 2) == {0} and set(always % 2) == {1}
    assert set(never // 2) == set(range(9))
    assert abs(np.mean(defaults.LiftHazard(0.5).predict(observations)[0] % 2) - 0.5) < 0.05


def test_across_bodies_reports_each_rows_validation_people_against_the_test_people() -> None:
    """The gap column is the mean over seeds of validation-people minus held-out success, in points."""
    report = _bench("report_learners")
    scripted = {name: {"success_rate": rate} for name, rate in (("oracle", 1.0), ("blind", 0.6), ("belief", 0.85))}

    def run(seed: int, validation: float, held_out: float) -> dict[str, Any]:
        frail = {"frail": {"success_rate": held_out - 0.1}}
        people = {"success_rate": validation}
        return {"training_seed": seed, "success_rate": held_out, "validation_people": people, "by_persona": frail}

    runs = [run(0, 0.9, 0.86), run(1, 0.8, 0.82), run(2, 0.7, 0.80)]
    row = {"what": "a row", "per_seed": runs}
    body = {"env_id": "E", "timesteps": 1000, "episodes": 10, "scripted": scripted, "rows": {"jax-x": row}}
    machine = {"cpu_count": 2, "load_average_1min": 1.0}
    record = {"command": "python bench/learners.py", "date": "2026-12-07", "machine": machine, "results": body}
    assert "No results file yet" in report.across_bodies({})
    page = report.across_bodies({"learners_bodies": record})
    line = next(line for line in page.splitlines() if line.startswith("| `jax-x`"))
    cells = [cell.strip() for cell in line.strip("|").split("|")]
    assert cells[1:3] == ["3", "80.0 %"] and cells[4] == "-2.7" and cells[5] == "80.0 %", cells
    assert cells[6] == "72.7 %" and cells[7] == "1 of 3", cells


def test_the_never_lift_studys_population_and_sb3_curriculum_cells_train_on_what_they_name(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``cleanrl-ppo-population`` trains on ``train_population``; ``sb3-defaults-curriculum`` wraps each of SB3's
    envs in the curriculum from the paper's level on the hard id's interface, its outcomes logged."""
    import gymnasium as gym

    _bench("cleanrl_defaults")
    cleanrl = sys.modules[gym.spec("LoggedPopulation/SitToStandHardDiscreteUnit-v2").entry_point.__module__]
    assert gym.spec("LoggedPopulation/SitToStandHardDiscreteUnit-v2").kwargs["personas"] == "train_population"
    env = gym.make("LoggedPopulation/SitToStandHardDiscreteUnit-v2")
    people = env.unwrapped.personas  # type: ignore[attr-defined]
    assert len(people) == 512 and all(p.name.startswith("population_") for p in people)
    defaults = _bench("library_defaults")
    wrappers: list[Any] = []
    monkeypatch.setattr(defaults, "_train_defaults", lambda seed, path, steps, wrapper: wrappers.append(wrapper))
    monkeypatch.setattr(defaults, "SB3Agent", lambda *args, **kwargs: None)
    monkeypatch.setattr(defaults.PPO, "load", lambda *args, **kwargs: None)
    for cell in ("sb3-defaults", "sb3-defaults-curriculum"):
        defaults._train_cell(cell, 0, 64, None, tmp_path)
    cleanrl = sys.modules["cleanrl_defaults"]  # the module the cells train with
    assert wrappers[0] is cleanrl.OutcomeLog
    wrapped = wrappers[1](gym.make(defaults.HARD_ID))
    assert isinstance(wrapped, cleanrl.OutcomeLog) and isinstance(wrapped.env, cleanrl.Curriculum)
    assert wrapped.env.easy.spec.id == cleanrl.CURRICULUM_EASY_SB3_ENV_ID


def test_a_section_without_its_results_file_names_one_command_that_saves_it(tmp_path) -> None:
    import re

    page = _bench("report").render(tmp_path)  # an empty results folder: every section says what makes it
    lines = re.findall(r"No results file yet: `([^`]*)`", page)
    assert lines, page[:500]
    for command in lines:
        assert command.startswith("python bench/") and len(re.findall(r"(?:^| )--save(?= |$)", command)) == 1, command
