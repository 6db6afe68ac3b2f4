"""Source of the batched step kernel, specialised per vector field by code generation.

Not imported to be run: :func:`quad_envs.physics.build_kernels` writes this file's text,
followed by the lines that bind ``_field`` and ``_observe`` (a vehicle's numba point
functions, or a surrogate's generated point rhs) and the vehicle's sizes, as one module
into the kernel cache folder and imports it, so that numba's on-disk cache applies to
every vehicle and every identified model without a vehicle switch in the kernel. The
sizes (``_N_STATE``, ``_N_ROTOR``, ``_N_INPUT``, ``_N_OBS``) are compile-time constants
there, so the compiler unrolls the loops over states, rotors and inputs.

``_field(x, u, thrust, wind, p, c, out)`` writes the extended dx/dt of one member;
``_observe(x, ref, out)`` writes the vehicle's observation of one member.

The kernels run without numba's reference counting (``_nrt=False``: no allocation inside,
every output is passed in). With it, the array views taken per member cost two atomic
operations each and made the per-member step about ten times slower.
"""

# ruff: noqa: ANN001, ANN201, ANN202, F821  (_field and _observe are bound by the generator)
from __future__ import annotations

import math  # noqa: F401  (used by generated point functions)
from typing import Any

import numba

from quad_envs.physics import (
    _DT,
    _GUST_A,
    _GUST_S,
    _NOISE,
    _OBS_ROTORS,
    _ROTOR,
    _SUBSTEPS,
    _WIND0,
    KERNEL_JIT,
    _add_noise,
    _all_finite,
    _command_one,
    _mix_into,
)

_field: Any  # bound by the generated module
_observe: Any  # bound by the generated module
_N_STATE: int  # the vehicle's rigid-body (or own) state size, bound by the generated module
_N_ROTOR: int  # its rotors (the mixer's columns)
_N_INPUT: int  # its collective inputs (the mixer's rows)
_N_OBS: int  # the entries its _observe writes


@numba.njit(cache=True, inline="always")
def _mix(mix, thrust, u):
    """The collective input u = mix @ thrust, unrolled for the vehicle's sizes."""
    _mix_into(mix, thrust, u, _N_INPUT, _N_ROTOR)


@numba.njit(cache=True, inline="always")
def _stage(out, x, a, k, rotor):
    """Writes x + a k into out (the rotor states too only with rotor dynamics)."""
    for j in range(_N_STATE):
        out[j] = x[j] + a * k[j]
    if rotor:
        for j in range(_N_STATE, _N_STATE + _N_ROTOR):
            out[j] = x[j] + a * k[j]


@numba.njit(cache=True, inline="always")
def _integrate_one(x, thrust, wind, p, c, mix, u, stages):
    """Classical RK4 (as :func:`quad_envs.integrators.rk4_step`) with the command held.

    ``stages`` is a (5, len(x)) work array (the four stages and the stage state).
    """
    rotor = c[_ROTOR] != 0.0
    h = c[_DT] / c[_SUBSTEPS]
    k1, k2, k3, k4, xs = stages[0], stages[1], stages[2], stages[3], stages[4]
    if not rotor:
        _mix(mix, thrust, u)
    for _ in range(int(c[_SUBSTEPS])):
        if rotor:
            _mix(mix, x[_N_STATE:], u)
        _field(x, u, thrust, wind, p, c, k1)
        _stage(xs, x, 0.5 * h, k1, rotor)
        if rotor:
            _mix(mix, xs[_N_STATE:], u)
        _field(xs, u, thrust, wind, p, c, k2)
        _stage(xs, x, 0.5 * h, k2, rotor)
        if rotor:
            _mix(mix, xs[_N_STATE:], u)
        _field(xs, u, thrust, wind, p, c, k3)
        _stage(xs, x, h, k3, rotor)
        if rotor:
            _mix(mix, xs[_N_STATE:], u)
        _field(xs, u, thrust, wind, p, c, k4)
        for j in range(_N_STATE + (_N_ROTOR if rotor else 0)):
            x[j] = x[j] + (h / 6.0) * (k1[j] + 2.0 * (k2[j] + k3[j]) + k4[j])
    if rotor:
        _mix(mix, x[_N_STATE:], u)


@numba.njit(cache=True, inline="always")
def _finish_one(x, ref, c, rng, i, bias, obsbox, xbox, obs):
    """Observation (biased, noisy, clipped), reward and termination of one member."""
    _observe(x, ref, obs)
    nobs = obs.shape[0]
    if c[_OBS_ROTORS] != 0.0:
        for j in range(_N_ROTOR):
            obs[_N_OBS + j] = x[_N_STATE + j]
    out = False
    for j in range(_N_STATE):
        if not (xbox[0, j] <= x[j] <= xbox[1, j]):  # NaN fails too
            out = True
    cost = 0.0
    for j in range(nobs):
        cost += obsbox[2, j] * obs[j] * obs[j]
    reward = 0.0 if out else math.exp(-cost)
    for j in range(nobs):
        v = obs[j]
        if not math.isfinite(v):  # only terminal states can have them
            v = 0.0 if math.isnan(v) else (1e308 if v > 0 else -1e308)
        obs[j] = v + bias[j]
    if c[_NOISE] > 0.0:
        _add_noise(rng, i, c[_NOISE], obs)
    for j in range(nobs):
        obs[j] = min(max(obs[j], obsbox[0, j]), obsbox[1, j])
    return reward, out


@numba.njit(**KERNEL_JIT)
def step(X, A, refs, P, C, rng, gust, bias, mix, unmix, box, frac, obsbox, xbox, active,
         obs, reward, end, u_app, u_cmd, work):  # fmt: skip
    """Steps every active member in place, writing obs, reward, end, u_app, u_cmd.

    ``work`` is a (8, w) scratch array, w >= the extended state, action, rotor and wind
    sizes; on return ``work[5, :k]`` holds the limited rotor commands of the last member
    stepped (the single env's ``info['rotor_commands']``). Returns False (and steps
    nothing) if an action is not finite.
    """
    b = X.shape[0]
    m, k = mix.shape
    nw, na = gust.shape[1], A.shape[1]
    if not _all_finite(A):
        return False
    stages = work[0:5, : X.shape[1]]
    thrust, wind, raw = work[5, :k], work[6, :nw], work[7, :na]
    ga, gs = C[_GUST_A], C[_GUST_S]
    one_p = P.shape[0] == 1
    for i in range(b):
        p = P[0] if one_p else P[i]
        if active[i]:
            _command_one(
                A[i], p, C, mix, unmix, box, frac, thrust, u_cmd[i], raw, _N_INPUT, _N_ROTOR
            )
            if gs > 0.0:
                for j in range(nw):
                    wind[j] = 0.0
                _add_noise(rng, i, gs, wind)
                for j in range(nw):
                    gust[i, j] = ga * gust[i, j] + wind[j]
            for j in range(nw):
                wind[j] = C[_WIND0 + j] + gust[i, j]
            _integrate_one(X[i], thrust, wind, p, C, mix, u_app[i], stages)
        else:
            for j in range(m):
                u_app[i, j] = 0.0
                u_cmd[i, j] = 0.0
        reward[i], end[i] = _finish_one(X[i], refs[i], C, rng, i, bias[i], obsbox, xbox, obs[i])
    return True


@numba.njit(**KERNEL_JIT)
def finish(X, refs, C, rng, bias, obsbox, xbox, obs, reward, end):
    """Observation, reward and termination of every member (written into the outputs)."""
    for i in range(X.shape[0]):
        reward[i], end[i] = _finish_one(X[i], refs[i], C, rng, i, bias[i], obsbox, xbox, obs[i])
    return True
