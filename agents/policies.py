"""Policies with one interface: ``policy(obs, info) -> action`` in the env's action space.

``info`` is the env's info dict (``state``, ``reference``), which the model-based
controllers use; learned policies use ``obs`` only.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

import quad_envs  # noqa: F401 (registers the ids)

POLICIES = ("pd", "random", "ou")


class PDPolicy:
    """The paper's planar PD or the 6-DOF cascaded PD, mapped into the env's action space.

    Args:
        env: The (possibly wrapped) env whose action space the actions must fit.
    """

    def __init__(self, env: gym.Env) -> None:
        self.env = env.unwrapped
        self.controller = self.env.vehicle.default_controller()

    def __call__(self, obs: np.ndarray, info: dict[str, Any]) -> np.ndarray:
        """The commanded input for the true state and reference in ``info``."""
        return self.env.action_from_input(self.controller(info["state"], info["reference"]))


class UniformRandomPolicy:
    """Independent uniform draws from the action space."""

    def __init__(self, env: gym.Env, seed: int | None = None) -> None:
        self.space = env.action_space
        self.rng = np.random.default_rng(seed)

    def __call__(self, obs: np.ndarray, info: dict[str, Any]) -> np.ndarray:
        """A fresh uniform action."""
        return self.rng.uniform(self.space.low, self.space.high).astype(self.space.dtype)


class OrnsteinUhlenbeckPolicy:
    """Smooth random exploration around hover: an OU process in the action box.

    a_{k+1} = a_k + theta (mu - a_k) dt + sigma sqrt(dt) N(0, 1), scaled to the box half-width
    and centred on its midpoint (hover thrust for the quadrotors).
    """

    def __init__(
        self,
        env: gym.Env,
        seed: int | None = None,
        theta: float = 2.0,
        sigma: float = 0.6,
        dt: float = 0.01,
    ) -> None:
        self.space = env.action_space
        self.center = 0.5 * (self.space.high + self.space.low)
        self.half = 0.5 * (self.space.high - self.space.low)
        self.rng = np.random.default_rng(seed)
        self.theta, self.sigma, self.dt = theta, sigma, dt
        self.state = np.zeros(self.space.shape)

    def __call__(self, obs: np.ndarray, info: dict[str, Any]) -> np.ndarray:
        """The next OU sample, clipped into the box."""
        noise = self.rng.standard_normal(self.state.shape)
        self.state += -self.theta * self.state * self.dt + self.sigma * np.sqrt(self.dt) * noise
        action = np.clip(self.center + self.half * self.state, self.space.low, self.space.high)
        return action.astype(self.space.dtype)


class SB3Policy:
    """A trained stable-baselines3 model (deterministic actions)."""

    def __init__(self, model: Any, deterministic: bool = True) -> None:
        self.model, self.deterministic = model, deterministic

    def __call__(self, obs: np.ndarray, info: dict[str, Any]) -> np.ndarray:
        """The model's action for ``obs``."""
        action, _ = self.model.predict(obs, deterministic=self.deterministic)
        return action


def make_policy(name: str, env_id: str, seed: int | None = None, **env_kwargs: Any) -> Any:
    """A named policy (``pd``, ``random``, ``ou``) for ``env_id`` with ``env_kwargs``."""
    if name not in POLICIES:
        raise ValueError(f"unknown policy {name!r}; valid choices: {', '.join(POLICIES)}")
    try:
        env = gym.make(env_id, **env_kwargs)
    except gym.error.Error as exc:
        raise ValueError(f"unknown env id {env_id!r}: {exc}") from None
    if name == "pd":
        return PDPolicy(env)
    if name == "random":
        return UniformRandomPolicy(env, seed)
    return OrnsteinUhlenbeckPolicy(env, seed)
