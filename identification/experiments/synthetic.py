"""Synthetic data for vehicles other than the paper's: the test bench of truth-free identification.

Everything here knows the truth (it integrates :func:`quad_envs.dynamics.planar_rhs` /
:func:`quad_envs.dynamics.quad6dof_rhs` with chosen parameters), so it lives in
``experiments`` and is used by tests, studies and the figures script, never by ``identify``.

Flights are either closed loop (the vehicle's PD on random waypoints plus random input
excitation, tilts of about 0.2 rad) or open loop (hover thrust plus smooth random sines on
every input). The inputs recorded are the *applied* (saturated) ones, held over each step.
Three integrators make data that no method can mistake for its own:

``rk4``       one RK4 step per sample (our formulation's own integrator: exact for ``rk4``);
``rk4x10``    ten RK4 substeps per sample;
``solve_ivp`` scipy's DOP853 at rtol 1e-11 over each sample step, the input held (ZOH).

Optional linear drag (force ``-c v`` on the translational velocities) changes the vehicle,
and :func:`truth_planar` / :func:`truth_quad6dof` give the true coefficients of what was flown.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp

from identification.data import Trajectory
from quad_envs.controllers import PlanarPD, Quad6DOFPD
from quad_envs.dynamics import (
    PLANAR_INPUT_NAMES,
    PLANAR_STATE_NAMES,
    QUAD6DOF_INPUT_NAMES,
    QUAD6DOF_STATE_NAMES,
    planar_rhs,
    quad6dof_rhs,
    saturate_planar,
    saturate_quad6dof,
)
from quad_envs.integrators import rk4_step
from quad_envs.params import PlanarQuadParams, Quad6DOFParams
from quad_envs.trajectories import RandomWaypoints

INTEGRATORS = ("rk4", "rk4x10", "solve_ivp")

OTHER_PLANAR = PlanarQuadParams(mass=0.5, Ixx=3e-3, arm_length=0.15, rotor_force_max=0.5 * 9.81)
"""A planar vehicle unlike the paper's: 2.8x the mass, 12x the inertia."""

OTHER_6DOF = Quad6DOFParams(
    mass=0.8, Jxx=6e-3, Jyy=7e-3, Jzz=1.2e-2, arm_length=0.2, rotor_force_max=0.8 * 9.81 / 2
)
"""A 6-DOF vehicle unlike the paper's: 4.4x the mass, 24-32x the inertia."""

HEAVY_PLANAR = PlanarQuadParams(mass=1.2, Ixx=8e-3, arm_length=0.2, rotor_force_max=1.2 * 9.81)
"""A second non-paper planar vehicle: 6.7x the mass, 32x the inertia of the paper's."""

HEAVY_6DOF = Quad6DOFParams(
    mass=2.0, Jxx=2e-2, Jyy=2.4e-2, Jzz=3.6e-2, arm_length=0.3, rotor_force_max=2.0 * 9.81 / 2
)
"""A second non-paper 6-DOF vehicle: 2.5x the mass of OTHER_6DOF, 3-3.4x its inertia. (With
J = diag(3, 4, 6)e-2 its yaw authority is half as large and the PD loses it at these
references: the flight generator refuses such flights.)"""


@dataclass(frozen=True)
class FlightSpec:
    """How to fly the synthetic data.

    Attributes:
        flights: Number of trajectories.
        steps: Samples per trajectory.
        dt: Sample (and input hold) period [s].
        integrator: One of :data:`INTEGRATORS`.
        open_loop: Hover thrust plus random sines instead of PD flights.
        tilt: Target tilt amplitude [rad] (waypoint spread / open-loop attitude sines).
        excitation: Random input noise, as a fraction of hover thrust (moments scaled alike).
        drag: Linear drag coefficient c [N s/m] (0: none).
        seed: Random seed.
        lag: Time constant [s] of a first-order lag the actuators follow the (saturated)
            commands through, integrated with the states; the commands are logged (0: none).
        log_commands: Log the commands before the rotors' limits clip them (a logger that
            records what the controller sent) instead of the applied inputs.
    """

    flights: int = 3
    steps: int = 1000
    dt: float = 0.01
    integrator: str = "rk4"
    open_loop: bool = False
    tilt: float = 0.2
    excitation: float = 0.05
    drag: float = 0.0
    seed: int = 0
    lag: float = 0.0
    log_commands: bool = False

    def __post_init__(self) -> None:
        if self.integrator not in INTEGRATORS:
            raise ValueError(f"unknown integrator {self.integrator!r}; valid: {INTEGRATORS}")
        if self.flights < 1 or self.steps < 2 or self.seed < 0:
            raise ValueError(f"flights and steps must be positive and seed non-negative, got "
                             f"{self.flights}, {self.steps} and {self.seed}")  # fmt: skip
        if not (np.isfinite(self.dt) and self.dt > 0 and np.isfinite(self.tilt) and self.tilt > 0):
            raise ValueError(f"dt and tilt must be finite and positive, got {self.dt} and "
                             f"{self.tilt}")  # fmt: skip
        if not (np.isfinite(self.excitation) and self.excitation >= 0 and np.isfinite(self.drag)
                and self.drag >= 0):  # fmt: skip
            raise ValueError(f"excitation and drag must be finite and non-negative, got "
                             f"{self.excitation} and {self.drag}")  # fmt: skip
        if not (np.isfinite(self.lag) and self.lag >= 0):
            raise ValueError(f"lag must be finite and non-negative, got {self.lag}")


def _step(
    rhs: Callable[[np.ndarray, np.ndarray], np.ndarray],
    x: np.ndarray,
    u: np.ndarray,
    dt: float,
    integrator: str,
) -> np.ndarray:
    if integrator == "rk4":
        return rk4_step(rhs, x, u, dt)
    if integrator == "rk4x10":
        return rk4_step(rhs, x, u, dt, substeps=10)
    sol = solve_ivp(lambda _t, y: rhs(y, u), (0.0, dt), x, method="DOP853", rtol=1e-11, atol=1e-12)
    return sol.y[:, -1]


def planar_drag_rhs(params: PlanarQuadParams, drag: float) -> Callable:
    """The planar rhs with linear drag ``-drag v / m`` on y_dot and z_dot."""

    def rhs(x: np.ndarray, u: np.ndarray) -> np.ndarray:
        out = planar_rhs(x, u, params)
        if drag:
            out = out.copy()
            out[..., 3:5] -= (drag / params.mass) * np.asarray(x)[..., 3:5]
        return out

    return rhs


def quad6dof_drag_rhs(params: Quad6DOFParams, drag: float) -> Callable:
    """The 6-DOF rhs with linear drag ``-drag v_body / m`` on u, v, w."""

    def rhs(x: np.ndarray, u: np.ndarray) -> np.ndarray:
        out = quad6dof_rhs(x, u, params)
        if drag:
            out = out.copy()
            out[..., 6:9] -= (drag / params.mass) * np.asarray(x)[..., 6:9]
        return out

    return rhs


OPEN_LOOP_BANDS = ((0.5, 2.0), (0.5, 2.0), (0.2, 0.6))
"""Frequency bands [Hz] of the open-loop swing of roll, pitch and yaw: the yaw moment of a
rotor's drag is small, and a faster yaw swing saturates the rotors."""


def _open_loop_inputs(
    rng: np.random.Generator, t: np.ndarray, hover: float, inertia: np.ndarray, tilt: float
) -> np.ndarray:
    """Hover thrust +-15 % and moments that swing each angle by about ``tilt`` (cosines).

    Each axis follows ``angle(t) = sum_k s_k a_k (1 - cos(w_k t))`` (signs alternating), which
    starts at rest (angle and rate zero, as the vehicle does), so the open-loop swing does
    not drift off; on the 6-DOF vehicle the coupling of the axes still makes it wander.
    """
    cols = [hover * (1.0 + 0.15 * _sines(rng, t, 3))]
    signs = np.array([1.0, -1.0, 1.0])
    for inertia_i, band in zip(inertia, OPEN_LOOP_BANDS, strict=False):
        freqs = rng.uniform(*band, size=3) * 2 * np.pi
        amps = signs * tilt / 3 * rng.uniform(0.5, 1.0, size=3)
        # angle'' = sum a w^2 cos(w t)  ->  moment = I angle''
        moment = (amps * freqs**2 * np.cos(np.outer(t, freqs))).sum(axis=1)
        cols.append(inertia_i * moment)
    return np.column_stack(cols)


def _sines(rng: np.random.Generator, t: np.ndarray, count: int) -> np.ndarray:
    freqs = rng.uniform(0.3, 2.0, size=count) * 2 * np.pi
    phases = rng.uniform(0, 2 * np.pi, size=count)
    return np.sin(np.outer(t, freqs) + phases).sum(axis=1) / count


def _sagging(plant: Callable, size: int, sag: float, length: float, power: int) -> Callable:
    """``plant(x, a)`` applying ``(1 - sag (t / length)^power) a``: a battery's sag.

    In continuous time: the time ``t`` rides along as a state after the plant's ``size``
    ones.
    """

    def rhs(z: np.ndarray, c: np.ndarray) -> np.ndarray:
        gain = 1.0 - sag * (z[size] / length) ** power
        return np.concatenate([plant(z[:size], gain * c), [1.0]])

    return rhs


def _actuated(plant: Callable, size: int, lag: float) -> Callable:
    """``plant(x, a)`` with the actuators' outputs ``a`` as states after its ``size`` ones.

    They follow the held command ``c`` as ``a' = (c - a) / lag``.
    """

    def rhs(z: np.ndarray, c: np.ndarray) -> np.ndarray:
        return np.concatenate([plant(z[:size], z[size:]), (c - z[size:]) / lag])

    return rhs


def _fly(
    rhs: Callable,
    saturate: Callable,
    controller: Callable | None,
    refs: np.ndarray | None,
    open_u: np.ndarray | None,
    x0: np.ndarray,
    noise: np.ndarray,
    spec: FlightSpec,
) -> tuple[np.ndarray, np.ndarray]:
    n, size = spec.steps, x0.size
    states = np.empty((n, size))
    applied = np.empty((n, noise.shape[1]))
    logged = np.empty_like(applied) if spec.log_commands else applied
    x = x0
    if spec.lag > 0:
        rhs = _actuated(rhs, size, spec.lag)
    for k in range(n):
        states[k] = x[:size]
        command = controller(x[:size], refs[k]) if controller is not None else open_u[k]
        logged[k] = command + noise[k]
        applied[k] = saturate(logged[k])
        if spec.lag > 0 and k == 0:  # the actuators start at the first command
            x = np.concatenate([x, applied[0]])
        x = _step(rhs, x, applied[k], spec.dt, spec.integrator)
    return states, logged


def planar_flights(
    params: PlanarQuadParams = OTHER_PLANAR, spec: FlightSpec = FlightSpec()
) -> list[Trajectory]:
    """Planar flights of ``params`` (closed loop by default), applied inputs recorded.

    Args:
        params: The vehicle.
        spec: Number, length, integrator, excitation, drag, seed.

    Returns:
        ``spec.flights`` trajectories of ``spec.steps`` samples (names as the planar preset).
    """
    rng = np.random.default_rng(spec.seed)
    rhs = planar_drag_rhs(params, spec.drag)
    sat = lambda u: saturate_planar(u, params)  # noqa: E731
    t = np.arange(spec.steps) * spec.dt
    scale = np.array([params.hover_thrust, params.Ixx * 20.0]) * spec.excitation
    trajs = []
    for _ in range(spec.flights):
        noise = rng.normal(size=(spec.steps, 2)) * scale
        x0 = np.zeros(6)
        x0[1] = 1.0
        if spec.open_loop:
            u = _open_loop_inputs(rng, t, params.hover_thrust, np.array([params.Ixx]), spec.tilt)
            states, applied = _fly(rhs, sat, None, None, u, x0, noise * 0.2, spec)
        else:
            # waypoint spread sets the tilt: a_y ~ g tilt needs ~ tilt g / Kp_y metres
            half = spec.tilt * params.gravity / 60.0 * 6.0
            ref = RandomWaypoints.sample(
                rng, 2, int(spec.steps * spec.dt / 1.5) + 2, (-half, 1.0 - half),
                (half, 1.0 + half), 1.5,
            )  # fmt: skip
            states, applied = _fly(rhs, sat, PlanarPD(params), ref(t), None, x0, noise, spec)
        _check_held(states[:, 2:3], len(trajs), spec)
        trajs.append(
            Trajectory(t, states, applied, PLANAR_STATE_NAMES, PLANAR_INPUT_NAMES, meta={})
        )
    return trajs


MAX_FLIGHT_TILT = 1.2
"""A flight tilting past this [rad] has been lost by the small-angle PD: refused."""


def _check_held(tilts: np.ndarray, index: int, spec: FlightSpec) -> None:
    """Refuses a flight whose roll or pitch left :data:`MAX_FLIGHT_TILT` (or finite numbers)."""
    worst = float(np.max(np.abs(tilts))) if np.isfinite(tilts).all() else np.inf
    if not worst < MAX_FLIGHT_TILT:
        if spec.open_loop:  # no controller: the random inputs themselves tipped it over
            raise ValueError(
                f"open-loop flight {index} of this vehicle tumbled (roll or pitch past "
                f"{MAX_FLIGHT_TILT} rad, {worst:.3g} at worst): its random inputs tipped it "
                f"over; lower the tilt (now {spec.tilt}), try another --seed, or fly it closed "
                "loop"
            )
        raise ValueError(
            f"flight {index} of this vehicle tumbled (roll or pitch past {MAX_FLIGHT_TILT} rad, "
            f"{worst:.3g} at worst): the PD lost it (saturated rotors, or a step of "
            f"{spec.dt:g} s too coarse for it); lower the tilt (now {spec.tilt}) or the step, or "
            "give the vehicle more control authority (rotor_force_max; arm_length for roll and "
            "pitch, gamma for yaw)"
        )


def quad6dof_flights(
    params: Quad6DOFParams = OTHER_6DOF, spec: FlightSpec = FlightSpec(flights=4)
) -> list[Trajectory]:
    """6-DOF flights of ``params`` (closed loop by default, yaw sweep), applied inputs recorded.

    Args:
        params: The vehicle.
        spec: Number, length, integrator, excitation, drag, seed.

    Returns:
        ``spec.flights`` trajectories of ``spec.steps`` samples (names as the 6-DOF preset).

    Raises:
        ValueError: A flight tilted past :data:`MAX_FLIGHT_TILT` (the PD lost the vehicle).
    """
    rng = np.random.default_rng(spec.seed)
    rhs = quad6dof_drag_rhs(params, spec.drag)
    sat = lambda u: saturate_quad6dof(u, params)  # noqa: E731
    t = np.arange(spec.steps) * spec.dt
    scale = (
        np.array([params.hover_thrust, params.Jxx * 20, params.Jyy * 20, params.Jzz * 10])
        * spec.excitation
    )
    trajs = []
    for _ in range(spec.flights):
        noise = rng.normal(size=(spec.steps, 4)) * scale
        x0 = np.zeros(12)
        x0[2] = 1.0
        if spec.open_loop:
            u = _open_loop_inputs(rng, t, params.hover_thrust, params.inertia, spec.tilt)
            states, applied = _fly(rhs, sat, None, None, u, x0, noise * 0.2, spec)
        else:
            half = spec.tilt * params.gravity / 20.0 * 4.0
            ref = RandomWaypoints.sample(
                rng, 3, int(spec.steps * spec.dt / 1.5) + 2, (-half, -half, 1.0 - half),
                (half, half, 1.0 + half), 1.5, yaw_amplitude=0.6, yaw_period=5.0,
            )  # fmt: skip
            ctrl = Quad6DOFPD(params)
            states, applied = _fly(rhs, sat, ctrl, ref(t), None, x0, noise, spec)
        _check_held(states[:, 3:5], len(trajs), spec)
        trajs.append(
            Trajectory(t, states, applied, QUAD6DOF_STATE_NAMES, QUAD6DOF_INPUT_NAMES, meta={})
        )
    return trajs


def add_noise(trajs: Sequence[Trajectory], sigma: float, seed: int = 7) -> list[Trajectory]:
    """Gaussian state noise of standard deviation ``sigma`` on every state (not on inputs)."""
    rng = np.random.default_rng(seed)
    return [
        Trajectory(
            tr.t,
            tr.x + sigma * rng.standard_normal(tr.x.shape),
            tr.u,
            tr.state_names,
            tr.input_names,
            meta={**tr.meta, "noise": sigma},
        )  # fmt: skip
        for tr in trajs
    ]


GUST_TAU = 0.4
"""Correlation time of :func:`gusty_planar_flights`' gusts [s]."""


def gusty_planar_flights(
    params: PlanarQuadParams, gust: float, seed: int, flights: int = 3, steps: int = 1200,
    dt: float = 0.01, lag: float = 0.0, sag: float = 0.0, sag_power: int = 1,
) -> list[Trajectory]:  # fmt: skip
    """Planar PD flights in unmeasured gusts: data from a simulator of its own, not the envs'.

    Ornstein-Uhlenbeck forces of standard deviation ``gust`` m g on y and z and a moment of
    ``gust`` m g times 2 cm, correlation :data:`GUST_TAU`, act on the planar equations,
    integrated by classical RK4 in five substeps per sample (the gusts drawn per substep).
    A PD of its own flies six random waypoints per flight with a tilt limit of 0.3 rad and an
    AR(1) dither on both inputs (5 % of m g, and 15 Ixx); the applied inputs are logged,
    held over each step, the gusts are not. The controller answers the gusts, so the inputs
    correlate with the equation errors: the closed-loop case of unmeasured forces.

    With ``lag`` > 0 [s] the actuators follow the commands through a first-order lag (a
    motor's time constant; integrated with the states) and the *commands* are logged: the
    case of :meth:`Trajectory.lag_inputs`.

    With ``sag`` > 0 a battery sags by that share over each flight: the vehicle applies
    ``1 - sag (t / T)^sag_power`` times the commands (``T`` the flight's length; 2: a sag
    that speeds up as the charge runs out; in continuous time,
    the RK4 stages see it move within the step), and the commands are logged (the case of
    :meth:`Trajectory.drift_inputs`); the PD does not know it. Not with ``lag``.
    """
    if sag and lag:
        raise ValueError("a sag and a lag together are not simulated: give one")
    rng = np.random.default_rng(seed)
    m, ixx, g = params.mass, params.Ixx, 9.81
    out = []
    for _ in range(flights):
        x, force, dither = np.array([0.0, 1.0, 0.0, 0.0, 0.0, 0.0]), np.zeros(3), np.zeros(2)
        act = np.array([m * g, 0.0])  # the actuators' output (with a lag)
        goals = rng.uniform([-1.5, 0.5], [1.5, 2.5], size=(6, 2))
        states, inputs = np.empty((steps, 6)), np.empty((steps, 2))
        for k in range(steps):
            y, z, phi, vy, vz, w = x
            goal = goals[k * 6 // steps]
            ay, az = 3 * (goal[0] - y) - 2.5 * vy, 4 * (goal[1] - z) - 3 * vz
            tilt = np.clip(-ay / g, -0.3, 0.3)
            dither = 0.9 * dither + 0.44 * rng.normal(size=2) * [0.05 * m * g, 15 * ixx]
            u = dither + [m * (g + az) / np.cos(phi), ixx * (250 * (tilt - phi) - 30 * w)]
            states[k], inputs[k] = x, u
            h = dt / 5
            for j in range(5):
                decay = np.exp(-h / GUST_TAU)
                kick = gust * m * g * rng.normal(size=3) * [1.0, 1.0, 0.02]
                force = decay * force + np.sqrt(1 - decay * decay) * kick

                def plant(s: np.ndarray, a: np.ndarray, d: np.ndarray = force) -> np.ndarray:
                    return np.array([s[3], s[4], s[5], (d[0] - a[0] * np.sin(s[2])) / m,
                                     (a[0] * np.cos(s[2]) - m * g + d[1]) / m,
                                     (a[1] + d[2]) / ixx])  # fmt: skip

                if lag > 0:  # the actuators' outputs ride along as states
                    both = rk4_step(_actuated(plant, 6, lag), np.concatenate([x, act]), u, h)
                    x, act = both[:6], both[6:]
                elif sag > 0:  # the time since the flight's start rides along
                    clock = np.concatenate([x, [k * dt + j * h]])
                    sagging = _sagging(plant, 6, sag, steps * dt, sag_power)
                    x = rk4_step(sagging, clock, u, h)[:6]
                else:
                    x = rk4_step(plant, x, u, h)
        t = np.arange(steps) * dt
        meta = {"gust": gust, "lag": lag, "sag": sag}
        out.append(Trajectory(t, states, inputs, PLANAR_STATE_NAMES, PLANAR_INPUT_NAMES, meta=meta))
    return out


def truth_planar(params: PlanarQuadParams = OTHER_PLANAR, drag: float = 0.0) -> dict:
    """True planar model {state: {feature: coefficient}}, with the drag terms when drag > 0."""
    m = params.mass
    truth: dict[str, dict[str, float]] = {
        "y": {"y_dot": 1.0},
        "z": {"z_dot": 1.0},
        "phi": {"phi_dot": 1.0},
        "y_dot": {"sin(phi) u1": -1.0 / m},
        "z_dot": {"1": -params.gravity, "cos(phi) u1": 1.0 / m},
        "phi_dot": {"u2": 1.0 / params.Ixx},
    }
    if drag:
        truth["y_dot"]["y_dot"] = -drag / m
        truth["z_dot"]["z_dot"] = -drag / m
    return truth


def truth_quad6dof(params: Quad6DOFParams = OTHER_6DOF, drag: float = 0.0) -> dict:
    """True 6-DOF model {state: {feature: coefficient}} (36 terms, 39 with drag)."""
    from identification.experiments.truth import quad6dof_truth

    truth = {k: dict(v) for k, v in quad6dof_truth(params).items()}
    if drag:
        for name in ("u", "v", "w"):
            truth[name][name] = -drag / params.mass
    return truth


@dataclass(frozen=True)
class SupportCheck:
    """A model against a known truth.

    Attributes:
        missed: True terms the model lacks, as ``state: term``.
        spurious: Terms the model has that the truth lacks.
        max_rel_error: Largest |found - true| / |true| over the true terms (inf if one missed).
        n_terms: Non-zero terms of the model.
    """

    missed: tuple[str, ...]
    spurious: tuple[str, ...]
    max_rel_error: float
    n_terms: int

    @property
    def exact_support(self) -> bool:
        """No term missed, none spurious."""
        return not self.missed and not self.spurious

    @property
    def off(self) -> int:
        """Missed plus spurious terms."""
        return len(self.missed) + len(self.spurious)


def check_support(model: object, truth: dict[str, dict[str, float]]) -> SupportCheck:
    """Compares a model's coefficients with a truth {state: {feature: value}} by canonical term."""
    from identification.features import parse_term

    found: dict[tuple[str, object], float] = {}
    for i, state in enumerate(model.state_names):  # type: ignore[attr-defined]
        for j, name in enumerate(model.feature_names):  # type: ignore[attr-defined]
            c = float(model.coefficients[i, j])  # type: ignore[attr-defined]
            if c != 0.0:
                key = (state, parse_term(name))
                found[key] = found.get(key, 0.0) + c
    true = {(s, parse_term(n)): v for s, terms in truth.items() for n, v in terms.items()}
    missed = tuple(f"{s}: {_name(t)}" for s, t in true if (s, t) not in found)
    spurious = tuple(f"{s}: {_name(t)}" for s, t in found if (s, t) not in true)
    errors = [abs(found.get(k, 0.0) - v) / abs(v) for k, v in true.items()]
    worst = float("inf") if missed else float(max(errors, default=0.0))
    return SupportCheck(missed, spurious, worst, len(found))


def truth_gaps(
    model: object, truth: dict[str, dict[str, float]], trajs: Sequence[Trajectory], window: int
) -> dict[str, float]:
    """How much worse each equation's found support fits the data than the true support.

    Both supports are refitted by least squares on the same RK4 rows (stage points from the
    truth, the model's window). Returns ``{state: (RSS_found - RSS_true) / sigma^2}``, in
    residual variances of the true support, for the equations whose support differs from the
    truth (a negative gap: the data prefer the found support).
    """
    from identification.experiments.truth import truth_matrix
    from identification.fit import Gram, grams
    from identification.support import residual_variance

    names = list(model.feature_names)  # type: ignore[attr-defined]
    states = list(model.state_names)  # type: ignore[attr-defined]
    true_xi = truth_matrix(truth, states, names)
    gram = Gram.stack(grams(trajs, names, "rk4", window, true_xi))
    out = {}
    for i, state in enumerate(states):
        found = np.flatnonzero(model.coefficients[i])  # type: ignore[attr-defined]
        true = np.flatnonzero(true_xi[i])
        if set(found) == set(true):
            continue
        rss_true, sigma2 = residual_variance(gram, i, true)
        rss_found, _ = residual_variance(gram, i, found)
        out[state] = (rss_found - rss_true) / sigma2
    return out


def worse_than_truth(
    model: object, truth: dict[str, dict[str, float]], trajs: Sequence[Trajectory], window: int
) -> list[str]:
    """States whose found support fits the data significantly worse than the true support.

    The F-test of the selection (p = 0.001) on :func:`truth_gaps`. An equation off the true
    support but not listed here is one the data cannot tell from the truth; one listed is a
    miss of the search.
    """
    from identification.support import F_CRITICAL

    return [s for s, gap in truth_gaps(model, truth, trajs, window).items() if gap > F_CRITICAL]


def _name(term: object) -> str:
    from identification.features import term_name

    return term_name(term)  # type: ignore[arg-type]


def rhs_error(model: object, truth_rhs: Callable, trajs: Sequence[Trajectory]) -> float:
    """Largest relative error of the model's rhs on the data: max|f - f_true| / max|f_true|."""
    x = np.concatenate([tr.x for tr in trajs])
    u = np.concatenate([tr.u for tr in trajs])
    true = truth_rhs(x, u)
    diff = model.rhs(x, u) - true  # type: ignore[attr-defined]
    return float(np.max(np.abs(diff).max(axis=0) / np.maximum(np.abs(true).max(axis=0), 1e-12)))
