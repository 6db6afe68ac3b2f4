import numpy as np
import pytest
from scipy.integrate import solve_ivp

from quad_envs import dynamics as dyn
from quad_envs.integrators import rk4_step
from quad_envs.params import PAPER_6DOF, PAPER_PLANAR

P2, P6 = PAPER_PLANAR, PAPER_6DOF


def planar(x, u):
    return dyn.planar_rhs(x, u, P2)


def six(x, u):
    return dyn.quad6dof_rhs(x, u, P6)


def test_hover_is_an_equilibrium():
    x2 = np.array([0.3, 1.2, 0, 0, 0, 0])
    np.testing.assert_allclose(planar(x2, dyn.hover_input_planar(P2)), 0, atol=1e-12)
    x6 = np.zeros(12)
    x6[:3] = [0.1, -0.4, 2.0]
    x6[5] = 0.7  # any yaw
    np.testing.assert_allclose(six(x6, dyn.hover_input_quad6dof(P6)), 0, atol=1e-12)
    # and RK4 keeps it there
    x = x6
    for _ in range(100):
        x = rk4_step(six, x, dyn.hover_input_quad6dof(P6), 0.01)
    np.testing.assert_allclose(x, x6, atol=1e-12)


def test_planar_rhs_matches_the_paper_equations():
    rng = np.random.default_rng(0)
    x, u = rng.normal(size=6), rng.normal(size=2)
    dx = planar(x, u)
    np.testing.assert_allclose(dx[:3], x[3:])
    assert dx[3] == pytest.approx(-u[0] * np.sin(x[2]) / 0.18)
    assert dx[4] == pytest.approx(u[0] * np.cos(x[2]) / 0.18 - 9.81)
    assert dx[5] == pytest.approx(u[1] / 2.5e-4)


@pytest.mark.parametrize("rhs,n,m", [(planar, 6, 2), (six, 12, 4)])
def test_batched_equals_looped(rhs, n, m):
    rng = np.random.default_rng(1)
    x, u = rng.normal(size=(3, 4, n)) * 0.5, rng.normal(size=(3, 4, m)) * 0.1
    batched = rhs(x, u)
    assert batched.shape == (3, 4, n)
    for i in range(3):
        for j in range(4):
            np.testing.assert_allclose(batched[i, j], rhs(x[i, j], u[i, j]), rtol=1e-14)
    # a single input broadcasts over a batch of states
    np.testing.assert_allclose(rhs(x, u[0, 0])[2, 3], rhs(x[2, 3], u[0, 0]))


def test_6dof_restricted_to_the_plane_equals_planar():
    """theta = psi = 0, u = q = r = 0, u3 = u4 = 0: the 6-DOF model is the planar one."""
    rng = np.random.default_rng(2)
    for _ in range(20):
        y, z, phi, phi_dot = rng.normal(size=4)
        v_inertial = rng.normal(size=2)
        u1, u2 = rng.uniform(0.5, 3), rng.normal() * 0.01
        c, s = np.cos(phi), np.sin(phi)
        v_body = np.array(
            [c * v_inertial[0] + s * v_inertial[1], -s * v_inertial[0] + c * v_inertial[1]]
        )
        x6 = np.array([0, y, z, phi, 0, 0, 0, *v_body, phi_dot, 0, 0])
        dx6 = six(x6, np.array([u1, u2, 0, 0]))
        dx2 = planar(np.array([y, z, phi, *v_inertial, phi_dot]), np.array([u1, u2]))
        # inertial acceleration from the body-frame derivative: d/dt (R v_B)
        rot = dyn.rotation_zxy(phi, 0.0, 0.0)
        omega = np.array([phi_dot, 0, 0])
        acc = rot @ (dx6[6:9] + np.cross(omega, x6[6:9]))
        np.testing.assert_allclose(dx6[[1, 2]], dx2[[0, 1]], atol=1e-12)
        assert dx6[3] == pytest.approx(dx2[2])
        np.testing.assert_allclose(acc[1:], dx2[3:5], atol=1e-10)
        assert dx6[9] == pytest.approx(dx2[5])
        np.testing.assert_allclose(dx6[[0, 4, 5, 10, 11]], 0, atol=1e-12)


def test_rotation_is_orthonormal_and_rates_matrix_inverts():
    rng = np.random.default_rng(3)
    ang = rng.uniform(-1, 1, size=(50, 3))
    rot = dyn.rotation_zxy(ang[:, 0], ang[:, 1], ang[:, 2])
    np.testing.assert_allclose(
        rot @ np.swapaxes(rot, 1, 2), np.broadcast_to(np.eye(3), rot.shape), atol=1e-12
    )
    np.testing.assert_allclose(np.linalg.det(rot), 1, atol=1e-12)
    # the rhs's angle rates are T^-1 omega
    x = np.zeros((50, 12))
    x[:, 3:6], x[:, 9:12] = ang, rng.normal(size=(50, 3))
    rates = six(x, np.zeros(4))[:, 3:6]
    tmat = dyn.euler_rates_matrix(ang[:, 0], ang[:, 1])
    np.testing.assert_allclose(np.einsum("nij,nj->ni", tmat, rates), x[:, 9:12], atol=1e-12)


def test_rotation_derivative_matches_body_rates():
    """R_dot = R [omega]x: the kinematics and the rotation matrix agree."""
    rng = np.random.default_rng(4)
    x = np.zeros(12)
    x[3:6], x[9:12] = rng.uniform(-0.5, 0.5, 3), rng.normal(size=3)
    rates = six(x, np.zeros(4))[3:6]
    h = 1e-6
    r_plus = dyn.rotation_zxy(*(x[3:6] + h * rates))
    r_minus = dyn.rotation_zxy(*(x[3:6] - h * rates))
    r_dot = (r_plus - r_minus) / (2 * h)
    p, q, r = x[9:12]
    skew = np.array([[0, -r, q], [r, 0, -p], [-q, p, 0]])
    np.testing.assert_allclose(r_dot, dyn.rotation_zxy(*x[3:6]) @ skew, atol=1e-8)


@pytest.mark.parametrize("rhs,x0,u", [
    (planar, np.array([0, 1, 0.3, 0.5, -0.2, 1.0]), np.array([2.0, 0.004])),
    (six, np.array([0, 0, 1, 0.2, -0.1, 0.3, 0.5, 0.1, -0.2, 0.5, -0.3, 0.2]),
     np.array([2.0, 0.003, -0.002, 0.001])),
])  # fmt: skip
def test_rk4_converges_at_fourth_order(rhs, x0, u):
    horizon = 1.0
    exact = solve_ivp(lambda t, x: rhs(x, u), (0, horizon), x0, rtol=1e-13, atol=1e-13).y[:, -1]
    errors = []
    for n in (40, 80, 160):
        x = x0
        for _ in range(n):
            x = rk4_step(rhs, x, u, horizon / n)
        errors.append(np.abs(x - exact).max())
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(orders > 3.7), (errors, orders)
    # substeps are the same as smaller steps
    np.testing.assert_allclose(
        rk4_step(rhs, x0, u, 0.1, substeps=4),
        rk4_step(
            rhs,
            rk4_step(rhs, rk4_step(rhs, rk4_step(rhs, x0, u, 0.025), u, 0.025), u, 0.025),
            u,
            0.025,
        ),
    )


def test_planar_saturation_per_rotor():
    arm, fmax = P2.arm_length, P2.rotor_force_max
    inside = np.array([1.0, 0.01])
    np.testing.assert_allclose(dyn.saturate_planar(inside, P2), inside)
    out = dyn.saturate_planar(np.array([[5.0, 0.0], [1.0, 0.2], [-1.0, 0.0]]), P2)
    np.testing.assert_allclose(out[0], [2 * fmax, 0])
    # f1 = (1 - 0.2/L)/2 < 0 -> 0, f2 = (1 + 0.2/L)/2 within limits
    f2 = 0.5 * (1 + 0.2 / arm)
    np.testing.assert_allclose(out[1], [f2, f2 * arm])
    np.testing.assert_allclose(out[2], [0, 0])


def test_6dof_saturation_clips_rotor_thrusts():
    mix = P6.mixer
    thrusts = np.array([0.2, 0.3, 0.25, 0.1])
    u = mix @ thrusts
    np.testing.assert_allclose(dyn.saturate_quad6dof(u, P6), u, atol=1e-15)
    too_much = mix @ np.array([2.0, -1.0, 0.3, 0.3])
    expected = mix @ np.array([P6.rotor_force_max, 0.0, 0.3, 0.3])
    np.testing.assert_allclose(dyn.saturate_quad6dof(too_much, P6), expected, atol=1e-15)
