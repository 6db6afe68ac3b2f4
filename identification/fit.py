"""SINDy-with-control fitting: regression formulations, pysindy optimizers, lambda scan.

Formulations (``derivative=``), each giving a linear problem Y ~ Theta Xi^T:

``forward``
    The paper's: Y_k = (x_{k+1} - x_k) / dt against Theta(x_k, u_k). On zero-order-hold
    data this is the mean slope over the step, biased by O(dt).
``rk4`` (default)
    Integrator-consistent: the same Y_k against the RK4 average of Theta over the stages
    s1..s4 of the step from x_k with u_k held, the stages computed with the current
    estimate; a few fixed-point passes. Data made by RK4 at the sample step are matched
    exactly (round-off); finer or exact integration leaves an O(dt^4) error.
``rk4`` with ``window=w > 1``
    The integral form of the same: (x_{k+w} - x_k) / (w dt) against the mean of the stage
    averages over the window. Averaging w steps damps measurement noise (weak-form-like).
``central`` / ``smoothed``
    pysindy's FiniteDifference (order 2) / SmoothedFiniteDifference at each sample against
    Theta(x_k, u_k): for comparison (central differences across input jumps fail).

Columns of Theta are scaled to unit RMS and each target to unit RMS before the optimizer,
so one threshold ``lam`` means the same for every term: a term is kept when its typical
contribution exceeds roughly ``lam`` times the typical derivative. After selection the
support is refitted by least squares (debiasing).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import pysindy as ps

from identification.data import Trajectory
from identification.features import compile_features, compile_rhs
from identification.model import IdentifiedModel

DERIVATIVES = ("rk4", "forward", "central", "smoothed")
OPTIMIZERS = ("sr3", "stlsq", "ensemble")
DEFAULT_LAMBDAS = tuple(np.round(np.concatenate([[0.0], np.logspace(-6, 0, 25)]), 12))
"""Default scan grid for our scaled threshold (0 and 25 log-spaced values from 1e-6 to 1)."""


@dataclass
class FitConfig:
    """How to fit.

    Attributes:
        derivative: One of :data:`DERIVATIVES`.
        optimizer: One of :data:`OPTIMIZERS`.
        lam: Scaled sparsity threshold (0: dense least squares).
        window: Steps per row of the integral form (``rk4`` and ``forward``).
        iterations: Fixed-point passes of the ``rk4`` formulation.
        scale: Scale columns and targets to unit RMS.
        n_models: Ensemble size (``ensemble``).
        seed: Ensemble bagging seed.
    """

    derivative: str = "rk4"
    optimizer: str = "sr3"
    lam: float = 1e-3
    window: int = 1
    iterations: int = 4
    scale: bool = True
    n_models: int = 20
    seed: int = 0

    def __post_init__(self) -> None:
        if self.derivative not in DERIVATIVES:
            raise ValueError(f"unknown derivative {self.derivative!r}; valid: {DERIVATIVES}")
        if self.optimizer not in OPTIMIZERS:
            raise ValueError(f"unknown optimizer {self.optimizer!r}; valid: {OPTIMIZERS}")
        if not np.isfinite(self.lam) or self.lam < 0:
            raise ValueError(f"lambda must be a non-negative number, got {self.lam!r}")
        if self.window < 1:
            raise ValueError(f"window must be >= 1, got {self.window}")


def _check_dataset(trajs: Sequence[Trajectory]) -> None:
    if not trajs:
        raise ValueError("no trajectories to fit")
    first = trajs[0]
    for tr in trajs[1:]:
        if (tr.state_names, tr.input_names) != (first.state_names, first.input_names):
            raise ValueError("all trajectories must have the same state and input names")


def _window_mean(rows: np.ndarray, w: int) -> np.ndarray:
    """Means of w consecutive rows (all overlapping windows)."""
    if w == 1:
        return rows
    c = np.concatenate([np.zeros((1, rows.shape[1])), np.cumsum(rows, axis=0)])
    return (c[w:] - c[:-w]) / w


def _targets(tr: Trajectory, w: int) -> np.ndarray:
    return (tr.x[w:] - tr.x[:-w]) / (w * tr.dt)


def _rk4_stage_theta(
    theta: Callable, rhs: Callable, x: np.ndarray, u: np.ndarray, dt: float
) -> np.ndarray:
    """RK4 average of Theta over the stages of each step (input held)."""
    h = dt
    k1 = rhs(x, u)
    s2 = x + 0.5 * h * k1
    k2 = rhs(s2, u)
    s3 = x + 0.5 * h * k2
    k3 = rhs(s3, u)
    s4 = x + h * k3
    return (theta(x, u) + 2 * theta(s2, u) + 2 * theta(s3, u) + theta(s4, u)) / 6.0


def regression_rows(
    trajs: Sequence[Trajectory],
    feature_names: Sequence[str],
    derivative: str,
    window: int = 1,
    xi: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Stacks (Theta, Y) over trajectories for one formulation.

    Args:
        trajs: Data.
        feature_names: Library.
        derivative: One of :data:`DERIVATIVES`.
        window: Integral window (``rk4``/``forward``).
        xi: Current coefficients for the ``rk4`` stage points (required for ``rk4``).

    Returns:
        Theta (rows, p) and Y (rows, n).
    """
    names = (trajs[0].state_names, trajs[0].input_names)
    theta = compile_features(feature_names, *names)
    rhs = compile_rhs(feature_names, xi, *names) if xi is not None else None
    thetas, targets = [], []
    for tr in trajs:
        if len(tr) <= window:
            raise ValueError(f"a trajectory of {len(tr)} samples is too short for window {window}")
        x, u = tr.x[:-1], tr.u[:-1]
        if derivative == "forward":
            thetas.append(_window_mean(theta(x, u), window))
            targets.append(_targets(tr, window))
        elif derivative == "rk4":
            if rhs is None:
                raise ValueError("the rk4 formulation needs current coefficients (xi)")
            thetas.append(_window_mean(_rk4_stage_theta(theta, rhs, x, u, tr.dt), window))
            targets.append(_targets(tr, window))
        else:
            method = (
                ps.FiniteDifference(order=2)
                if derivative == "central"
                else ps.SmoothedFiniteDifference()
            )
            thetas.append(theta(tr.x, tr.u))
            targets.append(method._differentiate(tr.x, tr.t))
    return np.concatenate(thetas), np.concatenate(targets)


def _make_optimizer(config: FitConfig) -> ps.optimizers.BaseOptimizer:
    if config.optimizer == "sr3":
        nu = 1.0
        weight = ps.SR3.calculate_l0_weight(config.lam, nu)
        return ps.SR3(reg_weight_lam=weight, regularizer="L0", relax_coeff_nu=nu, max_iter=100)
    stlsq = ps.STLSQ(threshold=config.lam, alpha=0.0, max_iter=50)
    if config.optimizer == "stlsq":
        return stlsq
    return ps.EnsembleOptimizer(stlsq, bagging=True, n_models=config.n_models)


def sparse_regression(theta: np.ndarray, y: np.ndarray, config: FitConfig) -> np.ndarray:
    """Scaled sparse regression with a pysindy optimizer and a least-squares refit.

    Returns:
        Coefficients, shape (n_targets, n_features), in the units of theta and y.
    """
    if not np.isfinite(theta).all():
        raise ValueError("the library evaluates to NaN or inf on this data (e.g. sec near 90 deg)")
    col = np.sqrt(np.mean(theta**2, axis=0)) if config.scale else np.ones(theta.shape[1])
    col[col == 0] = 1.0
    row = np.sqrt(np.mean(y**2, axis=0)) if config.scale else np.ones(y.shape[1])
    row[row == 0] = 1.0
    ts, ys = theta / col, y / row
    if config.lam == 0:
        coef_s = np.linalg.lstsq(ts, ys, rcond=None)[0].T
    else:
        if config.optimizer == "ensemble":
            np.random.seed(config.seed)  # noqa: NPY002 (pysindy's bagging uses the global RNG)
        opt = _make_optimizer(config)
        opt.fit(ts, ys)
        coef_s = np.atleast_2d(opt.coef_)
        coef_s = _debias(ts, ys, coef_s != 0)
    return coef_s * row[:, None] / col[None, :]


def _debias(ts: np.ndarray, ys: np.ndarray, support: np.ndarray) -> np.ndarray:
    out = np.zeros(support.shape)
    for i in range(support.shape[0]):
        cols = np.flatnonzero(support[i])
        if cols.size:
            out[i, cols] = np.linalg.lstsq(ts[:, cols], ys[:, i], rcond=None)[0]
    return out


def fit(
    trajs: Sequence[Trajectory],
    feature_names: Sequence[str],
    config: FitConfig | None = None,
    system: str | None = None,
) -> IdentifiedModel:
    """Identifies dx/dt = Xi Theta(x, u) from trajectories.

    Args:
        trajs: Training trajectories (same variables; dt may differ between them).
        feature_names: The candidate library.
        config: Formulation, optimizer and threshold.
        system: Vehicle the data come from (``planar``/``quad6dof``), if any.

    Returns:
        The identified model, with the fit settings in ``meta``.
    """
    config = config or FitConfig()
    _check_dataset(trajs)
    feature_names = list(feature_names)
    if config.derivative == "rk4":
        # Start from the forward-difference fit, then iterate the stage points to a fixed point.
        xi = sparse_regression(
            *regression_rows(trajs, feature_names, "forward", config.window), config
        )
        for _ in range(config.iterations):
            theta, y = regression_rows(trajs, feature_names, "rk4", config.window, xi)
            new = sparse_regression(theta, y, config)
            change = np.abs(new - xi).max() / max(np.abs(new).max(), 1e-300)
            xi = new
            if change < 1e-13:
                break
    else:
        xi = sparse_regression(
            *regression_rows(trajs, feature_names, config.derivative, config.window), config
        )
    meta = {
        "method": config.derivative,
        "optimizer": config.optimizer,
        "lambda": config.lam,
        "window": config.window,
        "n_trajectories": len(trajs),
        "n_samples": int(sum(len(t) for t in trajs)),
        "dt": trajs[0].dt,
    }
    first = trajs[0]
    return IdentifiedModel(feature_names, xi, first.state_names, first.input_names, system, meta)


@dataclass
class ScanResult:
    """Outcome of a lambda scan.

    Attributes:
        lambdas: The grid.
        n_terms: Non-zero terms of each fit.
        scores: Validation score of each fit (lower is better; inf if it diverged).
        models: The fitted models.
        best: Index of the chosen fit.
    """

    lambdas: list[float]
    n_terms: list[int]
    scores: list[float]
    models: list[IdentifiedModel] = field(repr=False)
    best: int

    @property
    def model(self) -> IdentifiedModel:
        """The chosen model."""
        return self.models[self.best]

    @property
    def lam(self) -> float:
        """The chosen lambda."""
        return self.lambdas[self.best]


def choose_best(scores: Sequence[float], n_terms: Sequence[int], rel_tol: float = 0.1) -> int:
    """Sparsest fit whose score is within ``rel_tol`` of the best (ties: lower score)."""
    scores_a = np.asarray(scores, dtype=float)
    if not np.isfinite(scores_a).any():
        raise ValueError("every fit of the scan diverged on the validation data")
    best = np.nanmin(scores_a[np.isfinite(scores_a)])
    ok = np.flatnonzero(scores_a <= best * (1 + rel_tol) + 1e-12)
    return int(min(ok, key=lambda i: (n_terms[i], scores_a[i])))


def scan_lambda(
    trajs: Sequence[Trajectory],
    feature_names: Sequence[str],
    score: Callable[[IdentifiedModel], float],
    lambdas: Sequence[float] = DEFAULT_LAMBDAS,
    config: FitConfig | None = None,
    system: str | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> ScanResult:
    """Fits over a lambda grid and picks the sparsest model that validates best.

    Args:
        trajs: Training data.
        feature_names: Library.
        score: Validation error of a model (e.g. closed-loop RMSE on held-out runs).
        lambdas: The grid.
        config: Fit settings (its lam is replaced by each grid value).
        system: Vehicle name for the models.
        progress: Called with (done, total) after each fit.

    Returns:
        The scan with the chosen model.
    """
    config = config or FitConfig()
    models, scores = [], []
    for i, lam in enumerate(lambdas):
        cfg = FitConfig(**{**config.__dict__, "lam": float(lam)})
        try:
            model = fit(trajs, feature_names, cfg, system)
            value = float(score(model))
        except (np.linalg.LinAlgError, FloatingPointError, ValueError):
            model, value = None, float("inf")
        models.append(model)
        scores.append(value if np.isfinite(value) else float("inf"))
        if progress:
            progress(i + 1, len(lambdas))
    n_terms = [m.n_terms if m is not None else 10**9 for m in models]
    best = choose_best(scores, n_terms)
    return ScanResult([float(v) for v in lambdas], n_terms, scores, models, best)  # type: ignore[arg-type]
