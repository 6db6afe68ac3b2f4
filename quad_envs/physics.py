"""The one physics the environments step: rigid body, optional effects, RK4, observation.

The equations of motion live once, as elementwise functions in :mod:`quad_envs.dynamics`
(numpy evaluates them on arrays, numba compiles them for single states). This module adds
the effects around them and compiles one batched step kernel per vehicle with numba; the
single env is the vector env's kernel with a batch of one, so the two agree to the bit.

Effects (:class:`Effects`), each off by default; units SI, frames as in
:mod:`quad_envs.dynamics` (z up; 6-DOF velocities in the body frame):

* **Actuator limits** (always on): the commanded rotor thrusts T_cmd,i are clipped to
  [rotor_force_min, rotor_force_max * rotor_max_fraction_i] [N]; ``rotor_max_fraction``
  (per rotor, default 1) models weak or failing motors.
* **Rotor dynamics** (``rotor_dynamics``): each rotor's thrust is a state,
  dT_i/dt = (T_cmd,i - T_i) / tau [N/s] with tau = ``rotor_time_constant`` [s]; the
  collective input is u = M T (``params.mixer``). Without it, T = T_cmd at once.
  The step response from T(0) is T(t) = T_cmd + (T(0) - T_cmd) exp(-t / tau).
* **Drag** (``drag``): with v_rel the air-relative velocity resolved on the body axes,
  F_i = -(D_i + c_i |v_rel|) v_rel,i [N]: linear rotor drag D [N s/m] and quadratic body
  drag c [N s^2/m^2] (``drag_linear_xy/z``, ``drag_quadratic_xy/z``; see
  :mod:`quad_envs.params` for the sources). The force divided by m adds to the
  (body-frame for 6-DOF, inertial for planar) acceleration.
* **Wind** (acts through drag): inertial wind w = w_mean + g(t) [m/s], the gust g an
  Ornstein-Uhlenbeck process per axis, sampled per control step and held over it:
  g_{k+1} = a g_k + sigma sqrt(1 - a^2) n_k, a = exp(-dt / gust_time_constant), n_k ~ N(0, 1),
  stationary standard deviation ``gust_std`` [m/s]. v_rel = v - w.
* **Sensor effects** on the observation: Gaussian noise (the env's ``obs_noise_std``), a
  constant bias per episode and entry drawn from N(0, ``obs_bias_std``^2), and a delay of
  ``obs_delay_steps`` whole control steps (the observation returned at step k is the one
  measured at step k - d; the first d steps repeat the reset observation). The reward and
  termination use the true state.

Random numbers (gusts, observation noise) come from a counter-based generator per member
(splitmix64) whose seed each episode draws from the env's ``np_random``: reproducible per
seed, the same in the single and the vector env.
"""

from __future__ import annotations

import math
import types
from collections.abc import Callable
from dataclasses import dataclass, fields
from typing import Any

import numba
import numpy as np

from quad_envs import dynamics
from quad_envs.types import FloatArray

# -- effects -----------------------------------------------------------------------------


@dataclass(frozen=True)
class Effects:
    """Which effects act, and their settings that are not vehicle parameters.

    Attributes:
        rotor_dynamics: First-order rotor-thrust lag; the rotor thrusts become states.
        observe_rotors: With rotor dynamics, append the rotor thrusts [N] to the observation.
        drag: Linear rotor drag and quadratic body drag.
        wind_mean: Constant inertial wind [m/s] ((w_y, w_z) planar, (w_x, w_y, w_z) 6-DOF);
            empty for none. Wind acts through drag.
        gust_std: Stationary standard deviation of the gust process per axis [m/s].
        gust_time_constant: Correlation time of the gusts [s].
        obs_bias_std: Standard deviation of the per-episode observation bias.
        obs_delay_steps: Observation delay in whole control steps.
        rotor_max_fraction: Per-rotor fraction of ``rotor_force_max`` available (empty: all 1).
    """

    rotor_dynamics: bool = False
    observe_rotors: bool = True
    drag: bool = False
    wind_mean: tuple[float, ...] = ()
    gust_std: float = 0.0
    gust_time_constant: float = 1.0
    obs_bias_std: float = 0.0
    obs_delay_steps: int = 0
    rotor_max_fraction: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "wind_mean", tuple(float(w) for w in self.wind_mean))
        object.__setattr__(
            self, "rotor_max_fraction", tuple(float(f) for f in self.rotor_max_fraction)
        )
        for name in ("gust_std", "obs_bias_std"):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0:
                raise ValueError(f"effects.{name} must be a non-negative number, got {value!r}")
        if not np.isfinite(self.gust_time_constant) or self.gust_time_constant <= 0:
            raise ValueError(
                f"effects.gust_time_constant must be positive, got {self.gust_time_constant!r}"
            )
        if int(self.obs_delay_steps) != self.obs_delay_steps or self.obs_delay_steps < 0:
            raise ValueError(
                f"effects.obs_delay_steps must be a non-negative integer, "
                f"got {self.obs_delay_steps!r}"
            )
        if not all(np.isfinite(self.wind_mean)):
            raise ValueError(f"effects.wind_mean must be finite, got {self.wind_mean!r}")
        if any(not (0 < f <= 1) for f in self.rotor_max_fraction):
            raise ValueError(
                f"effects.rotor_max_fraction entries must lie in (0, 1], "
                f"got {self.rotor_max_fraction!r}"
            )
        if self.wind and not self.drag:
            raise ValueError("wind acts through drag: switch drag on too (effects drag=True)")

    @property
    def wind(self) -> bool:
        """Whether any wind blows."""
        return any(w != 0 for w in self.wind_mean) or self.gust_std > 0

    @property
    def physical(self) -> bool:
        """Whether an effect changes the vector field (rotor dynamics, drag, wind)."""
        return self.rotor_dynamics or self.drag or self.wind

    @classmethod
    def all_on(cls, ndim: int, n_rotors: int) -> Effects:
        """Every effect with moderate settings (a 1 m/s breeze, 0.5 m/s gusts, a weak rotor)."""
        return cls(
            rotor_dynamics=True,
            drag=True,
            wind_mean=(1.0,) + (0.0,) * (ndim - 1),
            gust_std=0.5,
            gust_time_constant=1.0,
            obs_bias_std=0.01,
            obs_delay_steps=1,
            rotor_max_fraction=(1.0,) * (n_rotors - 1) + (0.9,),
        )

    @classmethod
    def from_spec(cls, spec: Any, ndim: int, n_rotors: int) -> Effects:
        """Effects from ``None``, an :class:`Effects`, ``"all"``, a dict of fields, or names.

        A list/tuple of names (``["drag", "rotor_dynamics"]``) switches those on with their
        defaults (``"wind"``: a 1 m/s breeze with 0.5 m/s gusts; ``"sensor"``: bias 0.01 and
        a one-step delay; ``"rotor_limits"``: the last rotor at 90 %).
        """
        if spec is None:
            return cls()
        if isinstance(spec, Effects):
            return spec
        if isinstance(spec, str):
            if spec == "all":
                return cls.all_on(ndim, n_rotors)
            spec = [spec]
        if isinstance(spec, dict):
            valid = [f.name for f in fields(cls)]
            unknown = sorted(set(spec) - set(valid))
            if unknown:
                raise ValueError(f"unknown effect setting(s) {unknown}; valid: {valid}")
            return cls(**spec)
        if isinstance(spec, list | tuple):
            full = cls.all_on(ndim, n_rotors)
            groups = {
                "rotor_dynamics": {"rotor_dynamics": True},
                "drag": {"drag": True},
                "wind": {
                    "drag": True,
                    "wind_mean": full.wind_mean,
                    "gust_std": full.gust_std,
                },
                "sensor": {"obs_bias_std": full.obs_bias_std, "obs_delay_steps": 1},
                "rotor_limits": {"rotor_max_fraction": full.rotor_max_fraction},
            }
            changes: dict[str, Any] = {}
            for name in spec:
                if name not in groups:
                    raise ValueError(
                        f"unknown effect {name!r}; valid choices: {', '.join(groups)}, all"
                    )
                changes.update(groups[name])
            return cls(**changes)
        raise ValueError(
            f"effects must be None, 'all', a list of names, a dict or Effects, got {spec!r}"
        )


# -- parameters as a vector ----------------------------------------------------------------

EFFECT_FIELDS: tuple[str, ...] = (
    "rotor_time_constant", "thrust_coefficient",
    "drag_linear_xy", "drag_linear_z", "drag_quadratic_xy", "drag_quadratic_z",
)  # fmt: skip
"""Parameter fields of the effects, randomised with the mass and inertia."""

PARAM_FIELDS: tuple[str, ...] = (
    "mass", "I1", "I2", "I3", "gravity", "rotor_time_constant",
    "drag_linear_xy", "drag_linear_z", "drag_quadratic_xy", "drag_quadratic_z",
    "rotor_force_min", "rotor_force_max", "rotor_thrust_per_speed2",
)  # fmt: skip
"""Layout of the parameter vector the kernels read (I1..I3: Ixx or Jxx, Jyy, Jzz)."""

(_MASS, _I1, _I2, _I3, _G, _TAU, _DXY, _DZ, _CXY, _CZ, _FMIN, _FMAX, _KT) = range(13)
_INERTIA_ALIASES = {"I1": ("Jxx", "Ixx"), "I2": ("Jyy",), "I3": ("Jzz",)}


def pack_params(params: Any) -> FloatArray:
    """The parameter vector (:data:`PARAM_FIELDS`) of one parameter set."""
    values = []
    for name in PARAM_FIELDS:
        for alias in _INERTIA_ALIASES.get(name, (name,)):
            if hasattr(params, alias):
                values.append(float(getattr(params, alias)))
                break
        else:
            values.append(0.0)
    return np.array(values)


# -- constants vector ----------------------------------------------------------------------

MODES = ("collective", "rotor_thrusts", "motor_speeds")
"""Action modes: collective thrust and moments, per-rotor thrusts [N], motor speeds [rad/s]."""

(_DT, _SUBSTEPS, _MODE, _NORMALIZE, _ROTOR, _DRAG, _OBS_ROTORS, _GUST_A, _GUST_S, _NOISE) = range(
    10
)
_WIND0 = 10
N_CONSTS = 13


def pack_consts(
    dt: float,
    substeps: int,
    mode: str,
    normalize: bool,
    effects: Effects,
    obs_noise_std: float,
    ndim: int,
) -> FloatArray:
    """The kernel's constants (time step, mode, effect switches and settings)."""
    c = np.zeros(N_CONSTS)
    c[_DT], c[_SUBSTEPS], c[_MODE], c[_NORMALIZE] = dt, substeps, MODES.index(mode), normalize
    c[_ROTOR], c[_DRAG] = effects.rotor_dynamics, effects.drag
    c[_OBS_ROTORS] = effects.rotor_dynamics and effects.observe_rotors
    if effects.gust_std > 0:
        a = math.exp(-dt / effects.gust_time_constant)
        c[_GUST_A], c[_GUST_S] = a, effects.gust_std * math.sqrt(1.0 - a * a)
    c[_NOISE] = obs_noise_std
    if effects.wind_mean:
        if len(effects.wind_mean) != ndim:
            raise ValueError(
                f"effects.wind_mean needs {ndim} components for this vehicle, "
                f"got {len(effects.wind_mean)}"
            )
        c[_WIND0 : _WIND0 + ndim] = effects.wind_mean
    return c


# -- random numbers (splitmix64 + Box-Muller), per member ----------------------------------

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)


@numba.njit(cache=True, inline="always")
def _next_uniform(rng: Any, i: int) -> float:
    z = rng[i] + _GOLDEN
    rng[i] = z
    z = (z ^ (z >> np.uint64(30))) * _MIX1
    z = (z ^ (z >> np.uint64(27))) * _MIX2
    z = z ^ (z >> np.uint64(31))
    return (float(z >> np.uint64(11)) + 0.5) * (1.0 / 9007199254740992.0)  # in (0, 1)


@numba.njit(cache=True, inline="always")
def _next_normal(rng: Any, i: int) -> float:
    u1 = _next_uniform(rng, i)
    u2 = _next_uniform(rng, i)
    return math.sqrt(-2.0 * math.log(u1)) * math.cos(2.0 * math.pi * u2)


# -- the vehicles' point functions (numba) -------------------------------------------------

_planar_field = numba.njit(cache=True, inline="always")(dynamics.planar_field)
_planar_drag = numba.njit(cache=True, inline="always")(dynamics.planar_drag)
_quad6dof_field = numba.njit(cache=True, inline="always")(dynamics.quad6dof_field)
_rotation_entries = numba.njit(cache=True, inline="always")(dynamics.rotation_entries)
_body_drag = numba.njit(cache=True, inline="always")(dynamics.body_drag)


@numba.njit(cache=True, inline="always")
def planar_point(x: Any, u: Any, thrust: Any, wind: Any, p: Any, c: Any, out: Any) -> None:
    """Extended planar field at one point: rigid body (+ drag, wind, rotor lag).

    Args:
        x: Extended state (6, or 8 with rotor thrusts).
        u: Collective input [u1, u2] (from the rotor thrusts in effect).
        thrust: Commanded rotor thrusts (2,).
        wind: Inertial wind (2,).
        p: Parameter vector (:data:`PARAM_FIELDS`).
        c: Constants vector.
        out: dx/dt (written).
    """
    d = _planar_field(x[2], x[3], x[4], x[5], u[0], u[1], p[_MASS], p[_I1], p[_G])
    for j in range(6):
        out[j] = d[j]
    if c[_DRAG] != 0.0:
        fy, fz = _planar_drag(
            x[2], x[3] - wind[0], x[4] - wind[1], p[_DXY], p[_DZ], p[_CXY], p[_CZ]
        )
        out[3] += fy / p[_MASS]
        out[4] += fz / p[_MASS]
    if c[_ROTOR] != 0.0:
        for j in range(2):
            out[6 + j] = (thrust[j] - x[6 + j]) / p[_TAU]


@numba.njit(cache=True, inline="always")
def quad6dof_point(x: Any, u: Any, thrust: Any, wind: Any, p: Any, c: Any, out: Any) -> None:
    """Extended 6-DOF field at one point (see :func:`planar_point`; wind (3,))."""
    d = _quad6dof_field(
        x[3], x[4], x[5], x[6], x[7], x[8], x[9], x[10], x[11], u[0], u[1], u[2], u[3],
        p[_MASS], p[_I1], p[_I2], p[_I3], p[_G],
    )  # fmt: skip
    for j in range(12):
        out[j] = d[j]
    if c[_DRAG] != 0.0:
        r = _rotation_entries(
            math.cos(x[3]), math.sin(x[3]), math.cos(x[4]), math.sin(x[4]),
            math.cos(x[5]), math.sin(x[5]),
        )  # fmt: skip
        # Body-frame air velocity v_B - R^T w.
        wx = r[0] * wind[0] + r[3] * wind[1] + r[6] * wind[2]
        wy = r[1] * wind[0] + r[4] * wind[1] + r[7] * wind[2]
        wz = r[2] * wind[0] + r[5] * wind[1] + r[8] * wind[2]
        fx, fy, fz = _body_drag(x[6] - wx, x[7] - wy, x[8] - wz, p[_DXY], p[_DZ], p[_CXY], p[_CZ])
        out[6] += fx / p[_MASS]
        out[7] += fy / p[_MASS]
        out[8] += fz / p[_MASS]
    if c[_ROTOR] != 0.0:
        for j in range(4):
            out[12 + j] = (thrust[j] - x[12 + j]) / p[_TAU]


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


_wrap_nb = numba.njit(cache=True, inline="always")(_wrap)


@numba.njit(cache=True, inline="always")
def planar_observe_point(x: Any, ref: Any, out: Any) -> None:
    """[state, ref - position, ref - velocity] of one planar state (10 entries)."""
    for j in range(6):
        out[j] = x[j]
    out[6] = ref[0] - x[0]
    out[7] = ref[1] - x[1]
    out[8] = ref[2] - x[3]
    out[9] = ref[3] - x[4]


@numba.njit(cache=True, inline="always")
def quad6dof_observe_point(x: Any, ref: Any, out: Any) -> None:
    """[state (yaw wrapped), ref - position, ref - inertial velocity, yaw error] (19)."""
    for j in range(12):
        out[j] = x[j]
    out[5] = _wrap_nb(x[5])
    r = _rotation_entries(
        math.cos(x[3]), math.sin(x[3]), math.cos(x[4]), math.sin(x[4]),
        math.cos(x[5]), math.sin(x[5]),
    )  # fmt: skip
    for j in range(3):
        out[12 + j] = ref[j] - x[j]
        v = r[3 * j] * x[6] + r[3 * j + 1] * x[7] + r[3 * j + 2] * x[8]
        out[15 + j] = ref[3 + j] - v
    out[18] = _wrap_nb(ref[9] - x[5])


# -- the kernels -----------------------------------------------------------------------------
#
# Module-level and dispatching on a vehicle id, so that numba caches them on disk; surrogates
# with a compiled point rhs get the same source rebound to their field (uncached).


@numba.njit(cache=True, inline="always")
def _command_one(a, p, c, mix, unmix, box, frac, thrust, u_cmd, raw):  # noqa: ANN001, ANN202
    """Action row -> limited rotor thrusts (written) and the commanded collective input."""
    m, k = mix.shape
    mode, normalize = int(c[_MODE]), c[_NORMALIZE] != 0.0
    for j in range(a.shape[0]):
        lo, hi = box[0, j], box[1, j]
        if normalize:
            v = min(max(a[j], -1.0), 1.0)
            raw[j] = 0.5 * (hi + lo) + 0.5 * (hi - lo) * v
        else:
            raw[j] = min(max(a[j], lo), hi)
    if mode == 0:
        for j in range(m):
            u_cmd[j] = raw[j]
        for i in range(k):
            s = 0.0
            for j in range(m):
                s += unmix[i, j] * raw[j]
            thrust[i] = s
    else:
        for i in range(k):
            thrust[i] = raw[i] if mode == 1 else p[_KT] * raw[i] * raw[i]
        _mix_into(mix, thrust, u_cmd)
    for i in range(k):
        thrust[i] = min(max(thrust[i], p[_FMIN]), p[_FMAX] * frac[i])


@numba.njit(cache=True, inline="always")
def _mix_into(mix, thrust, u):  # noqa: ANN001, ANN202
    m, k = mix.shape
    for j in range(m):
        s = 0.0
        for i in range(k):
            s += mix[j, i] * thrust[i]
        u[j] = s


@numba.njit(cache=True, inline="always")
def _integrate_one(vid, n, x, thrust, wind, p, c, mix, u, scratch):  # noqa: ANN001, ANN202
    """Classical RK4 (as :func:`quad_envs.integrators.rk4_step`) with the command held.

    ``scratch`` is a (5, len(x)) work array (stages and the stage state).
    """
    ne = x.shape[0]
    rotor = c[_ROTOR] != 0.0
    h = c[_DT] / c[_SUBSTEPS]
    k1, k2, k3, k4, xs = scratch[0], scratch[1], scratch[2], scratch[3], scratch[4]
    if not rotor:
        _mix_into(mix, thrust, u)
    for _ in range(int(c[_SUBSTEPS])):
        if rotor:
            _mix_into(mix, x[n:], u)
        _field(vid, x, u, thrust, wind, p, c, k1)
        for j in range(ne):
            xs[j] = x[j] + (0.5 * h) * k1[j]
        if rotor:
            _mix_into(mix, xs[n:], u)
        _field(vid, xs, u, thrust, wind, p, c, k2)
        for j in range(ne):
            xs[j] = x[j] + (0.5 * h) * k2[j]
        if rotor:
            _mix_into(mix, xs[n:], u)
        _field(vid, xs, u, thrust, wind, p, c, k3)
        for j in range(ne):
            xs[j] = x[j] + h * k3[j]
        if rotor:
            _mix_into(mix, xs[n:], u)
        _field(vid, xs, u, thrust, wind, p, c, k4)
        for j in range(ne):
            x[j] = x[j] + (h / 6.0) * (k1[j] + 2.0 * (k2[j] + k3[j]) + k4[j])
    if rotor:
        _mix_into(mix, x[n:], u)


@numba.njit(cache=True, inline="always")
def _finish_one(vid, x, ref, c, rng, i, bias, obsbox, xbox, obs):  # noqa: ANN001, ANN202
    """Observation (biased, noisy, clipped), reward and termination of one member."""
    n = xbox.shape[1]
    _observe(vid, x, ref, obs)
    nobs = obs.shape[0]
    if c[_OBS_ROTORS] != 0.0:
        k = x.shape[0] - n
        for j in range(k):
            obs[nobs - k + j] = x[n + j]
    out = False
    for j in range(n):
        if not (xbox[0, j] <= x[j] <= xbox[1, j]):  # NaN fails too
            out = True
    cost = 0.0
    for j in range(nobs):
        cost += obsbox[2, j] * obs[j] * obs[j]
    reward = 0.0 if out else math.exp(-cost)
    noise = c[_NOISE]
    for j in range(nobs):
        v = obs[j]
        if not math.isfinite(v):  # only terminal states can have them
            v = 0.0 if math.isnan(v) else (1e308 if v > 0 else -1e308)
        v += bias[j]
        if noise > 0.0:
            v += noise * _next_normal(rng, i)
        obs[j] = min(max(v, obsbox[0, j]), obsbox[1, j])
    return reward, out


@numba.njit(cache=True, inline="always")
def _all_finite(A):  # noqa: ANN001, ANN202
    for v in A.ravel():
        if not math.isfinite(v):
            return False
    return True


@numba.njit(cache=True)
def _step(vid, X, A, refs, P, C, rng, gust, bias, mix, unmix, box, frac, obsbox,
          xbox, active):  # noqa: ANN001, ANN202  # fmt: skip
    """Steps every active member in place; returns (obs, reward, end, u, u_cmd, ok)."""
    b = X.shape[0]
    m, k = mix.shape
    n, nw = xbox.shape[1], gust.shape[1]
    obs = np.empty((b, obsbox.shape[1]))
    reward, end = np.zeros(b), np.zeros(b, dtype=np.bool_)
    u_app, u_cmd = np.zeros((b, m)), np.zeros((b, m))
    if not _all_finite(A):
        return obs, reward, end, u_app, u_cmd, False
    thrust, wind, raw = np.empty(k), np.empty(nw), np.empty(A.shape[1])
    scratch = np.empty((5, X.shape[1]))
    ga, gs = C[_GUST_A], C[_GUST_S]
    for i in range(b):
        p = P[i if P.shape[0] > 1 else 0]
        if active[i]:
            _command_one(A[i], p, C, mix, unmix, box, frac, thrust, u_cmd[i], raw)
            for j in range(nw):
                if gs > 0.0:
                    gust[i, j] = ga * gust[i, j] + gs * _next_normal(rng, i)
                wind[j] = C[_WIND0 + j] + gust[i, j]
            _integrate_one(vid, n, X[i], thrust, wind, p, C, mix, u_app[i], scratch)
        reward[i], end[i] = _finish_one(
            vid, X[i], refs[i], C, rng, i, bias[i], obsbox, xbox, obs[i]
        )
    return obs, reward, end, u_app, u_cmd, True


@numba.njit(cache=True)
def _finish(vid, X, refs, C, rng, bias, obsbox, xbox):  # noqa: ANN001, ANN202
    b = X.shape[0]
    obs = np.empty((b, obsbox.shape[1]))
    reward, end = np.zeros(b), np.zeros(b, dtype=np.bool_)
    for i in range(b):
        reward[i], end[i] = _finish_one(
            vid, X[i], refs[i], C, rng, i, bias[i], obsbox, xbox, obs[i]
        )
    return obs, reward, end


@numba.njit(cache=True)
def command_batch(A, P, C, mix, unmix, box, frac):  # noqa: ANN001, ANN201
    """Rotor commands -> (applied collective input, commanded input, ok) for a Python field."""
    b = A.shape[0]
    m, k = mix.shape
    thrust, raw = np.empty(k), np.empty(A.shape[1])
    u_app, u_cmd = np.zeros((b, m)), np.zeros((b, m))
    if not _all_finite(A):
        return u_app, u_cmd, False
    for i in range(b):
        _command_one(A[i], P[i if P.shape[0] > 1 else 0], C, mix, unmix, box, frac, thrust,
                     u_cmd[i], raw)  # fmt: skip
        _mix_into(mix, thrust, u_app[i])
    return u_app, u_cmd, True


PLANAR_ID, QUAD6DOF_ID = 0, 1
VEHICLE_IDS = {"planar": PLANAR_ID, "quad6dof": QUAD6DOF_ID}
"""Kernel ids of the vehicles."""


@numba.njit(cache=True, inline="always")
def _field(vid, x, u, thrust, wind, p, c, out):  # noqa: ANN001, ANN202
    if vid == PLANAR_ID:
        planar_point(x, u, thrust, wind, p, c, out)
    else:
        quad6dof_point(x, u, thrust, wind, p, c, out)


@numba.njit(cache=True, inline="always")
def _observe(vid, x, ref, out):  # noqa: ANN001, ANN202
    if vid == PLANAR_ID:
        planar_observe_point(x, ref, out)
    else:
        quad6dof_observe_point(x, ref, out)


@dataclass(frozen=True)
class Kernels:
    """The compiled entry points for one vehicle (and, for surrogates, one point rhs).

    Attributes:
        vid: Vehicle id (:data:`VEHICLE_IDS`), the first argument of ``step`` and ``finish``.
        step: ``(vid, X, A, refs, P, C, rng, gust, bias, mix, unmix, box, frac, obsbox,
            xbox, active) -> (obs, reward, end, u, u_cmd, ok)``.
        finish: ``(vid, X, refs, C, rng, bias, obsbox, xbox) -> (obs, reward, end)``.
        command: ``(A, P, C, mix, unmix, box, frac) -> (u, u_cmd, ok)``.
    """

    vid: int
    step: Callable[..., Any]
    finish: Callable[..., Any]
    command: Callable[..., Any] = command_batch


def vehicle_kernels(name: str) -> Kernels:
    """The kernels of a registered vehicle (``planar``, ``quad6dof``)."""
    return Kernels(VEHICLE_IDS[name], _step, _finish)


def _rebind(func: Any, **names: Any) -> Any:
    """A numba dispatcher's source compiled again with some global names bound elsewhere."""
    py = func.py_func
    glob = {**py.__globals__, **names}
    clone = types.FunctionType(py.__code__, glob, py.__name__, py.__defaults__, py.__closure__)
    return numba.njit(clone)


_POINT_CACHE: dict[Any, Kernels] = {}


def point_rhs_kernels(name: str, point: Any) -> Kernels:
    """Kernels stepping a compiled ``point(x, u, out)`` vector field instead of the vehicle's.

    The same kernel source with ``_field`` bound to the point rhs (no effects act on it);
    compiled once per point function and process (not cached on disk).
    """
    key = (name, id(point))
    if key not in _POINT_CACHE:

        @numba.njit
        def field(vid, x, u, thrust, wind, p, c, out):  # noqa: ANN001, ANN202
            point(x, u, out)

        integrate = _rebind(_integrate_one, _field=field)
        step = _rebind(_step, _integrate_one=integrate)
        _POINT_CACHE[key] = Kernels(VEHICLE_IDS[name], step, _finish)
    return _POINT_CACHE[key]


def new_seed(rng: np.random.Generator) -> np.uint64:
    """A generator state for the kernels' per-member random numbers, drawn from ``rng``."""
    return np.uint64(rng.integers(0, 2**63))
