"""How well each estimator reads the mind on a level, under a caregiver's cue sequence.

``python -m agents.caregivers.reading --policy prober --episodes 2000`` plays the caregiver's first
episode in each of ``episodes`` seeded envs of ``--env`` (default ``CoopGym/SitToStandHard-v2``;
held-out personas) and, on the very same substep readings and cues, runs side by side:

* ``kalman`` -- the paper's filter (the env's own): its MAP mode is the thresholded estimate
  ``xi_hat`` (``+-0.3``, the paper's band); its ``P(xi = +1)`` is ``P(xi > 0.5)`` under
  ``N(xi_hat, xi_std^2)``;
* ``imm`` -- :class:`estimator.multiple_model.IMMEstimator` on the persona's nominal model;
* ``switching`` -- :class:`estimator.particle.SwitchingParticleFilter` on nominal people
  (``estimator="switching"``, what the agent observes);
* ``switching_true`` -- the same filter given each episode's TRUE person: the bound of a
  caregiver who knew the person.

It reports, per estimator: the per-step balanced accuracy of the MAP mode (the mean of the
three per-mode recalls), the expected calibration error of ``P(xi = +1)`` (10 equal bins),
and accuracy against the time since a words-only "lean forward" began (words playing, no push,
after a step with a push or silence -- with a 1 s utterance, the prober's probe is the tail of its
recruiting words once the push stops): how soon the answer to a probe is read. ``--png PREFIX``
writes the reliability diagram and the latency curve.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Annotated, Any

import gymnasium as gym
import numpy as np
import tyro
from numpy.typing import NDArray
from scipy.special import erfc

import coop_gym  # noqa: F401  (registers the ids)
from agents.caregivers.scripted import make_scripted
from coop_gym.cli import BadArgs, exit_status, parse
from coop_gym.envs.switching import SwitchingEstimator, SwitchingOptions
from coop_gym.registration import HARD_ENV_ID
from estimator.multiple_model import IMMEstimator

__all__ = ["ESTIMATORS", "PROG", "Args", "collect", "main", "summarise"]

ESTIMATORS = ("kalman", "imm", "switching", "switching_true")
LAGS_S = tuple(round(0.1 * k, 1) for k in range(0, 31))
"""Times since a words-only probe's onset at which the latency curve is read [s]."""
MIN_STEPS_PER_LAG = 100
"""Fewer steps at a lag than this leave the curve's point out (NaN): past a caregiver's probe window
only the odd episode is still probing, and its few steps would draw a spike."""
_BINS = 10
DEFAULT_ENV_ID = HARD_ENV_ID


def _kalman_probabilities(xi_hat: NDArray[np.float64], xi_std: NDArray[np.float64]) -> NDArray[np.float64]:
    # The paper's filter keeps xi continuous: its mode is the thresholded estimate, its P(+1) the tail above 0.5.
    std = np.maximum(xi_std, 1e-9)
    return 0.5 * erfc((0.5 - xi_hat) / (std * math.sqrt(2.0)))


def collect(
    policy: str, episodes: int, env_id: str = DEFAULT_ENV_ID, personas: str = "test", seed: int = 0
) -> dict[str, Any]:
    """Play the first episode of ``episodes`` envs (seeds ``seed + k``) and record every estimator per step."""
    venv: Any = gym.make_vec(
        env_id, num_envs=episodes, vectorization_mode="vector_entry_point", personas=personas, estimator="switching"
    )
    core = venv.unwrapped.core
    features = venv.unwrapped.features
    level = gym.spec(env_id).kwargs.get("difficulty")  # the env's level (None: the -v0 model)
    agent = make_scripted(policy, features=features, level=level)
    obs, _ = venv.reset(seed=[seed + k for k in range(episodes)])
    n = episodes
    imm = IMMEstimator(core.nominal.copy(), core.report[:, 0].copy())
    truth_filter = SwitchingEstimator(
        n, core.timing, core.realism, core.params, core.rngs, SwitchingOptions(difficulty=level, true_person=True)
    )
    truth_filter.reset(np.arange(n), core.report[:, 0].copy())
    col = {f: features.index(f) for f in features}
    live = np.ones(n, dtype=bool)
    rows: dict[str, list[NDArray[np.float64]]] = {k: [] for k in ("true_xi", "live", "probe_age", *ESTIMATORS)}
    p_up: dict[str, list[NDArray[np.float64]]] = {k: [] for k in ESTIMATORS}
    probe_onset = np.full(n, -np.inf)
    was_words_alone = np.zeros(n, dtype=bool)
    now = 0.0
    state = None
    for _ in range(10_000):
        actions, state = agent.predict(obs, state)
        obs, _, terminated, truncated, info = venv.step(actions)
        now += core.timing.action_period_s
        # A probe: "lean forward" with no push, where the last step had a push or silence.
        words_alone = (core._bank_verbal[:, 0] > 0.5) & (core._bank_force.max(axis=1) < 2.0)
        began = words_alone & ~was_words_alone
        probe_onset[began] = now - core.timing.action_period_s
        probe_onset[~words_alone & (core._bank_force.max(axis=1) >= 2.0)] = -np.inf  # a push ends the probe
        was_words_alone = words_alone
        probs_imm = imm.run(core._bank_force, core._bank_verbal, core._bank_position)[:, -1]
        probs_true = truth_filter.run(core._bank_force, core._bank_verbal, core._bank_position)[:, -1]
        xi_hat, xi_std = obs[:, col["xi_hat"]].astype(np.float64), obs[:, col["xi_std"]].astype(np.float64)
        probs_switching = obs[:, [col["p_uncooperative"], col["p_unresponsive"], col["p_cooperative"]]]
        rows["true_xi"].append(np.asarray(info["true_xi"], dtype=np.float64))
        rows["live"].append(live.copy())
        rows["probe_age"].append(now - probe_onset)
        rows["kalman"].append(np.where(xi_hat >= 0.3, 1.0, np.where(xi_hat <= -0.3, -1.0, 0.0)))
        p_up["kalman"].append(_kalman_probabilities(xi_hat, xi_std))
        for name, probs in (("imm", probs_imm), ("switching", probs_switching), ("switching_true", probs_true)):
            rows[name].append(np.argmax(probs, axis=1) - 1.0)
            p_up[name].append(np.asarray(probs[:, 2], dtype=np.float64))
        live &= ~(terminated | truncated)
        if not live.any():
            break
    venv.close()
    data = {k: np.array(v) for k, v in rows.items()}
    data.update({f"p_up_{k}": np.array(v) for k, v in p_up.items()})
    return data


def summarise(data: dict[str, Any]) -> dict[str, Any]:
    """Balanced accuracy, ECE, reliability bins and the latency curve of every estimator."""
    live = data["live"]
    truth = data["true_xi"][live]
    probe_age = data["probe_age"][live]
    out: dict[str, Any] = {}
    for name in ESTIMATORS:
        mode = data[name][live]
        recalls = [float(np.mean(mode[truth == k] == k)) for k in (-1.0, 0.0, 1.0) if np.any(truth == k)]
        p = data[f"p_up_{name}"][live]
        cooperative = truth == 1.0
        bins = np.minimum((p * _BINS).astype(int), _BINS - 1)
        reliability = []
        ece = 0.0
        for b in range(_BINS):
            sel = bins == b
            if sel.any():
                gap = abs(p[sel].mean() - cooperative[sel].mean())
                ece += gap * sel.mean()
                reliability.append((b, float(p[sel].mean()), float(cooperative[sel].mean()), int(sel.sum())))
        latency = []
        for lag in LAGS_S:
            sel = np.abs(probe_age - lag - 0.1) < 0.05  # the step that ends lag s after the onset
            enough = sel.sum() >= MIN_STEPS_PER_LAG
            latency.append(float(np.mean(mode[sel] == truth[sel])) if enough else math.nan)
        out[name] = {
            "balanced_accuracy": float(np.mean(recalls)),
            "recall_by_mode": recalls,
            "ece": float(ece),
            "reliability": reliability,
            "latency_accuracy": latency,
        }
    out["steps"] = int(live.sum())
    out["lags_s"] = list(LAGS_S)
    return out


def _plot(summary: dict[str, Any], prefix: str, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(4.5, 4.5))
    ax.plot([0, 1], [0, 1], color="grey", lw=0.8, ls="--")
    for name in ESTIMATORS:
        rel = summary[name]["reliability"]
        ax.plot([r[1] for r in rel], [r[2] for r in rel], marker="o", label=f"{name} (ECE {summary[name]['ece']:.3f})")
    ax.set(xlabel="predicted P(xi = +1)", ylabel="observed frequency of xi = +1", title=f"Reliability, {title}")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(f"{prefix}_reliability.png", dpi=110)
    fig, ax = plt.subplots(figsize=(6, 4))
    for name in ESTIMATORS:
        ax.plot(summary["lags_s"], summary[name]["latency_accuracy"], label=name)
    ax.set(xlabel="time since a words-only 'lean forward' began [s]", ylabel="accuracy of the MAP mode",
           title=f"Reading a probe's answer, {title}")  # fmt: skip
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(f"{prefix}_latency.png", dpi=110)


PROG = "python -m agents.caregivers.reading"


@dataclass
class Args:
    """The command line's arguments; each field's docstring is its ``--help``."""

    policy: str = "prober"
    """the scripted caregiver whose cues are played"""
    env: str = DEFAULT_ENV_ID
    """a registered id"""
    episodes: int = 2000
    """episodes, one seeded env each"""
    personas: str = "test"
    """the personas played: train, test, all, a name or names joined by ','"""
    seed: int = 0
    """seed of the first env (env k uses seed + k)"""
    json_out: str | None = None
    """write the summary to this JSON file"""
    png: Annotated[str | None, tyro.conf.arg(metavar="PREFIX")] = None
    """write PREFIX_reliability.png and PREFIX_latency.png"""

    def __post_init__(self) -> None:
        """A count no run can use is a usage error naming the flag."""
        if self.episodes < 1:
            raise BadArgs(f"--episodes must be positive, got {self.episodes}")


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: see the module docstring."""
    args = parse(Args, argv, PROG, __doc__.splitlines()[0])
    summary = summarise(collect(args.policy, args.episodes, args.env, args.personas, args.seed))
    steps = summary["steps"]
    print(f"{args.env}, {args.policy} cues, {args.episodes} episodes, {steps} steps ({args.personas} personas)")
    print(f"{'estimator':<16}{'balanced acc':>14}{'recall -1/0/+1':>22}{'ECE P(+1)':>11}{'acc@0.5s':>10}{'acc@1s':>8}")
    for name in ESTIMATORS:
        s = summary[name]
        recalls = "/".join(f"{r:.2f}" for r in s["recall_by_mode"])
        lat = s["latency_accuracy"]
        print(f"{name:<16}{s['balanced_accuracy']:>14.3f}{recalls:>22}{s['ece']:>11.3f}{lat[5]:>10.3f}{lat[10]:>8.3f}")
    if args.json_out:
        with open(args.json_out, "w") as fh:
            json.dump(summary, fh, indent=1)
    if args.png:
        _plot(summary, args.png, f"{args.policy} cues, {args.env.removeprefix('CoopGym/')}")
    return 0


if __name__ == "__main__":
    raise SystemExit(exit_status(main))
