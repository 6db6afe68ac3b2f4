"""The paper's planar quadrotor: two rotors, motion in the y-z plane, roll phi about x."""

from __future__ import annotations

import numpy as np

from quad_envs import dynamics, physics
from quad_envs.controllers import PlanarPD
from quad_envs.params import PAPER_PLANAR, PlanarQuadParams
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
)
"""The paper's planar vehicle (authors' ``get_quad_params.m``)."""
