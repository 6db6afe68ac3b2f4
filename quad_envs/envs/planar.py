"""PlanarQuad-v0: the paper's planar quadrotor tracking a reference in the y-z plane."""

from __future__ import annotations

import numpy as np

from quad_envs.envs.base import QuadrotorEnv, QuadrotorVectorEnv, Vehicle
from quad_envs.params import PAPER_PLANAR, PlanarQuadParams
from quad_envs.simulate import planar_system
from quad_envs.tasks import COST_WEIGHTS as W
from quad_envs.tasks import FlightVolume
from quad_envs.types import FloatArray


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


PLANAR = Vehicle(
    name="planar",
    make_system=planar_system,
    default_params=PAPER_PLANAR,
    observe=planar_observe,
    obs_names=("y", "z", "phi", "y_dot", "z_dot", "phi_dot", "e_y", "e_z", "e_y_dot", "e_z_dot"),
    cost_weights=np.array(
        [0, 0, W["tilt"], 0, 0, W["rates"], W["pos"], W["pos"], W["vel"], W["vel"]], dtype=float
    ),
    state_bounds=planar_state_bounds,
    obs_bounds=planar_obs_bounds,
    init_scale=np.array([0.5, 0.5, 0.3, 0.5, 0.5, 1.0]),
    action_bounds=planar_action_bounds,
    randomized_fields=("mass", "Ixx"),
)


class PlanarQuadEnv(QuadrotorEnv):
    """Planar quadrotor (paper section 3) tracking a reference in the y-z plane.

    Dynamics: y_ddot = -u1 sin(phi)/m, z_ddot = u1 cos(phi)/m - g, phi_ddot = u2/Ixx, per-rotor
    saturation, RK4 with the action held over each 0.01 s step.

    ## Observation space (10,)
    | index | name     | meaning                               | unit  |
    |-------|----------|---------------------------------------|-------|
    | 0, 1  | y, z     | position                              | m     |
    | 2     | phi      | roll angle                            | rad   |
    | 3, 4  | y_dot, z_dot | velocity                          | m/s   |
    | 5     | phi_dot  | roll rate                             | rad/s |
    | 6, 7  | e_y, e_z | reference minus position              | m     |
    | 8, 9  | e_y_dot, e_z_dot | reference minus velocity      | m/s   |

    ## Action space (2,)
    | index | name | meaning      | unit | bounds (default params)     |
    |-------|------|--------------|------|-----------------------------|
    | 0     | u1   | total thrust | N    | [0, 2 m g] = [0, 3.5316]    |
    | 1     | u2   | roll moment  | N m  | +-m g L = +-0.15186         |

    With ``normalize_actions=True`` both lie in [-1, 1] (0 is hover). Reward, termination and
    the other arguments: see :class:`quad_envs.envs.base.QuadrotorEnv` and
    :mod:`quad_envs.tasks`.
    """

    vehicle = PLANAR


class PlanarQuadVectorEnv(QuadrotorVectorEnv):
    """Native vector version of :class:`PlanarQuadEnv` (batched numpy, same physics)."""

    vehicle = PLANAR
