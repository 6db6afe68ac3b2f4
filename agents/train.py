"""stable-baselines3 training and evaluation on any registered id (truth or surrogate)."""

from __future__ import annotations

import json
import os
import zipfile
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import identification  # noqa: F401 (registers the surrogate ids)
from agents.tasks import HOVER_TASK, task_kwargs
from quad_envs.fileio import file_mode, write_csv, write_json

ALGOS = ("ppo", "sac")
__all__ = ["ALGOS", "HOVER_TASK", "check_seed", "evaluate", "load_agent", "make_algo", "train"]


def make_algo(algo: str, env: gym.Env, seed: int = 0, **kwargs: Any) -> Any:
    """A fresh PPO or SAC with small MLPs suited to these low-dimensional tasks."""
    from stable_baselines3 import PPO, SAC

    if algo not in ALGOS:
        raise ValueError(f"unknown algorithm {algo!r}; valid choices: {', '.join(ALGOS)}")
    if algo == "ppo":
        defaults = {
            "n_steps": 1024,
            "batch_size": 256,
            "learning_rate": 3e-4,
            "gamma": 0.99,
            "policy_kwargs": {"net_arch": [64, 64]},
        }
        model = PPO("MlpPolicy", env, seed=seed, verbose=0, device="cpu", **{**defaults, **kwargs})
    else:
        defaults = {"learning_starts": 1000, "policy_kwargs": {"net_arch": [64, 64]}}
        model = SAC("MlpPolicy", env, seed=seed, verbose=0, device="cpu", **{**defaults, **kwargs})
    return quiet_logger(model)


def quiet_logger(model: Any) -> Any:
    """Gives ``model`` a logger that writes nothing.

    Without a logger of its own, every ``learn()`` of a quiet stable-baselines3 model creates
    an empty ``SB3-<date>`` folder in the system's temporary directory (the default logger's
    folder, which it makes even when it writes nothing): hundreds of them after a study.
    """
    from stable_baselines3.common.logger import Logger

    if model.tensorboard_log is None:
        model.set_logger(Logger(folder=None, output_formats=[]))
    return model


def _positive(**values: int) -> None:
    for name, value in values.items():
        if int(value) != value or value < 1:
            raise ValueError(f"{name} must be a positive integer, got {value!r}")


MAX_SEED = 2**32 - 1
"""Largest seed numpy's and stable-baselines3's seeding takes."""


def check_seed(seed: int, name: str = "seed") -> None:
    """Raises ValueError unless ``seed`` is a whole number in [0, :data:`MAX_SEED`]."""
    if (
        isinstance(seed, bool)
        or not isinstance(seed, int | np.integer)
        or not 0 <= seed <= MAX_SEED
    ):
        raise ValueError(f"{name} must be an integer from 0 to 2**32 - 1, got {seed!r}")


def saved_algo(path: str | Path) -> str:
    """The algorithm (``ppo`` or ``sac``) of a model saved by stable-baselines3.

    Raises:
        ValueError: The file is missing or not a stable-baselines3 PPO/SAC archive.
    """
    path = Path(path)
    if path.is_dir():
        raise ValueError(f"{path} is a folder; give the agent's .zip (a train --out folder "
                         "holds model.zip)")  # fmt: skip
    if not path.is_file():
        raise ValueError(f"no such agent file: {path}")
    try:
        with zipfile.ZipFile(path) as archive:
            data = json.loads(archive.read("data"))
    except (zipfile.BadZipFile, KeyError, json.JSONDecodeError, UnicodeDecodeError):
        raise ValueError(f"{path} is not a saved stable-baselines3 agent") from None
    if "clip_range" in data:
        return "ppo"
    if "target_entropy" in data or "tau" in data:
        return "sac"
    raise ValueError(f"{path} holds an agent of an algorithm other than {', '.join(ALGOS)}")


def load_agent(path: str | Path, algo: str | None = None) -> Any:
    """Loads a saved PPO or SAC agent; ``algo`` (if given) must match what the file holds."""
    from stable_baselines3 import PPO, SAC

    found = saved_algo(path)
    if algo is not None and algo != found:
        raise ValueError(f"{path} holds a {found.upper()} agent, not {algo.upper()}")
    return quiet_logger((PPO if found == "ppo" else SAC).load(path, device="cpu"))


def _save(model: Any, path: Path) -> None:
    """Saves an agent atomically (a killed run leaves no half file).

    Its permissions are those of the other outputs (0666 less the umask, as
    :mod:`quad_envs.fileio` writes them), not a fixed mode.
    """
    partial = path.with_name(f".{path.stem}.partial.zip")
    model.save(partial)
    partial.chmod(file_mode())
    os.replace(partial, path)


def _resume(out: Path, config: dict[str, Any], env: gym.Env) -> tuple[Any, list]:
    """The agent and curve of an earlier run of ``config`` in ``out``, or (None, []).

    An unfinished run resumes from its last checkpoint (SAC without its replay buffer); a
    finished one is loaded, and trained on only when the step budget grew (its agent is not
    trained again from scratch and overwritten).

    Raises:
        ValueError: ``out`` holds a run of another configuration.
    """
    record_path = out / RUN_RECORD
    if not record_path.exists():
        return None, []
    try:
        saved = json.loads(record_path.read_text())
    except (OSError, json.JSONDecodeError):
        return None, []
    if not isinstance(saved, dict) or "seed" not in saved:
        return None, []  # a record of an older version: train afresh
    # the step budget may grow: a finished run trains on to the new budget
    same = {k: canonical(saved.get(k)) == canonical(v) for k, v in config.items()}
    differ = sorted(k for k, ok in same.items() if not ok and k != "steps")
    if differ:
        named = "; ".join(f"{k}: {saved.get(k)!r} there, {config[k]!r} here" for k in differ)
        raise ValueError(f"{out} holds a training run of another configuration ({named}); "
                         "use a new --out")  # fmt: skip
    source = out / ("model.zip" if saved.get("done") else CHECKPOINT)
    if not source.exists():
        return None, []
    model = load_agent(source, config["algo"])
    model.set_env(env)
    curve_path = out / "learning_curve.csv"
    lines = curve_path.read_text().splitlines() if curve_path.exists() else []
    rows = []
    for number, line in enumerate(lines[1:], start=2):
        try:
            rows.append([float(v) for v in line.split(",")] if line.strip() else [])
        except ValueError:
            raise ValueError(f"{curve_path} line {number} is not a row of numbers ({line!r}): "
                             "repair it, or use a new --out") from None  # fmt: skip
    curve = [(int(r[0]), r[1], r[2]) for r in rows
             if len(r) == 3 and np.isfinite(r[0]) and r[0] <= model.num_timesteps]  # fmt: skip
    return model, curve


def make_env(env_id: str, **env_kwargs: Any) -> gym.Env:
    """``gym.make`` for a quadrotor env or surrogate, with a one-line error for any other id.

    The tasks' options (normalised actions, a reference) are quadrotor-env options: another
    env (``CartPole-v1``) ended in a TypeError traceback.
    """
    try:
        return gym.make(env_id, **env_kwargs)
    except TypeError:
        raise ValueError(
            f"{env_id} does not take the task's options ({', '.join(env_kwargs)}): the tasks "
            "fly the quadrotor envs and their surrogates (PlanarQuad-v0, Quad6DOF-v0, "
            "PlanarQuadSINDy-v0, ...)"
        ) from None


def evaluate(
    policy: Any, env_id: str, episodes: int = 5, seed: int = 10_000, **env_kwargs: Any
) -> tuple[float, float]:
    """Mean and std of the return of ``policy(obs, info)`` over seeded episodes."""
    _positive(episodes=episodes)
    env = make_env(env_id, **env_kwargs)
    returns = []
    for ep in range(episodes):
        obs, info = env.reset(seed=seed + ep)
        total, done = 0.0, False
        while not done:
            obs, reward, terminated, truncated, info = env.step(policy(obs, info))
            total += float(reward)
            done = terminated or truncated
        returns.append(total)
    env.close()
    return float(np.mean(returns)), float(np.std(returns))


RUN_RECORD = "run.json"
"""Written beside a trained agent: its configuration (env id, algorithm, task, seed, steps,
evaluation settings, env options), the steps taken and whether the run is done."""

CHECKPOINT = "checkpoint.zip"
"""The agent at the last evaluation of an unfinished run: a rerun resumes from it."""


def canonical(value: Any) -> Any:
    """JSON values with numeric strings as numbers (``"4e-3"`` and ``0.004`` compare equal)."""
    if isinstance(value, dict):
        return {k: canonical(v) for k, v in value.items()}
    if isinstance(value, list):
        return [canonical(v) for v in value]
    if isinstance(value, str):
        try:
            return float(value)
        except ValueError:
            return value
    return value


def train(
    env_id: str,
    algo: str,
    steps: int,
    out: str | Path,
    seed: int = 0,
    eval_every: int = 10_000,
    eval_episodes: int = 5,
    env_kwargs: dict[str, Any] | None = None,
    progress: bool = True,
    task: str = "hover",
) -> dict[str, Any]:
    """Trains on ``env_id`` with periodic evaluation; saves the model and the learning curve.

    The env gets the options of ``task`` (:data:`agents.tasks.TASKS`) updated with
    ``env_kwargs``; evaluation runs on the same id with the same options.

    Returns:
        Summary with the final evaluation return and the curve.
    """
    import torch
    from stable_baselines3.common.callbacks import BaseCallback

    from agents.policies import SB3Policy

    _positive(steps=steps, eval_every=eval_every, eval_episodes=eval_episodes)
    check_seed(seed)  # before the output folder is made
    # SB3's small networks run fastest on one thread (SAC, 1500 steps on 2 cores: 16.2 s with
    # torch's default threads, 8.7 s on one; the same curve); TORCH_NUM_THREADS overrides
    torch.set_num_threads(int(os.environ.get("TORCH_NUM_THREADS", "1")))
    kwargs = task_kwargs(task, **(env_kwargs or {}))
    env = make_env(env_id, **kwargs)  # before the output folder: a bad id leaves nothing
    out = Path(out)
    config = {"env": env_id, "algo": algo, "task": task, "seed": seed, "steps": steps,
              "eval_every": eval_every, "eval_episodes": eval_episodes,
              "options": json.loads(json.dumps(env_kwargs or {}, default=str))}  # fmt: skip
    model, curve = _resume(out, config, env)
    if model is None:
        out.mkdir(parents=True, exist_ok=True)
        model, curve = make_algo(algo, env, seed), []
        write_json(out / RUN_RECORD, {**config, "steps_taken": 0, "done": False})
    header = ["steps", "return_mean", "return_std"]

    class Evaluate(BaseCallback):
        def _on_step(self) -> bool:
            if self.num_timesteps % eval_every == 0:
                mean, std = evaluate(SB3Policy(self.model), env_id, eval_episodes, **kwargs)
                curve.append((self.num_timesteps, mean, std))
                write_csv(out / "learning_curve.csv", header, np.array(curve))
                _save(self.model, out / CHECKPOINT)  # a killed run resumes from here
                write_json(out / RUN_RECORD, {**config, "steps_taken": self.num_timesteps,
                                              "done": False})  # fmt: skip
            return True

    started = int(model.num_timesteps)
    remaining = steps - started
    if remaining > 0:
        model.learn(total_timesteps=remaining, callback=Evaluate(), progress_bar=progress,
                    reset_num_timesteps=int(model.num_timesteps) == 0)  # fmt: skip
    mean, std = evaluate(SB3Policy(model), env_id, eval_episodes, **kwargs)
    # the steps taken, not asked for: PPO rounds up to whole rollouts (100 asked, 1024 taken:
    # a trial's sample-efficiency ratio was 10 times off); one row per step count
    done = int(model.num_timesteps)
    if curve and curve[-1][0] == done:
        curve[-1] = (done, mean, std)
    else:
        curve.append((done, mean, std))
    write_csv(out / "learning_curve.csv", header, np.array(curve))
    _save(model, out / "model.zip")
    # what the agent was trained on, for `evaluate` to compare with, and that it is done
    write_json(out / RUN_RECORD, {**config, "steps_taken": done, "done": True})
    (out / CHECKPOINT).unlink(missing_ok=True)
    return {"final_return": mean, "final_std": std, "curve": curve,
            "model": str(out / "model.zip"), "resumed_at": started}  # fmt: skip
