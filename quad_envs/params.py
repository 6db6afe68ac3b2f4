"""Vehicle parameters as frozen dataclasses (SI units) and the named presets.

Three vehicles, each as a planar and a 6-DOF parameter set (:data:`PRESETS`):

* ``paper``: the paper's vehicle (Manaa et al., section 2 and the authors' code), a 0.18 kg
  quadrotor with 0.086 m arms. The default; the environments reproduce the authors' runs.
* ``crazyflie``: the Crazyflie 2.1 Brushless of the nano-drone benchmark (Busetto et al.,
  "Nonlinear System Identification for a Nano-drone Benchmark", Control Eng. Practice 2026,
  arXiv 2512.14450; ``../shared/data/nanodrone/README.md``): m = 0.045 kg, X frame with a
  0.0353 m moment arm, J = diag(2.40e-5, 2.40e-5, 3.2e-5) kg m^2, Kt = 3.72e-8 N s^2, yaw
  coefficient 7.7e-11 N m s^2, motor speeds 500 to 2,500 rad/s as flown.
* ``pelican``: the AscTec Pelican of the RotorS simulator (Furrer et al., "RotorS: A Modular
  Gazebo MAV Simulator Framework", Robot Operating System (ROS), Springer 2016;
  ``rotors_description/urdf/pelican.xacro``): m = 1.0 kg, '+' frame with 0.21 m arms,
  J = diag(0.01, 0.01, 0.02) kg m^2, motor constant 9.9865e-6 N s^2, moment constant
  0.016 m, rotor time constant 0.0125 s (spin-up; 0.025 s spin-down there), at most 838 rad/s,
  rotor-drag coefficient 8.06428e-5 N s/m per rad/s of rotor speed.

The effect coefficients (rotor time constant, drag) are used only when the corresponding
effect is switched on (:class:`quad_envs.physics.Effects`); see :mod:`quad_envs.physics` for
the equations. Linear rotor drag follows Faessler, Franchi and Scaramuzza, "Differential
flatness of quadrotor dynamics subject to rotor drag", RA-L 2018: F_B = -D v_B with D
diagonal and constant (the rotor-speed-proportional drag of RotorS and rotorpy,
``k_d sum(omega_i) v``, evaluated at hover). Quadratic body drag is
F_B = -c |v_B| v_B per body axis with c = rho C_D A / 2.

A planar parameter set is the vehicle seen in its y-z plane: its two "rotors" are the left and
right halves of the vehicle (``motors_per_rotor`` motors each, so a planar rotor's limits are
that many motors' limits) at the roll moment arm.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

_G = 9.81

_POSITIVE = ("mass", "Ixx", "Jxx", "Jyy", "Jzz", "arm_length", "gravity")
_NONNEGATIVE = (
    "rotor_force_min",
    "rotor_time_constant",
    "thrust_coefficient",
    "drag_linear_xy",
    "drag_linear_z",
    "drag_quadratic_xy",
    "drag_quadratic_z",
)


def _check_physical(params: object) -> None:
    """Raises ValueError naming the first field a physical vehicle cannot have.

    Masses, inertias and arms are positive, the rotor limits ordered and non-negative, time
    constants, thrust and drag coefficients non-negative, every number finite (a zero or
    negative mass would fly a vehicle that cannot exist: inf accelerations, or one that falls
    up).
    """
    for field in dataclasses.fields(params):  # type: ignore[arg-type]
        value = getattr(params, field.name)
        if isinstance(value, str):
            continue
        value = np.asarray(value, dtype=float)  # arrays: a batch of vehicles
        if not np.isfinite(value).all():
            raise ValueError(f"vehicle parameter {field.name} must be finite, got {value}")
        if field.name in _POSITIVE and not (value > 0).all():
            raise ValueError(f"vehicle parameter {field.name} must be positive, got {value}")
        if field.name in _NONNEGATIVE and not (value >= 0).all():
            raise ValueError(f"vehicle parameter {field.name} must be >= 0, got {value}")
    low, high = params.rotor_force_min, params.rotor_force_max  # type: ignore[attr-defined]
    if not (np.asarray(high) > np.asarray(low)).all():
        raise ValueError(
            f"vehicle parameter rotor_force_max ({high}) must exceed rotor_force_min ({low})"
        )


@dataclass(frozen=True)
class PlanarQuadParams:
    """Planar (y-z plane) quadrotor: two rotors at +-L from the centre of mass.

    Attributes:
        mass: Vehicle mass m [kg].
        Ixx: Moment of inertia about the roll (x) axis [kg m^2].
        arm_length: Distance L from the centre of mass to each rotor [m].
        gravity: Gravitational acceleration g [m/s^2].
        rotor_force_min: Lower limit of each rotor's thrust [N].
        rotor_force_max: Upper limit of each rotor's thrust [N]; the authors' code uses
            max_force / 2 with max_force = 2 m g, i.e. m g per rotor.
        rotor_time_constant: Time constant tau of the first-order rotor-thrust response [s]
            (rotor-dynamics effect only).
        thrust_coefficient: Kt in T = Kt omega^2 per motor [N s^2] (0: unknown; the
            motor-speed action mode needs it).
        motors_per_rotor: Motors lumped into one planar rotor (1 for the paper's two-rotor
            vehicle, 2 for a quadrotor's left and right pairs).
        drag_linear_xy: Linear (rotor) drag D along the body's lateral axis [N s/m].
        drag_linear_z: Linear (rotor) drag D along the body's thrust axis [N s/m].
        drag_quadratic_xy: Quadratic body drag c along the lateral axis [N s^2/m^2].
        drag_quadratic_z: Quadratic body drag c along the thrust axis [N s^2/m^2].
    """

    mass: float = 0.18
    Ixx: float = 2.5e-4
    arm_length: float = 0.086
    gravity: float = _G
    rotor_force_min: float = 0.0
    rotor_force_max: float = 0.18 * _G
    rotor_time_constant: float = 0.02
    thrust_coefficient: float = 0.0
    motors_per_rotor: int = 1
    drag_linear_xy: float = 0.02
    drag_linear_z: float = 0.01
    drag_quadratic_xy: float = 0.005
    drag_quadratic_z: float = 0.01

    def __post_init__(self) -> None:
        _check_physical(self)
        if not (np.asarray(self.motors_per_rotor) >= 1).all():
            raise ValueError(
                f"vehicle parameter motors_per_rotor must be >= 1, got {self.motors_per_rotor}"
            )

    @property
    def hover_thrust(self) -> float:
        """Total thrust that balances gravity, m g [N]."""
        return self.mass * self.gravity

    @property
    def thrust_max(self) -> float:
        """Largest total thrust u1 the rotors can produce [N]."""
        return 2.0 * self.rotor_force_max

    @property
    def moment_max(self) -> float:
        """Largest roll moment |u2| the rotors can produce [N m]."""
        return (self.rotor_force_max - self.rotor_force_min) * self.arm_length

    @property
    def n_rotors(self) -> int:
        """Number of (planar) rotors: 2."""
        return 2

    @property
    def mixer(self) -> np.ndarray:
        """Matrix M with u = M @ [f1, f2]: u1 = f1 + f2, u2 = L (f2 - f1)."""
        arm = self.arm_length
        return np.array([[1.0, 1.0], [-arm, arm]])

    @property
    def rotor_thrust_per_speed2(self) -> float:
        """Thrust of one planar rotor per squared motor speed, motors_per_rotor Kt [N s^2]."""
        return self.motors_per_rotor * self.thrust_coefficient

    def replace(self, **changes: float) -> PlanarQuadParams:
        """Returns a copy with some fields changed (domain randomisation)."""
        return dataclasses.replace(self, **changes)


@dataclass(frozen=True)
class Quad6DOFParams:
    """Full 6-DOF quadrotor (paper section 2), '+' or 'x' frame.

    '+' frame (the paper's mixer): rotor 1 on +x, 2 on +y, 3 on -x, 4 on -y (z up);
    u = [sum T, L (T2 - T4), L (T3 - T1), gamma (T1 - T2 + T3 - T4)].
    'x' frame (the nano-drone benchmark's motor order: 1 front-right, 2 back-right,
    3 back-left, 4 front-left) with L the moment arm about each axis;
    u = [sum T, L (-T1 - T2 + T3 + T4), L (-T1 + T2 + T3 - T4), gamma (-T1 + T2 - T3 + T4)].

    Attributes:
        mass: Vehicle mass m [kg].
        Jxx: Moment of inertia about body x [kg m^2].
        Jyy: Moment of inertia about body y [kg m^2].
        Jzz: Moment of inertia about body z [kg m^2].
        arm_length: Moment arm L of each rotor about the roll and pitch axes [m].
        gravity: Gravitational acceleration g [m/s^2].
        gamma: Ratio k_M / k_F of a rotor's drag moment to its thrust [m]; 0.01 m is a
            typical value for small propellers (the paper leaves it symbolic).
        rotor_force_min: Lower limit of each rotor's thrust [N].
        rotor_force_max: Upper limit of each rotor's thrust [N]; m g / 2 gives the same
            thrust-to-weight ratio of 2 as the planar vehicle.
        frame: ``+`` or ``x`` (rotor layout of the mixer).
        rotor_time_constant: Time constant tau of the first-order rotor-thrust response [s].
        thrust_coefficient: Kt in T = Kt omega^2 [N s^2] (0: unknown).
        drag_linear_xy: Linear (rotor) drag D along body x and y [N s/m].
        drag_linear_z: Linear (rotor) drag D along body z [N s/m].
        drag_quadratic_xy: Quadratic body drag c along body x and y [N s^2/m^2].
        drag_quadratic_z: Quadratic body drag c along body z [N s^2/m^2].
    """

    mass: float = 0.18
    Jxx: float = 2.5e-4
    Jyy: float = 2.32e-4
    Jzz: float = 3.738e-4
    arm_length: float = 0.086
    gravity: float = _G
    gamma: float = 0.01
    rotor_force_min: float = 0.0
    rotor_force_max: float = 0.18 * _G / 2.0
    frame: str = "+"
    rotor_time_constant: float = 0.02
    thrust_coefficient: float = 0.0
    drag_linear_xy: float = 0.02
    drag_linear_z: float = 0.01
    drag_quadratic_xy: float = 0.005
    drag_quadratic_z: float = 0.01

    def __post_init__(self) -> None:
        if self.frame not in ("+", "x"):
            raise ValueError(f"frame must be '+' or 'x', got {self.frame!r}")
        _check_physical(self)

    @property
    def inertia(self) -> np.ndarray:
        """Diagonal of the inertia matrix J [kg m^2]."""
        return np.array([self.Jxx, self.Jyy, self.Jzz])

    @property
    def hover_thrust(self) -> float:
        """Total thrust that balances gravity, m g [N]."""
        return self.mass * self.gravity

    @property
    def thrust_max(self) -> float:
        """Largest total thrust u1 [N]."""
        return 4.0 * self.rotor_force_max

    @property
    def n_rotors(self) -> int:
        """Number of rotors: 4."""
        return 4

    @property
    def mixer(self) -> np.ndarray:
        """Matrix M with u = M @ T (see the class docstring for both frames)."""
        arm, gam = self.arm_length, self.gamma
        if self.frame == "x":
            return np.array(
                [
                    [1.0, 1.0, 1.0, 1.0],
                    [-arm, -arm, arm, arm],
                    [-arm, arm, arm, -arm],
                    [-gam, gam, -gam, gam],
                ]
            )
        return np.array(
            [
                [1.0, 1.0, 1.0, 1.0],
                [0.0, arm, 0.0, -arm],
                [-arm, 0.0, arm, 0.0],
                [gam, -gam, gam, -gam],
            ]
        )

    @property
    def rotor_thrust_per_speed2(self) -> float:
        """Thrust of one rotor per squared motor speed, Kt [N s^2]."""
        return self.thrust_coefficient

    def replace(self, **changes: float) -> Quad6DOFParams:
        """Returns a copy with some fields changed (domain randomisation)."""
        return dataclasses.replace(self, **changes)


PAPER_PLANAR = PlanarQuadParams()
"""The paper's planar vehicle (authors' `get_quad_params.m`).

The effect coefficients are not in the paper: tau = 0.02 s and the drag values are
typical of a 0.18 kg vehicle, used only when an effect is switched on.
"""

PAPER_6DOF = Quad6DOFParams()
"""The same vehicle in 6-DOF, with J = diag(2.5e-4, 2.32e-4, 3.738e-4) kg m^2."""

# -- Crazyflie 2.1 Brushless (nano-drone benchmark) -------------------------------------
_CF_KT = 3.72e-8  # N s^2, fitted on the benchmark's flights (README)
_CF_SPEED = (500.0, 2500.0)  # rad/s, motor speeds seen in flight
_CF_HOVER_SPEED_SUM = 4.0 * np.sqrt(0.045 * _G / 4.0 / _CF_KT)  # sum of omega at hover
_CF_DRAG = dict(
    # rotorpy's Crazyflie rotor drag k_d = 1.02506e-6 and inflow k_z = 7.553e-7 kg/rad
    # (rotorpy/vehicles/crazyflie_params.py, after Foerster 2015) times sum(omega) at hover.
    drag_linear_xy=1.02506e-6 * _CF_HOVER_SPEED_SUM,
    drag_linear_z=7.553e-7 * _CF_HOVER_SPEED_SUM,
    # rho C_D A / 2 with C_D = 1, side area 0.005 m^2, top area 0.01 m^2 (estimates).
    drag_quadratic_xy=0.5 * 1.225 * 0.005,
    drag_quadratic_z=0.5 * 1.225 * 0.01,
)
CRAZYFLIE_6DOF = Quad6DOFParams(
    mass=0.045,
    Jxx=2.40e-5,
    Jyy=2.40e-5,
    Jzz=3.2e-5,
    arm_length=0.0353,
    gamma=7.7e-11 / _CF_KT,
    rotor_force_min=_CF_KT * _CF_SPEED[0] ** 2,
    rotor_force_max=_CF_KT * _CF_SPEED[1] ** 2,
    frame="x",
    # rotorpy's Crazyflie motor response time (tau_m = 0.072 s for the brushed 2.0).
    rotor_time_constant=0.072,
    thrust_coefficient=_CF_KT,
    **_CF_DRAG,
)
"""Crazyflie 2.1 Brushless of the nano-drone benchmark (X frame, motor order of its logs)."""

CRAZYFLIE_PLANAR = PlanarQuadParams(
    mass=0.045,
    Ixx=2.40e-5,
    arm_length=0.0353,
    rotor_force_min=2 * _CF_KT * _CF_SPEED[0] ** 2,
    rotor_force_max=2 * _CF_KT * _CF_SPEED[1] ** 2,
    rotor_time_constant=0.072,
    thrust_coefficient=_CF_KT,
    motors_per_rotor=2,
    **_CF_DRAG,
)
"""The Crazyflie in its y-z plane: left and right motor pairs as the two rotors."""

# -- AscTec Pelican (RotorS) -------------------------------------------------------------
_PEL_KT = 9.9865e-6  # N s^2
_PEL_SPEED_MAX = 838.0  # rad/s
_PEL_HOVER_SPEED_SUM = 4.0 * np.sqrt(1.0 * _G / 4.0 / _PEL_KT)
_PEL_DRAG = dict(
    # RotorS rotor drag: 8.06428e-5 N s/m per rad/s of each rotor's speed, in the rotor
    # plane only (none along z), evaluated at hover.
    drag_linear_xy=8.06428e-5 * _PEL_HOVER_SPEED_SUM,
    drag_linear_z=0.0,
    # rho C_D A / 2 with C_D = 1, side area 0.03 m^2, top area 0.05 m^2 (estimates).
    drag_quadratic_xy=0.5 * 1.225 * 0.03,
    drag_quadratic_z=0.5 * 1.225 * 0.05,
)
PELICAN_6DOF = Quad6DOFParams(
    mass=1.0,
    Jxx=0.01,
    Jyy=0.01,
    Jzz=0.02,
    arm_length=0.21,
    gamma=0.016,
    rotor_force_min=0.0,
    rotor_force_max=_PEL_KT * _PEL_SPEED_MAX**2,
    frame="+",
    rotor_time_constant=0.0125,
    thrust_coefficient=_PEL_KT,
    **_PEL_DRAG,
)
"""AscTec Pelican as modelled in RotorS (about 1 kg, '+' frame, thrust-to-weight 2.9)."""

PELICAN_PLANAR = PlanarQuadParams(
    mass=1.0,
    Ixx=0.01,
    arm_length=0.21,
    rotor_force_min=0.0,
    rotor_force_max=2 * _PEL_KT * _PEL_SPEED_MAX**2,
    rotor_time_constant=0.0125,
    thrust_coefficient=_PEL_KT,
    motors_per_rotor=2,
    **_PEL_DRAG,
)
"""The Pelican in its y-z plane (a '+' frame seen as two lumped rotors at the arm)."""

PRESETS: dict[str, dict[str, PlanarQuadParams | Quad6DOFParams]] = {
    "paper": {"planar": PAPER_PLANAR, "quad6dof": PAPER_6DOF},
    "crazyflie": {"planar": CRAZYFLIE_PLANAR, "quad6dof": CRAZYFLIE_6DOF},
    "pelican": {"planar": PELICAN_PLANAR, "quad6dof": PELICAN_6DOF},
}
"""Named parameter sets by vehicle kind (``gym.make(..., vehicle="crazyflie")``)."""


def get_preset(name: str, kind: str) -> PlanarQuadParams | Quad6DOFParams:
    """The parameter set ``name`` for the vehicle kind ``kind`` (``planar``, ``quad6dof``)."""
    if name not in PRESETS:
        raise ValueError(f"unknown vehicle preset {name!r}; valid choices: {', '.join(PRESETS)}")
    return PRESETS[name][kind]


def check_can_hover(params: Any) -> None:
    """Raises ValueError when the rotors' largest thrust does not exceed the weight.

    No controller can fly such a vehicle: every flight, episode or log of it is a fall.
    """
    if not hasattr(params, "thrust_max"):
        return
    margin = np.asarray(params.thrust_max - params.hover_thrust, dtype=float)
    if not np.all(margin > 0):
        k = int(np.argmin(margin))  # the worst member of batched parameters
        top = float(np.ravel(np.broadcast_to(params.thrust_max, margin.shape))[k])
        weight = float(np.ravel(np.broadcast_to(params.hover_thrust, margin.shape))[k])
        raise ValueError(
            f"the vehicle cannot hover: its largest thrust {top:.4g} N does not exceed its "
            f"weight m g = {weight:.4g} N (raise rotor_force_max)"
        )


def with_changes(params: Any, changes: Mapping[str, str]) -> Any:
    """``params`` with some fields set from text (``mass=0.5`` on the command line).

    Each value is converted to its field's type; an unknown field, a value that is not of that
    type and a vehicle that cannot exist (:func:`_check_physical`) raise ValueError naming it.
    """
    fields = {f.name: getattr(params, f.name) for f in dataclasses.fields(params)}
    typed: dict[str, object] = {}
    for name, text in changes.items():
        if name not in fields:
            raise ValueError(
                f"unknown vehicle parameter {name!r}; valid names: {', '.join(fields)}"
            )
        kind = type(fields[name])
        if kind not in (float, int, str):
            raise ValueError(f"vehicle parameter {name!r} cannot be set from text")
        try:
            typed[name] = kind(text) if kind is not int else int(str(text), 10)
        except ValueError:
            raise ValueError(
                f"vehicle parameter {name} must be a {kind.__name__}, got {text!r}"
            ) from None
    return dataclasses.replace(params, **typed)
