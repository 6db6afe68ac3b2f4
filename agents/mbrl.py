"""Dyna-style model-based RL with SINDy surrogates (the SINDy-RL loop), over seeds.

One seed of the SINDy loop:

1. Collect a little real data with smooth random (Ornstein-Uhlenbeck) exploration.
2. Identify a SINDy model from all real data so far with the data-alone selection, or an
   ensemble of bagged models (E-SINDy): the policy then trains on the median model or on a
   member drawn per episode, and imagined episodes end where the members disagree.
3. Train the policy (PPO or SAC, continued across iterations) in the surrogate env.
4. Evaluate it on the ground truth; collect on-policy real data; go to 2.

Real-environment interactions counted are the steps used as training data; evaluation
episodes are reported separately, as in SINDy-RL. The baseline is the same algorithm trained
model-free on the ground truth. The sample-efficiency figure of a seed is the ratio of the
real steps each method needs to first reach 95 % of that seed's model-free final return;
across seeds it is reported as a geometric mean with a 95 % interval.

Every (method, seed) pair is an independent job (:func:`agents.parallel.run_jobs`: in
process or on Ray, same results), saved as it finishes, so an interrupted experiment resumes.
"""

from __future__ import annotations

import dataclasses
import json
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from agents.parallel import ray_available, run_jobs
from agents.policies import OrnsteinUhlenbeckPolicy, SB3Policy
from agents.tasks import task_kwargs
from agents.train import ALGOS, canonical, evaluate, make_algo, make_env, train
from identification.data import IdentificationWarning, Trajectory
from identification.fit import FitConfig, fit
from identification.libraries import default_library
from identification.model import IdentifiedModel
from identification.rollouts import RECORDS, collect_rollouts
from identification.selection import select_model
from identification.surrogate import ENSEMBLE_MODES, make_ensemble_surrogate
from quad_envs.fileio import write_json

METHODS = ("sindy", "model_free")


@dataclass(frozen=True)
class MBRLConfig:
    """One model-based RL experiment.

    Attributes:
        env_id: Ground-truth env id (its vehicle names the model's variables).
        task: Task name (:data:`agents.tasks.TASKS`).
        algo: ``ppo`` or ``sac``.
        iterations: Model-based iterations per seed.
        initial_real_steps: Random exploration steps before the first model.
        real_steps_per_iteration: On-policy real steps collected after each iteration.
        model_steps_per_iteration: Policy training steps in the surrogate per iteration.
        baseline_steps: Real steps of the model-free baseline.
        baseline_evals: Evaluations along the baseline's learning curve.
        eval_episodes: Ground-truth episodes per evaluation.
        ensemble: Bagged models (1: a single model).
        ensemble_mode: ``median`` or ``sample`` (a member per imagined episode).
        disagreement: Truncate imagined episodes whose one-step member spread (in units of
            each state's standard deviation in the data) exceeds this (None: never).
        env_options: Options of the ground truth (vehicle, params, effects). The surrogate
            gets the task options and the vehicle's (its action limits and trim: the model
            is its only physics), never the effects.
        data: What the real rollouts record for identification: ``truth`` (the true state
            and the applied input, as a simulator gives them) or ``measured`` (the state the
            sensors report, with the truth's noise, bias and delay, and the commanded input,
            as a real flight log holds them).
    """

    env_id: str = "PlanarQuad-v0"
    task: str = "hover"
    algo: str = "ppo"
    iterations: int = 4
    initial_real_steps: int = 2000
    real_steps_per_iteration: int = 1000
    model_steps_per_iteration: int = 50_000
    baseline_steps: int = 200_000
    baseline_evals: int = 10
    eval_episodes: int = 5
    ensemble: int = 1
    ensemble_mode: str = "median"
    disagreement: float | None = 0.1
    env_options: dict[str, Any] = field(default_factory=dict)
    data: str = "truth"

    def __post_init__(self) -> None:
        if self.data not in RECORDS:
            raise ValueError(f"unknown data {self.data!r}; valid choices: {RECORDS}")
        if self.algo not in ALGOS:
            raise ValueError(f"unknown algorithm {self.algo!r}; valid choices: {ALGOS}")
        if self.ensemble_mode not in ENSEMBLE_MODES:
            raise ValueError(f"unknown ensemble mode {self.ensemble_mode!r}: {ENSEMBLE_MODES}")
        task_kwargs(self.task)  # raises on an unknown task
        if self.disagreement is not None and not (
            np.isfinite(self.disagreement) and self.disagreement >= 0
        ):
            raise ValueError(
                f"disagreement must be a finite number >= 0 (None: never truncate), "
                f"got {self.disagreement!r}"
            )
        counts = ("iterations", "initial_real_steps", "real_steps_per_iteration",
                  "model_steps_per_iteration", "baseline_steps", "baseline_evals",
                  "eval_episodes", "ensemble")  # fmt: skip
        for name in counts:
            value = getattr(self, name)
            if int(value) != value or value < 1:
                raise ValueError(f"{name} must be a positive integer, got {value!r}")

    @property
    def truth_kwargs(self) -> dict[str, Any]:
        """Options of the ground-truth env: the task and the truth's own physics."""
        return task_kwargs(self.task, **self.env_options)

    @property
    def surrogate_kwargs(self) -> dict[str, Any]:
        """Options of the surrogate env: the task and the vehicle's limits (not the effects)."""
        vehicle = {k: v for k, v in self.env_options.items() if k in ("vehicle", "params")}
        return task_kwargs(self.task, **vehicle)


def _collect(config: MBRLConfig, policy: Any, steps: int, seed: int) -> list[Trajectory]:
    """Episodes of ``policy`` on the ground truth until ``steps`` transitions are recorded."""
    trajs, total, episode = [], 0, 0
    while total < steps:
        # the surrogate steps the rigid body: a rotor lag is model error here
        new = collect_rollouts(
            config.env_id, policy, 1, seed + episode, max_steps=max(steps - total, 10),
            env_kwargs=config.truth_kwargs, record=config.data, rotor_states=False,
        )  # fmt: skip
        episode += 1
        for traj in new:
            trajs.append(traj)
            total += len(traj) - 1  # transitions
        if episode > 10 * steps:
            raise RuntimeError("could not collect real data (every episode ended at once)")
    return trajs


def identify(
    data: list[Trajectory], library: list[str], config: MBRLConfig, seed: int
) -> list[IdentifiedModel]:
    """The model (or the bagged ensemble) identified from the real data so far.

    The sparsity and the integral window are chosen from the data alone
    (:func:`identification.selection.select_model`: cross-validated multi-step prediction);
    with ``config.ensemble > 1`` that configuration is refitted on bootstrap resamples of
    100-step segments (E-SINDy bagging), member 0 being the selected model itself.
    """
    with warnings.catch_warnings():  # refitted every iteration: the loop reports its scores
        warnings.simplefilter("ignore", IdentificationWarning)
        model, _ = select_model(data, library, n_models=0, seed=seed)
    models = [model]
    if config.ensemble == 1:
        return models
    chosen = FitConfig(optimizer="stlsq", lam=model.meta["lambda"], window=model.meta["window"])
    segments = [t.slice(i, min(i + 101, len(t))) for t in data for i in range(0, len(t) - 20, 100)]
    rng = np.random.default_rng(seed)
    for _ in range(10 * config.ensemble):
        if len(models) == config.ensemble:
            break
        picks = rng.integers(len(segments), size=len(segments))
        try:
            models.append(fit([segments[i] for i in picks], model.feature_names, chosen))
        except (ValueError, np.linalg.LinAlgError):
            continue  # a resample that cannot determine the model is drawn again
    return models


def _state_scale(data: list[Trajectory]) -> np.ndarray:
    scale = np.concatenate([t.x for t in data]).std(axis=0)
    return np.where(scale > 0, scale, 1.0)


def sindy_job(config: MBRLConfig, seed: int, out: str | None = None) -> dict[str, Any]:
    """One seed of the SINDy model-based loop; returns its learning curve over real steps.

    With ``out``, the last iteration's identified model(s) and the agent trained on them are
    kept in ``out/sindy_seed{seed}/`` (``model.json`` or ``model_K.json``, ``agent.zip``):
    the surrogate and the policy can be reused, as the baseline's ``model.zip`` can.
    """
    import torch

    torch.set_num_threads(1)  # same floating-point results in process and on Ray workers
    truth = gym.make(config.env_id, **config.truth_kwargs)
    vehicle = truth.unwrapped.vehicle
    library = default_library(vehicle.name)
    data = _collect(config, OrnsteinUhlenbeckPolicy(truth, seed), config.initial_real_steps, seed)
    real_steps = sum(len(t) - 1 for t in data)
    agent, curve = None, []
    for iteration in range(config.iterations):
        models = identify(data, library, config, seed + iteration)
        surrogate = gym.wrappers.TimeLimit(
            make_ensemble_surrogate(
                models, config.env_id, config.ensemble_mode,
                config.disagreement if config.ensemble > 1 else None, _state_scale(data),
                **config.surrogate_kwargs,
            ),
            truth.spec.max_episode_steps or 1000,
        )  # fmt: skip
        if agent is None:
            agent = make_algo(config.algo, surrogate, seed)  # seeds the surrogate too
        else:
            agent.set_env(surrogate)
            # A new env is unseeded: its first reset would draw the start from OS entropy.
            agent.env.seed(seed + 7919 * iteration)
        agent.learn(config.model_steps_per_iteration, reset_num_timesteps=False)
        mean, std = evaluate(
            SB3Policy(agent), config.env_id, config.eval_episodes, **config.truth_kwargs
        )
        curve.append(
            {
                "iteration": iteration,
                "real_steps": real_steps,
                "model_steps": (iteration + 1) * config.model_steps_per_iteration,
                "return_mean": mean,
                "return_std": std,
                "model_terms": surrogate.unwrapped.model.n_terms,
            }
        )
        if iteration + 1 < config.iterations:
            policy = SB3Policy(agent, deterministic=False)
            steps, collect_seed = config.real_steps_per_iteration, seed + 1000 * (iteration + 1)
            new = _collect(config, policy, steps, collect_seed)
            data += new
            real_steps += sum(len(t) - 1 for t in new)
    if out is not None:
        folder = Path(out) / f"sindy_seed{seed}"
        folder.mkdir(parents=True, exist_ok=True)
        for k, member in enumerate(models):
            member.save(folder / ("model.json" if len(models) == 1 else f"model_{k}.json"))
        agent.save(folder / "agent.zip")
    return {"method": "sindy", "seed": seed, "curve": curve}


def model_free_job(config: MBRLConfig, seed: int, out: str) -> dict[str, Any]:
    """One seed of the model-free baseline on the ground truth; returns its learning curve."""
    import torch

    torch.set_num_threads(1)
    eval_every = max(config.baseline_steps // config.baseline_evals, 1)
    result = train(
        config.env_id, config.algo, config.baseline_steps, Path(out) / f"model_free_seed{seed}",
        seed, eval_every, config.eval_episodes, env_kwargs=config.truth_kwargs, progress=False,
        task=config.task,
    )  # fmt: skip
    curve = [{"real_steps": s, "return_mean": m, "return_std": sd} for s, m, sd in result["curve"]]
    return {"method": "model_free", "seed": seed, "curve": curve}


def run_job(method: str, config: MBRLConfig, seed: int, out: str) -> dict[str, Any]:
    """One (method, seed) job of an experiment: ``sindy`` or ``model_free``.

    BLAS and OpenMP run on one thread inside a job, as on a Ray worker (Ray sets
    ``OMP_NUM_THREADS=1``): a multi-threaded BLAS sums in another order, and the same seed
    then gives other floating-point results in process than on Ray.
    """
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1):
        if method == "sindy":
            return sindy_job(config, seed, out)
        return model_free_job(config, seed, out)


def steps_to_reach(curve: list[dict[str, Any]], target: float) -> int | None:
    """Real steps at the first point of ``curve`` whose return reaches ``target``."""
    for point in curve:
        if point["return_mean"] >= target:
            return int(point["real_steps"])
    return None


def interval(values: list[float], log: bool = False) -> dict[str, float | None]:
    """Mean and 95 % Student-t interval (geometric with ``log``); None entries for n < 2."""
    from scipy import stats

    a = np.log(values) if log else np.asarray(values, dtype=float)
    if a.size == 0:
        return {"mean": None, "low": None, "high": None, "n": 0}
    mean = float(a.mean())
    half = (
        float(stats.t.ppf(0.975, a.size - 1) * a.std(ddof=1) / np.sqrt(a.size))
        if a.size > 1
        else None
    )
    back = np.exp if log else (lambda v: v)
    return {
        "mean": float(back(mean)),
        "low": float(back(mean - half)) if half is not None else None,
        "high": float(back(mean + half)) if half is not None else None,
        "n": int(a.size),
    }


def summarize(runs: dict[str, dict[int, dict[str, Any]]], seeds: list[int]) -> dict[str, Any]:
    """Per-seed sample efficiency and its interval over seeds."""
    per_seed = []
    for seed in seeds:
        free, sindy = runs["model_free"][seed]["curve"], runs["sindy"][seed]["curve"]
        target = 0.95 * free[-1]["return_mean"]
        free_steps, sindy_steps = steps_to_reach(free, target), steps_to_reach(sindy, target)
        per_seed.append(
            {
                "seed": seed,
                "model_free_final_return": free[-1]["return_mean"],
                "target_return": target,
                "model_free_steps": free_steps,
                "sindy_steps": sindy_steps,
                "sindy_best_return": max(p["return_mean"] for p in sindy),
                "ratio": free_steps / sindy_steps if sindy_steps else None,
                "ratio_to_budget": free[-1]["real_steps"] / sindy_steps if sindy_steps else None,
            }
        )
    ratios = [s["ratio"] for s in per_seed if s["ratio"] is not None]
    budget = [s["ratio_to_budget"] for s in per_seed if s["ratio_to_budget"] is not None]
    return {
        "seeds": per_seed,
        "reached": len(ratios),
        "missed": len(per_seed) - len(ratios),
        "sample_efficiency": interval(ratios, log=True),
        "sample_efficiency_vs_budget": interval(budget, log=True),
        "model_free_final_return": interval([s["model_free_final_return"] for s in per_seed]),
        "sindy_best_return": interval([s["sindy_best_return"] for s in per_seed]),
    }


def run_experiment(
    config: MBRLConfig,
    out: str | Path,
    seeds: int | list[int] = 5,
    workers: int = 1,
    address: str | None = None,
    echo: Any = print,
) -> dict[str, Any]:
    """Runs the SINDy loop and the model-free baseline for every seed; writes ``mbrl.json``.

    Each finished (method, seed) job is saved in ``out/runs/`` at once; a rerun with the same
    configuration loads those and runs only what is missing.

    Returns:
        The results: configuration, every curve, and the summary over seeds.
    """
    out = Path(out)
    seed_list = list(range(seeds)) if isinstance(seeds, int) else [int(s) for s in seeds]
    if not seed_list:
        raise ValueError("need at least one seed")
    if int(workers) != workers or workers < 1:
        raise ValueError(f"workers must be a positive integer, got {workers!r}")
    if workers > 1 and not ray_available():  # before anything is written
        raise ValueError("parallel runs need Ray: pip install 'quad-sindy[ray]' (or --workers 1)")
    # the ground truth must be a quadrotor env taking the task: checked before config.json
    # is written (a failed start left a folder that refused the next, valid run)
    make_env(config.env_id, **config.truth_kwargs).close()
    runs_dir = out / "runs"
    settings = {**dataclasses.asdict(config), "seeds": seed_list}
    config_path = out / "config.json"
    if config_path.exists():
        # seeds are jobs of their own: a rerun may add or leave out seeds; the rest must match
        # as values (params "4e-3" and "0.004" are one vehicle)
        # a setting added since that run was saved held its default value there
        defaults = dataclasses.asdict(MBRLConfig())
        what, fix = "an experiment configuration", "use a new --out"
        saved = _read_json(config_path, what, fix)
        if not isinstance(saved, dict):
            raise ValueError(f"{config_path} is not {what} (not a JSON object): {fix}")
        saved = canonical({**defaults, **saved})
        now = canonical(json.loads(json.dumps(settings)))
        differ = sorted(k for k in {*saved, *now} - {"seeds"} if saved.get(k) != now.get(k))
        if differ:
            named = "; ".join(f"{k}: {saved.get(k)!r} there, {now.get(k)!r} here" for k in differ)
            raise ValueError(f"{out} holds an experiment with another configuration ({named}); "
                             "use a new --out")  # fmt: skip
    runs: dict[str, dict[int, dict[str, Any]]] = {m: {} for m in METHODS}
    todo = []
    for method in METHODS:
        for seed in seed_list:
            path = runs_dir / f"{method}_seed{seed}.json"
            if path.exists():
                runs[method][seed] = _finished_run(path)
            else:
                todo.append((method, config, seed, str(runs_dir)))
    write_json(config_path, settings)
    echo(f"{len(todo)} jobs to run, {2 * len(seed_list) - len(todo)} loaded from {runs_dir}")

    def save(index: int, result: dict[str, Any]) -> None:
        method, _, seed, _ = todo[index]
        write_json(runs_dir / f"{method}_seed{seed}.json", result)
        runs[method][seed] = result
        echo(f"done: {method} seed {seed}")

    started = time.perf_counter()
    run_jobs(run_job, todo, workers, address, on_done=save)
    wall = time.perf_counter() - started
    # each session's jobs and time, so a resume keeps what the earlier runs took
    sessions = _sessions(out / "mbrl.json")
    sessions.append({"jobs": len(todo), "workers": workers, "wall_seconds": wall})
    results = {
        "config": settings,
        "runs": runs,
        "summary": summarize(runs, seed_list),
        "run": {
            "jobs": sum(r["jobs"] for r in sessions),
            "workers": workers,
            "wall_seconds": sum(r["wall_seconds"] for r in sessions),
        },  # fmt: skip
        "sessions": sessions,
    }
    write_json(out / "mbrl.json", results)
    plot_curves(results, out / "mbrl.png")
    return results


def _read_json(path: Path, what: str, fix: str) -> Any:
    """The JSON in ``path``, or a ValueError naming the file (empty, truncated, not text)."""
    try:
        return json.loads(path.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        reason = "it is empty" if not path.stat().st_size else f"not JSON: {exc}"
        raise ValueError(f"{path} is not {what} ({reason}): {fix}") from None


def _finished_run(path: Path) -> dict[str, Any]:
    """A saved job's result; a ValueError naming the file if it is not a finished run."""
    fix = "remove it to rerun that job"
    run = _read_json(path, "a finished run record", fix)
    curve = run.get("curve") if isinstance(run, dict) else None
    if not isinstance(curve, list) or not curve:
        raise ValueError(f"{path} is not a finished run record (no 'curve'): {fix}")
    for point in curve:
        values = [point.get(k) if isinstance(point, dict) else None for k in CURVE_KEYS]
        if not all(isinstance(v, int | float) and not isinstance(v, bool) for v in values):
            raise ValueError(
                f"{path} is not a finished run record (a 'curve' point without the numbers "
                f"{' and '.join(CURVE_KEYS)}: {point!r}): {fix}"
            )
    return run


CURVE_KEYS = ("real_steps", "return_mean")
"""What every point of a job's learning curve holds (the summary and the plot read them)."""


def _sessions(previous: Path) -> list[dict[str, Any]]:
    """The sessions (jobs, workers, wall time) recorded in an earlier ``mbrl.json``.

    ``mbrl.json`` is an output, written anew at the end: an unreadable one loses only the
    earlier sessions' times.
    """
    try:
        before = json.loads(previous.read_text()) if previous.exists() else {}
    except (UnicodeDecodeError, json.JSONDecodeError):
        before = {}
    if not isinstance(before, dict):
        return []
    sessions = before.get("sessions", [before["run"]] if "run" in before else [])
    if not isinstance(sessions, list):
        return []
    numbers = (int, float)
    return [s for s in sessions if isinstance(s, dict) and isinstance(s.get("jobs"), numbers)
            and isinstance(s.get("wall_seconds"), numbers)]  # fmt: skip


def plot_curves(results: dict[str, Any], path: Path) -> None:
    """Ground-truth return against real steps: mean over seeds with a 95 % band per method."""
    from identification.experiments.plots import pyplot, save_figure

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 4.2))
    labels = {"sindy": "SINDy model-based", "model_free": f"model-free {results['config']['algo']}"}
    for method, marker in (("sindy", "o-"), ("model_free", "s-")):
        curves = list(results["runs"][method].values())
        length = min(len(c["curve"]) for c in curves)
        steps = np.mean([[p["real_steps"] for p in c["curve"][:length]] for c in curves], axis=0)
        returns = np.array([[p["return_mean"] for p in c["curve"][:length]] for c in curves])
        mean = returns.mean(axis=0)
        ax.plot(steps, mean, marker, label=f"{labels[method]} ({len(curves)} seeds)")
        if len(curves) > 1:
            from scipy import stats

            half = stats.t.ppf(0.975, len(curves) - 1) * returns.std(axis=0, ddof=1)
            half /= np.sqrt(len(curves))
            ax.fill_between(steps, mean - half, mean + half, alpha=0.2)
    ax.set_xscale("log")
    ax.set_xlabel("real environment steps")
    ax.set_ylabel(f"ground-truth return ({results['config']['task']})")
    ax.grid(alpha=0.3)
    ax.legend()
    save_figure(fig, path)
