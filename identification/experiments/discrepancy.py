"""Identification of the discrepancy: drag and rotor dynamics, found from data alone.

The paper names unmodelled disturbances and discrepancy models as future work. Here the
environments fly with their effects switched on (:class:`quad_envs.physics.Effects`) and the
truth-free identifier (:func:`identification.selection.select_model`) sees only the recorded
flights. Truth enters only afterwards, to score what it returned:

* **Drag** (:func:`drag_study`): linear rotor drag and quadratic body drag on the planar
  vehicle. The drag force is R diag(D_lat + c_lat |v|, D_up + c_up |v|) R^T v in the inertial
  velocities, so the library needs ``v``, ``v cos(2 phi)``, ``v sin(2 phi)`` and each of them
  times ``norm(y_dot z_dot)`` (:func:`identification.libraries.drag_terms`, preset
  ``planar_drag``). The true coefficient of every such term follows from
  :func:`quad_envs.dynamics.planar_drag` by least squares on random points (exact: the terms
  span the force), and the four physical coefficients are recovered from the found ones.
* **Rotor dynamics, observed** (:func:`rotor_study`): the rotor thrusts T1, T2 are states,
  the commanded (limited) rotor thrusts Tc1, Tc2 are the inputs; the thrust equations
  T_i' = (Tc_i - T_i) / tau give the time constant twice per rotor.
* **Rotor dynamics, hidden** (:func:`drift_study`): the same flights with only the rigid-body
  state and the commanded collective input [u1, u2] = M Tc. No model with these states can be
  exact; the study reports what the identifier returns and how its open-loop predictions
  drift over horizons, beside the identifier on lag-free flights, the observed-rotor model and
  the true rigid-body model that ignores the lag.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np

import quad_envs  # noqa: F401 (registers the ids)
from identification.data import Trajectory
from identification.experiments.synthetic import SupportCheck, add_noise, check_support
from identification.experiments.truth import quad6dof_truth
from identification.features import compile_features, parse_term, term_name
from identification.libraries import (
    LibrarySpec,
    drag_terms,
    planar_drag_library,
    planar_library,
    quad6dof_drag_library,
    rotor_library,
    rotor_names,
)
from identification.model import IdentifiedModel
from identification.rollouts import excitation_rollouts
from identification.selection import select_model
from quad_envs.controllers import (
    LAG_GAINS_6DOF,
    LAG_GAINS_PLANAR,
    PlanarPD,
    PlanarPDGains,
    Quad6DOFPD,
    Quad6DOFPDGains,
)
from quad_envs.dynamics import (
    QUAD6DOF_INPUT_NAMES,
    QUAD6DOF_STATE_NAMES,
    body_drag,
    planar_drag,
    planar_rhs,
)
from quad_envs.integrators import rk4_step
from quad_envs.params import PlanarQuadParams, Quad6DOFParams, get_preset
from quad_envs.trajectories import RandomWaypoints

ENV_ID = "PlanarQuad-v0"
VELOCITIES = ("y_dot", "z_dot")
RIGID_STATES = ("y", "z", "phi", "y_dot", "z_dot", "phi_dot")
ROTOR_STATES, ROTOR_INPUTS = rotor_names(2)
DRAG_FIELDS = ("drag_linear_xy", "drag_linear_z", "drag_quadratic_xy", "drag_quadratic_z")
ROTOR_LIBRARY = LibrarySpec(degree=1, angles=("phi",))
"""Library of the observed-rotor case: 1, every variable, and each times sin(phi), cos(phi)."""
OTHER_VEHICLE = PlanarQuadParams(
    mass=0.6, Ixx=4e-3, arm_length=0.15, rotor_force_max=0.6 * 9.81 * 1.2,
    rotor_time_constant=0.04, drag_linear_xy=0.09, drag_linear_z=0.03,
    drag_quadratic_xy=0.012, drag_quadratic_z=0.02,
)  # fmt: skip
"""A third planar vehicle, neither preset: 0.6 kg, unequal drag on both axes, tau = 0.04 s."""
SOFT_GAINS = LAG_GAINS_PLANAR
"""PD gains of the planar flights with rotor lag (``controllers.LAG_GAINS_PLANAR``)."""


def planar_params(vehicle: str | PlanarQuadParams) -> PlanarQuadParams:
    """A planar parameter set from a preset name or itself."""
    if isinstance(vehicle, PlanarQuadParams):
        return vehicle
    return get_preset(vehicle, "planar")  # type: ignore[return-value]


# -- truth (used only to score) ------------------------------------------------------------


def drag_truth_terms(params: PlanarQuadParams) -> dict[str, dict[str, float]]:
    """True coefficients of the drag terms in the y_dot and z_dot equations.

    The acceleration F(phi, v) / m of :func:`quad_envs.dynamics.planar_drag` is fitted by least
    squares on 400 random points with the terms of :func:`drag_terms`; the residual must be
    at rounding level (the terms span the force exactly), else this raises.
    """
    names = drag_terms(VELOCITIES, "phi")
    rng = np.random.default_rng(0)
    n = 400
    phi = rng.uniform(-1.0, 1.0, n)
    vel = rng.uniform(-3.0, 3.0, (n, 2))
    fy, fz = planar_drag(
        phi, vel[:, 0], vel[:, 1], params.drag_linear_xy, params.drag_linear_z,
        params.drag_quadratic_xy, params.drag_quadratic_z,
    )  # fmt: skip
    acc = np.stack([fy, fz], axis=1) / params.mass
    x = np.zeros((n, 6))
    x[:, 2], x[:, 3:5] = phi, vel
    theta = compile_features(names, RIGID_STATES, ("u1", "u2"))(x, np.zeros((n, 2)))
    coef, *_ = np.linalg.lstsq(theta, acc, rcond=None)
    residual = np.abs(theta @ coef - acc).max()
    if residual > 1e-9 * max(np.abs(acc).max(), 1e-12):
        raise AssertionError(f"drag terms do not span the drag force (residual {residual:.2e})")
    scale = np.abs(coef).max()
    out: dict[str, dict[str, float]] = {"y_dot": {}, "z_dot": {}}
    for j, name in enumerate(names):
        for i, state in enumerate(("y_dot", "z_dot")):
            if abs(coef[j, i]) > 1e-9 * scale:
                out[state][name] = float(coef[j, i])
    return out


def planar_truth(
    params: PlanarQuadParams, drag: bool = False, rotors: bool = False
) -> dict[str, dict[str, float]]:
    """The true model {state: {term: coefficient}} of the planar vehicle with effects."""
    inv_m, g = 1.0 / params.mass, params.gravity
    truth: dict[str, dict[str, float]] = {
        "y": {"y_dot": 1.0},
        "z": {"z_dot": 1.0},
        "phi": {"phi_dot": 1.0},
    }
    if rotors:
        arm, tau = params.arm_length, params.rotor_time_constant
        truth["y_dot"] = {"T1 sin(phi)": -inv_m, "T2 sin(phi)": -inv_m}
        truth["z_dot"] = {"1": -g, "T1 cos(phi)": inv_m, "T2 cos(phi)": inv_m}
        truth["phi_dot"] = {"T1": -arm / params.Ixx, "T2": arm / params.Ixx}
        for t, tc in zip(ROTOR_STATES, ROTOR_INPUTS, strict=True):
            truth[t] = {t: -1.0 / tau, tc: 1.0 / tau}
    else:
        truth["y_dot"] = {"u1 sin(phi)": -inv_m}
        truth["z_dot"] = {"1": -g, "u1 cos(phi)": inv_m}
        truth["phi_dot"] = {"u2": 1.0 / params.Ixx}
    if drag:
        for state, terms in drag_truth_terms(params).items():
            truth[state].update(terms)
    return {s: {term_name(parse_term(n)): v for n, v in t.items()} for s, t in truth.items()}


def coefficient(model: IdentifiedModel, state: str, term: str) -> float:
    """The model's coefficient of ``term`` in the equation of ``state`` (0 if absent)."""
    key = parse_term(term)
    i = model.state_names.index(state)
    return float(
        sum(
            model.coefficients[i, j]
            for j, n in enumerate(model.feature_names)
            if parse_term(n) == key
        )
    )


# -- data ----------------------------------------------------------------------------------


def drag_flights(
    vehicle: str | PlanarQuadParams = "crazyflie",
    episodes: int = 3,
    steps: int = 1000,
    seed: int = 0,
    noise: float = 0.15,
) -> list[Trajectory]:
    """PD flights between random waypoints plus input noise, with drag on (applied inputs)."""
    kwargs: dict[str, Any] = {"effects": {"drag": True}}
    if isinstance(vehicle, str):
        kwargs["vehicle"] = vehicle
    else:
        kwargs["params"] = vehicle
    return excitation_rollouts(ENV_ID, episodes, seed, steps, noise, env_kwargs=kwargs)


@dataclass
class RotorFlights:
    """The same flights seen two ways.

    Attributes:
        observed: States rigid body + rotor thrusts (T1, T2), inputs the commanded rotor
            thrusts after the limits (Tc1, Tc2).
        hidden: States rigid body only, inputs the commanded collective [u1, u2] = M Tc.
    """

    observed: list[Trajectory]
    hidden: list[Trajectory]


def rotor_flights(
    vehicle: str | PlanarQuadParams = "crazyflie",
    episodes: int = 3,
    steps: int = 1000,
    seed: int = 0,
    noise: float = 0.05,
    rotor_dynamics: bool = True,
    gains: PlanarPDGains = SOFT_GAINS,
) -> RotorFlights:
    """PD flights between random waypoints in the per-rotor action mode, rotors recorded.

    The PD's collective command is split into rotor thrusts (M^-1 u) and Gaussian noise of
    ``noise`` times the half-width of the rotor box is added per rotor; the env clips the
    command to the box. With ``rotor_dynamics=False`` the rotors follow at once (the
    ``observed`` flights then show T = Tc). The PD uses ``gains`` (:data:`SOFT_GAINS`).
    """
    params = planar_params(vehicle)
    env = gym.make(
        ENV_ID,
        params=params,
        effects={"rotor_dynamics": rotor_dynamics},
        action_mode="rotor_thrusts",
        duration=steps * 0.01 + 1.0,
    )

    def reference(rng: np.random.Generator, ep: int) -> Any:
        return RandomWaypoints.sample(
            rng, ndim=2, num_waypoints=int(steps * 0.01 / 1.5) + 2, low=(-1.5, 0.5),
            high=(1.5, 2.0), segment_time=1.5,
        )  # fmt: skip

    names = (RIGID_STATES, ROTOR_STATES, ROTOR_INPUTS, ("u1", "u2"))
    meta = {"env": ENV_ID, "rotor_dynamics": rotor_dynamics}
    return _rotor_mode_flights(env, PlanarPD(params, gains), params.mixer, reference, names,
                               episodes, steps, seed, noise, rotor_dynamics, meta)  # fmt: skip


def _rotor_mode_flights(
    env: Any,
    pd: Any,
    mixer: np.ndarray,
    reference: Any,
    names: tuple[Sequence[str], Sequence[str], Sequence[str], Sequence[str]],
    episodes: int,
    steps: int,
    seed: int,
    noise: float,
    rotor_dynamics: bool,
    meta: dict[str, Any],
) -> RotorFlights:
    """The flight loop of :func:`rotor_flights` and :func:`quad6dof_flights` (closes ``env``).

    Args:
        env: An env in the per-rotor action mode.
        pd: The vehicle's PD: (state, reference) -> collective command.
        mixer: Rotor thrusts -> collective input.
        reference: (rng, episode) -> the episode's reference, drawn from the flights' rng.
        names: Rigid states, rotor states, rotor inputs, collective inputs.
        episodes: Flights to try (those ending before 50 steps are skipped).
        steps: Steps per flight.
        seed: Seed of the flights' rng (references, input noise) and of the env resets.
        noise: Input noise per rotor, as a fraction of the rotor box's half-width.
        rotor_dynamics: Whether the rotors lag (their thrusts are then recorded).
        meta: Stored with each flight (its seed added).
    """
    rigid, rotors, rotor_inputs, collective = names
    unmix = np.linalg.inv(mixer)
    low, high = env.action_space.low.astype(float), env.action_space.high.astype(float)
    half = 0.5 * (high - low)
    rng = np.random.default_rng(seed)
    observed, hidden = [], []
    for ep in range(episodes):
        _, info = env.reset(seed=seed + ep, options={"trajectory": reference(rng, ep)})
        ts, xs, thrusts, commands = [], [], [], []
        for _ in range(steps):
            command = unmix @ pd(info["state"], info["reference"])
            command = np.clip(command + noise * half * rng.standard_normal(low.size), low, high)
            command = command.astype(env.action_space.dtype).astype(float)  # what is applied
            ts.append(info["time"])
            xs.append(info["state"])
            thrusts.append(info["rotor_thrusts"] if rotor_dynamics else command)
            commands.append(command)
            _, _, terminated, truncated, info = env.step(command.astype(env.action_space.dtype))
            if terminated or truncated:
                break
        if len(ts) < 50:
            continue
        t, x, tc = np.array(ts), np.array(xs), np.array(commands)
        flight = {**meta, "seed": seed + ep}
        observed.append(Trajectory(t, np.hstack([x, np.array(thrusts)]), tc, (*rigid, *rotors),
                                   rotor_inputs, meta=flight))  # fmt: skip
        hidden.append(Trajectory(t, x, tc @ mixer.T, rigid, collective, meta=flight))
    env.close()
    return RotorFlights(observed, hidden)


# -- studies -------------------------------------------------------------------------------


@dataclass
class CoefficientRow:
    """One true term: where it is, its true and found coefficient."""

    state: str
    term: str
    true: float
    found: float

    @property
    def rel_error(self) -> float:
        """|found - true| / |true|."""
        return abs(self.found - self.true) / abs(self.true)


@dataclass
class DragResult:
    """What the identifier returned on drag flights, scored against the truth.

    Attributes:
        vehicle: Label of the vehicle.
        model: The identified model.
        support: Missed and spurious terms, worst relative coefficient error.
        rows: The true drag terms with found coefficients.
        physical: {field: (true, found)} of the drag coefficients D_xy, D_z, c_xy, c_z,
            recovered from the found term coefficients and the found 1/m.
        seconds: Wall time of the identification.
        rows_of_data: Rows of data used.
        sigma: Standard deviation of the state noise added to the data (0: clean).
    """

    vehicle: str
    model: IdentifiedModel
    support: SupportCheck
    rows: list[CoefficientRow]
    physical: dict[str, tuple[float, float]]
    seconds: float
    rows_of_data: int
    sigma: float = 0.0

    @property
    def worst_drag_error(self) -> float:
        """Largest relative error over the true drag terms."""
        return max(r.rel_error for r in self.rows)


def _drag_jacobian(params: Any, keys: list[tuple[str, str]], truth_terms: Any = None) -> np.ndarray:
    """d(term coefficients)/d(drag field / m): the terms are linear in the four drag fields.

    ``truth_terms`` maps parameters to {state: {term: coefficient}} (default: the planar
    :func:`drag_truth_terms`).
    """
    truth_terms = truth_terms or drag_truth_terms
    cols = []
    for name in DRAG_FIELDS:
        unit = params.replace(**{f: 0.0 for f in DRAG_FIELDS}).replace(**{name: params.mass})
        truth = truth_terms(unit)
        cols.append([truth[s].get(t, 0.0) for s, t in keys])
    return np.array(cols).T


def _physical_drag(
    params: Any,
    model: IdentifiedModel,
    keys: list[tuple[str, str]],
    mass_found: float,
    truth_terms: Any = None,
) -> dict[str, tuple[float, float]]:
    """{drag field: (true, found)}: least squares of the found term coefficients times m."""
    jac = _drag_jacobian(params, keys, truth_terms)
    found = np.array([coefficient(model, s, t) for s, t in keys])
    per_mass, *_ = np.linalg.lstsq(jac, found, rcond=None)
    return {
        name: (float(getattr(params, name)), float(per_mass[k] * mass_found))
        for k, name in enumerate(DRAG_FIELDS)
    }


def drag_study(
    vehicle: str | PlanarQuadParams = "crazyflie",
    episodes: int = 3,
    steps: int = 1000,
    seed: int = 0,
    n_models: int = 20,
    label: str | None = None,
    sigma: float = 0.0,
) -> DragResult:
    """Identifies the planar vehicle with drag on from its flights alone and scores it.

    ``sigma``: standard deviation of Gaussian noise added to every recorded state (sensor
    noise, seeded by ``seed + 7``; the inputs stay clean).
    """
    params = planar_params(vehicle)
    trajs = drag_flights(params, episodes, steps, seed)
    if sigma > 0:
        trajs = add_noise(trajs, sigma, seed + 7)
    start = time.perf_counter()
    model, _ = select_model(trajs, planar_drag_library(), n_models=n_models, seed=seed)
    seconds = time.perf_counter() - start
    truth = planar_truth(params, drag=True)
    drag = drag_truth_terms(params)
    rows = [
        CoefficientRow(s, term_name(parse_term(t)), v, coefficient(model, s, t))
        for s, terms in drag.items()
        for t, v in terms.items()
    ]
    # Physical coefficients from all term coefficients (least squares), scaled by found m.
    keys = [(s, t) for s in ("y_dot", "z_dot") for t in drag_terms(VELOCITIES, "phi")]
    mass_found = -1.0 / coefficient(model, "y_dot", "u1 sin(phi)")
    physical = _physical_drag(params, model, keys, mass_found)
    return DragResult(
        label or (vehicle if isinstance(vehicle, str) else "custom"), model,
        check_support(model, truth), rows, physical, seconds, sum(len(t) for t in trajs),
        sigma,
    )  # fmt: skip


@dataclass
class RotorResult:
    """The observed-rotor identification scored against the truth.

    Attributes:
        vehicle: Label of the vehicle.
        model: The identified model (8 states, inputs Tc1, Tc2).
        support: Missed and spurious terms, worst relative coefficient error.
        tau_true: The rotor time constant [s].
        tau_found: {"T1 from T1": ..., "T1 from Tc1": ..., ...}: -1/coef of T_i and
            1/coef of Tc_i in the equation of T_i [s] (inf where the term was not found).
        seconds: Wall time of the identification.
        rows_of_data: Rows of data used.
        sigma: Standard deviation of the state noise added to the data (0: clean).
    """

    vehicle: str
    model: IdentifiedModel
    support: SupportCheck
    tau_true: float
    tau_found: dict[str, float]
    seconds: float
    rows_of_data: int
    sigma: float = 0.0

    @property
    def worst_tau_error(self) -> float:
        """Largest relative error of the four estimates of tau."""
        return max(abs(v - self.tau_true) / self.tau_true for v in self.tau_found.values())


def _time_constant(rate: float) -> float:
    """1 / rate [s]; inf when the term was not found (rate 0)."""
    return 1.0 / rate if rate != 0.0 else float("inf")


def identify_rotors(
    trajs: Sequence[Trajectory], n_models: int = 20, seed: int = 0
) -> tuple[IdentifiedModel, float]:
    """The identifier on observed-rotor flights with :data:`ROTOR_LIBRARY`; (model, seconds)."""
    library = ROTOR_LIBRARY.build(trajs[0].state_names, trajs[0].input_names)
    start = time.perf_counter()
    model, _ = select_model(trajs, library, n_models=n_models, seed=seed)
    return model, time.perf_counter() - start


def rotor_study(
    vehicle: str | PlanarQuadParams = "crazyflie",
    episodes: int = 3,
    steps: int = 1000,
    seed: int = 0,
    n_models: int = 20,
    flights: RotorFlights | None = None,
    label: str | None = None,
    sigma: float = 0.0,
) -> RotorResult:
    """Identifies the time constant from flights with the rotor thrusts observed.

    ``sigma``: standard deviation of Gaussian noise added to every recorded state, the rotor
    thrusts included (seeded by ``seed + 7``; the commanded thrusts stay clean).
    """
    params = planar_params(vehicle)
    flights = flights or rotor_flights(params, episodes, steps, seed)
    observed = add_noise(flights.observed, sigma, seed + 7) if sigma > 0 else flights.observed
    model, seconds = identify_rotors(observed, n_models, seed)
    tau_found = {}
    for t, tc in zip(ROTOR_STATES, ROTOR_INPUTS, strict=True):
        tau_found[f"{t} from {t}"] = _time_constant(-coefficient(model, t, t))
        tau_found[f"{t} from {tc}"] = _time_constant(coefficient(model, t, tc))
    return RotorResult(
        label or (vehicle if isinstance(vehicle, str) else "custom"), model,
        check_support(model, planar_truth(params, rotors=True)), params.rotor_time_constant,
        tau_found, seconds, sum(len(t) for t in flights.observed), sigma,
    )  # fmt: skip


# -- drift over horizons -------------------------------------------------------------------

HORIZONS = (1, 2, 5, 10, 20, 50, 100)
"""Prediction horizons of the drift study [control steps of 0.01 s]."""


def drift(
    rhs: Any,
    trajs: Sequence[Trajectory],
    horizons: Sequence[int] = HORIZONS,
    stride: int = 20,
    n_rigid: int = 6,
) -> dict[str, np.ndarray]:
    """Open-loop prediction error of ``rhs`` against recorded flights, per horizon.

    From every ``stride``-th row (with room for the longest horizon), the model is integrated
    by RK4 with the recorded inputs held per step, from the recorded state.

    Returns:
        ``position`` (RMS of the position error [m]), ``phi`` (RMS attitude error [rad]) and
        ``diverged`` (fraction of non-finite predictions), each of shape (len(horizons),).
    """
    longest = max(horizons)
    pos = {h: [] for h in horizons}
    ang = {h: [] for h in horizons}
    bad = {h: 0 for h in horizons}
    count = 0
    for tr in trajs:
        starts = np.arange(0, len(tr) - longest - 1, stride)
        if len(starts) == 0:
            continue
        count += len(starts)
        x = tr.x[starts].copy()
        for k in range(1, longest + 1):
            rows = starts + k - 1
            dt = (tr.t[rows + 1] - tr.t[rows])[:, None]
            with np.errstate(all="ignore"):
                x = rk4_step(rhs, x, tr.u[rows], dt, 1)
            if k in pos:
                true = tr.x[starts + k]
                err = x[:, :n_rigid] - true[:, :n_rigid]
                ok = np.all(np.isfinite(err), axis=1) & (np.abs(err).max(axis=1) < 1e3)
                bad[k] += int((~ok).sum())
                pos[k].extend(np.sum(err[ok, :2] ** 2, axis=1))
                ang[k].extend(err[ok, 2] ** 2)
    return {
        "position": np.array([np.sqrt(np.mean(pos[h])) if pos[h] else np.inf for h in horizons]),
        "phi": np.array([np.sqrt(np.mean(ang[h])) if ang[h] else np.inf for h in horizons]),
        "diverged": np.array([bad[h] / max(count, 1) for h in horizons]),
    }


@dataclass
class DriftResult:
    """Rotor dynamics hidden: what the identifier returns and how its predictions drift.

    Attributes:
        vehicle: Label of the vehicle.
        hidden_model: Identified from the rigid-body states and commanded [u1, u2].
        hidden_support: It against the lag-free rigid-body truth.
        observed_model: Identified with the rotor thrusts observed (reference).
        lagfree_model: Identified on flights without rotor dynamics (reference).
        errors: {label: drift dict} on held-out flights (:func:`drift`).
        horizons: Horizons [steps].
        dt: Control step [s].
        seconds: Wall time of each identification.
    """

    vehicle: str
    hidden_model: IdentifiedModel
    hidden_support: SupportCheck
    observed_model: IdentifiedModel
    lagfree_model: IdentifiedModel
    errors: dict[str, dict[str, np.ndarray]]
    horizons: tuple[int, ...]
    dt: float = 0.01
    seconds: dict[str, float] = field(default_factory=dict)


def drift_study(
    vehicle: str | PlanarQuadParams = "crazyflie",
    episodes: int = 3,
    steps: int = 1000,
    seed: int = 0,
    n_models: int = 20,
    horizons: Sequence[int] = HORIZONS,
    label: str | None = None,
) -> DriftResult:
    """Rotor dynamics on but unobserved: identify, then measure the drift on new flights."""
    params = planar_params(vehicle)
    train = rotor_flights(params, episodes, steps, seed)
    test = rotor_flights(params, 2, steps, seed + 100)
    lagfree_train = rotor_flights(params, episodes, steps, seed, rotor_dynamics=False)
    lagfree_test = rotor_flights(params, 2, steps, seed + 100, rotor_dynamics=False)
    library = planar_library()
    seconds = {}
    start = time.perf_counter()
    hidden, _ = select_model(train.hidden, library, n_models=n_models, seed=seed)
    seconds["hidden"] = time.perf_counter() - start
    observed, seconds["observed"] = identify_rotors(train.observed, n_models, seed)
    start = time.perf_counter()
    lagfree, _ = select_model(lagfree_train.hidden, library, n_models=n_models, seed=seed)
    seconds["lag-free"] = time.perf_counter() - start

    def rigid(x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return planar_rhs(x, u, params)

    errors = {
        "no rotor lag: identified": drift(lagfree.rhs, lagfree_test.hidden, horizons),
        "lag, rotors observed: identified": drift(observed.rhs, test.observed, horizons),
        "lag, rotors hidden: identified": drift(hidden.rhs, test.hidden, horizons),
        "lag, rotors hidden: true rigid body": drift(rigid, test.hidden, horizons),
    }
    return DriftResult(
        label or (vehicle if isinstance(vehicle, str) else "custom"), hidden,
        check_support(hidden, planar_truth(params)), observed, lagfree, errors,
        tuple(horizons), 0.01, seconds,
    )  # fmt: skip


def plot_drift(result: DriftResult, path: str) -> None:
    """Position and attitude RMS error against the horizon, log-log, one line per model."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    seconds = np.array(result.horizons) * result.dt
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for label, err in result.errors.items():
        for ax, key in zip(axes, ("position", "phi"), strict=True):
            ax.loglog(seconds, np.maximum(err[key], 1e-16), marker="o", label=label)
    axes[0].set_ylabel("RMS position error [m]")
    axes[1].set_ylabel("RMS roll error [rad]")
    for ax in axes:
        ax.set_xlabel("prediction horizon [s]")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.suptitle(f"Open-loop drift on held-out flights ({result.vehicle}, planar)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# -- tables --------------------------------------------------------------------------------


def drag_table(results: Sequence[DragResult]) -> str:
    """Markdown: per vehicle, support, worst drag-term error and the physical coefficients."""
    noisy = any(r.sigma > 0 for r in results)
    lines = [
        "| vehicle | " + ("sigma | " if noisy else "") + "rows | time [s] | terms | missed | "
        "spurious | worst drag-term err | "
        "D_xy true / found | D_z true / found | c_xy true / found | c_z true / found |",
        "|---|---|---|---|---|---|---|---|---|---|---|" + ("---|" if noisy else ""),
    ]
    for r in results:
        phys = " | ".join(f"{t:.4g} / {f:.4g}" for t, f in r.physical.values())
        sigma = f"{r.sigma:g} | " if noisy else ""
        lines.append(
            f"| {r.vehicle} | {sigma}{r.rows_of_data} | {r.seconds:.1f} | {r.support.n_terms} | "
            f"{len(r.support.missed)} | {len(r.support.spurious)} | {r.worst_drag_error:.1e} | "
            f"{phys} |"
        )
    return "\n".join(lines)


def drag_terms_table(result: DragResult) -> str:
    """Markdown: every true drag term with its true and found coefficient."""
    lines = ["| equation | term | true | found | rel err |", "|---|---|---|---|---|"]
    for row in result.rows:
        lines.append(
            f"| {row.state}' | `{row.term}` | {row.true:.6g} | {row.found:.6g} | "
            f"{row.rel_error:.1e} |"
        )
    return "\n".join(lines)


def rotor_table(results: Sequence[RotorResult]) -> str:
    """Markdown: per vehicle, support and the four estimates of tau."""
    noisy = any(r.sigma > 0 for r in results)
    lines = [
        "| vehicle | " + ("sigma | " if noisy else "") + "rows | time [s] | terms | missed | "
        "spurious | tau true [s] | tau found [s] (from T_i; from Tc_i) | worst tau err |",
        "|---|---|---|---|---|---|---|---|---|" + ("---|" if noisy else ""),
    ]
    for r in results:
        from_t = [v for k, v in r.tau_found.items() if "from T" in k and "from Tc" not in k]
        from_tc = [v for k, v in r.tau_found.items() if "from Tc" in k]
        found = (
            ", ".join(f"{v:.6g}" for v in from_t) + "; " + ", ".join(f"{v:.6g}" for v in from_tc)
        )
        sigma = f"{r.sigma:g} | " if noisy else ""
        lines.append(
            f"| {r.vehicle} | {sigma}{r.rows_of_data} | {r.seconds:.1f} | {r.support.n_terms} | "
            f"{len(r.support.missed)} | {len(r.support.spurious)} | {r.tau_true:.4g} | "
            f"{found} | {r.worst_tau_error:.1e} |"
        )
    return "\n".join(lines)


def support_lines(result: DragResult | RotorResult, limit: int = 12) -> str:
    """The missed and spurious terms of a result, one line each (at most ``limit`` each)."""
    out = []
    for kind, terms in (("missed", result.support.missed), ("spurious", result.support.spurious)):
        shown = list(terms[:limit]) + (
            [f"... {len(terms) - limit} more"] if len(terms) > limit else []
        )
        out.append(f"{result.vehicle}, {kind} ({len(terms)}): " + ("; ".join(shown) or "none"))
    return "\n".join(out)


def drift_table(result: DriftResult) -> str:
    """Markdown: RMS position [m] and roll [rad] errors per horizon and model."""
    head = " | ".join(f"{h * result.dt:g} s" for h in result.horizons)
    lines = [f"| model | error | {head} |", "|---|---|" + "---|" * len(result.horizons)]
    for label, err in result.errors.items():
        for key, unit in (("position", "m"), ("phi", "rad")):
            cells = " | ".join(f"{v:.2g}" for v in err[key])
            lines.append(f"| {label} | {key} [{unit}] | {cells} |")
    return "\n".join(lines)


# -- 6-DOF ---------------------------------------------------------------------------------

ENV_6DOF = "Quad6DOF-v0"
BODY_VELOCITIES = ("u", "v", "w")
ROTOR_STATES_6DOF, ROTOR_INPUTS_6DOF = rotor_names(4)
OTHER_VEHICLE_6DOF = Quad6DOFParams(
    mass=0.6, Jxx=4e-3, Jyy=5e-3, Jzz=8e-3, arm_length=0.15, gamma=0.012,
    rotor_force_max=0.6 * 9.81 / 4 * 2.4, frame="+", rotor_time_constant=0.04,
    drag_linear_xy=0.09, drag_linear_z=0.03, drag_quadratic_xy=0.012, drag_quadratic_z=0.02,
)  # fmt: skip
"""A third 6-DOF vehicle, neither preset nor the paper's: 0.6 kg, '+' frame, unequal drag
along body z and in the rotor plane, tau = 0.04 s, thrust-to-weight 2.4."""
GAINS_6DOF = LAG_GAINS_6DOF
"""PD gains of the 6-DOF flights, drag and rotor lag alike (``controllers.LAG_GAINS_6DOF``)."""
SPAN_6DOF = 0.5
"""Half-width of the waypoint box [m] (z: half of it around 1 m): tilts up to about 0.45 rad
(RMS about 0.12 rad) with 1.5 s segments and the input noise."""


def quad6dof_params(vehicle: str | Quad6DOFParams) -> Quad6DOFParams:
    """A 6-DOF parameter set from a preset name or itself."""
    if isinstance(vehicle, Quad6DOFParams):
        return vehicle
    return get_preset(vehicle, "quad6dof")  # type: ignore[return-value]


def quad6dof_flights(
    vehicle: str | Quad6DOFParams = "crazyflie",
    episodes: int = 4,
    steps: int = 1000,
    seed: int = 0,
    noise: float = 0.1,
    drag: bool = False,
    rotor_dynamics: bool = False,
    gains: Quad6DOFPDGains = GAINS_6DOF,
    span: float = SPAN_6DOF,
) -> RotorFlights:
    """6-DOF PD flights between random waypoints with a yaw sweep, per-rotor action mode.

    The PD's collective command is split into rotor thrusts (M^-1 u), Gaussian noise of
    ``noise`` times the half-width of the rotor box is added per rotor and the command is
    clipped to the box and rounded to the action space's dtype (what the env applies). The
    yaw reference sweeps +-1 rad (period 10 s + episode) so that the yaw's trig factors vary.

    Returns:
        ``observed``: the 12 rigid-body states plus T1..T4 (the commands when the rotors do not
        lag), inputs Tc1..Tc4; ``hidden``: the 12 states, inputs [u1..u4] = M Tc (the applied
        collective input when the rotors do not lag).
    """
    params = quad6dof_params(vehicle)
    env = gym.make(
        ENV_6DOF,
        params=params,
        effects={"drag": drag, "rotor_dynamics": rotor_dynamics},
        action_mode="rotor_thrusts",
        duration=steps * 0.01 + 1.0,
    )

    def reference(rng: np.random.Generator, ep: int) -> Any:
        return RandomWaypoints.sample(
            rng, ndim=3, num_waypoints=int(steps * 0.01 / 1.5) + 2,
            low=(-span, -span, 1.0 - 0.5 * span), high=(span, span, 1.0 + 0.5 * span),
            segment_time=1.5, yaw_amplitude=1.0, yaw_period=10.0 + ep,
        )  # fmt: skip

    names = (QUAD6DOF_STATE_NAMES, ROTOR_STATES_6DOF, ROTOR_INPUTS_6DOF, QUAD6DOF_INPUT_NAMES)
    meta = {"env": ENV_6DOF, "drag": drag, "rotor_dynamics": rotor_dynamics}
    return _rotor_mode_flights(env, Quad6DOFPD(params, gains), params.mixer, reference, names,
                               episodes, steps, seed, noise, rotor_dynamics, meta)  # fmt: skip


def max_tilt(trajs: Sequence[Trajectory]) -> tuple[float, float]:
    """(largest, RMS) of |phi| and |theta| over the flights [rad]."""
    angles = np.vstack([np.asarray(tr.x)[:, 3:5] for tr in trajs])
    return float(np.abs(angles).max()), float(np.sqrt(np.mean(angles**2)))


def quad6dof_drag_truth_terms(params: Quad6DOFParams) -> dict[str, dict[str, float]]:
    """True coefficients of the drag terms in the u, v, w equations.

    The acceleration F(v) / m of :func:`quad_envs.dynamics.body_drag` is fitted by least
    squares on 400 random body velocities with the terms of ``drag_terms(("u", "v", "w"))``;
    the residual must be at rounding level, else this raises.
    """
    names = drag_terms(BODY_VELOCITIES)
    rng = np.random.default_rng(0)
    n = 400
    vel = rng.uniform(-3.0, 3.0, (n, 3))
    force = body_drag(
        vel[:, 0], vel[:, 1], vel[:, 2], params.drag_linear_xy, params.drag_linear_z,
        params.drag_quadratic_xy, params.drag_quadratic_z,
    )  # fmt: skip
    acc = np.stack(force, axis=1) / params.mass
    x = np.zeros((n, 12))
    x[:, 6:9] = vel
    theta = compile_features(names, QUAD6DOF_STATE_NAMES, QUAD6DOF_INPUT_NAMES)(x, np.zeros((n, 4)))
    coef, *_ = np.linalg.lstsq(theta, acc, rcond=None)
    residual = np.abs(theta @ coef - acc).max()
    if residual > 1e-9 * max(np.abs(acc).max(), 1e-12):
        raise AssertionError(f"drag terms do not span the body drag (residual {residual:.2e})")
    scale = np.abs(coef).max()
    out: dict[str, dict[str, float]] = {v: {} for v in BODY_VELOCITIES}
    for j, name in enumerate(names):
        for i, state in enumerate(BODY_VELOCITIES):
            if abs(coef[j, i]) > 1e-9 * max(scale, 1e-300):
                out[state][name] = float(coef[j, i])
    return out


def quad6dof_effects_truth(
    params: Quad6DOFParams, drag: bool = False, rotors: bool = False
) -> dict[str, dict[str, float]]:
    """The true 6-DOF model {state: {term: coefficient}} with drag and/or rotor lag.

    With ``rotors`` the inputs u = M T enter through the rotor thrusts T1..T4 (states) and
    T_i' = (Tc_i - T_i) / tau.
    """
    truth = {k: dict(v) for k, v in quad6dof_truth(params).items()}
    if rotors:
        mixer, tau = params.mixer, params.rotor_time_constant
        scale = {"w": 1.0 / params.mass, "p": 1.0 / params.Jxx, "q": 1.0 / params.Jyy,
                 "r": 1.0 / params.Jzz}  # fmt: skip
        for row, (state, inp) in enumerate(
            zip(("w", "p", "q", "r"), QUAD6DOF_INPUT_NAMES, strict=True)
        ):
            del truth[state][inp]
            for i, rotor in enumerate(ROTOR_STATES_6DOF):
                if mixer[row, i] != 0.0:
                    truth[state][rotor] = float(mixer[row, i] * scale[state])
        for t, tc in zip(ROTOR_STATES_6DOF, ROTOR_INPUTS_6DOF, strict=True):
            truth[t] = {t: -1.0 / tau, tc: 1.0 / tau}
    if drag:
        for state, terms in quad6dof_drag_truth_terms(params).items():
            truth[state].update(terms)
    return {  # a symmetric vehicle (Jxx = Jyy) has no p q term in r'
        s: {term_name(parse_term(n)): v for n, v in t.items() if v != 0.0} for s, t in truth.items()
    }


def drag6_study(
    vehicle: str | Quad6DOFParams = "crazyflie",
    episodes: int = 4,
    steps: int = 1000,
    seed: int = 0,
    n_models: int = 20,
    label: str | None = None,
    windows: Sequence[int] | None = None,
) -> DragResult:
    """Identifies the 6-DOF vehicle with drag on from its flights alone (``quad6dof_drag``).

    ``windows``: integral windows of the selection (None: its default).
    """
    params = quad6dof_params(vehicle)
    trajs = quad6dof_flights(params, episodes, steps, seed, drag=True).hidden
    kwargs: dict[str, Any] = {} if windows is None else {"windows": tuple(windows)}
    start = time.perf_counter()
    model, _ = select_model(trajs, quad6dof_drag_library(), n_models=n_models, seed=seed,
                            **kwargs)  # fmt: skip
    seconds = time.perf_counter() - start
    drag = quad6dof_drag_truth_terms(params)
    rows = [
        CoefficientRow(s, term_name(parse_term(t)), v, coefficient(model, s, t))
        for s, terms in drag.items()
        for t, v in terms.items()
    ]
    keys = [(s, t) for s in BODY_VELOCITIES for t in drag_terms(BODY_VELOCITIES)]
    mass_found = 1.0 / coefficient(model, "w", "u1")
    physical = _physical_drag(params, model, keys, mass_found, quad6dof_drag_truth_terms)
    return DragResult(
        label or (vehicle if isinstance(vehicle, str) else "custom"), model,
        check_support(model, quad6dof_effects_truth(params, drag=True)), rows, physical,
        seconds, sum(len(t) for t in trajs),
    )  # fmt: skip


def rotor6_study(
    vehicle: str | Quad6DOFParams = "crazyflie",
    episodes: int = 4,
    steps: int = 1000,
    seed: int = 0,
    n_models: int = 20,
    label: str | None = None,
    windows: Sequence[int] | None = None,
) -> RotorResult:
    """Identifies tau of the 6-DOF vehicle with the four rotor thrusts observed."""
    params = quad6dof_params(vehicle)
    flights = quad6dof_flights(params, episodes, steps, seed, noise=0.05, rotor_dynamics=True)
    kwargs: dict[str, Any] = {} if windows is None else {"windows": tuple(windows)}
    start = time.perf_counter()
    model, _ = select_model(flights.observed, rotor_library("quad6dof"), n_models=n_models,
                            seed=seed, **kwargs)  # fmt: skip
    seconds = time.perf_counter() - start
    tau_found = {}
    for t, tc in zip(ROTOR_STATES_6DOF, ROTOR_INPUTS_6DOF, strict=True):
        tau_found[f"{t} from {t}"] = _time_constant(-coefficient(model, t, t))
        tau_found[f"{t} from {tc}"] = _time_constant(coefficient(model, t, tc))
    return RotorResult(
        label or (vehicle if isinstance(vehicle, str) else "custom"), model,
        check_support(model, quad6dof_effects_truth(params, rotors=True)),
        params.rotor_time_constant, tau_found, seconds,
        sum(len(t) for t in flights.observed),
    )  # fmt: skip
