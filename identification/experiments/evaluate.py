"""Model against ground truth: closed-loop replays, RMSE per state, divergence time."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from identification.model import IdentifiedModel
from quad_envs.simulate import ClosedLoopRun, simulate_closed_loop
from quad_envs.trajectories import Reference, make_trajectory
from quad_envs.vehicles import get_vehicle


def rmse_per_state(a: np.ndarray, b: np.ndarray, names: Sequence[str]) -> dict[str, float]:
    """Root-mean-square difference of each column (inf where either is non-finite)."""
    diff = a - b
    out = {}
    for i, name in enumerate(names):
        col = diff[:, i]
        out[name] = float(np.sqrt(np.mean(col**2))) if np.isfinite(col).all() else float("inf")
    return out


@dataclass
class ClosedLoopComparison:
    """The same controller and reference flown by the truth and by the model."""

    truth: ClosedLoopRun
    model: ClosedLoopRun
    rmse: dict[str, float]

    @property
    def abs_error(self) -> np.ndarray:
        """|model - truth| over time, shape (N, n)."""
        return np.abs(self.model.states - self.truth.states)


def simulate_model_closed_loop(
    model: IdentifiedModel,
    reference: Reference,
    controller: Callable | None = None,
    dt: float = 0.01,
    duration: float = 10.0,
    x0: np.ndarray | None = None,
) -> ClosedLoopRun:
    """Flies the model under a controller (its system's PD by default), with saturation."""
    if model.system is None:
        raise ValueError("closed-loop simulation needs a model of a known system (system=...)")
    vehicle = replace(get_vehicle(model.system), dynamics=lambda x, u, _params: model.rhs(x, u))
    return simulate_closed_loop(vehicle, reference, controller, dt, duration, x0)


def compare_closed_loop(
    model: IdentifiedModel, reference: Reference | str, dt: float = 0.01, duration: float = 10.0
) -> ClosedLoopComparison:
    """Flies ``reference`` with the system's PD on the truth and on the model (the paper's test)."""
    if model.system is None:
        raise ValueError("closed-loop comparison needs a model of a known system")
    vehicle = get_vehicle(model.system)
    if isinstance(reference, str):
        reference = make_trajectory(reference, ndim=vehicle.ndim, rng=np.random.default_rng(0))
    truth = simulate_closed_loop(vehicle, reference, dt=dt, duration=duration)
    with np.errstate(all="ignore"):
        flown = simulate_model_closed_loop(model, reference, dt=dt, duration=duration)
    return ClosedLoopComparison(
        truth, flown, rmse_per_state(flown.states, truth.states, vehicle.state_names)
    )


def normalized_score(comparisons: Sequence[ClosedLoopComparison]) -> float:
    """Mean over runs and states of RMSE / std(truth state): a scale-free validation error."""
    values = []
    for comp in comparisons:
        scale = comp.truth.states.std(axis=0)
        scale[scale == 0] = 1.0
        for i, name in enumerate(comp.truth.vehicle.state_names):
            values.append(comp.rmse[name] / scale[i])
    return float(np.mean(values))


def validation_references(system: str, count: int = 2, seed: int = 1234) -> list[Reference]:
    """Held-out references for lambda selection: smooth random waypoint flights."""
    ndim = get_vehicle(system).ndim
    rng = np.random.default_rng(seed)
    return [make_trajectory("random", ndim=ndim, rng=rng) for _ in range(count)]
