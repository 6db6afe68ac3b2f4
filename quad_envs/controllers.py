"""Tracking controllers: a controller maps (state, reference) to the commanded input.

All controllers are batched over leading axes and return the *commanded* input; the rotor
saturation is applied by whoever integrates the dynamics.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quad_envs.dynamics import body_to_inertial_velocity
from quad_envs.params import PAPER_6DOF, PAPER_PLANAR, PlanarQuadParams, Quad6DOFParams
from quad_envs.types import FloatArray


@dataclass(frozen=True)
class PlanarPDGains:
    """Gains of the paper's planar PD controller (authors' ``controller.m``)."""

    kp_z: float = 50.0
    kv_z: float = 15.0
    kp_phi: float = 80.0
    kv_phi: float = 20.0
    kp_y: float = 60.0
    kv_y: float = 15.0


LAG_GAINS_PLANAR = PlanarPDGains(kp_z=16.0, kv_z=8.0, kp_phi=30.0, kv_phi=10.0, kp_y=6.0,
                                 kv_y=5.0)  # fmt: skip
"""Planar PD gains for vehicles whose rotors lag: the paper's attitude loop (80, 20) is
unstable on the Crazyflie with its 0.072 s rotor time constant; these keep it well inside
1 / tau."""


class PlanarPD:
    """The paper's PD controller, linearised about hover.

    phi_c = -(y_ddot_d + Kv_y (y_dot_d - y_dot) + Kp_y (y_d - y)) / g
    phi_c_dot = -(Kv_y (y_ddot_d + g phi) + Kp_y (y_dot_d - y_dot)) / g
    u1 = m (g + z_ddot_d + Kv_z (z_dot_d - z_dot) + Kp_z (z_d - z))
    u2 = Ixx (Kv_phi (phi_c_dot - phi_dot) + Kp_phi (phi_c - phi))

    Args:
        params: Vehicle parameters the controller believes in.
        gains: PD gains.
        max_tilt: Largest roll the position loop commands [rad]; unlimited (the paper's law)
            by default. Far waypoints command tilts of several radians, which a vehicle with
            less control authority than the paper's cannot follow.
    """

    def __init__(
        self,
        params: PlanarQuadParams = PAPER_PLANAR,
        gains: PlanarPDGains = PlanarPDGains(),
        max_tilt: float = np.inf,
    ) -> None:
        self.params, self.gains, self.max_tilt = params, gains, float(max_tilt)

    def __call__(self, state: FloatArray, ref: FloatArray) -> FloatArray:
        """Commanded [u1, u2] for planar states (..., 6) and references (..., 6)."""
        k, g = self.gains, self.params.gravity
        y, z, phi = state[..., 0], state[..., 1], state[..., 2]
        y_dot, z_dot, phi_dot = state[..., 3], state[..., 4], state[..., 5]
        y_d, z_d, y_dot_d, z_dot_d = ref[..., 0], ref[..., 1], ref[..., 2], ref[..., 3]
        y_ddot_d, z_ddot_d = ref[..., 4], ref[..., 5]
        phi_c = -(y_ddot_d + k.kv_y * (y_dot_d - y_dot) + k.kp_y * (y_d - y)) / g
        phi_c_dot = -(k.kv_y * (y_ddot_d + g * phi) + k.kp_y * (y_dot_d - y_dot)) / g
        if np.isfinite(self.max_tilt):  # a held limit: its command does not move
            limited = np.abs(phi_c) > self.max_tilt
            phi_c = np.clip(phi_c, -self.max_tilt, self.max_tilt)
            phi_c_dot = np.where(limited, 0.0, phi_c_dot)
        u = np.empty(np.broadcast_shapes(np.shape(state)[:-1], np.shape(ref)[:-1]) + (2,))
        u[..., 0] = self.params.mass * (
            g + z_ddot_d + k.kv_z * (z_dot_d - z_dot) + k.kp_z * (z_d - z)
        )
        u[..., 1] = self.params.Ixx * (k.kv_phi * (phi_c_dot - phi_dot) + k.kp_phi * (phi_c - phi))
        return u


@dataclass(frozen=True)
class Quad6DOFPDGains:
    """Gains of the cascaded 6-DOF PD controller."""

    kp_xy: float = 20.0
    kv_xy: float = 8.0
    kp_z: float = 50.0
    kv_z: float = 15.0
    kp_att: tuple[float, float, float] = (300.0, 300.0, 60.0)
    kv_att: tuple[float, float, float] = (30.0, 30.0, 12.0)


LAG_GAINS_6DOF = Quad6DOFPDGains(
    kp_xy=2.0, kv_xy=2.5, kp_z=16.0, kv_z=8.0, kp_att=(80.0, 80.0, 10.0),
    kv_att=(16.0, 16.0, 4.0),
)  # fmt: skip
"""6-DOF PD gains for vehicles whose rotors lag: the default attitude loop (300, 30) and
position loop (20, 8) lose the Crazyflie (tau 0.072 s) within 0.5 to 3 s once the rotors
lag; the yaw loop is soft so that a yaw sweep does not saturate the rotors."""


class Quad6DOFPD:
    """Cascaded PD on the model linearised about hover (small-angle, Z-X-Y angles).

    Position loop: a_c = a_d + Kv (v_d - v) + Kp (p_d - p) in the inertial frame.
    u1 = m (g + a_c,z) / (cos phi cos theta); attitude commands from the small-angle map
    phi_c = (a_c,x sin psi_d - a_c,y cos psi_d) / g,
    theta_c = (a_c,x cos psi_d + a_c,y sin psi_d) / g.
    Attitude loop: M = J (Kp_att (angle_c - angle) + Kv_att (rate_c - omega)),
    rate_c = [0, 0, psi_dot_d].

    Args:
        params: Vehicle parameters the controller believes in.
        gains: PD gains.
        max_tilt: Largest tilt the position loop commands [rad] (the horizontal acceleration
            command is scaled to g max_tilt); unlimited by default. A Pelican flying the
            excitation waypoints was commanded 6 rad and fell.
    """

    def __init__(
        self,
        params: Quad6DOFParams = PAPER_6DOF,
        gains: Quad6DOFPDGains = Quad6DOFPDGains(),
        max_tilt: float = np.inf,
    ) -> None:
        self.params, self.gains, self.max_tilt = params, gains, float(max_tilt)

    def __call__(self, state: FloatArray, ref: FloatArray) -> FloatArray:
        """Commanded [u1, u2, u3, u4] for states (..., 12) and 3-D references (..., 11)."""
        k, g, m = self.gains, self.params.gravity, self.params.mass
        vel = body_to_inertial_velocity(state)
        kp = np.array([k.kp_xy, k.kp_xy, k.kp_z])
        kv = np.array([k.kv_xy, k.kv_xy, k.kv_z])
        acc_c = ref[..., 6:9] + kv * (ref[..., 3:6] - vel) + kp * (ref[..., 0:3] - state[..., 0:3])
        if np.isfinite(self.max_tilt):
            level = np.hypot(acc_c[..., 0], acc_c[..., 1])
            scale = np.minimum(1.0, g * self.max_tilt / np.maximum(level, 1e-300))
            acc_c = np.concatenate([acc_c[..., :2] * scale[..., None], acc_c[..., 2:]], axis=-1)
        psi_d, psi_dot_d = ref[..., 9], ref[..., 10]
        sp, cp = np.sin(psi_d), np.cos(psi_d)
        angle_c = np.stack(
            np.broadcast_arrays(
                (acc_c[..., 0] * sp - acc_c[..., 1] * cp) / g,
                (acc_c[..., 0] * cp + acc_c[..., 1] * sp) / g,
                psi_d,
            ),
            axis=-1,
        )
        rate_c = np.zeros_like(angle_c)
        rate_c[..., 2] = psi_dot_d
        angle_err = angle_c - state[..., 3:6]
        angle_err[..., 2] = np.angle(np.exp(1j * angle_err[..., 2]))  # wrap yaw error
        moments = self.params.inertia * (
            np.asarray(k.kp_att) * angle_err + np.asarray(k.kv_att) * (rate_c - state[..., 9:12])
        )
        tilt = np.cos(state[..., 3]) * np.cos(state[..., 4])
        u = np.empty(moments.shape[:-1] + (4,))
        u[..., 0] = m * (g + acc_c[..., 2]) / np.maximum(tilt, 0.5)
        u[..., 1:] = moments
        return u
