r"""identification: SINDy-with-control models of the quadrotors, discovered from data alone.

The method (``data``, ``features``, ``libraries``, ``fit``, ``model``, ``surrogate``) sees
only trajectories; ``rollouts`` makes data from environments; ``experiments`` holds the
reproductions and studies that may compare with a known truth.

Importing the package registers the surrogate ids ``PlanarQuadSINDy-v0`` and
``Quad6DOFSINDy-v0`` (``gym.make(id, model=...)`` with a model or its JSON path), and
``CrazyflieSINDy-v0``: a rotorcraft model identified from real flights
(:mod:`identification.rotorcraft`) flying the motor-speed Crazyflie env.

The main API is importable from the package (loaded on first use, so importing it stays
light)::

    from identification import Trajectory, select_model, load_model

    data = [Trajectory(t, x, u, state_names, input_names) for t, x, u in flights]
    model, report = select_model(data, "degree=2;angles=phi")  # or a preset, or terms
    print(*model.equations(), *report.warnings, sep="\n")

(A fixed lambda: ``identification.fit.fit``; the submodule ``fit`` shares that name.)
"""

from __future__ import annotations

import importlib
from typing import Any

from gymnasium.envs.registration import register, registry

import quad_envs

_EXPORTS = {
    "Trajectory": "identification.data",
    "IdentificationWarning": "identification.data",
    "clean": "identification.data",
    "load_data": "identification.data",
    "FitConfig": "identification.fit",
    "select_model": "identification.selection",
    "held_out_errors": "identification.scoring",
    "IdentifiedModel": "identification.model",
    "load_model": "identification.model",
    "library_from_spec": "identification.libraries",
    "make_surrogate": "identification.surrogate",
    "register_surrogate": "identification.surrogate",
}
__all__ = ["SURROGATE_IDS", *_EXPORTS]


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'identification' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted([*globals(), *_EXPORTS])


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
