"""Quad6DOF-v0: the full 6-DOF quadrotor (paper section 2) tracking a 3-D reference."""

from __future__ import annotations

import numpy as np

from quad_envs.dynamics import body_to_inertial_velocity
from quad_envs.envs.base import QuadrotorEnv, QuadrotorVectorEnv, Vehicle
from quad_envs.params import PAPER_6DOF, Quad6DOFParams
from quad_envs.simulate import quad6dof_system
from quad_envs.tasks import COST_WEIGHTS as W
from quad_envs.tasks import FlightVolume
from quad_envs.types import FloatArray


def _wrap(angle: FloatArray) -> FloatArray:
    return np.mod(angle + np.pi, 2 * np.pi) - np.pi


def quad6dof_observe(states: FloatArray, refs: FloatArray) -> FloatArray:
    """[state (yaw wrapped), ref - position, ref - inertial velocity, yaw error]."""
    velocity = body_to_inertial_velocity(states)
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
    """Box of commandable [u1, u2, u3, u4] from the rotor limits through the mixer."""
    f_lo, f_hi = params.rotor_force_min, params.rotor_force_max
    moment = (f_hi - f_lo) * params.arm_length
    yaw = 2 * (f_hi - f_lo) * params.gamma
    return (
        np.array([4 * f_lo, -moment, -moment, -yaw]),
        np.array([4 * f_hi, moment, moment, yaw]),
    )


QUAD6DOF = Vehicle(
    name="quad6dof",
    make_system=quad6dof_system,
    default_params=PAPER_6DOF,
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
    randomized_fields=("mass", "Jxx", "Jyy", "Jzz"),
)


class Quad6DOFEnv(QuadrotorEnv):
    """Full 6-DOF quadrotor (Z-X-Y Euler angles, body-frame velocity) tracking a 3-D reference.

    ## Observation space (19,)
    | index  | name          | meaning                                   | unit  |
    |--------|---------------|-------------------------------------------|-------|
    | 0-2    | x, y, z       | inertial position                         | m     |
    | 3-5    | phi, theta, psi | roll, pitch, yaw (Z-X-Y)                | rad   |
    | 6-8    | u, v, w       | body-frame velocity                       | m/s   |
    | 9-11   | p, q, r       | body angular rate                         | rad/s |
    | 12-14  | e_x, e_y, e_z | reference minus position                  | m     |
    | 15-17  | e_vx, e_vy, e_vz | reference minus inertial velocity      | m/s   |
    | 18     | e_psi         | yaw error wrapped to (-pi, pi]            | rad   |

    ## Action space (4,)
    | index | name | meaning                       | unit | bounds (default params) |
    |-------|------|-------------------------------|------|-------------------------|
    | 0     | u1   | total thrust                  | N    | [0, 2 m g]              |
    | 1     | u2   | roll moment L (T2 - T4)       | N m  | +-L m g / 2             |
    | 2     | u3   | pitch moment L (T3 - T1)      | N m  | +-L m g / 2             |
    | 3     | u4   | yaw moment gamma (T1-T2+T3-T4) | N m | +-gamma m g             |

    The per-rotor limits [0, m g / 2] apply inside the dynamics. ``normalize_actions=True``
    maps [-1, 1] onto the box (0 is hover). Other arguments: see
    :class:`quad_envs.envs.base.QuadrotorEnv`.
    """

    vehicle = QUAD6DOF


class Quad6DOFVectorEnv(QuadrotorVectorEnv):
    """Native vector version of :class:`Quad6DOFEnv` (batched numpy, same physics)."""

    vehicle = QUAD6DOF
