"""quad_envs: Gymnasium quadrotor environments on paper-exact RK4 physics.

Importing the package registers ``PlanarQuad-v0`` and ``Quad6DOF-v0`` (also reachable as
``gym.make("quad_envs:PlanarQuad-v0")`` without the import). The surrogate ids of identified
models are registered by :mod:`identification` (``gym.make("identification:PlanarQuadSINDy-v0",
model=...)``): this package knows nothing of the packages built on it.
"""

from __future__ import annotations

from gymnasium.envs.registration import register, registry

__version__ = "0.1.0"

MAX_EPISODE_STEPS = 1000
"""Default time limit: 10 s at the default 0.01 s control step."""

_ENVS = {
    "PlanarQuad-v0": ("planar:PlanarQuadEnv", "planar:PlanarQuadVectorEnv"),
    "Quad6DOF-v0": ("quad6dof:Quad6DOFEnv", "quad6dof:Quad6DOFVectorEnv"),
}

for _env_id, (_single, _vector) in _ENVS.items():
    if _env_id not in registry:
        register(
            id=_env_id,
            entry_point=f"quad_envs.envs.{_single}",
            vector_entry_point=f"quad_envs.envs.{_vector}",
            max_episode_steps=MAX_EPISODE_STEPS,
        )

ENV_IDS: tuple[str, ...] = tuple(_ENVS)

MOTOR_SPEED_ENV_IDS: tuple[str, ...] = ("CrazyflieMotors-v0",)
"""Vehicles commanded in motor speeds with the motors as states (no presets, action modes or
rotor dynamics to choose): kept out of :data:`ENV_IDS`, whose tests sweep those options."""

if "CrazyflieMotors-v0" not in registry:
    register(
        id="CrazyflieMotors-v0",
        entry_point="quad_envs.envs.crazyflie:CrazyflieMotorsEnv",
        vector_entry_point="quad_envs.envs.crazyflie:CrazyflieMotorsVectorEnv",
        max_episode_steps=MAX_EPISODE_STEPS,
    )
