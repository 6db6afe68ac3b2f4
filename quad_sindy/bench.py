"""Speed benchmarks (scripts print numbers; tests never time anything)."""

from __future__ import annotations

import importlib.util
import time
from collections.abc import Callable

import gymnasium as gym
import numpy as np


def _check_seconds(min_seconds: float) -> None:
    """Raises ValueError unless the timing is finite and positive (NaN never ends one)."""
    if not (np.isfinite(min_seconds) and min_seconds > 0):
        raise ValueError(f"the time per measurement must be positive and finite, got {min_seconds}")


def _rate(step: Callable[[], object], min_seconds: float) -> float:
    """Calls ``step`` repeatedly for at least min_seconds; returns calls per second.

    Batches of calls double up to 200 between clock reads, so that a slow step (a peer's
    1024 envs) does not overrun min_seconds by many batches.
    """
    start = time.perf_counter()
    for _ in range(50):  # warm-up, at most a quarter of the time
        step()
        if time.perf_counter() - start > min_seconds / 4:
            break
    calls, batch, start = 0, 1, time.perf_counter()
    while True:
        for _ in range(batch):
            step()
        calls += batch
        elapsed = time.perf_counter() - start
        if elapsed >= min_seconds:
            return calls / elapsed
        batch = min(2 * batch, 200)


def _single_stepper(env_id: str, **kwargs: object) -> tuple[Callable[[], object], int, object]:
    env = gym.make(env_id, **kwargs)
    env.reset(seed=0)
    action = _hover_action(env)

    def step() -> None:
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()

    return step, 1, env


def _vector_stepper(
    env_id: str, num_envs: int, **kwargs: object
) -> tuple[Callable[[], object], int, object]:
    env = gym.make_vec(env_id, num_envs=num_envs, **kwargs)
    env.reset(seed=0)
    actions = np.tile(_hover_action(env, single=True), (num_envs, 1))
    return (lambda: env.step(actions)), num_envs, env


PEER_EXTRA = "pip install 'quad-sindy[peers]'"
"""How to install the peers measured by :func:`bench_envs`."""


def _peer_missing() -> str | None:
    """Why the peer (rotorpy's batched QuadrotorEnv) cannot run here, or None."""
    for module in ("rotorpy", "torchdiffeq"):  # rotorpy's batched env integrates with it
        if importlib.util.find_spec(module) is None:
            return f"{module} not installed ({PEER_EXTRA})"
    return None


def _rotorpy_stepper(num_envs: int) -> tuple[Callable[[], object], int, object]:
    """The peer: rotorpy's ``QuadrotorEnv`` (an SB3 VecEnv of torch-batched Crazyflies).

    Motor-speed commands at each member's hover speed; its default model (motor lag,
    rotor and body drag: ``aero=True``), RK4 at 100 Hz, as our envs' 0.01 s step. torch
    runs on one thread, as our envs do (two threads on a loaded two-core machine ran
    ~20x slower). rotorpy registers ``Quadrotor-v0`` with Gymnasium, but ``gym.make``
    refuses it (not a ``gymnasium.Env``), so the class is made directly.
    """
    import torch
    from rotorpy.learning.quadrotor_environments import QuadrotorEnv
    from rotorpy.vehicles.crazyflie_params import quad_params

    torch.set_num_threads(1)
    n = num_envs
    initial = {
        "x": torch.zeros(n, 3, dtype=torch.float64),
        "v": torch.zeros(n, 3, dtype=torch.float64),
        "q": torch.tensor([0.0, 0.0, 0.0, 1.0], dtype=torch.float64).repeat(n, 1),
        "w": torch.zeros(n, 3, dtype=torch.float64),
        "wind": torch.zeros(n, 3, dtype=torch.float64),
        "rotor_speeds": torch.zeros(n, 4, dtype=torch.float64),
    }
    env = QuadrotorEnv(
        num_envs=n, initial_states=initial, control_mode="cmd_motor_speeds",
        quad_params=dict(quad_params), sim_rate=100, render_mode="None",
    )  # fmt: skip
    env.reset(seed=0)
    hover = env.default_rotor_speed.cpu().numpy().reshape(n, 1)
    low = np.asarray(env.rotor_speed_min, dtype=np.float64).reshape(n, 1)
    high = np.asarray(env.rotor_speed_max, dtype=np.float64).reshape(n, 1)
    actions = np.repeat(2.0 * (hover - low) / (high - low) - 1.0, 4, axis=1)
    return (lambda: env.step(actions)), n, env


def _best_rates(
    steppers: list[tuple[Callable[[], object], int, object]], min_seconds: float, rounds: int
) -> list[float]:
    """Env-steps/s of each stepper: measured in turn, ``rounds`` times, the best kept.

    The machine is shared: alternating the measurements exposes each to the same load
    changes, and the best round is the one least disturbed (as ``timeit`` advises).
    """
    best = [0.0] * len(steppers)
    for _ in range(rounds):
        for i, (step, width, _) in enumerate(steppers):
            best[i] = max(best[i], _rate(step, min_seconds / rounds) * width)
    for _, _, env in steppers:
        env.close()  # type: ignore[attr-defined]
    return best


def single_env_rate(env_id: str, min_seconds: float = 2.0, **kwargs: object) -> float:
    """Steps per second of ``gym.make(env_id)`` under a fixed in-bounds action."""
    _check_seconds(min_seconds)
    return _best_rates([_single_stepper(env_id, **kwargs)], min_seconds, 1)[0]


def vector_env_rate(
    env_id: str, num_envs: int = 1024, min_seconds: float = 2.0, **kwargs: object
) -> float:
    """Env-steps per second of ``gym.make_vec(env_id, num_envs)`` (native vector env)."""
    _check_seconds(min_seconds)
    return _best_rates([_vector_stepper(env_id, num_envs, **kwargs)], min_seconds, 1)[0]


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
    rounds: int = 3,
    peers: bool = True,
) -> list[dict]:
    """Measures Pendulum-v1 and each env id single and vectorised, in one run.

    Args:
        env_ids: Env ids to measure.
        num_envs: Vector env size.
        min_seconds: Minimum timing per measurement.
        effects: Effect settings to measure each env with (``None``: the paper vehicle;
            ``"all"``: every effect on, observation noise and 10 % parameter randomisation).
        rounds: Every measurement is taken this many times in turn (``min_seconds`` each
            in all), the best kept (see :func:`_best_rates`).
        peers: Also measure rotorpy's ``QuadrotorEnv`` with 1 and ``num_envs`` members
            (:func:`_rotorpy_stepper`) where it is installed (the ``peers`` extra).

    Returns:
        Rows ``env, mode, effects, steps_per_s, ratio`` (ratio to Pendulum-v1's single rate);
        a peer that cannot run gives a row with only ``note``.
    """
    _check_seconds(min_seconds)
    labels = [("Pendulum-v1", "single", "-")]
    steppers = [_single_stepper("Pendulum-v1")]
    for env_id in env_ids:
        for spec in effects:
            kwargs: dict = {}
            if spec is not None:
                kwargs = {"effects": spec, "obs_noise_std": 0.01, "param_randomization": 0.1}
            label = "none" if spec is None else str(spec)
            labels.append((env_id, "single", label))
            steppers.append(_single_stepper(env_id, **kwargs))
            labels.append((env_id, f"vector x{num_envs}", label))
            steppers.append(_vector_stepper(env_id, num_envs, **kwargs))
    missing = _peer_missing() if peers else None
    if peers and missing is None:
        for width in (1, num_envs):
            labels.append(("rotorpy", f"vector x{width}", "aero"))
            steppers.append(_rotorpy_stepper(width))
    rates = _best_rates(steppers, min_seconds * rounds, rounds)
    rows = [
        {"env": env, "mode": mode, "effects": eff, "steps_per_s": rate, "ratio": rate / rates[0]}
        for (env, mode, eff), rate in zip(labels, rates, strict=True)
    ]
    if missing is not None:
        rows.append({"note": f"(peer rotorpy skipped: {missing})"})
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
    _check_seconds(min_seconds)
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
    truth, registered, numpy_rhs, compiled, vec_truth, vec_registered = _best_rates(
        [
            _single_stepper("PlanarQuad-v0"),
            _single_stepper("PlanarQuadSINDy-v0", model=model),
            _single_stepper("PlanarQuad-v0", rhs=model.rhs),
            _single_stepper("PlanarQuad-v0", rhs=compiled_rhs(model)),
            _vector_stepper("PlanarQuad-v0", 1024),
            _vector_stepper("PlanarQuadSINDy-v0", 1024, model=model),
        ],
        3 * min_seconds,
        3,
    )
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
