"""Shared core of the quadrotor environments: one single env and one native vector env.

Both classes are generic over a :class:`Vehicle` (the planar and 6-DOF modules each define
one) and step the same compiled kernel (:mod:`quad_envs.physics`): the vehicle's equations of
motion from :mod:`quad_envs.dynamics`, the optional effects, RK4, observation, reward and
termination. The single env is the kernel with a batch of one. A surrogate environment is the
same class with the vector field replaced by an identified model's ``rhs`` (a Python
``rhs(x, u)`` is integrated by :func:`quad_envs.integrators.rk4_step`; an object with a
``point_source`` attribute, the source of a scalar ``point(X, U, out)`` such as
:class:`identification.compiled.CompiledRhs`, is compiled into the kernel). Of the physical
effects only rotor dynamics applies to such a field: its input is then the mix of the
rotor-thrust states (:class:`quad_envs.physics.RotorLagField`), the surrogate of a model
whose inputs act through a first-order lag.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, fields, is_dataclass
from numbers import Real
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from quad_envs import physics
from quad_envs.integrators import Rhs, rk4_step
from quad_envs.params import PRESETS, check_can_hover, get_preset, with_changes
from quad_envs.tasks import FlightVolume
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
        substeps: RK4 substeps per control period (with rotor dynamics raised, where
            needed, so that a substep is no longer than the fastest rotor time constant).
        duration: Horizon [s] over which references are tabulated (the time limit comes
            from registration: ``max_episode_steps``).
        normalize_actions: Actions in [-1, 1] mapped affinely onto the physical action box
            (0 is its middle: hover for the paper vehicle's collective mode).
        init_state_scale: Scale of the uniform initial-state perturbation (0: start at rest
            on the reference).
        obs_noise_std: Standard deviation of Gaussian noise added to observations.
        param_randomization: Fractional uniform perturbation per episode of the vehicle's
            randomised parameters (mass, inertia, rotor time constant, thrust coefficient,
            drag coefficients).
        params: Vehicle parameters (overrides ``vehicle``), or a mapping of changes to the
            ``vehicle`` preset's (``{"mass": 0.6, "Ixx": 4e-3}``; the CLI's ``--param``).
        volume: Flight volume and attitude limits for termination.
        vehicle: Parameter preset: ``paper`` (default), ``crazyflie`` or ``pelican``
            (:data:`quad_envs.params.PRESETS`).
        effects: Effects (:class:`quad_envs.physics.Effects`, a dict of its fields, a list
            of effect names, or ``"all"``); none by default.
        action_mode: ``collective`` (thrust [N] and moments [N m]), ``rotor_thrusts`` [N]
            or ``motor_speeds`` [rad/s] (vehicles with a thrust coefficient).
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
    vehicle: str = "paper"
    effects: Any = None
    action_mode: str = "collective"

    def __post_init__(self) -> None:
        if not isinstance(self.normalize_actions, bool | np.bool_):  # "no" is truthy
            raise ValueError(
                f"normalize_actions must be True or False, got {self.normalize_actions!r}"
            )
        numbers = ("dt", "duration", "substeps", "init_state_scale", "obs_noise_std",
                   "param_randomization")  # fmt: skip
        for name in numbers:
            _check_real(name, getattr(self, name))
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
        if self.vehicle not in PRESETS:
            raise ValueError(
                f"unknown vehicle preset {self.vehicle!r}; valid choices: {', '.join(PRESETS)}"
            )
        if self.action_mode not in physics.MODES:
            raise ValueError(
                f"unknown action_mode {self.action_mode!r}; valid choices: "
                f"{', '.join(physics.MODES)}"
            )

    @classmethod
    def from_options(cls, options: dict[str, Any]) -> EnvConfig:
        """Builds the config from keyword options, naming any unknown one."""
        valid = [f.name for f in fields(cls)]
        unknown = sorted(set(options) - set(valid))
        if unknown:
            raise ValueError(f"unknown env option(s) {unknown}; valid options: {valid}")
        return cls(**options)


def _check_real(name: str, value: Any) -> None:
    """Raises ValueError naming ``name`` unless ``value`` is a real number (not text, a bool)."""
    if isinstance(value, bool | np.bool_) or not isinstance(value, Real):
        raise ValueError(f"{name} must be a number, got {value!r}")


def _effects(spec: Any, ndim: int, n_rotors: int) -> physics.Effects:
    """:meth:`physics.Effects.from_spec` with each setting's type checked, naming the setting.

    A switch given as text (``{"drag": "no"}``) would be truthy, and a number given as text
    ended deep inside the kernels' packing.
    """
    if isinstance(spec, Mapping):
        defaults = physics.Effects()
        for name, value in spec.items():
            default = getattr(defaults, str(name), None)  # unknown names: from_spec names them
            if isinstance(default, bool) and not isinstance(value, bool | np.bool_):
                raise ValueError(f"effects.{name} must be True or False, got {value!r}")
            if isinstance(default, int | float) and not isinstance(default, bool):
                _check_real(f"effects.{name}", value)
        spec = dict(spec)
    effects = physics.Effects.from_spec(spec, ndim, n_rotors)
    for name in ("rotor_dynamics", "observe_rotors", "drag"):  # an Effects made by hand
        if not isinstance(getattr(effects, name), bool | np.bool_):
            raise ValueError(
                f"effects.{name} must be True or False, got {getattr(effects, name)!r}"
            )
    return effects


_RESET_OPTIONS = ("trajectory", "state")


@dataclass
class _Draws:
    """What one member draws at reset, in this order from its generator (None: not drawn).

    Attributes:
        traj: The episode's reference (drawn for ``random``).
        uniforms: U(0, 1) numbers: the initial-state offset (if ``init_state_scale``), then
            the parameter factors (if ``param_randomization``).
        seed: State of the kernels' generator of the member (gusts, observation noise).
        normals: N(0, 1) numbers: the initial gust (if gusts), then the observation bias.
    """

    traj: Reference
    uniforms: FloatArray | None
    seed: int
    normals: FloatArray | None


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
        self.action_mode = config.action_mode
        params = config.params
        if params is None or isinstance(params, Mapping):
            preset = get_preset(config.vehicle, self.vehicle.name)
            params = with_changes(preset, params) if params else preset
        elif not isinstance(params, type(self.vehicle.params)):
            raise ValueError(
                f"params must be a mapping of changes ({{'mass': 0.6}}) or a "
                f"{type(self.vehicle.params).__name__}, got "
                f"{type(params).__name__ if is_dataclass(params) else repr(params)}"
            )
        check_can_hover(params)
        self.vehicle = self.vehicle.with_params(params)
        self.params = params
        veh = self.vehicle
        self._n, self._k, self._m = veh.n_states, veh.n_rotors, veh.n_inputs
        self.effects = _effects(config.effects, veh.ndim, self._k)
        effects = self.effects
        if rhs is not None and (effects.drag or effects.wind):
            raise ValueError(
                "drag and wind are part of the ground-truth vector field; with rhs= only "
                "rotor_dynamics (the rhs's inputs are then the mixed, lagged rotor thrusts), "
                "sensor effects and rotor limits apply"
            )
        frac = effects.rotor_max_fraction or (1.0,) * self._k
        if len(frac) != self._k:
            raise ValueError(f"effects.rotor_max_fraction needs {self._k} entries, got {len(frac)}")
        self._frac = np.array(frac)
        self._rotor_state = effects.rotor_dynamics
        if self._rotor_state:  # RK4 steps no longer than the fastest rotor's time constant:
            # a recheck trial's tau = 3 ms at 10 ms steps diverged (thrusts of -1800 N), 5 ms
            # was 9 % off; randomised parameters reach (1 - spread) tau
            fastest = float(params.rotor_time_constant) * (1.0 - self.param_randomization)
            self.substeps = max(self.substeps, math.ceil(self.dt / fastest - 1e-9))
        self._n_ext = self._n + (self._k if self._rotor_state else 0)
        self.volume = config.volume
        self._custom_rhs = rhs
        self._range: tuple[FloatArray, FloatArray, FloatArray] | None = None
        self._rhs: Rhs = rhs if rhs is not None else veh.rhs
        self._trajectory_spec = self._check_trajectory(config.trajectory)
        self._mix = np.ascontiguousarray(params.mixer, dtype=np.float64)
        self._unmix = np.linalg.inv(self._mix)
        low, high = self._action_box(params)
        self._u_low, self._u_high = low, high
        self._u_center, self._u_half = 0.5 * (high + low), 0.5 * (high - low)
        self._box = np.stack([low, high])
        self._x_low, self._x_high = veh.state_bounds(self.volume)
        self._xbox = np.stack([self._x_low, self._x_high])
        obs_low, obs_high = veh.obs_bounds(self.volume)
        weights = np.asarray(veh.cost_weights, dtype=np.float64)
        self._nobs_vehicle = obs_low.size
        if self._rotor_state and effects.observe_rotors:
            f_hi = 2.0 * params.rotor_force_max
            obs_low = np.concatenate([obs_low, np.zeros(self._k)])
            obs_high = np.concatenate([obs_high, np.full(self._k, f_hi)])
            weights = np.concatenate([weights, np.zeros(self._k)])
        self._obs_low, self._obs_high = obs_low, obs_high
        self._obsbox = np.stack([obs_low, obs_high, weights])
        self._single_obs_space = spaces.Box(obs_low, obs_high, dtype=np.float64)
        if self.normalize_actions:
            # float32 as RL libraries expect; the physics converts to float64.
            self._single_act_space = spaces.Box(-1.0, 1.0, (low.size,), dtype=np.float32)
        else:
            self._single_act_space = spaces.Box(low, high, dtype=np.float64)
        self._consts = physics.pack_consts(
            self.dt, self.substeps, self.action_mode, self.normalize_actions, effects,
            self.obs_noise_std, veh.ndim,
        )  # fmt: skip
        self._P0 = physics.pack_params(params)[None, :]
        n_factors = len(self.vehicle.randomized_fields)
        self._n_offset = self._n if self.init_state_scale > 0 else 0
        self._n_uniforms = self._n_offset + (n_factors if self.param_randomization > 0 else 0)
        self._n_gust = self.vehicle.ndim if effects.gust_std > 0 else 0
        self._n_normals = self._n_gust + (self._obs_low.size if effects.obs_bias_std > 0 else 0)
        self._offset_scale = self.init_state_scale * np.asarray(veh.init_scale, dtype=np.float64)
        self._factor_of_entry = np.full(self._P0.shape[1], n_factors)
        self._more_factors = np.zeros((0, 2), dtype=np.int64)
        if self.param_randomization > 0:
            self._factor_of_entry, self._more_factors = self._randomised_entries(params)
        self._none = np.zeros((0, 0))  # rows of no draws
        self._unmix0 = np.ascontiguousarray(self._unmix[:, 0])
        self._delay = int(effects.obs_delay_steps)
        self._python_field = rhs is not None and getattr(rhs, "point_source", None) is None
        self._kernels = _kernels_of(self)
        self._work_array = self._work(1)
        self._rest_of: tuple[Any, FloatArray] = (None, np.zeros(0))
        self._n_table = int(round(self.duration / self.dt)) + 1
        self._t_table = np.arange(self._n_table) * self.dt

    def set_training_range(self, low: Any, high: Any) -> None:
        """Adds ``info["outside_training"]`` to each step: how far it went past a range.

        The value is the largest excursion of the state or the applied input beyond
        ``[low, high]`` (states then inputs; +-inf leaves one unbounded), in widths of that
        range; 0 inside.

        A surrogate sets its model's training range (:meth:`IdentifiedModel.training_box`):
        the model was tested only inside it, so a rollout with a large value leans on
        extrapolation (truncate it, or trust its returns less).
        """
        low, high = np.asarray(low, dtype=np.float64), np.asarray(high, dtype=np.float64)
        if low.shape != (self._n + self._m,) or high.shape != low.shape or np.any(low > high):
            raise ValueError(
                f"a training range needs {self._n + self._m} lows and highs (states then "
                f"inputs) with low <= high, got {low.shape} and {high.shape}"
            )
        width = np.where(np.isfinite(high - low), np.maximum(high - low, 1e-12), np.inf)
        self._range = (low, high, width)

    def _outside(self, states: FloatArray, inputs: FloatArray) -> FloatArray:
        """Per row, the largest excursion past the training range in its widths (0 inside)."""
        low, high, width = self._range
        v = np.concatenate([states, inputs], axis=-1)
        with np.errstate(invalid="ignore"):
            beyond = np.maximum(np.maximum(low - v, v - high), 0.0) / width
        return np.max(np.nan_to_num(beyond, nan=np.inf), axis=-1)

    def _action_box(self, params: Any) -> tuple[FloatArray, FloatArray]:
        """The physical action box of the configured action mode."""
        if self.action_mode == "collective":
            return self.vehicle.action_bounds(params)
        lo = np.full(self._k, float(params.rotor_force_min))
        hi = np.full(self._k, float(params.rotor_force_max))
        if self.action_mode == "rotor_thrusts":
            return lo, hi
        kt = float(params.rotor_thrust_per_speed2)
        if kt <= 0:
            raise ValueError(
                "action_mode='motor_speeds' needs a thrust coefficient; the "
                f"{self.config.vehicle!r} vehicle has none (try vehicle='crazyflie')"
            )
        return np.sqrt(lo / kt), np.sqrt(hi / kt)

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
        """Validates reset options; a ``trajectory`` applies to the episode(s) it starts."""
        if options is not None and not isinstance(options, Mapping):
            raise ValueError(
                f"reset options must be a dict (keys {list(_RESET_OPTIONS)}), got {options!r}"
            )
        options = dict(options or {})
        unknown = set(options) - set(_RESET_OPTIONS)
        if unknown:
            raise ValueError(
                f"unknown reset option(s) {sorted(unknown)}; valid options: {list(_RESET_OPTIONS)}"
            )
        if "trajectory" in options:
            options["trajectory"] = self._check_trajectory(options["trajectory"])
        return options

    def _check_state(self, state: Any, batch: tuple[int, ...]) -> FloatArray:
        """options['state']: n (or n + rotors with rotor dynamics) finite numbers per member."""
        x0 = np.asarray(state, dtype=np.float64)
        sizes = {self._n, self._n_ext}
        shapes = [(s,) for s in sorted(sizes)] + [batch + (s,) for s in sorted(sizes) if batch]
        if x0.shape not in shapes or not np.isfinite(x0).all():
            raise ValueError(
                f"options['state'] must be finite with shape {' or '.join(map(str, shapes))}, "
                f"got shape {x0.shape}"
            )
        return x0

    def _randomised_entries(self, params: Any) -> tuple[np.ndarray, np.ndarray]:
        """Which randomised field scales each entry of the parameter vector.

        Found by doubling each field: an entry that changes must double too (a parameter,
        or a property proportional to it such as the thrust per squared speed), so that a
        member's parameter vector is the nominal one times its factors. Returns the factor
        of each entry (the number of fields: none) and any further (entry, factor) pairs.
        """
        names = self.vehicle.randomized_fields
        nominal = physics.pack_params(params)
        first = np.full(nominal.size, len(names))
        more = []
        for k, name in enumerate(names):
            doubled = physics.pack_params(params.replace(**{name: getattr(params, name) * 2.0}))
            changed = np.flatnonzero(doubled != nominal)
            if not np.allclose(doubled[changed], 2.0 * nominal[changed], rtol=1e-12, atol=0.0):
                raise ValueError(f"randomised parameter {name!r} must scale the kernels' entries")
            for entry in changed:
                if first[entry] == len(names):
                    first[entry] = k
                else:
                    more.append((int(entry), k))
        return first, np.array(more, dtype=np.int64).reshape(-1, 2)

    def _randomised_params(self, factors: FloatArray) -> Any:
        """The parameter set scaled by factors (one per randomised field; arrays batch)."""
        names = self.vehicle.randomized_fields
        return self.params.replace(
            **{name: getattr(self.params, name) * f for name, f in zip(names, factors, strict=True)}
        )

    def _draw_episode(self, rng: np.random.Generator, spec: Any = None) -> _Draws:
        """Draws one episode from rng: its trajectory, uniforms, a seed, normals (3 calls).

        Only the draws run per member; :meth:`_episode_arrays` turns the draws of many
        members into their starts in one batch.
        """
        spec = self._trajectory_spec if spec is None else spec
        traj = (
            spec
            if isinstance(spec, Reference)
            else make_trajectory(spec, ndim=self.vehicle.ndim, rng=rng)
        )
        uniforms = rng.random(self._n_uniforms) if self._n_uniforms else None
        seed = rng.bit_generator.random_raw()
        normals = rng.standard_normal(self._n_normals) if self._n_normals else None
        return _Draws(traj, uniforms, seed, normals)

    def _episode_arrays(self, draws: list[_Draws]) -> tuple[FloatArray, ...]:
        """Batched start of the drawn episodes: (X0, P, seeds, gust, bias, factors).

        The single env calls it with one member, the vector env with the members it resets,
        so both compute every number the same way. ``P`` is ``_P0`` (one row) without
        parameter randomisation, ``factors`` then None.
        """
        r, n = len(draws), self._n
        X0 = np.empty((r, self._n_ext))
        if all(d.traj is self._rest_of[0] for d in draws):
            X0[:, :n] = self._rest_of[1]
        else:
            for j, d in enumerate(draws):
                if d.traj is not self._rest_of[0]:  # the rest state on a reference, reused
                    self._rest_of = (d.traj, self.vehicle.initial_state(d.traj(0.0)))
                X0[j, :n] = self._rest_of[1]
        U = np.array([d.uniforms for d in draws]) if self._n_uniforms else self._none
        N = np.array([d.normals for d in draws]) if self._n_normals else self._none
        randomised = self.param_randomization > 0
        P = np.empty((r, self._P0.shape[1])) if randomised else self._P0
        F = np.empty((r, len(self.vehicle.randomized_fields)))
        gust, bias = np.empty((r, self.vehicle.ndim)), np.empty((r, self._obs_low.size))
        self._starts(X0, U, self._n_offset, self.param_randomization, N, P, F, gust, bias)
        seeds = np.array([d.seed for d in draws], dtype=np.uint64)
        return X0, P, seeds, gust, bias, (F if randomised else None)

    def _starts(self, X0: FloatArray, U: FloatArray, n_offset: int, spread: float,
                N: FloatArray, P: FloatArray, F: FloatArray, gust: FloatArray,
                bias: FloatArray) -> None:  # fmt: skip
        """:func:`quad_envs.physics.episode_starts` with this env's constants."""
        physics.episode_starts(
            X0, self._n, U, n_offset, self._offset_scale, spread, self._P0[0],
            self._factor_of_entry, self._more_factors, self._unmix0, self._frac, N,
            self.effects.gust_std, self.effects.obs_bias_std, P, F, gust, bias,
        )  # fmt: skip

    def _set_state(self, x: FloatArray, state: FloatArray, P: FloatArray) -> None:
        """Writes a reset-option state (rigid part, and rotor thrusts if given) into x.

        ``P`` is the member's parameter vector as a (1, len) row.
        """
        x[: state.size] = state
        if self._rotor_state and state.size == self._n:  # the hover thrusts, as at reset
            none = self._none
            self._starts(x[None, :], none, 0, 0.0, none, P, P[:0], P[:1, :0], P[:1, :0])

    def action_from_input(self, u: FloatArray) -> FloatArray:
        """The action that commands the collective input ``u`` (clipped into the action box).

        The inverse of the env's action mapping: ``u`` goes to rotor thrusts (and motor
        speeds) for those action modes; with ``normalize_actions`` the result is mapped
        affinely into [-1, 1].
        """
        u = np.asarray(u, dtype=np.float64)
        if self.action_mode == "collective":
            phys = u
        else:
            phys = u @ self._unmix.T
            if self.action_mode == "motor_speeds":
                kt = float(self.params.rotor_thrust_per_speed2)
                phys = np.sqrt(np.maximum(phys, 0.0) / kt)
        if self.normalize_actions:
            action = np.clip((phys - self._u_center) / self._u_half, -1.0, 1.0)
        else:
            action = np.clip(phys, self._u_low, self._u_high)
        return action.astype(self._single_act_space.dtype)

    def _rotor_commands(self, A: FloatArray, active: Any = None) -> FloatArray:
        """The thrust each rotor was commanded by actions ``A`` (b, k), after its limits.

        With rotor dynamics these are the inputs of the thrust states, held over the step
        (``info['rotor_commands']``); members not stepped (``active`` false) get zeros.
        """
        thrust = np.zeros((A.shape[0], self._k))
        A = np.ascontiguousarray(A, dtype=np.float64)
        physics.rotor_command_batch(
            A, self._P, self._consts, self._mix, self._unmix, self._box, self._frac, thrust,
            self._work_array,
        )  # fmt: skip
        if active is not None:
            thrust[~active] = 0.0
        return thrust

    def _work(self, b: int) -> FloatArray:
        """Scratch array of the kernels (see ``kernel_template.step``)."""
        width = max(self._n_ext, self._k, self.vehicle.ndim, self._u_low.size)
        return np.empty((8, width))

    def _advance(
        self, X: FloatArray, A: FloatArray, refs: FloatArray, P: FloatArray, rng: Any,
        gust: FloatArray, bias: FloatArray, active: FloatArray, rhs: Rhs,
    ) -> tuple[FloatArray, ...]:  # fmt: skip
        """One control step of the members in place: (obs, reward, end, u, u_cmd)."""
        kern = self._kernels
        if A.dtype != np.float64 or not A.flags.c_contiguous:
            A = np.ascontiguousarray(A, dtype=np.float64)
        b = X.shape[0]
        obs = np.empty((b, self._obsbox.shape[1]))
        reward, end = np.empty(b), np.empty(b, dtype=bool)
        u, u_cmd = np.empty((b, self._m)), np.empty((b, self._m))  # every row written
        if not self._python_field:
            ok = kern.step(
                X, A, refs, P, self._consts, rng, gust, bias, self._mix, self._unmix,
                self._box, self._frac, self._obsbox, self._xbox, active, obs, reward, end,
                u, u_cmd, self._work_array,
            )  # fmt: skip
        else:
            ok = kern.command(
                A, P, self._consts, self._mix, self._unmix, self._box, self._frac, u, u_cmd,
                self._work_array,
            )  # fmt: skip
            if ok:
                if not active.all():
                    u[~active] = 0.0
                    u_cmd[~active] = 0.0
                if self._rotor_state:  # the thrust states follow the limited rotor commands
                    thrust = np.empty((b, self._k))
                    physics.rotor_command_batch(
                        A, P, self._consts, self._mix, self._unmix, self._box, self._frac,
                        thrust, self._work_array,
                    )  # fmt: skip
                    thrust = thrust[active]
                    tau = P[:, physics.P_TAU] if P.shape[0] == 1 else P[active, physics.P_TAU]
                    field = physics.RotorLagField(rhs, self._mix, self._n, tau[:, None])
                    X[active] = rk4_step(field, X[active], thrust, self.dt, self.substeps)
                    u[active] = X[active, self._n :] @ self._mix.T  # applied: at the step's end
                else:
                    X[active] = rk4_step(rhs, X[active], u[active], self.dt, self.substeps)
                kern.finish(
                    X, refs, self._consts, rng, bias, self._obsbox, self._xbox, obs, reward, end
                )
        if not ok:
            raise ValueError(f"action must be finite (no NaN or inf), got {A!r}")
        return obs, reward, end, u, u_cmd

    def _observe_all(
        self, X: FloatArray, refs: FloatArray, rng: Any, bias: FloatArray
    ) -> FloatArray:
        """Observations of the members (no step), e.g. at reset."""
        b = X.shape[0]
        obs = np.empty((b, self._obsbox.shape[1]))
        reward, end = np.empty(b), np.empty(b, dtype=bool)
        self._kernels.finish(
            X, refs, self._consts, rng, bias, self._obsbox, self._xbox, obs, reward, end
        )
        return obs


class QuadrotorEnv(_EnvCore, gym.Env):
    """A quadrotor tracking a reference; subclasses fix the vehicle (see their docstrings).

    Args:
        render_mode: ``rgb_array`` (frames) or ``human`` (a matplotlib window: needs a display;
            without one nothing is shown).
        rhs: Vector field replacing the ground-truth physics (surrogate models). With
            ``rotor_dynamics`` its input is the mix of the rotor-thrust states: a model
            whose inputs act through a first-order lag, stepped with its actuators.
        **options: The fields of :class:`EnvConfig` (``trajectory``, ``dt``, ``substeps``,
            ``duration``, ``normalize_actions``, ``init_state_scale``, ``obs_noise_std``,
            ``param_randomization``, ``params``, ``volume``, ``vehicle``, ``effects``,
            ``action_mode``).

    Info keys: ``state`` (rigid-body state), ``reference``, ``action`` (the collective input
    the rotors applied; with rotor dynamics, at the end of the step), ``commanded`` (the
    collective input commanded, before the rotor limits), ``rotor_thrusts`` (with rotor
    dynamics: the rotor thrust states [N]), ``rotor_commands`` (with rotor dynamics, after a
    step: the thrust each rotor was commanded over it, after its limits [N]), ``time``.
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 100}

    def __init__(
        self, render_mode: str | None = None, rhs: Rhs | None = None, **options: Any
    ) -> None:
        self._configure(EnvConfig.from_options(options), rhs)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode must be one of {self.metadata['render_modes']}, got {render_mode!r}"
            )
        # One frame per control step: the video plays in real time.
        self.metadata = {**self.metadata, "render_fps": int(round(1.0 / self.dt))}
        self.render_mode = render_mode
        self.observation_space = self._single_obs_space
        self.action_space = self._single_act_space
        self._X = np.zeros((1, self._n_ext))
        self._k_step = 0
        self._was_reset = False
        self._renderer: Any = None
        self._trail: list[FloatArray] = []
        self._active = np.ones(1, dtype=bool)

    @property
    def state(self) -> FloatArray:
        """The true rigid-body state (a copy)."""
        return self._X[0, : self._n].copy()

    @property
    def time(self) -> float:
        """Simulated time since reset [s]."""
        return self._k_step * self.dt

    def _reference(self, k: int) -> FloatArray:
        if k < self._n_table:
            return self._refs[k]
        return self._traj(k * self.dt)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[FloatArray, dict[str, Any]]:
        """Starts an episode; options: ``trajectory`` (this episode only), ``state``."""
        super().reset(seed=seed)
        options = self._check_options(options)
        draws = self._draw_episode(self.np_random, options.get("trajectory"))
        X0, self._P, self._rng, self._gust, self._bias, factors = self._episode_arrays([draws])
        self._traj = draws.traj
        self._refs = draws.traj(self._t_table)
        if factors is not None and self._custom_rhs is None:
            self._rhs = self.vehicle.with_params(self._randomised_params(factors[0])).rhs
        if "state" in options:
            self._set_state(X0[0], self._check_state(options["state"], ()), self._P)
        self._X = X0
        self._k_step = 0
        self._was_reset = True
        self._trail = [self._X[0, : self._n].copy()]
        obs = self._observe_all(self._X, self._refs[:1], self._rng, self._bias)[0]
        if self._delay:
            self._history = deque([obs] * (self._delay + 1), maxlen=self._delay + 1)
            obs = self._history[0].copy()
        zero_u = np.zeros(self._m)
        return obs, self._info(self._refs[0], zero_u, zero_u)

    def step(self, action: Any) -> tuple[FloatArray, float, bool, bool, dict[str, Any]]:
        """Holds the action over dt (RK4); returns (obs, reward, terminated, False, info)."""
        if not self._was_reset:
            raise gym.error.ResetNeeded("call reset() before step()")
        a = action if isinstance(action, np.ndarray) else np.asarray(action, dtype=np.float64)
        if a.shape != self._u_low.shape:
            raise ValueError(f"action must have shape {self._u_low.shape}, got {a.shape}")
        ref = self._reference(self._k_step + 1)
        obs, reward, end, u, u_cmd = self._advance(
            self._X, a.reshape(1, -1), ref.reshape(1, -1), self._P, self._rng, self._gust,
            self._bias, self._active, self._rhs,
        )  # fmt: skip
        self._k_step += 1
        terminated = bool(end[0])
        obs = obs[0]
        if self._delay:
            self._history.append(obs)
            obs = self._history[0].copy()
        if self.render_mode is not None:
            self._trail.append(self._X[0, : self._n].copy())
            if self.render_mode == "human":
                self.render()
        info = self._info(ref, u[0], u_cmd[0])
        if self._rotor_state:
            # the step kernels leave the (one) member's limited rotor commands in their
            # scratch row 5; recomputing them took 0.7 us of an 11 us step
            info["rotor_commands"] = self._work_array[5, : self._k].copy()
        info["out_of_bounds"] = terminated
        if self._range is not None:
            info["outside_training"] = float(self._outside(info["state"], u[0]))
        return obs, float(reward[0]), terminated, False, info

    def _info(self, ref: FloatArray, u: FloatArray, u_cmd: FloatArray) -> dict[str, Any]:
        info = {
            "state": self._X[0, : self._n].copy(),
            "reference": ref.copy(),
            "action": u,
            "commanded": u_cmd,
            "time": self._k_step * self.dt,
        }
        if self._rotor_state:
            info["rotor_thrusts"] = self._X[0, self._n :].copy()
        return info

    def render(self) -> FloatArray | None:
        """Draws the vehicle, the reference and the trail (``rgb_array`` returns the image)."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode= to make()")
            return None
        from quad_envs.rendering import QuadRenderer

        if self._renderer is None:
            self._renderer = QuadRenderer(self.vehicle, self.render_mode, self.metadata)
        refs = self._refs[: min(self._n_table, self._k_step + 1)]
        return self._renderer.draw(
            self._X[0, : self._n], np.array(self._trail), refs, self._k_step * self.dt
        )

    def close(self) -> None:
        """Closes the render window."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_renderer"] = None  # a figure does not pickle; it is rebuilt on demand
        state["_kernels"] = None
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._kernels = _kernels_of(self)


def _kernels_of(env: _EnvCore) -> physics.Kernels:
    """The compiled kernels of an env's vector field."""
    rhs = env._custom_rhs
    if rhs is not None and getattr(rhs, "point_source", None) is not None:
        return physics.point_rhs_kernels(env.vehicle, rhs.point_source)
    return physics.vehicle_kernels(env.vehicle)


class QuadrotorVectorEnv(_EnvCore, VectorEnv):
    """Native batched version of :class:`QuadrotorEnv` (same arguments, plus ``num_envs``).

    Member i is seeded with ``seed + i`` and draws its episodes exactly as a single env
    seeded that way, so the vector env equals N single envs step for step. Autoreset is
    Gymnasium's NEXT_STEP mode; truncation comes from ``max_episode_steps``. A reset
    option ``trajectory`` applies to the episodes that reset starts (autoresets go back to
    the configured one); ``state`` is one state for all members or one per member.
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
        self.metadata = {**self.metadata, "render_fps": int(round(1.0 / self.dt))}
        self.num_envs = int(num_envs)
        self.max_episode_steps = max_episode_steps
        self.render_mode = render_mode
        self.single_observation_space = self._single_obs_space
        self.single_action_space = self._single_act_space
        self.observation_space = batch_space(self._single_obs_space, self.num_envs)
        self.action_space = batch_space(self._single_act_space, self.num_envs)
        b = self.num_envs
        self._states = np.zeros((b, self._n_ext))
        self._steps = np.zeros(b, dtype=np.int64)
        self._needs_reset = np.zeros(b, dtype=bool)
        self._rngs = [np.random.default_rng() for _ in range(b)]
        self._trajs: list[Reference] = []
        self._factors = np.ones((b, len(self.vehicle.randomized_fields)))
        self._rng_state = np.zeros(b, dtype=np.uint64)
        self._gust = np.zeros((b, self.vehicle.ndim))
        self._bias = np.zeros((b, self._obs_low.size))
        # The parameter vector of every member, or the nominal one shared by all.
        self._P = np.tile(self._P0, (b, 1)) if self.param_randomization > 0 else self._P0
        self._all_active = np.ones(b, dtype=bool)
        self._steps_bound = 0  # no member has taken more steps since its reset
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
        state = None
        if "state" in options:
            state = self._check_state(options["state"], (self.num_envs,))
        self._trajs = [None] * self.num_envs  # type: ignore[list-item]
        self._reset_members(np.arange(self.num_envs), state, options.get("trajectory"))
        self._refresh_episode_tables()
        self._needs_reset[:] = False
        self._steps_bound = 0
        self._was_reset = True
        refs = self._references()
        obs = self._observe_all(self._states, refs, self._rng_state, self._bias)
        if self._delay:
            # The observations still to return, oldest first: each step appends the new one
            # and returns (hands over) the oldest, so no observation is copied.
            self._pending = deque(obs.copy() for _ in range(self._delay))
        zero_u = np.zeros((self.num_envs, self._m))  # a policy reading info acts at once
        return obs, self._info_all(refs, zero_u, zero_u.copy())

    def _reset_members(self, rows: np.ndarray, state: Any = None, spec: Any = None) -> None:
        """Starts new episodes of the members in rows: each draws from its own generator.

        Only the draws run per member; the rest is one batched computation
        (:meth:`_episode_arrays`, as the single env's reset).
        """
        draws = [self._draw_episode(self._rngs[i], spec) for i in rows]
        X0, P, seeds, gust, bias, factors = self._episode_arrays(draws)
        for j, i in enumerate(rows):
            self._trajs[i] = draws[j].traj
            if state is not None:
                P_j = P[j : j + 1] if factors is not None else P
                self._set_state(X0[j], state if state.ndim == 1 else state[i], P_j)
        self._states[rows] = X0
        self._rng_state[rows] = seeds
        self._gust[rows] = gust
        self._bias[rows] = bias
        if factors is not None:
            self._factors[rows] = factors
            self._P[rows] = P
        self._steps[rows] = 0

    def _update_episode_rows(self, rows: np.ndarray) -> None:
        """After an autoreset: writes the new members' waypoints in place."""
        if isinstance(self._batched_traj, RandomWaypoints):
            for i in rows:
                self._batched_traj.waypoints[i] = self._trajs[i].waypoints  # type: ignore[attr-defined]
        elif isinstance(self._batched_traj, _ListTrajectory):
            pass  # holds self._trajs itself
        elif self._batched_traj is None and any(self._trajs[i] is not self._trajs[0] for i in rows):
            self._refresh_episode_tables()  # an autoreset left a per-reset trajectory

    def _refresh_episode_tables(self) -> None:
        """Builds the batched reference source (and, if randomised, the batched rhs)."""
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
        if self.param_randomization > 0 and self._custom_rhs is None:
            self._rhs = self.vehicle.with_params(self._randomised_params(self._factors.T)).rhs

    def _references(self) -> FloatArray:
        if self._batched_traj is None:
            refs = np.take(self._shared_refs, self._steps, axis=0, mode="clip")
            if self._steps_bound >= self._n_table:  # some member may be past the table
                late = self._steps >= self._n_table
                if late.any():
                    refs[late] = self._trajs[0](self._steps[late] * self.dt)
            return refs
        return self._batched_traj(self._steps * self.dt)

    def step(
        self, actions: Any
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, dict[str, Any]]:
        """Steps every member; members that ended last step are reset instead (NEXT_STEP)."""
        if not self._was_reset:
            raise gym.error.ResetNeeded("call reset() before step() on a vector env")
        a = actions if isinstance(actions, np.ndarray) else np.asarray(actions, dtype=np.float64)
        expected = (self.num_envs,) + self._u_low.shape
        if a.shape != expected:
            raise ValueError(f"action must have shape {expected}, got {a.shape}")
        resetting = self._needs_reset
        any_reset = bool(resetting.any())
        self._steps_bound += 1
        if any_reset:
            rows = np.flatnonzero(resetting)
            self._reset_members(rows)
            self._update_episode_rows(rows)
            active = ~resetting
            self._steps[active] += 1
        else:
            active = self._all_active
            self._steps += 1
        refs = self._references()
        obs, reward, end, u, u_cmd = self._advance(
            self._states, a, refs, self._P, self._rng_state, self._gust, self._bias,
            active, self._rhs,
        )  # fmt: skip
        if any_reset:
            terminated = end & active
            reward[resetting] = 0.0
        else:
            terminated = end
        if self.max_episode_steps is not None and self._steps_bound >= self.max_episode_steps:
            truncated = self._steps >= self.max_episode_steps
            if any_reset:
                truncated &= active
        else:
            truncated = np.zeros(self.num_envs, dtype=bool)
        if self._delay:
            if any_reset:  # a new episode repeats its first observation
                for old in self._pending:
                    old[resetting] = obs[resetting]
            self._pending.append(obs)
            obs = self._pending.popleft()
        self._needs_reset = terminated | truncated
        info = self._info_all(refs, u, u_cmd)
        if self._rotor_state:
            info["rotor_commands"] = self._rotor_commands(a, active)
        info["out_of_bounds"] = terminated.copy()  # as the single env's step info
        if self._range is not None:
            info["outside_training"] = np.where(resetting, 0.0, self._outside(info["state"], u))
        return obs, reward, terminated, truncated, info

    def _info_all(self, refs: FloatArray, u: FloatArray, u_cmd: FloatArray) -> dict[str, Any]:
        """The single env's info, member by member (one copy of the states; views of it)."""
        states = self._states.copy()
        info = {
            "state": states[:, : self._n],
            "reference": refs,
            "action": u,
            "commanded": u_cmd,
            "time": self._steps * self.dt,
        }
        if self._rotor_state:
            info["rotor_thrusts"] = states[:, self._n :]
        return info

    def render(self) -> FloatArray | None:
        """Draws member 0 (``rgb_array``)."""
        if self.render_mode != "rgb_array":
            return None
        from quad_envs.rendering import QuadRenderer

        if getattr(self, "_renderer", None) is None:
            self._renderer = QuadRenderer(self.vehicle, "rgb_array", self.metadata)
        refs = self._trajs[0](self._t_table[: int(self._steps[0]) + 1])
        return self._renderer.draw(
            self._states[0, : self._n], self._states[:1, : self._n], refs, self._steps[0] * self.dt
        )

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_renderer"] = None
        state["_kernels"] = None
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._kernels = _kernels_of(self)


class _ListTrajectory(Reference):
    """Per-member trajectories of mixed kinds, evaluated one by one."""

    def __init__(self, trajs: list[Reference]) -> None:
        self.trajs, self.ndim = trajs, trajs[0].ndim

    def __call__(self, t: FloatArray | float) -> FloatArray:
        t = np.asarray(t, dtype=np.float64)
        return np.stack([traj(ti) for traj, ti in zip(self.trajs, t, strict=True)])
