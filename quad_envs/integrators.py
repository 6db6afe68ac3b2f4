"""The one integrator: classical fourth-order Runge-Kutta with a zero-order-hold input."""

from __future__ import annotations

from collections.abc import Callable

from quad_envs.types import FloatArray

Rhs = Callable[[FloatArray, FloatArray], FloatArray]
"""A vector field f(x, u) batched over leading axes."""


def rk4_step(f: Rhs, x: FloatArray, u: FloatArray, dt: float, substeps: int = 1) -> FloatArray:
    """Advances x by dt with RK4, holding the input u constant over the step.

    Args:
        f: Vector field f(x, u) -> dx/dt, batched over leading axes.
        x: State(s), shape (..., n).
        u: Input(s) held over the whole step, shape (..., m).
        dt: Step length [s].
        substeps: Number of equal RK4 substeps inside dt (the input stays held).

    Returns:
        The state after dt, shape of ``x``.
    """
    h = dt / substeps
    for _ in range(substeps):
        k1 = f(x, u)
        k2 = f(x + (0.5 * h) * k1, u)
        k3 = f(x + (0.5 * h) * k2, u)
        k4 = f(x + h * k3, u)
        x = x + (h / 6.0) * (k1 + 2.0 * (k2 + k3) + k4)
    return x
