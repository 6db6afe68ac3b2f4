"""Speed benchmarks (scripts print numbers; tests never time anything)."""

from __future__ import annotations

import time
from collections.abc import Callable

import gymnasium as gym
import numpy as np


def _rate(step: Callable[[], object], min_seconds: float) -> float:
    """Calls ``step`` repeatedly for at least min_seconds; returns calls per second."""
    for _ in range(50):  # warm-up
        step()
    calls, start = 0, time.perf_counter()
    while True:
        for _ in range(200):
            step()
        calls += 200
        elapsed = time.perf_counter() - start
        if elapsed >= min_seconds:
            return calls / elapsed


def single_env_rate(env_id: str, min_seconds: float = 2.0, **kwargs: object) -> float:
    """Steps per second of ``gym.make(env_id)`` under a fixed in-bounds action."""
    env = gym.make(env_id, **kwargs)
    env.reset(seed=0)
    action = _hover_action(env)

    def step() -> None:
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()

    rate = _rate(step, min_seconds)
    env.close()
    return rate


def vector_env_rate(
    env_id: str, num_envs: int = 1024, min_seconds: float = 2.0, **kwargs: object
) -> float:
    """Env-steps per second of ``gym.make_vec(env_id, num_envs)`` (native vector env)."""
    env = gym.make_vec(env_id, num_envs=num_envs, **kwargs)
    env.reset(seed=0)
    actions = np.tile(_hover_action(env, single=True), (num_envs, 1))
    rate = _rate(lambda: env.step(actions), min_seconds) * num_envs
    env.close()
    return rate


def _hover_action(env: object, single: bool = False) -> np.ndarray:
    space = env.single_action_space if single else env.action_space  # type: ignore[attr-defined]
    params = getattr(env.unwrapped, "params", None)  # type: ignore[attr-defined]
    if params is None or getattr(env.unwrapped, "normalize_actions", True):  # type: ignore[attr-defined]
        return np.clip(np.zeros(space.shape), space.low, space.high)
    action = np.zeros(space.shape)
    action[0] = params.hover_thrust
    return action


def bench_envs(
    env_ids: tuple[str, ...],
    num_envs: int = 1024,
    min_seconds: float = 2.0,
    effects: tuple[object, ...] = (None, "all"),
) -> list[dict]:
    """Measures Pendulum-v1 and each env id single and vectorised, in one run.

    Args:
        env_ids: Env ids to measure.
        num_envs: Vector env size.
        min_seconds: Minimum timing per measurement.
        effects: Effect settings to measure each env with (``None``: the paper vehicle;
            ``"all"``: every effect on, observation noise and 10 % parameter randomisation).

    Returns:
        Rows ``env, mode, effects, steps_per_s, ratio`` (ratio to Pendulum-v1's single rate:
        the median of its measurements before each env and at the end; the first row's
        ``range`` holds their lowest and highest).
    """
    # The machine is shared: Pendulum is measured before each env and at the end, and the
    # median is the reference, so that a load change during the run moves it less.
    references = []
    rows = []
    for env_id in env_ids:
        references.append(single_env_rate("Pendulum-v1", min_seconds / 2))
        for spec in effects:
            kwargs: dict = {}
            if spec is not None:
                kwargs = {"effects": spec, "obs_noise_std": 0.01, "param_randomization": 0.1}
            label = "none" if spec is None else str(spec)
            single = single_env_rate(env_id, min_seconds, **kwargs)
            vec = vector_env_rate(env_id, num_envs, min_seconds, **kwargs)
            rows.append({"env": env_id, "mode": "single", "effects": label, "steps_per_s": single})
            rows.append(
                {"env": env_id, "mode": f"vector x{num_envs}", "effects": label, "steps_per_s": vec}
            )
    references.append(single_env_rate("Pendulum-v1", min_seconds / 2))
    pendulum = float(np.median(references))
    rows.insert(
        0,
        {
            "env": "Pendulum-v1",
            "mode": f"single, med{len(references)}",
            "effects": "-",
            "steps_per_s": pendulum,
            "range": (min(references), max(references)),
        },
    )
    for row in rows:
        row["ratio"] = row["steps_per_s"] / pendulum
    return rows


def bench_surrogate(min_seconds: float = 2.0) -> list[dict]:
    """Steps/s of the ground truth and of surrogates of it, in one run.

    The model is the exact planar model (what ``reproduce`` identifies) in our library:
    ``PlanarQuadSINDy-v0`` as registered (the model compiled by numba into the env's kernel,
    :mod:`identification.compiled`; single and x1024), the model's numpy ``rhs`` integrated
    by ``rk4_step``, and a pysindy-``predict`` surrogate (a fitted ``ps.SINDy`` called once
    per RK4 stage). The last row is the time ``gym.make`` of the surrogate took first in
    this process (numba compiles a new model once per machine, then loads its cache).
    """
    import pysindy as ps

    from identification.compiled import compiled_rhs
    from identification.data import Trajectory
    from identification.experiments.truth import model_from_truth
    from identification.libraries import paper_planar_library
    from quad_envs.simulate import simulate_case

    model = model_from_truth("planar")
    run = simulate_case("C")
    data = Trajectory.from_run(run)
    sindy = ps.SINDy(optimizer=ps.STLSQ(threshold=0.1), feature_library=paper_planar_library())
    sindy.fit(data.x, t=data.dt, u=data.u, feature_names=[*data.state_names, *data.input_names])

    def predict_rhs(x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return np.asarray(sindy.predict(np.atleast_2d(x), u=np.atleast_2d(u))).reshape(x.shape)

    start = time.perf_counter()
    gym.make("PlanarQuadSINDy-v0", model=model).close()  # compiles, or loads numba's cache
    ready = time.perf_counter() - start
    truth = single_env_rate("PlanarQuad-v0", min_seconds)
    registered = single_env_rate("PlanarQuadSINDy-v0", min_seconds, model=model)
    vec_truth = vector_env_rate("PlanarQuad-v0", 1024, min_seconds)
    vec_registered = vector_env_rate("PlanarQuadSINDy-v0", 1024, min_seconds, model=model)
    numpy_rhs = single_env_rate("PlanarQuad-v0", min_seconds, rhs=model.rhs)
    compiled = single_env_rate("PlanarQuad-v0", min_seconds, rhs=compiled_rhs(model))
    slow = single_env_rate("PlanarQuad-v0", min_seconds / 4, rhs=predict_rhs)
    return [
        {"env": "PlanarQuad-v0 (ground truth)", "steps_per_s": truth, "ratio": 1.0},
        {
            "env": "PlanarQuadSINDy-v0 (registered)",
            "steps_per_s": registered,
            "ratio": registered / truth,
        },
        {"env": "PlanarQuad-v0 x1024 (truth)", "steps_per_s": vec_truth, "ratio": 1.0},
        {
            "env": "PlanarQuadSINDy-v0 x1024",
            "steps_per_s": vec_registered,
            "ratio": vec_registered / vec_truth,
        },
        {"env": "surrogate, numpy rhs", "steps_per_s": numpy_rhs, "ratio": numpy_rhs / truth},
        {"env": "surrogate, compiled_rhs", "steps_per_s": compiled, "ratio": compiled / truth},
        {"env": "surrogate via pysindy predict", "steps_per_s": slow, "ratio": slow / truth},
        {"env": "compiled / predict", "steps_per_s": float("nan"), "ratio": compiled / slow},
        {
            "env": f"(its first gym.make took {ready:.1f} s)",
            "steps_per_s": float("nan"),
            "ratio": float("nan"),
        },
    ]
