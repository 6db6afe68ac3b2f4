"""Closed-loop simulation: controller + saturation + RK4 on a reference trajectory.

This reproduces the authors' loop (``simulate_SINDy.m``): at each t_k the reference is
sampled, the controller computes the command from the state, the dynamics integrate one RK4
step with the (saturated) command held over the step.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quad_envs.integrators import rk4_step
from quad_envs.params import check_can_hover
from quad_envs.trajectories import Reference, make_trajectory
from quad_envs.types import FloatArray
from quad_envs.vehicles import Controller, Vehicle, get_vehicle


@dataclass
class ClosedLoopRun:
    """Result of :func:`simulate_closed_loop`; arrays indexed by sample k = 0..N-1.

    Attributes:
        t: Times t_k [s], shape (N,).
        states: x(t_k), shape (N, n).
        commanded: Controller output at t_k (what the authors record), shape (N, m).
        applied: Saturated input held over [t_k, t_k+1), shape (N, m).
        refs: Reference at t_k, shape (N, r).
        vehicle: The simulated vehicle.
    """

    t: FloatArray
    states: FloatArray
    commanded: FloatArray
    applied: FloatArray
    refs: FloatArray
    vehicle: Vehicle

    def table(self) -> tuple[list[str], FloatArray]:
        """Header and rows ``t, states, applied inputs, references, commanded inputs``.

        The input columns carry the input names (``u1, u2``): they are what the vehicle
        applied, the inputs an identification must see. The first columns follow the
        authors' CSV layout; the commanded inputs (what the authors record; they differ from
        the applied ones where the rotors saturate) come last as ``u1_cmd, u2_cmd``.
        """
        veh = self.vehicle
        commanded = [f"{name}_cmd" for name in veh.input_names]
        header = ["t", *veh.state_names, *veh.input_names, *veh.ref_names, *commanded]
        return header, np.column_stack(
            [self.t, self.states, self.applied, self.refs, self.commanded]
        )


def simulate_closed_loop(
    vehicle: Vehicle,
    trajectory: Reference,
    controller: Controller | None = None,
    dt: float = 0.01,
    duration: float = 10.0,
    x0: FloatArray | None = None,
    substeps: int = 1,
) -> ClosedLoopRun:
    """Flies ``vehicle`` along ``trajectory`` under ``controller`` (the authors' RK4 loop).

    Args:
        vehicle: The vehicle (its ``rhs`` may be an identified model's: see
            ``dataclasses.replace(vehicle, dynamics=...)``).
        trajectory: Reference; its dimension must match the vehicle's.
        controller: Maps (state, ref) to the commanded input; the vehicle's own by default.
        dt: Control (and sample) period [s].
        duration: Final time [s]; samples at k dt for k = 0..round(duration/dt).
        x0: Initial state; at rest on the reference by default.
        substeps: RK4 substeps per control period.

    Returns:
        The sampled run.
    """
    if dt <= 0 or duration <= 0:
        raise ValueError(f"dt and duration must be positive, got dt={dt}, duration={duration}")
    if trajectory.ndim != vehicle.ndim:
        raise ValueError(
            f"{vehicle.name} needs a {vehicle.ndim}-D trajectory, got {trajectory.ndim}-D"
        )
    controller = controller or vehicle.default_controller()
    n = int(round(duration / dt)) + 1
    t = np.arange(n) * dt
    refs = trajectory(t)
    x = vehicle.initial_state(refs[0]) if x0 is None else np.asarray(x0, dtype=np.float64)
    states = np.empty((n, vehicle.n_states))
    commanded = np.empty((n, vehicle.n_inputs))
    applied = np.empty_like(commanded)
    for k in range(n):
        states[k] = x
        commanded[k] = controller(x, refs[k])
        applied[k] = vehicle.saturate(commanded[k])
        x = rk4_step(vehicle.rhs, x, applied[k], dt, substeps)
    return ClosedLoopRun(t, states, commanded, applied, refs, vehicle)


def simulate_case(
    case: str, vehicle: str | Vehicle = "planar", dt: float = 0.01, duration: float = 10.0
) -> ClosedLoopRun:
    """Simulates one of the paper's cases (``A``, ``B``, ``C``) or any named trajectory.

    Raises:
        ValueError: The vehicle cannot hover (its rotors' largest thrust does not exceed its
            weight): no controller can fly the reference, and the run would be a fall.
    """
    veh = get_vehicle(vehicle) if isinstance(vehicle, str) else vehicle
    check_can_hover(veh.params)
    traj = make_trajectory(case, ndim=veh.ndim, rng=np.random.default_rng(0))
    return simulate_closed_loop(veh, traj, dt=dt, duration=duration)
