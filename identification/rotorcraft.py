"""A physics-informed 6-DOF library for real rotorcraft driven by measured motor speeds.

State ``[x, y, z, phi, theta, psi, u, v, w, p, q, r]`` as in :mod:`quad_envs.dynamics` (Z-X-Y
Euler angles, body-frame velocity, body rates), inputs the K = 4 motor speeds
``omega1..omega4`` [rad/s], plus an optional first-order actuator state ``a`` (the speeds
through a lag of time constant ``tau``, initialised from the measured speeds before the
window; ``tau = 0``: no lag, ``a = omega``).

What is *not* fitted (kinematics):

    position' = R(phi, theta, psi) v_B,     angles' = T(phi, theta)^-1 omega_B,
    v_B' = -omega_B x v_B + f_B,            a' = (omega - a) / tau.

What *is* identified: the specific force f_B (3 equations) and the angular acceleration
omega_B' (3 equations) as sparse combinations of the readable terms of :data:`FEATURES`:

* squared motor speeds and their mixer combinations (the benchmark's X layout)
  ``W = sum a_i^2``, ``Mx = a3^2 + a4^2 - a1^2 - a2^2``, ``My = a2^2 + a3^2 - a1^2 - a4^2``,
  ``Mz = a2^2 + a4^2 - a1^2 - a3^2``;
* gravity in the body frame, ``R^T e_z = (gx, gy, gz)`` (coefficient -g where it belongs);
* velocity (rotor and body drag) ``u v w``, rates ``p q r``, motor speed times velocity
  ``S u, S v, S w`` with ``S = sum a_i`` (rotor drag is proportional to it);
* products of rates (rigid-body gyroscopic) ``q r, p r, p q``; rotor angular momentum
  ``N = a2 + a4 - a1 - a3`` times rates ``N p, N q``, and its rate ``Ndot`` (reaction torque
  of spinning rotors up, from the actuator state);
* a constant ``1`` (trim and sensor offsets).

The thrust term of ``w'`` (coefficient of ``W``) is Kt / m in m/rad^2.

Fitting (:func:`identify`): (1) sparse regression (pysindy ``STLSQ``) of smoothed derivatives
on the scaled library (equation error) gives a support and a start; (2) the coefficients on
that support are refined on ``horizon``-step open-loop rollouts of the training flights
(simulation error, Huber loss, L-BFGS, torch autograd); (3) terms whose typical contribution
is small are pruned and the rest refined again.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from identification.data import Trajectory
from quad_envs.dynamics import QUAD6DOF_STATE_NAMES
from quad_envs.fileio import write_json

SCHEMA = "quad-sindy/rotorcraft"
DYNAMIC_STATES = ("u", "v", "w", "p", "q", "r")
"""The identified equations: specific force (plus the exact -omega x v) and angular acceleration."""

FEATURES: dict[str, str] = {
    "1": "constant (trim, sensor offsets)",
    "gx": "gravity direction in body x, -cos(phi) sin(theta)",
    "gy": "gravity direction in body y, sin(phi)",
    "gz": "gravity direction in body z, cos(phi) cos(theta)",
    "W": "collective a1^2 + a2^2 + a3^2 + a4^2 [rad^2/s^2]",
    "Mx": "roll mix a3^2 + a4^2 - a1^2 - a2^2",
    "My": "pitch mix a2^2 + a3^2 - a1^2 - a4^2",
    "Mz": "yaw mix a2^2 + a4^2 - a1^2 - a3^2",
    "u": "body velocity x [m/s]",
    "v": "body velocity y [m/s]",
    "w": "body velocity z [m/s]",
    "p": "roll rate [rad/s]",
    "q": "pitch rate [rad/s]",
    "r": "yaw rate [rad/s]",
    "S u": "rotor drag: (a1 + a2 + a3 + a4) u",
    "S v": "rotor drag: (a1 + a2 + a3 + a4) v",
    "S w": "rotor drag: (a1 + a2 + a3 + a4) w",
    "q r": "gyroscopic q r",
    "p r": "gyroscopic p r",
    "p q": "gyroscopic p q",
    "N p": "rotor momentum (a2 + a4 - a1 - a3) p",
    "N q": "rotor momentum (a2 + a4 - a1 - a3) q",
    "Ndot": "rotor acceleration d/dt (a2 + a4 - a1 - a3)",
}
FEATURE_NAMES = tuple(FEATURES)

ENVELOPE = (
    (-1e3, -1e3, -1e3, -1.5, -1e6, -1e6, -30.0, -30.0, -30.0, -60.0, -60.0, -60.0),
    (1e3, 1e3, 1e3, 1.5, 1e6, 1e6, 30.0, 30.0, 30.0, 60.0, 60.0, 60.0),
)
"""Bounds a rollout's state is clipped to after every step (far outside any real flight;
roll inside +-1.5 rad keeps the Z-X-Y angle rates finite). A model that leaves them scores
large but finite errors, and a refinement started from it keeps finite gradients."""


@dataclass(frozen=True)
class NominalRotorcraft:
    """The benchmark's nominal vehicle (Crazyflie 2.1 Brushless), SI units.

    Attributes:
        mass: Mass [kg].
        arm: Arm length projected on the body axes [m].
        kt: Thrust per squared motor speed [N s^2].
        kc: Yaw moment per squared motor speed [N m s^2].
        jxx: Roll inertia [kg m^2].
        jyy: Pitch inertia [kg m^2].
        jzz: Yaw inertia [kg m^2].
        gravity: Gravitational acceleration [m/s^2].
        thrust_to_weight: Largest thrust over weight (the benchmark clips the thrust there).
    """

    mass: float = 0.045
    arm: float = 0.0353
    kt: float = 3.72e-8
    kc: float = 7.74e-12
    jxx: float = 2.3951e-5
    jyy: float = 2.3951e-5
    jzz: float = 3.2347e-5
    gravity: float = 9.81
    thrust_to_weight: float = 2.0

    @property
    def thrust_coefficient(self) -> float:
        """Kt / m: body-z acceleration per squared motor speed [m/rad^2]."""
        return self.kt / self.mass


NANODRONE_NOMINAL = NominalRotorcraft()


# -- batched kinematics (numpy arrays or torch tensors) -----------------------------------
def _xp(arr: Any) -> Any:
    """The array module of ``arr``: torch for tensors, else numpy (same names used below)."""
    return torch if isinstance(arr, torch.Tensor) else np


def _cat(arrays: Sequence[Any]) -> Any:
    return (
        torch.cat(arrays, -1) if isinstance(arrays[0], torch.Tensor) else np.concatenate(arrays, -1)
    )


def rotation_zxy_torch(phi: torch.Tensor, theta: torch.Tensor, psi: torch.Tensor) -> torch.Tensor:
    """:func:`quad_envs.dynamics.rotation_zxy` for tensors (or arrays): shape S + (3, 3)."""
    xp = _xp(phi)
    cf, sf, ct, st = xp.cos(phi), xp.sin(phi), xp.cos(theta), xp.sin(theta)
    cp, sp = xp.cos(psi), xp.sin(psi)
    rows = (
        (cp * ct - sf * sp * st, -cf * sp, cp * st + ct * sf * sp),
        (ct * sp + cp * sf * st, cf * cp, sp * st - cp * ct * sf),
        (-cf * st, sf, cf * ct),
    )
    return xp.stack([xp.stack(row, -1) for row in rows], -2)


def library(x: torch.Tensor, a: torch.Tensor, a_dot: torch.Tensor) -> torch.Tensor:
    """The terms of :data:`FEATURES` at states (..., 12), actuator speeds and their rates (..., 4).

    Works on torch tensors (differentiable) and numpy arrays alike.

    Returns:
        Array (..., len(FEATURES)), columns in :data:`FEATURE_NAMES` order.
    """
    xp = _xp(x)
    phi, theta = x[..., 3], x[..., 4]
    u, v, w, p, q, r = (x[..., i] for i in range(6, 12))
    sq = a * a
    a1, a2, a3, a4 = (a[..., i] for i in range(4))
    s1, s2, s3, s4 = (sq[..., i] for i in range(4))
    speed_sum = a1 + a2 + a3 + a4
    momentum = a2 + a4 - a1 - a3
    momentum_dot = a_dot[..., 1] + a_dot[..., 3] - a_dot[..., 0] - a_dot[..., 2]
    cf = xp.cos(phi)
    cols = (
        xp.ones_like(phi),
        -cf * xp.sin(theta),
        xp.sin(phi),
        cf * xp.cos(theta),
        s1 + s2 + s3 + s4,
        s3 + s4 - s1 - s2,
        s2 + s3 - s1 - s4,
        s2 + s4 - s1 - s3,
        u, v, w, p, q, r,
        speed_sum * u, speed_sum * v, speed_sum * w,
        q * r, p * r, p * q,
        momentum * p, momentum * q,
        momentum_dot,
    )  # fmt: skip
    return xp.stack(cols, -1)


def kinematics(x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The exact parts: position rate R v_B, Euler angle rates T^-1 omega, and -omega x v_B.

    R v_B is written out row by row (as in :func:`quad_envs.dynamics.quad6dof_rhs`), sharing
    the sines and cosines with the angle rates: fewer operations than building R.
    """
    phi, theta, psi = x[..., 3], x[..., 4], x[..., 5]
    u, v, w, p, q, r = (x[..., i] for i in range(6, 12))
    xp = _xp(x)
    cf, sf, ct, st = xp.cos(phi), xp.sin(phi), xp.cos(theta), xp.sin(theta)
    cp, sp = xp.cos(psi), xp.sin(psi)
    sf_st, sf_ct = sf * st, sf * ct
    pos_dot = xp.stack(
        (
            (cp * ct - sf_st * sp) * u - cf * sp * v + (cp * st + sf_ct * sp) * w,
            (ct * sp + cp * sf_st) * u + cf * cp * v + (sp * st - cp * sf_ct) * w,
            cf * (ct * w - st * u) + sf * v,
        ),
        -1,
    )
    angle_dot = xp.stack(
        (ct * p + st * r, q + (sf / cf) * (st * p - ct * r), (-st * p + ct * r) / cf), -1
    )
    coriolis = xp.stack((r * v - q * w, p * w - r * u, q * u - p * v), -1)
    return pos_dot, angle_dot, coriolis


# -- the model --------------------------------------------------------------------------
@dataclass
class RotorcraftModel:
    """Exact kinematics plus sparse identified accelerations over :data:`FEATURES`.

    Attributes:
        coefficients: Shape (6, len(FEATURES)), rows :data:`DYNAMIC_STATES`, physical units.
        tau: Actuator time constant [s]; 0 for none.
        dt: Sample period the model was identified at [s].
        meta: Provenance (flights, settings, losses).
    """

    coefficients: np.ndarray
    tau: float = 0.0
    dt: float = 0.01
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.coefficients = np.asarray(self.coefficients, dtype=np.float64)
        shape = (len(DYNAMIC_STATES), len(FEATURE_NAMES))
        if self.coefficients.shape != shape:
            raise ValueError(f"coefficients must have shape {shape}, got {self.coefficients.shape}")
        if not np.isfinite(self.coefficients).all():
            raise ValueError("coefficients contain NaN or infinite values")
        if self.tau < 0 or not np.isfinite(self.tau):
            raise ValueError(f"tau must be a non-negative number, got {self.tau}")

    @property
    def n_terms(self) -> int:
        """Non-zero identified coefficients (the kinematics are not counted)."""
        return int(np.count_nonzero(self.coefficients))

    @property
    def thrust_coefficient(self) -> float:
        """Coefficient of W in w': body-z acceleration per squared motor speed [m/rad^2]."""
        return float(self.coefficients[2, FEATURE_NAMES.index("W")])

    def equations(self, precision: int = 4) -> list[str]:
        """The identified equations as text (the kinematics are stated once)."""
        lines = [
            "[x, y, z]' = R(phi, theta, psi) [u, v, w]   (exact)",
            "[phi, theta, psi]' = T(phi, theta)^-1 [p, q, r]   (exact)",
        ]
        if self.tau > 0:
            lines.append(f"a_i' = (omega_i - a_i) / {self.tau:.4g}   (actuator, i = 1..4)")
        else:
            lines.append("a_i = omega_i   (no actuator lag)")
        coriolis = {"u": "r v - q w", "v": "p w - r u", "w": "q u - p v"}
        for i, state in enumerate(DYNAMIC_STATES):
            parts = [coriolis[state]] if state in coriolis else []
            for j, name in enumerate(FEATURE_NAMES):
                c = self.coefficients[i, j]
                if c != 0:
                    parts.append(f"{c:.{precision}g}" + ("" if name == "1" else f" {name}"))
            rhs = " + ".join(parts).replace("+ -", "- ") if parts else "0"
            lines.append(f"{state}' = {rhs}")
        return lines

    def hover_speeds(self) -> np.ndarray:
        """The four equal-time motor speeds that zero w', p', q', r' at rest, level [rad/s].

        At rest only the constant, gravity (gz = 1) and squared-speed mix terms act; their
        rows for w, p, q, r are linear in the squared speeds (least squares where a row has
        no motor term). Negative squares are clipped to zero.
        """
        names = FEATURE_NAMES
        mix = np.array([[1, 1, 1, 1], [-1, -1, 1, 1], [-1, 1, 1, -1], [-1, 1, -1, 1]], float)
        rows = self.coefficients[2:6]
        cols = [names.index(n) for n in ("W", "Mx", "My", "Mz")]
        offset = rows[:, names.index("1")] + rows[:, names.index("gz")]
        squares = np.linalg.lstsq(rows[:, cols] @ mix, -offset, rcond=None)[0]
        return np.sqrt(np.maximum(squares, 0.0))

    # -- simulation -------------------------------------------------------------------
    def actuator_states(self, omega: np.ndarray) -> np.ndarray:
        """Causal first-order filter of measured speeds (N, 4): the actuator state at each sample.

        ``a[k]`` uses ``omega[0..k-1]`` only (zero-order hold, exact discretisation), so a rollout
        from sample k may start from it; with ``tau = 0`` it is ``omega`` itself.
        """
        omega = np.asarray(omega, dtype=np.float64)
        if self.tau == 0:
            return omega.copy()
        alpha = 1.0 - np.exp(-self.dt / self.tau)
        out = np.empty_like(omega)
        out[0] = omega[0]
        for k in range(1, len(omega)):
            out[k] = out[k - 1] + alpha * (omega[k - 1] - out[k - 1])
        return out

    def rhs_torch(self, coefficients: torch.Tensor | None = None) -> Callable:
        """f(z, omega) on tensors: z = [state(12), actuator(4)], omega the held speeds (..., 4)."""
        xi = torch.as_tensor(self.coefficients) if coefficients is None else coefficients
        return self._field(xi)

    def _field(self, xi: Any) -> Callable:
        tau = self.tau

        def rhs(z: Any, omega: Any) -> Any:
            x, a = z[..., :12], z[..., 12:]
            if tau > 0:
                a_dot = (omega - a) / tau
            else:
                a, a_dot = omega, 0.0 * omega
            theta = library(x, a, a_dot)
            coef = xi.to(theta.dtype) if isinstance(theta, torch.Tensor) else xi
            accel = theta @ coef.T
            pos_dot, angle_dot, coriolis = kinematics(x)
            body = accel[..., 0:3] + coriolis
            return _cat((pos_dot, angle_dot, body, accel[..., 3:6], a_dot))

        return rhs

    def rhs(self, z: np.ndarray, omega: np.ndarray) -> np.ndarray:
        """dz/dt in numpy for z = [state(12), actuator(4)] (..., 16) and held speeds (..., 4).

        With ``tau = 0`` the actuator part of z is ignored (and its rate is zero). This is the
        vector field an environment or :func:`quad_envs.integrators.rk4_step` can step.
        """
        z = np.asarray(z, dtype=np.float64)
        omega = np.asarray(omega, dtype=np.float64)
        if z.shape[-1] != 16 or omega.shape[-1] != 4:
            raise ValueError(
                f"z must be (..., 16) and omega (..., 4), got {z.shape}, {omega.shape}"
            )
        return self._field(self.coefficients)(z, omega)

    def rollout(
        self,
        x0: np.ndarray | torch.Tensor,
        a0: np.ndarray | torch.Tensor,
        omega: np.ndarray | torch.Tensor,
        coefficients: torch.Tensor | None = None,
        dtype: torch.dtype = torch.float64,
    ) -> torch.Tensor:
        """Open-loop RK4 from states (B, 12) and actuator states (B, 4) under speeds (B, H, 4).

        The state is clipped to :data:`ENVELOPE` after every step.

        Returns:
            States after each step, shape (B, H, 12) (tensor; differentiable in coefficients).
        """
        x0, a0, omega = (torch.as_tensor(v, dtype=dtype) for v in (x0, a0, omega))
        rhs = self.rhs_torch(coefficients)
        z = torch.cat((x0, a0), -1)
        low = torch.as_tensor(ENVELOPE[0] + (-np.inf,) * a0.shape[-1], dtype=dtype)
        high = torch.as_tensor(ENVELOPE[1] + (np.inf,) * a0.shape[-1], dtype=dtype)
        h = self.dt
        out = []
        for k in range(omega.shape[1]):
            u = omega[:, k]
            k1 = rhs(z, u)
            k2 = rhs(z + 0.5 * h * k1, u)
            k3 = rhs(z + 0.5 * h * k2, u)
            k4 = rhs(z + h * k3, u)
            z = z + (h / 6.0) * (k1 + 2.0 * (k2 + k3) + k4)
            z = torch.clamp(torch.nan_to_num(z, nan=0.0), low, high)
            out.append(z[:, :12])
        return torch.stack(out, 1)

    def simulate(
        self, x0: np.ndarray, omega: np.ndarray, a0: np.ndarray | None = None
    ) -> np.ndarray:
        """One open-loop run: states (len(omega) + 1, 12) from x0 (12,) under speeds (H, 4)."""
        x0 = np.asarray(x0, dtype=np.float64)
        omega = np.atleast_2d(np.asarray(omega, dtype=np.float64))
        if x0.shape != (12,) or omega.shape[1] != 4:
            raise ValueError(f"x0 must be (12,) and omega (H, 4), got {x0.shape}, {omega.shape}")
        a0 = omega[0] if a0 is None else np.asarray(a0, dtype=np.float64)
        with torch.no_grad():
            states = self.rollout(x0[None], a0[None], omega[None])[0].numpy()
        return np.vstack([x0, states])

    # -- persistence ------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary."""
        return {
            "schema": SCHEMA,
            "schema_version": 1,
            "state_names": list(QUAD6DOF_STATE_NAMES),
            "input_names": ["omega1", "omega2", "omega3", "omega4"],
            "identified_states": list(DYNAMIC_STATES),
            "feature_names": list(FEATURE_NAMES),
            "features": FEATURES,
            "coefficients": self.coefficients.tolist(),
            "tau": self.tau,
            "dt": self.dt,
            "n_terms": self.n_terms,
            "equations": self.equations(precision=8),
            "meta": self.meta,
        }

    def save(self, path: str | Path) -> Path:
        """Writes the model as JSON, atomically."""
        return write_json(path, self.to_dict())


def load_rotorcraft(path: str | Path) -> RotorcraftModel:
    """Reads a model written by :meth:`RotorcraftModel.save`."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no such model file: {path}")
    try:
        data = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: malformed JSON ({exc})") from None
    if not isinstance(data, dict) or data.get("schema") != SCHEMA:
        raise ValueError(f"{path}: not a quad-sindy rotorcraft model")
    if list(data.get("feature_names", [])) != list(FEATURE_NAMES):
        raise ValueError(f"{path}: feature names differ from this version's library")
    return RotorcraftModel(
        np.array(data["coefficients"]), float(data["tau"]), float(data["dt"]), data.get("meta", {})
    )


def nominal_model(vehicle: NominalRotorcraft = NANODRONE_NOMINAL) -> RotorcraftModel:
    """The rigid body with thrust Kt W / m, mixer moments and Euler's gyroscopic terms."""
    xi = np.zeros((len(DYNAMIC_STATES), len(FEATURE_NAMES)))
    col = FEATURE_NAMES.index
    g = vehicle.gravity
    for i, name in enumerate(("gx", "gy", "gz")):
        xi[i, col(name)] = -g
    xi[2, col("W")] = vehicle.thrust_coefficient
    jx, jy, jz = vehicle.jxx, vehicle.jyy, vehicle.jzz
    xi[3, col("Mx")] = vehicle.kt * vehicle.arm / jx
    xi[4, col("My")] = vehicle.kt * vehicle.arm / jy
    xi[5, col("Mz")] = vehicle.kc / jz
    xi[3, col("q r")] = (jy - jz) / jx
    xi[4, col("p r")] = (jz - jx) / jy
    xi[5, col("p q")] = (jx - jy) / jz
    return RotorcraftModel(xi, 0.0, 0.01, {"method": "nominal"})


# -- data for fitting -------------------------------------------------------------------
@dataclass
class Windows:
    """Open-loop windows of several flights: start states, actuator states, speeds, truth.

    Attributes:
        x0: Start states (B, 12).
        a0: Actuator states at the start (B, 4).
        omega: Measured speeds over the window (B, H, 4).
        truth: Measured states after each step (B, H, 12).
    """

    x0: np.ndarray
    a0: np.ndarray
    omega: np.ndarray
    truth: np.ndarray

    def __len__(self) -> int:
        return len(self.x0)


def make_windows(
    trajs: Sequence[Trajectory],
    horizon: int,
    stride: int = 1,
    actuator: Callable[[np.ndarray], np.ndarray] | None = None,
) -> Windows:
    """Every ``stride``-th window of ``horizon`` steps (the benchmark's: stride 1, horizon 50).

    The window from sample i starts at state x[i], applies omega[i .. i+H-1] and is compared
    with x[i+1 .. i+H]; ``actuator`` maps a flight's speeds to actuator states (default: none).
    """
    parts: list[tuple[np.ndarray, ...]] = []
    for tr in trajs:
        n = len(tr)
        if n <= horizon:
            continue
        starts = np.arange(0, n - horizon, stride)
        idx = starts[:, None] + np.arange(1, horizon + 1)
        act = tr.u if actuator is None else actuator(tr.u)
        parts.append((tr.x[starts], act[starts], tr.u[idx - 1], tr.x[idx]))
    if not parts:
        raise ValueError(f"no flight is longer than the horizon ({horizon} steps)")
    return Windows(*(np.concatenate(p) for p in zip(*parts, strict=True)))


def smoothed_derivative(values: np.ndarray, dt: float, window: int = 9) -> np.ndarray:
    """Savitzky-Golay (order 2) derivative along axis 0."""
    from scipy.signal import savgol_filter

    return savgol_filter(values, window, 2, deriv=1, delta=dt, axis=0)


def fit_equation_error(
    trajs: Sequence[Trajectory], tau: float, threshold: float = 0.02, window: int = 9
) -> RotorcraftModel:
    """Sparse regression (pysindy STLSQ) of smoothed accelerations on the scaled library.

    Targets: v_B' + omega x v_B (the specific force) and omega'; columns and targets scaled to
    unit RMS so ``threshold`` is a fraction of a typical acceleration.
    """
    import pysindy as ps

    model = RotorcraftModel(np.zeros((6, len(FEATURE_NAMES))), tau, trajs[0].dt)
    thetas, targets = [], []
    for tr in trajs:
        x = tr.x
        deriv = smoothed_derivative(x[:, 6:12], tr.dt, window)
        xt = torch.as_tensor(x)
        _, _, coriolis = kinematics(xt)
        a = model.actuator_states(tr.u)
        a_dot = (tr.u - a) / tau if tau > 0 else np.zeros_like(a)
        theta = library(xt, torch.as_tensor(a), torch.as_tensor(a_dot)).numpy()
        target = deriv.copy()
        target[:, 0:3] -= coriolis.numpy()
        cut = slice(window, len(x) - window)
        thetas.append(theta[cut])
        targets.append(target[cut])
    theta = np.concatenate(thetas)
    target = np.concatenate(targets)
    col_scale = np.sqrt(np.mean(theta**2, axis=0))
    col_scale[col_scale == 0] = 1.0
    tgt_scale = np.sqrt(np.mean(target**2, axis=0))
    opt = ps.STLSQ(threshold=threshold, alpha=1e-6, max_iter=50)
    opt.fit(theta / col_scale, target / tgt_scale)
    xi = opt.coef_ * tgt_scale[:, None] / col_scale[None, :]
    model.coefficients = np.asarray(xi, dtype=np.float64)
    model.meta = {"method": "equation error (STLSQ)", "threshold": threshold}
    return model


# -- simulation-error refinement --------------------------------------------------------
GROUPS = ("position", "velocity", "attitude", "rates")


def group_errors(pred: torch.Tensor, truth: torch.Tensor) -> dict[str, torch.Tensor]:
    """Per-window, per-step error norms of position, world velocity, attitude, rates.

    Attitude is the geodesic angle; velocity is compared in the world frame.
    """
    rot_p = rotation_zxy_torch(pred[..., 3], pred[..., 4], pred[..., 5])
    rot_t = rotation_zxy_torch(truth[..., 3], truth[..., 4], truth[..., 5])
    vel_p = (rot_p @ pred[..., 6:9, None])[..., 0]
    vel_t = (rot_t @ truth[..., 6:9, None])[..., 0]
    trace = (rot_p * rot_t).sum((-1, -2))
    cos_angle = torch.clamp(0.5 * (trace - 1.0), -1.0, 1.0)
    return {
        "position": torch.linalg.vector_norm(pred[..., 0:3] - truth[..., 0:3], dim=-1),
        "velocity": torch.linalg.vector_norm(vel_p - vel_t, dim=-1),
        "attitude": torch.arccos(cos_angle),
        "rates": torch.linalg.vector_norm(pred[..., 9:12] - truth[..., 9:12], dim=-1),
        "_attitude_smooth": torch.linalg.matrix_norm(rot_p - rot_t) / np.sqrt(2.0),
    }


def refine(
    model: RotorcraftModel,
    windows: Windows,
    scales: dict[str, float],
    iterations: int = 30,
    delta: float = 1.0,
    progress: Callable[[int, float], None] | None = None,
    dtype: torch.dtype = torch.float64,
) -> RotorcraftModel:
    """Refines the non-zero coefficients on open-loop rollouts (simulation error).

    Loss: mean over windows and steps of sum over groups of Huber(error / scale) with the
    smooth chordal attitude error; L-BFGS with a strong-Wolfe line search. The rollouts run
    in ``dtype``; the parameters (relative changes of the coefficients) in double precision.
    The cost is dominated by per-operation overhead (50 steps x 4 RK4 stages), so it barely
    grows with the number of windows.
    """
    mask = torch.as_tensor(model.coefficients != 0)
    base = torch.as_tensor(model.coefficients)
    # Optimise relative changes: every parameter starts at 1 and is O(1).
    params = torch.ones(int(mask.sum()), dtype=torch.float64, requires_grad=True)
    x0, a0 = torch.as_tensor(windows.x0, dtype=dtype), torch.as_tensor(windows.a0, dtype=dtype)
    omega = torch.as_tensor(windows.omega, dtype=dtype)
    truth = torch.as_tensor(windows.truth, dtype=dtype)
    huber = torch.nn.HuberLoss(delta=delta)

    def coefficients() -> torch.Tensor:
        xi = torch.zeros_like(base)
        xi[mask] = base[mask] * params
        return xi

    def loss_fn() -> torch.Tensor:
        pred = model.rollout(x0, a0, omega, coefficients(), dtype)
        errs = group_errors(pred, truth)
        keys = {"position": "position", "velocity": "velocity", "_attitude_smooth": "attitude"}
        keys["rates"] = "rates"
        total = 0.0
        for key, group in keys.items():
            e = errs[key] / scales[group]
            total = total + huber(e, torch.zeros_like(e))
        return total

    opt = torch.optim.LBFGS(
        [params], lr=1.0, max_iter=iterations, history_size=20, line_search_fn="strong_wolfe"
    )
    calls = [0]

    def closure() -> torch.Tensor:
        opt.zero_grad()
        loss = loss_fn()
        if not torch.isfinite(loss):
            raise FloatingPointError("rollout diverged during refinement")
        loss.backward()
        calls[0] += 1
        if progress is not None:
            progress(calls[0], float(loss.detach()))
        return loss

    opt.step(closure)
    with torch.no_grad():
        final = loss_fn()
    out = RotorcraftModel(coefficients().detach().numpy(), model.tau, model.dt, dict(model.meta))
    out.meta["refined_loss"] = float(final)
    return out


def contributions(model: RotorcraftModel, trajs: Sequence[Trajectory]) -> np.ndarray:
    """RMS of each term's contribution (|xi| x feature RMS) over the flights, shape (6, F)."""
    thetas = []
    for tr in trajs:
        a = model.actuator_states(tr.u)
        a_dot = (tr.u - a) / model.tau if model.tau > 0 else np.zeros_like(a)
        thetas.append(
            library(torch.as_tensor(tr.x), torch.as_tensor(a), torch.as_tensor(a_dot)).numpy()
        )
    rms = np.sqrt(np.mean(np.concatenate(thetas) ** 2, axis=0))
    return np.abs(model.coefficients) * rms[None, :]


def prune(model: RotorcraftModel, trajs: Sequence[Trajectory], fraction: float) -> RotorcraftModel:
    """Drops terms contributing less than ``fraction`` of their equation's largest term."""
    contrib = contributions(model, trajs)
    keep = contrib >= fraction * contrib.max(axis=1, keepdims=True)
    out = RotorcraftModel(np.where(keep, model.coefficients, 0.0), model.tau, model.dt)
    out.meta = dict(model.meta, pruned_fraction=fraction)
    return out


def prune_to(
    model: RotorcraftModel, trajs: Sequence[Trajectory], max_terms: int
) -> RotorcraftModel:
    """Keeps the ``max_terms`` terms with the largest contribution relative to their equation's.

    Ranks every term by its RMS contribution divided by the largest in its equation (the
    measure of :func:`prune`) and zeroes all but the top ``max_terms``.
    """
    if max_terms < 1:
        raise ValueError(f"max_terms must be >= 1, got {max_terms}")
    contrib = contributions(model, trajs)
    relative = contrib / np.maximum(contrib.max(axis=1, keepdims=True), 1e-300)
    relative[model.coefficients == 0] = -1.0
    keep = np.zeros(relative.size, dtype=bool)
    keep[np.argsort(relative, axis=None)[::-1][:max_terms]] = True
    keep = keep.reshape(relative.shape) & (model.coefficients != 0)
    out = RotorcraftModel(np.where(keep, model.coefficients, 0.0), model.tau, model.dt)
    out.meta = dict(model.meta, pruned_to=max_terms)
    return out
