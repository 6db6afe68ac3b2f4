"""Quadrotor equations of motion as pure, batched functions.

Every function here takes states and inputs with arbitrary leading (batch) axes and returns
arrays of the same leading shape. Nothing here holds state, draws random numbers or knows
about Gymnasium: the environments, the simulators and the identification code all call these.

Planar state ``[y, z, phi, y_dot, z_dot, phi_dot]`` (inertial y-z plane, roll phi about x) and
input ``[u1, u2]`` (total thrust [N], roll moment [N m]):

    y_ddot = -u1 sin(phi) / m,   z_ddot = u1 cos(phi) / m - g,   phi_ddot = u2 / Ixx.

6-DOF state ``[x, y, z, phi, theta, psi, u, v, w, p, q, r]``: inertial position [m], Z-X-Y Euler
angles roll, pitch, yaw [rad], body-frame velocity [m/s] and body angular rate [rad/s]; input
``[u1, u2, u3, u4]``: total thrust [N] and body moments [N m] (paper section 2).

The ``*_rhs`` functions do not saturate: the rotor limits are a separate step
(:func:`saturate_planar`, :func:`saturate_quad6dof`) that the environments and simulators apply
to the commanded input before integrating, as the authors' code does inside its dynamics.
"""

from __future__ import annotations

import numpy as np

from quad_envs.params import PlanarQuadParams, Quad6DOFParams
from quad_envs.types import FloatArray

PLANAR_STATE_NAMES: tuple[str, ...] = ("y", "z", "phi", "y_dot", "z_dot", "phi_dot")
PLANAR_INPUT_NAMES: tuple[str, ...] = ("u1", "u2")
QUAD6DOF_STATE_NAMES: tuple[str, ...] = (
    "x", "y", "z", "phi", "theta", "psi", "u", "v", "w", "p", "q", "r",
)  # fmt: skip
QUAD6DOF_INPUT_NAMES: tuple[str, ...] = ("u1", "u2", "u3", "u4")
PLANAR_ANGLE_INDICES: tuple[int, ...] = (2,)
QUAD6DOF_ANGLE_INDICES: tuple[int, ...] = (3, 4, 5)


def _unpack(x: FloatArray, u: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Component views of x and u with a common batch shape, component axis first.

    ``.T`` reverses every axis, so each component has the batch axes reversed; the rhs
    computes elementwise and transposes back, which is the fastest layout for both a single
    state (numpy scalars) and a batch.
    """
    x = np.asarray(x, dtype=np.float64)
    u = np.asarray(u, dtype=np.float64)
    if x.shape[:-1] != u.shape[:-1]:
        batch = np.broadcast_shapes(x.shape[:-1], u.shape[:-1])
        x = np.broadcast_to(x, batch + x.shape[-1:])
        u = np.broadcast_to(u, batch + u.shape[-1:])
    return x.T, u.T


def planar_rhs(x: FloatArray, u: FloatArray, params: PlanarQuadParams) -> FloatArray:
    """Time derivative of the planar state (no saturation).

    Args:
        x: States, shape (..., 6).
        u: Inputs [u1, u2], shape (..., 2); batch axes broadcast against x's.
        params: Vehicle parameters.

    Returns:
        dx/dt, shape (..., 6).
    """
    (_, _, phi, y_dot, z_dot, phi_dot), (u1, u2) = _unpack(x, u)
    inv_m = 1.0 / params.mass
    return np.array(
        (
            y_dot,
            z_dot,
            phi_dot,
            -u1 * np.sin(phi) * inv_m,
            u1 * np.cos(phi) * inv_m - params.gravity,
            u2 / params.Ixx,
        )
    ).T


def saturate_planar(u: FloatArray, params: PlanarQuadParams) -> FloatArray:
    """Applies the per-rotor thrust limits to commanded planar inputs.

    The commanded [u1, u2] is split into rotor forces f1 = (u1 - u2/L)/2, f2 = (u1 + u2/L)/2,
    each is clipped to [rotor_force_min, rotor_force_max], and the applied inputs are
    u1 = f1 + f2, u2 = (f2 - f1) L (the authors' ``planar_quad_discovered_eom.m``).

    Args:
        u: Commanded inputs, shape (..., 2).
        params: Vehicle parameters.

    Returns:
        The applied inputs, same shape.
    """
    u = np.asarray(u, dtype=np.float64)
    arm = params.arm_length
    u1, u2 = u.T
    lo, hi = params.rotor_force_min, params.rotor_force_max
    f1 = np.minimum(np.maximum(0.5 * (u1 - u2 / arm), lo), hi)
    f2 = np.minimum(np.maximum(0.5 * (u1 + u2 / arm), lo), hi)
    return np.array((f1 + f2, (f2 - f1) * arm)).T


def rotation_zxy(phi: FloatArray, theta: FloatArray, psi: FloatArray) -> FloatArray:
    """Body-to-inertial rotation for Z-X-Y Euler angles, as printed in the paper.

    Args:
        phi: Roll [rad], any shape S.
        theta: Pitch [rad], shape S.
        psi: Yaw [rad], shape S.

    Returns:
        Rotation matrices, shape S + (3, 3).
    """
    cf, sf = np.cos(phi), np.sin(phi)
    ct, st = np.cos(theta), np.sin(theta)
    cp, sp = np.cos(psi), np.sin(psi)
    rot = np.empty(np.shape(phi) + (3, 3))
    rot[..., 0, 0] = cp * ct - sf * sp * st
    rot[..., 0, 1] = -cf * sp
    rot[..., 0, 2] = cp * st + ct * sf * sp
    rot[..., 1, 0] = ct * sp + cp * sf * st
    rot[..., 1, 1] = cf * cp
    rot[..., 1, 2] = sp * st - cp * ct * sf
    rot[..., 2, 0] = -cf * st
    rot[..., 2, 1] = sf
    rot[..., 2, 2] = cf * ct
    return rot


def euler_rates_matrix(phi: FloatArray, theta: FloatArray) -> FloatArray:
    """Matrix T with omega_body = T @ [phi_dot, theta_dot, psi_dot] (Z-X-Y angles).

    Args:
        phi: Roll [rad], shape S.
        theta: Pitch [rad], shape S.

    Returns:
        Matrices of shape S + (3, 3); singular where cos(phi) = 0.
    """
    cf, sf = np.cos(phi), np.sin(phi)
    ct, st = np.cos(theta), np.sin(theta)
    mat = np.zeros(np.shape(phi) + (3, 3))
    mat[..., 0, 0] = ct
    mat[..., 0, 2] = -cf * st
    mat[..., 1, 1] = 1.0
    mat[..., 1, 2] = sf
    mat[..., 2, 0] = st
    mat[..., 2, 2] = cf * ct
    return mat


def quad6dof_rhs(x: FloatArray, u: FloatArray, params: Quad6DOFParams) -> FloatArray:
    """Time derivative of the 6-DOF state (no saturation), paper section 2.

    r_dot = R v_B;  angle rates = T^-1 omega;
    v_B_dot = R^T [0, 0, -g] + [0, 0, u1/m] - omega x v_B;
    omega_dot = J^-1 (M - omega x J omega) with M = [u2, u3, u4].

    Args:
        x: States, shape (..., 12).
        u: Inputs [u1, u2, u3, u4], shape (..., 4); batch axes broadcast against x's.
        params: Vehicle parameters.

    Returns:
        dx/dt, shape (..., 12).
    """
    (_, _, _, phi, theta, psi, vx, vy, vz, p, q, r), (u1, u2, u3, u4) = _unpack(x, u)
    cf, sf = np.cos(phi), np.sin(phi)
    ct, st = np.cos(theta), np.sin(theta)
    cp, sp = np.cos(psi), np.sin(psi)
    g = params.gravity
    jx, jy, jz = params.Jxx, params.Jyy, params.Jzz
    return np.array(
        (
            # Inertial velocity R v_B (rows of the Z-X-Y rotation).
            (cp * ct - sf * sp * st) * vx - cf * sp * vy + (cp * st + ct * sf * sp) * vz,
            (ct * sp + cp * sf * st) * vx + cf * cp * vy + (sp * st - cp * ct * sf) * vz,
            -cf * st * vx + sf * vy + cf * ct * vz,
            # Euler angle rates T^-1 omega.
            ct * p + st * r,
            q + (sf / cf) * (st * p - ct * r),
            (-st * p + ct * r) / cf,
            # Body-frame acceleration.
            g * cf * st + r * vy - q * vz,
            -g * sf + p * vz - r * vx,
            -g * cf * ct + u1 / params.mass + q * vx - p * vy,
            # Euler's equation.
            (u2 - (jz - jy) * q * r) / jx,
            (u3 - (jx - jz) * r * p) / jy,
            (u4 - (jy - jx) * p * q) / jz,
        )
    ).T


def saturate_quad6dof(u: FloatArray, params: Quad6DOFParams) -> FloatArray:
    """Applies the per-rotor thrust limits to commanded 6-DOF inputs.

    The rotor thrusts T = M^-1 u (``params.mixer``) are clipped to
    [rotor_force_min, rotor_force_max] and mixed back.

    Args:
        u: Commanded inputs, shape (..., 4).
        params: Vehicle parameters.

    Returns:
        The applied inputs, same shape.
    """
    mixer = params.mixer
    thrusts = np.asarray(u, dtype=np.float64) @ np.linalg.inv(mixer).T
    thrusts = np.clip(thrusts, params.rotor_force_min, params.rotor_force_max)
    return thrusts @ mixer.T


def body_to_inertial_velocity(x: FloatArray) -> FloatArray:
    """Inertial velocity R v_B of 6-DOF states, shape (..., 3)."""
    rot = rotation_zxy(x[..., 3], x[..., 4], x[..., 5])
    return np.einsum("...ij,...j->...i", rot, x[..., 6:9])


def hover_input_planar(params: PlanarQuadParams) -> FloatArray:
    """Input that holds the planar vehicle still: [m g, 0]."""
    return np.array([params.hover_thrust, 0.0])


def hover_input_quad6dof(params: Quad6DOFParams) -> FloatArray:
    """Input that holds the 6-DOF vehicle still: [m g, 0, 0, 0]."""
    return np.array([params.hover_thrust, 0.0, 0.0, 0.0])
