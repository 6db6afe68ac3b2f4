"""Closed-loop simulation: controller + saturation + RK4 on a reference trajectory.

This reproduces the authors' loop (``simulate_SINDy.m``): at each t_k the reference is
sampled, the controller computes the command from the state, the dynamics integrate one RK4
step with the (saturated) command held over the step.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial

import numpy as np

from quad_envs import dynamics
from quad_envs.controllers import PlanarPD, Quad6DOFPD
from quad_envs.integrators import rk4_step
from quad_envs.params import PAPER_6DOF, PAPER_PLANAR, PlanarQuadParams, Quad6DOFParams
from quad_envs.trajectories import (
    PLANAR_REF_NAMES,
    SPATIAL_REF_NAMES,
    Reference,
    make_trajectory,
)
from quad_envs.types import FloatArray

Controller = Callable[[FloatArray, FloatArray], FloatArray]


@dataclass(frozen=True)
class System:
    """A vehicle: its rhs, its saturation and the names of its variables."""

    name: str
    params: PlanarQuadParams | Quad6DOFParams
    rhs: Callable[[FloatArray, FloatArray], FloatArray]
    saturate: Callable[[FloatArray], FloatArray]
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    angle_indices: tuple[int, ...]
    ref_names: tuple[str, ...]
    traj_ndim: int = field(default=2)

    @property
    def n_states(self) -> int:
        """Number of states."""
        return len(self.state_names)

    @property
    def n_inputs(self) -> int:
        """Number of inputs."""
        return len(self.input_names)

    def initial_state(self, ref0: FloatArray) -> FloatArray:
        """State at rest on the reference: its position and velocity, level attitude."""
        x0 = np.zeros(self.n_states)
        if self.name == "planar":
            x0[0:2], x0[3:5] = ref0[0:2], ref0[2:4]
        else:  # body velocity: the inertial one rotated by the yaw only
            x0[0:3], x0[5] = ref0[0:3], ref0[9]
            x0[6:9] = dynamics.rotation_zxy(0.0, 0.0, ref0[9]).T @ ref0[3:6]
        return x0

    def default_controller(self) -> Controller:
        """The paper's PD (planar) or the cascaded PD (6-DOF) for these parameters."""
        if self.name == "planar":
            return PlanarPD(self.params)  # type: ignore[arg-type]
        return Quad6DOFPD(self.params)  # type: ignore[arg-type]


def planar_system(params: PlanarQuadParams = PAPER_PLANAR) -> System:
    """The planar quadrotor as a :class:`System`."""
    return System(
        "planar",
        params,
        partial(dynamics.planar_rhs, params=params),
        partial(dynamics.saturate_planar, params=params),
        dynamics.PLANAR_STATE_NAMES,
        dynamics.PLANAR_INPUT_NAMES,
        dynamics.PLANAR_ANGLE_INDICES,
        PLANAR_REF_NAMES,
        2,
    )


def quad6dof_system(params: Quad6DOFParams = PAPER_6DOF) -> System:
    """The 6-DOF quadrotor as a :class:`System`."""
    return System(
        "quad6dof",
        params,
        partial(dynamics.quad6dof_rhs, params=params),
        partial(dynamics.saturate_quad6dof, params=params),
        dynamics.QUAD6DOF_STATE_NAMES,
        dynamics.QUAD6DOF_INPUT_NAMES,
        dynamics.QUAD6DOF_ANGLE_INDICES,
        SPATIAL_REF_NAMES,
        3,
    )


SYSTEMS: dict[str, Callable[[], System]] = {"planar": planar_system, "quad6dof": quad6dof_system}


def get_system(name: str) -> System:
    """The system called ``planar`` or ``quad6dof``."""
    try:
        return SYSTEMS[name]()
    except KeyError:
        raise ValueError(f"unknown system {name!r}; valid choices: {', '.join(SYSTEMS)}") from None


@dataclass
class ClosedLoopRun:
    """Result of :func:`simulate_closed_loop`; arrays indexed by sample k = 0..N-1.

    Attributes:
        t: Times t_k [s], shape (N,).
        states: x(t_k), shape (N, n).
        commanded: Controller output at t_k (what the authors record), shape (N, m).
        applied: Saturated input held over [t_k, t_k+1), shape (N, m).
        refs: Reference at t_k, shape (N, r).
        system: The simulated system.
    """

    t: FloatArray
    states: FloatArray
    commanded: FloatArray
    applied: FloatArray
    refs: FloatArray
    system: System

    def table(self, inputs: str = "commanded") -> tuple[list[str], FloatArray]:
        """Header and rows ``t, states, inputs, references`` (the authors' CSV layout)."""
        u = self.commanded if inputs == "commanded" else self.applied
        header = ["t", *self.system.state_names, *self.system.input_names, *self.system.ref_names]
        return header, np.column_stack([self.t, self.states, u, self.refs])


def simulate_closed_loop(
    system: System,
    trajectory: Reference,
    controller: Controller | None = None,
    dt: float = 0.01,
    duration: float = 10.0,
    x0: FloatArray | None = None,
    substeps: int = 1,
) -> ClosedLoopRun:
    """Flies ``system`` along ``trajectory`` under ``controller`` (the authors' RK4 loop).

    Args:
        system: The vehicle.
        trajectory: Reference; its dimension must match the system.
        controller: Maps (state, ref) to the commanded input; the system's PD by default.
        dt: Control (and sample) period [s].
        duration: Final time [s]; samples at k dt for k = 0..round(duration/dt).
        x0: Initial state; at rest on the reference by default.
        substeps: RK4 substeps per control period.

    Returns:
        The sampled run.
    """
    if dt <= 0 or duration <= 0:
        raise ValueError(f"dt and duration must be positive, got dt={dt}, duration={duration}")
    if trajectory.ndim != system.traj_ndim:
        raise ValueError(
            f"{system.name} needs a {system.traj_ndim}-D trajectory, got {trajectory.ndim}-D"
        )
    controller = controller or system.default_controller()
    n = int(round(duration / dt)) + 1
    t = np.arange(n) * dt
    refs = trajectory(t)
    x = system.initial_state(refs[0]) if x0 is None else np.asarray(x0, dtype=np.float64)
    states = np.empty((n, system.n_states))
    commanded = np.empty((n, system.n_inputs))
    applied = np.empty_like(commanded)
    for k in range(n):
        states[k] = x
        commanded[k] = controller(x, refs[k])
        applied[k] = system.saturate(commanded[k])
        x = rk4_step(system.rhs, x, applied[k], dt, substeps)
    return ClosedLoopRun(t, states, commanded, applied, refs, system)


def simulate_case(
    case: str, system: str = "planar", dt: float = 0.01, duration: float = 10.0
) -> ClosedLoopRun:
    """Simulates one of the paper's cases (``A``, ``B``, ``C``) or any named trajectory."""
    sys_ = get_system(system)
    rng = np.random.default_rng(0)
    traj = make_trajectory(case, ndim=sys_.traj_ndim, rng=rng)
    return simulate_closed_loop(sys_, traj, dt=dt, duration=duration)
