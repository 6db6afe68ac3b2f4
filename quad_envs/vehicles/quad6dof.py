"""The full 6-DOF quadrotor of the paper's section 2: '+' configuration, Z-X-Y Euler angles."""

from __future__ import annotations

import itertools
import math
from typing import Any

import numba
import numpy as np

from quad_envs import dynamics, physics
from quad_envs.controllers import Quad6DOFPD
from quad_envs.params import PAPER_6DOF, Quad6DOFParams
from quad_envs.physics import (
    C_DRAG,
    C_ROTOR,
    P_DRAG_LINEAR_XY,
    P_DRAG_LINEAR_Z,
    P_DRAG_QUADRATIC_XY,
    P_DRAG_QUADRATIC_Z,
    P_GRAVITY,
    P_I1,
    P_I2,
    P_I3,
    P_MASS,
    P_TAU,
)
from quad_envs.tasks import COST_WEIGHTS as W
from quad_envs.tasks import FlightVolume
from quad_envs.trajectories import SPATIAL_REF_NAMES
from quad_envs.types import FloatArray
from quad_envs.vehicles.base import Vehicle, View


def _wrap(angle: FloatArray) -> FloatArray:
    return np.mod(angle + np.pi, 2 * np.pi) - np.pi


def quad6dof_rest_state(ref0: FloatArray) -> FloatArray:
    """At the reference position and yaw, level; the reference velocity in the body frame."""
    x0 = np.zeros(12)
    x0[0:3], x0[5] = ref0[0:3], ref0[9]
    x0[6:9] = dynamics.rotation_zxy(0.0, 0.0, ref0[9]).T @ ref0[3:6]
    return x0


def quad6dof_observe(states: FloatArray, refs: FloatArray) -> FloatArray:
    """[state (yaw wrapped), ref - position, ref - inertial velocity, yaw error]."""
    velocity = dynamics.body_to_inertial_velocity(states)
    wrapped = states.copy()
    wrapped[..., 5] = _wrap(states[..., 5])
    return np.concatenate(
        (
            wrapped,
            refs[..., 0:3] - states[..., 0:3],
            refs[..., 3:6] - velocity,
            _wrap(refs[..., 9:10] - states[..., 5:6]),
        ),
        axis=-1,
    )


_field = numba.njit(cache=True, inline="always")(dynamics.quad6dof_field)
_rotation = numba.njit(cache=True, inline="always")(dynamics.rotation_entries)
_body_drag = numba.njit(cache=True, inline="always")(dynamics.body_drag)


@numba.njit(cache=True, inline="always")
def _wrap_one(angle: float) -> float:
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


@numba.njit(cache=True, inline="always")
def quad6dof_point(x: Any, u: Any, thrust: Any, wind: Any, p: Any, c: Any, out: Any) -> None:
    """Extended 6-DOF field at one point for the kernels (see ``planar_point``; wind (3,)).

    The equations are :func:`quad_envs.dynamics.quad6dof_field` and
    :func:`quad_envs.dynamics.body_drag`, compiled.
    """
    # Read once into locals: ``out`` may alias ``x`` for the compiler, which would otherwise
    # reload the angles and evaluate their sines and cosines again for the drag.
    phi, theta, psi, vx, vy, vz = x[3], x[4], x[5], x[6], x[7], x[8]
    d = _field(
        phi, theta, psi, vx, vy, vz, x[9], x[10], x[11], u[0], u[1], u[2], u[3],
        p[P_MASS], p[P_I1], p[P_I2], p[P_I3], p[P_GRAVITY],
    )  # fmt: skip
    for j in range(12):
        out[j] = d[j]
    if c[C_DRAG] != 0.0:
        r = _rotation(
            math.cos(phi), math.sin(phi), math.cos(theta), math.sin(theta),
            math.cos(psi), math.sin(psi),
        )  # fmt: skip
        # Body-frame air velocity v_B - R^T w.
        wx = r[0] * wind[0] + r[3] * wind[1] + r[6] * wind[2]
        wy = r[1] * wind[0] + r[4] * wind[1] + r[7] * wind[2]
        wz = r[2] * wind[0] + r[5] * wind[1] + r[8] * wind[2]
        fx, fy, fz = _body_drag(
            vx - wx, vy - wy, vz - wz, p[P_DRAG_LINEAR_XY], p[P_DRAG_LINEAR_Z],
            p[P_DRAG_QUADRATIC_XY], p[P_DRAG_QUADRATIC_Z],
        )  # fmt: skip
        out[6] += fx / p[P_MASS]
        out[7] += fy / p[P_MASS]
        out[8] += fz / p[P_MASS]
    if c[C_ROTOR] != 0.0:
        for j in range(4):
            out[12 + j] = (thrust[j] - x[12 + j]) / p[P_TAU]


@numba.njit(cache=True, inline="always")
def quad6dof_observe_point(x: Any, ref: Any, out: Any) -> None:
    """:func:`quad6dof_observe` of one state for the kernels (19 entries written)."""
    for j in range(12):
        out[j] = x[j]
    out[5] = _wrap_one(x[5])
    r = _rotation(
        math.cos(x[3]), math.sin(x[3]), math.cos(x[4]), math.sin(x[4]),
        math.cos(x[5]), math.sin(x[5]),
    )  # fmt: skip
    for j in range(3):
        out[12 + j] = ref[j] - x[j]
        v = r[3 * j] * x[6] + r[3 * j + 1] * x[7] + r[3 * j + 2] * x[8]
        out[15 + j] = ref[3 + j] - v
    out[18] = _wrap_one(ref[9] - x[5])


def quad6dof_state_bounds(volume: FlightVolume) -> tuple[FloatArray, FloatArray]:
    """States allowed before termination (yaw is free; body speeds bounded like speeds)."""
    lat, tilt, v, w = volume.lateral, volume.max_tilt, volume.max_speed, volume.max_rate
    high = np.array([lat, lat, volume.z_max, tilt, tilt, np.inf, v, v, v, w, w, w])
    low = np.array([-lat, -lat, volume.z_min, -tilt, -tilt, -np.inf, -v, -v, -v, -w, -w, -w])
    return low, high


def quad6dof_obs_bounds(volume: FlightVolume) -> tuple[FloatArray, FloatArray]:
    """Observation space: the state box with yaw in [-pi, pi], then the tracking errors."""
    low, high = quad6dof_state_bounds(volume)
    low[5], high[5] = -np.pi, np.pi
    e_pos = 2 * max(volume.lateral, volume.z_max - volume.z_min)
    err = np.array([e_pos] * 3 + [2 * volume.max_speed] * 3 + [np.pi])
    return np.concatenate([low, -err]), np.concatenate([high, err])


def quad6dof_action_bounds(params: Quad6DOFParams) -> tuple[FloatArray, FloatArray]:
    """Box of commandable [u1, u2, u3, u4]: each mixer row's range over the rotor limits."""
    ends = params.mixer[:, :, None] * np.array([params.rotor_force_min, params.rotor_force_max])
    return ends.min(axis=2).sum(axis=1), ends.max(axis=2).sum(axis=1)


def quad6dof_library() -> list[str]:
    """Physics-informed 6-DOF library (519 terms): trig products times velocities, rates, inputs.

    Every product f(phi) g(theta) h(psi) with f in {1, sin, cos, tan, sec}, g and h in
    {1, sin, cos}, times one of {1, u, v, w, p, q, r, u1..u4}; the 21 quadratic products of
    velocities and rates (gyroscopic and Coriolis terms); and x, y, z as distractors.
    The true 6-DOF model (36 terms) lies in it.
    """
    phi = ["", "sin(phi)", "cos(phi)", "tan(phi)", "sec(phi)"]
    theta = ["", "sin(theta)", "cos(theta)"]
    psi = ["", "sin(psi)", "cos(psi)"]
    mult = ["", "u", "v", "w", "p", "q", "r", *dynamics.QUAD6DOF_INPUT_NAMES]
    names = [
        " ".join(x for x in combo if x) or "1" for combo in itertools.product(phi, theta, psi, mult)
    ]
    moving = ["u", "v", "w", "p", "q", "r"]
    names += [
        f"{a} {b}" if a != b else f"{a}^2"
        for a, b in itertools.combinations_with_replacement(moving, 2)
    ]
    return [*names, "x", "y", "z"]


def quad6dof_rotor_points(state: FloatArray, params: Quad6DOFParams) -> FloatArray:
    """The four rotors in space ('+': on the body axes; 'x': on the diagonals)."""
    rot = dynamics.rotation_zxy(state[3], state[4], state[5])
    if params.frame == "x":  # motor order 1 front-right, 2 back-right, 3 back-left, 4 front-left
        arms = params.arm_length * np.array([[1, -1, 0], [-1, -1, 0], [-1, 1, 0], [1, 1, 0]])
    else:  # rotor 1 on +x, 2 on +y, 3 on -x, 4 on -y
        arms = params.arm_length * np.array([[1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]])
    return state[0:3] + arms @ rot.T


QUAD6DOF = Vehicle(
    name="quad6dof",
    params=PAPER_6DOF,
    dynamics=dynamics.quad6dof_rhs,
    saturation=dynamics.saturate_quad6dof,
    state_names=dynamics.QUAD6DOF_STATE_NAMES,
    input_names=dynamics.QUAD6DOF_INPUT_NAMES,
    angle_names=("phi", "theta", "psi"),
    position_names=("x", "y", "z"),
    ref_names=SPATIAL_REF_NAMES,
    ndim=3,
    rest_state=quad6dof_rest_state,
    controller=Quad6DOFPD,
    observe=quad6dof_observe,
    obs_names=(
        "x",
        "y",
        "z",
        "phi",
        "theta",
        "psi",
        "u",
        "v",
        "w",
        "p",
        "q",
        "r",
        "e_x",
        "e_y",
        "e_z",
        "e_vx",
        "e_vy",
        "e_vz",
        "e_psi",
    ),  # fmt: skip
    cost_weights=np.array(
        [0, 0, 0, W["tilt"], W["tilt"], 0, 0, 0, 0]
        + [W["rates"]] * 3
        + [W["pos"]] * 3
        + [W["vel"]] * 3
        + [W["yaw"]],
        dtype=float,
    ),  # fmt: skip
    state_bounds=quad6dof_state_bounds,
    obs_bounds=quad6dof_obs_bounds,
    init_scale=np.array([0.5, 0.5, 0.5, 0.3, 0.3, 0.5, 0.5, 0.5, 0.5, 1.0, 1.0, 1.0]),
    action_bounds=quad6dof_action_bounds,
    randomized_fields=("mass", "Jxx", "Jyy", "Jzz", *physics.EFFECT_FIELDS),
    library=quad6dof_library,
    rotor_points=quad6dof_rotor_points,
    views=(View((1, 2), ("y [m]", "z [m]")), View((0, 1), ("x [m]", "y [m]"))),
    point_field=quad6dof_point,
    point_observe=quad6dof_observe_point,
)
"""The paper's vehicle in 6-DOF, J = diag(2.5e-4, 2.32e-4, 3.738e-4) kg m^2."""
