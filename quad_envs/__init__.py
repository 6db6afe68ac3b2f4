"""quad_envs: Gymnasium quadrotor environments on paper-exact RK4 physics.

Importing the package registers ``PlanarQuad-v0`` and ``Quad6DOF-v0`` (also reachable as
``gym.make("quad_envs:PlanarQuad-v0")`` without the import) and the surrogate ids
``PlanarQuadSINDy-v0`` / ``Quad6DOFSINDy-v0``, which take ``model=`` (an identified model or
the path of its JSON file).
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

# Surrogates of identified models: gym.make("PlanarQuadSINDy-v0", model="model.json").
for _env_id, _base in (
    ("PlanarQuadSINDy-v0", "PlanarQuad-v0"),
    ("Quad6DOFSINDy-v0", "Quad6DOF-v0"),
):
    if _env_id not in registry:
        register(
            id=_env_id,
            entry_point="identification.surrogate:make_surrogate",
            vector_entry_point="identification.surrogate:make_surrogate_vector",
            max_episode_steps=MAX_EPISODE_STEPS,
            kwargs={"base_id": _base},
        )

ENV_IDS: tuple[str, ...] = tuple(_ENVS)
SURROGATE_IDS: tuple[str, ...] = ("PlanarQuadSINDy-v0", "Quad6DOFSINDy-v0")
