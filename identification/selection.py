"""Model selection from the user's data alone: cross-validated multi-step prediction.

Nothing here knows a vehicle or a simulator. :func:`select_model` is the entry point:

1. **Folds.** With three or more trajectories (segments), whole trajectories are held out in
   turn (k-fold over trajectories, k <= ``folds``); with fewer, each trajectory is cut into
   contiguous blocks and blocks are held out.
2. **Candidates.** Every integral window in ``windows`` times every threshold in
   ``lambdas``. For each window the RK4 stage points come from a pilot fit on all data (they
   only need an accurate rhs, not a sparse one: dense least squares, or for ``stepwise`` its
   model at the smallest threshold, which stays accurate off the data where dense least
   squares on a nearly singular library does not); the regression of each
   fold is then a sum of per-trajectory triangular factors (:class:`identification.fit.Gram`),
   so a candidate costs one small p x p sparse solve. The default optimizer is ``stepwise``
   (:mod:`identification.stepwise`: forward selection with backward pruning on the factor,
   one path per equation and fold from which every threshold is read off); near-collinear
   alternatives are never both entered, and of two the data cannot tell apart the simpler
   is kept. pysindy optimizers (``stlsq``, ``sr3``, ``ensemble`` or an object) still work.
3. **Score.** Multi-step open-loop prediction on the held-out data: from start points spread
   over each held-out trajectory, the candidate is integrated by RK4 with the *recorded*
   inputs for ``horizon`` steps (rows a logger lost are predicted through, not compared);
   the error of every state, divided by that state's scale (the smaller of its standard
   deviation over the data and the error of holding it over the horizon:
   :func:`score_scale`), is averaged over states, steps and starts (root mean square).
   The windows and the horizon are sized to the segments that hold most of the data
   (:func:`typical_length`).
   A prediction that leaves finite numbers or grows past 1e3 state deviations scores inf.
4. **Rule: one standard error.** Among candidates whose mean fold score is within one
   standard error (over folds) of the best mean, the one with the fewest terms (fitted on all
   data) wins; ties go to the lower mean. Sparser models that predict as well as the best,
   within what the folds can resolve, are preferred.
5. **Final model.** The chosen window and threshold are refitted on all data (full RK4 fixed
   point). Where the greedy path stopped short holding a wrong twin, each equation's best
   support one term larger (or of the same size) within its terms' near twins and best next
   entries is taken when the data need it (:func:`grow_significant`). Near-collinear pairs
   on the data (``1`` / ``cos(phi)``, ``u2`` / ``cos(phi) u2``:
   columns with |cosine| > 0.999, one term the other times more factors) are resolved towards
   the simpler term when an F-test on the residuals (p = 0.001, with every row an effective
   sample: under white measurement noise the targets (x_{k+w} - x_k) / (w dt) of neighbouring
   rows share no sample, so rows / window undercounted them) cannot tell them apart
   (all swaps of an equation together); each case is reported as a warning naming the pair.
   Terms whose removal costs less than the Bonferroni bar for the best of p, against the
   residuals' long-run variance, are dropped (:func:`prune_insignificant`).
6. **Uncertainty (E-SINDy).** A block bootstrap (whole blocks of rows, drawn with
   replacement) refits the chosen candidate ``n_models`` times; each coefficient's spread and
   inclusion probability go into the model; terms kept in fewer than half of the bags are
   dropped (E-SINDy's inclusion threshold), unless the term or a column nearly parallel to
   it on the data (|cos| > 0.999) is in at least half (the bags then only disagree on which
   of two columns the data cannot tell apart carries the direction), or its removal alone
   fails the F-test on all data (p = 0.001: one of a cancelling pair such as gravity and
   thrust, spread by the bags over many near twins). A bag takes the grown support where
   its own rows pass the same bar; a kept term's spread is over its near twin's direction in
   bags that hold the twin.

Scores, the rule and the warnings go into ``model.meta["selection"]`` (JSON-safe).
"""

from __future__ import annotations

import dataclasses
import io
import warnings
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from identification.data import IdentificationWarning, Trajectory, clock_line, data_ranges
from identification.features import compile_rhs, parse_term, term_name
from identification.fit import (
    TALLY,
    FitConfig,
    Gram,
    check_identifiable,
    fit_coefficients,
    grams,
    iter_rows,
    rk4_steps,
    serial_blas,
    solve,
    solve_lambdas,
)
from identification.libraries import library_from_spec
from identification.model import IdentifiedModel
from quad_envs.fileio import jsonable

SELECT_LAMBDAS: tuple[float, ...] = tuple(float(v) for v in np.logspace(-6, 0, 13))
"""Scaled thresholds tried by default (half decades from 1e-6 to 1)."""

WINDOWS: tuple[int, ...] = (1, 4, 16, 64)
"""Integral windows tried by default (1: clean data; longer: noise; a window of a quarter of the
data's typical segment (:func:`typical_length`) or more is skipped). 64 lets the validation
average sigma = 1e-2 noise."""

BAG_T = 2.0
"""A kept term's coefficient must exceed this many standard deviations of its bootstrap fits,
or the full data must reject its removal (F-test), to stay in the model."""

PRUNE_P = 1e-3
"""Significance of a kept term (Bonferroni over the library: see :func:`prune_insignificant`)."""

F_CRITICAL = 10.83
"""F(1, inf) quantile at p = 0.001: a swap to the simpler term of a near-collinear pair is
refused when the residual grows by more than this many residual variances."""


POOR_FIT = 0.5
"""A chosen model whose held-out score is above this fraction of holding the state's is
reported as a poor fit (a warning; the model is still returned)."""

MISFIT_WINDOW, MISFIT_SHRINK, MISFIT_FLOOR = 16, 1.5, 1e-5
"""An equation whose residual (relative to its target's spread, above the floor) shrinks by
less than ``MISFIT_SHRINK`` from window 1 to window ``MISFIT_WINDOW`` is reported: white
measurement noise in the residual shrinks about as 1 / window, misfit does not."""


def standard_error(values: np.ndarray) -> float:
    """Standard error of the mean of ``values`` (0 for a single value)."""
    return float(values.std(ddof=1) / np.sqrt(values.size)) if values.size > 1 else 0.0


@dataclass
class Candidate:
    """One scored candidate.

    Attributes:
        window: Integral window.
        lam: Scaled threshold.
        n_terms: Terms of the fit on all data.
        fold_scores: Validation score of each fold (inf: diverged).
        empty: Equations with no term in the fit on all data (the state held).
        mean: Mean fold score.
        se: Standard error of the mean over folds.
    """

    window: int
    lam: float
    n_terms: int
    fold_scores: list[float]
    empty: tuple[int, ...] = ()
    mean: float = field(init=False)
    se: float = field(init=False)

    def __post_init__(self) -> None:
        scores = np.asarray(self.fold_scores)
        if np.isfinite(scores).all():
            self.mean = float(scores.mean())
            self.se = standard_error(scores)
        else:
            self.mean = self.se = float("inf")


@dataclass
class SelectionReport:
    """What :func:`select_model` tried and why it chose what it chose.

    Attributes:
        candidates: Every scored candidate.
        chosen: Index of the chosen candidate.
        folds: Number of folds.
        horizon: Prediction horizon [steps].
        rule: The selection rule, in words.
        warnings: Near-collinear pairs resolved, dropped terms, optimizer warnings.
        hold: The score of holding the state (every derivative zero) on the same folds: the
            yardstick a score is read against.
        final_terms: Terms of the returned model: the chosen candidate's support after the
            refit on all data, growth, pruning and bootstrap checks.
    """

    candidates: list[Candidate]
    chosen: int
    folds: int
    horizon: int
    rule: str
    warnings: list[str] = field(default_factory=list)
    hold: float = float("nan")
    final_terms: int | None = None

    @property
    def best(self) -> Candidate:
        """The chosen candidate."""
        return self.candidates[self.chosen]

    def to_meta(self) -> dict[str, Any]:
        """JSON-safe summary (non-finite scores become null)."""
        return jsonable(
            {
                "rule": self.rule,
                "folds": self.folds,
                "horizon": self.horizon,
                "chosen": {"window": self.best.window, "lambda": self.best.lam,
                           "n_terms": self.best.n_terms, "score": self.best.mean,
                           "se": self.best.se},
                "hold_score": self.hold,
                "final_terms": self.final_terms,
                "candidates": [
                    {"window": c.window, "lambda": c.lam, "n_terms": c.n_terms,
                     "score": c.mean, "se": c.se}
                    for c in self.candidates
                ],
                "warnings": self.warnings,
            }
        )  # fmt: skip

    def plot(self, path: str | Path) -> Path:
        """Validation error against number of terms, one series per window, choice marked."""
        import matplotlib

        matplotlib.use("Agg", force=False)
        import matplotlib.pyplot as plt
        from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

        from quad_envs.fileio import atomic_write_bytes

        fig, ax = plt.subplots(figsize=(6.4, 4.2))
        for w in sorted({c.window for c in self.candidates}):
            cs = [c for c in self.candidates if c.window == w and np.isfinite(c.mean)]
            if cs:
                ax.errorbar([c.n_terms for c in cs], [c.mean for c in cs],
                            yerr=[c.se for c in cs], fmt="o", ms=4, capsize=2,
                            label=f"window {w}")  # fmt: skip
        b = self.best
        final = self.final_terms
        after = f" (model after the checks: {final})" if final not in (None, b.n_terms) else ""
        ax.plot([b.n_terms], [b.mean], "r*", ms=16, label=f"chosen: {b.n_terms} terms{after}")
        ax.axhline(b.mean + b.se, color="0.6", lw=0.8, ls="--")
        ax.set_xscale("log")
        ax.set_yscale("log")
        # term counts as plain integers (1, 2, 5, 10, ...); no crowded minor labels (3x10^0)
        ax.xaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
        ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_xlabel("terms in the model (fit on all data)")
        ax.set_ylabel(f"held-out {self.horizon}-step prediction error (normalised)")
        ax.set_title("Model selection: cross-validated prediction error")
        ax.legend(fontsize=8)
        fig.tight_layout()
        buffer = io.BytesIO()
        fig.savefig(buffer, format="png", dpi=120)
        plt.close(fig)
        return atomic_write_bytes(path, buffer.getvalue())


# -- folds and scores -------------------------------------------------------------------
def make_units(trajs: Sequence[Trajectory], folds: int, min_rows: int) -> list[Trajectory]:
    """Whole trajectories when there are at least 3, else contiguous blocks of them."""
    if len(trajs) >= 3:
        return list(trajs)
    total = sum(len(t) for t in trajs)
    units = []
    for tr in trajs:
        pieces = max(1, int(round(folds * len(tr) / total)))
        pieces = min(pieces, max(1, len(tr) // min_rows))
        edges = np.linspace(0, len(tr), pieces + 1).astype(int)
        units += [tr.slice(a, b) for a, b in zip(edges[:-1], edges[1:], strict=True)]
    return units


MIN_UNIT_ROWS = 20
"""Fewest rows of one cross-validation block."""


def validation_units(
    trajs: Sequence[Trajectory], folds: int, windows: Sequence[int], horizon: int
) -> tuple[list[Trajectory], list[int], int]:
    """The cross-validation units, and the windows and horizon that fit them.

    Windows are capped at a quarter and the horizon at half of the typical segment; on a
    single short log (one flight of 150 rows) they shrink further until the data make two
    blocks, so that every fold has data to train on.

    Raises:
        ValueError: Too few rows for two blocks of :data:`MIN_UNIT_ROWS`.
    """
    typical = typical_length(trajs)
    wins = sorted({int(w) for w in windows if 0 < w < max(typical // 4, 2)}) or [1]
    horizon = int(max(1, min(horizon, typical // 2)))
    while True:
        units = make_units(trajs, folds, min_rows=max(2 * horizon, 4 * max(wins), MIN_UNIT_ROWS))
        if len(units) >= 2 or (horizon <= 5 and wins == [1]):
            break
        horizon = max(min(horizon, 5), horizon // 2)
        wins = [w for w in wins if w < max(wins)] or [1]
    if len(units) < 2:
        rows = sum(len(t) for t in trajs)
        raise ValueError(
            f"too little data to validate a model: {rows} rows in {len(trajs)} segment(s) "
            f"make one validation block, and automatic selection needs two of at least "
            f"{MIN_UNIT_ROWS} rows; record more, or give a fixed --lambda"
        )
    return units, wins, horizon


def typical_length(trajs: Sequence[Trajectory], share: float = 0.9) -> int:
    """The longest length L such that segments of at least L rows hold ``share`` of the rows.

    A real log split at its gaps leaves a few long segments and many short fragments; the
    shortest fragment must not cap the window and the horizon of all the data (20 rows would
    allow windows up to 4 and a 10-step horizon on an hour of flight). Windows are sized to the
    segments that hold most of the data; shorter segments sit out the windows they cannot hold.
    """
    lengths = np.sort([len(t) for t in trajs])[::-1]
    covered = np.cumsum(lengths) / lengths.sum()
    return int(lengths[int(np.searchsorted(covered, share - 1e-12))])


def long_enough(trajs: Sequence[Trajectory], window: int) -> list[Trajectory]:
    """The trajectories that hold at least one row of the integral form with ``window``."""
    return [t for t in trajs if len(t) > window]


def _rollouts(
    rhs: Any, trajs: Sequence[Trajectory], horizon: int, max_starts: int, substeps: int = 1
) -> Any:
    """Yields (predicted, recorded, observed, which) step by step from evenly spread starts.

    Starts are observed rows, up to ``max_starts`` per trajectory; the starts of every
    trajectory are stepped together, one batch per step (100 logs of 1000 rows took 5 times
    as long as one log of 100 000 rows when each log was stepped on its own). A trajectory's
    starts take ``min(horizon, len - 1)`` steps; the arrays yielded hold the starts still
    stepping, ``which`` their trajectory's index. ``observed`` marks the predictions that
    have a recorded state to compare with (not a row the logger lost:
    :attr:`Trajectory.missing`).
    """
    starts, lengths, offset = [], [], 0
    for tr in trajs:
        n = len(tr)
        h_len = max(min(horizon, n - 1), 0)
        candidates = np.flatnonzero(tr.observed[: n - h_len])
        pick = np.linspace(0, candidates.size - 1, min(max_starts, candidates.size)).astype(int)
        chosen = candidates[np.unique(pick)]
        starts.append(offset + chosen)
        lengths.append(np.full(chosen.size, h_len))
        offset += n
    if not offset:
        return
    rows = np.concatenate(starts)
    h_len = np.concatenate(lengths)
    which = np.repeat(np.arange(len(trajs)), [len(s) for s in starts])
    states = np.concatenate([tr.x for tr in trajs])
    observed = np.concatenate([tr.observed for tr in trajs])
    steps = np.concatenate([np.append(np.diff(tr.t), np.nan) for tr in trajs])
    held = not any(tr.measured for tr in trajs)
    if held:  # each step's input is its row's
        stages = [np.concatenate([tr.u for tr in trajs])]
    else:
        stages = [np.concatenate(parts) for parts in zip(*[_all_stages(tr) for tr in trajs],
                                                         strict=True)]  # fmt: skip
    x = states[rows]
    for j in range(int(h_len.max(initial=0))):
        active = h_len > j
        at = rows[active] + j
        u0 = stages[0][at]
        u = (u0, u0, u0) if held else (u0, stages[1][at], stages[2][at])
        stepped = rk4_steps(rhs, x[active], u, steps[at], substeps)
        x[active] = stepped
        yield stepped, states[at + 1], observed[at + 1], which[active]


def _all_stages(tr: Trajectory) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:meth:`Trajectory.stage_inputs` of every step, with a last row (no step) repeated."""
    if len(tr) < 2:
        return tr.u, tr.u, tr.u
    every = tr.stage_inputs(np.arange(len(tr) - 1))
    return tuple(np.vstack([a, a[-1:]]) for a in every)


def score_scale(units: Sequence[Trajectory], horizon: int) -> np.ndarray:
    """Each state's normaliser of the prediction error: its spread, or what holding it costs.

    The smaller of the state's standard deviation over the data and the RMS error of holding
    it over 1 .. ``horizon`` steps. A state that drifts (a position 55 m across, covered at a
    few metres per horizon) has a standard deviation far above its error over a horizon: by
    that alone, a model with ``pos' = 0`` scored as well as one with ``pos' = vel``, and won
    as the sparser (new-user trials, cart-pole and unicycle).
    """
    x_all = np.concatenate([u.x for u in units])
    std = x_all.std(axis=0)
    total, count = np.zeros(x_all.shape[1]), 0
    for u in units:
        for j in range(1, min(horizon, len(u) - 1) + 1):
            total += np.sum((u.x[j:] - u.x[:-j]) ** 2, axis=0)
            count += len(u) - j
    hold = np.sqrt(total / max(count, 1))
    scale = np.minimum(std, hold)
    return np.where(scale > 0, scale, np.where(std > 0, std, 1.0))


def prediction_score(
    rhs: Any,
    held_out: Sequence[Trajectory],
    scale: np.ndarray,
    horizon: int,
    max_starts: int = 64,
) -> float:
    """RMS over starts, steps and states of the normalised ``horizon``-step prediction error.

    Args:
        rhs: Compiled rhs(x, u) of the candidate.
        held_out: Trajectories to predict (recorded inputs, each row's own step).
        scale: Per-state normaliser (:func:`score_scale`).
        horizon: Steps to predict from each start.
        max_starts: Start points per trajectory (evenly spread).

    Returns:
        The score (inf if the prediction diverged).
    """
    total, count, k = 0.0, 0, len(held_out)
    with np.errstate(all="ignore"):
        for x, recorded, seen, which in _rollouts(rhs, held_out, horizon, max_starts):
            sq = np.where(seen, np.sum(((x - recorded) / scale) ** 2, axis=1), 0.0)
            per_log = np.bincount(which, weights=sq, minlength=k)
            size = np.bincount(which, weights=seen, minlength=k) * x.shape[1]
            # a log whose prediction runs away makes the candidate diverged, whatever the rest
            if not np.all(np.isfinite(per_log)) or np.any(per_log > 1e6 * size):
                return float("inf")
            total += float(per_log.sum())
            count += int(size.sum())
    return float(np.sqrt(total / max(count, 1)))


@dataclass
class HeldOutErrors:
    """How a model predicts data it was not fitted on (:func:`held_out_errors`).

    Attributes:
        steps: Steps predicted from each start (the horizon).
        starts: Start points used.
        diverged: Starts whose prediction became non-finite (left out of the errors).
        rms: Per state, the RMS error after ``steps`` steps.
        state_range: Per state, its range over the data (max - min).
        score: The selection's score on this data (``steps``-step, see
            :func:`prediction_score`); ``hold``: the same for holding the state.
    """

    steps: int
    starts: int
    diverged: int
    rms: np.ndarray
    state_range: np.ndarray
    score: float
    hold: float

    @property
    def relative(self) -> np.ndarray:
        """Per state, the RMS error after ``steps`` steps as a fraction of its range."""
        return self.rms / np.where(self.state_range > 0, self.state_range, 1.0)


def held_out_errors(
    model: IdentifiedModel, trajs: Sequence[Trajectory], steps: int, max_starts: int = 64
) -> HeldOutErrors:
    """Open-loop prediction of held-out data with the recorded inputs, from evenly spread starts.

    The figure the docs quote as "simulation error at 1 s": each start is simulated ``steps``
    steps (RK4 over each row's own step, inputs as recorded) and compared with the recorded
    state there. Segments shorter than ``steps + 1`` rows are skipped.

    Raises:
        ValueError: The data have other variables than the model, or no segment is long
            enough.
    """
    if not isinstance(steps, int | np.integer) or steps < 1:
        raise ValueError(f"steps must be a positive integer, got {steps!r}")
    names = (model.state_names, model.input_names)
    if any((t.state_names, t.input_names) != names for t in trajs):
        raise ValueError(f"the data's variables are not the model's {names[0]} / {names[1]}")
    usable = [t for t in trajs if len(t) > steps]
    if not usable:
        longest = max((len(t) for t in trajs), default=0)
        raise ValueError(
            f"no segment is longer than {steps} steps (the longest has {longest} rows): "
            "predict fewer steps"
        )
    rhs = compile_rhs(model.feature_names, model.coefficients, *names)
    with np.errstate(all="ignore"):  # every start takes ``steps`` steps: the last batch
        x, recorded, seen, _ = deque(_rollouts(rhs, usable, steps, max_starts), maxlen=1)[0]
        err = (x - recorded)[seen]
        ok = np.all(np.isfinite(err), axis=1)
    diverged, starts = int(np.sum(~ok)), len(err)
    stacked = err[ok]
    rms = np.sqrt(np.mean(stacked**2, axis=0)) if len(stacked) else np.full(len(names[0]), np.inf)
    x_all = np.concatenate([t.x for t in usable])
    scale = score_scale(usable, steps)
    still = lambda x, u: np.zeros_like(x)  # noqa: E731
    return HeldOutErrors(
        steps, starts, diverged, rms, np.ptp(x_all, axis=0),
        prediction_score(rhs, usable, scale, steps, max_starts),
        prediction_score(still, usable, scale, steps, max_starts),
    )  # fmt: skip


RANGE_MARGIN = 0.05
"""A held-out value counts as outside the training range past this share of its span."""

RANGE_ROWS = 0.05
"""A variable is named when at least this share of the rows lie outside its range."""


def range_note(model: IdentifiedModel, trajs: Sequence[Trajectory]) -> str:
    """A warning naming the variables where ``trajs`` leave the model's training range.

    The selection scores a model only on what its training flights span; a trial's 6-DOF
    model, right where its flights went, drifted 17.5 % in 1 s on a held-out flight whose
    yaw went past the training range. The inputs and the states the model's terms use are
    checked (:meth:`IdentifiedModel.training_box`), each where :data:`RANGE_ROWS` of the
    rows or more lie past :data:`RANGE_MARGIN` of the span. Empty where none does or the
    model file has no ranges (files before 2026-11-26).
    """
    box = model.training_box()
    if box is None or not trajs:
        return ""
    names = (*model.state_names, *model.input_names)
    values = np.vstack([np.hstack([t.x, t.u]) for t in trajs])
    out = []
    for k in np.flatnonzero(np.isfinite(box[0])):  # a position no term reads may be anywhere
        lo, hi = float(box[0][k]), float(box[1][k])
        margin = RANGE_MARGIN * max(hi - lo, 1e-12)
        column = values[:, k]
        outside = (column < lo - margin) | (column > hi + margin)
        if np.mean(outside) >= RANGE_ROWS:
            far = column[outside][np.argmax(np.abs(column[outside] - 0.5 * (lo + hi)))]
            out.append(f"{names[k]} to {far:.3g} (trained on {lo:.3g} to {hi:.3g}; "
                       f"{np.mean(outside):.1%} of the rows outside)")  # fmt: skip
    if not out:
        return ""
    return (
        f"the data leave the model's training range: {'; '.join(out)}. The selection tested "
        "the model only within that range: its errors there can be larger than its scores"
    )


def integrator_resolution(
    rhs: Any,
    held_out: Sequence[Trajectory],
    scale: np.ndarray,
    horizon: int,
    max_starts: int = 64,
    per_log: bool = False,
) -> Any:
    """The scores' own numerical error: RMS of one RK4 step per sample against two, normalised.

    The score integrates every candidate by RK4 at the data's step, so on clean data made by
    another integrator a model can gain on the score by fitting RK4's truncation error with
    extra terms of tiny coefficients. Score differences below this are not evidence. With
    ``per_log``, one value per trajectory of ``held_out`` (an array).
    """
    k = len(held_out)
    total, count = np.zeros(k), np.zeros(k)
    with np.errstate(all="ignore"):
        coarse = _rollouts(rhs, held_out, horizon, max_starts)
        fine = _rollouts(rhs, held_out, horizon, max_starts, substeps=2)
        for (one, _, seen, which), (two, *_) in zip(coarse, fine, strict=True):
            sq = np.where(seen, np.sum(((one - two) / scale) ** 2, axis=1), 0.0)
            total += np.bincount(which, weights=sq, minlength=k)
            count += np.bincount(which, weights=seen, minlength=k) * one.shape[1]
        if per_log:
            value = np.sqrt(total / np.maximum(count, 1))
            return np.where(np.isfinite(value), value, 0.0)
        value = float(np.sqrt(total.sum() / max(count.sum(), 1)))
    return value if np.isfinite(value) else 0.0


def best_candidate(candidates: Sequence[Candidate]) -> int:
    """Index of the best mean score.

    Raises:
        ValueError: Every candidate with terms diverged. The empty model (the state held)
            never diverges, but it is no answer when it is the only one left: two real
            Crazyflie flights, body rates from motor speeds, gave ``wx' = wy' = wz' = 0``
            with exit 0 that way.
    """
    means = np.array([c.mean for c in candidates])
    if not any(np.isfinite(c.mean) and c.n_terms > 0 for c in candidates):
        raise ValueError(
            "every candidate model with terms diverged when predicting the held-out data: "
            "the library may not contain the dynamics, or the data are too short or too "
            "noisy (holding the state, the only model left, is not an identified model)"
        )
    return int(np.nanargmin(means))


def choose_one_se(candidates: Sequence[Candidate], resolution: float = 0.0) -> int:
    """Index of the sparsest candidate within one standard error of the best mean score.

    A candidate that holds a state the best one moves (an equation with no term: the empty
    model holds them all) must also be within one standard error of the best in the paired
    sense, fold by fold: on real logs the folds differ so much in difficulty that the
    standard error of a mean swallowed a gain the best model made on every fold (two
    Crazyflie flights: `z' = vz` lost to `z' = 0`; a unicycle at 5 % noise: `px' = py' = 0`
    won over the exact model).

    Args:
        candidates: The scored candidates.
        resolution: The scores' own numerical error (:func:`integrator_resolution`), added
            to the standard error: differences below it are not evidence.
    """
    best = best_candidate(candidates)
    limit = candidates[best].mean + candidates[best].se + resolution
    ok = [
        i
        for i, c in enumerate(candidates)
        if c.mean <= limit * (1 + 1e-12)
        and (
            not set(c.empty) - set(candidates[best].empty)
            or _paired_within(c, candidates[best], resolution)
        )
    ]
    return min(ok, key=lambda i: (candidates[i].n_terms, candidates[i].mean))


def _paired_within(c: Candidate, best: Candidate, resolution: float) -> bool:
    """Whether ``c`` trails ``best`` by at most one standard error of their fold differences."""
    d = np.asarray(c.fold_scores) - np.asarray(best.fold_scores)
    return float(d.mean()) <= (standard_error(d) + resolution) * (1 + 1e-12) + 1e-12 * best.mean


# -- near-collinear pairs ---------------------------------------------------------------
def collinear_pairs(
    gram: Gram, feature_names: Sequence[str], threshold: float = 0.999
) -> list[tuple[int, int, float]]:
    """(simple, complex, |cosine|) for columns nearly parallel on the data.

    Only pairs where the complex term is the simple one times further factors count (e.g.
    ``u2`` and ``cos(phi) u2``; ``1`` and ``cos(phi)``).
    """
    terms = [set(parse_term(n)) for n in feature_names]
    r = gram.r / np.maximum(gram.col_norms, 1e-300)
    cos = np.abs(r.T @ r)
    out = []
    for a, b in zip(*np.nonzero(np.triu(cos > threshold, 1)), strict=True):
        ta, tb = terms[a], terms[b]
        if ta < tb:
            out.append((int(a), int(b), float(cos[a, b])))
        elif tb < ta:
            out.append((int(b), int(a), float(cos[a, b])))
    return out


def _rss(a: np.ndarray, b: np.ndarray, cols: list[int]) -> tuple[float, np.ndarray]:
    if not cols:
        return float(b @ b), np.zeros(0)
    coef = np.linalg.lstsq(a[:, cols], b, rcond=None)[0]
    resid = b - a[:, cols] @ coef
    return float(resid @ resid), coef


def _refit(gram: Gram, i: int, support: Sequence[int]) -> np.ndarray:
    """Equation ``i``'s coefficient row: least squares on ``support``, zero elsewhere."""
    row = np.zeros(gram.p)
    row[list(support)] = _rss(gram.r, gram.z[:, i], list(support))[1]
    return row


def _residual_variance(gram: Gram, i: int, support: Sequence[int]) -> tuple[float, float]:
    """RSS of equation ``i`` on ``support``, and its residual variance for the F-tests.

    The variance counts the residual left outside the p-dimensional range of R (total minus
    explained) and every row as an effective sample (under white measurement noise the
    targets of neighbouring rows share no sample).
    """
    rss = _rss(gram.r, gram.z[:, i], list(support))[0]
    total = float(np.linalg.norm(gram.r_aug[:, gram.p + i]) ** 2)
    outside = max(total - float(gram.z[:, i] @ gram.z[:, i]), 0.0)
    return rss, (rss + outside) / max(max(float(gram.rows), 2.0) - len(support), 1.0)


def resolve_collinear(
    xi: np.ndarray,
    gram: Gram,
    feature_names: Sequence[str],
    state_names: Sequence[str],
    window: int,
) -> tuple[np.ndarray, dict[tuple[int, int, int], str]]:
    """Prefers the simpler term of each near-collinear pair the data cannot tell apart.

    And the complex term where the data can: a simple term is exchanged for its complex
    twin when that lowers the residual by more than the F-test's bar (p = 0.001), the same
    rule the other way round (the greedy path and the growth usually get there first: no
    run of the planar and 6-DOF noise sweeps changed).

    Returns:
        The coefficients (refitted where changed) and a warning per resolved pair, keyed by
        (equation, simple column, complex column).
    """
    pairs = collinear_pairs(gram, feature_names)
    if not pairs:
        return xi, {}
    a, z = gram.r, gram.z
    xi = xi.copy()
    notes = {}
    for i, state in enumerate(state_names):
        support = list(np.flatnonzero(xi[i]))
        # against the fit's own support: swaps each within the F-test of the one before could
        # add up to a support the data reject (four twins in x', 16 variances)
        rss, sigma2 = _residual_variance(gram, i, support) if support else (0.0, 0.0)
        for simple, complex_, cosine in pairs:
            if simple in support and complex_ not in support:
                trial = sorted(complex_ if c == simple else c for c in support)
                if rss - _rss(a, z[:, i], trial)[0] > F_CRITICAL * sigma2:
                    support = trial
                    notes[i, simple, complex_] = (
                        f"{state}': kept {_term_list(feature_names, [complex_])} in place of "
                        f"its nearly collinear {_term_list(feature_names, [simple])} (|cos| = "
                        f"{cosine:.6f}): the data prefer it beyond the F-test's bar"
                    )
                continue
            if complex_ not in support:
                continue
            trial = [c for c in support if c != complex_]
            if simple not in trial:
                trial.append(simple)
            rss_new, _ = _rss(a, z[:, i], trial)
            if (rss_new - rss) <= F_CRITICAL * sigma2:
                support = sorted(trial)
                kept = "both" if simple in np.flatnonzero(xi[i]) else "the complex one"
                notes[i, simple, complex_] = (
                    f"{state}': {term_name(parse_term(feature_names[simple]))!r} and "
                    f"{term_name(parse_term(feature_names[complex_]))!r} are nearly collinear "
                    f"on this data (|cos| = {cosine:.6f}; the fit had {kept}): kept the "
                    "simpler term"
                )
        if sorted(support) != list(np.flatnonzero(xi[i])):
            xi[i] = _refit(gram, i, support)
    return xi, notes


def long_run_ratio(
    trajs: Sequence[Trajectory], names: Sequence[str], xi: np.ndarray, window: int
) -> np.ndarray:
    """Per equation: the long-run variance of the RK4 rows' residuals over their variance.

    Bartlett weights up to lag ``4 window`` (at least 8), autocovariances pooled over the
    trajectories, residuals in time order. 1 for uncorrelated residuals; above 1 where they
    are smooth over the window (the noise inside window-averaged columns, or model error),
    where every row counted as an independent sample overstates how significant a term is.
    """
    lags = max(4 * window, 8)
    parts: dict[int, list[np.ndarray]] = {}
    for index, theta, y in iter_rows(trajs, names, "rk4", window, xi):
        parts.setdefault(index, []).append(y - theta @ xi.T)
    gamma0 = np.zeros(xi.shape[0])
    long_run = np.zeros(xi.shape[0])
    for chunks in parts.values():
        e = np.concatenate(chunks)
        g0 = np.einsum("ij,ij->j", e, e)
        gamma0 += g0
        long_run += g0
        for lag in range(1, min(lags, len(e) // 2)):
            long_run += 2.0 * (1.0 - lag / lags) * np.einsum("ij,ij->j", e[lag:], e[:-lag])
    return np.maximum(long_run, 0.0) / np.maximum(gamma0, 1e-300)


def restart_centred(
    xi: np.ndarray,
    gram: Gram,
    ratio: np.ndarray,
    feature_names: Sequence[str],
    state_names: Sequence[str],
) -> tuple[np.ndarray, list[str]]:
    """Replaces an equation the greedy path built around a cancelling pair it could not enter.

    Forward selection enters one column at a time, so two large columns whose difference is
    the signal (thrust and gravity in ``w'``: ``u1`` and ``cos(phi) cos(theta)``, each far
    from zero, their difference near zero in hover) gain little one by one; the path then
    builds that difference from other columns. A held-out 6-DOF trial at sigma = 1e-2 got a
    52-term ``w'`` without ``u1`` that fitted the data worse than the true 4 terms and
    predicted held-out flights with 66 % error at 1 s. Here a second path runs on columns
    centred by the constant column (offsets removed, so the difference's parts enter on
    their own), stopped where a term explains less than the significance bar of
    :func:`prune_insignificant`; its support with the constant, pruned to that bar, replaces
    the equation's where its penalised residual (residual sum of squares in residual
    variances, plus the bar for each term: a Bonferroni-type information criterion) is lower
    than the path's, pruned the same way, by more than the F-test's bar, and it has no more
    terms. Libraries without a constant term are left as they are.

    Returns:
        The coefficients (refitted where changed) and one note per equation replaced.
    """
    from identification.stepwise import simpler_twins, stepwise_path

    names = [term_name(parse_term(n)) for n in feature_names]
    if "1" not in names or not np.any(xi):
        return xi, []
    one = names.index("1")
    bar = _significance_bar(gram.p)
    a = gram.r / np.maximum(gram.col_norms, 1e-300)
    if not np.linalg.norm(a[:, one]) > 0:
        return xi, []
    q = a[:, one] / np.linalg.norm(a[:, one])
    centred = a - np.outer(q, q @ a)
    twins = simpler_twins(a, feature_names)
    xi = xi.copy()
    notes = []
    for i, state in enumerate(state_names):
        path_support = [int(j) for j in np.flatnonzero(xi[i])]
        if not path_support:
            continue
        scale = max(float(ratio[i]), 1.0)
        now, _ = _prune_support(gram, i, path_support, scale, bar)  # as the checks prune it
        rss_now, sigma2_now = _residual_variance(gram, i, now)
        b = gram.z[:, i]
        total = float(np.linalg.norm(gram.r_aug[:, gram.p + i]) ** 2)
        path = stepwise_path(centred, b - q * (q @ b), min(gram.p, gram.rows),
                             simpler=twins, total=total - float(q @ b) ** 2,
                             n_eff=gram.rows, floor=bar * scale * sigma2_now)  # fmt: skip
        start = sorted({one, *(path[-1][0] if path else ())})
        other, _ = _prune_support(gram, i, start, scale, bar)
        if sorted(other) == sorted(now) or len(other) > len(now):
            continue  # larger: growth is grow_significant's (on clean data the residuals
            # are round-off, and a round-off "gain" passes any bar in its own variances)
        rss_other, sigma2_other = _residual_variance(gram, i, other)
        sigma2 = min(sigma2_now, sigma2_other) * scale
        cost_now = rss_now / sigma2 + bar * len(now)
        cost_other = rss_other / sigma2 + bar * len(other)
        if cost_other + F_CRITICAL >= cost_now:
            continue
        xi[i] = _refit(gram, i, other)
        notes.append(
            f"{state}': a path on centred columns (offsets removed: a cancelling pair such "
            f"as thrust and gravity enters there) gives {len(other)} terms "
            f"({_term_list(feature_names, other)}) in place of the path's {len(now)}"
            + (f" ({_term_list(feature_names, now)})" if len(now) <= 8 else "")
            + ": "
            f"penalised residual {cost_other:.4g} against {cost_now:.4g} residual variances "
            f"(each term costs {bar:.3g})"
        )
    return xi, notes


GROW_POOL = 10
"""Columns outside a support that enter :func:`grow_significant`'s pool: those that best explain
its residual (every near twin of a pooled column enters too)."""

SWAP_TOP = 5
"""Replacements tried for each term in :func:`grow_significant`'s exchange-and-add move: the
columns that best explain the residual of the support without that term."""


def _best_entries(
    a: np.ndarray, b: np.ndarray, support: Sequence[int], allowed: np.ndarray, n: int
) -> list[int]:
    """The ``n`` allowed columns whose entry beside ``support`` lowers the residual most."""
    if support:
        q = np.linalg.qr(a[:, list(support)])[0]
        resid = b - q @ (q.T @ b)
        perp = a - q @ (q.T @ a)
    else:
        resid, perp = b, a
    p2 = np.einsum("ij,ij->j", perp, perp)
    gains = np.where(allowed & (p2 > 1e-10), (perp.T @ resid) ** 2 / np.maximum(p2, 1e-300), 0)
    return [int(j) for j in np.argsort(gains)[::-1][:n] if gains[j] > 0]


def exchange_and_add(
    a: np.ndarray, b: np.ndarray, support: Sequence[int], usable: np.ndarray, twin: np.ndarray
) -> tuple[float, tuple[int, ...]] | None:
    """The best support one term larger reached by exchanging one term and adding another.

    Where a term stands in for a true one together with a missing second term, neither the
    exchange alone (it fits worse until the second enters) nor an addition alone (the
    stand-in already holds the direction) gains: on a held-out 6-DOF trial ``y'`` kept
    ``sin(phi) w`` (its coefficient an average of ``cos(psi)``) for ``sin(phi) cos(psi) w``
    and ``sin(psi) sin(theta) w``, and the model drifted 17.5 % of the range in 1 s where the
    yaw left the training range. For each term, the :data:`SWAP_TOP` columns that best
    explain the residual without it are tried in its place, each with its best next entry.
    Columns are unit-norm; no column enters beside a near twin (``twin``) of the support.

    Returns:
        ``(explained sum of squares, support)``, or None where no move is possible.
    """
    best: tuple[float, tuple[int, ...]] = (-np.inf, ())
    for j in support:
        rest = [c for c in support if c != j]
        allowed = usable & ~twin[:, rest].any(axis=1) if rest else usable.copy()
        allowed[list(support)] = False
        for k in _best_entries(a, b, rest, allowed, SWAP_TOP):
            base = [*rest, k]
            after = usable & ~twin[:, base].any(axis=1)
            after[[*base, j]] = False
            for extra in _best_entries(a, b, base, after, 1):
                trial = [*base, extra]
                explained = float(b @ b) - _rss(a, b, trial)[0]
                if explained > best[0]:
                    best = (explained, tuple(sorted(trial)))
    return best if best[1] else None


def _significance_bar(p: int) -> float:
    """Chi-square(1) at :data:`PRUNE_P` / p: the bar for the best of p candidate terms."""
    from scipy.stats import chi2

    return float(chi2.isf(PRUNE_P / max(p, 1), 1))


def grow_significant(
    xi: np.ndarray,
    gram: Gram,
    ratio: np.ndarray,
    feature_names: Sequence[str],
    state_names: Sequence[str],
) -> tuple[np.ndarray, list[str]]:
    """Adds the terms the data need where the greedy path, holding a wrong twin, stopped short.

    At small tilt the path can enter a twin of a true term (``sin(phi) sin(psi) w`` for
    ``sin(phi) sin(psi) cos(theta) w``); then a small true term is never its best next entry
    and the threshold stops the path before it. Here each equation's best supports of its
    size and of one term more are found exhaustively (:func:`~identification.stepwise.best_subset`)
    within a pool: the chosen terms, the :data:`GROW_POOL` columns that best explain the
    residual, and every near twin (|cos| > 0.99) of these; no two columns with
    |cos| > 0.999 together. The larger support is taken when it explains more than the
    significance bar of :func:`prune_insignificant` (the Bonferroni bar for the best of p
    terms, variance scaled by the long-run ratio), and the search repeats from it. Where no
    support of the pool does, :func:`exchange_and_add` looks outside it (one term exchanged,
    one added), against the Bonferroni bar for the moves it tries. Else the
    best support of the same size is taken when the data tell it from the current one
    (F-test, p = 0.001): the path's twin choices, each within the F-test of the one before,
    can add up to a support the data reject; :func:`resolve_collinear` then moves back to
    simpler twins only within the F-test of it.

    Returns:
        The coefficients (refitted where changed) and one note per equation grown.
    """
    from identification.stepwise import best_subset

    bar = _significance_bar(gram.p)
    moves_bar = bar  # the exchange-and-add bar, for a support of the size it grew from
    a = gram.r / np.maximum(gram.col_norms, 1e-300)
    g = a.T @ a
    cos = np.abs(g)
    np.fill_diagonal(cos, 0.0)
    near, twin = cos > 0.99, cos > 0.999
    usable = np.diag(g) > 0.5  # unit columns (an all-zero column has norm 0)
    xi = xi.copy()
    notes = []
    for i, state in enumerate(state_names):
        support = [int(j) for j in np.flatnonzero(xi[i])]
        if not support:
            continue
        b = gram.z[:, i]
        c = a.T @ b
        total = float(np.linalg.norm(gram.r_aug[:, gram.p + i]) ** 2)
        scale = max(float(ratio[i]), 1.0)
        start = list(support)
        while True:
            outside = usable.copy()
            outside[support] = False
            top = _best_entries(a, b, support, outside, GROW_POOL)
            base = sorted({*support, *top})
            pool = sorted({*base, *np.flatnonzero(near[:, base].any(axis=1) & usable)})
            now = best_subset(g, c, pool, len(support), twin)
            if now is None:  # more supports than the limit
                break
            explained_now = float(b @ b) - _rss(a, b, support)[0]
            bigger = best_subset(g, c, pool, len(support) + 1, twin)
            if bigger is not None:
                sigma2 = (total - bigger[0]) / max(float(gram.rows) - len(bigger[1]), 1.0)
                if bigger[0] - max(now[0], explained_now) > bar * scale * sigma2:
                    support = list(bigger[1])
                    continue
            moved = exchange_and_add(a, b, support, usable, twin)
            if moved is not None:  # its own bar: the best of |S| x SWAP_TOP x p moves
                sigma2 = (total - moved[0]) / max(float(gram.rows) - len(moved[1]), 1.0)
                moves_bar = _significance_bar(gram.p * len(support) * SWAP_TOP)
                if moved[0] - max(now[0], explained_now) > moves_bar * scale * sigma2:
                    support = list(moved[1])
                    continue
            sigma2 = (total - now[0]) / max(float(gram.rows) - len(now[1]), 1.0)
            if now[0] - explained_now > F_CRITICAL * sigma2:
                support = list(now[1])
            break
        if sorted(support) != sorted(start):
            xi[i] = _refit(gram, i, support)
            added = [j for j in support if j not in start]
            removed = [j for j in start if j not in support]
            notes.append(
                f"{state}': the best support of {len(support)} terms among the near twins of "
                f"its terms, its best next entries and one-term exchanges holds "
                f"{_term_list(feature_names, added)}"
                + (f" in place of {_term_list(feature_names, removed)}" if removed else "")
                + f" (a term more must explain {bar:.3g} x {scale:.3g} residual variances, "
                f"{moves_bar:.3g} x {scale:.3g} by an exchange; a support of the same size "
                f"{F_CRITICAL})"
            )
    return xi, notes


WINDOW_SHRINK = 0.5
"""A term the growth added is dropped where its coefficient at the next wider window is below
this share of its own (or of the other sign)."""


def drop_window_bias(
    xi: np.ndarray,
    path_xi: np.ndarray,
    gram: Gram,
    trajs: Sequence[Trajectory],
    names: list[str],
    wider: int,
    state_names: Sequence[str],
    window: int,
) -> tuple[np.ndarray, list[str]]:
    """Drops terms the growth added that fit the state noise's bias rather than the dynamics.

    Noise in the states enters both the integral target and the terms evaluated on the noisy
    states, so a short window carries an errors-in-variables bias (a new-user trial: 100
    planar flights at sigma = 1e-3, window 1, `phi' = phi_dot - 0.077 sin(phi)`, the growth
    taking the bias for a term: 100,000 rows make any bias significant). The bias falls as
    the window widens, a term of the dynamics keeps its coefficient. Each added term is
    refitted with its equation's support at the next wider window of the grid and dropped
    where its coefficient there is under :data:`WINDOW_SHRINK` of its own.

    Returns:
        The coefficients (refitted where changed) and one note per term dropped.
    """
    added = [(i, int(j)) for i in range(xi.shape[0]) for j in np.flatnonzero(xi[i])
             if path_xi[i, j] == 0]  # fmt: skip
    if not added:
        return xi, []
    wide = Gram.stack(grams(long_enough(trajs, wider), names, "rk4", wider, xi))
    xi = xi.copy()
    notes = []
    for i in sorted({i for i, _ in added}):
        support = [int(j) for j in np.flatnonzero(xi[i])]
        there = _refit(wide, i, support)
        gone = [j for k, j in added if k == i
                and there[j] * xi[i, j] < WINDOW_SHRINK * xi[i, j] ** 2]  # fmt: skip
        if not gone:
            continue
        for j in gone:
            notes.append(
                f"{state_names[i]}': dropped {term_name(parse_term(names[j]))!r}, which the "
                f"growth added: its coefficient is {xi[i, j]:.3g} at window {window} and "
                f"{there[j]:.3g} at window {wider}, as a bias of the states' noise shrinks "
                "with the window (a term of the dynamics keeps its coefficient)"
            )
        xi[i] = _refit(gram, i, [j for j in support if j not in gone])
    return xi, notes


def _term_list(feature_names: Sequence[str], columns: Sequence[int]) -> str:
    return ", ".join(repr(term_name(parse_term(feature_names[j]))) for j in columns)


def _prune_support(
    gram: Gram, i: int, support: list[int], scale: float, bar: float
) -> tuple[list[int], list[tuple[int, float]]]:
    """Equation ``i``'s backward elimination against ``bar`` residual variances.

    The cheapest term whose removal costs less than the bar (variance times ``scale``) goes,
    and the rest are refitted, until every term passes.

    Returns:
        The support left, and each removed column with its cost.
    """
    from identification.stepwise import _removal_costs

    support = list(support)
    removed = []
    while len(support) > 1:
        _, sigma2 = _residual_variance(gram, i, support)
        costs = _removal_costs(gram.r, gram.z[:, i], support) / (scale * sigma2)
        k = int(np.argmin(costs))
        if costs[k] >= bar:
            break
        removed.append((int(support.pop(k)), float(costs[k])))
    return support, removed


def prune_insignificant(
    xi: np.ndarray,
    gram: Gram,
    ratio: np.ndarray,
    feature_names: Sequence[str],
    state_names: Sequence[str],
) -> tuple[np.ndarray, list[str]]:
    """Backward elimination of the terms the data do not need, against an honest variance.

    A term of the model was chosen as the best of ``p`` candidates, so its removal cost must
    pass the Bonferroni bar for the best of ``p`` (chi-square(1) at :data:`PRUNE_P` / p), in
    residual variances scaled by the residuals' long-run ratio where that is above 1
    (:func:`long_run_ratio`). The cheapest failing term is removed and the rest refitted,
    until every term passes.

    Returns:
        The coefficients (refitted where changed) and one warning per equation pruned.
    """
    bar = _significance_bar(gram.p)
    xi = xi.copy()
    notes = []
    for i, state in enumerate(state_names):
        scale = max(float(ratio[i]), 1.0)
        support, removed = _prune_support(gram, i, list(np.flatnonzero(xi[i])), scale, bar)
        dropped = [f"{term_name(parse_term(feature_names[j]))!r} ({cost:.3g})"
                   for j, cost in removed]  # fmt: skip
        if dropped:
            xi[i] = _refit(gram, i, support)
            notes.append(
                f"{state}': dropped {', '.join(dropped)}: removing each costs less than "
                f"{bar:.3g} residual variances (the bar for the best of {gram.p} terms; "
                f"variance x {scale:.3g} for the residual's correlation over the window)"
            )
    return xi, notes


def indistinguishable_twins(
    xi: np.ndarray,
    gram: Gram,
    feature_names: Sequence[str],
    state_names: Sequence[str],
    window: int,
) -> tuple[list[str], set[tuple[int, int, int]]]:
    """Warnings for chosen terms whose near-collinear twins fit the data as well.

    For each chosen term with a near-collinear twin (see :func:`collinear_pairs`) outside the
    model, the twin is put in its place; when the residual changes by no more than the F-test
    resolves (p = 0.001, every row an effective sample), the data cannot tell the two
    apart. One warning per chosen term names it and all such twins with their residual
    changes (the kept term is the simpler, by construction).

    Returns:
        The warnings, and the pairs they cover as (equation, simple column, complex column).
    """
    pairs = collinear_pairs(gram, feature_names)
    if not pairs:
        return [], set()
    a, z = gram.r, gram.z
    groups: dict[tuple[int, int], list[tuple[int, float, float]]] = {}
    covered = set()
    for i in range(len(state_names)):
        support = list(np.flatnonzero(xi[i]))
        if not support:
            continue
        rss, sigma2 = _residual_variance(gram, i, support)
        for simple, complex_, cosine in pairs:
            for kept, other in ((simple, complex_), (complex_, simple)):
                if kept not in support or other in support:
                    continue
                trial = [other if c == kept else c for c in support]
                change = _rss(a, z[:, i], trial)[0] - rss
                if abs(change) <= F_CRITICAL * sigma2:  # neither fits significantly better
                    groups.setdefault((i, kept), []).append(
                        (other, change / max(sigma2, 1e-300), cosine)
                    )
                    covered.add((i, simple, complex_))  # fmt: skip
    notes = []
    for (i, kept), others in groups.items():
        listed = ", ".join(f"{_term_list(feature_names, [o])} ({c:.3g})" for o, c, _ in others)
        notes.append(
            f"{state_names[i]}': kept {_term_list(feature_names, [kept])}; its nearly collinear "
            f"twin{'s' if len(others) > 1 else ''} on this data fit it equally well: {listed} "
            f"(residual change in variances with the twin in its place; |cos| >= "
            f"{min(c for *_, c in others):.6f}; the F-test needs {F_CRITICAL})"
        )
    return notes, covered


# -- the entry point --------------------------------------------------------------------
@serial_blas
def select_model(
    trajs: Sequence[Trajectory],
    library: Sequence[str],
    *,
    config: FitConfig | None = None,
    lambdas: Sequence[float] = SELECT_LAMBDAS,
    windows: Sequence[int] = WINDOWS,
    folds: int = 5,
    horizon: int = 50,
    n_models: int = 20,
    seed: int = 0,
    system: str | None = None,
    progress: bool = False,
    drop_outliers: bool = False,
    _cut: tuple[str, ...] = (),
) -> tuple[IdentifiedModel, SelectionReport]:
    """Identifies a model and chooses its sparsity and window from the data alone.

    Args:
        trajs: The data (one or more trajectories / clean segments, same variables).
        library: Candidate feature names.
        config: Base fit settings (formulation and optimizer); ``lam`` and ``window`` are
            chosen here. Default: the RK4 formulation with the ``stepwise`` optimizer
            (:mod:`identification.stepwise`).
        lambdas: Scaled thresholds to try.
        windows: Integral windows to try.
        folds: Largest number of folds.
        horizon: Prediction horizon of the score [steps].
        n_models: Bootstrap bags for the coefficient uncertainty (0: none).
        seed: Seed of the bootstrap.
        system: Optional vehicle label stored in the model.
        progress: Show a progress bar.
        drop_outliers: Cut out the steps whose residual stands out of their neighbours'
            (:func:`outlying_steps`) before selecting, under a fit of the whole library; and
            where the selected model's own residuals show more, cut those too and select
            once more. By default they are only reported.
        _cut: Internal: the notes of steps already cut (the second selection).

    Returns:
        The model (scores in ``meta["selection"]``, ensemble statistics attached) and the
        report. Each of the report's notes is also issued as an
        :class:`identification.data.IdentificationWarning`.

    Raises:
        ValueError: Unidentifiable data (see :func:`identification.fit.check_identifiable`),
            every candidate with terms diverged, or the chosen model has no term (nothing
            predicts the held-out data better than holding the state).
    """
    from tqdm import tqdm

    if isinstance(trajs, Trajectory):
        trajs = [trajs]
    if not trajs:
        raise ValueError("no trajectories to fit")
    first = trajs[0]
    if any((t.state_names, t.input_names) != (first.state_names, first.input_names) for t in trajs):
        raise ValueError("all trajectories must have the same state and input names")
    _check_settings(folds, lambdas, windows, horizon, n_models)
    if isinstance(library, str):  # a preset or a spec ("planar", "degree=2;angles=phi")
        library = library_from_spec(library, first.state_names, first.input_names)
    if library is None or len(library) == 0:
        raise ValueError("the library is empty: give feature names, a preset or a spec")
    variables = [*first.state_names, *first.input_names]
    names = [term_name(parse_term(n, variables)) for n in library]
    base = config or FitConfig(optimizer="stepwise")
    TALLY.counts.clear()
    one_step = Gram.stack(grams(trajs, names, "forward", 1))
    check_identifiable(one_step, names, trajs)
    trajs, stamped = stamp_jitter(trajs, names, one_step)
    # The stage points need an rhs accurate near the data. Dense least squares is that on a
    # well-conditioned library; on a nearly singular one (6-DOF at small tilt, condition 6e11)
    # it is accurate on the data but wild half a step off it, so the stepwise optimizer uses
    # its own least sparse model of the grid (the smallest threshold) instead.
    positive = [float(v) for v in lambdas if v > 0]
    pilot_lam = min(positive) if base.optimizer == "stepwise" and positive else 0.0
    outliers = None
    if drop_outliers and base.derivative not in ("rk4", "forward"):
        raise ValueError(
            f"drop_outliers works with the rk4 and forward formulations, not {base.derivative!r}"
        )
    if drop_outliers:
        cfg = dataclasses.replace(base, lam=pilot_lam, window=1, iterations=2, full_path=True)
        flagged = outlying_steps(trajs, names, base.derivative,
                                 fit_coefficients(trajs, names, cfg))  # fmt: skip
        if flagged:
            kept, lost = cut_steps(trajs, flagged)
            if not kept:
                raise ValueError("no piece of the data is long enough once the outlying "
                                 "steps are cut out")  # fmt: skip
            outliers = outlier_note(trajs, flagged, True, lost)
            trajs = kept
    asked = sorted({int(w) for w in windows})
    horizon_asked = horizon
    units, windows, horizon = validation_units(trajs, folds, windows, horizon)
    if not set(asked) & set(windows):
        raise ValueError(
            f"every window asked ({asked}) is too long for this data: windows up to a quarter "
            f"of the typical segment ({typical_length(trajs)} rows) fit; window "
            f"{max(windows)} does"
        )
    k = min(folds, len(units))
    fold_of = np.arange(len(units)) % k
    scale = score_scale(units, horizon)

    # Each window's pilot starts from the previous window's (a forward-difference start only
    # for the first): its stage points are then accurate from the first pass, which keeps the
    # sparse paths short (6-DOF: a third of the time).
    candidates: list[Candidate] = []
    models: list[np.ndarray] = []  # each candidate's fit on all data
    pilots: dict[int, np.ndarray] = {}
    pilot = None
    steps = tqdm(total=len(windows) * (k + 1), desc="selecting", disable=not progress)
    for w in windows:
        pilot_cfg = dataclasses.replace(base, lam=pilot_lam, window=w, iterations=2,
                                        full_path=True)  # fmt: skip
        pilot = fit_coefficients(long_enough(units, w), names, pilot_cfg, pilot)
        pilots[w] = pilot
        fitted = iter(grams(long_enough(units, w), names, base.derivative, w, pilot))
        unit_grams = [next(fitted) if len(u) > w else Gram.zeros(len(names), len(first.state_names))
                      for u in units]  # fmt: skip
        # candidates are the forward paths; the chosen one is refitted with the backward check
        grid_cfg = dataclasses.replace(base, window=w, backward=False)
        scores = np.full((len(lambdas), k), np.inf)
        fold_eqs = np.zeros((len(lambdas), len(first.state_names)))  # folds with terms there
        for f in range(k):
            train = Gram.stack([g for g, fo in zip(unit_grams, fold_of, strict=True) if fo != f])
            held = [u for u, fo in zip(units, fold_of, strict=True) if fo == f]
            try:
                fold_xis = solve_lambdas(train, grid_cfg, lambdas, names)
            except (np.linalg.LinAlgError, ValueError, FloatingPointError):
                steps.update()
                continue
            fold_eqs += np.any(fold_xis != 0, axis=2)
            for li, xi in enumerate(fold_xis):
                try:
                    rhs = compile_rhs(names, xi, first.state_names, first.input_names)
                    scores[li, f] = prediction_score(rhs, held, scale, horizon)
                except (np.linalg.LinAlgError, ValueError, FloatingPointError):
                    scores[li, f] = np.inf
            steps.update()
        full = Gram.stack(unit_grams)
        full_xis = solve_lambdas(full, grid_cfg, lambdas, names)
        for li, (lam, xi) in enumerate(zip(lambdas, full_xis, strict=True)):
            # The scores must be the candidate's own: where the fit on all data leaves an
            # equation empty that most fold fits filled (an exact one-term equation sits on
            # the threshold lam = 1, and round-off decides), the folds scored another model.
            # Kept, it won as the sparsest (x' = v dropped on clean data).
            if np.any(~np.any(xi != 0, axis=1) & (fold_eqs[li] > k / 2)):
                scores[li] = np.inf
            empty = tuple(int(i) for i in np.flatnonzero(~np.any(xi != 0, axis=1)))
            candidates.append(Candidate(w, float(lam), int(np.count_nonzero(xi)),
                                        list(scores[li]), empty))  # fmt: skip
            models.append(xi)
        steps.update()
    steps.close()
    top = compile_rhs(names, models[best_candidate(candidates)], first.state_names,
                      first.input_names)  # fmt: skip
    resolution = float(np.mean(integrator_resolution(top, units, scale, horizon, per_log=True)))
    chosen = choose_one_se(candidates, resolution)
    best = candidates[chosen]
    rule = (
        f"{k}-fold cross-validation over {'trajectories' if len(trajs) >= 3 else 'blocks'}; "
        f"score = RMS of the {horizon}-step open-loop prediction error normalised by each "
        "state's scale (the smaller of its standard deviation and the error of holding it "
        "over the horizon); chosen: the fewest terms within one standard error of "
        f"the best mean score plus the scores' own integrator error ({resolution:.2g}); "
        "refitted on all data with the backward-elimination check; an equation replaced by a "
        "path on centred columns where that has no more terms and a penalised residual lower "
        "by the F-test's bar; each equation grown to its "
        "best support one term larger among its terms' near twins and best next entries (or "
        "one exchange plus one addition) where that passes the Bonferroni bar (a grown term "
        "kept only where its coefficient holds at the next wider window); terms that do "
        "not pass the bar against the residuals' long-run variance dropped"
    )
    report = SelectionReport(candidates, chosen, k, horizon, rule)
    report.warnings += data_warnings(trajs, names)
    report.warnings += [*([stamped] if stamped else []), *_cut,
                        *([outliers] if outliers else [])]  # fmt: skip
    still = lambda x, u: np.zeros_like(x)  # noqa: E731
    report.hold = float(np.mean([
        prediction_score(still, [u for u, fo in zip(units, fold_of, strict=True) if fo == f],
                         scale, horizon)
        for f in range(k)
    ]))  # fmt: skip
    if best.mean > POOR_FIT * report.hold:
        report.warnings.append(
            f"the model predicts the held-out data {horizon} steps ahead with "
            f"{best.mean / report.hold:.0%} of the error of holding the state ({best.mean:.3g} "
            f"against {report.hold:.3g}): the library may lack the dynamics, the inputs may "
            "not explain the states, or the states are noisy (then the error is mostly the "
            "noise, and a right model scores no better)"
        )

    validated = len(report.warnings)  # the notes below describe the checks' model
    final_cfg = dataclasses.replace(base, lam=best.lam, window=best.window)
    used = long_enough(trajs, best.window)  # the segments this window's rows come from
    xi = fit_coefficients(used, names, final_cfg, pilots[best.window])
    final_gram = Gram.stack(grams(used, names, "rk4", best.window, xi))
    ratio = long_run_ratio(used, names, xi, best.window)
    path_xi = xi
    xi, notes = restart_centred(xi, final_gram, ratio, names, first.state_names)
    report.warnings += notes
    xi, notes = grow_significant(xi, final_gram, ratio, names, first.state_names)
    report.warnings += notes
    wider = [w for w in sorted(windows) if w > best.window and long_enough(used, w)]
    if wider:
        xi, notes = drop_window_bias(xi, path_xi, final_gram, used, names, wider[0],
                                     first.state_names, best.window)  # fmt: skip
        report.warnings += notes
    grown = {i: list(np.flatnonzero(xi[i])) for i in range(xi.shape[0])
             if set(np.flatnonzero(xi[i])) != set(np.flatnonzero(path_xi[i]))}  # fmt: skip
    xi, resolved = resolve_collinear(xi, final_gram, names, first.state_names, best.window)
    xi, notes = prune_insignificant(xi, final_gram, ratio, names, first.state_names)
    report.warnings += notes
    twins, covered = indistinguishable_twins(xi, final_gram, names, first.state_names,
                                             best.window)  # fmt: skip
    report.warnings += [note for key, note in resolved.items() if key not in covered] + twins
    std = prob = None
    if n_models > 0:
        xi, std, prob, held, dropped = _bootstrap(used, names, final_cfg, xi, n_models, seed,
                                                  grown, ratio)  # fmt: skip
        report.warnings += dropped
        # a term whose near twin the other bags hold is not unsettled (its twin note says so)
        report.warnings += _weak_terms_note(xi, std, held, names, first.state_names)
    xi, note = _predicts_as_validated(xi, models[chosen], units, scale, horizon, resolution,
                                      names, first)  # fmt: skip
    if note:  # the checks' model is not returned: neither its notes nor statistics apply
        report.warnings = [*report.warnings[:validated], note]
        std = prob = None
    else:  # a growth note describes its support: drop it where later checks changed that
        moved = [i for i, cols in grown.items() if set(np.flatnonzero(xi[i])) != set(cols)]
        stale = tuple(f"{first.state_names[i]}': the best support of" for i in moved)
        report.warnings = [w for w in report.warnings if not w.startswith(stale)]
    if not np.any(xi):
        raise ValueError(_empty_model_message(candidates, report.hold))
    shifted = input_shift_note(used, names, best.window, xi, ratio)
    shifted = shifted or state_shift_note(used, names, best.window, xi, ratio)
    shifted = shifted or angle_offset_note(xi, names, first.state_names)
    if shifted:  # before the notes it causes (outlying steps, misfit)
        report.warnings.append(shifted)
    if base.derivative in ("rk4", "forward"):
        # The returned model's own residuals: sparse, it cannot bend to bad steps as a fit of
        # the whole library does (4 % of the steps with a wrong input hid from such a fit).
        flagged = outlying_steps(trajs, names, base.derivative, xi)
        if flagged and drop_outliers:  # cut these too and select once more
            kept, lost = cut_steps(trajs, flagged)
            if kept:
                done = (*_cut, *([outliers] if outliers else []),
                        outlier_note(trajs, flagged, True, lost))  # fmt: skip
                return _warned(*select_model(
                    kept, names, config=config, lambdas=lambdas, windows=asked, folds=folds,
                    horizon=horizon_asked, n_models=n_models, seed=seed, system=system,
                    progress=progress, drop_outliers=False, _cut=done,
                ))  # fmt: skip
        if flagged:
            note = outlier_note(trajs, flagged, False)
            report.warnings.append(f"after cutting, still: {note}" if _cut else note)
    named = any("robust deviations" in w for w in report.warnings)
    misfit = misfit_note(used, names, base.derivative, xi, outliers=named)
    if misfit:
        report.warnings.append(misfit)
    report.final_terms = int(np.count_nonzero(xi))
    tally = TALLY.summary()
    if tally:
        report.warnings.append(tally)
    meta = {
        **final_cfg.label,
        "n_trajectories": len(trajs),
        **({"measured_inputs": list(trajs[0].measured)} if trajs[0].measured else {}),
        "n_samples": int(sum(len(t) for t in trajs)),
        "dt": first.dt,
        "ranges": data_ranges(trajs),
        "selection": report.to_meta(),
    }
    model = IdentifiedModel(names, xi, first.state_names, first.input_names, system, meta,
                            std, prob)  # fmt: skip
    return (model, report) if _cut else _warned(model, report)


def _warned(
    model: IdentifiedModel, report: SelectionReport
) -> tuple[IdentifiedModel, SelectionReport]:
    """Issues each of the report's notes as an :class:`IdentificationWarning`.

    API users see them without reading ``report.warnings``; the CLI prints the list instead.
    """
    for note in report.warnings:
        warnings.warn(note, IdentificationWarning, stacklevel=4)  # past serial_blas
    return model, report


OUTLIER_Z = 10.0
"""A row stands out where its one-step residual departs from its neighbours' by more than this
many robust deviations (Gaussian noise: a chance of 1e-23 per row)."""

OUTLIER_FLOOR = 1e-3
"""Departures under this share of the target's spread are not judged: on clean data the robust
deviation is near round-off, and a fit bent by a few bad steps misfits its other steps by more
(15 of 19 flags false on a trial's clean log before)."""


def outlying_steps(
    trajs: Sequence[Trajectory], names: list[str], derivative: str, xi: np.ndarray
) -> dict[int, np.ndarray]:
    """The steps whose residual stands out of their neighbours', per trajectory.

    The residual of each step (window 1) under ``xi`` (a fit of the whole library, or the
    selected model) is compared with the median of its 11 neighbours; a step stands out
    where that departure exceeds :data:`OUTLIER_Z` robust deviations (1.4826 times the
    median absolute departure, per equation, at least :data:`OUTLIER_FLOOR` of the target's
    spread). Smooth misfit (a missing drag term) moves the neighbours too; an input that did
    not act as logged (a command that saturated the rotors, a glitch) does not.

    Returns:
        {trajectory index: (rows, states) mask}, rows in the order :func:`iter_rows` yields
        them (the observed steps); empty where nothing stands out or a formulation other
        than the step-wise ones is used.
    """
    from scipy.ndimage import median_filter

    if derivative not in ("rk4", "forward"):
        return {}
    parts: dict[int, list[np.ndarray]] = {}
    targets = []
    with np.errstate(all="ignore"):
        for i, theta, y in iter_rows(trajs, names, derivative, 1, xi):
            parts.setdefault(i, []).append(y - theta @ xi.T)
            targets.append(y)
        local = {}
        for i, chunks in parts.items():
            r = np.concatenate(chunks)
            local[i] = r - median_filter(r, size=(11, 1), mode="nearest")
        stacked = np.concatenate(list(local.values()))
        if not np.all(np.isfinite(stacked)):
            return {}
        floor = OUTLIER_FLOOR * np.concatenate(targets).std(axis=0)
        deviation = np.maximum(1.4826 * np.median(np.abs(stacked), axis=0), floor)
        deviation = np.where(deviation > 0, deviation, 1.0)
        flagged = {i: np.abs(v) / deviation > OUTLIER_Z for i, v in local.items()}
    return {i: f for i, f in flagged.items() if f.any()}


def _relative_residuals(
    trajs: Sequence[Trajectory], names: list[str], derivative: str, window: int, xi: np.ndarray
) -> np.ndarray:
    """Per equation, the RMS residual of ``xi`` at ``window`` over the target's spread."""
    total = np.zeros(xi.shape[0])
    targets: list[np.ndarray] = []
    count = 0
    with np.errstate(all="ignore"):
        for _, theta, y in iter_rows(trajs, names, derivative, window, xi):
            total += np.sum((y - theta @ xi.T) ** 2, axis=0)
            count += len(y)
            targets.append(y)
        spread = np.concatenate(targets).std(axis=0) if targets else np.ones(xi.shape[0])
    return np.sqrt(total / max(count, 1)) / np.where(spread > 0, spread, 1.0)


def misfit_note(
    trajs: Sequence[Trajectory],
    names: list[str],
    derivative: str,
    xi: np.ndarray,
    outliers: bool = False,
) -> str | None:
    """A warning for equations whose residual is not white noise (see :data:`MISFIT_SHRINK`).

    The residual of the model at window 1 and at :data:`MISFIT_WINDOW` is compared: white
    measurement noise in the targets shrinks about as 1 / window, while a term the library
    lacks (Z-Y-X angles logged under Z-X-Y names) leaves the same residual at every window.
    Residuals at round-off (:data:`MISFIT_FLOOR`) are not judged. Filtered (time-correlated)
    noise shrinks less too, so the note names that cause as well, and a few bad steps
    (``outliers``: some were named) do not shrink either. A misfit well under the noise at
    window 1 is not seen (a missing `cos(phi) u1` at sigma = 1e-3 and tilts of 0.3 rad).
    """
    if derivative not in ("rk4", "forward"):
        return None
    usable = long_enough(trajs, 4 * MISFIT_WINDOW)
    if not usable:
        return None
    one = _relative_residuals(usable, names, derivative, 1, xi)
    wide = _relative_residuals(usable, names, derivative, MISFIT_WINDOW, xi)
    flagged = [i for i in range(len(one))
               if one[i] > MISFIT_FLOOR and one[i] < MISFIT_SHRINK * wide[i]]  # fmt: skip
    if not flagged:
        return None
    states = trajs[0].state_names
    listed = ", ".join(f"{states[i]}' ({one[i]:.2g} at window 1, {wide[i]:.2g} at "
                       f"{MISFIT_WINDOW})" for i in flagged)  # fmt: skip
    return (
        f"the residual of {listed} (a share of each target's spread) does not shrink with the "
        "integral window as measurement noise does: the library may lack a term, the "
        "variables may follow another convention (Z-Y-X angles, world-frame velocities), "
        + ("the outlying steps named above may cause it, " if outliers else "")
        + "or the states' noise is correlated in time (filtered estimates)"
    )


INPUT_SHIFTS = (-3, -2, -1, 1, 2, 3)
"""Shifts of the inputs [rows] that :func:`input_shift_note` tries."""

SHIFT_GAIN = 0.9
"""A shift is named only where it leaves at most this share of an equation's residual."""


def input_shift_note(
    trajs: Sequence[Trajectory],
    names: list[str],
    window: int,
    xi: np.ndarray,
    ratio: np.ndarray,
    command: str = "identify again",
) -> str | None:
    """A warning where the model's equations fit better with the inputs shifted a few rows.

    A log that records each input a row late (a new-user trial: the 1-step delay of a
    logger) is fitted with made-up damping and controller-shaped terms, and the model drifts
    24 % of the roll range in 1 s; no other check named it. Each shift of
    :data:`INPUT_SHIFTS` refits the model's own terms on the same rows (``max |shift|`` rows
    cut at both ends of every segment) with the inputs taken that many rows later (or
    earlier). A shift is named where, in an equation with an input term, it leaves at most
    :data:`SHIFT_GAIN` of the residual and the drop passes the Bonferroni bar for the shifts
    and equations tried (in residual variances, times the long-run ratio ``ratio``), and no
    such equation fits worse by as much: a log's delay shifts every input, so on aligned
    data every shift fits worse. On states with AR(1) noise (a trial: aligned inputs, the
    model within 0.05 %) `score`, then without the long-run ratio, named a shift that made
    `y_dot'` fit 15 to 30 % better and `z_dot'`, `phi_dot'` far worse; following it raised
    the held-out score 30 times.
    """
    inputs = set(trajs[0].input_names)
    variables = [*trajs[0].state_names, *trajs[0].input_names]
    driven = [i for i in range(xi.shape[0])
              if any(f.var in inputs for j in np.flatnonzero(xi[i])
                     for f in parse_term(names[j], variables))]  # fmt: skip
    margin = max(abs(d) for d in INPUT_SHIFTS)
    usable = long_enough(trajs, window + 2 * margin + 2)
    if not driven or not usable:
        return None
    refit = _own_terms_refit(xi, names, window, driven)

    def residuals(shift: int) -> tuple[np.ndarray, np.ndarray]:
        return refit([t.shift_inputs(shift, margin) for t in usable])

    rss0, sigma0 = residuals(0)
    bar = _significance_bar(len(INPUT_SHIFTS) * len(driven))
    scale = np.maximum(np.asarray(ratio, dtype=float)[driven], 1.0)
    best: tuple[float, int, np.ndarray] | None = None
    for shift in INPUT_SHIFTS:
        rss, sigma2 = residuals(shift)
        passes = (rss <= SHIFT_GAIN * rss0) & (rss0 - rss > bar * scale * sigma2)
        worse = rss - rss0 > bar * scale * sigma0
        if passes.any() and not worse.any():
            share = float(np.min(rss / np.maximum(rss0, 1e-300)))
            if best is None or share < best[0]:
                best = (share, shift, rss / np.maximum(rss0, 1e-300))
    if best is None:
        return None
    _, shift, shares = best
    states = trajs[0].state_names
    pairs = [(states[i], share) for i, share in zip(driven, shares, strict=True)]
    listed = ", ".join(f"{s}' to {100 * r:.2g} %" for s, r in pairs if r <= SHIFT_GAIN)
    applied = int(trajs[0].meta.get("input_shift", 0))  # already shifted by --input-shift
    widest = max(INPUT_SHIFTS)
    cause = (
        "the log may record the inputs late"
        if shift > 0
        else "the actuators may lag (a motor's time constant: the library lacks it), the "
        "states may be filtered estimates that lag the inputs (a low-pass filter or a state "
        "estimator; no shift undoes a filter), or the log records the inputs early"
    )
    return (
        f"the model's terms fit the data better with the inputs taken {abs(shift)} row(s) "
        f"{'later' if shift > 0 else 'earlier'} (residual {listed}; shifts up to {widest} "
        f"rows tried): {cause}; {command} with --input-shift {applied + shift} if the "
        "log is off (the other warnings may be its symptoms)"
    )


def _own_terms_refit(xi: np.ndarray, names: Sequence[str], window: int, rows: Sequence[int]) -> Any:
    """Per data set, RSS and residual variance of equations ``rows`` on the model's own terms.

    Each equation is refitted on its terms in ``xi`` (RK4 rows at ``window``, stage points
    from ``xi``): the shift notes compare the same model on shifted copies of the data.
    """
    cols = sorted({int(j) for j in np.flatnonzero(np.any(xi != 0, axis=0))})
    sub, xs = [names[j] for j in cols], xi[:, cols]
    supports = {i: [k for k, j in enumerate(cols) if xi[i, j] != 0] for i in rows}

    def residuals(part: Sequence[Trajectory]) -> tuple[np.ndarray, np.ndarray]:
        g = Gram.stack(grams(part, sub, "rk4", window, xs))
        pairs = [_residual_variance(g, i, supports[i]) for i in rows]
        return np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])

    return residuals


def _state_taken_later(tr: Trajectory, state: int, rows: int, margin: int) -> Trajectory:
    """``tr`` with state column ``state`` taken ``rows`` rows later, ``margin`` rows cut."""
    part = tr.slice(margin, len(tr) - margin)
    part.x = part.x.copy()
    part.x[:, state] = tr.x[margin + rows : len(tr) - margin + rows, state]
    return part


def state_shift_note(
    trajs: Sequence[Trajectory],
    names: list[str],
    window: int,
    xi: np.ndarray,
    ratio: np.ndarray,
) -> str | None:
    """A warning where the model's terms fit better with one state's column shifted a few rows.

    Logged states are often a state estimator's output, and its velocity and rate estimates
    lag the positions and angles (a trial's steady-state Kalman filter: about 2 rows). The
    selection then builds the lag into the model (``phi' = phi_dot + 0.18 u2``, gravity 7 %
    off, 18.7 % of the roll range at 1 s on clean flights) and no other check names it:
    the inputs are aligned. Each state's column is taken each of :data:`INPUT_SHIFTS` rows
    later (``max |shift|`` rows cut at both ends of every segment) and the model's own terms
    refitted. A state is named where, in some equation, a shift leaves at most
    :data:`SHIFT_GAIN` of the residual and the drop passes the Bonferroni bar for the states,
    shifts and equations tried (in residual variances, times the long-run ratio ``ratio``),
    and the equations the column enters gain together (the geometric mean of their residual
    shares is under 1; an adversarial trial's 1-row lag of phi went unnamed while each
    equation had to gain: a term the lag made up fitted 460 times worse once aligned): on
    consistent data every shift of a column fits worse.
    """
    states = trajs[0].state_names
    margin = max(abs(d) for d in INPUT_SHIFTS)
    usable = long_enough(trajs, window + 2 * margin + 2)
    rows = [i for i in range(xi.shape[0]) if np.any(xi[i])]
    if not usable or not rows:
        return None
    residuals = _own_terms_refit(xi, names, window, rows)
    rss0, sigma0 = residuals([t.slice(margin, len(t) - margin) for t in usable])
    bar = _significance_bar(len(states) * len(INPUT_SHIFTS) * len(rows))
    scale = np.maximum(np.asarray(ratio, dtype=float)[rows], 1.0)
    variables = [*states, *trajs[0].input_names]
    reads = [{f.var for j in np.flatnonzero(xi[i]) for f in parse_term(names[j], variables)}
             for i in rows]  # fmt: skip
    found: list[tuple[float, int, int, np.ndarray]] = []
    for s in range(len(states)):
        # the equations the column enters: its own, and those whose terms read it (the RK4
        # stage points couple the others only through the model's own error)
        mine = np.array([i == s or states[s] in used for i, used in zip(rows, reads,
                                                                         strict=True)])  # fmt: skip
        best: tuple[float, int, int, np.ndarray] | None = None
        for shift in INPUT_SHIFTS:
            rss, sigma2 = residuals([_state_taken_later(t, s, shift, margin) for t in usable])
            passes = mine & (rss <= SHIFT_GAIN * rss0) & (rss0 - rss > bar * scale * sigma2)
            shares = np.where(mine, rss / np.maximum(rss0, 1e-300), 1.0)
            # a term the lag made up (sin(phi) u2 in z') fits worse once the column is
            # aligned: the equations it enters must gain together (their shares' geometric
            # mean), not each one
            gain = np.exp(np.mean(np.log(np.maximum(shares[mine], 1e-300))))
            if passes.any() and gain < 1.0:
                if best is None or shares.min() < best[0]:
                    best = (float(shares.min()), s, shift, shares)
        if best is not None:
            found.append(best)
    if not found:
        return None
    found.sort()
    parts = []
    for _, s, shift, shares in found[:3]:
        listed = ", ".join(f"{states[i]}' to {100 * r:.2g} %"
                           for i, r in zip(rows, shares, strict=True)
                           if r <= SHIFT_GAIN)  # fmt: skip
        when = "later" if shift > 0 else "earlier"
        parts.append(f"{states[s]} taken {abs(shift)} row(s) {when} (residual {listed})")
    return (
        f"the model's terms fit the data better with {'; '.join(parts)}; shifts up to "
        f"{max(INPUT_SHIFTS)} rows tried: the log's states are not simultaneous (a state "
        "estimator's or filter's lag in some of them, velocities differentiated off-centre, "
        "a sensor read late), and the model holds terms that stand in for the offset; align "
        "the columns (or log the raw measurements) and identify again"
    )


def _step_rows(tr: Trajectory) -> np.ndarray:
    """The rows whose steps :func:`iter_rows` yields at window 1 (both ends observed)."""
    seen = tr.observed
    return np.flatnonzero(seen[:-1] & seen[1:])


def cut_steps(
    trajs: Sequence[Trajectory], flagged: dict[int, np.ndarray]
) -> tuple[list[Trajectory], int]:
    """The trajectories split at the flagged steps; pieces under :data:`MIN_UNIT_ROWS` go.

    Returns:
        The pieces and the number of rows lost in pieces too short to keep.
    """
    out: list[Trajectory] = []
    lost = 0
    for i, tr in enumerate(trajs):
        if i not in flagged:
            out.append(tr)
            continue
        start = 0
        for k in [*_step_rows(tr)[flagged[i].any(axis=1)], len(tr) - 1]:
            stop = int(k) + 1  # the piece keeps sample k, not the step from k to k + 1
            if stop - start >= MIN_UNIT_ROWS:
                out.append(tr.slice(start, stop))
            else:
                lost += stop - start
            start = stop
    return out, lost


def outlier_note(
    trajs: Sequence[Trajectory], flagged: dict[int, np.ndarray], dropped: bool, lost: int = 0
) -> str:
    """What :func:`outlying_steps` found, and whether the steps were cut out."""
    count = int(sum(f.any(axis=1).sum() for f in flagged.values()))
    total = sum(len(_step_rows(t)) for t in trajs)
    where = sorted({trajs[0].state_names[j] for f in flagged.values()
                    for j in np.flatnonzero(f.any(axis=0))})  # fmt: skip
    places = sorted((i, float(trajs[i].t[k])) for i, f in flagged.items()
                    for k in _step_rows(trajs[i])[f.any(axis=1)])  # fmt: skip
    several = len(trajs) > 1  # each segment's clock may start at 0: name the segment
    shown = ", ".join(f"{t:.4g}" + (f" (segment {i + 1})" if several else "")
                      for i, t in places[:6]) + (", ..." if len(places) > 6 else "")  # fmt: skip
    found = (
        f"{count} step(s) of {total} stand more than {OUTLIER_Z:g} robust deviations out of "
        f"their neighbours' residuals in {', '.join(w + chr(39) for w in where)} "
        f"(at t = {shown} s): inputs that did not act as logged (saturated actuators: log the "
        "applied inputs), glitches, or abrupt effects the library lacks (gusts)"
    )
    if dropped:
        lost_note = f"; {lost} rows in pieces too short to keep" if lost else ""
        return f"cut out before selecting: {found}{lost_note}"
    return (
        f"{found}; kept (on real flights cutting them out predicted held-out flights worse): "
        "--drop-outliers (drop_outliers=True) cuts them out"
    )


TRIG_KINDS = ("sin", "cos", "tan", "sec")


def trig_variables(feature_names: Sequence[str]) -> set[str]:
    """The variables a library puts inside sin, cos, tan or sec (its angles)."""
    return {f.var for term in feature_names for f in parse_term(term) if f.kind in TRIG_KINDS}


def data_warnings(trajs: Sequence[Trajectory], feature_names: Sequence[str] = ()) -> list[str]:
    """Signs that the data are not in the units the fit assumes: seconds and radians.

    A step of a second or more is a log in milliseconds read as seconds (rates 1000 times too
    small); a variable inside sin/cos/tan/sec past 2 pi is an angle in degrees, or one that
    turns several times (fine); one that jumps by about 2 pi between rows was wrapped.
    """
    notes = []
    dt = float(np.median([t.dt for t in trajs]))
    if dt >= 1.0:  # the unit that brings the step under a second
        name, per = next((n, p) for n, p in (("nanoseconds", 1e9), ("microseconds", 1e6),
                                             ("milliseconds", 1e3)) if dt >= p / 1e3)  # fmt: skip
        flag = {"milliseconds": "ms", "microseconds": "us", "nanoseconds": "ns"}[name]
        notes.append(
            f"the time step is {dt:g} s: a log in {name} gives rates {per:g} times too small "
            f"(say its unit: --time-unit {flag}, or time_unit={1 / per:g} in load_data)"
        )
    names = [*trajs[0].state_names, *trajs[0].input_names]
    inside = trig_variables(feature_names)
    peaks = np.max([np.abs(np.column_stack([t.x, t.u])).max(axis=0) for t in trajs], axis=0)
    # a log that wrapped an angle at +-pi logged it in radians (a spinning flight)
    wrapped = {n for t in trajs for n in t.meta.get("unwrapped", ())}
    notes += [
        f"{name} reaches {peak:.3g} inside sin/cos: angles are in radians (a log in degrees "
        "gives wrong models: say its unit, --angle-unit deg or angle_unit=pi/180 in "
        "load_data; an angle that turns several times is fine)"
        for name, peak in zip(names, peaks, strict=True)
        if name in inside and peak > 2 * np.pi and name not in wrapped
    ]
    notes += _frozen(trajs)
    notes += _unit_mismatch(trajs, inside)
    jumps = np.max([np.abs(np.diff(np.column_stack([t.x, t.u]), axis=0)).max(axis=0)
                    for t in trajs], axis=0)  # fmt: skip
    notes += [
        f"{name} jumps by {jump:.3g} between two rows: a wrapped angle? Unwrap it (declare it "
        "an angle: --angles, or clean(..., angles=...)), else its derivative is a spike"
        for name, jump in zip(names, jumps, strict=True)
        if name in inside and jump > 0.9 * 2 * np.pi
    ]
    return notes


OFFSET_LIMIT = 0.3
"""Largest rotation [rad] :func:`angle_offset_note` reads as an angle's offset."""


def angle_offset_note(
    xi: np.ndarray, names: Sequence[str], state_names: Sequence[str]
) -> str | None:
    """A note where two equations rotate the same factor by one angle's common offset.

    A logged angle with a constant offset b (an IMU's mounting, an estimator's bias) turns
    ``sin(phi) u1`` into ``cos(b) sin(phi) u1 - sin(b) cos(phi) u1``: a trial's 0.01 rad
    gave ``y_dot' = -0.5555 sin(phi) u1 + 0.005555 cos(phi) u1`` and its twin in ``z_dot'``
    (all P = 1.00) with no note; the model is right for logs with that offset, 2.1 % of the
    range off at 1 s on flights without it. In an equation holding ``c_s sin(a) X + c_c
    cos(a) X`` the pair is a sine shifted by atan2(c_c, c_s); where two equations or more
    agree on that shift up to quarter turns (the physics' phases), by at most
    :data:`OFFSET_LIMIT`, the angle is named with it: an offset, or an axis tilted by it.
    """
    found: dict[tuple[str, str], list[tuple[str, float]]] = {}
    for i, state in enumerate(state_names):
        pairs: dict[tuple[str, str], dict[str, float]] = {}
        for j in np.flatnonzero(xi[i]):
            term = parse_term(names[j])
            trig = [f for f in term if f.kind in ("sin", "cos") and f.k == 1]
            if len(trig) != 1 or sum(f.var == trig[0].var for f in term) != 1:
                continue
            rest = term_name(tuple(f for f in term if f is not trig[0]))
            pairs.setdefault((trig[0].var, rest), {})[trig[0].kind] = float(xi[i, j])
        for key, both in pairs.items():
            if len(both) == 2:
                turn = -np.arctan2(both["cos"], both["sin"])
                shift = (turn + np.pi / 4) % (np.pi / 2) - np.pi / 4
                found.setdefault(key, []).append((state, float(shift)))
    for (angle, factor), seen in found.items():
        shifts = np.array([b for _, b in seen])
        small = np.abs(shifts)
        if len(seen) < 2 or not (1e-4 < small.min() and small.max() < OFFSET_LIMIT):
            continue
        if np.ptp(shifts) > max(0.1 * np.abs(shifts).min(), 1e-4):
            continue
        offset = float(np.mean(shifts))
        where = " and ".join(f"{state}'" for state, _ in seen)
        return (
            f"{where} hold sin({angle}) {factor} and cos({angle}) {factor} together as one "
            f"sine shifted by {offset:.4g} rad: the logged {angle} may be offset by "
            f"{offset:.4g} rad (an IMU's mounting, an estimator's bias; subtract it and "
            f"identify again), or the vehicle's axis is tilted by it"
        )
    return None


STAMP_JITTER = 1e-3
"""Steps that vary by more than this share of the median step are tested as stamp jitter."""


STAMP_FLOOR = 1e-8
"""Below this residual share (summed over the equations) the stamps fit as they are: the
comparison would be between round-offs."""


def stamp_jitter(
    trajs: Sequence[Trajectory], names: Sequence[str], own: Gram | None = None
) -> tuple[list[Trajectory], str | None]:
    """The trajectories on regular clocks where their jittery stamps fit worse, and a note.

    Jittery stamps are of two kinds: samples taken at irregular times (each row's own step
    is right) or a regular clock stamped with noise (message arrival times: each row's own
    step is wrong by the noise). A trial's +-1 ms stamps on an exact 10 ms clock gave a
    good model but 324 "outlying steps" and a misfit note blaming the library. The data
    tell the two apart: a least-squares fit of the whole library on one-step differences
    (window 1), with each row's own step and with each segment's stamps on the line through
    them. Where the regular clock's residual is lower by more than the Bonferroni bar for
    the equations (in residual variances), it is used and said; else the stamps are kept
    (a first rule, at most half the residual, missed the same stamps under state noise
    1e-3, whose held-out score was 20 times worse than on the true stamps). ``own``: the
    one-step Gram on the stamps, where the caller has it.
    """
    steps = [np.diff(t.t) for t in trajs if len(t) > 3]
    if not steps or max(np.ptp(h) / np.median(h) for h in steps) <= STAMP_JITTER:
        return list(trajs), None
    regular = [dataclasses.replace(t, t=clock_line(t.t)) if len(t) > 3 else t for t in trajs]

    def residual(g: Gram) -> tuple[np.ndarray, float]:
        """Per equation, the least-squares residual's share of the target; the rows left."""
        total = np.sum(g.r_aug[:, g.p :] ** 2, axis=0)  # the targets' squares
        explained = np.sum(g.z**2, axis=0)
        shares = np.maximum(total - explained, 0.0) / np.maximum(total, 1e-300)
        return shares, max(float(g.rows) - g.p, 1.0)

    own = own if own is not None else Gram.stack(grams(trajs, list(names), "forward", 1))
    own_eq = residual(own)[0]
    grid_eq, rows = residual(Gram.stack(grams(regular, list(names), "forward", 1)))
    # the clock must fit better by more than chance: the drop in residual variances of the
    # clock's fit, summed over the equations, past the bar for the equations compared
    drop = float(np.sum((own_eq - grid_eq) / np.maximum(grid_eq / rows, 1e-300)))
    stamped, clocked = float(own_eq.sum()), float(grid_eq.sum())
    if stamped <= STAMP_FLOOR or drop <= _significance_bar(len(own_eq)):
        return list(trajs), None
    worst = max(float(np.max(np.abs(a.t - b.t))) for a, b in zip(trajs, regular, strict=True))
    return regular, (
        f"the time stamps jitter (up to {worst:.3g} s off a regular clock) but the data fit "
        f"a regular clock better (residual {clocked / stamped:.2g} of the stamps' own steps'): "
        "read as each segment's regular clock (stamps with noise, such as message arrival "
        "times)"
    )


def _frozen(trajs: Sequence[Trajectory]) -> list[str]:
    """Notes naming a state that holds one value over a whole file while it moves in others.

    A sensor that froze (or a column a logger never filled) for a whole flight: a trial's
    file with ``z`` stuck at 1.0 gave ``z' = 0.2095 y_dot`` with exit 0, and the notes blamed
    outliers and the library. A flight that never moved that state (a vertical climb's
    ``y``) holds it too, so this is a note, not a refusal.
    """
    sources: dict[str, list[Trajectory]] = {}
    for tr in trajs:
        sources.setdefault(str(tr.meta.get("source", "")), []).append(tr)
    if len(sources) < 2:
        return []
    spread = {src: np.ptp(np.vstack([t.x for t in parts]), axis=0)
              for src, parts in sources.items()}  # fmt: skip
    notes = []
    for j, name in enumerate(trajs[0].state_names):
        still = [src for src, ptp in spread.items() if ptp[j] == 0]
        if still and len(still) < len(spread):
            value = sources[still[0]][0].x[0, j]
            shown = ", ".join(Path(s).name or "(unnamed)" for s in still[:3])
            notes.append(
                f"{name} holds one value ({value:.6g}) over all of {shown} while it moves in "
                f"the other files: a frozen or unfilled sensor gives wrong terms (leave that "
                "file out); a flight that never moved it is fine"
            )
    return notes


UNIT_FACTOR = 30.0
"""A file whose variables' spreads differ from the median file's by at least this factor, the
same for three or more variables (within a factor of 2), is named as logged in another unit;
so is one whose operating level (a thrust at hover) differs by :data:`LEVEL_FACTOR`."""

LEVEL_FACTOR = 5.0
"""An input's operating level this many times off the other files' is a unit (kgf for N:
9.81; a payload or a battery changes a hover thrust by tens of percent)."""


def _unit_mismatch(trajs: Sequence[Trajectory], angles: set[str] = frozenset()) -> list[str]:
    """Files that look logged in another unit than the others: one note per such file.

    A unit changes some variables by one factor (mm for m: positions and velocities by 1000,
    angles and rates as they were), where a flight of another amplitude changes them all: a
    hover flight among tracking flights has velocities and rates 100 times smaller, and a
    gentle one its rates and thrust 180 times (an adversarial trial: both were named). So
    three or more variables off by one factor of :data:`UNIT_FACTOR` are named only where
    some state is within 3 times of the median file's spread and no angle is among them (no
    unit of length or time scales an angle; a vertical flight's small roll does). An input
    with an operating level in every file (a thrust at hover, its median over 3 spreads from
    zero) keeps that level whatever the flight: :data:`LEVEL_FACTOR` times off is a unit
    (thrust in grams or kgf among files in newtons, which the spreads missed; positions are
    left out, their origin is arbitrary). An angle inside sin/cos spread 30 to 100 times
    more than in the others and past 1 rad is in degrees. A scale trial's 3 files in m and 1
    in mm gave a model without thrust or gravity, worse than holding the state, with only
    outlier notes; one in cm among 3 (80 to 180 times) went unnamed at a factor of 100.
    """
    by_file: dict[str, list[Trajectory]] = {}
    for t in trajs:
        by_file.setdefault(str(t.meta.get("source", "")), []).append(t)
    if len(by_file) < 2 or "" in by_file:
        return []
    names = [*trajs[0].state_names, *trajs[0].input_names]
    data = [np.vstack([np.column_stack([t.x, t.u]) for t in segs]) for segs in by_file.values()]
    spread = np.array([np.std(d, axis=0) for d in data])
    level = np.array([np.abs(np.median(d, axis=0)) for d in data])
    peak = np.array([np.max(np.abs(d), axis=0) for d in data])
    steady = np.all(level > 3 * spread, axis=0)  # an input's operating point; positions
    steady[: len(trajs[0].state_names)] = False  # have an arbitrary origin (a trial: z = 25 m)
    paths = list(by_file)
    if len(paths) == 2:  # which of two is off cannot be told: the second, against the first
        usual_spread, usual_level, judged = spread[0], level[0], [1]
    else:  # against the median file, itself included: the median of the other two of three
        # is their mean, half the odd file's (a trial's 3 files, one in cm: all 3 named)
        usual_spread, usual_level = (np.exp(np.median(np.log(np.maximum(a, 1e-300)), axis=0))
                                     for a in (spread, level))  # fmt: skip
        judged = range(len(paths))
    states = len(trajs[0].state_names)
    notes = []
    for i in judged:
        with np.errstate(divide="ignore", invalid="ignore"):
            logs, levels = np.log10(spread[i] / usual_spread), level[i] / usual_level
        said = []
        far = np.flatnonzero(np.isfinite(logs) & (np.abs(logs) >= np.log10(UNIT_FACTOR)))
        kept = np.isfinite(logs[:states]) & (np.abs(logs[:states]) <= np.log10(3.0))
        if far.size >= 3 and kept.any():  # a unit leaves some states as they were
            centre = np.median(logs[far])
            same = far[np.abs(logs[far] - centre) <= np.log10(2.0)]
            if same.size >= 3 and not {names[k] for k in same} & angles:  # no unit of length
                # or time scales an angle; a flight of another kind does (a vertical one)
                said.append(
                    f"{', '.join(names[k] for k in same)} vary about "
                    f"{10 ** abs(centre):.3g} times {'more' if centre > 0 else 'less'}"
                )
        for k in np.flatnonzero(steady & ((levels >= LEVEL_FACTOR) | (levels <= 1 / LEVEL_FACTOR))):
            said.append(f"{names[k]} sits at {level[i, k]:.4g} against {usual_level[k]:.4g}")
        for k, name in enumerate(names):
            if name in angles and 30 <= 10 ** logs[k] <= 100 and peak[i, k] > 1.0:
                said.append(
                    f"{name} spreads {10 ** logs[k]:.3g} times more, to {peak[i, k]:.3g} (degrees?)"
                )
        if said:
            where = paths[i] if len(paths) > 2 else f"{paths[1]} against {paths[0]}"
            against = "the other files" if len(paths) > 2 else "it"
            notes.append(
                f"{where}: {'; '.join(said)}, against {against}: logged in another "
                "unit (mm for m, g for N, degrees for radians)? Convert it, or leave "
                "the file out"
            )
    return notes


def _check_settings(
    folds: int, lambdas: Sequence[float], windows: Sequence[int], horizon: int, n_models: int
) -> None:
    """Raises ValueError naming a selection setting that cannot work."""

    def whole(value: Any) -> bool:
        return not isinstance(value, bool) and isinstance(value, int | np.integer)

    if not whole(folds) or folds < 2:
        raise ValueError(f"folds must be an integer of at least 2, got {folds!r}")
    if not whole(horizon) or horizon < 1:
        raise ValueError(f"horizon must be a positive integer of steps, got {horizon!r}")
    if not whole(n_models) or n_models < 0:
        raise ValueError(f"n_models must be a non-negative integer, got {n_models!r}")
    values = np.asarray(list(lambdas), dtype=float)
    if values.size == 0 or not np.all(np.isfinite(values) & (values >= 0)):
        raise ValueError(f"lambdas must be one or more finite numbers >= 0, got {lambdas!r}")
    if len(windows) == 0 or not all(whole(w) and w >= 1 for w in windows):
        raise ValueError(f"windows must be one or more positive integers, got {windows!r}")


REFIT_TOLERANCE = 1.5
"""The refit checks' model may predict the data at most this many times worse than the chosen
candidate's fit on all data (both in sample); else the candidate's fit is returned."""


def _predicts_as_validated(
    xi: np.ndarray,
    candidate: np.ndarray,
    units: Sequence[Trajectory],
    scale: np.ndarray,
    horizon: int,
    resolution: float,
    names: Sequence[str],
    first: Trajectory,
) -> tuple[np.ndarray, str]:
    """The checked model, or the chosen candidate's fit where the checks broke its predictions.

    The refit, growth, pruning and bootstrap steps after the selection change terms that no
    fold scored. On data the library cannot hold (motor lag with the commands logged, a
    new-user trial) they grew a validated 17-term model to 44 terms that diverged on its own
    training flights. Both are fitted on all data, so both are scored on all of it, over twice
    the selection's horizon.
    """

    def score(coefficients: np.ndarray) -> float:
        rhs = compile_rhs(names, coefficients, first.state_names, first.input_names)
        try:  # twice the horizon: the grown 47-term model of the trial held 50 steps, not 100
            return prediction_score(rhs, units, scale, 2 * horizon)
        except (np.linalg.LinAlgError, ValueError, FloatingPointError):
            return float("inf")

    if np.array_equal(xi != 0, candidate != 0):
        return xi, ""
    checked, chosen = score(xi), score(candidate)
    if np.isfinite(checked) and checked <= REFIT_TOLERANCE * chosen + resolution:
        return xi, ""
    if not np.isfinite(chosen):
        return xi, ""
    told = "diverges" if not np.isfinite(checked) else f"scores {checked:.3g}"
    return candidate, (
        f"the refit checks' model ({int(np.count_nonzero(xi))} terms) {told} on the data "
        f"against {chosen:.3g} for the chosen candidate: returned the candidate's fit "
        f"({int(np.count_nonzero(candidate))} terms, no bootstrap statistics); the library "
        "may lack the dynamics (actuator lag, delays, unmodelled effects)"
    )


WEAK_PROBABILITY = 0.6
"""A kept term in fewer bootstrap fits than this, or spread over half its size, is named weak."""


def _weak_terms_note(
    xi: np.ndarray,
    std: np.ndarray | None,
    prob: np.ndarray | None,
    names: Sequence[str],
    states: Sequence[str],
) -> list[str]:
    """One note naming the kept terms the bootstrap leaves uncertain.

    They are kept because the F-test on all data needs them; a trial on 2 s of a real
    flight read ``-2.7 (+-2.7, P=0.50) alt`` without a word.
    """
    if std is None or prob is None:
        return []
    weak = [
        f"{names[j]} in {states[i]}' (P={prob[i, j]:.2f}, +-{std[i, j]:.2g})"
        for i, j in zip(*np.nonzero(xi), strict=True)
        if prob[i, j] < WEAK_PROBABILITY or std[i, j] > 0.5 * abs(xi[i, j])
    ]
    if not weak:
        return []
    more = f" and {len(weak) - 6} more" if len(weak) > 6 else ""
    return [
        f"weak terms, kept because the fit on all data needs them but unsettled across the "
        f"bootstrap fits: {', '.join(weak[:6])}{more}; more data (or more excitation) would "
        "settle them"
    ]


def _empty_model_message(candidates: Sequence[Candidate], hold: float) -> str:
    """Why an identified model with no term is refused, with the scores that say so."""
    scored = [c for c in candidates if c.n_terms > 0 and np.isfinite(c.mean)]
    top = min(scored, key=lambda c: c.mean)
    against = f"; the state held: {hold:.3g}" if np.isfinite(hold) else ""
    terms = f"{top.n_terms} term{'s' if top.n_terms != 1 else ''}"
    return (
        "the identified model has no term: no model with terms predicts the held-out data "
        f"significantly better than holding the state (best with terms: {terms}, "
        f"score {top.mean:.3g}{against}); the library may not contain the dynamics, or the "
        "inputs do not explain the states (lagged, mislabelled or closed-loop inputs)"
    )


def bag_spread(bags: np.ndarray, center: np.ndarray | None = None) -> np.ndarray:
    """Robust bootstrap standard error: how far 68.27 % of the bags (axis 0) lie from ``center``.

    ``center`` is the reported coefficient (default: the bags' median). For normally spread
    bags about it this is their standard deviation. A term that most bags leave out is
    ``|coefficient|`` uncertain: half the central 68 % range of such bags was 0, shown as
    ``+-0`` beside an inclusion probability of 5 % (a new-user trial). A single wild bag (a
    fit of a resample on which the library is nearly singular: one of twenty bags of clean open-loop
    6-DOF data held 20 terms in `w'`) moved the standard deviation of an exact `-0.375 w` to
    13; it does not move this. This is the spread stored in the model and shown; the weak-term
    rule still uses the standard deviation, where a wild bag can only make a term look weak
    and the F-test on all data then keeps it if the data need it.
    """
    center = np.median(bags, axis=0) if center is None else center
    return np.percentile(np.abs(bags - center), 68.27, axis=0)


def _bootstrap(
    trajs: Sequence[Trajectory],
    names: list[str],
    config: FitConfig,
    xi: np.ndarray,
    n_models: int,
    seed: int,
    grown: dict[int, list[int]] | None = None,
    ratio: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """Block bootstrap of the chosen fit: spread, inclusion probability, E-SINDy thresholding.

    ``grown``: the supports :func:`grow_significant` chose ({equation: columns}), with
    ``ratio`` the long-run ratios. A bag takes such a support in place of its own path's
    where its own rows pass the same bar (each added term past the Bonferroni bar, or a
    better fit at no more terms), so the inclusion probabilities describe the procedure that
    made the model.

    Returns:
        The coefficients (weak terms dropped), the spread, the inclusion probability, the
        share of bags holding each term or a near twin in its place (for the weak-term
        note: an exact `phi_dot` whose twin `cos(phi) phi_dot` half the bags held was named
        unsettled beside the twin note), and the notes.
    """
    w = config.window
    n_blocks = 40 if len(names) < 100 else 12
    total = sum(len(t) for t in trajs)
    size = max(4 * w, total // n_blocks, 10)
    blocks = []
    for tr in trajs:
        for s in range(0, len(tr) - w - 1, size):
            stop = min(s + size + w, len(tr))
            if stop - s > w + 1:
                blocks.append(tr.slice(s, stop))
    block_grams = grams(blocks, names, "rk4", w, xi)
    rng = np.random.default_rng(seed)
    bags = []
    bar = _significance_bar(len(names))
    for _ in range(n_models):
        weights = rng.multinomial(len(blocks), np.full(len(blocks), 1.0 / len(blocks)))
        bag_gram = Gram.stack(block_grams, list(weights.astype(float)))
        bag = solve(bag_gram, config, names)
        for i, support in (grown or {}).items():
            own = list(np.flatnonzero(bag[i]))
            rss_own = _rss(bag_gram.r, bag_gram.z[:, i], own)[0]
            rss_new, sigma2 = _residual_variance(bag_gram, i, support)
            extra = max(len(support) - len(own), 0)
            scale = 1.0 if ratio is None else max(float(ratio[i]), 1.0)
            if rss_own - rss_new > bar * scale * sigma2 * extra:
                bag[i] = _refit(bag_gram, i, support)
        bags.append(bag)
    bags_a = np.array(bags)
    prob = np.mean(bags_a != 0, axis=0)
    std = bags_a.std(axis=0)  # the weak rule's scale (a wild bag only makes it cautious)
    notes = []
    weak = (xi != 0) & (prob < 0.5)
    full = Gram.stack(block_grams)
    if weak.any():
        # A term whose near-collinear twin stands in for it in the other bags is not weak:
        # the bags disagree on which of two columns the data cannot tell apart carries the
        # direction (|cos| > 0.999 on the data: `sin(phi) r` / `tan(phi) r` at small tilt),
        # not on whether it belongs to the model (dropping it lost whole kinematic terms).
        unit = full.r / np.maximum(full.col_norms, 1e-300)
        for i, j in zip(*np.nonzero(weak), strict=True):
            group = np.flatnonzero(np.abs(unit.T @ unit[:, j]) > 0.999)
            if np.mean((bags_a[:, i, group] != 0).any(axis=1)) >= 0.5:
                weak[i, j] = False
    # A term the bags hold but whose coefficient they spread across zero (|coefficient| under
    # BAG_T bootstrap deviations) is weak too, unless the full data need it (F-test below).
    weak |= (xi != 0) & (np.abs(xi) < BAG_T * std)
    if weak.any():
        # Nor is a term whose removal alone the full data reject (F-test, p = 0.001): one of a
        # cancelling pair (gravity and thrust in w') whose columns the bags spread over many
        # twins is weak in every bag and still carries a force the fit cannot do without.
        for i in np.unique(np.nonzero(weak)[0]):
            support = list(np.flatnonzero(xi[i]))
            rss, sigma2 = _residual_variance(full, i, support)
            for j in np.flatnonzero(weak[i]):
                trial = [c for c in support if c != j]
                if _rss(full.r, full.z[:, i], trial)[0] - rss > F_CRITICAL * sigma2:
                    weak[i, j] = False
    xi_in = xi
    if weak.any():
        xi = xi.copy()
        for i in np.unique(np.nonzero(weak)[0]):
            xi[i] = _refit(full, i, [c for c in np.flatnonzero(xi[i]) if not weak[i, c]])
        states = trajs[0].state_names
        for i, j in zip(*np.nonzero(weak), strict=True):
            notes.append(
                f"{states[i]}': dropped term {names[j]!r}: kept in {prob[i, j]:.0%} of bootstrap "
                f"fits, coefficient {xi_in[i, j]:.3g} (bootstrap deviation {std[i, j]:.2g}), "
                "and the data do not need it (F-test)"
            )
    # Where the bags that leave a kept term out hold a near twin of it instead, its spread is
    # the coefficient of that shared direction (the twin's, in the term's column scale), not
    # a zero: the bags chose between columns the data cannot tell apart.
    unit = full.r / np.maximum(full.col_norms, 1e-300)
    shown = bags_a.copy()
    held = prob.copy()  # bags holding the term or, in its place, a near twin of it
    for i, j in zip(*np.nonzero((xi != 0) & (prob < 1.0)), strict=True):
        cos = unit.T @ unit[:, j]
        group = [k for k in np.flatnonzero(np.abs(cos) > 0.999) if k != j]
        if not group:
            continue
        scale = np.sign(cos[group]) * full.col_norms[group] / max(full.col_norms[j], 1e-300)
        swapped = (bags_a[:, i, j] == 0) & (bags_a[:, i, group] != 0).any(axis=1)
        if swapped.any():
            shown[swapped, i, j] = bags_a[swapped][:, i, group] @ scale
            held[i, j] += float(np.mean(swapped))
        if np.mean(swapped) >= 0.5:  # why a kept term's inclusion probability is low
            kept = [names[k] for k in group if np.any(bags_a[swapped, i, k] != 0)]
            notes.append(
                f"{trajs[0].state_names[i]}': {np.mean(swapped):.0%} of the bootstrap fits hold "
                f"a near twin of {names[j]!r} in its place ({', '.join(map(repr, kept))}; "
                "|cos| > 0.999 on this data); its spread is over that shared direction"
            )
    return xi, bag_spread(shown, xi_in), prob, held, notes  # about the fit the bags resample
