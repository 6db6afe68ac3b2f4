"""Dyna-style model-based RL with SINDy surrogates (the SINDy-RL loop).

1. Collect a little real data with smooth random (Ornstein-Uhlenbeck) exploration.
2. Identify a SINDy model (RK4-consistent regression) from all real data so far.
3. Train the policy (PPO or SAC, continued across iterations) in the surrogate env.
4. Evaluate it on the ground truth; collect on-policy real data; go to 2.

Real-environment interactions counted are the steps used as training data; evaluation
episodes are reported separately, as in SINDy-RL. The baseline is the same algorithm
trained model-free on the ground truth, with its learning curve over real steps.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym

from agents.policies import OrnsteinUhlenbeckPolicy, SB3Policy
from agents.train import HOVER_TASK, evaluate, make_algo, train
from identification.data import Trajectory
from identification.fit import FitConfig, fit
from identification.libraries import default_library
from identification.rollouts import collect_rollouts
from identification.surrogate import make_surrogate
from quad_envs.fileio import write_json

ENV_ID = "PlanarQuad-v0"


def _collect(policy: Any, steps: int, seed: int) -> list[Trajectory]:
    """Episodes of ``policy`` on the real env until ``steps`` transitions are recorded."""
    trajs, total, ep = [], 0, 0
    while total < steps:
        new = collect_rollouts(
            ENV_ID, policy, 1, seed + ep, max_steps=max(steps - total, 10), env_kwargs=HOVER_TASK
        )
        ep += 1
        for tr in new:
            trajs.append(tr)
            total += len(tr) - 1  # transitions
        if ep > 10 * steps:
            raise RuntimeError("could not collect real data (every episode ended at once)")
    return trajs


def run_mbrl(
    out: str | Path,
    algo: str = "ppo",
    iterations: int = 4,
    initial_real_steps: int = 2000,
    real_steps_per_iteration: int = 1000,
    model_steps_per_iteration: int = 50_000,
    baseline_steps: int = 200_000,
    seed: int = 0,
    progress: bool = True,
) -> dict[str, Any]:
    """Runs the loop and the model-free baseline; writes ``mbrl.json`` and ``mbrl.png``.

    Results are written after every iteration, so an interrupted run keeps what it did.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    env = gym.make(ENV_ID, **HOVER_TASK)
    data = _collect(OrnsteinUhlenbeckPolicy(env, seed), initial_real_steps, seed)
    real_steps = sum(len(t) - 1 for t in data)
    lib = default_library("planar")
    agent = None
    history: list[dict[str, Any]] = []
    results: dict[str, Any] = {"algo": algo, "task": HOVER_TASK, "mbrl": history}
    for it in range(iterations):
        model = fit(data, lib, FitConfig(lam=1e-3), "planar")
        model.save(out / f"model_iter{it}.json")
        surrogate = gym.wrappers.TimeLimit(make_surrogate(model, ENV_ID, **HOVER_TASK), 1000)
        if agent is None:
            agent = make_algo(algo, surrogate, seed)
        else:
            agent.set_env(surrogate)
        agent.learn(model_steps_per_iteration, reset_num_timesteps=False, progress_bar=progress)
        mean, std = evaluate(SB3Policy(agent), ENV_ID, **HOVER_TASK)
        history.append(
            {
                "iteration": it,
                "real_steps": real_steps,
                "model_steps": (it + 1) * model_steps_per_iteration,
                "return_mean": mean,
                "return_std": std,
                "model_terms": model.n_terms,
            }
        )
        write_json(out / "mbrl.json", results)
        new = _collect(
            SB3Policy(agent, deterministic=False), real_steps_per_iteration, seed + 1000 * (it + 1)
        )
        data += new
        real_steps += sum(len(t) - 1 for t in new)
    agent.save(out / "mbrl_agent.zip")

    baseline = train(
        ENV_ID,
        algo,
        baseline_steps,
        out / "model_free",
        seed,
        eval_every=max(baseline_steps // 10, 1000),
        progress=progress,
    )
    results["model_free"] = [
        {"real_steps": s, "return_mean": m, "return_std": sd} for s, m, sd in baseline["curve"]
    ]
    final_mf = baseline["final_return"]
    best_mb = max(history, key=lambda h: h["return_mean"])
    # Real steps the model-based loop needed to reach 95 % of the model-free final return.
    reached = [h for h in history if h["return_mean"] >= 0.95 * final_mf]
    results["summary"] = {
        "model_free_final_return": final_mf,
        "model_free_real_steps": baseline_steps,
        "mbrl_best_return": best_mb["return_mean"],
        "mbrl_real_steps_to_95pct": reached[0]["real_steps"] if reached else None,
        "sample_efficiency": baseline_steps / reached[0]["real_steps"] if reached else None,
    }
    write_json(out / "mbrl.json", results)
    _plot(results, out / "mbrl.png")
    return results


def _plot(results: dict[str, Any], path: Path) -> None:
    from identification.experiments.plots import pyplot, save_figure

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 4.2))
    mb, mf = results["mbrl"], results["model_free"]
    ax.plot(
        [h["real_steps"] for h in mb],
        [h["return_mean"] for h in mb],
        "o-",
        label="SINDy model-based",
    )
    ax.plot(
        [h["real_steps"] for h in mf],
        [h["return_mean"] for h in mf],
        "s-",
        label=f"model-free {results['algo'].upper()}",
    )
    ax.set_xscale("log")
    ax.set_xlabel("real environment steps")
    ax.set_ylabel("ground-truth return (hover task)")
    ax.grid(alpha=0.3)
    ax.legend()
    save_figure(fig, path)
