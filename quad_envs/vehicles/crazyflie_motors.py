"""The Crazyflie driven by motor speeds, with a first-order motor lag as four extra states.

State ``[x, y, z, phi, theta, psi, u, v, w, p, q, r, a1, a2, a3, a4]``: the 6-DOF rigid body of
:mod:`quad_envs.vehicles.quad6dof` plus the four motor speeds ``a_i`` [rad/s]; inputs the four
commanded motor speeds ``omega1..omega4`` [rad/s] (the benchmark's X layout and motor order).
This is the state and input of the model identified from real flights
(:class:`identification.rotorcraft.RotorcraftModel`), so the identified model steps in an env
built on this vehicle. The ground truth here is the nominal Crazyflie
(:data:`quad_envs.params.CRAZYFLIE_6DOF`):

    T_i = Kt a_i^2,   [u1..u4] = M T   (the Crazyflie's X mixer),
    rigid body = :func:`quad_envs.dynamics.quad6dof_rhs`,   a_i' = (omega_i - a_i) / tau.

The env's rotor-command path sees the motor speeds themselves: the params' ``mixer`` is the
identity and its per-rotor command limits (``rotor_force_min``/``max``) are the motor-speed
limits, so the commanded speeds are clipped to them and handed to the vector field.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np

from quad_envs import dynamics, physics
from quad_envs.controllers import Quad6DOFPD
from quad_envs.params import CRAZYFLIE_6DOF, Quad6DOFParams
from quad_envs.physics import P_KT, P_TAU
from quad_envs.tasks import FlightVolume
from quad_envs.types import FloatArray
from quad_envs.vehicles.base import Vehicle
from quad_envs.vehicles.quad6dof import (
    QUAD6DOF,
    quad6dof_obs_bounds,
    quad6dof_observe,
    quad6dof_observe_point,
    quad6dof_point,
    quad6dof_rest_state,
    quad6dof_rotor_points,
    quad6dof_state_bounds,
)

MOTOR_NAMES = ("a1", "a2", "a3", "a4")
"""The motor-speed states [rad/s]."""
INPUT_NAMES = ("omega1", "omega2", "omega3", "omega4")
"""The commanded motor speeds [rad/s] (the names of the identified model's inputs)."""
MOTOR_SPEED_OBS_MAX = 4000.0
"""Upper bound of the observed motor speeds [rad/s] (the observation box)."""

_MIX = np.ascontiguousarray(CRAZYFLIE_6DOF.mixer)
"""The Crazyflie's X mixer, [u1..u4] = M T (rotor geometry is fixed in the kernels)."""


@dataclass(frozen=True)
class MotorSpeedParams:
    """A Crazyflie commanded in motor speeds (defaults: :data:`quad_envs.params.CRAZYFLIE_6DOF`).

    Attributes:
        mass: Mass m [kg].
        Jxx: Roll inertia [kg m^2].
        Jyy: Pitch inertia [kg m^2].
        Jzz: Yaw inertia [kg m^2].
        gravity: Gravitational acceleration g [m/s^2].
        thrust_coefficient: Kt in T = Kt a^2 per motor [N s^2].
        rotor_time_constant: Motor time constant tau of a' = (omega - a) / tau [s].
        motor_speed_min: Lowest commandable motor speed [rad/s].
        motor_speed_max: Highest commandable motor speed [rad/s] (the flights' 500-2,500 rad/s
            lie inside [motor_speed_min, motor_speed_max]).
        hover_speeds: Motor speeds at rest [rad/s] (the reset state); None: the equal speeds
            whose thrust balances gravity, sqrt(m g / (4 Kt)).
        drag_linear_xy: Linear (rotor) drag along body x and y [N s/m] (drag effect).
        drag_linear_z: Linear (rotor) drag along body z [N s/m] (drag effect).
        drag_quadratic_xy: Quadratic body drag along body x and y [N s^2/m^2] (drag effect).
        drag_quadratic_z: Quadratic body drag along body z [N s^2/m^2] (drag effect).
    """

    mass: float = CRAZYFLIE_6DOF.mass
    Jxx: float = CRAZYFLIE_6DOF.Jxx
    Jyy: float = CRAZYFLIE_6DOF.Jyy
    Jzz: float = CRAZYFLIE_6DOF.Jzz
    gravity: float = CRAZYFLIE_6DOF.gravity
    thrust_coefficient: float = CRAZYFLIE_6DOF.thrust_coefficient
    rotor_time_constant: float = CRAZYFLIE_6DOF.rotor_time_constant
    motor_speed_min: float = 400.0
    motor_speed_max: float = 3000.0
    hover_speeds: tuple[float, ...] | None = None
    drag_linear_xy: float = CRAZYFLIE_6DOF.drag_linear_xy
    drag_linear_z: float = CRAZYFLIE_6DOF.drag_linear_z
    drag_quadratic_xy: float = CRAZYFLIE_6DOF.drag_quadratic_xy
    drag_quadratic_z: float = CRAZYFLIE_6DOF.drag_quadratic_z

    @property
    def motor_speeds_hover(self) -> FloatArray:
        """The four motor speeds at rest [rad/s] (``hover_speeds``, or the thrust balance)."""
        if self.hover_speeds is not None:
            return np.asarray(self.hover_speeds, dtype=np.float64)
        balance = np.sqrt(self.mass * self.gravity / (4.0 * self.thrust_coefficient))
        return np.full(4, balance)

    @property
    def rotor_force_min(self) -> float:
        """The env's per-rotor command limit: here the lowest motor speed [rad/s]."""
        return self.motor_speed_min

    @property
    def rotor_force_max(self) -> float:
        """The env's per-rotor command limit: here the highest motor speed [rad/s]."""
        return self.motor_speed_max

    @property
    def rotor_thrust_per_speed2(self) -> float:
        """Kt [N s^2] (the kernels read it as the thrust coefficient)."""
        return self.thrust_coefficient

    @property
    def mixer(self) -> np.ndarray:
        """The identity: the env's rotor commands are the vehicle's inputs, the motor speeds."""
        return np.eye(4)

    @property
    def hover_thrust(self) -> float:
        """Total thrust that balances gravity, m g [N]."""
        return self.mass * self.gravity

    @property
    def rigid_body(self) -> Quad6DOFParams:
        """The same Crazyflie as 6-DOF parameters (thrust limits from the speed limits)."""
        kt = self.thrust_coefficient
        return dataclasses.replace(
            CRAZYFLIE_6DOF,
            mass=self.mass, Jxx=self.Jxx, Jyy=self.Jyy, Jzz=self.Jzz, gravity=self.gravity,
            thrust_coefficient=kt, rotor_time_constant=self.rotor_time_constant,
            rotor_force_min=kt * self.motor_speed_min**2,
            rotor_force_max=kt * self.motor_speed_max**2,
        )  # fmt: skip

    def replace(self, **changes: Any) -> MotorSpeedParams:
        """Returns a copy with some fields changed (domain randomisation, identified trim)."""
        return dataclasses.replace(self, **changes)


CRAZYFLIE_MOTOR_SPEEDS = MotorSpeedParams()
"""The nominal Crazyflie 2.1 Brushless commanded in motor speeds."""


def motor_speeds_rhs(x: FloatArray, u: FloatArray, params: MotorSpeedParams) -> FloatArray:
    """dx/dt of the 16 states for commanded speeds u (..., 4) (no saturation).

    The rigid body is :func:`quad_envs.dynamics.quad6dof_rhs` driven by the thrusts of the
    motor states; the motor states follow the commands with time constant tau.
    """
    x, u = np.asarray(x, dtype=np.float64), np.asarray(u, dtype=np.float64)
    speeds = x[..., 12:16]
    kt = np.asarray(params.thrust_coefficient)[..., None]
    tau = np.asarray(params.rotor_time_constant)[..., None]
    collective = (kt * speeds * speeds) @ _MIX.T
    body = dynamics.quad6dof_rhs(x[..., :12], collective, params)
    return np.concatenate([body, (u - speeds) / tau], axis=-1)


def saturate_motor_speeds(u: FloatArray, params: MotorSpeedParams) -> FloatArray:
    """Commanded motor speeds clipped to [motor_speed_min, motor_speed_max]."""
    return np.clip(u, params.motor_speed_min, params.motor_speed_max)


@numba.njit(cache=True, inline="always")
def motor_speeds_point(x: Any, u: Any, thrust: Any, wind: Any, p: Any, c: Any, out: Any) -> None:
    """:func:`motor_speeds_rhs` at one point for the kernels (plus drag and wind).

    The rigid body and its effects are :func:`quad_envs.vehicles.quad6dof.quad6dof_point`
    driven by the collective input of the motor states.
    """
    kt, tau = p[P_KT], p[P_TAU]
    a1, a2, a3, a4 = x[12], x[13], x[14], x[15]
    w1, w2, w3, w4 = u[0], u[1], u[2], u[3]
    t1, t2, t3, t4 = kt * a1 * a1, kt * a2 * a2, kt * a3 * a3, kt * a4 * a4
    collective = (
        _MIX[0, 0] * t1 + _MIX[0, 1] * t2 + _MIX[0, 2] * t3 + _MIX[0, 3] * t4,
        _MIX[1, 0] * t1 + _MIX[1, 1] * t2 + _MIX[1, 2] * t3 + _MIX[1, 3] * t4,
        _MIX[2, 0] * t1 + _MIX[2, 1] * t2 + _MIX[2, 2] * t3 + _MIX[2, 3] * t4,
        _MIX[3, 0] * t1 + _MIX[3, 1] * t2 + _MIX[3, 2] * t3 + _MIX[3, 3] * t4,
    )
    quad6dof_point(x, collective, thrust, wind, p, c, out)
    out[12] = (w1 - a1) / tau
    out[13] = (w2 - a2) / tau
    out[14] = (w3 - a3) / tau
    out[15] = (w4 - a4) / tau


def motor_speeds_rest_state(ref0: FloatArray, hover_speeds: Any = None) -> FloatArray:
    """The 6-DOF rest state on the reference, the motors at ``hover_speeds`` (default: nominal)."""
    if hover_speeds is None:
        hover_speeds = CRAZYFLIE_MOTOR_SPEEDS.motor_speeds_hover
    return np.concatenate([quad6dof_rest_state(ref0), hover_speeds])


def motor_speeds_observe(states: FloatArray, refs: FloatArray) -> FloatArray:
    """The 6-DOF observation (19 entries), then the four motor speeds."""
    return np.concatenate([quad6dof_observe(states[..., :12], refs), states[..., 12:16]], axis=-1)


@numba.njit(cache=True, inline="always")
def motor_speeds_observe_point(x: Any, ref: Any, out: Any) -> None:
    """:func:`motor_speeds_observe` of one state for the kernels (23 entries written)."""
    quad6dof_observe_point(x, ref, out)
    for j in range(4):
        out[19 + j] = x[12 + j]


def motor_speeds_state_bounds(volume: FlightVolume) -> tuple[FloatArray, FloatArray]:
    """The 6-DOF termination box; the motor states are free."""
    low, high = quad6dof_state_bounds(volume)
    return np.concatenate([low, np.full(4, -np.inf)]), np.concatenate([high, np.full(4, np.inf)])


def motor_speeds_obs_bounds(volume: FlightVolume) -> tuple[FloatArray, FloatArray]:
    """The 6-DOF observation box, then [0, MOTOR_SPEED_OBS_MAX] per motor."""
    low, high = quad6dof_obs_bounds(volume)
    return (
        np.concatenate([low, np.zeros(4)]),
        np.concatenate([high, np.full(4, MOTOR_SPEED_OBS_MAX)]),
    )


def motor_speeds_action_bounds(params: MotorSpeedParams) -> tuple[FloatArray, FloatArray]:
    """The motor-speed box [rad/s]."""
    return np.full(4, float(params.motor_speed_min)), np.full(4, float(params.motor_speed_max))


class MotorSpeedPD:
    """:class:`quad_envs.controllers.Quad6DOFPD` on the rigid body, its thrusts as motor speeds.

    Args:
        params: Vehicle parameters the controller believes in.
        max_tilt: Largest tilt the position loop commands [rad] (see ``Quad6DOFPD``).
    """

    def __init__(
        self, params: MotorSpeedParams = CRAZYFLIE_MOTOR_SPEEDS, max_tilt: float = np.inf
    ) -> None:
        self.params = params
        self._pd = Quad6DOFPD(params.rigid_body, max_tilt=max_tilt)
        self._unmix = np.linalg.inv(_MIX)

    def __call__(self, state: FloatArray, ref: FloatArray) -> FloatArray:
        """Commanded motor speeds [rad/s] for states (..., 16) and references (..., 11)."""
        thrust = self._pd(state[..., :12], ref) @ self._unmix.T
        return np.sqrt(np.maximum(thrust, 0.0) / self.params.thrust_coefficient)


def motor_speeds_library() -> list[str]:
    """A small physics-informed library: trig products times 1, velocities, rates, speeds^2."""
    trig = ["", "sin(phi)", "cos(phi)", "sin(theta)", "cos(theta)", "cos(phi) cos(theta)"]
    mult = ["", "u", "v", "w", "p", "q", "r", *(f"{a}^2" for a in MOTOR_NAMES)]
    names = [" ".join(t for t in (a, b) if t) or "1" for a in trig for b in mult]
    return [*names, "q r", "p r", "p q"]


def motor_speeds_rotor_points(state: FloatArray, params: MotorSpeedParams) -> FloatArray:
    """The four rotors in space (the Crazyflie's X layout)."""
    return quad6dof_rotor_points(state[:12], CRAZYFLIE_6DOF)


CRAZYFLIE_MOTORS = Vehicle(
    name="crazyflie_motors",
    params=CRAZYFLIE_MOTOR_SPEEDS,
    dynamics=motor_speeds_rhs,
    saturation=saturate_motor_speeds,
    state_names=(*dynamics.QUAD6DOF_STATE_NAMES, *MOTOR_NAMES),
    input_names=INPUT_NAMES,
    angle_names=QUAD6DOF.angle_names,
    position_names=QUAD6DOF.position_names,
    ref_names=QUAD6DOF.ref_names,
    ndim=3,
    rest_state=motor_speeds_rest_state,
    controller=MotorSpeedPD,
    observe=motor_speeds_observe,
    obs_names=(*QUAD6DOF.obs_names, *MOTOR_NAMES),
    cost_weights=np.concatenate([QUAD6DOF.cost_weights, np.zeros(4)]),
    state_bounds=motor_speeds_state_bounds,
    obs_bounds=motor_speeds_obs_bounds,
    init_scale=np.concatenate([QUAD6DOF.init_scale, np.zeros(4)]),
    action_bounds=motor_speeds_action_bounds,
    randomized_fields=("mass", "Jxx", "Jyy", "Jzz", *physics.EFFECT_FIELDS),
    library=motor_speeds_library,
    rotor_points=motor_speeds_rotor_points,
    views=QUAD6DOF.views,
    point_field=motor_speeds_point,
    point_observe=motor_speeds_observe_point,
)
"""The Crazyflie commanded in motor speeds, motor lag as states (16 states, 4 inputs)."""
