"""Real flight logs: read a table, repair it, and turn it into a 6-DOF :class:`Trajectory`.

A log is any table (parquet or CSV) with a time column, position, velocity (world or body
frame), attitude (a quaternion, or Z-X-Y Euler angles), body rates and one speed per motor.
:class:`LogColumns` names those columns; :data:`NANODRONE_COLUMNS` is the mapping of the public
nano-drone benchmark (Crazyflie 2.1 Brushless, ESC eRPM telemetry, 6 pole pairs).

The conversion (:func:`flight_to_trajectory`) gives the toolkit's 6-DOF state

    [x, y, z, phi, theta, psi, u, v, w, p, q, r]

(world position [m], Z-X-Y Euler angles [rad] as in :func:`quad_envs.dynamics.rotation_zxy`,
body-frame velocity v_B = R^T v_W [m/s], body rates [rad/s]) and the inputs ``omega1..omegaK``,
the motor speeds [rad/s] (``Omega = eRPM * 2 pi / (60 * pole_pairs)``). On the way it repairs:

* **stale rows**: a row whose state columns all equal the previous row's (a dropped radio
  packet re-logged) is replaced by linear interpolation in time between the fresh rows around
  it; the same for the motor columns on their own;
* **motor spikes**: speeds that are not finite or lie outside ``[0, omega_max]`` are replaced by
  interpolation between the valid neighbours;
* **missing values** (NaN) in state columns: interpolated, counted;
* **quaternion offset**: a constant c subtracted from every component is estimated from
  ``|q_k - c| = 1`` by Gauss-Newton (:func:`estimate_quaternion_offset`) and removed; the result
  is normalised and made sign-continuous.

Every repair is counted in ``traj.meta["cleaning"]`` (:class:`CleaningReport`).
:func:`trajectory_to_table` runs the conversion backwards (synthetic logs for tests).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from identification.data import Trajectory, read_table
from quad_envs.dynamics import QUAD6DOF_STATE_NAMES, rotation_zxy

MOTOR_UNITS = ("rad/s", "rpm", "erpm")
_SEQUENCE_FIELDS = {"position", "velocity", "quaternion", "euler_zxy", "euler_zyx", "rates",
                    "motors"}  # fmt: skip
VELOCITY_FRAMES = ("world", "body")


@dataclass(frozen=True)
class LogColumns:
    """Which columns of a log hold what, and in which units and frames.

    Attributes:
        time: Time column [s].
        position: World position columns (x, y, z) [m].
        velocity: Velocity columns (x, y, z) [m/s].
        velocity_frame: ``world`` or ``body``: the frame of ``velocity``.
        quaternion: Quaternion columns in (x, y, z, w) order, body to world; or None when
            Euler angles are given.
        euler_zxy: Z-X-Y Euler angle columns (roll phi, pitch theta, yaw psi) [rad]: the
            preset's convention, R = Rz(psi) Rx(phi) Ry(theta).
        euler_zyx: Z-Y-X Euler angle columns (roll, pitch, yaw) [rad]: most autopilots'
            logs, R = Rz(yaw) Ry(pitch) Rx(roll); converted to Z-X-Y.
        rates: Body angular rate columns (p, q, r) [rad/s].
        motors: One speed column per motor, in the order of the inputs ``omega1..``.
        motor_unit: ``rad/s``, ``rpm`` or ``erpm`` (electrical RPM, needs ``pole_pairs``).
        pole_pairs: Motor pole pairs (eRPM = pole_pairs x mechanical RPM).
        omega_max: Largest credible motor speed [rad/s]; faster readings are spikes.
        quaternion_offset: Estimate and remove a constant quaternion offset (unit quaternions
            give c = 0); False: only normalise.
    """

    time: str = "t"
    position: tuple[str, str, str] = ("x", "y", "z")
    velocity: tuple[str, str, str] = ("vx", "vy", "vz")
    velocity_frame: str = "world"
    quaternion: tuple[str, str, str, str] | None = ("qx", "qy", "qz", "qw")
    euler_zxy: tuple[str, str, str] | None = None
    euler_zyx: tuple[str, str, str] | None = None
    rates: tuple[str, str, str] = ("wx", "wy", "wz")
    motors: tuple[str, ...] = ("m1_erpm", "m2_erpm", "m3_erpm", "m4_erpm")
    motor_unit: str = "erpm"
    pole_pairs: int = 6
    omega_max: float = 5000.0
    quaternion_offset: bool = True

    def __post_init__(self) -> None:
        if self.motor_unit not in MOTOR_UNITS:
            raise ValueError(f"unknown motor_unit {self.motor_unit!r}; valid: {MOTOR_UNITS}")
        if self.velocity_frame not in VELOCITY_FRAMES:
            raise ValueError(
                f"unknown velocity_frame {self.velocity_frame!r}; valid: {VELOCITY_FRAMES}"
            )
        given = [a for a in (self.quaternion, self.euler_zxy, self.euler_zyx) if a is not None]
        if len(given) != 1:
            raise ValueError(
                "give exactly one attitude: quaternion, euler_zxy or euler_zyx columns"
            )
        if not self.motors:
            raise ValueError("motors must name at least one column")
        if self.motor_unit == "erpm" and self.pole_pairs < 1:
            raise ValueError(f"pole_pairs must be >= 1, got {self.pole_pairs}")
        if not self.omega_max > 0:
            raise ValueError(f"omega_max must be positive, got {self.omega_max}")

    @classmethod
    def from_mapping(cls, mapping: Mapping[str, Any], base: LogColumns | None = None) -> LogColumns:
        """Overrides the fields of ``base`` (default :data:`NANODRONE_COLUMNS`) from a mapping.

        Sequence fields take lists or comma-separated strings, e.g.
        ``{"motors": "rpm1,rpm2,rpm3,rpm4", "motor_unit": "rpm"}``.
        """
        base = base or NANODRONE_COLUMNS
        known = set(asdict(base))
        unknown = sorted(set(mapping) - known)
        if unknown:
            raise ValueError(f"unknown column mapping key(s) {unknown}; valid: {sorted(known)}")
        values: dict[str, Any] = {}
        for key, value in mapping.items():
            current = getattr(base, key)
            if isinstance(value, str) and key in _SEQUENCE_FIELDS:
                value = tuple(v.strip() for v in value.split(","))
            elif isinstance(value, str) and isinstance(current, bool):
                value = value.strip().lower() in ("1", "true", "yes", "on")
            elif isinstance(value, str) and isinstance(current, int | float):
                try:
                    value = type(current)(value)
                except ValueError:
                    raise ValueError(f"column mapping {key}={value!r} is not a number") from None
            elif isinstance(value, list):
                value = tuple(value)
            values[key] = value
        if ("euler_zxy" in values or "euler_zyx" in values) and "quaternion" not in values:
            values["quaternion"] = None
        return replace(base, **values)

    def required(self) -> list[str]:
        """Every column the conversion reads."""
        attitude = self.attitude()
        return [
            self.time, *self.position, *self.velocity, *attitude, *self.rates, *self.motors,
        ]  # fmt: skip

    def attitude(self) -> tuple[str, ...]:
        """The attitude columns: the quaternion's or the Euler angles'."""
        return next(a for a in (self.quaternion, self.euler_zxy, self.euler_zyx) if a is not None)

    def motor_scale(self) -> float:
        """Factor from the logged unit to rad/s."""
        if self.motor_unit == "rad/s":
            return 1.0
        per_minute = 2.0 * np.pi / 60.0
        return per_minute / self.pole_pairs if self.motor_unit == "erpm" else per_minute


NANODRONE_COLUMNS = LogColumns()
"""The nano-drone benchmark: world velocity, (x, y, z, w) quaternion, eRPM, 6 pole pairs."""


@dataclass
class CleaningReport:
    """What the conversion repaired in one flight.

    Attributes:
        rows: Rows in the log.
        stale_state_rows: Rows whose state repeated the previous row (interpolated).
        stale_motor_rows: Rows whose motor speeds repeated the previous row (interpolated).
        motor_spikes: Motor readings outside [0, omega_max] or not finite, per motor.
        missing_state_values: NaN state values (interpolated).
        quaternion_offset: The estimated constant c (x, y, z, w) removed from the quaternion.
        quaternion_norm_range: min and max of |q| before the repair.
        quaternion_norm_error: max | |q - c| - 1 | after removing c (before normalising).
    """

    rows: int = 0
    stale_state_rows: int = 0
    stale_motor_rows: int = 0
    motor_spikes: list[int] = field(default_factory=list)
    missing_state_values: int = 0
    quaternion_offset: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0, 0.0])
    quaternion_norm_range: list[float] = field(default_factory=lambda: [1.0, 1.0])
    quaternion_norm_error: float = 0.0

    def summary(self) -> str:
        """One line for logs and reports."""
        offset = ", ".join(f"{c:+.4f}" for c in self.quaternion_offset)
        return (
            f"{self.rows} rows: {self.stale_state_rows} stale state rows, "
            f"{self.stale_motor_rows} stale motor rows, {sum(self.motor_spikes)} motor spikes, "
            f"{self.missing_state_values} missing values; quaternion offset ({offset}), "
            f"|q| {self.quaternion_norm_range[0]:.3f}..{self.quaternion_norm_range[1]:.3f} "
            f"-> residual {self.quaternion_norm_error:.1e}"
        )


# -- rotations --------------------------------------------------------------------------
def estimate_quaternion_offset(q: np.ndarray, iterations: int = 20) -> np.ndarray:
    """The constant c with |q_k - c| = 1 for all k (least squares, Gauss-Newton from c = 0).

    Args:
        q: Quaternions, shape (N, 4), any component order.
        iterations: Gauss-Newton steps.

    Returns:
        c, shape (4,), in the same component order.
    """
    q = np.asarray(q, dtype=np.float64)
    c = np.zeros(4)
    for _ in range(iterations):
        diff = q - c
        norm = np.linalg.norm(diff, axis=1)
        residual = norm - 1.0
        jac = -diff / norm[:, None]  # d|q - c| / dc
        step, *_ = np.linalg.lstsq(jac, -residual, rcond=None)
        c = c + step
        if np.abs(step).max() < 1e-12:
            break
    return c


def quaternion_to_rotation(q_xyzw: np.ndarray) -> np.ndarray:
    """Rotation matrices (body to world) of unit quaternions (x, y, z, w), shape (..., 3, 3)."""
    q = np.asarray(q_xyzw, dtype=np.float64)
    x, y, z, w = np.moveaxis(q, -1, 0)
    rot = np.empty(q.shape[:-1] + (3, 3))
    rot[..., 0, 0] = 1 - 2 * (y * y + z * z)
    rot[..., 0, 1] = 2 * (x * y - z * w)
    rot[..., 0, 2] = 2 * (x * z + y * w)
    rot[..., 1, 0] = 2 * (x * y + z * w)
    rot[..., 1, 1] = 1 - 2 * (x * x + z * z)
    rot[..., 1, 2] = 2 * (y * z - x * w)
    rot[..., 2, 0] = 2 * (x * z - y * w)
    rot[..., 2, 1] = 2 * (y * z + x * w)
    rot[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return rot


def rotation_to_quaternion(rot: np.ndarray) -> np.ndarray:
    """Unit quaternions (x, y, z, w) with w >= 0 of rotation matrices (..., 3, 3).

    Shepperd's method: per matrix, the largest of |x|, |y|, |z|, |w| is taken from the
    diagonal and the others from the off-diagonal sums and differences.
    """
    r = np.asarray(rot, dtype=np.float64)
    trace = np.trace(r, axis1=-2, axis2=-1)
    sums = (r[..., 0, 1] + r[..., 1, 0], r[..., 0, 2] + r[..., 2, 0], r[..., 1, 2] + r[..., 2, 1])
    diffs = (r[..., 2, 1] - r[..., 1, 2], r[..., 0, 2] - r[..., 2, 0], r[..., 1, 0] - r[..., 0, 1])
    xy, xz, yz = sums
    wx, wy, wz = diffs
    cands = []
    for k, diag in enumerate((r[..., 0, 0], r[..., 1, 1], r[..., 2, 2], None)):
        big = 0.5 * np.sqrt(
            np.maximum(1.0 + trace if diag is None else 1.0 + 2 * diag - trace, 1e-300)
        )
        f = 0.25 / big
        if k == 0:
            cands.append((big, xy * f, xz * f, wx * f))
        elif k == 1:
            cands.append((xy * f, big, yz * f, wy * f))
        elif k == 2:
            cands.append((xz * f, yz * f, big, wz * f))
        else:
            cands.append((wx * f, wy * f, wz * f, big))
    stacked = np.stack([np.stack(c, -1) for c in cands], -2)  # (..., 4 candidates, 4)
    choice = np.argmax(np.stack([r[..., 0, 0], r[..., 1, 1], r[..., 2, 2], trace], -1), -1)
    q = np.take_along_axis(stacked, choice[..., None, None], -2)[..., 0, :]
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., 3:4] < 0, -q, q)


def rotation_to_euler_zxy(rot: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Z-X-Y Euler angles (phi, theta, psi) of rotations, inverse of :func:`rotation_zxy`.

    From ``R[2,1] = sin(phi)``, ``R[2,0] = -cos(phi) sin(theta)``,
    ``R[2,2] = cos(phi) cos(theta)``, ``R[0,1] = -cos(phi) sin(psi)``,
    ``R[1,1] = cos(phi) cos(psi)``, with phi in [-pi/2, pi/2].
    """
    rot = np.asarray(rot, dtype=np.float64)
    phi = np.arcsin(np.clip(rot[..., 2, 1], -1.0, 1.0))
    theta = np.arctan2(-rot[..., 2, 0], rot[..., 2, 2])
    psi = np.arctan2(-rot[..., 0, 1], rot[..., 1, 1])
    return phi, theta, psi


def rotation_zyx(roll: np.ndarray, pitch: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """Body-to-world rotations of Z-Y-X Euler angles, R = Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr, cp, sp = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch)
    cy, sy = np.cos(yaw), np.sin(yaw)
    rows = [
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ]
    return np.stack([np.stack(np.broadcast_arrays(*r), axis=-1) for r in rows], axis=-2)


def rotation_to_euler_zyx(rot: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Z-Y-X Euler angles (roll, pitch, yaw) of rotations, inverse of :func:`rotation_zyx`."""
    rot = np.asarray(rot, dtype=np.float64)
    pitch = np.arcsin(np.clip(-rot[..., 2, 0], -1.0, 1.0))
    roll = np.arctan2(rot[..., 2, 1], rot[..., 2, 2])
    yaw = np.arctan2(rot[..., 1, 0], rot[..., 0, 0])
    return roll, pitch, yaw


def geodesic_angle(rot_a: np.ndarray, rot_b: np.ndarray) -> np.ndarray:
    """Angle [rad] of the rotation between two attitudes, arccos((tr(A^T B) - 1) / 2)."""
    trace = np.einsum("...ij,...ij->...", rot_a, rot_b)
    return np.arccos(np.clip(0.5 * (trace - 1.0), -1.0, 1.0))


# -- repairs ----------------------------------------------------------------------------
def _repeated_rows(values: np.ndarray) -> np.ndarray:
    """Rows equal (all columns) to the previous row; row 0 is never repeated."""
    same = np.zeros(len(values), dtype=bool)
    same[1:] = np.all(values[1:] == values[:-1], axis=1)
    return same


def _interpolate_rows(t: np.ndarray, values: np.ndarray, bad: np.ndarray) -> np.ndarray:
    """Replaces rows flagged ``bad`` (N,) or entries flagged (N, k) by linear interpolation."""
    out = values.copy()
    bad2 = np.broadcast_to(bad[:, None] if bad.ndim == 1 else bad, values.shape)
    for j in range(values.shape[1]):
        col_bad = bad2[:, j]
        if not col_bad.any():
            continue
        good = ~col_bad
        if good.sum() < 2:
            raise ValueError(f"column {j}: fewer than 2 valid samples to interpolate from")
        out[col_bad, j] = np.interp(t[col_bad], t[good], values[good, j])
    return out


# -- conversion -------------------------------------------------------------------------
def flight_to_trajectory(
    table: Mapping[str, np.ndarray],
    columns: LogColumns = NANODRONE_COLUMNS,
    repair_stale: bool = True,
    source: str = "log",
) -> Trajectory:
    """Converts one flight table into a 6-DOF trajectory with motor-speed inputs.

    Args:
        table: Column name -> values (see :func:`read_table`).
        columns: Which columns hold what.
        repair_stale: Interpolate over repeated (stale) rows; without it they are only counted.
        source: Name used in error messages and ``meta``.

    Returns:
        Trajectory with states ``x y z phi theta psi u v w p q r`` and inputs ``omega1..``;
        ``meta["cleaning"]`` holds the :class:`CleaningReport` as a dict.

    Raises:
        ValueError: A column is missing, the time grid is not uniform, or too little valid data.
    """
    missing = [c for c in columns.required() if c not in table]
    if missing:
        raise ValueError(f"{source}: missing column(s) {missing}")
    t = np.asarray(table[columns.time], dtype=np.float64)
    n = t.size
    if n < 3:
        raise ValueError(f"{source}: a flight needs at least 3 rows, got {n}")
    report = CleaningReport(rows=n)

    def stack(names: Sequence[str]) -> np.ndarray:
        return np.column_stack([np.asarray(table[c], dtype=np.float64) for c in names])

    attitude_cols = columns.attitude()
    state_raw = stack([*columns.position, *columns.velocity, *attitude_cols, *columns.rates])
    nan = ~np.isfinite(state_raw)
    report.missing_state_values = int(nan.sum())
    stale = _repeated_rows(state_raw) if repair_stale else np.zeros(n, dtype=bool)
    report.stale_state_rows = int(_repeated_rows(state_raw).sum())
    if nan.all(axis=0).any():
        raise ValueError(f"{source}: a state column has no finite values")
    state = _interpolate_rows(t, state_raw, nan | stale[:, None])
    pos, vel, rates = state[:, 0:3], state[:, 3:6], state[:, -3:]
    att = state[:, 6:-3]

    if columns.quaternion is not None:
        fresh = ~(stale | nan.any(axis=1))
        norms = np.linalg.norm(att[fresh], axis=1)
        report.quaternion_norm_range = [float(norms.min()), float(norms.max())]
        c = estimate_quaternion_offset(att[fresh]) if columns.quaternion_offset else np.zeros(4)
        report.quaternion_offset = [float(v) for v in c]
        report.quaternion_norm_error = float(
            np.abs(np.linalg.norm(att[fresh] - c, axis=1) - 1.0).max()
        )
        quat = att - c
        quat /= np.linalg.norm(quat, axis=1, keepdims=True)
        rot = quaternion_to_rotation(quat)
        phi, theta, psi = rotation_to_euler_zxy(rot)
    elif columns.euler_zyx is not None:
        rot = rotation_zyx(*att.T)
        phi, theta, psi = rotation_to_euler_zxy(rot)
    else:
        phi, theta, psi = att.T
        rot = rotation_zxy(phi, theta, psi)
    psi = np.unwrap(psi)
    theta = np.unwrap(theta)

    v_body = np.einsum("nji,nj->ni", rot, vel) if columns.velocity_frame == "world" else vel

    motors_raw = stack(columns.motors) * columns.motor_scale()
    spikes = ~np.isfinite(motors_raw) | (motors_raw < 0) | (motors_raw > columns.omega_max)
    report.motor_spikes = [int(s) for s in spikes.sum(axis=0)]
    motor_stale = _repeated_rows(np.where(spikes, np.nan, motors_raw))
    report.stale_motor_rows = int(motor_stale.sum())
    bad_motor = spikes | (motor_stale[:, None] if repair_stale else False)
    omega = _interpolate_rows(t, motors_raw, np.asarray(bad_motor))

    x = np.column_stack([pos, phi, theta, psi, v_body, rates])
    names = tuple(f"omega{i + 1}" for i in range(omega.shape[1]))
    meta = {"source": source, "cleaning": asdict(report), "columns": asdict(columns)}
    try:
        return Trajectory(t, x, omega, QUAD6DOF_STATE_NAMES, names, meta=meta)
    except ValueError as exc:
        raise ValueError(f"{source}: {exc}") from None


def read_flight(
    path: str | Path, columns: LogColumns = NANODRONE_COLUMNS, repair_stale: bool = True
) -> Trajectory:
    """Reads one flight log (parquet or CSV) into a 6-DOF trajectory; see the module doc."""
    table = read_table(path, columns.required())
    return flight_to_trajectory(table, columns, repair_stale, source=str(path))


def read_vehicle_log(
    path: str | Path, mapping: Mapping[str, Any], repair_stale: bool = True
) -> Trajectory:
    """Generic reader: a column mapping (fields of :class:`LogColumns`) over the defaults.

    Example for a CSV with body-frame velocity, Euler angles and motor speeds in RPM::

        read_vehicle_log("flight.csv", {
            "time": "time", "velocity": "u,v,w", "velocity_frame": "body",
            "euler_zxy": "roll,pitch,yaw", "motors": "rpm1,rpm2,rpm3,rpm4", "motor_unit": "rpm",
        })
    """
    return read_flight(path, LogColumns.from_mapping(mapping), repair_stale)


def trajectory_to_table(
    traj: Trajectory,
    columns: LogColumns = NANODRONE_COLUMNS,
    quaternion_offset: Sequence[float] = (0.0, 0.0, 0.0, 0.0),
) -> dict[str, np.ndarray]:
    """The conversion backwards: a 6-DOF trajectory with motor speeds as a log table.

    Args:
        traj: States ``x y z phi theta psi u v w p q r`` and motor speeds [rad/s].
        columns: The log format to write (quaternion or Euler attitude, velocity frame, unit).
        quaternion_offset: A constant subtracted from the quaternion (as the benchmark's
            processing did), to test the repair.

    Returns:
        Column name -> values, readable by :func:`flight_to_trajectory`.
    """
    if traj.x.shape[1] != 12:
        raise ValueError(f"expected a 12-state 6-DOF trajectory, got {traj.x.shape[1]} states")
    if traj.u.shape[1] != len(columns.motors):
        raise ValueError(f"trajectory has {traj.u.shape[1]} inputs, log {len(columns.motors)}")
    x = traj.x
    rot = rotation_zxy(x[:, 3], x[:, 4], x[:, 5])
    vel = (
        np.einsum("nij,nj->ni", rot, x[:, 6:9]) if columns.velocity_frame == "world" else x[:, 6:9]
    )
    table: dict[str, np.ndarray] = {columns.time: traj.t.copy()}
    for names, values in ((columns.position, x[:, 0:3]), (columns.velocity, vel)):
        table.update({c: values[:, i].copy() for i, c in enumerate(names)})
    if columns.quaternion is not None:
        quat = rotation_to_quaternion(rot) - np.asarray(quaternion_offset, dtype=np.float64)
        table.update({c: quat[:, i] for i, c in enumerate(columns.quaternion)})
    elif columns.euler_zyx is not None:
        angles = rotation_to_euler_zyx(rot)
        table.update({c: angles[i] for i, c in enumerate(columns.euler_zyx)})
    else:
        table.update({c: x[:, 3 + i].copy() for i, c in enumerate(columns.euler_zxy)})
    table.update({c: x[:, 9 + i].copy() for i, c in enumerate(columns.rates)})
    motors = traj.u / columns.motor_scale()
    table.update({c: motors[:, i].copy() for i, c in enumerate(columns.motors)})
    return table
