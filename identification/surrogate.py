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
from gymnasium.envs.registration import load_env_creator, register, registry

import quad_envs
from identification.model import IdentifiedModel, load_model


def _base_class(base_id: str, vector: bool) -> Any:
    """The env class registered as ``base_id`` (its vector class with ``vector``)."""
    problem = f"{base_id!r} is not a quadrotor env; valid choices: {', '.join(quad_envs.ENV_IDS)}"
    try:
        spec = gym.spec(base_id)
    except gym.error.Error:
        raise ValueError(problem) from None
    entry = spec.vector_entry_point if vector else spec.entry_point
    cls = load_env_creator(entry) if isinstance(entry, str) else entry
    if not isinstance(cls, type) or not hasattr(cls, "vehicle"):
        raise ValueError(problem)
    return cls


def _resolve(model: IdentifiedModel | str | Path | None, base_id: str, vector: bool) -> tuple:
    cls = _base_class(base_id, vector)
    if model is None:
        raise ValueError("a surrogate env needs model= (a model object or a model JSON path)")
    if not isinstance(model, IdentifiedModel):
        model = load_model(model)
    vehicle = cls.vehicle
    if (model.state_names, model.input_names) != (vehicle.state_names, vehicle.input_names):
        raise ValueError(
            f"model variables {model.state_names} / {model.input_names} do not match {base_id}'s "
            f"{vehicle.state_names} / {vehicle.input_names}"
        )
    return model, cls


def make_surrogate(
    model: IdentifiedModel | str | Path | None = None, base_id: str = "PlanarQuad-v0", **kwargs: Any
) -> gym.Env:
    """A single surrogate env: the base env stepping ``model.rhs``."""
    model, cls = _resolve(model, base_id, vector=False)
    env = cls(rhs=model.rhs, **kwargs)
    env.model = model
    return env


def make_surrogate_vector(
    model: IdentifiedModel | str | Path | None = None,
    base_id: str = "PlanarQuad-v0",
    num_envs: int = 1,
    **kwargs: Any,
) -> gym.vector.VectorEnv:
    """A native vector surrogate env (batched ``model.rhs``)."""
    model, cls = _resolve(model, base_id, vector=True)
    env = cls(num_envs=num_envs, rhs=model.rhs, **kwargs)
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
    model, _ = _resolve(model, base_id, vector=False)
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
