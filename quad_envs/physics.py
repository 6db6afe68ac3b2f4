"""The one physics the environments step: rigid body, optional effects, RK4, observation.

The equations of motion live once, as elementwise functions in :mod:`quad_envs.dynamics`
(numpy evaluates them on arrays, numba compiles them for single states). Each vehicle
module compiles them, with the effects below, into its point functions (``point_field``,
``point_observe`` of its :class:`~quad_envs.vehicles.Vehicle` record). This module builds
one batched step kernel per vector field from them (:func:`vehicle_kernels`; a surrogate's
generated rhs: :func:`point_rhs_kernels`): the kernel source
(:mod:`quad_envs.kernel_template`) is written with the lines that bind the vehicle's
functions into the cache folder (:func:`cache_dir`) and imported, so numba's on-disk cache
applies and no vehicle switch exists in the kernel. The single env is the vector env's
kernel with a batch of one, so the two agree to the bit.

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
(splitmix64; normals by a 256-layer ziggurat, as numpy's) whose seed each episode draws
from the env's ``np_random``: reproducible per seed, the same in the single and the vector
env.
"""

from __future__ import annotations

import dataclasses
import hashlib
import importlib
import importlib.util
import math
import os
import sys
import tempfile
import types
import uuid
from collections.abc import Callable
from dataclasses import dataclass, fields
from pathlib import Path
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
        for name, example in (
            ("wind_mean", "[1.0, 0.0]"),
            ("rotor_max_fraction", "[1, 1, 1, 0.9]"),
        ):
            value = getattr(self, name)
            try:
                object.__setattr__(self, name, tuple(float(v) for v in value))
            except (TypeError, ValueError):
                raise ValueError(
                    f"effects.{name} takes one number per axis or rotor, e.g. {example}; "
                    f"got {value!r}"
                ) from None
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


# -- rotor dynamics around a field integrated in Python -------------------------------------


@dataclass(frozen=True)
class RotorLagField:
    """A rigid-body field ``rhs(x, u)`` with rotor dynamics, for :func:`rk4_step`.

    The state is extended by the rotor thrusts T (k, after the n rigid-body states) and the
    input is the rotors' commands T_cmd: dx/dt = rhs(x, M T) and dT/dt = (T_cmd - T) / tau,
    as the compiled kernels step it. A field whose inputs act through a first-order lag
    (an identified model's) is stepped so: the lag is linear and the same for every rotor,
    so lagging the rotor thrusts and mixing them equals lagging the mixed commands.

    Attributes:
        rhs: The rigid-body field, batched over leading axes.
        mix: The mixer M (inputs x rotors).
        n: Rigid-body states.
        tau: Rotor time constant [s] (a number, or one per row of the batch as (b, 1)).
    """

    rhs: Callable[[FloatArray, FloatArray], FloatArray]
    mix: FloatArray
    n: int
    tau: Any

    def __call__(self, x: FloatArray, thrust_cmd: FloatArray) -> FloatArray:
        """dx/dt of the extended state (..., n + k) under the rotor commands (..., k)."""
        rotors = x[..., self.n :]
        rigid = self.rhs(x[..., : self.n], rotors @ self.mix.T)
        return np.concatenate([rigid, (thrust_cmd - rotors) / self.tau], axis=-1)


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

(P_MASS, P_I1, P_I2, P_I3, P_GRAVITY, P_TAU, P_DRAG_LINEAR_XY, P_DRAG_LINEAR_Z,
 P_DRAG_QUADRATIC_XY, P_DRAG_QUADRATIC_Z, P_FMIN, P_FMAX, P_KT) = range(13)  # fmt: skip
"""Indices into the parameter vector, for the vehicles' point functions."""
_MASS, _TAU, _FMIN, _FMAX, _KT = P_MASS, P_TAU, P_FMIN, P_FMAX, P_KT
_INERTIA_ALIASES = {"I1": ("Jxx", "Ixx"), "I2": ("Jyy",), "I3": ("Jzz",)}


def _param_names(params: Any) -> tuple[str | None, ...]:
    """The attribute of a parameter set behind each entry of :data:`PARAM_FIELDS`."""
    names = []
    for name in PARAM_FIELDS:
        found = [a for a in _INERTIA_ALIASES.get(name, (name,)) if hasattr(params, a)]
        names.append(found[0] if found else None)
    return tuple(names)


_PARAM_NAMES: dict[type, tuple[str | None, ...]] = {}


def pack_params(params: Any) -> FloatArray:
    """The parameter vector (:data:`PARAM_FIELDS`) of one parameter set."""
    cls = type(params)
    names = _PARAM_NAMES.get(cls)
    if names is None:
        names = _PARAM_NAMES.setdefault(cls, _param_names(params))
    return np.array([0.0 if n is None else float(getattr(params, n)) for n in names])


# -- constants vector ----------------------------------------------------------------------

MODES = ("collective", "rotor_thrusts", "motor_speeds")
"""Action modes: collective thrust and moments, per-rotor thrusts [N], motor speeds [rad/s]."""

(_DT, _SUBSTEPS, _MODE, _NORMALIZE, _ROTOR, _DRAG, _OBS_ROTORS, _GUST_A, _GUST_S, _NOISE) = range(
    10
)
_WIND0 = 10
N_CONSTS = 13
C_ROTOR, C_DRAG = _ROTOR, _DRAG
"""Indices of the rotor-dynamics and drag switches in the constants vector."""


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


# -- random numbers (splitmix64 + a ziggurat), per member --------------------------------

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)


def _ziggurat_tables() -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Tables of the 256-layer ziggurat for N(0, 1) (Marsaglia and Tsang 2000, as numpy's).

    Layer i >= 1 is the box [0, x_i) x [f(x_i), f(x_{i-1})] under f(x) = exp(-x^2 / 2)
    (x_0 = 0, x_255 = r); layer 0 is [0, v / f(r)) x [0, f(r)], the base strip plus the
    tail beyond r. Every layer has the area v. Returns (k, w, f, r): a 52-bit magnitude m
    drawn in layer i gives x = m w_i, inside the curve for sure if m < k_i.
    """
    r = 3.6541528853610088  # x_255 for 256 layers
    density = lambda x: math.exp(-0.5 * x * x)  # noqa: E731
    v = r * density(r) + math.sqrt(math.pi / 2) * math.erfc(r / math.sqrt(2))
    scale = 2.0**52
    k, w, f = np.zeros(256, np.uint64), np.zeros(256), np.zeros(256)
    q = v / density(r)
    k[0], k[1] = int(r / q * scale), 0
    w[0], w[255] = q / scale, r / scale
    f[0], f[255] = 1.0, density(r)
    x_outer = r
    for i in range(254, 0, -1):
        x_inner = math.sqrt(-2.0 * math.log(v / x_outer + density(x_outer)))
        k[i + 1] = int(x_inner / x_outer * scale)
        f[i], w[i] = density(x_inner), x_inner / scale
        x_outer = x_inner
    return k, w, f, r


_ZIG_K, _ZIG_W, _ZIG_F, _ZIG_R = _ziggurat_tables()


@numba.njit(cache=True, inline="always")
def _mix64(z: Any) -> Any:
    """splitmix64's output function: 64 random bits from the counter value z."""
    z = (z ^ (z >> np.uint64(30))) * _MIX1
    z = (z ^ (z >> np.uint64(27))) * _MIX2
    return z ^ (z >> np.uint64(31))


@numba.njit(cache=True, inline="always")
def _uniform(bits: Any) -> float:
    """A uniform number in (0, 1) from 64 random bits (their top 53)."""
    top53 = np.int64(bits >> np.uint64(11))
    return (float(top53) + 0.5) * (1.0 / 9007199254740992.0)


@numba.njit(cache=True, inline="always")
def _zig_box(bits: Any) -> tuple[float, bool]:
    """The ziggurat's candidate from 64 bits, and whether it lies inside its layer's box.

    Bits 0-7 pick the layer, bit 8 the sign, bits 9-60 the magnitude (as numpy's ziggurat).
    """
    magnitude = (bits >> np.uint64(9)) & np.uint64(0xFFFFFFFFFFFFF)
    layer = int(bits & np.uint64(0xFF))
    x = float(np.int64(magnitude)) * _ZIG_W[layer]
    if bits & np.uint64(0x100):
        x = -x
    return x, magnitude < _ZIG_K[layer]


@numba.njit(cache=True, inline="always")
def _normal_rare(z: Any, bits: Any, x: float) -> tuple[float, Any]:
    """The ziggurat's rare branches (~1 % of draws): the tail, a wedge, or a new draw.

    Returns the normal and the counter after the draws it took.
    """
    while True:
        layer = int(bits & np.uint64(0xFF))
        if layer == 0:  # the tail beyond r (Marsaglia's exponential rejection)
            while True:
                z += _GOLDEN
                tail = -math.log(_uniform(_mix64(z))) / _ZIG_R
                z += _GOLDEN
                if -2.0 * math.log(_uniform(_mix64(z))) > tail * tail:
                    return (-(_ZIG_R + tail) if x < 0.0 else _ZIG_R + tail), z
        z += _GOLDEN
        height = _ZIG_F[layer] + _uniform(_mix64(z)) * (_ZIG_F[layer - 1] - _ZIG_F[layer])
        if height < math.exp(-0.5 * x * x):
            return x, z
        z += _GOLDEN
        bits = _mix64(z)
        x, fast = _zig_box(bits)
        if fast:
            return x, z


@numba.njit(cache=True, inline="always")
def _normal(z: Any) -> tuple[float, Any]:
    """A standard normal from counter z: one 64-bit draw and a table look-up ~99 % of the time.

    Bits 0-7 pick the layer, bit 8 the sign, bits 9-60 the magnitude (as numpy's ziggurat).
    Returns the normal and the advanced counter.
    """
    z += _GOLDEN
    bits = _mix64(z)
    x, fast = _zig_box(bits)
    if fast:
        return x, z
    return _normal_rare(z, bits, x)


@numba.njit(cache=True, inline="always")
def _add_noise(rng: Any, i: int, scale: float, values: Any) -> None:
    """Adds ``scale`` times independent standard normals to every entry of ``values``.

    Member i's counter ``rng[i]`` is read once and written back once (kept in a register
    in between rather than stored per draw).
    """
    z = rng[i]
    for j in range(values.shape[0]):
        x, z = _normal(z)
        values[j] += scale * x
    rng[i] = z


# -- shared pieces of the kernels (inlined into them) ------------------------------------

KERNEL_JIT: dict[str, Any] = {"cache": True, "_nrt": False, "error_model": "numpy"}
"""numba options of the kernels' entry points: cached on disk, and without numba's reference
counting, which costs two atomic operations per array view taken per member (about ten
times the arithmetic of a planar RK4 step); the kernels therefore allocate nothing."""


@numba.njit(cache=True, inline="always")
def _command_one(a, p, c, mix, unmix, box, frac, thrust, u_cmd, raw, m, k):  # noqa: ANN001, ANN202
    """Action row -> limited rotor thrusts (written) and the commanded collective input.

    ``m, k`` are the mixer's shape (inputs, rotors): constants in the generated kernels.
    """
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
        _mix_into(mix, thrust, u_cmd, m, k)
    for i in range(k):
        thrust[i] = min(max(thrust[i], p[_FMIN]), p[_FMAX] * frac[i])


@numba.njit(cache=True, inline="always")
def _mix_into(mix, thrust, u, m, k):  # noqa: ANN001, ANN202
    """The collective input u = mix @ thrust (``mix`` of shape (m, k))."""
    for j in range(m):
        s = 0.0
        for i in range(k):
            s += mix[j, i] * thrust[i]
        u[j] = s


@numba.njit(cache=True, inline="always")
def _all_finite(A):  # noqa: ANN001, ANN202
    for i in range(A.shape[0]):
        for j in range(A.shape[1]):
            if not math.isfinite(A[i, j]):
                return False
    return True


@numba.njit(**KERNEL_JIT)
def command_batch(A, P, C, mix, unmix, box, frac, u_app, u_cmd, work):  # noqa: ANN001, ANN201
    """Rotor commands -> applied and commanded collective inputs (written).

    For a vector field integrated in Python. As in the step kernel, ``work[5, :k]`` holds
    the last member's limited rotor commands on return. Returns False if an action is not
    finite.
    """
    b = A.shape[0]
    m, k = mix.shape
    if not _all_finite(A):
        return False
    thrust, raw = work[5, :k], work[7, : A.shape[1]]
    for i in range(b):
        p = P[0] if P.shape[0] == 1 else P[i]
        _command_one(A[i], p, C, mix, unmix, box, frac, thrust, u_cmd[i], raw, m, k)
        _mix_into(mix, thrust, u_app[i], m, k)
    return True


@numba.njit(**KERNEL_JIT)
def rotor_command_batch(A, P, C, mix, unmix, box, frac, thrust, work):  # noqa: ANN001, ANN201
    """Rotor commands -> the thrust each rotor is commanded, after its limits (written).

    Row i of ``thrust`` (b, k) is what the rotors of member i follow over the step: with
    rotor dynamics the thrust states' targets, held over the step. Returns False if an
    action is not finite.
    """
    m, k = mix.shape
    if not _all_finite(A):
        return False
    raw, u_cmd = work[7, : A.shape[1]], work[6, :m]
    for i in range(A.shape[0]):
        p = P[0] if P.shape[0] == 1 else P[i]
        _command_one(A[i], p, C, mix, unmix, box, frac, thrust[i], u_cmd, raw, m, k)
    return True


@numba.njit(cache=True)
def episode_starts(  # noqa: ANN201
    X0, n, U, n_offset, offset_scale, spread, P0, factor_of_entry, more_factors,  # noqa: ANN001
    unmix0, frac, N, gust_std, bias_std, P, F, gust, bias,  # noqa: ANN001
):  # fmt: skip
    """The starts of drawn episodes from their draws, in place (resets and autoresets).

    Row j of ``X0`` (r, n_ext) holds a rest state in its first n columns. The first
    ``n_offset`` (0 or n) of them get the offset (2 U - 1) ``offset_scale`` (U's first
    columns). With ``spread`` > 0 the factors F = (1 - spread) + 2 spread U (U's other
    columns) scale the nominal parameters ``P0``: P[j, e] = P0[e] F[j, factor_of_entry[e]]
    (an index past F's columns: unscaled), times F[j, k] for each (e, k) row of
    ``more_factors``; else ``P`` is the nominal (1, len) row, read only. Rotor states (the
    columns after n) are the thrusts ``unmix0`` m g that give the hover input (m g is
    ``params.hover_thrust``), limited to [T_min, T_max ``frac``]. ``gust`` and ``bias``
    are ``gust_std`` and ``bias_std`` times N's first gust columns and the rest (zero if
    the std is zero).
    """
    r, n_ext = X0.shape
    n_gust = gust.shape[1] if gust_std > 0.0 else 0
    for j in range(r):
        for q in range(n_offset):
            X0[j, q] += (2.0 * U[j, q] - 1.0) * offset_scale[q]
        row = 0
        if spread > 0.0:
            row = j
            nf = F.shape[1]
            for f in range(nf):
                F[j, f] = (1.0 - spread) + (2.0 * spread) * U[j, n_offset + f]
            for e in range(P0.shape[0]):
                k = factor_of_entry[e]
                P[j, e] = P0[e] * F[j, k] if k < nf else P0[e]
            for m in range(more_factors.shape[0]):
                P[j, more_factors[m, 0]] *= F[j, more_factors[m, 1]]
        hover = P[row, _MASS] * P[row, P_GRAVITY]
        for i in range(n_ext - n):
            thrust = unmix0[i] * hover
            X0[j, n + i] = min(max(thrust, P[row, _FMIN]), P[row, _FMAX] * frac[i])
        for q in range(gust.shape[1]):
            gust[j, q] = gust_std * N[j, q] if gust_std > 0.0 else 0.0
        for q in range(bias.shape[1]):
            bias[j, q] = bias_std * N[j, n_gust + q] if bias_std > 0.0 else 0.0
    return True


# -- kernels built per vector field ------------------------------------------------------


@dataclass(frozen=True)
class Kernels:
    """The compiled entry points for one vector field and observation.

    Attributes:
        step: ``(X, A, refs, P, C, rng, gust, bias, mix, unmix, box, frac, obsbox, xbox,
            active, obs, reward, end, u, u_cmd, work) -> ok`` (outputs written in place).
        finish: ``(X, refs, C, rng, bias, obsbox, xbox, obs, reward, end) -> True``.
        command: ``(A, P, C, mix, unmix, box, frac, u, u_cmd, work) -> ok``.
        module: The generated module (its file lies in the kernel cache folder).
    """

    step: Callable[..., Any]
    finish: Callable[..., Any]
    command: Callable[..., Any]
    module: types.ModuleType


def cache_dir() -> Path:
    """Folder of the generated kernel modules and numba's cache of them.

    ``$QUAD_SINDY_CACHE`` if set, else ``$XDG_CACHE_HOME/quad-sindy`` (``~/.cache/quad-sindy``);
    where that cannot be written, ``quad-sindy-<uid>`` in the temporary directory.
    """
    env = os.environ.get("QUAD_SINDY_CACHE")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "quad-sindy"


_TEMPLATE = Path(__file__).with_name("kernel_template.py")
_DEPENDS = (Path(__file__), Path(dynamics.__file__), _TEMPLATE)
_BUILT: dict[str, Kernels] = {}


def _ref(func: Any) -> tuple[str, str]:
    """(module, name) of a module-level numba function, checked to be importable."""
    if func is None:
        raise ValueError("the vehicle record has no point_field/point_observe to build kernels")
    py = getattr(func, "py_func", func)
    module, name = py.__module__, py.__qualname__
    if "." in name or getattr(importlib.import_module(module), name, None) is not func:
        raise ValueError(f"{name} must be a module-level function of {module} to build kernels")
    return module, name


def _write_module(stem: str, text: str) -> Path:
    """Writes ``text`` as ``stem.py`` in the cache folder (atomically, umask permissions)."""
    folder = cache_dir()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        probe = folder / f".probe.{os.getpid()}"
        probe.touch()
        probe.unlink()
    except OSError:  # read-only home: a private folder under the temporary directory
        folder = Path(tempfile.gettempdir()) / f"quad-sindy-{os.getuid()}"
        folder.mkdir(mode=0o700, parents=True, exist_ok=True)
    path = folder / f"{stem}.py"
    if path.exists() and path.read_text() == text:
        return path
    tmp = folder / f".{stem}.{os.getpid()}.{uuid.uuid4().hex}.tmp"
    tmp.write_text(text)
    os.replace(tmp, path)
    return path


def build_kernels(footer: str, depends: tuple[Any, ...] = (), label: str = "kernels") -> Kernels:
    """Kernels whose ``_field`` and ``_observe`` are bound by the source ``footer``.

    The module (the kernel template, then ``footer``) is written to :func:`cache_dir`, named
    by a hash of its text and of the sources it inlines (this module, the dynamics, the
    modules in ``depends``), and imported, so numba's ``cache=True`` compiles it once per
    machine rather than once per process, and a changed source gets a fresh module.
    """
    text = (
        f"# Generated by quad_envs.physics.build_kernels ({label}); do not edit.\n"
        + _TEMPLATE.read_text()
        + "\n\n# -- the vector field and observation of these kernels --\n"
        + footer
    )
    digest = hashlib.sha256(text.encode())
    for source in (*_DEPENDS, *depends):
        digest.update(Path(source).read_bytes())
    stem = f"quad_sindy_{label}_{digest.hexdigest()[:16]}"
    if stem in _BUILT:
        return _BUILT[stem]
    module = sys.modules.get(stem)
    if module is None:
        path = _write_module(stem, text)
        spec = importlib.util.spec_from_file_location(stem, path)
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        sys.modules[stem] = module
        try:
            spec.loader.exec_module(module)
        except BaseException:
            del sys.modules[stem]
            raise
    kernels = Kernels(module.step, module.finish, command_batch, module)
    _BUILT[stem] = kernels
    return kernels


def _sizes(vehicle: Any) -> str:
    """The footer lines binding the kernel template's size constants for a vehicle."""
    return (
        f"_N_STATE = {vehicle.n_states}\n_N_ROTOR = {vehicle.n_rotors}\n"
        f"_N_INPUT = {vehicle.n_inputs}\n_N_OBS = {len(vehicle.obs_names)}\n"
    )


def vehicle_kernels(vehicle: Any) -> Kernels:
    """The kernels of a vehicle record (its ``point_field`` and ``point_observe``)."""
    field_mod, field_name = _ref(vehicle.point_field)
    obs_mod, obs_name = _ref(vehicle.point_observe)
    footer = (
        f"from {field_mod} import {field_name} as _field  # noqa: E402\n"
        f"from {obs_mod} import {obs_name} as _observe  # noqa: E402\n"
    ) + _sizes(vehicle)
    depends = {sys.modules[field_mod].__file__, sys.modules[obs_mod].__file__}
    return build_kernels(footer, tuple(sorted(depends)), vehicle.name)


def point_rhs_kernels(vehicle: Any, point_source: str) -> Kernels:
    """Kernels stepping a generated ``point(X, U, out)`` vector field (a surrogate's).

    ``point_source`` is the Python source of ``point`` (scalar code using ``math``) over the
    vehicle's rigid-body state. Drag and wind do not act on it (rotor limits and sensor
    effects do). With rotor dynamics the rotor thrusts are states as in the vehicles' fields
    (dT/dt = (T_cmd - T) / tau) and ``point`` sees their mix as its input: a model whose
    inputs act through a first-order lag is stepped with its actuators.
    """
    obs_mod, obs_name = _ref(vehicle.point_observe)
    footer = (
        '\n@numba.njit(cache=True, inline="always")\n'
        + point_source
        + '\n\n@numba.njit(cache=True, inline="always")\n'
        "def _field(x, u, thrust, wind, p, c, out):\n"
        "    point(x, u, out)\n"
        "    if c[_ROTOR] != 0.0:\n"
        "        for j in range(_N_ROTOR):\n"
        "            out[_N_STATE + j] = (thrust[j] - x[_N_STATE + j]) / p[_P_TAU]\n\n\n"
        "from quad_envs.physics import P_TAU as _P_TAU  # noqa: E402\n"
        f"from {obs_mod} import {obs_name} as _observe  # noqa: E402\n"
    ) + _sizes(vehicle)
    kernels = build_kernels(footer, (sys.modules[obs_mod].__file__,), f"{vehicle.name}_model")
    # The observation kernel does not involve the field: share the vehicle's (compiled once).
    return dataclasses.replace(kernels, finish=vehicle_kernels(vehicle).finish)


def warm_up(kernels: Kernels, n_ext: int, n_actions: int, n_obs: int, n_wind: int,
            mix: FloatArray) -> None:  # fmt: skip
    """Compiles (or loads from numba's cache) a kernel set's entry points, stepping nobody.

    Raises whatever numba raises if the kernels do not compile.
    """
    m, k = np.shape(mix)
    f = np.float64
    X, A, refs = np.zeros((0, n_ext)), np.zeros((0, n_actions)), np.zeros((0, 16))
    P, C = np.zeros((1, len(PARAM_FIELDS))), np.zeros(N_CONSTS)
    rng, gust, bias = np.zeros(0, np.uint64), np.zeros((0, n_wind)), np.zeros((0, n_obs))
    box, frac, obsbox, xbox = np.zeros((2, n_actions)), np.ones(k), np.zeros((3, n_obs)), None
    xbox = np.zeros((2, n_ext))
    obs, reward, end = np.zeros((0, n_obs)), np.zeros(0, f), np.zeros(0, bool)
    u, u_cmd, work = np.zeros((0, m)), np.zeros((0, m)), np.zeros((8, 16))
    mix = np.ascontiguousarray(mix, dtype=f)
    kernels.step(X, A, refs, P, C, rng, gust, bias, mix, mix, box, frac, obsbox, xbox,
                 np.zeros(0, bool), obs, reward, end, u, u_cmd, work)  # fmt: skip
    kernels.finish(X, refs, C, rng, bias, obsbox, xbox, obs, reward, end)
