"""Ground truth and surrogate side by side under the same policy and initial state."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import quad_envs  # noqa: F401 (registers the ids)
from identification.experiments.evaluate import rmse_per_state
from identification.model import IdentifiedModel
from identification.surrogate import make_surrogate


@dataclass
class EnvComparison:
    """States of the truth and the surrogate env, step by step.

    Attributes:
        t: Times [s].
        truth: Ground-truth states (N, n).
        surrogate: Surrogate states (N, n) (NaN after it terminated).
        state_names: Names of the states.
        rmse: RMSE per state over the common steps.
        divergence_time: First time the states part by more than ``tolerance`` (None: never).
        tolerance: Max-abs state difference that counts as parting.
    """

    t: np.ndarray
    truth: np.ndarray
    surrogate: np.ndarray
    state_names: tuple[str, ...]
    rmse: dict[str, float]
    divergence_time: float | None
    tolerance: float


def _rollout(
    env: gym.Env, policy: Callable, seed: int, options: dict | None, steps: int
) -> np.ndarray:
    obs, info = env.reset(seed=seed, options=options)
    states = [info["state"]]
    for _ in range(steps):
        obs, _, terminated, truncated, info = env.step(policy(obs, info))
        states.append(info["state"])
        if terminated or truncated:
            break
    return np.array(states)


def compare_envs(
    model: IdentifiedModel,
    env_id: str,
    make_policy: Callable[[], Callable[[np.ndarray, dict[str, Any]], np.ndarray]],
    trajectory: str = "hover",
    seed: int = 0,
    steps: int = 1000,
    tolerance: float = 1e-3,
    env_kwargs: dict[str, Any] | None = None,
    truth_kwargs: dict[str, Any] | None = None,
) -> EnvComparison:
    """Flies a policy in ``env_id`` and in the surrogate of ``model`` from the same start.

    ``make_policy`` is called once per env, so a stochastic policy draws the same action
    noise in both (a shared policy object would continue its random stream instead).
    ``env_kwargs`` go to both envs, ``truth_kwargs`` to the ground truth only (its
    ``effects``: a model identified on drag data holds the drag itself).
    """
    kwargs = {"trajectory": trajectory, **(env_kwargs or {})}
    truth_env = gym.make(env_id, **kwargs, **(truth_kwargs or {}))
    surrogate_env = gym.wrappers.TimeLimit(
        make_surrogate(model, env_id, **kwargs), truth_env.spec.max_episode_steps
    )
    truth = _rollout(truth_env, make_policy(), seed, None, steps)
    with np.errstate(all="ignore"):
        surrogate = _rollout(surrogate_env, make_policy(), seed, None, steps)
    n = min(len(truth), len(surrogate))
    padded = np.full_like(truth, np.nan)
    padded[:n] = surrogate[:n]
    diff = np.abs(padded - truth)  # rows after the surrogate's episode ended: NaN (parted)
    gap = np.where(
        np.isnan(diff).all(axis=1), np.nan, np.nanmax(np.nan_to_num(diff, nan=-1.0), axis=1)
    )
    parted = np.flatnonzero(~(gap <= tolerance))
    dt = truth_env.unwrapped.dt
    return EnvComparison(
        t=np.arange(len(truth)) * dt,
        truth=truth,
        surrogate=padded,
        state_names=truth_env.unwrapped.vehicle.state_names,
        rmse=rmse_per_state(surrogate[:n], truth[:n], truth_env.unwrapped.vehicle.state_names),
        divergence_time=float(parted[0] * dt) if parted.size else None,
        tolerance=tolerance,
    )


def write_comparison(comp: EnvComparison, out: str | Path, title: str = "") -> dict[str, Any]:
    """Absolute-error plot, states CSV and summary JSON into ``out``."""
    from identification.experiments.plots import save_figure, state_grid
    from quad_envs.fileio import write_csv, write_json

    out = Path(out)
    names = comp.state_names
    fig, axes = state_grid(names)
    err = np.abs(comp.surrogate - comp.truth)
    for i, (ax, name) in enumerate(zip(axes, names, strict=False)):
        ax.semilogy(comp.t, np.maximum(err[:, i], 1e-18))
        ax.axhline(comp.tolerance, color="tab:red", lw=0.8, ls="--")
        ax.set_ylabel(f"|error| {name}")
    fig.suptitle(title or "|surrogate - ground truth|, same policy and initial state")
    save_figure(fig, out / "abs_error.png")
    header = ["t", *[f"{n}_truth" for n in names], *[f"{n}_surrogate" for n in names]]
    write_csv(out / "states.csv", header, np.column_stack([comp.t, comp.truth, comp.surrogate]))
    summary = {
        "rmse": comp.rmse,
        "divergence_time": comp.divergence_time,
        "tolerance": comp.tolerance,
        "steps": len(comp.t) - 1,
    }
    write_json(out / "summary.json", summary)
    return summary
