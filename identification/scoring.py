"""Held-out scoring of candidate models: validation units and multi-step open-loop prediction.

Step 3 of :func:`identification.selection.select_model`. From start points spread over each
held-out trajectory a candidate is integrated by RK4 with the *recorded* inputs for
``horizon`` steps (rows a logger lost are predicted through, not compared); the error of
every state, divided by that state's scale (:func:`score_scale`), is averaged over states,
steps and starts (root mean square). Nothing here knows a vehicle or a simulator.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from identification.data import Trajectory, as_trajectories
from identification.features import compile_rhs
from identification.fit import (
    rk4_steps,
)
from identification.model import IdentifiedModel


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

    Windows are capped at :func:`window_cap` and the horizon at half of the typical segment
    (:func:`typical_length`); on a single short log (one flight of 150 rows) they shrink
    further until the data make two blocks, so that every fold has data to train on.

    Raises:
        ValueError: Too few rows for two blocks of :data:`MIN_UNIT_ROWS`.
    """
    wins = sorted({int(w) for w in windows if 0 < w < window_cap(trajs)}) or [1]
    horizon = int(max(1, min(horizon, typical_length(trajs) // 2)))
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


WINDOW_SHARE = 0.5
"""Windows fit a quarter of the segments that hold this share of the rows (:func:`window_cap`)."""


def window_cap(trajs: Sequence[Trajectory]) -> int:
    """The integral windows :func:`validation_units` tries are shorter than this.

    A quarter of the segments that hold :data:`WINDOW_SHARE` of the rows; the shorter ones
    sit out the windows they cannot hold. Sized to 90 % of the rows as the horizon is, a
    6-DOF log cut around its clipped steps (55 pieces of at most 165 rows) allowed window
    4 only, and the fit of its *applied* inputs was 0.46 % off at 1 s; with window 16,
    which half of its rows hold, 0.061 % (the whole flights': 0.012 %).
    """
    return max(typical_length(trajs, WINDOW_SHARE) // 4, 2)


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


def spread_blocks(trajs: Sequence[Trajectory], rows: int, block: int = 2000) -> list[Trajectory]:
    """Blocks of ``block`` rows spread evenly over the data, about ``rows`` rows in all.

    All of the data where it holds no more; else every trajectory cut into blocks (a last
    one under a quarter of a block left out) and an evenly spaced choice of them, so that
    each log and each part of a long one is represented. Data in pieces all shorter than
    that (a long noisy log cut around its rows at rest) give about ``rows`` rows of them.
    """
    total = sum(len(t) for t in trajs)
    if total <= rows:
        return list(trajs)
    parts = [t.slice(a, min(a + block, len(t))) for t in trajs for a in range(0, len(t), block)]
    long = [p for p in parts if len(p) > block // 4]
    # (a 1e5-row log at sigma = 1e-2 cut around its still blocks left none: an IndexError)
    count = max(rows // block, 1) if long else max(rows * len(parts) // total, 1)
    parts = long or parts
    picks = np.unique(np.linspace(0, len(parts) - 1, count).round().astype(int))
    return [parts[i] for i in picks]


START_SPANS = (2, 3, 5, 7, 10, 14, 20)
"""Half-widths in rows of the local quadratics a start state may be estimated over
(:func:`start_states`); 0, the logged row itself, is always a choice."""


SPAN_ROWS = 100_000
"""Rows, in blocks spread over the data, that :func:`start_spans` reads (a 1e6-row log took
9 s and 0.5 GB when read whole, for the same spans)."""

MIN_SPAN_ROWS = 100
"""Fewest rows that estimate a state's noise, or a span's residuals (:func:`start_spans`)."""


def _quadratic_weights(half: int) -> np.ndarray:
    """Weights giving the centre value of a least-squares quadratic over 2 ``half`` + 1 rows."""
    j = np.arange(-half, half + 1)
    return (3 * (3 * half**2 + 3 * half - 1) - 15 * j**2) / (
        (2 * half + 1) * (4 * half**2 + 4 * half - 3)
    )


def _local_quadratic(x: np.ndarray, half: int) -> np.ndarray:
    """Each row's value of the quadratic fitted over rows k - half .. k + half (NaN near ends)."""
    out = np.full(x.shape, np.nan)
    if len(x) > 2 * half:
        windows = np.lib.stride_tricks.sliding_window_view(x, 2 * half + 1, axis=0)
        out[half : len(x) - half] = windows @ _quadratic_weights(half)
    return out


def start_spans(units: Sequence[Trajectory]) -> np.ndarray:
    """Per state, the half-width of the local quadratic that best estimates its true value.

    The mean squared error of a span is its noise share plus its bias, both from the data
    (Stein's unbiased risk estimate for a linear smoother): a quadratic over 2 m + 1 rows
    keeps ``w0`` sigma^2 of the noise (``w0`` its centre weight) and leaves residuals of
    mean square ``(1 - w0) sigma^2 + bias^2``. sigma comes from the third differences, whose
    variance and lag-1 covariance hold the white noise and a random walk in known
    proportions (20 sigma^2 + 6 q and -15 sigma^2 - 4 q; a smooth signal enters only
    through its third derivative). A held input that changes every row puts a kink into the
    velocities at every row, a random walk at the sample scale: read as noise (by the spread
    of the sixth differences alone) it bought clean logs a span that bent them. A clean log
    keeps its rows (span 0); a slow noisy state takes a wide span, a fast one a narrow one.
    """
    n = units[0].x.shape[1]
    units = spread_blocks(units, SPAN_ROWS)
    third = [np.diff(u.x, 3, axis=0) for u in units if len(u) > 4]
    rows = sum(len(d) for d in third)
    if rows < MIN_SPAN_ROWS:
        return np.zeros(n, dtype=int)
    var = sum(np.sum(d * d, axis=0) for d in third) / rows
    cov = sum(np.sum(d[1:] * d[:-1], axis=0) for d in third) / (rows - len(third))
    sigma2 = np.maximum(-(2.0 * var + 3.0 * cov) / 5.0, 0.0)  # solves the two moments above
    best, best_mse = np.zeros(n, dtype=int), sigma2.copy()
    for half in START_SPANS:
        res = _residuals(units, half)
        if len(res) < MIN_SPAN_ROWS:
            break
        w0 = _quadratic_weights(half)[half]
        bias2 = np.maximum(np.mean(res**2, axis=0) - (1.0 - w0) * sigma2, 0.0)
        mse = bias2 + w0 * sigma2
        better = mse < best_mse
        best[better], best_mse[better] = half, mse[better]
    return best


def _residuals(units: Sequence[Trajectory], half: int) -> np.ndarray:
    """The logged states less their local quadratics of ``half``, at observed inner rows."""
    res = np.concatenate([(u.x - _local_quadratic(u.x, half))[u.observed] for u in units])
    return res[np.isfinite(res).all(axis=1)]


def start_states(units: Sequence[Trajectory], spans: np.ndarray) -> list[np.ndarray]:
    """Each unit's states as prediction starts: a state's local quadratic of its span.

    Rows nearer an end than the span take the widest span in :data:`START_SPANS` that fits
    (the logged row at the very ends).
    """
    out = []
    for u in units:
        est = u.x.copy()
        for half in np.unique(spans[spans > 0]):
            cols = np.flatnonzero(spans == half)
            est[:, cols] = _edged_quadratic(u.x[:, cols], int(half))
        out.append(est)
    return out


def _edged_quadratic(x: np.ndarray, half: int) -> np.ndarray:
    """:func:`_local_quadratic` of ``half``, the rows near the ends from narrower spans."""
    est = _local_quadratic(x, half)
    n = len(x)
    # each end's rows from the 2 half rows there, which hold every narrower span that fits
    ends = ((0, np.arange(min(half, n))), (max(n - 2 * half, 0), np.arange(max(n - half, 0), n)))
    for first, rows in ends:
        piece = x[first : first + 2 * half]
        fill = piece.copy()  # the logged rows where no span fits
        for narrower in (m for m in START_SPANS if m < half):
            fit = _local_quadratic(piece, narrower)
            fill = np.where(np.isfinite(fit), fit, fill)
        gap = rows[~np.isfinite(est[rows, 0])]
        est[gap] = fill[gap - first]
    return est


def _rollouts(
    rhs: Any,
    trajs: Sequence[Trajectory],
    horizon: int,
    max_starts: int,
    substeps: int = 1,
    starts: Sequence[np.ndarray] | None = None,
) -> Any:
    """Yields (predicted, recorded, observed, which) step by step from evenly spread starts.

    Starts are observed rows, up to ``max_starts`` per trajectory, taken from ``starts``
    (one array of states per trajectory, :func:`start_states`) where given; the starts of every
    trajectory are stepped together, one batch per step (100 logs of 1000 rows took 5 times
    as long as one log of 100 000 rows when each log was stepped on its own). A trajectory's
    starts take ``min(horizon, len - 1)`` steps; the arrays yielded hold the starts still
    stepping, ``which`` their trajectory's index. ``observed`` marks the predictions that
    have a recorded state to compare with (not a row the logger lost:
    :attr:`Trajectory.missing`).
    """
    picked, lengths, offset = [], [], 0
    for tr in trajs:
        n = len(tr)
        h_len = max(min(horizon, n - 1), 0)
        candidates = np.flatnonzero(tr.observed[: n - h_len])
        pick = np.linspace(0, candidates.size - 1, min(max_starts, candidates.size)).astype(int)
        chosen = candidates[np.unique(pick)]
        picked.append(offset + chosen)
        lengths.append(np.full(chosen.size, h_len))
        offset += n
    if not offset:
        return
    rows = np.concatenate(picked)
    h_len = np.concatenate(lengths)
    which = np.repeat(np.arange(len(trajs)), [len(s) for s in picked])
    states = np.concatenate([tr.x for tr in trajs])
    observed = np.concatenate([tr.observed for tr in trajs])
    steps = np.concatenate([np.append(np.diff(tr.t), np.nan) for tr in trajs])
    held = not any(tr.measured or tr.commands is not None or tr.meta.get("input_drift")
                   for tr in trajs)  # fmt: skip
    if held:  # each step's input is its row's
        stages = [np.concatenate([tr.u for tr in trajs])]
    else:
        stages = [np.concatenate(parts) for parts in zip(*[_all_stages(tr) for tr in trajs],
                                                         strict=True)]  # fmt: skip
    x = (np.concatenate(starts) if starts is not None else states)[rows]
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
    starts: Sequence[np.ndarray] | None = None,
) -> float:
    """RMS over starts, steps and states of the normalised ``horizon``-step prediction error.

    Args:
        rhs: Compiled rhs(x, u) of the candidate.
        held_out: Trajectories to predict (recorded inputs, each row's own step).
        scale: Per-state normaliser (:func:`score_scale`).
        horizon: Steps to predict from each start.
        max_starts: Start points per trajectory (evenly spread).
        starts: The states to start from, one array per trajectory (:func:`start_states`);
            the logged rows when None.

    Returns:
        The score (inf if the prediction diverged).
    """
    total, count, k = 0.0, 0, len(held_out)
    with np.errstate(all="ignore"):
        for x, recorded, seen, which in _rollouts(
            rhs, held_out, horizon, max_starts, starts=starts
        ):
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
    if isinstance(steps, bool) or not isinstance(steps, int | np.integer) or steps < 1:
        raise ValueError(f"steps must be a positive integer, got {steps!r}")
    trajs = as_trajectories(trajs)
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
