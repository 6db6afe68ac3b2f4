"""Quad6DOF-v0: the full 6-DOF quadrotor (paper section 2) tracking a 3-D reference."""

from __future__ import annotations

from quad_envs.envs.base import QuadrotorEnv, QuadrotorVectorEnv
from quad_envs.vehicles import QUAD6DOF


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

    ## Vehicles, action modes, effects
    ``vehicle="paper"`` (default), ``"crazyflie"`` or ``"pelican"``
    (:data:`quad_envs.params.PRESETS`). ``action_mode="collective"`` (the table above),
    ``"rotor_thrusts"`` (4 thrusts [N] in [rotor_force_min, rotor_force_max]) or
    ``"motor_speeds"`` (4 speeds [rad/s]; vehicles with a thrust coefficient).
    ``effects=`` switches on rotor dynamics (the 4 rotor thrusts [N] are appended to the
    observation), drag, wind and gusts, observation bias and delay, per-rotor limits
    (:class:`quad_envs.physics.Effects`; ``effects="all"`` for all of them).
    """

    vehicle = QUAD6DOF


class Quad6DOFVectorEnv(QuadrotorVectorEnv):
    """Native vector version of :class:`Quad6DOFEnv` (the same compiled kernel, batched)."""

    vehicle = QUAD6DOF
