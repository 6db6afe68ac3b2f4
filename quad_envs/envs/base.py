"""Shared core of the quadrotor environments: one single env and one native vector env.

Both classes are generic over a :class:`Vehicle` (the planar and 6-DOF modules each define
one) and step the same batched physics (:mod:`quad_envs.dynamics`) with the same RK4
(:func:`quad_envs.integrators.rk4_step`). A surrogate environment is the same class with the
ground-truth vector field replaced by an identified model's ``rhs``.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from quad_envs.integrators import Rhs, rk4_step
from quad_envs.tasks import FlightVolume, out_of_bounds, tracking_reward
from quad_envs.trajectories import RandomWaypoints, Reference, make_trajectory
from quad_envs.types import FloatArray
from quad_envs.vehicles import Vehicle

DEFAULT_VOLUME = FlightVolume()


@dataclass(frozen=True)
class EnvConfig:
    """Options shared by the single and the vector environment (validated on creation).

    Attributes:
        trajectory: Reference name (``hover``, ``step``, ``sine``, ``diamond``, ``figure8``,
            ``random``; ``A``/``B``/``C`` alias the paper cases) or a Reference object.
        dt: Control period [s]; the action is held over it (zero-order hold).
        substeps: RK4 substeps per control period.
        duration: Horizon [s] over which references are tabulated (the time limit comes
            from registration: ``max_episode_steps``).
        normalize_actions: Actions in [-1, 1] mapped affinely onto the physical input box
            (0 is hover thrust and zero moments).
        init_state_scale: Scale of the uniform initial-state perturbation (0: start at rest
            on the reference).
        obs_noise_std: Standard deviation of Gaussian noise added to observations.
        param_randomization: Fractional uniform perturbation of the vehicle's randomised
            parameters (mass and inertia) per episode.
        params: Vehicle parameters (the vehicle's preset by default).
        volume: Flight volume and attitude limits for termination.
    """

    trajectory: str | Reference = "hover"
    dt: float = 0.01
    substeps: int = 1
    duration: float = 10.0
    normalize_actions: bool = False
    init_state_scale: float = 0.0
    obs_noise_std: float = 0.0
    param_randomization: float = 0.0
    params: Any = None
    volume: FlightVolume = DEFAULT_VOLUME

    def __post_init__(self) -> None:
        for name in ("dt", "duration"):
            value = getattr(self, name)
            if not np.isfinite(value) or value <= 0:
                raise ValueError(f"{name} must be a positive number, got {value!r}")
        if int(self.substeps) != self.substeps or self.substeps < 1:
            raise ValueError(f"substeps must be a positive integer, got {self.substeps!r}")
        for name in ("init_state_scale", "obs_noise_std", "param_randomization"):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0:
                raise ValueError(f"{name} must be a non-negative number, got {value!r}")
        if self.param_randomization >= 1:
            raise ValueError(f"param_randomization must be below 1, got {self.param_randomization}")

    @classmethod
    def from_options(cls, options: dict[str, Any]) -> EnvConfig:
        """Builds the config from keyword options, naming any unknown one."""
        valid = [f.name for f in fields(cls)]
        unknown = sorted(set(options) - set(valid))
        if unknown:
            raise ValueError(f"unknown env option(s) {unknown}; valid options: {valid}")
        return cls(**options)


_RESET_OPTIONS = ("trajectory", "state")


class _EnvCore:
    """Configuration and episode sampling shared by the single and the vector env.

    Subclasses set the class attribute ``vehicle`` (a :class:`Vehicle` preset); an instance
    replaces it by the same vehicle with the configured parameters.
    """

    vehicle: Vehicle

    def _configure(self, config: EnvConfig, rhs: Rhs | None) -> None:
        if rhs is not None and config.param_randomization > 0:
            raise ValueError("param_randomization needs the ground-truth physics (rhs=None)")
        self.config = config
        self.dt, self.substeps, self.duration = (
            float(config.dt),
            int(config.substeps),
            float(config.duration),
        )
        self.normalize_actions = bool(config.normalize_actions)
        self.init_state_scale = float(config.init_state_scale)
        self.obs_noise_std = float(config.obs_noise_std)
        self.param_randomization = float(config.param_randomization)
        if config.params is not None:
            self.vehicle = self.vehicle.with_params(config.params)
        self.params = self.vehicle.params
        self.volume = config.volume
        self._custom_rhs = rhs
        self._rhs: Rhs = rhs if rhs is not None else self.vehicle.rhs
        self._trajectory_spec = self._check_trajectory(config.trajectory)
        low, high = self.vehicle.action_bounds(self.params)
        self._u_low, self._u_high = low, high
        self._u_center, self._u_half = 0.5 * (high + low), 0.5 * (high - low)
        self._x_low, self._x_high = self.vehicle.state_bounds(self.volume)
        self._obs_low, self._obs_high = self.vehicle.obs_bounds(self.volume)
        self._single_obs_space = spaces.Box(self._obs_low, self._obs_high, dtype=np.float64)
        if self.normalize_actions:
            m = low.size
            # float32 as RL libraries expect; the physics converts to float64.
            self._single_act_space = spaces.Box(-1.0, 1.0, (m,), dtype=np.float32)
        else:
            self._single_act_space = spaces.Box(low, high, dtype=np.float64)
        self._n_table = int(round(self.duration / self.dt)) + 1
        self._t_table = np.arange(self._n_table) * self.dt

    def _check_trajectory(self, trajectory: str | Reference) -> str | Reference:
        if isinstance(trajectory, Reference):
            if trajectory.ndim != self.vehicle.ndim:
                raise ValueError(
                    f"{self.vehicle.name} needs a {self.vehicle.ndim}-D trajectory, "
                    f"got {trajectory.ndim}-D"
                )
            return trajectory
        # Deterministic references are built once and shared by every episode and member;
        # ``random`` stays a name and is drawn per episode. Unknown names raise here.
        built = make_trajectory(
            str(trajectory), ndim=self.vehicle.ndim, rng=np.random.default_rng(0)
        )
        return str(trajectory) if isinstance(built, RandomWaypoints) else built

    def _check_options(self, options: dict[str, Any] | None) -> dict[str, Any]:
        options = dict(options or {})
        unknown = set(options) - set(_RESET_OPTIONS)
        if unknown:
            raise ValueError(
                f"unknown reset option(s) {sorted(unknown)}; valid options: {list(_RESET_OPTIONS)}"
            )
        if "trajectory" in options:
            self._trajectory_spec = self._check_trajectory(options["trajectory"])
        return options

    def _sample_episode(self, rng: np.random.Generator) -> tuple[Reference, FloatArray, Any]:
        """Draws one episode's trajectory, initial-state offset and parameters from rng."""
        spec = self._trajectory_spec
        traj = (
            spec
            if isinstance(spec, Reference)
            else make_trajectory(spec, ndim=self.vehicle.ndim, rng=rng)
        )
        offset = np.zeros(self.vehicle.n_states)
        if self.init_state_scale > 0:
            offset = rng.uniform(-1.0, 1.0, self.vehicle.n_states) * (
                self.init_state_scale * self.vehicle.init_scale
            )
        params = self.params
        if self.param_randomization > 0:
            s = self.param_randomization
            changes = {
                name: getattr(params, name) * rng.uniform(1 - s, 1 + s)
                for name in self.vehicle.randomized_fields
            }
            params = params.replace(**changes)
        return traj, offset, params

    def _finish_obs(self, clean: FloatArray, rng_noise: Any, sanitize: bool) -> FloatArray:
        """Adds observation noise and clips into the observation space.

        Args:
            clean: Noise-free observations from ``vehicle.observe``.
            rng_noise: shape -> standard normal draws.
            sanitize: Replace non-finite entries first (only terminal states can have them).
        """
        obs = np.nan_to_num(clean) if sanitize else clean
        if self.obs_noise_std > 0:
            obs = obs + self.obs_noise_std * rng_noise(obs.shape)
        return np.minimum(np.maximum(obs, self._obs_low), self._obs_high)

    def action_from_input(self, u: FloatArray) -> FloatArray:
        """The action that commands the physical input ``u`` (clipped into the action box).

        The inverse of the env's action mapping: with ``normalize_actions`` the input is
        mapped affinely into [-1, 1]; otherwise it is clipped to the input box.
        """
        u = np.asarray(u, dtype=np.float64)
        if self.normalize_actions:
            action = np.clip((u - self._u_center) / self._u_half, -1.0, 1.0)
        else:
            action = np.clip(u, self._u_low, self._u_high)
        return action.astype(self._single_act_space.dtype)

    def _to_physical(self, action: Any, batch_shape: tuple[int, ...]) -> FloatArray:
        """Validates an action (shape, finiteness) and maps it to a physical input."""
        a = np.asarray(action, dtype=np.float64)
        expected = batch_shape + self._u_low.shape
        if a.shape != expected:
            raise ValueError(f"action must have shape {expected}, got {a.shape}")
        if not np.isfinite(a).all():
            raise ValueError(f"action must be finite (no NaN or inf), got {action!r}")
        if self.normalize_actions:
            return self._u_center + self._u_half * np.minimum(np.maximum(a, -1.0), 1.0)
        return np.minimum(np.maximum(a, self._u_low), self._u_high)


class QuadrotorEnv(_EnvCore, gym.Env):
    """A quadrotor tracking a reference; subclasses fix the vehicle (see their docstrings).

    Args:
        render_mode: ``rgb_array`` or ``human``.
        rhs: Vector field replacing the ground-truth physics (surrogate models).
        **options: The fields of :class:`EnvConfig` (``trajectory``, ``dt``, ``substeps``,
            ``duration``, ``normalize_actions``, ``init_state_scale``, ``obs_noise_std``,
            ``param_randomization``, ``params``, ``volume``).
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 50}

    def __init__(
        self, render_mode: str | None = None, rhs: Rhs | None = None, **options: Any
    ) -> None:
        self._configure(EnvConfig.from_options(options), rhs)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode must be one of {self.metadata['render_modes']}, got {render_mode!r}"
            )
        self.render_mode = render_mode
        self.observation_space = self._single_obs_space
        self.action_space = self._single_act_space
        self._state = np.zeros(self.vehicle.n_states)
        self._k = 0
        self._was_reset = False
        self._renderer: Any = None
        self._trail: list[FloatArray] = []

    @property
    def state(self) -> FloatArray:
        """The true state (a copy)."""
        return self._state.copy()

    @property
    def time(self) -> float:
        """Simulated time since reset [s]."""
        return self._k * self.dt

    def _reference(self, k: int) -> FloatArray:
        if k < self._n_table:
            return self._refs[k]
        return self._traj(k * self.dt)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[FloatArray, dict[str, Any]]:
        """Starts an episode; options: ``trajectory`` (name or object), ``state`` (initial)."""
        super().reset(seed=seed)
        options = self._check_options(options)
        traj, offset, params = self._sample_episode(self.np_random)
        self._traj = traj
        self._refs = traj(self._t_table)
        vehicle = self.vehicle if params is self.params else self.vehicle.with_params(params)
        self._saturate = vehicle.saturate
        if self._custom_rhs is None:
            self._rhs = vehicle.rhs
        if "state" in options:
            x0 = np.asarray(options["state"], dtype=np.float64)
            if x0.shape != (self.vehicle.n_states,) or not np.isfinite(x0).all():
                raise ValueError(
                    f"options['state'] must be {self.vehicle.n_states} finite numbers, "
                    f"got shape {x0.shape}"
                )
        else:
            x0 = self.vehicle.initial_state(self._refs[0]) + offset
        self._state, self._k = x0, 0
        self._was_reset = True
        self._trail = [x0]
        zero_u = np.zeros_like(self._u_low)
        clean = self.vehicle.observe(x0, self._refs[0])
        obs = self._finish_obs(clean, self.np_random.standard_normal, False)
        return obs, self._info(self._refs[0], zero_u, zero_u)

    def step(self, action: Any) -> tuple[FloatArray, float, bool, bool, dict[str, Any]]:
        """Holds the action over dt (RK4); returns (obs, reward, terminated, False, info)."""
        if not self._was_reset:
            raise gym.error.ResetNeeded("call reset() before step()")
        u_cmd = self._to_physical(action, ())
        u = self._saturate(u_cmd)
        self._state = rk4_step(self._rhs, self._state, u, self.dt, self.substeps)
        self._k += 1
        ref = self._reference(self._k)
        terminated = bool(out_of_bounds(self._state, self._x_low, self._x_high))
        clean = self.vehicle.observe(self._state, ref)
        reward = 0.0 if terminated else float(tracking_reward(clean, self.vehicle.cost_weights))
        obs = self._finish_obs(clean, self.np_random.standard_normal, terminated)
        if self.render_mode is not None:
            self._trail.append(self._state)
            if self.render_mode == "human":
                self.render()
        info = self._info(ref, u, u_cmd)
        info["out_of_bounds"] = terminated
        return obs, reward, terminated, False, info

    def _info(self, ref: FloatArray, u: FloatArray, u_cmd: FloatArray) -> dict[str, Any]:
        return {
            "state": self._state,  # rk4_step returns a fresh array each step
            "reference": ref.copy(),
            "action": u,
            "commanded": u_cmd,
            "time": self._k * self.dt,
        }

    def render(self) -> FloatArray | None:
        """Draws the vehicle, the reference and the trail (``rgb_array`` returns the image)."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode= to make()")
            return None
        from quad_envs.rendering import QuadRenderer

        if self._renderer is None:
            self._renderer = QuadRenderer(self.vehicle, self.render_mode)
        refs = self._refs[: min(self._n_table, self._k + 1)]
        return self._renderer.draw(self._state, np.array(self._trail), refs, self._k * self.dt)

    def close(self) -> None:
        """Closes the render window."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


class QuadrotorVectorEnv(_EnvCore, VectorEnv):
    """Native batched version of :class:`QuadrotorEnv` (same arguments, plus ``num_envs``).

    Member i is seeded with ``seed + i`` and draws its episodes exactly as a single env
    seeded that way, so the vector env equals N single envs step for step. Autoreset is
    Gymnasium's NEXT_STEP mode; truncation comes from ``max_episode_steps``.
    """

    metadata = {"render_modes": ["rgb_array"], "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(
        self,
        num_envs: int = 1,
        max_episode_steps: int | None = None,
        render_mode: str | None = None,
        rhs: Rhs | None = None,
        **options: Any,
    ) -> None:
        if int(num_envs) != num_envs or num_envs < 1:
            raise ValueError(f"num_envs must be a positive integer, got {num_envs!r}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode must be one of {self.metadata['render_modes']}, got {render_mode!r}"
            )
        self._configure(EnvConfig.from_options(options), rhs)
        self.num_envs = int(num_envs)
        self.max_episode_steps = max_episode_steps
        self.render_mode = render_mode
        self.single_observation_space = self._single_obs_space
        self.single_action_space = self._single_act_space
        self.observation_space = batch_space(self._single_obs_space, self.num_envs)
        self.action_space = batch_space(self._single_act_space, self.num_envs)
        n = self.vehicle.n_states
        self._states = np.zeros((self.num_envs, n))
        self._k = np.zeros(self.num_envs, dtype=np.int64)
        self._needs_reset = np.zeros(self.num_envs, dtype=bool)
        self._rngs = [np.random.default_rng() for _ in range(self.num_envs)]
        self._trajs: list[Reference] = []
        self._params_list: list[Any] = [self.params] * self.num_envs
        self._was_reset = False

    def reset(
        self, *, seed: int | list[int] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[FloatArray, dict[str, Any]]:
        """Resets every member; ``seed`` int seeds member i with seed + i."""
        if seed is not None:
            seeds = seed if isinstance(seed, list) else [seed + i for i in range(self.num_envs)]
            if len(seeds) != self.num_envs:
                raise ValueError(f"need {self.num_envs} seeds, got {len(seeds)}")
            self._rngs = [np.random.default_rng(s) for s in seeds]
        options = self._check_options(options)
        self._trajs = [None] * self.num_envs  # type: ignore[list-item]
        self._reset_members(np.ones(self.num_envs, dtype=bool), options.get("state"))
        self._refresh_episode_tables()
        self._was_reset = True
        clean = self.vehicle.observe(self._states, self._references())
        return self._finish_obs(clean, self._batch_noise, False), {}

    def _reset_members(self, mask: FloatArray, state: Any = None) -> None:
        for i in np.flatnonzero(mask):
            traj, offset, params = self._sample_episode(self._rngs[i])
            self._trajs[i] = traj
            self._params_list[i] = params
            ref0 = traj(0.0)
            self._states[i] = self.vehicle.initial_state(ref0) + offset
        if state is not None:
            x0 = np.broadcast_to(np.asarray(state, dtype=np.float64), self._states.shape)
            if not np.isfinite(x0).all():
                raise ValueError("options['state'] must be finite")
            self._states[mask] = x0[mask]
        self._k[mask] = 0

    def _update_episode_rows(self, mask: FloatArray) -> None:
        """After an autoreset: writes the new members' waypoints and parameters in place.

        Shared references need nothing; a ``_ListTrajectory`` holds ``self._trajs`` itself;
        the batched parameter arrays are the ones the rhs holds, so row writes reach it.
        """
        rows = np.flatnonzero(mask)
        if isinstance(self._batched_traj, RandomWaypoints):
            for i in rows:
                self._batched_traj.waypoints[i] = self._trajs[i].waypoints  # type: ignore[attr-defined]
        if self.param_randomization > 0:
            for name, values in self._batched_params.items():
                for i in rows:
                    values[i] = getattr(self._params_list[i], name)

    def _refresh_episode_tables(self) -> None:
        """Builds the batched reference source and, if randomised, batched parameters."""
        first = self._trajs[0]
        if all(t is first for t in self._trajs):
            self._shared_refs = first(self._t_table)
            self._batched_traj = None
        elif all(isinstance(t, RandomWaypoints) for t in self._trajs):
            wps = np.stack([t.waypoints for t in self._trajs])  # type: ignore[attr-defined]
            self._batched_traj = RandomWaypoints(
                wps,
                first.segment_time,
                first.yaw_amplitude,
                first.yaw_period,  # type: ignore[attr-defined]
            )
        else:
            self._batched_traj = _ListTrajectory(self._trajs)
        if self.param_randomization > 0:
            self._batched_params = {
                f.name: np.array([getattr(p, f.name) for p in self._params_list])
                for f in fields(self.params)
                if f.name in self.vehicle.randomized_fields
            }
            vehicle = self.vehicle.with_params(self.params.replace(**self._batched_params))
            self._rhs, self._saturate = vehicle.rhs, vehicle.saturate
        else:
            self._saturate = self.vehicle.saturate

    def _references(self) -> FloatArray:
        if self._batched_traj is None:
            k = np.minimum(self._k, self._n_table - 1)
            refs = self._shared_refs[k]
            late = self._k >= self._n_table
            if late.any():
                refs[late] = self._trajs[0](self._k[late] * self.dt)
            return refs
        return self._batched_traj(self._k * self.dt)

    def _batch_noise(self, shape: tuple[int, ...]) -> FloatArray:
        """Standard normal noise, member i drawn from member i's generator."""
        return np.stack([rng.standard_normal(shape[1:]) for rng in self._rngs])

    def step(
        self, actions: Any
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, dict[str, Any]]:
        """Steps every member; members that ended last step are reset instead (NEXT_STEP)."""
        if not self._was_reset:
            raise gym.error.ResetNeeded("call reset() before step() on a vector env")
        u_cmd = self._to_physical(actions, (self.num_envs,))
        resetting = self._needs_reset.copy()
        u = self._saturate(u_cmd)
        new_states = rk4_step(self._rhs, self._states, u, self.dt, self.substeps)
        self._states = np.where(resetting[:, None], self._states, new_states)
        self._k += 1
        if resetting.any():
            self._reset_members(resetting)
            self._update_episode_rows(resetting)
        refs = self._references()
        terminated = out_of_bounds(self._states, self._x_low, self._x_high) & ~resetting
        clean = self.vehicle.observe(self._states, refs)
        reward = tracking_reward(clean, self.vehicle.cost_weights)
        reward = np.where(terminated | resetting, 0.0, reward)
        obs = self._finish_obs(clean, self._batch_noise, bool(terminated.any()))
        if self.max_episode_steps is not None:
            truncated = (self._k >= self.max_episode_steps) & ~resetting
        else:
            truncated = np.zeros(self.num_envs, dtype=bool)
        self._needs_reset = terminated | truncated
        info = {
            "state": self._states.copy(),
            "reference": refs,
            "action": u,
            "time": self._k * self.dt,
        }
        return obs, reward, terminated, truncated, info

    def render(self) -> FloatArray | None:
        """Draws member 0 (``rgb_array``)."""
        if self.render_mode != "rgb_array":
            return None
        from quad_envs.rendering import QuadRenderer

        if getattr(self, "_renderer", None) is None:
            self._renderer = QuadRenderer(self.vehicle, "rgb_array")
        refs = self._trajs[0](self._t_table[: int(self._k[0]) + 1])
        return self._renderer.draw(self._states[0], self._states[:1], refs, self._k[0] * self.dt)


class _ListTrajectory(Reference):
    """Per-member trajectories of mixed kinds, evaluated one by one."""

    def __init__(self, trajs: list[Reference]) -> None:
        self.trajs, self.ndim = trajs, trajs[0].ndim

    def __call__(self, t: FloatArray | float) -> FloatArray:
        t = np.asarray(t, dtype=np.float64)
        return np.stack([traj(ti) for traj, ti in zip(self.trajs, t, strict=True)])
