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
from numba.extending import register_jitable

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


def components(x: FloatArray, u: FloatArray) -> tuple[FloatArray, FloatArray]:
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


def planar_field(
    phi: FloatArray,
    y_dot: FloatArray,
    z_dot: FloatArray,
    phi_dot: FloatArray,
    u1: FloatArray,
    u2: FloatArray,
    mass: FloatArray,
    Ixx: FloatArray,
    gravity: FloatArray,
) -> tuple[FloatArray, ...]:
    """The planar equations of motion, elementwise: the one source of them.

    Written on numbers so that numpy evaluates it on arrays (:func:`planar_rhs`) and numba
    compiles it for single states (:mod:`quad_envs.physics`).

    Returns:
        (y', z', phi', y_dot', z_dot', phi_dot').
    """
    inv_m = 1.0 / mass
    return (
        y_dot,
        z_dot,
        phi_dot,
        -u1 * np.sin(phi) * inv_m,
        u1 * np.cos(phi) * inv_m - gravity,
        u2 / Ixx,
    )


def planar_rhs(x: FloatArray, u: FloatArray, params: PlanarQuadParams) -> FloatArray:
    """Time derivative of the planar state (no saturation).

    Args:
        x: States, shape (..., 6).
        u: Inputs [u1, u2], shape (..., 2); batch axes broadcast against x's.
        params: Vehicle parameters.

    Returns:
        dx/dt, shape (..., 6).
    """
    (_, _, phi, y_dot, z_dot, phi_dot), (u1, u2) = components(x, u)
    return np.array(
        planar_field(phi, y_dot, z_dot, phi_dot, u1, u2, params.mass, params.Ixx, params.gravity)
    ).T


def planar_drag(
    phi: FloatArray,
    vy_rel: FloatArray,
    vz_rel: FloatArray,
    d_xy: FloatArray,
    d_z: FloatArray,
    c_xy: FloatArray,
    c_z: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """Inertial drag force [N] on the planar vehicle, elementwise.

    The air-relative velocity v = (vy_rel, vz_rel) [m/s] (inertial) is resolved on the body
    axes b_y = (cos phi, sin phi) and b_z = (-sin phi, cos phi) (b_z is the thrust axis);
    along each body axis F = -(D + c |v|) v_axis (linear rotor drag D [N s/m], quadratic body
    drag c [N s^2/m^2]); the result is rotated back to the inertial y-z frame.

    Returns:
        (F_y, F_z) [N].
    """
    c, s = np.cos(phi), np.sin(phi)
    v_lat = c * vy_rel + s * vz_rel
    v_up = -s * vy_rel + c * vz_rel
    speed = np.sqrt(vy_rel * vy_rel + vz_rel * vz_rel)
    f_lat = -(d_xy + c_xy * speed) * v_lat
    f_up = -(d_z + c_z * speed) * v_up
    return c * f_lat - s * f_up, s * f_lat + c * f_up


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


@register_jitable
def rotation_entries(
    cf: FloatArray, sf: FloatArray, ct: FloatArray, st: FloatArray, cp: FloatArray, sp: FloatArray
) -> tuple[FloatArray, ...]:
    """The nine entries (row-major) of the Z-X-Y body-to-inertial rotation, elementwise.

    Args:
        cf: cos(phi) (roll), any shape S.
        sf: sin(phi).
        ct: cos(theta) (pitch).
        st: sin(theta).
        cp: cos(psi) (yaw).
        sp: sin(psi).

    Returns:
        (R00, R01, R02, R10, R11, R12, R20, R21, R22), each of shape S.
    """
    return (
        cp * ct - sf * sp * st,
        -cf * sp,
        cp * st + ct * sf * sp,
        ct * sp + cp * sf * st,
        cf * cp,
        sp * st - cp * ct * sf,
        -cf * st,
        sf,
        cf * ct,
    )


def rotation_zxy(phi: FloatArray, theta: FloatArray, psi: FloatArray) -> FloatArray:
    """Body-to-inertial rotation for Z-X-Y Euler angles, as printed in the paper.

    Args:
        phi: Roll [rad], any shape S.
        theta: Pitch [rad], shape S.
        psi: Yaw [rad], shape S.

    Returns:
        Rotation matrices, shape S + (3, 3).
    """
    entries = rotation_entries(
        np.cos(phi), np.sin(phi), np.cos(theta), np.sin(theta), np.cos(psi), np.sin(psi)
    )
    rot = np.empty(np.shape(phi) + (9,))
    for i, entry in enumerate(entries):
        rot[..., i] = entry
    return rot.reshape(np.shape(phi) + (3, 3))


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


def quad6dof_field(
    phi: FloatArray,
    theta: FloatArray,
    psi: FloatArray,
    vx: FloatArray,
    vy: FloatArray,
    vz: FloatArray,
    p: FloatArray,
    q: FloatArray,
    r: FloatArray,
    u1: FloatArray,
    u2: FloatArray,
    u3: FloatArray,
    u4: FloatArray,
    mass: FloatArray,
    jx: FloatArray,
    jy: FloatArray,
    jz: FloatArray,
    g: FloatArray,
) -> tuple[FloatArray, ...]:
    """The 6-DOF equations of motion, elementwise: the one source of them.

    Numpy evaluates it on arrays (:func:`quad6dof_rhs`), numba compiles it for single states
    (:mod:`quad_envs.physics`).

    Returns:
        The 12 derivatives (x', y', z', phi', theta', psi', u', v', w', p', q', r').
    """
    cf, sf = np.cos(phi), np.sin(phi)
    ct, st = np.cos(theta), np.sin(theta)
    cp, sp = np.cos(psi), np.sin(psi)
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = rotation_entries(cf, sf, ct, st, cp, sp)
    return (
        # Inertial velocity R v_B.
        r00 * vx + r01 * vy + r02 * vz,
        r10 * vx + r11 * vy + r12 * vz,
        r20 * vx + r21 * vy + r22 * vz,
        # Euler angle rates T^-1 omega.
        ct * p + st * r,
        q + (sf / cf) * (st * p - ct * r),
        (-st * p + ct * r) / cf,
        # Body-frame acceleration.
        g * cf * st + r * vy - q * vz,
        -g * sf + p * vz - r * vx,
        -g * cf * ct + u1 / mass + q * vx - p * vy,
        # Euler's equation.
        (u2 - (jz - jy) * q * r) / jx,
        (u3 - (jx - jz) * r * p) / jy,
        (u4 - (jy - jx) * p * q) / jz,
    )


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
    (_, _, _, phi, theta, psi, vx, vy, vz, p, q, r), (u1, u2, u3, u4) = components(x, u)
    return np.array(
        quad6dof_field(
            phi,
            theta,
            psi,
            vx,
            vy,
            vz,
            p,
            q,
            r,
            u1,
            u2,
            u3,
            u4,
            params.mass,
            params.Jxx,
            params.Jyy,
            params.Jzz,
            params.gravity,
        )  # fmt: skip
    ).T


def body_drag(
    vx_rel: FloatArray,
    vy_rel: FloatArray,
    vz_rel: FloatArray,
    d_xy: FloatArray,
    d_z: FloatArray,
    c_xy: FloatArray,
    c_z: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Body-frame drag force [N] for the body-frame air-relative velocity [m/s], elementwise.

    F_i = -(D_i + c_i |v|) v_i: linear rotor drag D (d_xy on x and y, d_z on z) [N s/m] and
    quadratic body drag c (c_xy, c_z) [N s^2/m^2], |v| the air speed.

    Returns:
        (F_x, F_y, F_z) [N] in the body frame.
    """
    speed = np.sqrt(vx_rel * vx_rel + vy_rel * vy_rel + vz_rel * vz_rel)
    k_xy = d_xy + c_xy * speed
    return -k_xy * vx_rel, -k_xy * vy_rel, -(d_z + c_z * speed) * vz_rel


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
