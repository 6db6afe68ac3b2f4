"""identification: SINDy-with-control models of the quadrotors, discovered from data alone.

The method (``data``, ``features``, ``libraries``, ``fit``, ``model``, ``surrogate``) sees
only trajectories; ``rollouts`` makes data from environments; ``experiments`` holds the
reproductions and studies that may compare with a known truth.

Importing the package registers the surrogate ids ``PlanarQuadSINDy-v0`` and
``Quad6DOFSINDy-v0`` (``gym.make(id, model=...)`` with a model or its JSON path), and
``CrazyflieSINDy-v0``: a rotorcraft model identified from real flights
(:mod:`identification.rotorcraft`) flying the motor-speed Crazyflie env.
"""

from __future__ import annotations

from gymnasium.envs.registration import register, registry

import quad_envs

SURROGATE_IDS: tuple[str, ...] = ("PlanarQuadSINDy-v0", "Quad6DOFSINDy-v0")

for _env_id, _base in zip(SURROGATE_IDS, ("PlanarQuad-v0", "Quad6DOF-v0"), strict=True):
    if _env_id not in registry:
        register(
            id=_env_id,
            entry_point="identification.surrogate:make_surrogate",
            vector_entry_point="identification.surrogate:make_surrogate_vector",
            max_episode_steps=quad_envs.MAX_EPISODE_STEPS,
            kwargs={"base_id": _base},
        )

if "CrazyflieSINDy-v0" not in registry:
    register(
        id="CrazyflieSINDy-v0",
        entry_point="identification.surrogate:make_rotorcraft_surrogate",
        vector_entry_point="identification.surrogate:make_rotorcraft_surrogate_vector",
        max_episode_steps=quad_envs.MAX_EPISODE_STEPS,
    )
