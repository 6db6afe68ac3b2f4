"""SINDy-with-control fitting: regression formulations, pysindy optimizers, identifiability.

Formulations (``derivative=``), each giving a linear problem Y ~ Theta Xi^T:

``forward``
    The paper's: Y_k = (x_{k+1} - x_k) / dt_k against Theta(x_k, u_k). On zero-order-hold
    data this is the mean slope over the step, biased by O(dt).
``rk4`` (default)
    Integrator-consistent: the same Y_k against the RK4 average of Theta over the stages
    s1..s4 of the step from x_k with u_k held, the stages computed with the current
    estimate; a few fixed-point passes. Data made by RK4 at the sample step are matched
    exactly (round-off); finer or exact integration leaves an O(dt^4) error. Each row uses
    its own step dt_k, so jittery time stamps need no resampling.
``rk4`` with ``window=w > 1``
    The integral form of the same: (x_{k+w} - x_k) / (t_{k+w} - t_k) against the
    step-weighted mean of the stage averages over the window. Averaging w steps damps
    measurement noise (weak-form-like).
``central`` / ``smoothed`` / a pysindy differentiation object
    pysindy's FiniteDifference (order 2) / SmoothedFiniteDifference (or the object given),
    called through its public ``__call__`` at each sample, against Theta(x_k, u_k).

The regression is carried by its normal equations (:class:`Gram`): Theta^T Theta, Theta^T Y
and Y^T Y summed over chunks of rows, so memory does not grow with the data, folds and
bootstrap bags are sums of per-chunk Grams, and a pysindy optimizer sees a p x p problem
with the same least-squares objective (``A = S^1/2 V^T`` from ``Theta^T Theta = V S V^T``).
Columns of Theta are scaled to unit RMS and each target to unit RMS before the optimizer, so
one threshold ``lam`` means the same for every term. After selection the support is refitted
by least squares (debiasing).

Before any fit, :func:`check_identifiable` refuses data on which the library cannot be
identified (too few rows, a constant input, exactly collinear or all-zero columns, an input
that follows the states to its logging resolution) with a one-line ValueError that names the
terms and the data that would fix it.
"""

from __future__ import annotations

import collections
import dataclasses
import functools
import warnings
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np
import pysindy as ps
from pysindy.differentiation import BaseDifferentiation
from pysindy.optimizers import BaseOptimizer
from sklearn.base import clone
from threadpoolctl import threadpool_limits

from identification.data import (
    Trajectory,
    as_trajectories,
    check_glitches,
    data_ranges,
    drift_meta,
    input_drift_of,
    input_lag_of,
)
from identification.features import compile_features, compile_rhs, parse_term, term_name
from identification.model import IdentifiedModel
from identification.stepwise import simpler_twins, stepwise_coefficients

DERIVATIVES = ("rk4", "forward", "central", "smoothed")
OPTIMIZERS = ("sr3", "stlsq", "ensemble", "stepwise")
DEFAULT_LAMBDAS = tuple(np.round(np.concatenate([[0.0], np.logspace(-6, 0, 25)]), 12))
"""Default scan grid for our scaled threshold (0 and 25 log-spaced values from 1e-6 to 1)."""

SINGULAR_TOL = 1e-12
"""Ratio of singular values below which a column of the normalised triangular factor is read as
given by the earlier ones, to name an exact relation (its square root bounds the diagonal)."""

ROUNDOFF = 10.0
"""Columns are exactly collinear on the data where the column-normalised library's smallest
singular value is below ``ROUNDOFF`` x float64 epsilon x sqrt(terms): the round-off in
evaluating unit columns, each entry to a few epsilon, bounds the smallest singular value of
an exactly singular library by about that (the Frobenius norm of the error). Exact relations
(a column that copies another, a yaw held still) lie at 1e-16 or below. A fixed ratio of
1e-12 refused clean 6-DOF flights of 5 s at 0.2 rad tilt (519 terms, ratio 4e-13) that give
the exact model (a held-out trial); a bar of 100 eps sqrt(terms) refused a user's 627-term
library at 2e-13 on four clean flights (5e-9 on a flight held out: a near relation, not an
exact one), and four clean 6-DOF flights of 300 rows (1.5e-13) that give the exact model."""

CHUNK_ELEMENTS = 4_000_000
"""Rows x features per chunk when building the normal equations (about 32 MB a stage)."""


def serial_blas(func: Callable) -> Callable:
    """Runs ``func`` with one BLAS thread.

    The factors here are small (p up to a few hundred columns, chunks of rows). On a busy
    machine a threaded BLAS spins its threads on them: a 1000 x 30 QR took 0.3 s with two
    OpenBLAS threads and 0.4 ms with one.
    """

    @functools.wraps(func)
    def wrapper(*args: object, **kwargs: object) -> object:
        with threadpool_limits(limits=1, user_api="blas"):
            return func(*args, **kwargs)

    return wrapper


@dataclass(frozen=True)
class FitConfig:
    """How to fit (frozen: change it with ``dataclasses.replace``).

    Attributes:
        derivative: One of :data:`DERIVATIVES`, or a pysindy differentiation object
            (e.g. ``ps.SmoothedFiniteDifference()``), called at each sample.
        optimizer: One of :data:`OPTIMIZERS`, or a pysindy optimizer object. A string uses
            ``lam`` as its scaled threshold; an object is cloned and used with its own
            settings (its ``threshold`` is set to ``lam`` when ``set_lam`` is true).
            ``stepwise`` is our forward-backward greedy selection on the QR factor
            (:mod:`identification.stepwise`), where ``lam`` is the fraction of a target's RMS
            a term must explain beyond the terms already chosen.
        lam: Scaled sparsity threshold (0: dense least squares).
        window: Steps per row of the integral form (``rk4`` and ``forward``).
        iterations: Fixed-point passes of the ``rk4`` formulation.
        scale: Scale columns and targets to unit RMS.
        n_models: Ensemble size (``ensemble``).
        seed: Ensemble bagging seed.
        set_lam: Whether ``lam`` overrides an optimizer object's ``threshold``.
        full_path: ``stepwise`` only: run each path to its longest support instead of
            ending it after a few entries in a row that fail the F-test (noise). The pilot
            that places the RK4 stage points of the selection uses the full path.
        backward: ``stepwise`` only: where backward elimination from the columns the path
            entered gives a significantly better support than the forward path
            (:func:`identification.stepwise.backward_path`), take it. On for a fit; the
            candidates of the automatic selection are scored without it, and the chosen
            one is refitted with it.
    """

    derivative: str | BaseDifferentiation = "rk4"
    optimizer: str | BaseOptimizer = "sr3"
    lam: float = 1e-3
    window: int = 1
    iterations: int = 4
    scale: bool = True
    n_models: int = 20
    seed: int = 0
    set_lam: bool = False
    full_path: bool = False
    backward: bool = True

    def __post_init__(self) -> None:
        if isinstance(self.derivative, str) and self.derivative not in DERIVATIVES:
            raise ValueError(f"unknown derivative {self.derivative!r}; valid: {DERIVATIVES}")
        if not isinstance(self.derivative, str | BaseDifferentiation):
            raise ValueError(
                f"derivative must be a name or a pysindy object, not {self.derivative!r}"
            )
        if isinstance(self.optimizer, str) and self.optimizer not in OPTIMIZERS:
            raise ValueError(f"unknown optimizer {self.optimizer!r}; valid: {OPTIMIZERS}")
        if not isinstance(self.optimizer, str | BaseOptimizer):
            raise ValueError(
                f"optimizer must be a name or a pysindy object, not {self.optimizer!r}"
            )
        if not np.isfinite(self.lam) or self.lam < 0:
            raise ValueError(f"lambda must be a non-negative number, got {self.lam!r}")
        if self.window < 1:
            raise ValueError(f"window must be >= 1, got {self.window}")

    @property
    def label(self) -> dict[str, object]:
        """JSON-safe description of the settings."""

        def name(obj: object) -> str:
            return obj if isinstance(obj, str) else type(obj).__name__

        return {
            "method": name(self.derivative), "optimizer": name(self.optimizer),
            "lambda": self.lam, "window": self.window,
        }  # fmt: skip


# -- least-squares accumulator ---------------------------------------------------------
def _augmented(theta: np.ndarray, y: np.ndarray) -> np.ndarray:
    """[Theta | Y], column-major as LAPACK works.

    numpy copies other layouts first (7366 x 555 rows: 0.13 s against 0.16 s).
    """
    rows = np.empty((theta.shape[0], theta.shape[1] + y.shape[1]), order="F")
    rows[:, : theta.shape[1]] = theta
    rows[:, theta.shape[1] :] = y
    return rows


@dataclass
class Gram:
    """A regression Y ~ Theta Xi^T reduced to the triangular factor of [Theta Y].

    ``r_aug`` is the R of a QR factorisation of the stacked rows [Theta, Y]: its top-left
    p x p block R has R^T R = Theta^T Theta, its top-right block z = Q^T Y, and column norms
    equal those of Theta and Y. Least squares on (R, z) has the same objective as on the rows
    up to a constant, with the conditioning of Theta (not squared as in Theta^T Theta).
    Factors of disjoint row sets combine by stacking and re-factorising (folds, bags).

    Attributes:
        r_aug: Upper-triangular factor, shape (p + n, p + n) (fewer rows if fewer data rows).
        p: Number of features.
        rows: Number of data rows summed.
    """

    r_aug: np.ndarray
    p: int
    rows: int

    @classmethod
    def zeros(cls, p: int, n: int) -> Gram:
        """The empty sum."""
        return cls(np.zeros((0, p + n)), p, 0)

    @classmethod
    def from_rows(cls, theta: np.ndarray, y: np.ndarray) -> Gram:
        """Factor of explicit rows."""
        return cls.from_augmented(_augmented(theta, y), theta.shape[1])

    @classmethod
    def from_augmented(cls, rows: np.ndarray, p: int) -> Gram:
        """Factor of explicit rows [Theta | Y] (Theta's p columns first)."""
        return cls(np.linalg.qr(rows, mode="r"), p, rows.shape[0])

    @classmethod
    def stack(cls, parts: Sequence[Gram], weights: Sequence[float] | None = None) -> Gram:
        """The factor of the union of the parts' rows (each row set weighted if given)."""
        if weights is None:
            weights = [1.0] * len(parts)
        blocks = [np.sqrt(w) * g.r_aug for g, w in zip(parts, weights, strict=True) if w > 0]
        rows = int(round(sum(g.rows * w for g, w in zip(parts, weights, strict=True))))
        stacked = np.vstack(blocks) if blocks else parts[0].r_aug[:0]
        return cls(np.linalg.qr(stacked, mode="r") if stacked.shape[0] else stacked,
                   parts[0].p, rows)  # fmt: skip

    def __add__(self, other: Gram) -> Gram:
        return Gram.stack([self, other])

    @property
    def r(self) -> np.ndarray:
        """R with R^T R = Theta^T Theta (rows padded to p)."""
        return self._padded()[:, : self.p]

    @property
    def z(self) -> np.ndarray:
        """Q^T Y, shape (p, n)."""
        return self._padded()[:, self.p :]

    def _padded(self) -> np.ndarray:
        width = self.r_aug.shape[1]
        out = np.zeros((self.p, width))
        k = min(self.p, self.r_aug.shape[0])
        out[:k] = self.r_aug[:k]
        return out

    @property
    def col_norms(self) -> np.ndarray:
        """Euclidean norms of the columns of Theta."""
        return np.linalg.norm(self.r_aug[:, : self.p], axis=0)

    @property
    def y_norms(self) -> np.ndarray:
        """Euclidean norms of the columns of Y."""
        return np.linalg.norm(self.r_aug[:, self.p :], axis=0)


def _window_mean(rows: np.ndarray, weights: np.ndarray, w: int) -> np.ndarray:
    """Weighted means of w consecutive rows (all overlapping windows).

    Consumes ``rows`` (weighted and summed in place: the chunks' arrays are large), so a
    chunk holds two such arrays here, not four.
    """
    if w == 1:
        return rows
    rows *= weights[:, None]
    c = np.cumsum(rows, axis=0, out=rows)  # c[i] = sum of rows 0..i
    out = np.empty((c.shape[0] - w + 1, c.shape[1]), order="F")  # column-major as the rows
    out[0] = c[w - 1]
    np.subtract(c[w:], c[:-w], out=out[1:])
    cw = np.concatenate([[0.0], np.cumsum(weights)])
    out /= (cw[w:] - cw[:-w])[:, None]
    return out


Stages = tuple[np.ndarray, np.ndarray, np.ndarray]
"""Inputs at the start, middle and end of each step (:meth:`Trajectory.stage_inputs`)."""


def _rk4_stage_theta(
    theta: Callable, rhs: Callable, x: np.ndarray, u: Stages, h: np.ndarray
) -> np.ndarray:
    """RK4 average of Theta over the stages of each step (step h per row)."""
    h = h[:, None]
    u0, um, u1 = u
    k1 = rhs(x, u0)
    s2 = x + 0.5 * h * k1
    k2 = rhs(s2, um)
    s3 = x + 0.5 * h * k2
    k3 = rhs(s3, um)
    s4 = x + h * k3
    out = theta(x, u0)  # summed in place: the (rows, features) arrays are large
    for stage in (s2, s3):
        mid = theta(stage, um)
        mid *= 2.0
        out += mid
        del mid  # two such arrays at a time, not three
    out += theta(s4, u1)
    out /= 6.0
    return out


def rk4_steps(
    rhs: Callable, x: np.ndarray, u: Stages, h: np.ndarray, substeps: int = 1
) -> np.ndarray:
    """One RK4 step of each row (step h per row), in ``substeps`` equal parts.

    Held inputs (the same array three times) stay constant; otherwise the input over the
    step is the parabola through its start, middle and end values.
    """
    u0, um, u1 = u
    held = um is u0 and u1 is u0
    h = h[:, None] / substeps

    def at(tau: float) -> np.ndarray:
        if held:
            return u0
        return u0 + tau * (4 * um - 3 * u0 - u1) + tau**2 * (2 * u0 - 4 * um + 2 * u1)

    for i in range(substeps):
        if substeps == 1:  # the stage inputs themselves, as in the fit's rows
            a, m, b = u0, um, u1
        else:
            a, m, b = at(i / substeps), at((i + 0.5) / substeps), at((i + 1) / substeps)
        k1 = rhs(x, a)
        k2 = rhs(x + 0.5 * h * k1, m)
        k3 = rhs(x + 0.5 * h * k2, m)
        k4 = rhs(x + h * k3, b)
        x = x + h / 6.0 * (k1 + 2.0 * (k2 + k3) + k4)
    return x


def predict_missing(tr: Trajectory, rhs: Callable) -> np.ndarray:
    """The states of ``tr`` with its missing rows predicted by RK4 steps of ``rhs``.

    Each missing row is one RK4 step (the logged inputs, its own step) from the row
    before it, so a run of missing rows is predicted from the last observed one. With the
    true coefficients this reproduces data made by RK4 exactly: the fit's fixed point is
    unchanged by the rows the logger lost.
    """
    if tr.missing is None:
        return tr.x
    x, miss = tr.x.copy(), tr.missing
    # position of each missing row in its run (1 for the first): predicted in that order
    run = np.zeros(miss.size, dtype=int)
    for k in np.flatnonzero(miss):
        run[k] = run[k - 1] + 1 if k > 0 else 1
    h = np.diff(tr.t)
    for depth in range(1, int(run.max()) + 1):
        k = np.flatnonzero((run == depth) & (np.arange(miss.size) > 0))
        x[k] = rk4_steps(rhs, x[k - 1], tr.stage_inputs(k - 1), h[k - 1])
    return x


def _observed_rows(
    keep: np.ndarray, theta: np.ndarray, y: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The rows whose targets come from observed states (all of them on a complete log)."""
    return (theta, y) if keep.all() else (theta[keep], y[keep])


def _differentiator(derivative: str | BaseDifferentiation) -> BaseDifferentiation:
    if isinstance(derivative, BaseDifferentiation):
        return derivative
    if derivative == "central":
        return ps.FiniteDifference(order=2)
    return ps.SmoothedFiniteDifference()


def iter_rows(
    trajs: Sequence[Trajectory],
    feature_names: Sequence[str],
    derivative: str | BaseDifferentiation,
    window: int = 1,
    xi: np.ndarray | None = None,
    chunk_rows: int | None = None,
) -> Iterator[tuple[int, np.ndarray, np.ndarray]]:
    """Yields (trajectory index, Theta rows, Y rows) chunk by chunk.

    Args:
        trajs: Data.
        feature_names: Library.
        derivative: A formulation name or a pysindy differentiation object.
        window: Integral window (``rk4``/``forward``).
        xi: Current coefficients for the ``rk4`` stage points (required for ``rk4``).
        chunk_rows: Rows per chunk (default: about :data:`CHUNK_ELEMENTS` / features).

    Yields:
        Trajectory index, Theta (rows, p) and Y (rows, n) of one chunk.
    """
    for index, chunk in _row_chunks(trajs, feature_names, derivative, window, xi, chunk_rows):
        yield index, *chunk()


def _row_chunks(
    trajs: Sequence[Trajectory],
    feature_names: Sequence[str],
    derivative: str | BaseDifferentiation,
    window: int = 1,
    xi: np.ndarray | None = None,
    chunk_rows: int | None = None,
) -> Iterator[tuple[int, Callable[[], tuple[np.ndarray, np.ndarray]]]]:
    """The chunks of :func:`iter_rows` as (trajectory index, function making its rows).

    The functions are independent of each other (threads may run them in any order).
    """
    names = (trajs[0].state_names, trajs[0].input_names)
    theta = compile_features(feature_names, *names)
    rhs = compile_rhs(feature_names, xi, *names) if xi is not None else None
    if derivative == "rk4" and rhs is None:
        raise ValueError("the rk4 formulation needs current coefficients (xi)")
    step = chunk_rows or max(500, CHUNK_ELEMENTS // max(len(feature_names), 1))
    for index, tr in enumerate(trajs):
        seen = tr.observed  # rows with observed states: the only fit targets
        if not isinstance(derivative, str) or derivative in ("central", "smoothed"):
            dx = np.asarray(_differentiator(derivative)(tr.x, tr.t))
            for s in range(0, len(tr), step):
                yield index, functools.partial(_derivative_chunk, theta, tr, seen, dx, s, step)
            continue
        if len(tr) <= window:
            raise ValueError(f"a trajectory of {len(tr)} samples is too short for window {window}")
        n_rows = len(tr) - window
        xs = predict_missing(tr, rhs) if rhs is not None else tr.x
        rho = float(tr.meta.get(AR1, 0.0))
        for s in range(0, n_rows, step):
            stop = min(s + step, n_rows)  # window rows s..stop-1 use samples s..stop-1+window
            yield index, functools.partial(_integral_chunk, theta, rhs, derivative, tr, seen,
                                           xs, s, stop, window, rho)  # fmt: skip


def _derivative_chunk(
    theta: Callable, tr: Trajectory, seen: np.ndarray, dx: np.ndarray, s: int, step: int
) -> tuple[np.ndarray, np.ndarray]:
    """Rows s..s+step-1 against estimated derivatives."""
    rows = theta(tr.x[s : s + step], tr.u[s : s + step])
    return _observed_rows(seen[s : s + step], rows, dx[s : s + step])


def _integral_chunk(
    theta: Callable,
    rhs: Callable | None,
    derivative: str,
    tr: Trajectory,
    seen: np.ndarray,
    xs: np.ndarray,
    s: int,
    stop: int,
    window: int,
    rho: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Window rows s..stop-1 of the integral formulation (samples s..stop-1+window).

    With ``rho`` the rows are prewhitened (:data:`AR1`): row r becomes row r - rho row r-1,
    and the first row of the trajectory sqrt(1 - rho^2) times itself, so every step keeps
    its row.
    """
    first = s
    if rho:
        s = max(s - 1, 0)  # the row before the chunk, for its first difference
    x = xs[s : stop + window - 1]
    h = np.diff(tr.t[s : stop + window])
    if derivative == "forward":
        rows = theta(x, tr.u[s : stop + window - 1])
    else:
        stages = tr.stage_inputs(np.arange(s, stop + window - 1))
        rows = _rk4_stage_theta(theta, rhs, x, stages, h)
    y = (xs[s + window : stop + window] - xs[s:stop]) / (
        tr.t[s + window : stop + window] - tr.t[s:stop]
    )[:, None]
    keep = seen[s:stop] & seen[s + window : stop + window]
    rows = _window_mean(rows, h, window)
    if rho:
        rows, y, keep = _prewhiten(rows, y, keep, rho, first == 0)
    return _observed_rows(keep, rows, y)


AR1 = "ar1"
"""``Trajectory.meta`` key: the lag-1 autocorrelation of the equation errors on this data.

Where it is set, the integral formulations' rows are prewhitened with it (Prais-Winsten
feasible GLS for AR(1) errors): unmeasured forces (wind, gusts) make the equation error of
neighbouring steps alike, and a controller answers them, so the inputs correlate with the
error and a plain least-squares fit is biased (a trial: 2 % m g gusts moved gravity and
1/m by 9 %). The innovations of an AR(1) error are not yet known to the controller.
:func:`identification.selection.select_model` sets it when the data call for it."""


def _prewhiten(
    rows: np.ndarray, y: np.ndarray, keep: np.ndarray, rho: float, starts: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rows r - rho (r - 1) of a chunk that holds one row before its own.

    With ``starts`` the chunk begins the trajectory. A row without an observed row before
    it (the trajectory's first, or the first after rows a logger lost) starts the AR(1)
    chain anew: it is scaled by sqrt(1 - rho^2). Every row the plain rows keep is kept, so
    the prewhitened rows and the steps stay in step (the outlier notes map one to the
    other; a trial's log with re-sent rows failed there).
    """
    if starts:
        own, own_y, own_keep = rows, y, keep
        prev = np.concatenate([rows[:1], rows[:-1]])
        prev_y = np.concatenate([y[:1], y[:-1]])
        chained = np.concatenate([[False], keep[:-1]])
    else:
        own, own_y, own_keep = rows[1:], y[1:], keep[1:]
        prev, prev_y, chained = rows[:-1], y[:-1], keep[:-1]
    scale = np.where(chained, 1.0, np.sqrt(1.0 - rho * rho))[:, None]
    lag = np.where(chained, rho, 0.0)[:, None]
    out = np.empty(own.shape, order="F")
    np.multiply(own, scale, out=out)
    out -= lag * prev
    return out, own_y * scale - lag * prev_y, own_keep


def regression_rows(
    trajs: Sequence[Trajectory],
    feature_names: Sequence[str],
    derivative: str | BaseDifferentiation,
    window: int = 1,
    xi: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Stacks (Theta, Y) over trajectories for one formulation (see :func:`iter_rows`)."""
    parts = list(iter_rows(trajs, feature_names, derivative, window, xi))
    return np.concatenate([p[1] for p in parts]), np.concatenate([p[2] for p in parts])


WORKERS = 2
"""Threads that build and factor the regression rows in :func:`grams`."""


def _chunk_factor(chunk: Callable[[], tuple[np.ndarray, np.ndarray]]) -> Gram:
    theta, y = chunk()
    if not np.isfinite(theta).all():
        raise ValueError(
            "the library evaluates to NaN or inf on this data (e.g. sec or tan near 90 deg)"
        )
    p, rows = theta.shape[1], _augmented(theta, y)
    del theta  # the QR copies its input: two chunk-sized arrays at a time, not three
    return Gram.from_augmented(rows, p)


@serial_blas
def grams(
    trajs: Sequence[Trajectory],
    feature_names: Sequence[str],
    derivative: str | BaseDifferentiation,
    window: int = 1,
    xi: np.ndarray | None = None,
) -> list[Gram]:
    """Normal equations of each trajectory, streamed chunk by chunk (memory: a few chunks).

    :data:`WORKERS` threads build chunks' rows and factor them (numpy's loops and LAPACK
    release the GIL); the factors are combined in chunk order, so the result is bit for bit
    that of one chunk after another. One 6-DOF log of 1e5 rows (543 terms) on two cores: a
    pass 2.1 to 2.4 s -> 1.7 to 1.9 s, the whole ``identify`` 82 s -> 56 s with the
    column-major rows and in-place sums below.
    """
    out = [Gram.zeros(len(feature_names), len(trajs[0].state_names)) for _ in trajs]
    pending: collections.deque[tuple[int, Future]] = collections.deque()

    def combine() -> None:
        index, future = pending.popleft()
        part = future.result()
        out[index] = part if out[index].rows == 0 else out[index] + part

    with ThreadPoolExecutor(max_workers=WORKERS) as pool:
        for index, chunk in _row_chunks(trajs, feature_names, derivative, window, xi):
            pending.append((index, pool.submit(_chunk_factor, chunk)))
            if len(pending) > WORKERS:
                combine()
        while pending:
            combine()
    return out


# -- identifiability --------------------------------------------------------------------
def check_identifiable(
    gram: Gram,
    feature_names: Sequence[str],
    trajs: Sequence[Trajectory] | None = None,
    tol: float | None = None,
) -> dict[str, float]:
    """Refuses data on which the library cannot be identified; returns conditioning numbers.

    Raises ValueError (one line, naming terms and the data that would fix it) when there are
    fewer regression rows than terms, an input never changes, a term is zero on all data, or
    a set of terms is exactly collinear (smallest singular value of the column-normalised
    library below the round-off of its columns, :data:`ROUNDOFF`, or ``tol`` times the
    largest).

    Args:
        gram: Normal equations of the library on the data.
        feature_names: The library.
        trajs: The data (for the per-input excitation check).
        tol: Collinearity tolerance on the ratio of the normalised singular values (None:
            the columns' round-off).

    Returns:
        ``{"condition": ...}``: the condition number of the column-normalised library.
    """
    names = list(feature_names)
    p = len(names)
    if gram.rows < p:
        rows = sum(len(t) for t in trajs or ())
        unseen = sum(int(np.sum(~t.observed)) for t in trajs or ())
        if unseen > rows // 3:  # states logged at a lower rate than the inputs
            raise ValueError(
                f"only {gram.rows} regression rows for a library of {p} terms: {unseen} of "
                f"{rows} rows hold no states, and a row of the fit needs the states at both "
                "ends of a step; log the states at the inputs' rate, or keep only the rows "
                "that hold them"
            )
        raise ValueError(
            f"only {gram.rows} regression rows for a library of {p} terms: record at least "
            f"{p - gram.rows} more samples, or use a smaller library"
        )
    if trajs:
        u = np.concatenate([tr.u for tr in trajs])
        for j, name in enumerate(trajs[0].input_names):
            span = np.ptp(u[:, j])
            if span <= 1e-12 * max(np.abs(u[:, j]).max(), 1e-300):
                with_input = [n for n in names if name in {f.var for f in parse_term(n)}]
                raise ValueError(
                    f"input {name!r} is constant ({u[0, j]:g}) over all data, so its terms "
                    f"{with_input[:4]} cannot be told from the others: record data in which "
                    f"{name} varies (e.g. add excitation to it)"
                )
        same = _same_signals(trajs)
        if same:
            a, b = same
            raise ValueError(
                f"variables {a!r} and {b!r} are the same signal on this data (one is an exact "
                f"scaled and shifted copy of the other), so no term can tell them apart: drop "
                "one, or record data in which they differ"
            )
    norm = gram.col_norms
    zero = [names[j] for j in np.flatnonzero(norm <= 0)]
    if zero:
        raise ValueError(
            f"term(s) {zero[:6]} are zero on all data: record data in which they vary, or "
            "remove them from the library"
        )
    unit = gram.r / norm
    _, sing, vt = np.linalg.svd(unit, full_matrices=False)
    ratio = sing[-1] / sing[0]
    floor = ROUNDOFF * np.finfo(float).eps * np.sqrt(p) if tol is None else tol * sing[0]
    if sing[-1] < floor:
        raise ValueError(_collinear_message(unit, norm, vt[-1], int(np.sum(sing < floor)),
                                            ratio, names, trajs))  # fmt: skip
    if trajs:
        feedback = _feedback(unit, norm, names, trajs)
        if feedback:
            raise ValueError(feedback)
    return {"condition": float(1.0 / ratio)}


def _relation(
    unit: np.ndarray, norm: np.ndarray, names: Sequence[str], j: int, among: Sequence[int]
) -> tuple[str, list[str]]:
    """``names[j]`` as the least-squares combination of the columns ``among``, in data units.

    Its 5 largest parts by contribution (the law an input follows, where it is feedback),
    and the names of all parts above 1e-3 of the largest, largest first.
    """
    among = list(among)
    coef = np.linalg.lstsq(unit[:, among], unit[:, j], rcond=None)[0]
    order = [k for k in np.argsort(-np.abs(coef)) if abs(coef[k]) > 1e-3 * np.abs(coef).max()]
    data = coef * norm[j] / norm[among]
    terms = " ".join(_signed(data[k], names[among[k]]) for k in order[:5])
    text = f"{names[j]} = {terms.removeprefix('+ ')}{' ...' if len(order) > 5 else ''}"
    return text, [names[among[k]] for k in order]


def _signed(value: float, name: str) -> str:
    """``+ 2.5 u1``, ``- qw^2`` (a unit coefficient of a term is not written), ``- 9.81``."""
    size = f"{abs(value):.4g}"
    if name == "1":
        part = size
    else:
        part = name if size == "1" else f"{size} {name}"
    return f"{'-' if value < 0 else '+'} {part}"


def _collinear_message(
    unit: np.ndarray,
    norm: np.ndarray,
    null: np.ndarray,
    dimension: int,
    ratio: float,
    names: Sequence[str],
    trajs: Sequence[Trajectory] | None,
) -> str:
    """Why the library is singular on the data: the simplest exact relation, with a fix.

    In library order (simplest terms first), the first column that the earlier ones give to
    round-off is named with them; a null vector's largest entries, where a null space has
    several dimensions, mixed relations (regulation flights: ``u1``, ``cos(phi)``, ``1`` and
    ``cos(phi) u1`` were named, the exact set is ``1, z, z_dot, u1``, the controller's law).
    """
    diag = np.abs(np.diag(unit))
    first = np.flatnonzero(diag < np.sqrt(SINGULAR_TOL))
    law = ""
    if first.size:
        j = int(first[0])
        before = [k for k in range(j) if diag[k] >= np.sqrt(SINGULAR_TOL)]
        text, parts = _relation(unit, norm, names, j, before) if before else ("", [])
        involved, law = [names[j], *parts][:6], f": {text}" if text else ""
    else:
        involved = [names[k] for k in np.argsort(-np.abs(null)) if abs(null[k]) > 0.05][:6]
    several = f"; one of {dimension} independent such combinations" if dimension > 1 else ""
    head = (f"terms {involved} are exactly collinear on this data (a combination of them is "
            f"zero to {ratio:.0e} of the largest{several}){law}")  # fmt: skip
    if trajs:  # a variable of two values: its powers are a line in it, whatever the data
        variables = [*trajs[0].state_names, *trajs[0].input_names]
        read = {f.var for n in involved for f in parse_term(n)}
        both = np.concatenate([np.column_stack([t.x, t.u]) for t in trajs])
        for name in sorted(read & set(variables)):
            levels = np.unique(both[:, variables.index(name)])
            if levels.size == 2:
                return head + (
                    f": {name!r} takes only two values on this data ({levels[0]:g} and "
                    f"{levels[1]:g}), so its powers and products are lines in it: a flag is no "
                    f"variable for a polynomial library (leave {name} out: --states/--inputs), "
                    f"and an input switched between two levels needs a third"
                )
    inputs = set(trajs[0].input_names) if trajs else set()
    carried = [n for n in involved if {f.var for f in parse_term(n)} & inputs]
    if len(carried) == 1 and first.size:
        name = sorted({f.var for f in parse_term(carried[0])} & inputs)[0]
        return head + (
            f": {name!r} follows the states exactly (feedback with no excitation of its own), "
            f"so its terms cannot be told from the controller's state terms; record flights "
            f"in which {name} also moves independently of the states (dither on it, reference "
            "changes)"
        )
    if not carried and first.size:  # states only: perhaps an identity no data can break
        return head + (
            f": record data in which they vary independently (other inputs, larger angles); "
            f"if the relation is an identity of the variables (a unit quaternion, a conserved "
            f"quantity), no data will, so leave a term out of the library (a spec's "
            f"exclude={names[int(first[0])]} drops it and its products)"
        )
    return head + (": record data in which they vary independently (other inputs, larger "
                   "angles), or leave one of them out of the library")  # fmt: skip


FEEDBACK_FACTOR = 3.0
"""An input term is refused as feedback where what the state-only terms leave of it is under
this many times the share its logging resolution alone leaves (rounded regulation logs:
0.75 to 0.99; 1 % dither logged to 4 decimals: 20; float64 logs: 1e11 and more)."""


def _feedback(
    unit: np.ndarray, norm: np.ndarray, names: Sequence[str], trajs: Sequence[Trajectory]
) -> str:
    """A refusal where an input follows the states to within its logging resolution.

    Under feedback with no excitation of its own an input is a function of the states; the
    data then say nothing of its effect that the controller's state terms do not say as well.
    Exactly (float64) that is a singular library; logged to a few decimals the rounding hides
    it from a round-off test and adds a variation that did not act on the vehicle. A trial's
    regulation flights with inputs logged to 4 decimals gave 36 terms for 7, the controller's
    gains in ``z_dot'``, exact on held-out regulation and worse than holding the state on
    tracking flights, with exit 0.

    Each input term's residual after projection on the state-only terms (a share of its
    norm) is compared with the share the rounding of its inputs leaves in that term
    (:func:`identification.data.logged_resolution`, through the term's derivative in the
    input on the data: a product's floor is not its bare input's: an adversarial trial's
    ``sin(phi) u2`` was refused against ``u2``'s floor, 4 to 5 times too high). Where the
    input's own rest (its bare term's, where that is at its rounding too; else the term's:
    a second adversarial trial's ``u1 = m (g + a_z) / cos(phi)`` left ``u1`` a smooth rest
    that acts while ``cos(phi) u1`` was the law) is what acted, a command rounded before it
    was applied (integer PWM), the input is not refused
    (:func:`_rest_acts`; the same trial's actuator-rounded flights were refused, and are
    identified exactly).
    """
    from identification.data import logged_resolution

    first = trajs[0]
    inputs = list(first.input_names)
    uses = [{f.var for f in parse_term(n)} & set(inputs) for n in names]
    state_only = [j for j, used in enumerate(uses) if not used]
    carried = [j for j, used in enumerate(uses) if used]
    if not state_only or not carried:
        return ""
    basis = np.linalg.qr(unit[:, state_only])[0]
    away = unit[:, carried] - basis @ (basis.T @ unit[:, carried])
    left = np.linalg.norm(away, axis=0)
    logged = {n: np.concatenate([t.u[:, k] for t in trajs]) for k, n in enumerate(inputs)}
    quantum = {n: logged_resolution(values) for n, values in logged.items()}
    floor = _rounding_share([names[j] for j in carried], uses, carried, trajs, quantum)
    below = np.flatnonzero(left < FEEDBACK_FACTOR * floor)
    if not below.size:
        return ""
    judged: dict[str, tuple[bool, float]] = {}
    under = {names[carried[k]] for k in below}
    for k in below:
        j = carried[k]
        name = sorted(uses[j])[0]
        if name not in judged:  # on the bare input where it is itself at its rounding
            probe = names.index(name) if name in under else j
            judged[name] = _rest_acts(trajs, names, state_only, probe)
        acted, power = judged[name]
        if acted:  # its rounding acted: a command rounded before it was applied (PWM)
            continue
        spread = float(np.std(logged[name]))
        if spread < FEEDBACK_FACTOR * quantum[name]:  # no law needed: it barely moves
            return (
                f"input {name!r} varies little more than its logging step (standard deviation "
                f"{spread:.3g} against a step of {quantum[name]:.3g}): its terms cannot be "
                f"told from the rounding; log {name} at full precision, or excite it more"
            )
        law = _relation(unit, norm, names, j, state_only)[0]
        head = (f"input {name!r} follows the states to within its logging resolution: {law} "
                f"leaves {left[k]:.2g} of {names[j]!r}, the rounding of the logged {name} "
                f"alone {floor[k]:.2g}")  # fmt: skip
        fix = (f"its terms cannot be told from the controller's state terms: record flights "
               f"in which {name} also moves independently of the states (dither on it, "
               "reference changes)")  # fmt: skip
        if power < ACTS_T:  # had the rounding acted, the state noise would hide it
            return (
                f"{head}, and the state noise hides whether that rest moved the states (had "
                f"it, {power:.2g} standard errors on these data). Under feedback with no "
                f"excitation of its own, {fix}"
            )
        return (f"{head}, and that rest does not move the states (had it, {power:.2g} "
                f"standard errors). Under feedback with no excitation of its own, {fix}, or "
                f"log it at full precision")  # fmt: skip
    return ""


DIFF_ORDER = 3
"""Differences taken before the correlation: the smooth rest (the law beyond the library)
drops as dt^3, the white rounding stays."""

ACTS_T = 5.0
"""|t| of the correlation between the third differences of an input term's rest (off the
state-only terms) and of a state's one-step residual above which the rest moved the vehicle
(5 standard errors, Bonferroni-safe over a few equations)."""


def _rest_acts(
    trajs: Sequence[Trajectory], names: Sequence[str], state_only: Sequence[int], j: int,
    rows: int = 50_000,
) -> tuple[bool, float]:  # fmt: skip
    """Whether what the state-only terms leave of term ``j`` moved the states.

    A command rounded before it was applied (integer PWM) acts with its rounding; one
    rounded only when logged does not. The rounding is white, the controller's smooth rest
    (the law beyond the library) is not: the third differences (:data:`DIFF_ORDER`) of the
    term's rest and of each state's one-step residual off the state-only terms (forward
    differences) are correlated where the rounding acted, and not where it did not (first
    differences left enough of a ``1 / cos(phi)`` law to call its logged rounding acting).
    On up to ``rows`` rows.

    Returns whether it acted, and the test's power: the largest |t| over the states had the
    rest acted with the effect the input has on the data (the term's state-explained part
    regressed into each state's; where the input is a law of the states, its whole effect
    lies there). Under state noise a rounding that acted can be under the test's reach (a
    trial's actuator-rounded flights at sigma = 1e-3: about 1): the refusal then says that
    the noise hides it, not that the rest did not act.
    """
    first = trajs[0]
    columns = [names[k] for k in state_only] + [names[j]]
    theta = compile_features(columns, first.state_names, first.input_names)
    feats, targets, starts, used = [], [], [], 0
    for tr in trajs:
        n = min(len(tr) - 1, rows - used)
        if n < 3:
            continue
        feats.append(theta(tr.x[:n], tr.u[:n]))
        targets.append(np.diff(tr.x[: n + 1], axis=0) / np.diff(tr.t[: n + 1])[:, None])
        starts.append(used)
        used += n
    if not feats:
        return False, 0.0
    a, y = np.vstack(feats), np.vstack(targets)
    scale = np.sqrt(np.mean(a**2, axis=0))
    scale[scale == 0] = 1.0
    both = np.column_stack([a[:, -1], y])
    explained = (a[:, :-1] / scale[:-1]) @ np.linalg.lstsq(a[:, :-1] / scale[:-1], both,
                                                             rcond=None)[0]  # fmt: skip
    rest = both - explained
    explained -= explained.mean(axis=0)
    spread = explained[:, 0] @ explained[:, 0]
    effect = explained[:, 1:].T @ explained[:, 0] / spread if spread > 0 else np.zeros(y.shape[1])
    order = DIFF_ORDER
    keep = np.ones(len(rest) - order, dtype=bool)
    for start in starts[1:]:  # no difference across two segments
        keep[max(start - order, 0) : start] = False
    change = np.diff(rest, n=order, axis=0)[keep]
    change -= change.mean(axis=0)
    size = np.sqrt(np.sum(change**2, axis=0))
    if size[0] == 0:
        return False, 0.0
    with np.errstate(invalid="ignore", divide="ignore"):
        r = (change[:, 1:].T @ change[:, 0]) / (size[1:] * size[0])
        t = np.abs(r) * np.sqrt(max(len(change) - 2, 1)) / np.sqrt(np.maximum(1 - r**2, 1e-300))
        power = np.abs(effect) * size[0] / size[1:] * np.sqrt(len(change))
    return bool(np.any(np.nan_to_num(t) > ACTS_T)), float(np.max(np.nan_to_num(power)))


def _rounding_share(
    terms: Sequence[str],
    uses: Sequence[set[str]],
    carried: Sequence[int],
    trajs: Sequence[Trajectory],
    step: dict[str, float],
    rows: int = 20_000,
) -> np.ndarray:
    """Per input term, the share of its norm the rounding of its inputs leaves in it.

    Uniform rounding by a step q has a standard deviation q / sqrt(12); in a term f it leaves
    about that times |df/du| (evaluated on up to ``rows`` evenly spread samples).
    """
    first = trajs[0]
    x = np.concatenate([t.x for t in trajs])
    u = np.concatenate([t.u for t in trajs])
    pick = np.unique(np.linspace(0, len(x) - 1, min(rows, len(x))).astype(int))
    x, u = x[pick], u[pick]
    theta = compile_features(list(terms), first.state_names, first.input_names)
    size = np.sqrt(np.mean(theta(x, u) ** 2, axis=0))
    share = np.zeros(len(terms))
    for k, name in enumerate(first.input_names):
        h = 1e-6 * (np.sqrt(np.mean(u[:, k] ** 2)) or 1.0)
        up, down = u.copy(), u.copy()
        up[:, k] += h
        down[:, k] -= h
        slope = np.sqrt(np.mean(((theta(x, up) - theta(x, down)) / (2 * h)) ** 2, axis=0))
        mine = np.array([name in uses[j] for j in carried])
        part = step[name] / np.sqrt(12.0) * slope / np.where(size > 0, size, np.inf)
        share = np.where(mine, np.maximum(share, part), share)
    return share


def _same_signals(trajs: Sequence[Trajectory]) -> tuple[str, str] | None:
    """Two variables that are exact affine copies of each other on the data, if any."""
    names = [*trajs[0].state_names, *trajs[0].input_names]
    both = np.concatenate([np.column_stack([tr.x, tr.u]) for tr in trajs])
    centred = both - both.mean(axis=0)
    norms = np.linalg.norm(centred, axis=0)
    moving = np.flatnonzero(norms > 1e-12 * (1.0 + np.abs(both).max(axis=0)) * np.sqrt(len(both)))
    unit = centred[:, moving] / norms[moving]
    cos = np.abs(unit.T @ unit)
    np.fill_diagonal(cos, 0.0)
    i, j = np.unravel_index(int(np.argmax(cos)), cos.shape) if cos.size else (0, 0)
    if cos.size and cos[i, j] > 1.0 - 1e-12:
        return names[moving[min(i, j)]], names[moving[max(i, j)]]
    return None


# -- sparse regression ------------------------------------------------------------------
def _make_optimizer(config: FitConfig) -> BaseOptimizer:
    if isinstance(config.optimizer, BaseOptimizer):
        opt = clone(config.optimizer)
        if config.set_lam and "threshold" in opt.get_params():
            opt.set_params(threshold=config.lam)
        return opt
    if config.optimizer == "sr3":
        nu = 1.0
        weight = ps.SR3.calculate_l0_weight(config.lam, nu)
        return ps.SR3(reg_weight_lam=weight, regularizer="L0", relax_coeff_nu=nu, max_iter=100)
    stlsq = ps.STLSQ(threshold=config.lam, alpha=0.0, max_iter=50)
    if config.optimizer == "stlsq":
        return stlsq
    return ps.EnsembleOptimizer(stlsq, bagging=True, n_models=config.n_models)


@dataclass
class WarningTally:
    """Counts pysindy's warnings instead of printing each (summarised once by the caller)."""

    counts: dict[str, int] = field(default_factory=dict)

    def add(self, caught: Sequence[warnings.WarningMessage]) -> None:
        """Adds caught warnings, keyed by their first line."""
        for w in caught:
            key = str(w.message).splitlines()[0][:120]
            self.counts[key] = self.counts.get(key, 0) + 1

    def summary(self) -> str:
        """One line, or the empty string when nothing was caught."""
        if not self.counts:
            return ""
        total = sum(self.counts.values())
        top = max(self.counts, key=self.counts.get)  # type: ignore[arg-type]
        return f"{total} optimizer warning(s) (e.g. {top!r}); results are validated regardless"


TALLY = WarningTally()
"""Warnings of the optimizers run since the last :meth:`WarningTally.counts` reset."""


def _scales(gram: Gram, scale: bool) -> tuple[np.ndarray, np.ndarray]:
    n = max(gram.rows, 1)
    col = gram.col_norms / np.sqrt(n) if scale else np.ones(gram.p)
    col[col == 0] = 1.0
    row = gram.y_norms / np.sqrt(n) if scale else np.ones(gram.r_aug.shape[1] - gram.p)
    row[row == 0] = 1.0
    return col, row


def solve(gram: Gram, config: FitConfig, feature_names: Sequence[str] | None = None) -> np.ndarray:
    """Scaled sparse regression on the triangular factor with a pysindy optimizer, debiased.

    The optimizer sees ``A = R`` and ``B = Q^T Y`` (p rows), whose least-squares objective
    equals that of the data rows up to a constant.

    Returns:
        Coefficients, shape (n_targets, n_features), in the units of Theta and Y.
    """
    if config.optimizer == "stepwise" and config.lam > 0:
        return solve_lambdas(gram, config, [config.lam], feature_names)[0]
    col, row = _scales(gram, config.scale)
    a = gram.r / col[None, :]
    b = gram.z / row[None, :]
    if config.lam == 0 and isinstance(config.optimizer, str):
        coef_s = np.linalg.lstsq(a, b, rcond=None)[0].T
    else:
        opt = _make_optimizer(config)
        # pysindy's bagging draws from numpy's global RNG: seeded, then the caller's state
        # restored (unseeded, two identical `--optimizer ensemble` runs gave 25 and 26 terms)
        state = np.random.get_state()  # noqa: NPY002
        try:
            np.random.seed(config.seed)  # noqa: NPY002
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                opt.fit(a, b)
        finally:
            np.random.set_state(state)  # noqa: NPY002
        TALLY.add(caught)
        coef_s = _debias(a, b, np.atleast_2d(opt.coef_) != 0)
    return coef_s * row[:, None] / col[None, :]


def solve_lambdas(
    gram: Gram,
    config: FitConfig,
    lams: Sequence[float],
    feature_names: Sequence[str] | None = None,
) -> np.ndarray:
    """:func:`solve` at every threshold of ``lams``, shape (len(lams), n_targets, n_features).

    The ``stepwise`` optimizer computes its path once per target and reads every threshold
    off it; the others are solved threshold by threshold. With ``feature_names`` the stepwise
    path enters the simpler of two near-collinear terms that the data cannot tell apart
    (see :func:`identification.stepwise.stepwise_path`).
    """
    if config.optimizer != "stepwise":
        return np.array([solve(gram, dataclasses.replace(config, lam=float(v))) for v in lams])
    col, row = _scales(gram, config.scale)
    a = gram.r / col[None, :]
    b = gram.z / row[None, :]
    twins = simpler_twins(a, feature_names) if feature_names is not None else None
    rows = max(gram.rows, 1)
    # the pilot (full path) only places stage points: no replacement search there
    coef_s = stepwise_coefficients(a, b, rows, lams, simpler=twins, n_eff=rows,
                                   stop_noise=not config.full_path,
                                   replace=not config.full_path,
                                   backward=config.backward and not config.full_path)  # fmt: skip
    for li, lam in enumerate(lams):
        if lam == 0:
            coef_s[li] = np.linalg.lstsq(a, b, rcond=None)[0].T
    return coef_s * row[None, :, None] / col[None, None, :]


def _debias(a: np.ndarray, b: np.ndarray, support: np.ndarray) -> np.ndarray:
    out = np.zeros(support.shape)
    for i in range(support.shape[0]):
        cols = np.flatnonzero(support[i])
        if cols.size:
            out[i, cols] = np.linalg.lstsq(a[:, cols], b[:, i], rcond=None)[0]
    return out


def sparse_regression(theta: np.ndarray, y: np.ndarray, config: FitConfig) -> np.ndarray:
    """Scaled sparse regression on explicit rows (pysindy's ensemble bags rows).

    Returns:
        Coefficients, shape (n_targets, n_features), in the units of theta and y.
    """
    if not np.isfinite(theta).all():
        raise ValueError("the library evaluates to NaN or inf on this data (e.g. sec near 90 deg)")
    is_ensemble = config.optimizer == "ensemble" or isinstance(
        config.optimizer, ps.EnsembleOptimizer
    )
    if not is_ensemble or config.lam == 0:
        return solve(Gram.from_rows(theta, y), config)
    col = np.sqrt(np.mean(theta**2, axis=0)) if config.scale else np.ones(theta.shape[1])
    col[col == 0] = 1.0
    row = np.sqrt(np.mean(y**2, axis=0)) if config.scale else np.ones(y.shape[1])
    row[row == 0] = 1.0
    ts, ys = theta / col, y / row
    # pysindy's bagging draws from numpy's global RNG: seed it, then restore the caller's state
    state = np.random.get_state()  # noqa: NPY002
    try:
        np.random.seed(config.seed)  # noqa: NPY002
        opt = _make_optimizer(config)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            opt.fit(ts, ys)
        TALLY.add(caught)
    finally:
        np.random.set_state(state)  # noqa: NPY002
    coef_s = _debias(ts, ys, np.atleast_2d(opt.coef_) != 0)
    return coef_s * row[:, None] / col[None, :]


def _check_dataset(trajs: Sequence[Trajectory]) -> None:
    if not trajs:
        raise ValueError("no trajectories to fit")
    first = trajs[0]
    for tr in trajs[1:]:
        if (tr.state_names, tr.input_names) != (first.state_names, first.input_names):
            raise ValueError("all trajectories must have the same state and input names")


START_LAM = 1e-3
"""Threshold of the ``stepwise`` passes that only seed the RK4 fixed point (their stage points
are O(dt) off, so terms explaining under 0.1 % of a target add nothing there)."""


@serial_blas
def fit_coefficients(
    trajs: Sequence[Trajectory],
    feature_names: Sequence[str],
    config: FitConfig,
    start: np.ndarray | None = None,
    last_rows: list[Gram] | None = None,
) -> np.ndarray:
    """Xi for one configuration: the formulation's fixed point (no identifiability check).

    Args:
        trajs: The data.
        feature_names: The library.
        config: The fit settings.
        start: For the ``rk4`` formulation, coefficients whose rhs gives the first stage
            points (default: a forward-difference fit). An accurate start saves the passes
            whose stage points are still O(dt) off, which are the slow ones: their residual
            keeps the sparse path going to its longest support.
        last_rows: A list that receives the last pass's factor of each trajectory (the rows
            whose solution the returned Xi is: for ``rk4``, at the stage points of the Xi
            before it), so that a caller needs no pass of its own over the data (left empty
            with the ``ensemble`` optimizer, which fits explicit rows).
    """
    names = list(feature_names)
    is_ensemble = config.optimizer == "ensemble" or isinstance(
        config.optimizer, ps.EnsembleOptimizer
    )

    def one(
        derivative: str | BaseDifferentiation, xi: np.ndarray | None, cfg: FitConfig = config
    ) -> np.ndarray:
        if is_ensemble:
            return sparse_regression(*regression_rows(trajs, names, derivative, cfg.window, xi),
                                     cfg)  # fmt: skip
        factors = grams(trajs, names, derivative, cfg.window, xi)
        if last_rows is not None:
            last_rows[:] = factors
        return solve(Gram.stack(factors), cfg, names)

    if config.derivative != "rk4":
        return one(config.derivative, None)
    # Start from the forward-difference fit, then iterate the stage points to a fixed point.
    if start is None:
        # The passes before the stage points are accurate only place the next pass's stage
        # points; on the stepwise path they stop at a coarse threshold (a long path fitting
        # O(dt) truncation error is the slow part of a fit, and is thrown away).
        coarse = config
        if config.optimizer == "stepwise" and 0 < config.lam < START_LAM:
            coarse = dataclasses.replace(config, lam=START_LAM)
        xi = one("forward", None, coarse)
        if coarse is not config:
            xi = one("rk4", xi, coarse)
    else:
        xi = np.asarray(start, dtype=float)
    for _ in range(config.iterations):
        new = one("rk4", xi)
        change = np.abs(new - xi).max() / max(np.abs(new).max(), 1e-300)
        xi = new
        if change < 1e-13:
            break
    return xi


@serial_blas
def fit(
    trajs: Sequence[Trajectory],
    feature_names: Sequence[str],
    config: FitConfig | None = None,
    system: str | None = None,
) -> IdentifiedModel:
    """Identifies dx/dt = Xi Theta(x, u) from trajectories with one fixed configuration.

    For automatic choice of lambda and window use :func:`identification.selection.select_model`.

    Args:
        trajs: Training trajectories (same variables; steps may differ, row by row).
        feature_names: The candidate library.
        config: Formulation, optimizer and threshold.
        system: Optional label of the vehicle (``planar``/``quad6dof`` are checked).

    Returns:
        The identified model, with the fit settings in ``meta``.

    Raises:
        ValueError: The data cannot identify the library (see :func:`check_identifiable`).
    """
    config = config or FitConfig()
    trajs = as_trajectories(trajs)
    _check_dataset(trajs)
    check_glitches(trajs)
    first = trajs[0]
    if isinstance(feature_names, str):  # a preset or a spec ("planar", "degree=2;angles=phi")
        from identification.libraries import library_from_spec

        feature_names = library_from_spec(feature_names, first.state_names, first.input_names)
    if feature_names is None or len(feature_names) == 0:
        raise ValueError("the library is empty: give feature names, a preset or a spec")
    names = [term_name(parse_term(n)) for n in feature_names]
    for n in feature_names:
        parse_term(n, [*first.state_names, *first.input_names])
    base = Gram.stack(grams(trajs, names, "forward", 1))
    conditioning = check_identifiable(base, names, trajs)
    window = max(int(config.window), 1)
    rows = sum(len(t) - window for t in trajs if len(t) > window)
    if window > 1 and rows < len(names):
        raise ValueError(
            f"window {window} leaves only {rows} regression rows for a library of {len(names)} "
            "terms: use a shorter window (--window), or record longer segments"
        )
    xi = fit_coefficients(trajs, list(feature_names), config)
    if not np.any(xi):
        raise ValueError(
            f"the model has no term: at lambda {config.lam:g} every term falls below the "
            "threshold; lower --lambda (lam= in Python) or let --lambda auto choose it"
        )
    meta = {
        **config.label,
        "n_trajectories": len(trajs),
        **({"measured_inputs": list(trajs[0].measured)} if trajs[0].measured else {}),
        **({"input_lag": lag} if (lag := input_lag_of(trajs)) else {}),
        **({"input_drift": drift_meta(rate)} if any(rate := input_drift_of(trajs)) else {}),
        "n_samples": int(sum(len(t) for t in trajs)),
        "dt": first.dt,
        "conditioning": conditioning,
        "ranges": data_ranges(trajs),
    }
    return IdentifiedModel(
        list(feature_names), xi, first.state_names, first.input_names, system, meta
    )


def replace_config(config: FitConfig, **changes: object) -> FitConfig:
    """``dataclasses.replace`` for :class:`FitConfig` (validated again)."""
    return dataclasses.replace(config, **changes)
