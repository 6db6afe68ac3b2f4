"""The vehicle record: everything that makes one kind of vehicle, in one place.

A :class:`Vehicle` holds a parameter preset and the pure functions of that kind of vehicle
(dynamics, rotor saturation, observation, bounds, drawing) plus the names of its variables.
The simulator, the environments, the renderer and the plots read everything they need from
it, so a new vehicle is one new module in :mod:`quad_envs.vehicles` plus its registration.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from quad_envs.types import FloatArray

Controller = Callable[[FloatArray, FloatArray], FloatArray]
"""Maps (state, reference) to the commanded input, batched over leading axes."""


@dataclass(frozen=True)
class View:
    """One drawn projection of the scene.

    Attributes:
        axes: Indices of the two position coordinates drawn (into the reference position).
        labels: Axis labels.
    """

    axes: tuple[int, int]
    labels: tuple[str, str]


@dataclass(frozen=True)
class Vehicle:
    """One kind of vehicle with one set of parameters.

    Attributes:
        name: Registry name (``planar``, ``quad6dof``, ...).
        params: Parameters (a frozen dataclass with SI units); :meth:`with_params` swaps them.
        dynamics: Pure rhs ``(x, u, params) -> dx/dt``, batched over leading axes, no
            saturation.
        saturation: ``(u, params) -> u`` applying the rotor limits to a commanded input.
        state_names: Names of the states, in order.
        input_names: Names of the inputs, in order.
        angle_names: States that are angles [rad] (Fourier terms, wrapping).
        position_names: States that are the position (compared with the reference).
        ref_names: Columns of a reference sample (see :mod:`quad_envs.trajectories`).
        ndim: Spatial dimension of the references (2: the y-z plane, 3: space).
        rest_state: ``reference sample -> state`` at rest on the reference (level attitude).
        controller: ``params -> controller``: the vehicle's default feedback law.
        observe: ``(states, refs) -> observations``, batched.
        obs_names: Names of the observation entries.
        cost_weights: One weight per observation entry (see :mod:`quad_envs.tasks`).
        state_bounds: ``volume -> (low, high)`` of the states allowed before termination.
        obs_bounds: ``volume -> (low, high)`` of the observation space.
        init_scale: Per-state half-width of the initial-state perturbation at scale 1.
        action_bounds: ``params -> (low, high)`` of the physical input box.
        randomized_fields: Parameter fields scaled by domain randomisation.
        library: ``() -> feature names`` of the vehicle's physics-informed SINDy library
            (names in the grammar of :mod:`identification.features`).
        rotor_points: ``(state, params) -> (k, ndim)`` rotor positions for drawing.
        views: Projections the renderer draws.
        point_field: Module-level numba function ``(x, u, thrust, wind, p, c, out)`` writing
            the extended dx/dt of one state (rigid body from :mod:`quad_envs.dynamics`,
            plus the effects of :mod:`quad_envs.physics`); the step kernels are built from
            it (:func:`quad_envs.physics.vehicle_kernels`).
        point_observe: Module-level numba function ``(x, ref, out)`` writing ``observe``
            of one state (tests check that the two agree).
    """

    name: str
    params: Any
    dynamics: Callable[[FloatArray, FloatArray, Any], FloatArray]
    saturation: Callable[[FloatArray, Any], FloatArray]
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    angle_names: tuple[str, ...]
    position_names: tuple[str, ...]
    ref_names: tuple[str, ...]
    ndim: int
    rest_state: Callable[[FloatArray], FloatArray]
    controller: Callable[[Any], Controller]
    observe: Callable[[FloatArray, FloatArray], FloatArray]
    obs_names: tuple[str, ...]
    cost_weights: FloatArray
    state_bounds: Callable[[Any], tuple[FloatArray, FloatArray]]
    obs_bounds: Callable[[Any], tuple[FloatArray, FloatArray]]
    init_scale: FloatArray
    action_bounds: Callable[[Any], tuple[FloatArray, FloatArray]]
    randomized_fields: tuple[str, ...]
    library: Callable[[], list[str]]
    rotor_points: Callable[[FloatArray, Any], FloatArray]
    views: tuple[View, ...]
    point_field: Callable[..., None] | None = None
    point_observe: Callable[..., None] | None = None

    def rhs(self, x: FloatArray, u: FloatArray) -> FloatArray:
        """dx/dt with this vehicle's parameters (no saturation)."""
        return self.dynamics(x, u, self.params)

    def saturate(self, u: FloatArray) -> FloatArray:
        """The input the rotors apply for a commanded input."""
        return self.saturation(u, self.params)

    def with_params(self, params: Any) -> Vehicle:
        """The same vehicle with other parameters (a preset, or batched arrays)."""
        return dataclasses.replace(self, params=params)

    def initial_state(self, ref0: FloatArray) -> FloatArray:
        """State at rest on the reference sample ``ref0``."""
        return self.rest_state(ref0)

    def default_controller(self, max_tilt: float | None = None, gains: Any = None) -> Controller:
        """The vehicle's feedback law for its parameters.

        ``max_tilt``: its tilt limit [rad]; ``gains``: its controller's gains (for the
        controllers that take them).
        """
        options: dict[str, Any] = {} if gains is None else {"gains": gains}
        if max_tilt is not None:
            options["max_tilt"] = max_tilt
        return self.controller(self.params, **options)

    @property
    def n_states(self) -> int:
        """Number of states."""
        return len(self.state_names)

    @property
    def n_inputs(self) -> int:
        """Number of inputs."""
        return len(self.input_names)

    @property
    def n_rotors(self) -> int:
        """Number of rotors (the mixer's columns)."""
        return int(np.asarray(self.params.mixer).shape[1])

    @property
    def angle_indices(self) -> tuple[int, ...]:
        """Indices of the angle states."""
        return tuple(self.state_names.index(a) for a in self.angle_names)
