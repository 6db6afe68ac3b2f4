"""Identified models as Gymnasium environments (surrogates of the ground truth).

A surrogate is the base environment class itself (same spaces, tasks, reward, termination,
saturation and RK4) with the ground-truth vector field replaced by the model's compiled
``rhs``. States that leave the flight volume or become non-finite end the episode as
``terminated`` with ``info["out_of_bounds"]`` set, and the observation stays finite. Where the
model file records its training range, each step's ``info["outside_training"]`` says how far
the rollout went past it (in widths of the range; 0 inside): the model was tested only there.

A model whose inputs act through a first-order lag (identified with ``--input-lag``:
``meta["input_lag"]`` = tau) steps with its actuators: its surrogate is the env with rotor
dynamics at that time constant, the model driven by the mix of the rotor-thrust states (the
lag is linear and the same for every rotor, so those are the lagged commands it was fitted
to). Its observation then ends with the rotor thrusts, as the ground truth's with rotor
dynamics (``effects={"observe_rotors": False}`` drops them).
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.envs.registration import load_env_creator, register, registry

import quad_envs
import quad_envs.envs.base as quad_envs_base
from identification.model import IdentifiedModel, load_model
from quad_envs import physics
from quad_envs.integrators import rk4_step


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
        model = load_model(_model_path(model, "an IdentifiedModel"))
    vehicle = cls.vehicle
    ours = (model.state_names, model.input_names)
    theirs = (vehicle.state_names, vehicle.input_names)
    if ours != theirs and (set(ours[0]), set(ours[1])) == (set(theirs[0]), set(theirs[1])):
        model = _in_order(model, *theirs)  # the same variables, logged in another order
    elif ours != theirs:
        raise ValueError(_mismatch(model, base_id, theirs))
    return model, cls


def _lag_options(model: IdentifiedModel, kwargs: dict[str, Any]) -> dict[str, Any]:
    """The env options of a model whose inputs act through a first-order lag, merged.

    A model identified with ``--input-lag`` (``meta["input_lag"]`` = tau) is fitted to
    commands that reach the vehicle through ``a' = (c - a) / tau``. Its surrogate is the env
    with rotor dynamics at that time constant: the lag is linear and the same for every
    rotor, so the mixed rotor-thrust states are the lagged commands the model was fitted to
    (and reset puts them at hover). The settings are merged into the user's ``effects`` and
    ``params``; an :class:`~quad_envs.physics.Effects` or a parameter set names every field,
    so it is given them; a spec that names them otherwise (``{"rotor_dynamics": False}``,
    a change of ``rotor_time_constant`` to another value) is a one-line ValueError.
    """
    lag = float(model.meta.get("input_lag", 0.0))
    if not lag:
        return kwargs
    options = dict(kwargs)
    effects = options.get("effects")
    if effects is None:
        effects = ["rotor_dynamics"]
    elif isinstance(effects, str):
        effects = effects if effects == "all" else [effects, "rotor_dynamics"]
    elif isinstance(effects, list | tuple):
        effects = [*effects, *(() if "rotor_dynamics" in effects else ("rotor_dynamics",))]
    elif isinstance(effects, Mapping):
        off = effects.get("rotor_dynamics", True)
        if isinstance(off, bool | np.bool_) and not off:
            raise ValueError(
                f"the model's inputs act through a first-order lag of {lag:g} s (identified "
                "with --input-lag): its surrogate steps them with rotor dynamics, and "
                "effects asks for rotor_dynamics=False"
            )
        effects = {"rotor_dynamics": True, **effects}
    elif isinstance(effects, physics.Effects):
        effects = dataclasses.replace(effects, rotor_dynamics=True)
    options["effects"] = effects  # anything else: the env names what is wrong with it
    params = options.get("params")
    if params is None or isinstance(params, Mapping):
        changes = dict(params or {})
        asked = changes.get("rotor_time_constant", lag)
        try:
            other = not math.isclose(float(asked), lag, rel_tol=1e-9, abs_tol=0.0)
        except (TypeError, ValueError):
            other = False  # not a number: the env's parameter check names it
        if other:
            raise ValueError(
                f"the model's inputs act through a first-order lag of {lag:g} s (identified "
                f"with --input-lag), its surrogate's rotor time constant; params asks for "
                f"rotor_time_constant={asked}"
            )
        changes.setdefault("rotor_time_constant", lag)
        options["params"] = changes
    elif dataclasses.is_dataclass(params) and hasattr(params, "rotor_time_constant"):
        options["params"] = dataclasses.replace(params, rotor_time_constant=lag)
    return options


def _model_path(model: Any, kind: str) -> str | os.PathLike:
    """``model`` where it names a file; a ValueError naming ``model=`` for anything else."""
    if not isinstance(model, str | os.PathLike):
        raise ValueError(f"model= takes {kind} or the path of its JSON file, got {model!r}")
    return model


def _in_order(model: IdentifiedModel, states: tuple, inputs: tuple) -> IdentifiedModel:
    """The model with its states (rows) and inputs in the given order (features are names)."""
    rows = [model.state_names.index(n) for n in states]
    pick = lambda a: None if a is None else a[rows]  # noqa: E731
    return IdentifiedModel(model.feature_names, model.coefficients[rows], states, inputs,
                           model.system, model.meta, pick(model.coefficient_std),
                           pick(model.inclusion_probability))  # fmt: skip


def _mismatch(model: IdentifiedModel, base_id: str, theirs: tuple) -> str:
    """Why a model cannot step ``base_id``'s vehicle, with what would fix it."""
    from quad_envs.vehicles import vehicles_with

    head = (f"model variables {model.state_names} / {model.input_names} do not match "
            f"{base_id}'s {theirs[0]} / {theirs[1]}")  # fmt: skip
    if not model.input_names:
        return head + ": the model has no inputs, and a surrogate env steps with actions"
    owner = next(iter(vehicles_with(model.state_names, model.input_names)), None)
    if owner is not None:
        return head + f": it is a model of the {owner} vehicle; use that vehicle's env"
    extra = set(model.state_names) - set(theirs[0])
    if extra and all(re.fullmatch(r"T\d+", n) for n in extra):
        return head + (
            ": a model with rotor-thrust states (rollouts of an env with rotor dynamics) has "
            "no surrogate env: the surrogates step the rigid body under the collective input "
            "(identify from flights without rotor dynamics, or fly the model with "
            "model.simulate)"
        )
    return head + (
        f": a surrogate steps its vehicle's variables, so identify from a log of those "
        f"quantities (inputs {', '.join(theirs[1])}: the collective thrust and moments, what "
        "the env reports as info['action'] in every action mode); --columns renames a CSV's "
        "columns only where they hold the same quantities (rotor thrusts or motor speeds "
        "renamed u1, u2 give a wrong surrogate)"
    )


def surrogate_rhs(model: IdentifiedModel, cls: Any, compiled: bool = True) -> Any:
    """The rhs a surrogate env steps: the model compiled into the env's kernel, or numpy.

    The compiled rhs (:func:`identification.compiled.compiled_rhs`) is built and compiled
    here (numba caches it on disk, keyed by the model's generated source: a model costs its
    compile time once per machine). If numba fails, the model's numpy ``rhs`` is returned
    with a warning (the env then integrates it in Python, several times slower).
    """
    if not compiled:
        return model.rhs
    try:
        from identification.compiled import compiled_rhs

        rhs = compiled_rhs(model)
        vehicle = cls.vehicle
        kernels = physics.point_rhs_kernels(vehicle, rhs.point_source)
        n_obs = vehicle.obs_bounds(quad_envs_base.DEFAULT_VOLUME)[0].size
        physics.warm_up(
            kernels, vehicle.n_states, vehicle.n_inputs, n_obs, vehicle.ndim,
            vehicle.params.mixer,
        )  # fmt: skip
    except Exception as error:  # noqa: BLE001  (any numba or file-system failure)
        warnings.warn(
            f"compiling the model's rhs with numba failed ({type(error).__name__}: {error}); "
            "the surrogate steps the numpy rhs instead (slower)",
            RuntimeWarning,
            stacklevel=3,
        )
        return model.rhs
    return rhs


GAIN_MISMATCH = 0.1
"""Relative difference of the model's and the vehicle's response to an input at hover above
which :func:`check_vehicle` warns."""

HOVER_MISMATCH = 1.0
"""Largest acceleration [m/s^2 or rad/s^2] the model may predict at rest under the env
vehicle's hover input before :func:`check_vehicle` warns."""


def check_vehicle(model: IdentifiedModel, vehicle: Any) -> str | None:
    """A warning when the env's vehicle cannot be the model's: the model does not hover at it.

    The surrogate takes its action limits, saturation and hover trim from the env's vehicle
    parameters (``params`` / ``vehicle``; the paper vehicle by default), the model only its
    vector field. A model of another vehicle flown there falls at full thrust or cannot be
    held (a 0.6 kg model in the paper vehicle's 3.5 N box trained an agent on a vehicle that
    cannot fly, exit 0). At rest, under the vehicle's hover input (weight as thrust, no
    moments), the model's accelerations should vanish.
    """
    hover = np.zeros(len(model.input_names))
    hover[0] = float(vehicle.params.hover_thrust)
    rest = np.zeros((1, len(model.state_names)))
    accel = np.asarray(model.rhs(rest, hover[None, :]))[0]
    worst = int(np.argmax(np.abs(accel)))
    fix = (
        "set the env's vehicle to the model's (params={'mass': ...} or vehicle=..., "
        "--param/--vehicle on the command line): its action limits and trim are the env's"
    )
    if abs(accel[worst]) > HOVER_MISMATCH:
        return (
            f"the model does not hover at this env's vehicle: at rest under its hover thrust "
            f"{hover[0]:.3g} N it predicts {model.state_names[worst]}' = {accel[worst]:.3g}; " + fix
        )
    # the response to each input at hover: an inertia the user forgot to set (a trial's
    # exact model parted from "the truth" at 0.02 s without a word)
    step = 1e-3 * max(hover[0], 1.0)
    base = np.asarray(vehicle.rhs(rest[0], hover), dtype=np.float64)
    for j, name in enumerate(model.input_names):
        pushed = hover.copy()
        pushed[j] += step
        ours = (np.asarray(model.rhs(rest, pushed[None, :]))[0] - accel) / step
        theirs = (np.asarray(vehicle.rhs(rest[0], pushed), dtype=np.float64) - base) / step
        gap = np.linalg.norm(ours - theirs) / max(np.linalg.norm(theirs), 1e-12)
        if gap > GAIN_MISMATCH:
            k = int(np.argmax(np.abs(theirs)))
            return (
                f"the model's response to {name} at hover differs from this env's vehicle by "
                f"{gap:.0%} ({model.state_names[k]}' per unit {name}: {ours[k]:.4g} in the "
                f"model, {theirs[k]:.4g} in the vehicle); " + fix
            )
    return None


def _warn_vehicle(model: IdentifiedModel, env: Any) -> None:
    problem = check_vehicle(model, env.vehicle)
    if problem:
        warnings.warn(problem, RuntimeWarning, stacklevel=3)


def _attach(model: IdentifiedModel, env: Any) -> None:
    """Gives a surrogate env its model and its training range; warns of a vehicle mismatch."""
    env.model = model
    box = model.training_box()
    if box is not None:
        env.set_training_range(*box)
    _warn_vehicle(model, env)


def make_surrogate(
    model: IdentifiedModel | str | Path | None = None,
    base_id: str = "PlanarQuad-v0",
    compiled: bool = True,
    **kwargs: Any,
) -> gym.Env:
    """A single surrogate env: the base env stepping the model.

    The model runs compiled inside the env's kernel (:func:`surrogate_rhs`);
    ``compiled=False`` steps the numpy ``model.rhs`` (no compile time). A model with an
    input lag gets rotor dynamics at that time constant (:func:`_lag_options`).
    """
    model, cls = _resolve(model, base_id, vector=False)
    options = _lag_options(model, kwargs)  # a conflict is named before the compile
    env = cls(rhs=surrogate_rhs(model, cls, compiled), **options)
    _attach(model, env)
    return env


def make_surrogate_vector(
    model: IdentifiedModel | str | Path | None = None,
    base_id: str = "PlanarQuad-v0",
    num_envs: int = 1,
    compiled: bool = True,
    **kwargs: Any,
) -> gym.vector.VectorEnv:
    """A native vector surrogate env (the model compiled as in :func:`make_surrogate`)."""
    model, cls = _resolve(model, base_id, vector=True)
    options = _lag_options(model, kwargs)
    env = cls(num_envs=num_envs, rhs=surrogate_rhs(model, cls, compiled), **options)
    _attach(model, env)
    return env


def _rotorcraft_env(model: Any, vector: bool, kwargs: dict[str, Any]) -> tuple[Any, dict]:
    """The motor-speed env class and its options for a rotorcraft model (or its JSON path)."""
    from identification.rotorcraft import RotorcraftModel, load_rotorcraft
    from quad_envs.envs.crazyflie import CrazyflieMotorsEnv, CrazyflieMotorsVectorEnv
    from quad_envs.params import with_changes
    from quad_envs.vehicles.crazyflie_motors import CRAZYFLIE_MOTOR_SPEEDS, MotorSpeedParams

    if model is None:
        raise ValueError("a rotorcraft surrogate needs model= (a RotorcraftModel or its JSON path)")
    if not isinstance(model, RotorcraftModel):
        model = load_rotorcraft(_model_path(model, "a RotorcraftModel"))
    params = kwargs.pop("params", None) or CRAZYFLIE_MOTOR_SPEEDS
    if isinstance(params, Mapping):  # changes to the nominal vehicle, as the env takes them
        params = with_changes(CRAZYFLIE_MOTOR_SPEEDS, params)
    if not isinstance(params, MotorSpeedParams):
        raise ValueError(
            f"params must be a mapping of changes or a MotorSpeedParams, got {params!r}"
        )
    # Reset at the speeds the identified model hovers at (its own thrust and trim).
    params = params.replace(hover_speeds=tuple(float(s) for s in model.hover_speeds()))
    cls = CrazyflieMotorsVectorEnv if vector else CrazyflieMotorsEnv
    return model, cls, {**kwargs, "params": params}


def make_rotorcraft_surrogate(model: Any = None, **kwargs: Any) -> gym.Env:
    """The Crazyflie motor-speed env stepping a model identified from real flights.

    The :class:`identification.rotorcraft.RotorcraftModel` (or its JSON path) replaces the
    nominal physics of ``CrazyflieMotors-v0``: its 16 states (rigid body and actuator
    states) and motor-speed inputs are that vehicle's, the actuator states start at the
    model's hover speeds (:meth:`RotorcraftModel.hover_speeds`). Its numpy ``rhs`` is
    integrated by the env's RK4 (no compiled kernel).
    """
    model, cls, options = _rotorcraft_env(model, False, dict(kwargs))
    env = cls(rhs=model.rhs, **options)
    env.model = model
    return env


def make_rotorcraft_surrogate_vector(
    model: Any = None, num_envs: int = 1, **kwargs: Any
) -> gym.vector.VectorEnv:
    """Native vector version of :func:`make_rotorcraft_surrogate`."""
    model, cls, options = _rotorcraft_env(model, True, dict(kwargs))
    env = cls(num_envs=num_envs, rhs=model.rhs, **options)
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


# -- ensembles ------------------------------------------------------------------------------
ENSEMBLE_MODES = ("median", "sample")


class EnsembleRhs:
    """The vector fields of K models over one library, evaluated for K states at once.

    Args:
        models: Models with the same state, input and feature names.
    """

    def __init__(self, models: Sequence[IdentifiedModel]) -> None:
        if not models:
            raise ValueError("an ensemble needs at least one model")
        first = models[0]
        names = (first.state_names, first.input_names, first.feature_names)
        for model in models[1:]:
            if (model.state_names, model.input_names, model.feature_names) != names:
                raise ValueError("ensemble members must share state, input and feature names")
        self.members = list(models)
        self.coefficients = np.stack([m.coefficients for m in models])  # (K, n, p)
        self._theta = first.theta

    def __call__(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """dx/dt of member k at x[..., k, :], u[..., k, :]; shape (..., K, n)."""
        return np.einsum("knp,...kp->...kn", self.coefficients, self._theta(x, u))

    def median_model(self) -> IdentifiedModel:
        """The model whose coefficients are the members' medians (E-SINDy's aggregate)."""
        first = self.members[0]
        meta = {**first.meta, "ensemble_size": len(self.members), "aggregate": "median"}
        return IdentifiedModel(
            first.feature_names, np.median(self.coefficients, axis=0), first.state_names,
            first.input_names, first.system, meta,
        )  # fmt: skip


class _MemberRhs:
    """The rhs of one member, switchable between episodes."""

    def __init__(self, members: Sequence[IdentifiedModel]) -> None:
        self.members, self.index = list(members), 0

    def __call__(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return self.members[self.index].rhs(x, u)


class EnsembleSurrogate(gym.Wrapper):
    """A surrogate env driven by an ensemble, ending imagined episodes the models dispute.

    After every step, each member predicts the step from the previous state with the
    applied input (one RK4 step); the spread of the predictions, per state divided by
    ``scale`` and maximised over states, is ``info["disagreement"]``. Above ``threshold`` the
    episode is truncated: the policy never learns from states where the data leave the
    models undecided. With ``mode="sample"`` each episode is flown by one member drawn
    from the env's RNG; with ``median`` by the median model.

    Args:
        env: A surrogate env whose rhs is the ensemble's (see :func:`make_ensemble_surrogate`).
        ensemble: The members.
        member_rhs: The switchable rhs of ``sample`` mode (None for ``median``).
        threshold: Largest tolerated disagreement (None: never truncate).
        scale: Per-state scale of the disagreement (e.g. the data's standard deviation).
    """

    def __init__(
        self,
        env: gym.Env,
        ensemble: EnsembleRhs,
        member_rhs: _MemberRhs | None,
        threshold: float | None,
        scale: np.ndarray,
    ) -> None:
        super().__init__(env)
        self.ensemble, self.member_rhs = ensemble, member_rhs
        self.threshold, self.scale = threshold, np.asarray(scale, dtype=np.float64)
        self._state: np.ndarray | None = None

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        """Resets the env and, in ``sample`` mode, draws the member for this episode."""
        obs, info = self.env.reset(**kwargs)
        if self.member_rhs is not None:
            self.member_rhs.index = int(
                self.env.unwrapped.np_random.integers(len(self.ensemble.members))
            )
        self._state = self._full_state(info)
        return obs, info

    @staticmethod
    def _full_state(info: dict[str, Any]) -> np.ndarray:
        """The state the members step from: with rotor dynamics, the rotor thrusts too."""
        if "rotor_thrusts" in info:
            return np.concatenate([info["state"], info["rotor_thrusts"]])
        return np.asarray(info["state"])

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        """Steps the env; truncates where the members' one-step predictions disagree."""
        obs, reward, terminated, truncated, info = self.env.step(action)
        base = self.env.unwrapped
        k, n = len(self.ensemble.members), self.scale.size
        field, applied = self.ensemble, info["action"]
        if "rotor_commands" in info:  # lagged inputs: the members step the rotors too
            tau = float(base.params.rotor_time_constant)
            field = physics.RotorLagField(self.ensemble, np.asarray(base.params.mixer), n, tau)
            applied = info["rotor_commands"]
        x = np.broadcast_to(self._state, (k, self._state.size))
        u = np.broadcast_to(applied, (k, np.size(applied)))
        with np.errstate(all="ignore"):
            predictions = rk4_step(field, x, u, base.dt, base.substeps)
        spread = np.ptp(predictions[:, :n], axis=0) / self.scale
        disagreement = float(np.max(spread)) if np.isfinite(spread).all() else float("inf")
        info["disagreement"] = disagreement
        if self.threshold is not None and disagreement > self.threshold and not terminated:
            truncated = True
        self._state = self._full_state(info)
        return obs, reward, terminated, truncated, info


def make_ensemble_surrogate(
    models: Sequence[IdentifiedModel],
    base_id: str = "PlanarQuad-v0",
    mode: str = "median",
    threshold: float | None = None,
    scale: np.ndarray | None = None,
    **kwargs: Any,
) -> EnsembleSurrogate:
    """A surrogate env flown by an ensemble of models (median or one member per episode).

    Args:
        models: Ensemble members over the same library (e.g. bagged fits).
        base_id: The ground-truth env the members stand in for.
        mode: ``median`` (the median-coefficient model) or ``sample`` (a member per episode).
            Members with an input lag (one for all) step with rotor dynamics, as
            :func:`make_surrogate` does, and predict the step with their rotors.
        threshold: Truncate an episode where the disagreement exceeds this (None: never).
        scale: Per-state scale of the disagreement (default 1).
        **kwargs: Options of the base env (task, dt, ...).

    Returns:
        The wrapped env; ``env.unwrapped.model`` is the median model.
    """
    if mode not in ENSEMBLE_MODES:
        raise ValueError(f"unknown ensemble mode {mode!r}; valid choices: {ENSEMBLE_MODES}")
    ensemble = EnsembleRhs(models)
    lags = sorted({float(m.meta.get("input_lag", 0.0)) for m in models})
    if len(lags) > 1:
        raise ValueError(
            f"ensemble members act through different input lags ({', '.join(map(str, lags))} "
            "s): the surrogate steps one actuator lag; identify them with one --input-lag"
        )
    median = ensemble.median_model()
    _, cls = _resolve(median, base_id, vector=False)
    member_rhs = _MemberRhs(models) if mode == "sample" else None
    env = cls(rhs=member_rhs if member_rhs is not None else median.rhs,
              **_lag_options(median, kwargs))  # fmt: skip
    env.model = median
    box = median.training_box()
    if box is not None:
        env.set_training_range(*box)
    n = len(median.state_names)
    scale = np.ones(n) if scale is None else np.asarray(scale, dtype=np.float64)
    if scale.shape != (n,) or not (scale > 0).all():
        raise ValueError(f"scale must be {n} positive numbers, got {scale!r}")
    return EnsembleSurrogate(env, ensemble, member_rhs, threshold, scale)
