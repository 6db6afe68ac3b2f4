"""PlanarQuad-v0: the paper's planar quadrotor tracking a reference in the y-z plane."""

from __future__ import annotations

from quad_envs.envs.base import QuadrotorEnv, QuadrotorVectorEnv
from quad_envs.vehicles import PLANAR


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

    ## Vehicles, action modes, effects
    ``vehicle="paper"`` (default), ``"crazyflie"`` or ``"pelican"``
    (:data:`quad_envs.params.PRESETS`). ``action_mode="collective"`` (the table above),
    ``"rotor_thrusts"`` (2 thrusts [N] in [rotor_force_min, rotor_force_max]) or
    ``"motor_speeds"`` (2 speeds [rad/s]; vehicles with a thrust coefficient).
    ``effects=`` switches on rotor dynamics (the 2 rotor thrusts [N] are appended to the
    observation), drag, wind and gusts, observation bias and delay, per-rotor limits
    (:class:`quad_envs.physics.Effects`; ``effects="all"`` for all of them).
    """

    vehicle = PLANAR


class PlanarQuadVectorEnv(QuadrotorVectorEnv):
    """Native vector version of :class:`PlanarQuadEnv` (the same compiled kernel, batched)."""

    vehicle = PLANAR
