"""The paper's planar quadrotor: two rotors, motion in the y-z plane, roll phi about x."""

from __future__ import annotations

from typing import Any

import numba
import numpy as np

from quad_envs import dynamics, physics
from quad_envs.controllers import PlanarPD
from quad_envs.params import PAPER_PLANAR, PlanarQuadParams
from quad_envs.physics import (
    C_DRAG,
    C_ROTOR,
    P_DRAG_LINEAR_XY,
    P_DRAG_LINEAR_Z,
    P_DRAG_QUADRATIC_XY,
    P_DRAG_QUADRATIC_Z,
    P_GRAVITY,
    P_I1,
    P_MASS,
    P_TAU,
)
from quad_envs.tasks import COST_WEIGHTS as W
from quad_envs.tasks import FlightVolume
from quad_envs.trajectories import PLANAR_REF_NAMES
from quad_envs.types import FloatArray
from quad_envs.vehicles.base import Vehicle, View


def planar_rest_state(ref0: FloatArray) -> FloatArray:
    """At the reference position with its velocity, level."""
    x0 = np.zeros(6)
    x0[0:2], x0[3:5] = ref0[0:2], ref0[2:4]
    return x0


def planar_observe(states: FloatArray, refs: FloatArray) -> FloatArray:
    """[state, reference - position, reference - velocity] for (..., 6) states and refs."""
    return np.concatenate(
        (states, refs[..., 0:2] - states[..., 0:2], refs[..., 2:4] - states[..., 3:5]), axis=-1
    )


_field = numba.njit(cache=True, inline="always")(dynamics.planar_field)
_drag = numba.njit(cache=True, inline="always")(dynamics.planar_drag)


@numba.njit(cache=True, inline="always")
def planar_point(x: Any, u: Any, thrust: Any, wind: Any, p: Any, c: Any, out: Any) -> None:
    """Extended planar field at one point for the kernels: rigid body (+ drag, wind, rotor lag).

    The equations are :func:`quad_envs.dynamics.planar_field` and
    :func:`quad_envs.dynamics.planar_drag`, compiled; the effects are described in
    :mod:`quad_envs.physics`.

    Args:
        x: Extended state (6, or 8 with rotor thrusts).
        u: Collective input [u1, u2] (from the rotor thrusts in effect).
        thrust: Commanded rotor thrusts (2,).
        wind: Inertial wind (2,).
        p: Parameter vector (:data:`quad_envs.physics.PARAM_FIELDS`).
        c: Constants vector (:func:`quad_envs.physics.pack_consts`).
        out: dx/dt (written).
    """
    # Read once into locals (``out`` may alias ``x`` for the compiler): the drag then shares
    # the field's sine and cosine of phi.
    phi, y_dot, z_dot = x[2], x[3], x[4]
    d = _field(phi, y_dot, z_dot, x[5], u[0], u[1], p[P_MASS], p[P_I1], p[P_GRAVITY])
    for j in range(6):
        out[j] = d[j]
    if c[C_DRAG] != 0.0:
        fy, fz = _drag(
            phi, y_dot - wind[0], z_dot - wind[1], p[P_DRAG_LINEAR_XY], p[P_DRAG_LINEAR_Z],
            p[P_DRAG_QUADRATIC_XY], p[P_DRAG_QUADRATIC_Z],
        )  # fmt: skip
        out[3] += fy / p[P_MASS]
        out[4] += fz / p[P_MASS]
    if c[C_ROTOR] != 0.0:
        for j in range(2):
            out[6 + j] = (thrust[j] - x[6 + j]) / p[P_TAU]


@numba.njit(cache=True, inline="always")
def planar_observe_point(x: Any, ref: Any, out: Any) -> None:
    """:func:`planar_observe` of one state for the kernels (10 entries written)."""
    for j in range(6):
        out[j] = x[j]
    out[6] = ref[0] - x[0]
    out[7] = ref[1] - x[1]
    out[8] = ref[2] - x[3]
    out[9] = ref[3] - x[4]


def planar_state_bounds(volume: FlightVolume) -> tuple[FloatArray, FloatArray]:
    """States allowed before termination: the flight volume and the tilt/speed limits."""
    v, w = volume.max_speed, volume.max_rate
    high = np.array([volume.lateral, volume.z_max, volume.max_tilt, v, v, w])
    low = np.array([-volume.lateral, volume.z_min, -volume.max_tilt, -v, -v, -w])
    return low, high


def planar_obs_bounds(volume: FlightVolume) -> tuple[FloatArray, FloatArray]:
    """Observation space: the state box, then tracking errors up to twice the volume."""
    low, high = planar_state_bounds(volume)
    e_pos = 2 * max(volume.lateral, volume.z_max - volume.z_min)
    e_vel = 2 * volume.max_speed
    err = np.array([e_pos, e_pos, e_vel, e_vel])
    return np.concatenate([low, -err]), np.concatenate([high, err])


def planar_action_bounds(params: PlanarQuadParams) -> tuple[FloatArray, FloatArray]:
    """Box of commandable [u1, u2]: u1 in [2 f_min, 2 f_max], |u2| <= (f_max - f_min) L."""
    return (
        np.array([2 * params.rotor_force_min, -params.moment_max]),
        np.array([params.thrust_max, params.moment_max]),
    )


def planar_library() -> list[str]:
    """The paper's 24 distinct terms.

    1, y, z, y_dot, z_dot, phi_dot, u1, u2, and each of them times sin(phi) and cos(phi).
    """
    plain = ["y", "z", "y_dot", "z_dot", "phi_dot", "u1", "u2"]
    trig = [f"{f}(phi){' ' + m if m else ''}" for m in ["", *plain] for f in ("sin", "cos")]
    return ["1", *plain, *trig]


def planar_rotor_points(state: FloatArray, params: PlanarQuadParams) -> FloatArray:
    """The two rotors in the y-z plane."""
    d = params.arm_length * np.array([np.cos(state[2]), np.sin(state[2])])
    return np.array([state[0:2] - d, state[0:2] + d])


PLANAR = Vehicle(
    name="planar",
    params=PAPER_PLANAR,
    dynamics=dynamics.planar_rhs,
    saturation=dynamics.saturate_planar,
    state_names=dynamics.PLANAR_STATE_NAMES,
    input_names=dynamics.PLANAR_INPUT_NAMES,
    angle_names=("phi",),
    position_names=("y", "z"),
    ref_names=PLANAR_REF_NAMES,
    ndim=2,
    rest_state=planar_rest_state,
    controller=PlanarPD,
    observe=planar_observe,
    obs_names=("y", "z", "phi", "y_dot", "z_dot", "phi_dot", "e_y", "e_z", "e_y_dot", "e_z_dot"),
    cost_weights=np.array(
        [0, 0, W["tilt"], 0, 0, W["rates"], W["pos"], W["pos"], W["vel"], W["vel"]], dtype=float
    ),
    state_bounds=planar_state_bounds,
    obs_bounds=planar_obs_bounds,
    init_scale=np.array([0.5, 0.5, 0.3, 0.5, 0.5, 1.0]),
    action_bounds=planar_action_bounds,
    randomized_fields=("mass", "Ixx", *physics.EFFECT_FIELDS),
    library=planar_library,
    rotor_points=planar_rotor_points,
    views=(View((0, 1), ("y [m]", "z [m]")),),
    point_field=planar_point,
    point_observe=planar_observe_point,
)
"""The paper's planar vehicle (authors' ``get_quad_params.m``)."""
