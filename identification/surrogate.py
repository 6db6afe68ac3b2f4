"""Identified models as Gymnasium environments (surrogates of the ground truth).

A surrogate is the base environment class itself (same spaces, tasks, reward, termination,
saturation and RK4) with the ground-truth vector field replaced by the model's compiled
``rhs``. States that leave the flight volume or become non-finite end the episode as
``terminated`` with ``info["out_of_bounds"]`` set, and the observation stays finite.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
from gymnasium.envs.registration import register, registry

from identification.model import IdentifiedModel, load_model

BASES = {
    "PlanarQuad-v0": ("quad_envs.envs.planar", "PlanarQuadEnv", "PlanarQuadVectorEnv"),
    "Quad6DOF-v0": ("quad_envs.envs.quad6dof", "Quad6DOFEnv", "Quad6DOFVectorEnv"),
}


def _resolve(
    model: IdentifiedModel | str | Path | None, base_id: str
) -> tuple[IdentifiedModel, Any]:
    import importlib

    if base_id not in BASES:
        raise ValueError(f"unknown base env {base_id!r}; valid choices: {', '.join(BASES)}")
    if model is None:
        raise ValueError("a surrogate env needs model= (a model object or a model JSON path)")
    if not isinstance(model, IdentifiedModel):
        model = load_model(model)
    module = importlib.import_module(BASES[base_id][0])
    single = getattr(module, BASES[base_id][1])
    system = single.vehicle.make_system(single.vehicle.default_params)
    if (model.state_names, model.input_names) != (system.state_names, system.input_names):
        raise ValueError(
            f"model variables {model.state_names} / {model.input_names} do not match {base_id}'s "
            f"{system.state_names} / {system.input_names}"
        )
    return model, module


def make_surrogate(
    model: IdentifiedModel | str | Path | None = None, base_id: str = "PlanarQuad-v0", **kwargs: Any
) -> gym.Env:
    """A single surrogate env: the base env stepping ``model.rhs``."""
    model, module = _resolve(model, base_id)
    env = getattr(module, BASES[base_id][1])(rhs=model.rhs, **kwargs)
    env.model = model
    return env


def make_surrogate_vector(
    model: IdentifiedModel | str | Path | None = None,
    base_id: str = "PlanarQuad-v0",
    num_envs: int = 1,
    **kwargs: Any,
) -> gym.vector.VectorEnv:
    """A native vector surrogate env (batched ``model.rhs``)."""
    model, module = _resolve(model, base_id)
    env = getattr(module, BASES[base_id][2])(num_envs=num_envs, rhs=model.rhs, **kwargs)
    env.model = model
    return env


def register_surrogate(
    model: IdentifiedModel | str | Path,
    env_id: str,
    base_id: str = "PlanarQuad-v0",
    max_episode_steps: int = 1000,
) -> str:
    """Registers ``model`` as ``env_id`` (single and native vector entry points).

    Returns:
        The id, ready for ``gym.make(env_id)`` and ``gym.make_vec(env_id, n)``.
    """
    model, _ = _resolve(model, base_id)
    if env_id in registry:
        del registry[env_id]
    register(
        id=env_id,
        entry_point=make_surrogate,
        vector_entry_point=make_surrogate_vector,
        max_episode_steps=max_episode_steps,
        kwargs={"model": model, "base_id": base_id},
    )
    return env_id
