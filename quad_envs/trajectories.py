"""Reference trajectories: a trajectory maps time to a reference vector.

Planar references have 6 entries ``[y, z, y_dot, z_dot, y_ddot, z_ddot]`` (the authors' order);
3-D references have 11 ``[x, y, z, vx, vy, vz, ax, ay, az, psi, psi_dot]`` (inertial frame).
Every trajectory is vectorised: ``traj(t)`` with ``t`` of shape S returns shape S + (dim,).

The paper's cases A (step), B (sine) and C (diamond) follow the authors' MATLAB code exactly,
including its ``t - 1e-5`` segment guards. In 3-D they fly in the y-z plane (x = 0).
"""

from __future__ import annotations

import numpy as np

from quad_envs.types import FloatArray

PLANAR_REF_NAMES: tuple[str, ...] = (
    "y_ref", "z_ref", "y_dot_ref", "z_dot_ref", "y_ddot_ref", "z_ddot_ref",
)  # fmt: skip
SPATIAL_REF_NAMES: tuple[str, ...] = (
    "x_ref", "y_ref", "z_ref", "vx_ref", "vy_ref", "vz_ref",
    "ax_ref", "ay_ref", "az_ref", "psi_ref", "psi_dot_ref",
)  # fmt: skip


class Reference:
    """Base class: a smooth (or piecewise) path in the y-z plane or in 3-D space.

    Subclasses implement :meth:`pva` returning position, velocity and acceleration arrays of
    shape S + (ndim,). ``ndim`` is 2 for planar (y, z) and 3 for spatial (x, y, z) paths.
    """

    ndim: int = 2
    name: str = "trajectory"

    def pva(self, t: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Position, velocity and acceleration at times t."""
        raise NotImplementedError

    def yaw(self, t: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Yaw and yaw rate at times t (zero unless a subclass says otherwise)."""
        zeros = np.zeros(np.shape(t))
        return zeros, zeros

    def __call__(self, t: FloatArray | float) -> FloatArray:
        """The reference vector at time(s) t."""
        t = np.asarray(t, dtype=np.float64)
        pos, vel, acc = self.pva(t)
        parts = [pos, vel, acc]
        if self.ndim == 3:
            psi, psi_dot = self.yaw(t)
            parts += [psi[..., None], psi_dot[..., None]]
        return np.concatenate(parts, axis=-1)

    @property
    def dim(self) -> int:
        """Length of the reference vector."""
        return 6 if self.ndim == 2 else 11


def _stack(*cols: FloatArray) -> FloatArray:
    return np.stack(np.broadcast_arrays(*cols), axis=-1)


def _trapezoid(t: FloatArray, v_max: float, a_max: float) -> tuple[FloatArray, ...]:
    """Rest-to-rest trapezoidal velocity profile along a line (the authors' segments).

    Accelerate at a_max to v_max, cruise, brake, then hold 2 v_max^2 / a_max; each phase
    lasts v_max / a_max (boundaries inclusive on the left phase, as in the MATLAB code).

    Returns:
        Distance, speed and acceleration along the line at t.
    """
    t1, t2, t3 = v_max / a_max, 2 * v_max / a_max, 3 * v_max / a_max
    d1, d2, d3 = t, t - t1, t - t2
    conds = [t <= t1, t <= t2, t <= t3]
    acc = np.select(conds, [a_max, 0.0, -a_max], 0.0)
    vel = np.select(conds, [a_max * d1, v_max, v_max - a_max * d3], 0.0)
    pos = np.select(
        conds,
        [
            0.5 * a_max * d1**2,
            v_max**2 / (2 * a_max) + v_max * d2,
            3 * v_max**2 / (2 * a_max) + v_max * d3 - 0.5 * a_max * d3**2,
        ],
        2 * v_max**2 / a_max,
    )
    return pos, vel, acc


class Hover(Reference):
    """Hold a fixed point.

    Args:
        position: (y, z) in the plane or (x, y, z) in space [m].
    """

    name = "hover"

    def __init__(self, position: tuple[float, ...] = (0.0, 1.0)) -> None:
        self.position = np.asarray(position, dtype=np.float64)
        self.ndim = self.position.size

    def pva(self, t: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Constant position, zero velocity and acceleration."""
        pos = np.broadcast_to(self.position, np.shape(t) + (self.ndim,)).copy()
        zeros = np.zeros_like(pos)
        return pos, zeros, zeros.copy()


class PaperStep(Reference):
    """Paper case A: (0, 0) before 1 s, then a step to (0.5, 0.2) (authors' ``traj_step.m``)."""

    name = "step"

    def pva(self, t: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Piecewise-constant position, zero velocity and acceleration."""
        after = (t >= 1.0)[..., None]
        pos = np.where(after, np.array([0.5, 0.2]), 0.0)
        zeros = np.zeros(np.shape(t) + (2,))
        return pos, zeros, zeros.copy()


class PaperSine(Reference):
    """Paper case B: trapezoidal velocity in y, one-cosine bumps in z (``traj_sine.m``).

    y accelerates at 2 m/s^2 to 2 m/s, cruises, brakes, and stops at y = 4 m at t = 3 s;
    z = 0.25 (1 - cos(w t)) with w = 4 pi / 3 until 3 s, then held.
    """

    name = "sine"
    v_max = 2.0
    a_max = 2.0

    def pva(self, t: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Position, velocity and acceleration of the authors' sine reference."""
        pos_y, vel_y, acc_y = _trapezoid(t, self.v_max, self.a_max)
        t3 = 3 * self.v_max / self.a_max
        omega = 4 * np.pi / t3
        before = t < t3
        pos_z = np.where(before, 0.25 * (1 - np.cos(omega * t)), 0.25 * (1 - np.cos(omega * t3)))
        vel_z = np.where(before, 0.25 * omega * np.sin(omega * t), 0.0)
        acc_z = np.where(before, 0.25 * omega**2 * np.cos(omega * t), 0.0)
        return _stack(pos_y, pos_z), _stack(vel_y, vel_z), _stack(acc_y, acc_z)


class PaperDiamond(Reference):
    """Paper case C: a diamond of four 0.5 m sides from (0, 1.8) (``traj_diamond.m``).

    Each side takes 2 s (0.5 s accelerate at 1 m/s^2, 0.5 s cruise at 0.5 m/s, 0.5 s brake,
    0.5 s hover); headings +45, -45, -135, -225 degrees; held after 8 s. The segment index
    uses the authors' ``floor((t - 1e-5) / 2)`` guard.
    """

    name = "diamond"
    v_max = 0.5
    a_max = 1.0
    start = (0.0, 1.8)

    def __init__(self) -> None:
        side = 2 * self.v_max**2 / self.a_max
        corners = [np.array(self.start)]
        for heading in (np.pi / 4, -np.pi / 4, -3 * np.pi / 4):
            rot = np.array(
                [[np.cos(heading), -np.sin(heading)], [np.sin(heading), np.cos(heading)]]
            )
            corners.append(corners[-1] + rot @ np.array([side, 0.0]))
        self.corners = np.stack(corners)

    def pva(self, t: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Position, velocity and acceleration of the authors' diamond reference."""
        vm, am = self.v_max, self.a_max
        t_seg = 4 * vm / am
        done = t >= 4 * t_seg
        t = np.where(done, 4 * t_seg, t)
        guarded = np.maximum(0.0, t - 0.00001)
        t_prune = np.where(done, t_seg, np.mod(guarded, t_seg))
        corner_index = np.select([t <= t_seg, t <= 2 * t_seg, t <= 3 * t_seg], [0, 1, 2], 3)
        corner = self.corners[corner_index]
        theta = np.pi / 4 - np.floor(guarded / t_seg) * np.pi / 2

        pos, vel, acc = _trapezoid(t_prune, vm, am)
        c, s = np.cos(theta), np.sin(theta)
        pos_out = corner + _stack(c * pos, s * pos)
        return pos_out, _stack(c * vel, s * vel), _stack(c * acc, s * acc)


class Figure8(Reference):
    """A lemniscate: y = a sin(w t), z = z0 + (a/2) sin(2 w t) in the plane.

    In 3-D (``ndim=3``) the figure lies horizontally: x = a sin(w t), y = (a/2) sin(2 w t),
    z = z0.

    Args:
        amplitude: a [m].
        period: 2 pi / w [s].
        center_z: z0 [m].
        ndim: 2 for the y-z plane, 3 for space.
    """

    name = "figure8"

    def __init__(
        self, amplitude: float = 1.0, period: float = 8.0, center_z: float = 1.0, ndim: int = 2
    ) -> None:
        self.amplitude, self.period, self.center_z, self.ndim = amplitude, period, center_z, ndim

    def pva(self, t: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Analytic position, velocity and acceleration."""
        a, w = self.amplitude, 2 * np.pi / self.period
        s1, c1 = np.sin(w * t), np.cos(w * t)
        s2, c2 = np.sin(2 * w * t), np.cos(2 * w * t)
        lat = (a * s1, a * w * c1, -a * w**2 * s1)
        lon = (0.5 * a * s2, a * w * c2, -2 * a * w**2 * s2)
        if self.ndim == 2:
            z = (self.center_z + lon[0], lon[1], lon[2])
            return tuple(_stack(lat[i], z[i]) for i in range(3))  # type: ignore[return-value]
        zero = np.zeros(np.shape(t))
        z = (self.center_z + zero, zero, zero)
        return tuple(_stack(lat[i], lon[i], z[i]) for i in range(3))  # type: ignore[return-value]


class RandomWaypoints(Reference):
    """Smooth random flight through waypoints joined by minimum-jerk (quintic) segments.

    Rest-to-rest segments of ``segment_time`` seconds between waypoints drawn uniformly from a
    box; the path starts at rest at the first waypoint and holds the last one. Waypoints may
    carry leading batch axes (one path per vector-env member): ``waypoints`` has shape
    B + (K, ndim) and then ``t`` must broadcast against B.

    Args:
        waypoints: Waypoint array, shape B + (K, ndim).
        segment_time: Duration of each segment [s].
        yaw_amplitude: In 3-D, yaw follows yaw_amplitude sin(2 pi t / yaw_period) [rad]
            (0 by default; a sweep excites the yaw dynamics for identification).
        yaw_period: Period of the yaw sweep [s].
    """

    name = "random"

    def __init__(
        self,
        waypoints: FloatArray,
        segment_time: float = 2.0,
        yaw_amplitude: float = 0.0,
        yaw_period: float = 7.0,
    ) -> None:
        self.waypoints = np.asarray(waypoints, dtype=np.float64)
        if self.waypoints.ndim < 2 or self.waypoints.shape[-1] not in (2, 3):
            raise ValueError(
                f"waypoints must have shape (..., K, 2 or 3), got {self.waypoints.shape}"
            )
        self.ndim = self.waypoints.shape[-1]
        self.segment_time = float(segment_time)
        self.yaw_amplitude, self.yaw_period = float(yaw_amplitude), float(yaw_period)

    def yaw(self, t: FloatArray) -> tuple[FloatArray, FloatArray]:
        """The optional yaw sweep and its rate."""
        w = 2 * np.pi / self.yaw_period
        t = np.asarray(t, dtype=np.float64)
        return self.yaw_amplitude * np.sin(w * t), self.yaw_amplitude * w * np.cos(w * t)

    @classmethod
    def sample(
        cls,
        rng: np.random.Generator,
        ndim: int = 2,
        num_waypoints: int = 6,
        low: tuple[float, ...] | None = None,
        high: tuple[float, ...] | None = None,
        segment_time: float = 2.0,
        batch_shape: tuple[int, ...] = (),
        yaw_amplitude: float = 0.0,
        yaw_period: float = 7.0,
    ) -> RandomWaypoints:
        """Draws waypoints uniformly in the box [low, high] (default 2 m wide around z = 1)."""
        low_arr = np.asarray(low if low is not None else (-1.0,) * (ndim - 1) + (0.5,))
        high_arr = np.asarray(high if high is not None else (1.0,) * (ndim - 1) + (1.5,))
        pts = rng.uniform(low_arr, high_arr, size=batch_shape + (num_waypoints, ndim))
        return cls(pts, segment_time, yaw_amplitude, yaw_period)

    def pva(self, t: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Quintic (minimum-jerk) interpolation between consecutive waypoints."""
        num = self.waypoints.shape[-2]
        seg_float = np.clip(np.asarray(t) / self.segment_time, 0.0, num - 1)
        idx = np.minimum(np.floor(seg_float).astype(int), num - 2)
        tau = (seg_float - idx)[..., None]
        wp = self.waypoints
        if wp.ndim == 2:
            start, end = wp[idx], wp[idx + 1]
        else:  # one path per batch member: t has the batch shape
            idx_b = np.broadcast_to(idx, wp.shape[:-2])[..., None, None]
            start = np.take_along_axis(wp, idx_b, axis=-2)[..., 0, :]
            end = np.take_along_axis(wp, idx_b + 1, axis=-2)[..., 0, :]
        delta, ts = end - start, self.segment_time
        s = 10 * tau**3 - 15 * tau**4 + 6 * tau**5
        ds = (30 * tau**2 - 60 * tau**3 + 30 * tau**4) / ts
        dds = (60 * tau - 180 * tau**2 + 120 * tau**3) / ts**2
        return start + s * delta, ds * delta, dds * delta


class Embedded3D(Reference):
    """A planar (y-z) trajectory flown in space at x = 0 with zero yaw."""

    ndim = 3

    def __init__(self, planar: Reference) -> None:
        if planar.ndim != 2:
            raise ValueError("Embedded3D wraps a planar trajectory")
        self.planar = planar
        self.name = planar.name

    def pva(self, t: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """The planar path with x = 0 prepended."""
        out = []
        for arr in self.planar.pva(t):
            out.append(np.concatenate([np.zeros(arr.shape[:-1] + (1,)), arr], axis=-1))
        return tuple(out)  # type: ignore[return-value]


TRAJECTORY_NAMES: tuple[str, ...] = ("hover", "step", "sine", "diamond", "figure8", "random")
"""Names accepted by :func:`make_trajectory` (``A``/``B``/``C`` are aliases of the paper cases)."""


def make_trajectory(
    name: str, ndim: int = 2, rng: np.random.Generator | None = None, **kwargs: object
) -> Reference:
    """Builds a trajectory by name.

    Args:
        name: One of :data:`TRAJECTORY_NAMES`, or a paper case letter ``A``, ``B``, ``C``.
        ndim: 2 for the y-z plane, 3 for space (paper cases are embedded at x = 0).
        rng: Generator for the random trajectory (required for ``random``).
        **kwargs: Passed to the trajectory's constructor (or ``RandomWaypoints.sample``).

    Returns:
        The trajectory.

    Raises:
        ValueError: Unknown name or dimension.
    """
    if ndim not in (2, 3):
        raise ValueError(f"ndim must be 2 or 3, got {ndim}")
    key = {"A": "step", "B": "sine", "C": "diamond"}.get(name, name)
    if key == "hover":
        default = (0.0, 1.0) if ndim == 2 else (0.0, 0.0, 1.0)
        return Hover(kwargs.get("position", default))  # type: ignore[arg-type]
    if key in ("step", "sine", "diamond"):
        planar = {"step": PaperStep, "sine": PaperSine, "diamond": PaperDiamond}[key]()
        return planar if ndim == 2 else Embedded3D(planar)
    if key == "figure8":
        return Figure8(ndim=ndim, **kwargs)  # type: ignore[arg-type]
    if key == "random":
        if rng is None:
            rng = np.random.default_rng()
        return RandomWaypoints.sample(rng, ndim=ndim, **kwargs)  # type: ignore[arg-type]
    valid = ", ".join(TRAJECTORY_NAMES + ("A", "B", "C"))
    raise ValueError(f"unknown trajectory {name!r}; valid choices: {valid}")
