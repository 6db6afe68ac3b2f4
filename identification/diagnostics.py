"""What the data and a fitted model say about the log: notes and warnings, never fits.

Every function here reads trajectories (and a model's coefficients) and returns notes for
the user: outlying steps and the rows they cut, misfit that is not white noise, inputs or
state columns logged late, an angle logged with an offset, time stamps noisier than their
clock, frozen sensors, unit mismatches, and predictions outside the training range.
:func:`identification.selection.select_model` issues them; ``score`` issues those that
apply to a model it did not fit.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from identification.data import (
    LAG_SETTLE,
    Trajectory,
    clock_line,
    drift_gain,
    input_drift_of,
    input_lag_of,
    log_starts,
    logged_resolution,
)
from identification.features import compile_features, parse_term, term_name
from identification.fit import (
    Gram,
    grams,
    iter_rows,
)
from identification.model import IdentifiedModel
from identification.scoring import MIN_UNIT_ROWS, long_enough, spread_blocks
from identification.support import PRUNE_P, residual_variance, significance_bar

MISFIT_WINDOW, MISFIT_SHRINK, MISFIT_FLOOR = 16, 1.5, 1e-5
"""An equation whose residual (relative to its target's spread, above the floor) shrinks by
less than ``MISFIT_SHRINK`` from window 1 to window ``MISFIT_WINDOW`` is reported: white
measurement noise in the residual shrinks about as 1 / window, misfit does not."""


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
    spread and the state's quantisation noise, :func:`quantisation_noise`). Smooth misfit (a
    missing drag term) moves the neighbours too; an input that did not act as logged (a
    command that saturated the rotors, a glitch) does not.

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
        floor = np.maximum(OUTLIER_FLOOR * np.concatenate(targets).std(axis=0),
                           quantisation_noise(trajs))  # fmt: skip
        deviation = np.maximum(1.4826 * np.median(np.abs(stacked), axis=0), floor)
        deviation = np.where(deviation > 0, deviation, 1.0)
        flagged = {i: np.abs(v) / deviation > OUTLIER_Z for i, v in local.items()}
    return {i: f for i, f in flagged.items() if f.any()}


def quantisation_noise(trajs: Sequence[Trajectory]) -> np.ndarray:
    """Each state's quantisation noise in its step-wise target ``dx / dt``, 0 where none.

    A state logged to a step q (:func:`~identification.data.logged_resolution`: decimals,
    float32) carries rounding noise uniform in +-q / 2 on each sample; the difference of two
    over a step dt has deviation q / (dt sqrt(6)). A trial's 1 cm and 0.01 rad logs had 38 %
    of their steps named as outlying against a median departure that the few levels of
    their residuals put near zero. Unrounded float64 states give round-off here. Only
    observed rows are read (bridged rows are interpolated off the grid).
    """
    x = np.concatenate([t.x[t.observed] for t in trajs])
    dt = float(np.median(np.concatenate([np.diff(t.t) for t in trajs])))
    grid = np.array([logged_resolution(col) for col in x.T])
    return grid / (dt * np.sqrt(6.0))


def _residuals(
    trajs: Sequence[Trajectory], names: list[str], derivative: str, window: int, xi: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Per equation, the RMS residual of ``xi`` at ``window`` and the target's spread."""
    total = np.zeros(xi.shape[0])
    targets: list[np.ndarray] = []
    count = 0
    with np.errstate(all="ignore"):
        for _, theta, y in iter_rows(trajs, names, derivative, window, xi):
            total += np.sum((y - theta @ xi.T) ** 2, axis=0)
            count += len(y)
            targets.append(y)
        spread = np.concatenate(targets).std(axis=0) if targets else np.ones(xi.shape[0])
    return np.sqrt(total / max(count, 1)), np.where(spread > 0, spread, 1.0)


AR1_SHARE, AR1_MIN, AR1_MAX = 1e-3, 0.5, 0.995
"""Equation errors are read as correlated in time where, over the equations whose window-1
residual is at least ``AR1_SHARE`` of their target's spread (round-off and integrator
error of clean logs lie far below: 1e-8 on an independent simulator's), the pooled lag-1
autocorrelation exceeds ``AR1_MIN``. White measurement noise gives about -0.5 there (a
difference of two noisy samples), filtered noise near 0; unmeasured forces with a
correlation time of 0.05 to 0.5 s gave 0.84 to 0.98 at dt = 0.01 s on a trial's flights,
and so did effects the library lacks (a sagging battery, ground effect: 0.9 and 0.99). A
prewhitening coefficient is capped at ``AR1_MAX``."""


def equation_error_ar1(
    trajs: Sequence[Trajectory], names: list[str], derivative: str, xi: np.ndarray
) -> tuple[float | None, float]:
    """The pooled lag-1 autocorrelation of ``xi``'s window-1 residuals, and their largest share.

    Pooled over the equations whose residual is at least :data:`AR1_SHARE` of their
    target's spread (each equation weighted by its target's variance); None where none is
    (a model exact to round-off) or the formulation is not an integral one.

    Returns:
        (correlation or None, the largest residual share).
    """
    if derivative not in ("rk4", "forward"):
        return None, 0.0
    lagged = square = last = 0.0
    targets: list[np.ndarray] = []
    with np.errstate(all="ignore"):
        for _, theta, y in iter_rows(trajs, names, derivative, 1, xi):
            e = y - theta @ xi.T
            lagged = lagged + np.sum(e[1:] * e[:-1], axis=0)
            last = last + np.sum(e[:-1] ** 2, axis=0)
            square = square + np.sum(e**2, axis=0)
            targets.append(y)
        if not targets:
            return None, 0.0
        spread = np.concatenate(targets).var(axis=0) * sum(len(t) for t in targets)
    share = np.sqrt(square / np.where(spread > 0, spread, np.inf))
    use = np.isfinite(share) & (share >= AR1_SHARE)
    if not use.any() or not np.all(np.isfinite(lagged[use])):
        return None, float(np.nanmax(share, initial=0.0))
    weight = 1.0 / spread[use]
    rho = float(np.sum(weight * lagged[use]) / np.sum(weight * last[use]))
    return rho, float(share.max())


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
    (res_one, spread_one), (res_wide, spread_wide) = (
        _residuals(usable, names, derivative, w, xi) for w in (1, MISFIT_WINDOW)
    )
    one, wide = res_one / spread_one, res_wide / spread_wide
    # a share that does not shrink, from a residual that shrinks less than a quarter as much as
    # white noise's (1 / window): where noise fills the targets at both windows the shares of
    # an exact model stay near 1 too (a trial's false notes at dt = 0.005, sigma = 1e-2)
    flagged = [i for i in range(len(one))
               if one[i] > MISFIT_FLOOR and one[i] < MISFIT_SHRINK * wide[i]
               and res_one[i] < MISFIT_WINDOW / 4 * res_wide[i]]  # fmt: skip
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
        + "unmeasured forces may act (wind, gusts: a controller's answer to them biases the "
        "fit, and beside measurement noise their correlation in time is not seen), "
        "or the states' noise is correlated in time (filtered estimates)"
    )


DISAGREE_P, DISAGREE_SHARE = 1e-3, 1e-3
"""An equation's per-log refits disagree where their differences are beyond their noise (a
chi-square on the whole coefficient vector at ``DISAGREE_P``, Bonferroni over the
equations) and material: one fit of all logs leaves at least ``DISAGREE_SHARE`` of the
targets' sum of squares more than the per-log fits (round-off and integrator differences
between clean logs lie many orders below)."""


def disagreement_note(
    trajs: Sequence[Trajectory],
    names: Sequence[str],
    window: int,
    xi: np.ndarray,
) -> tuple[str | None, bool]:
    """A warning where the model's terms, refitted on each log alone, differ between logs.

    Pooled flights of different vehicles (payloads, batteries, `param_randomization`) get
    one model that fits none of them: a trial's four planar flights, each identified
    exactly alone (1/m from 1.54 to 2.22), gave gravity -5.2 and terms in `sin(phi) z`
    pooled, with warnings that blamed the library or the noise. Each equation's support is
    refitted on each segment of at least 5 rows a term, and the coefficient vectors are
    compared jointly with their covariances (each segment's residual variance times the
    long-run ratio of its own refit's residual): per-term tests missed a 1.0 / 1.3 kg pair
    at sigma = 1e-2 in hover, where `1`, `f1 cos(phi)` and `f2 cos(phi)` are nearly
    collinear within each log and only their combination differs. The worst equation is
    named with the term whose spread moves the target most (its coefficient's range times
    the column's RMS; a trial's note named a spurious stand-in, `sin(phi) z`, whose range
    was large only against its small pooled value, not the thrust gain that differed). A
    library that lacks a term varying between the logs does the same, so the note names
    both causes.

    Where the logs agree, the first and second halves of each log are compared the same
    way: a battery that sags alike in every flight moved `u2` from 242 to 221 between the
    halves of each of a trial's three logs, and no note had said so.

    Returns:
        The note (None: the logs agree) and whether the logs agree but their halves
        disagree on an input's gain (a drift :func:`input_drift` may fit).
    """
    found = _disagreeing(trajs, names, window, xi)
    halves = [part for tr in trajs for part in (tr.slice(0, len(tr) // 2),
                                                tr.slice(len(tr) // 2, len(tr)))]  # fmt: skip
    drift = _disagreeing(long_enough(halves, 4 * window), names, window, xi, gains=True)
    if found:
        count, i, j, low, high, more = found
        return (
            f"the logs disagree: refitted on each of {count} segments alone, "
            f"{trajs[0].state_names[i]}' differs beyond what their noise allows ('{names[j]}' "
            f"from {low:.4g} to {high:.4g}){_others(more)}: the library lacks a term that "
            "varies between the logs, or logs of different vehicles (payloads, batteries) "
            "were pooled, which no one model fits (identify each vehicle's logs on its own)"
            + ("; the halves of the logs disagree too, so a parameter may drift within the "
               "flights (a battery that sags)" if drift else ""),
            False,  # (the halves of logs that disagree differ between the logs too)
        )  # fmt: skip
    if not drift:
        return None, False
    count, i, j, low, high, more = drift
    return (
        f"the halves of the logs disagree: refitted on each of {count} half-logs alone, "
        f"{trajs[0].state_names[i]}' differs beyond what their noise allows ('{names[j]}' "
        f"from {low:.4g} to {high:.4g}){_others(more)}: a parameter drifts within the flights "
        "(a battery that sags, fuel or a payload that changes), the inputs did not act as "
        "logged, or the library lacks a term that changes along them; no one model fits both "
        "halves",
        True,
    )


DRIFT_SPAN = 0.4
"""The largest change of the inputs' gain over the longest log that :func:`input_drift`
searches (either way from the drift the data already carry)."""

DRIFT_MATERIAL = 1e-2
"""A drift that changes the inputs' gain by less than this share over the longest log is not
tried (clean logs of a vehicle that does not sag fit one of 1e-8 "significantly"; logs of
clipped rotors and of lagging actuators fitted with their lag named 0.12 % and 1 %, and
each cost a selection more)."""


def input_drift(trajs: Sequence[Trajectory], names: Sequence[str], window: int,
                xi: np.ndarray, named: bool = True) -> tuple[float, float] | None:  # fmt: skip
    """The drift ``(a1, a2)`` of the inputs' gain that the model's own terms fit best.

    A battery that sags alike in every flight turns each logged command into less force as
    the flight goes on (:meth:`~identification.data.Trajectory.drift_inputs`: applied =
    ``(1 + a1 tau + a2 tau^2) command``, ``tau`` the time since the log's first row). Each
    equation with an input term is refitted on its terms in ``xi`` with the held inputs so
    scaled, and the drift that leaves the least mean log residual is found: ``a1`` first
    (bounded search of :data:`DRIFT_SPAN` over the longest log about the drift the data
    carry: the model selected with a drift refines it), then ``a2`` where it earns its
    place beside it and the gain runs one way (a sag that speeds up as the charge runs out:
    a held-out trial's ``1 - 0.08 (tau / T)^2`` fitted as a line was 1.3 % off on the
    thrust, 9.7 % at 1 s; a curve down 8 % and back up stood in for an 80 ms lag of inputs
    kept as logged).

    ``named``: something else named the drift (the halves of the logs disagree on an
    input's gain, or the data carry one). Else ``a1`` must earn its place too. A
    coefficient earns it where its drop in the equations' residual variances (taken over
    the rows' long-run ratio) passes the chi-square bar at
    :data:`~identification.support.PRUNE_P` for the equations and it changes the gain by at
    least :data:`DRIFT_MATERIAL` over the longest log. A closed loop answers a sag, and its
    model can hold stand-ins for it that leave the halves agreeing: a trial's 8 % over each
    flight got `-0.1623 z` and `0.1047 y` in `z_dot'` and no note (the drift's drop there:
    1.8e18 variances; without a sag, gusts of 2 to 5 % m g gave 1.5 to 3.9, and +1.1 %
    passed a bar that took the correlated rows as independent).

    Returns:
        The drift (the data's own where none fits better), or None where it is not named
        and does not earn its place.
    """
    from scipy.optimize import minimize, minimize_scalar
    from scipy.stats import chi2

    from identification.support import long_run_ratio

    driven = _driven(trajs, names, xi)
    usable = [(t, s) for t, s in zip(trajs, log_starts(trajs), strict=True)
              if len(t) >= window + 3]  # fmt: skip
    now = input_drift_of(trajs)
    if not driven or not usable:
        return now if named else None
    span = max(float(t.t[-1]) - s for t, s in usable)
    refit = _own_terms_refit(xi, names, window, driven)
    scale = np.array([span, span**2])  # a coefficient times its scale: its gain change

    def drifted(terms: tuple[float, float]) -> list[Trajectory] | None:
        try:
            return [t.drift_inputs(terms, s) for t, s in usable]
        except ValueError:  # a gain under the floor
            return None

    def cost(terms: tuple[float, float]) -> float:
        data = drifted(terms)
        return np.inf if data is None else float(np.mean(np.log(refit(data)[0])))

    bar = chi2.isf(PRUNE_P, len(driven))

    @functools.cache
    def ratio() -> np.ndarray:  # (only where a drift is material: one pass over the rows)
        return np.maximum(long_run_ratio([t for t, _ in usable], names, xi, window)[driven], 1.0)

    def earns(before: tuple[float, float], after: tuple[float, float], k: int) -> bool:
        """Whether changing coefficient ``k`` from ``before`` to ``after`` earns its place."""
        if abs(after[k] - before[k]) * scale[k] < DRIFT_MATERIAL:
            return False
        rss0, _ = refit(drifted(before))
        rss1, sigma2 = refit(drifted(after))
        return float(np.sum((rss0 - rss1) / (sigma2 * ratio()))) > bar

    bounds = (now[0] - DRIFT_SPAN / span, now[0] + DRIFT_SPAN / span)
    found = minimize_scalar(lambda a: cost((a, 0.0)), bounds=bounds, method="bounded",
                            options={"xatol": 1e-4 / span})  # fmt: skip
    linear = (float(found.x), 0.0)
    if abs(linear[0] - now[0]) * span < DRIFT_MATERIAL and not any(now):
        return None  # (named or not: so small a drift is not worth a selection)
    if not named and not earns((0.0, 0.0), linear, 0):
        return None
    # the second coefficient, from the line (in units of the gain's change over the span)
    start = np.multiply(linear, scale)
    curve = minimize(
        lambda b: cost((b[0] / span, b[1] / span**2)),
        start,
        method="Nelder-Mead",
        options={"xatol": 1e-9, "fatol": 1e-12, "initial_simplex": _simplex(start)},
    )
    curved = (float(curve.x[0] / span), float(curve.x[1] / span**2))
    steps = np.diff(drift_gain(curved, np.linspace(0.0, span, 101)))
    # a battery's gain (or a fuel burn's) runs one way: a curve that turns back is no drift
    one_way = min(np.sum(steps[steps > 0]), -np.sum(steps[steps < 0])) < DRIFT_MATERIAL
    if one_way and earns(linear, curved, 1):
        return curved
    near = (found.x - 2e-4 / span, found.x + 2e-4 / span)  # a1 to 1e-8 of the gain
    fine = minimize_scalar(lambda a: cost((a, 0.0)), bounds=near, method="bounded",
                           options={"xatol": 1e-8 / span})  # fmt: skip
    return min((linear, (float(fine.x), 0.0)), key=cost)


def _simplex(start: np.ndarray) -> np.ndarray:
    """Nelder-Mead's first simplex about ``start``: 1 % of the gain each way."""
    return np.array([start, start + [0.01, 0.0], start + [0.0, 0.01]])


def _others(more: int) -> str:
    return f" (and {more} other equation(s))" if more else ""


def _disagreeing(
    trajs: Sequence[Trajectory],
    names: Sequence[str],
    window: int,
    xi: np.ndarray,
    gains: bool = False,
) -> tuple | None:
    """The segments' disagreement of :func:`disagreement_note`, or None.

    ``gains``: an equation counts only where the term that moves it most holds an input. A
    vehicle's drifting parameters (a battery, a payload) are input gains; a constant that
    moves between the halves of a log is a slow force (gusts: a trial's `'1' from -10.02 to
    -9.559`) or a misfit, and was named as drift.

    Returns:
        (segments compared, state, term, lowest and highest refit of the term, other
        equations that disagree).
    """
    from scipy.stats import chi2

    from identification.support import long_run_ratio, refit_support

    if len(trajs) < 2 or not np.any(xi):
        return None
    parts = grams(list(trajs), list(names), "rk4", window, xi)
    supports = [[int(j) for j in np.flatnonzero(row)] for row in xi]
    fits = []  # per segment and equation: coefficients, precision, normal matrix, target, rows
    for tr, g in zip(trajs, parts, strict=True):
        if g.rows < max(5 * max(len(s) for s in supports), MIN_UNIT_ROWS):
            continue
        own = np.array([refit_support(g, i, support) for i, support in enumerate(supports)])
        ratio = np.maximum(long_run_ratio([tr], list(names), own, window), 1.0)
        per = []
        for i, support in enumerate(supports):
            sigma2 = residual_variance(g, i, support)[1] * float(ratio[i])
            normal = g.r[:, support].T @ g.r[:, support]
            total = float(np.linalg.norm(g.r_aug[:, g.p + i]) ** 2)
            per.append((own[i, support], normal / max(sigma2, 1e-300), normal, total, g.rows))
        fits.append(per)
    if len(fits) < 2:
        return None
    found = []  # (excess over the bar, state, term, low, high)
    for i, support in enumerate(supports):
        if not support:
            continue
        est = np.array([f[i][0] for f in fits])
        precision = sum(f[i][1] for f in fits)
        pooled = np.linalg.lstsq(precision, sum(f[i][1] @ f[i][0] for f in fits), rcond=None)[0]
        chi = sum(float((f[i][0] - pooled) @ f[i][1] @ (f[i][0] - pooled)) for f in fits)
        lost = sum(float((f[i][0] - pooled) @ f[i][2] @ (f[i][0] - pooled)) for f in fits)
        targets = sum(f[i][3] for f in fits)
        bar = chi2.isf(DISAGREE_P / xi.shape[0], len(support) * (len(fits) - 1))
        if chi > bar and lost > DISAGREE_SHARE * targets:
            rms = np.sqrt(np.mean([np.diag(f[i][2]) / f[i][4] for f in fits], axis=0))
            k = int(np.argmax((est.max(axis=0) - est.min(axis=0)) * rms))
            inputs = set(trajs[0].input_names)
            if gains and not any(f.var in inputs for f in parse_term(names[support[k]])):
                continue
            found.append((chi / bar, i, support[k], est[:, k].min(), est[:, k].max()))
    if not found:
        return None
    _, i, j, low, high = max(found)
    return len(fits), i, j, low, high, len(found) - 1


INPUT_SHIFTS = (-3, -2, -1, 1, 2, 3)
"""Shifts of the inputs [rows] that :func:`input_timing` tries."""

INPUT_LAGS = (0.5, 1.0, 2.0, 3.0, 4.0, 6.0, 8.0, 12.0, 16.0)
"""First-order lags of the held inputs [median steps] that :func:`input_timing` tries (to
0.16 s at 100 Hz: a Crazyflie's motors take about 0.07 s)."""

LONGER_LAGS = (1.0, 1.5, 2.0, 3.0, 4.0)
"""Where the longest of :data:`INPUT_LAGS` fits best, these multiples of it are tried too
(their start cut is longer, so short logs do not pay for it; a recheck trial's 0.25 s lag
was named at 0.16 s, 1.7 % at 1 s against an exact model at 0.25 s)."""

SHIFT_GAIN = 0.9
"""A shift is named only where it leaves at most this share of an equation's residual."""


ROUNDOFF_SHARE = 1e-9
"""A residual under this share of its target's norm is round-off (the shift checks' floor)."""

SHIFT_ROWS = 20_000
"""Rows the shift checks refit on at most (evenly spread blocks of more data): a 6-DOF log of
1e5 rows spent 30 of its 130 s refitting each state and input shift on all of them."""


@dataclasses.dataclass(frozen=True)
class InputTiming:
    """What :func:`input_timing` found: its note, and the shift or lag that fits best.

    Attributes:
        note: The warning, in words.
        kind: ``"shift"`` (whole rows) or ``"lag"`` (a first-order time constant).
        value: The shift [rows, from the data as given] or the lag [s, from the commands].
        lag: Where a shift to earlier rows fits best, the best lag that passed too [s] (0:
            none): under state noise a lag's in-sample fit may trail the shift it looks
            like, and cross-validation can tell them apart.
    """

    note: str
    kind: str
    value: float
    lag: float = 0.0


def input_timing(
    trajs: Sequence[Trajectory],
    names: list[str],
    window: int,
    xi: np.ndarray,
    ratio: np.ndarray,
    command: str = "identify again",
    shifts: Sequence[int] = INPUT_SHIFTS,
) -> InputTiming | None:
    """Where the model's equations fit better with the inputs shifted or lagged: how, and a note.

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

    Held inputs are also passed through first-order lags of :data:`INPUT_LAGS` median steps
    (:meth:`Trajectory.lag_inputs` from the logged commands, the first :data:`LAG_SETTLE`
    longest time constants of each block cut): motors that lag their commands act like
    inputs taken a few rows earlier, and no shift fits them (a planar trial at 40 ms:
    ``phi_dot'`` to 31 % with 2 rows, to round-off with the lag). A lag passes the same bar,
    where the equations gain together (an equation whose terms the lag made up may fit
    worse), its time constant is refined between its grid neighbours, and it is named where
    it leaves less of the residual than the best shift. ``shifts=()`` tries the lags alone.
    """
    driven = _driven(trajs, names, xi)
    margin = max(abs(d) for d in INPUT_SHIFTS)
    blocks = spread_blocks(trajs, SHIFT_ROWS)
    usable = long_enough(blocks, window + 2 * margin + 2)
    if not driven or not usable:
        return None
    refit = _own_terms_refit(xi, names, window, driven)
    applied_lag = input_lag_of(trajs)
    dt = float(np.median([t.dt for t in usable]))
    held = any(n not in trajs[0].measured for n in trajs[0].input_names)
    lags = [m * dt for m in INPUT_LAGS if abs(m * dt - applied_lag) > 0.1 * applied_lag]
    lags = [0.0, *lags] if applied_lag and held else lags if held else []
    bar = significance_bar((len(shifts) + len(lags)) * len(driven))
    scale = np.maximum(np.asarray(ratio, dtype=float)[driven], 1.0)

    def gain(rss: np.ndarray, sigma2: np.ndarray, rss0: np.ndarray, sigma0: np.ndarray,
             together: bool = False) -> Any:  # fmt: skip
        """Residual shares where a candidate passes the bar and no equation fits worse.

        With ``together`` (a lag) an equation may fit worse where the equations gain
        together (the geometric mean of their shares under 1): a model fitted to commands
        of lagging actuators holds input terms in equations they do not drive (a planar
        trial: ``y'`` four times worse, ``phi_dot'`` exact with the lag).
        """
        passes = (rss <= SHIFT_GAIN * rss0) & (rss0 - rss > bar * scale * sigma2)
        worse = rss - rss0 > bar * scale * sigma0
        shares = rss / np.maximum(rss0, 1e-300)
        if together and worse.any():
            worse = np.mean(np.log(shares)) >= 0.0
        return shares if passes.any() and not worse.any() else None

    rss0, sigma0 = refit([t.shift_inputs(0, margin) for t in usable])
    best: tuple[float, float, np.ndarray, str] | None = None  # (share, shift or lag, shares, kind)
    for shift in shifts:
        shares = gain(*refit([t.shift_inputs(shift, margin) for t in usable]), rss0, sigma0)
        if shares is not None and (best is None or shares.min() < best[0]):
            best = (float(shares.min()), shift, shares, "shift")

    def lag_search(grid: Sequence[float]) -> tuple[float, float, np.ndarray] | None:
        """The best passing lag of ``grid``, refined between its neighbours.

        Each block is cut by :data:`LAG_SETTLE` of the grid's longest lag.
        """
        settle = int(np.ceil(LAG_SETTLE * max(grid) / dt))  # the actuators' unknown start
        usable = long_enough(blocks, window + settle + 2)
        if not usable:
            return None
        lag0 = refit([t.slice(settle, len(t)) for t in usable])

        def lagged(tau: float) -> tuple[np.ndarray, np.ndarray]:
            return refit([t.lag_inputs(tau, settle=False).slice(settle, len(t))
                          for t in usable])  # fmt: skip

        found = [(tau, gain(*lagged(tau), *lag0, together=True)) for tau in grid]
        passing = [(float(shares.min()), tau, shares) for tau, shares in found
                   if shares is not None]  # fmt: skip
        if not passing:
            return None
        share, tau, shares = min(passing)
        if tau > 0:  # between the grid's neighbours: the lag that fits best
            tau, shares = _closest_lag(lagged, lag0[0], tau, grid)
        return float(shares.min()), tau, shares

    found_lag = lag_search(lags) if lags else None
    if found_lag and found_lag[1] >= 0.97 * max(lags):  # at the grid's top: longer lags too
        top = max(lags)
        longer = lag_search([top * f for f in LONGER_LAGS])
        if longer and longer[0] < found_lag[0]:
            found_lag, lags = longer, [*lags, *(top * f for f in LONGER_LAGS)]
    if found_lag and (best is None or found_lag[0] < best[0]):
        best = (found_lag[0], found_lag[1], found_lag[2], "lag")
    if best is None:
        return None
    _, value, shares, kind = best
    states = trajs[0].state_names
    pairs = [(states[i], share) for i, share in zip(driven, shares, strict=True)]
    listed = ", ".join(f"{s}' to {100 * r:.2g} %" for s, r in pairs if r <= SHIFT_GAIN)
    applied = int(trajs[0].meta.get("input_shift", 0))  # already shifted by --input-shift
    widest = max(INPUT_SHIFTS)
    filtered = ("the states may be filtered estimates that lag the inputs (a low-pass filter "
                "or a state estimator")  # fmt: skip
    if kind == "lag":
        tried = f"lags of {min(lags):.2g} to {max(lags):.2g} s and shifts up to {widest} rows"
        if value == 0:
            return InputTiming(
                f"the model's terms fit the data better with the inputs acting as logged, "
                f"without the lag of {applied_lag:.2g} s (residual {listed}; {tried} tried): "
                f"{command} with --input-lag 0", "lag", 0.0,
            )  # fmt: skip
        lagging = ", ".join(n for n in trajs[0].input_names if n not in trajs[0].measured)
        return InputTiming(
            f"the model's terms fit the data better with the inputs {lagging} acting through "
            f"a first-order lag of {value:.3g} s (residual {listed}; {tried} tried): the "
            f"actuators may lag their commands (a motor's time constant), or {filtered}: a "
            f"lag then stands in for the filter); {command} with --input-lag {value:.3g} if "
            "the actuators lag (the other warnings may be its symptoms)", "lag",
            float(f"{value:.3g}"),
        )  # fmt: skip
    shift = int(value)
    runner_up = float(f"{found_lag[1]:.3g}") if found_lag and shift < 0 else 0.0
    lag_hint = ": --input-lag models it" if held else ""  # (measured signals are not lagged)
    cause = (
        "the log may record the inputs late, or the inputs are signals that change within "
        "each step, sampled at its rows (an actuator's measured output: --measured "
        "interpolates them; a held-out trial's lagged thrust logged as held: 0.42 % at 1 s, "
        "0.04 % with --measured)"
        if shift > 0
        else f"the actuators may lag (a motor's time constant{lag_hint}), {filtered}; no "
        "shift undoes a filter), or the log records the inputs early"
    )
    return InputTiming(
        f"the model's terms fit the data better with the inputs taken {abs(shift)} row(s) "
        f"{'later' if shift > 0 else 'earlier'} (residual {listed}; shifts up to {widest} "
        f"rows tried): {cause}; {command} with --input-shift {applied + shift} if the "
        "log is off (the other warnings may be its symptoms)", "shift", float(shift), runner_up,
    )  # fmt: skip


def _driven(trajs: Sequence[Trajectory], names: Sequence[str], xi: np.ndarray) -> list[int]:
    """The equations of ``xi`` that hold a term of an input."""
    inputs = set(trajs[0].input_names)
    variables = [*trajs[0].state_names, *trajs[0].input_names]
    return [i for i in range(xi.shape[0])
            if any(f.var in inputs for j in np.flatnonzero(xi[i])
                   for f in parse_term(names[j], variables))]  # fmt: skip


SATURATION_SHARES = (0.9, 0.95, 0.98, 0.99, 0.995, 0.998)
"""Shares of the rows below the thresholds of the hinges :func:`input_saturation` tries."""

SATURATION_FLOOR = 1e-3
"""A hinge must lower an equation's residual by this share of its target's sum of squares on
the hinge's own rows, on top of passing the bar: on clean data the residual is truncation
error, which any column explains "significantly" (of the whole target, the few clipped steps
left after an outlier cut never reached it)."""

SATURATION_HINGES = 2
"""Hinges :func:`input_saturation` names at most per input: a mixer of as many rotors as
inputs, each at either limit."""


def input_directions(m: int) -> np.ndarray:
    """Unit directions in the space of ``m`` standardised inputs (rows).

    Both signs of one input; 72 angles for two (a planar mixer's rotor is one of them to
    within 2.5 deg); else 64 per input drawn at random (a fixed seed) and the axes.
    """
    if m == 1:
        return np.array([[1.0], [-1.0]])
    if m == 2:
        angles = np.linspace(0.0, 2.0 * np.pi, 72, endpoint=False)
        return np.column_stack([np.cos(angles), np.sin(angles)])
    drawn = np.random.default_rng(0).standard_normal((64 * m, m))
    drawn = np.vstack([drawn, np.eye(m), -np.eye(m)])
    return drawn / np.linalg.norm(drawn, axis=1, keepdims=True)


@dataclasses.dataclass(frozen=True)
class Hinge:
    """A combination of the logged inputs beyond whose limit the states respond less.

    Attributes:
        weights: The combination of the logged inputs.
        limit: The value of ``weights @ u`` beyond which the response flattens.
        share: The share of the rows beyond it.
        drop: The residual variances it takes back, summed over the driven equations.
    """

    weights: np.ndarray
    limit: float
    share: float
    drop: float


@dataclasses.dataclass(frozen=True)
class Saturation:
    """What :func:`input_saturation` found: its note and its hinges, strongest first."""

    note: str
    hinges: tuple[Hinge, ...]

    def flagged(self, trajs: Sequence[Trajectory]) -> dict[int, np.ndarray]:
        """The steps beyond any hinge, every state, as :func:`outlying_steps` gives steps."""
        out = {}
        for i, tr in enumerate(trajs):
            u = tr.u[_step_rows(tr)]
            beyond = np.any([u @ h.weights > h.limit for h in self.hinges], axis=0)
            if beyond.any():
                out[i] = np.repeat(beyond[:, None], len(tr.state_names), axis=1)
        return out


def input_saturation(
    trajs: Sequence[Trajectory], names: Sequence[str], xi: np.ndarray
) -> Saturation | None:
    """The directions of the inputs beyond whose extremes the states respond less, or None.

    Commands that the actuators clip (a rotor at its limit) act less than logged on the rows
    beyond the limit; with sensor noise no single step stands out (:func:`outlying_steps`)
    and the fit bends its coefficients instead (a held-out trial: 7 to 22 % at 1 s and no
    note). The residuals of the model's input-driven equations (window 1, RK4, each refitted
    on its own terms) are tested for a hinge ``max(0, d . u - c)`` of the standardised
    inputs ``u``: every direction ``d`` of :func:`input_directions` and threshold ``c`` at a
    share of :data:`SATURATION_SHARES` of the rows. An equation counts the hinge only where
    it takes the response back (its slope against the model's own mean change along ``d`` on
    the hinge's rows); the drops in residual variances, summed over the equations, must pass
    the chi-square bar at p = 0.001 over all the hinges tried, and one drop must be
    :data:`SATURATION_FLOOR` of its target on the hinge's rows.

    A hinge that passes is refined: its direction and threshold move to where the drop is
    largest (Nelder-Mead, at most the grid's widest share of the rows beyond it), since in
    four inputs the drawn directions lie up to about 25 deg off a rotor's and cut as many
    unclipped rows as clipped ones (a held-out trial: 40 steps beyond, 17 of them clipped).
    The equations are then refitted with the hinges found beside their own terms and the
    next hinge is searched the same way, up to :data:`SATURATION_HINGES` per input: every
    rotor of a mixer may clip, at either limit.
    """
    from scipy.stats import chi2

    driven = _driven(trajs, names, xi)
    blocks = [t for t in spread_blocks(trajs, SHIFT_ROWS) if len(t) > 3]
    if not driven or not blocks or not trajs[0].input_names:
        return None
    thetas, ys = [], []
    for _, theta, y in iter_rows(blocks, list(names), "rk4", 1, xi):
        thetas.append(theta)
        ys.append(y)
    theta, y = np.concatenate(thetas), np.concatenate(ys)
    inputs = np.concatenate([t.u[_step_rows(t)] for t in blocks])
    if len(inputs) != len(y):
        return None
    spread = inputs.std(axis=0)
    own_terms = np.count_nonzero(np.any(xi[driven] != 0, axis=0))
    if len(y) < 10 * own_terms or np.any(spread <= 0):
        return None
    directions = input_directions(inputs.shape[1])
    standardised = (inputs - inputs.mean(axis=0)) / spread
    along = standardised @ directions.T
    bar = float(chi2.isf(PRUNE_P / (len(directions) * len(SATURATION_SHARES)), len(driven)))
    states = np.concatenate([t.x[_step_rows(t)] for t in blocks])
    # the model's change per standardised unit of each input, (rows, equations, inputs)
    response = _input_jacobian(names, trajs[0], xi[driven], states, inputs, spread) * spread
    most = int((1.0 - min(SATURATION_SHARES)) * len(y))
    found: list[Hinge] = []
    columns: list[np.ndarray] = []
    while len(found) < SATURATION_HINGES * inputs.shape[1]:
        fits = _own_fits(theta, y, xi, driven, columns)
        best = None
        for share in SATURATION_SHARES:
            start = np.quantile(along, share, axis=0)
            hinges = np.maximum(along - start, 0.0)
            drop, material = _hinge_drops(fits, hinges, directions, response)
            ok = (drop > bar) & material
            k = int(np.argmax(np.where(ok, drop, -np.inf)))
            if ok[k] and (best is None or drop[k] > best[0]):
                best = (float(drop[k]), directions[k], float(start[k]))
        if best is None:
            break
        drop, d, c = _refined_hinge(fits, standardised, response, *best, most)
        columns.append(np.maximum(standardised @ d - c, 0.0))
        weights = d / spread
        found.append(Hinge(weights, c + float(weights @ inputs.mean(axis=0)),
                           float(np.mean(columns[-1] > 0)), drop))  # fmt: skip
    if not found:
        return None
    first, *more = found
    named = trajs[0].input_names
    others = (
        f"; {len(more)} more past it, each refitted beside those before: "
        + ", ".join(f"{_combination(h.weights, named)} (top {h.share:.1%})" for h in more)
        if more else ""
    )  # fmt: skip
    note = (
        f"the states respond less to the inputs beyond their extremes: along "
        f"{_combination(first.weights, named)}, the top {first.share:.1%} of the rows leave a "
        f"hinge in the residuals ({first.drop:.0f} residual variances against the bar of "
        f"{bar:.0f}){others}: commands beyond what the actuators give (a rotor at its limit) "
        "were logged, and the model bends to them; log the applied inputs"
    )
    return Saturation(note, tuple(found))


def _own_fits(
    theta: np.ndarray, y: np.ndarray, xi: np.ndarray, driven: list[int], columns: list
) -> list[tuple]:
    """Each driven equation refitted on its own terms and ``columns`` (the hinges found).

    Returns (orthonormal basis, residual, its sum of squares, the target's squares, degrees
    of freedom) per equation.
    """
    fits = []
    for i in driven:
        basis, _ = np.linalg.qr(np.column_stack([theta[:, np.flatnonzero(xi[i])], *columns]))
        residual = y[:, i] - basis @ (basis.T @ y[:, i])
        dof = max(len(y) - basis.shape[1] - 1, 1)
        fits.append((basis, residual, float(residual @ residual), y[:, i] ** 2, dof))
    return fits


def _combination(weights: np.ndarray, names: Sequence[str]) -> str:
    """``weights`` of the inputs ``names``, scaled to a largest of one, as a note prints them."""
    scaled = weights / np.max(np.abs(weights))
    return " ".join(f"{w:+.2g} {n}" for w, n in zip(scaled, names, strict=True))


def _hinge_drops(
    fits: list, hinges: np.ndarray, directions: np.ndarray, response: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The residual variances each hinge takes back, and whether it is material in one.

    ``hinges`` (rows, k) lie along ``directions`` (k, inputs); the drops are summed over the
    equations ``fits`` (:func:`_own_fits`).
    """
    on = (hinges > 0).astype(float)
    count = np.maximum(on.sum(axis=0), 1.0)
    drop = np.zeros(hinges.shape[1])
    material = np.zeros(hinges.shape[1], dtype=bool)
    for e, (basis, residual, rss, squares, dof) in enumerate(fits):
        h = hinges - basis @ (basis.T @ hinges)
        fit = residual @ h
        gain = fit**2 / np.maximum(np.sum(h * h, axis=0), 1e-300)
        # only a hinge that takes the model's response along d back counts: its slope
        # against the model's mean change per unit step along d on the hinge's rows
        mean_change = np.sum((on.T @ response[:, e, :]) * directions, axis=1) / count
        back = fit * mean_change < 0.0
        drop += np.where(back, gain / np.maximum((rss - gain) / dof, 1e-300), 0.0)
        material |= back & (gain > SATURATION_FLOOR * (squares @ on))
    return drop, material


def _refined_hinge(
    fits: list, standardised: np.ndarray, response: np.ndarray, drop: float, d: np.ndarray,
    c: float, most: int,
) -> tuple[float, np.ndarray, float]:  # fmt: skip
    """The direction and threshold near ``(d, c)`` whose hinge takes back most (a drop, d, c)."""
    from scipy.optimize import minimize

    def cost(p: np.ndarray) -> float:
        d = p[:-1] / max(float(np.linalg.norm(p[:-1])), 1e-12)
        hinge = np.maximum(standardised @ d - p[-1], 0.0)[:, None]
        if not 3 <= np.count_nonzero(hinge) <= most:
            return 0.0
        drop, material = _hinge_drops(fits, hinge, d[None, :], response)
        return -float(drop[0]) if material[0] else 0.0

    start = np.append(d, c)
    simplex = np.vstack([start, start + 0.05 * np.eye(len(start))])
    options = {"initial_simplex": simplex, "maxfev": 100 * len(start), "xatol": 1e-4,
               "fatol": 1e-3}  # fmt: skip
    found = minimize(cost, start, method="Nelder-Mead", options=options)
    if -found.fun <= drop:
        return drop, d, c
    norm = float(np.linalg.norm(found.x[:-1]))
    return float(-found.fun), found.x[:-1] / norm, float(found.x[-1])


def _input_jacobian(
    names: Sequence[str], first: Trajectory, xi: np.ndarray, states: np.ndarray,
    inputs: np.ndarray, spread: np.ndarray,
) -> np.ndarray:  # fmt: skip
    """The rows' derivatives of the equations ``xi`` by each input, (rows, equations, inputs)."""
    used = np.flatnonzero(np.any(xi != 0, axis=0))  # the equations' own terms only
    xi = xi[:, used]
    theta = compile_features([names[j] for j in used], first.state_names, first.input_names)
    base = theta(states, inputs) @ xi.T
    out = np.empty((len(inputs), xi.shape[0], inputs.shape[1]))
    for j, step in enumerate(1e-6 * spread):
        moved = inputs.copy()
        moved[:, j] += step
        out[:, :, j] = (theta(states, moved) @ xi.T - base) / step
    return out


LAG_REFINE = 1.15
""":func:`refined_lag` searches within this factor of the lag it is given."""


def refined_lag(
    trajs: Sequence[Trajectory], names: Sequence[str], window: int, xi: np.ndarray, tau: float
) -> float:
    """The lag within :data:`LAG_REFINE` of ``tau`` that the model's own terms fit best.

    :func:`input_timing` finds a lag on the terms of the model of the inputs as logged,
    which lacks terms the lag hid and holds some it made up, so its lag lands a few per
    cent off (our own planar flights at 80 ms: 0.079 s, and the model selected with it
    held 2 spurious terms). The model selected with that lag holds nearly the right terms;
    refitted on them with the inputs lagged again (``trajs``: the logged commands), the
    mean log residual of the equations with an input term is least at the lag the data
    hold (golden section on log tau, to 0.1 %). Returns ``tau`` where nothing fits better.
    """
    from scipy.optimize import minimize_scalar

    driven = _driven(trajs, names, xi)
    dt = float(np.median([t.dt for t in trajs]))
    settle = int(np.ceil(LAG_SETTLE * LAG_REFINE * tau / dt))  # the actuators' unknown start
    usable = long_enough(spread_blocks(trajs, SHIFT_ROWS), window + settle + 2)
    if not driven or not usable:
        return tau
    refit = _own_terms_refit(xi, names, window, driven)

    def cost(log_tau: float) -> float:
        lagged = [t.lag_inputs(float(np.exp(log_tau)), settle=False).slice(settle, len(t))
                  for t in usable]  # fmt: skip
        return float(np.mean(np.log(np.maximum(refit(lagged)[0], 1e-300))))

    bounds = (np.log(tau / LAG_REFINE), np.log(tau * LAG_REFINE))
    found = minimize_scalar(cost, bounds=bounds, method="bounded", options={"xatol": 1e-3})
    return float(np.exp(found.x)) if cost(found.x) < cost(np.log(tau)) else tau


def _closest_lag(lagged: Any, rss0: np.ndarray, tau: float, lags: Sequence[float]) -> tuple:
    """The lag between ``tau``'s neighbours in ``lags`` whose refit leaves the least residual.

    Minimises the mean log residual share of the equations (golden section on log tau, to
    about 3 %); returns the lag and its shares.
    """
    from scipy.optimize import minimize_scalar

    grid = sorted(t for t in lags if t > 0)
    i = grid.index(tau)
    low, high = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
    if low == high:
        return tau, lagged(tau)[0] / np.maximum(rss0, 1e-300)

    def cost(log_tau: float) -> float:
        rss = lagged(float(np.exp(log_tau)))[0]
        return float(np.mean(np.log(rss / np.maximum(rss0, 1e-300))))

    found = minimize_scalar(cost, bounds=(np.log(low), np.log(high)), method="bounded",
                            options={"xatol": 0.03})  # fmt: skip
    best = float(np.exp(found.x)) if cost(found.x) <= cost(np.log(tau)) else tau
    return best, lagged(best)[0] / np.maximum(rss0, 1e-300)


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
        pairs = [residual_variance(g, i, supports[i]) for i in rows]
        sigma2 = np.array([p[1] for p in pairs])
        # the whole residual (the variance's numerator): the RSS within the columns' range
        # alone is near zero where one equation holds nearly all of them (a real log's
        # vz' on its 12 terms: 1e-9 against a variance of 0.3, and no shift could pass)
        rss = sigma2 * np.array([max(max(g.rows, 2.0) - len(supports[i]), 1.0) for i in rows])
        # residuals under round-off of the targets are no residuals: a shift that changes
        # them is no gain (a recheck trial's exact model named "w taken 1 row earlier")
        floor = (ROUNDOFF_SHARE * g.y_norms[list(rows)]) ** 2
        return np.maximum(rss, floor), np.maximum(sigma2, floor / max(g.rows, 1))

    return residuals


def timing_note(
    trajs: Sequence[Trajectory],
    names: list[str],
    window: int,
    xi: np.ndarray,
    ratio: np.ndarray,
    command: str = "identify again",
) -> str | None:
    """:func:`input_timing`'s note, else :func:`state_shift_note`'s (a state column that lags)."""
    timing = input_timing(trajs, names, window, xi, ratio, command)
    return timing.note if timing else state_shift_note(trajs, names, window, xi, ratio)


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
    usable = long_enough(spread_blocks(trajs, SHIFT_ROWS), window + 2 * margin + 2)
    rows = [i for i in range(xi.shape[0]) if np.any(xi[i])]
    if not usable or not rows:
        return None
    residuals = _own_terms_refit(xi, names, window, rows)
    rss0, sigma0 = residuals([t.slice(margin, len(t) - margin) for t in usable])
    bar = significance_bar(len(states) * len(INPUT_SHIFTS) * len(rows))
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
        if not mine.any():  # no equation reads this column (its own is empty)
            continue
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


REST_ROWS = 20
"""Rows a still block spans at least (:func:`still_blocks`), and the chunks it is judged in."""

REST_SHARE = 0.05
"""Share of a state's standard deviation over the data that a model's prediction over a still
chunk must leave it by (and :data:`REST_NOISE` noise deviations) for the chunk to be held."""

REST_NOISE = 10.0
"""Noise deviations (:func:`_state_noise`) a held chunk's prediction must leave a state by."""

REST_BAND = 8.0
"""Noise deviations within which every state of a still block stays (:func:`still_blocks`)."""

REST_DRIFT_ROWS = 100
"""Rows a block in which one state drifts along a line (an altitude estimate on the ground)
spans at least (:func:`still_blocks`)."""

REST_MARGIN = 3.0
"""A held chunk leaves the logged states by this many times what the model leaves them by in
19 of 20 chunks of the rest of the data (:func:`held_blocks`)."""

REST_SAMPLE = 300
"""Chunks of the rest of the data that :func:`held_blocks` flies to learn the model's usual
miss."""


def _state_noise(trajs: Sequence[Trajectory]) -> np.ndarray:
    """Each state's white-noise deviation, from the robust spread of its second differences."""
    second = np.concatenate([np.diff(t.x, 2, axis=0) for t in trajs if len(t) > 2])
    second = second[np.isfinite(second).all(axis=1)]
    if not len(second):
        return np.zeros(trajs[0].x.shape[1])
    mad = np.median(np.abs(second - np.median(second, axis=0)), axis=0)
    return 1.4826 * mad / np.sqrt(6.0)


def still_blocks(trajs: Sequence[Trajectory]) -> list[tuple[int, int, int]]:
    """Blocks of rows where every state stays within its noise: (trajectory, start, stop).

    A block spans at least :data:`REST_ROWS` rows in which no state's range exceeds
    :data:`REST_BAND` of its noise deviations (:func:`_state_noise`, or the rows' own; exact
    repeats on clean data). One state of three or more may drift along a straight line
    instead where the block spans :data:`REST_DRIFT_ROWS` rows: an estimate that drifts on
    the ground (a barometer in the rotors' wash). A vehicle resting on the ground, or
    hovering, looks like this; :func:`held_blocks` tells them apart.
    """
    sigma = _state_noise(trajs)
    spread = np.nanstd(np.concatenate([t.x for t in trajs]), axis=0)
    band = REST_BAND * sigma + 1e-9 * np.maximum(spread, 1e-300)
    line = np.arange(REST_ROWS) - (REST_ROWS - 1) / 2
    line /= np.linalg.norm(line)
    found = []
    for i, tr in enumerate(trajs):
        n = len(tr)
        if n < REST_ROWS:
            continue
        windows = np.lib.stride_tricks.sliding_window_view(tr.x, REST_ROWS, axis=0)
        # each window's own noise too: a vehicle on the floor shakes its sensors (a recheck
        # trial's ground rows at 1e-2 in a log at 1e-3 in the air never looked still)
        second = np.diff(windows, 2, axis=2)
        with np.errstate(invalid="ignore"):
            ranges = np.nanmax(windows, axis=2) - np.nanmin(windows, axis=2)
            local = 1.4826 * np.nanmedian(np.abs(second - np.nanmedian(second, axis=2,
                                                                       keepdims=True)),
                                          axis=2) / np.sqrt(6.0)  # fmt: skip
            limit = np.maximum(band, REST_BAND * local)
            within = ranges <= limit  # window k: rows k.. k+19
            covered = _covered(np.flatnonzero(np.all(within, axis=1)), n, 1)
            # one state along a line (a trial's altitude estimate drifting 5 cm/s on the
            # ground never looked still: 10 terms, 17 % off at 1 s, and no note); two at
            # least stay still (a thermal system's one state along a line is no sign of
            # anything held)
            if windows.shape[1] >= 3:
                centred = windows - np.nanmean(windows, axis=2, keepdims=True)
                off_line = centred - np.einsum("kst,t->ks", centred, line)[..., None] * line
                straight = np.nanmax(off_line, axis=2) - np.nanmin(off_line, axis=2)
                drifting = (np.sum(~within, axis=1) == 1) & np.all(
                    within | (straight <= limit), axis=1
                )
                covered |= _covered(np.flatnonzero(drifting), n, REST_DRIFT_ROWS)
        found += [(i, a, b) for a, b in _runs(covered)]
    return found


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """The (start, stop) of each run of True in ``mask``."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(int), [0]])))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def _covered(starts: np.ndarray, n: int, least: int) -> np.ndarray:
    """The rows covered by windows of :data:`REST_ROWS` rows that start at ``starts``.

    Runs of covered rows shorter than ``least`` are left out.
    """
    rows = np.zeros(n + 1, dtype=int)
    np.add.at(rows, starts, 1)
    np.add.at(rows, starts + REST_ROWS, -1)
    covered = np.cumsum(rows)[:n] > 0
    for a, b in _runs(covered):
        if b - a < least:
            covered[a:b] = False
    return covered


def held_blocks(
    model: IdentifiedModel, trajs: Sequence[Trajectory], blocks: Sequence[tuple[int, int, int]]
) -> list[tuple[int, int, int, str, float]]:
    """The chunks of still blocks in which the model says the states would have moved.

    Each block is judged in chunks of :data:`REST_ROWS` rows: the model is flown open loop
    from a chunk's first state with its inputs. Where a state leaves the logged one by more
    than :data:`REST_SHARE` of its spread and :data:`REST_NOISE` noise deviations, and by
    :data:`REST_MARGIN` times more than the model leaves the logged states in 19 of 20
    chunks of the rest of the data, something the model lacks held the vehicle still (the
    ground under it, a stand, a tether); a hovering vehicle's chunk is predicted to stay.
    (Under noise of 1e-2 slow stretches of flight stay within the noise band, and a
    trial's model of lagged actuators, started from a noisy state, left one by 1.1 bars.)
    Returns (trajectory, start, stop, the state that would have moved most, by how many of
    its spreads).
    """
    sigma = _state_noise(trajs)
    spread = np.nanstd(np.concatenate([t.x for t in trajs]), axis=0)
    bar = np.maximum(np.maximum(REST_SHARE * spread, REST_NOISE * sigma), 1e-300)

    def chunks(a: int, b: int) -> list[tuple[int, int]]:
        starts = range(a, b - REST_ROWS + 1, REST_ROWS)  # the last chunk takes the rest
        return [(s, b if b - s < 2 * REST_ROWS else s + REST_ROWS) for s in starts]

    lag = float(model.meta.get("input_lag", 0.0))
    measured = set(model.meta.get("measured_inputs", ()))
    held_inputs = [k for k, n in enumerate(model.input_names) if n not in measured]
    # a lagged model's actuators are where the commands since the segment's start put them
    # (started at a chunk's first command, the dithered commands of a trial's airborne
    # flights left every chunk by 2.85 bars in phi_dot, and 8 of 8 lost rows as "held")
    outputs = [t.lag_inputs(lag, settle=False).u if lag and held_inputs else None for t in trajs]

    def gap(i: int, start: int, stop: int) -> np.ndarray | None:
        """How far the model's path leaves the logged states over rows [start, stop)."""
        tr = trajs[i]
        x = tr.x[start:stop]
        if not np.isfinite(x).all():
            return None
        inputs = tr.commands if tr.commands is not None else tr.u
        at = None if outputs[i] is None else outputs[i][start, held_inputs]
        with np.errstate(all="ignore"):
            try:
                path = model.simulate(x[0], inputs[start : stop - 1], np.diff(tr.t[start:stop]),
                                      actuators=at)  # fmt: skip
            except (ValueError, FloatingPointError):
                return None
            far = np.nanmax(np.abs(path - x), axis=0)
        return np.where(np.isfinite(far), far, np.inf)

    still = {i: np.zeros(len(t), dtype=bool) for i, t in enumerate(trajs)}
    for i, a, b in blocks:
        still[i][a:b] = True
    moving = []  # the chunks of the rest of the data, evenly spread
    for i in range(len(trajs)):
        moving += [(i, *c) for a, b in _runs(~still[i]) for c in chunks(a, b)]
    picks = np.unique(np.linspace(0, len(moving) - 1, min(len(moving), REST_SAMPLE)).astype(int))
    typical = [g for k in picks if moving and (g := gap(*moving[k])) is not None]
    usual = float(np.quantile([np.max(g / bar) for g in typical], 0.95)) if typical else 0.0
    threshold = max(1.0, REST_MARGIN * usual)
    held = []
    for i, a, b in blocks:
        for start, stop in chunks(a, b):
            far = gap(i, start, stop)
            if far is not None and np.max(far / bar) > threshold:
                j = int(np.argmax(far / np.maximum(spread, 1e-300)))
                held.append((i, start, stop, trajs[i].state_names[j], float(far[j] / spread[j])))
    return held


def cut_rows(
    trajs: Sequence[Trajectory], blocks: Sequence[tuple[int, ...]]
) -> tuple[list[Trajectory], int]:
    """The trajectories without the rows of ``blocks`` ((trajectory, start, stop, ...)).

    Pieces under :data:`MIN_UNIT_ROWS` go too; returns the pieces and the rows lost that way.
    """
    drop = {i: np.zeros(len(t), dtype=bool) for i, t in enumerate(trajs)}
    for i, a, b, *_ in blocks:
        drop[i][a:b] = True
    out: list[Trajectory] = []
    lost = 0
    for i, tr in enumerate(trajs):
        for a, b in _runs(~drop[i]):
            if b - a >= MIN_UNIT_ROWS:
                out.append(tr.slice(a, b))
            else:
                lost += b - a
    return out, lost


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
        "applied inputs; inputs measured with noise), glitches, or abrupt effects the library "
        "lacks (gusts)"
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
    notes += _clocks(trajs)
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
    found: dict[str, list[tuple[str, str, float]]] = {}
    for i, state in enumerate(state_names):
        pairs: dict[tuple[str, str], dict[str, float]] = {}
        for j in np.flatnonzero(xi[i]):
            term = parse_term(names[j])
            for trig in term:  # each angle's one sine or cosine in it (other angles' kept)
                if trig.kind not in ("sin", "cos") or trig.k != 1:
                    continue
                if sum(f.var == trig.var for f in term) != 1:
                    continue
                rest = term_name(tuple(f for f in term if f is not trig))
                pairs.setdefault((trig.var, rest), {})[trig.kind] = float(xi[i, j])
        for (angle, rest), both in pairs.items():
            if len(both) == 2:
                turn = -np.arctan2(both["cos"], both["sin"])
                shift = (turn + np.pi / 4) % (np.pi / 2) - np.pi / 4
                found.setdefault(angle, []).append((state, rest, float(shift)))
    # One angle's pairs, whatever their factors: in 6-DOF each equation rotates another
    # factor (`sin(psi) cos(theta) u1` in vx', `cos(theta) u1` in vz'), and a trial's 0.01 rad
    # offset of phi, one pair per equation, went unnamed while grouped by factor.
    for angle, seen in found.items():
        shifts = np.array([b for _, _, b in seen])
        small = np.abs(shifts)
        if len(seen) < 2 or not (1e-4 < small.min() and small.max() < OFFSET_LIMIT):
            continue
        if np.ptp(shifts) > max(0.1 * np.abs(shifts).min(), 1e-4):
            continue
        offset = float(np.mean(shifts))
        where = list(dict.fromkeys(f"{state}'" for state, _, _ in seen))
        factors = list(dict.fromkeys(rest for _, rest, _ in seen))
        verb = "hold" if len(where) > 1 else "holds"
        held = (f"{' and '.join(where)} {verb} sin({angle}) {factors[0]} and cos({angle}) "
                f"{factors[0]}" if len(factors) == 1 else
                f"{', '.join(where)} {verb} sin({angle}) X and cos({angle}) X for each X of "
                f"{', '.join(factors)}")  # fmt: skip
        return (
            f"{held} together as one sine shifted by {offset:.4g} rad: the "
            f"logged {angle} may be offset by {offset:.4g} rad (an IMU's mounting, an "
            f"estimator's bias; subtract it and identify again), or the vehicle's axis is "
            f"tilted by it"
        )
    return None


BIAS_FLOOR = 1e-3
"""A state's constant bias is named only above this share of its standard deviation."""

KINEMATIC_TOL = 0.02
"""A term ``R v`` with a coefficient within this of +-1 reads as a kinematic relation."""


def _kinematic(term: tuple, coef: float, moving: set[str], angles: set[str]) -> bool:
    """Whether ``coef term`` reads as a kinematic relation (``phi_dot``, ``p cos(theta)``).

    One state that is not an angle, to the first power, times functions of the angles only,
    with a coefficient within :data:`KINEMATIC_TOL` of +-1.
    """
    plain = [f for f in term if f.var in moving and f.kind == "pow"]
    return (
        abs(abs(coef) - 1) < KINEMATIC_TOL
        and len(plain) == 1
        and plain[0].k == 1
        and all(f.var in angles for f in term if f is not plain[0])
    )


POSITION_SHARE = 0.01
"""Position terms are named where they carry at least this share of their equation's rhs on
the data (standard deviations): a noise term of no weight is left to the term notes."""


def position_terms_note(
    trajs: Sequence[Trajectory], names: Sequence[str], xi: np.ndarray
) -> str | None:
    """A note where a vehicle's driven equations hold its position.

    A free-flying vehicle's accelerations do not depend on where it is. Terms in a position
    (a state whose own equation is a kinematic relation, as ``z' = z_dot``; angles are
    left out) in an equation that holds an input stand for a force field (ground effect, a
    tether) or for unmeasured forces that the controller answers around its set points: a
    trial's gusts gave ``y_dot' = -16.72 y + 16.72 cos(phi) y + ...`` and ground effect
    ``z_dot' = -9.22 - 0.91 z + ...``, with no word on what they meant. For vehicles only
    (a pendulum's or a spring's position terms are its physics).
    """
    state_names, input_names = trajs[0].state_names, trajs[0].input_names
    angles = trig_variables(names)
    moving = set(state_names) - angles
    terms = [parse_term(n) for n in names]
    positions = {
        state for i, state in enumerate(state_names) if state in moving
        and any(_kinematic(terms[j], xi[i, j], moving, angles) for j in np.flatnonzero(xi[i]))
    }  # fmt: skip
    found = []
    x = u = None  # the data, read once where needed
    for i, state in enumerate(state_names):
        cols = np.flatnonzero(xi[i])
        if state in positions or not any(
            f.var in input_names for j in cols for f in terms[j]
        ):  # a kinematic relation, or no input: not a driven equation
            continue
        placed = [j for j in cols if any(f.var in positions and f.kind == "pow" for f in terms[j])]
        if not placed:
            continue
        if x is None:
            x, u = np.concatenate([t.x for t in trajs]), np.concatenate([t.u for t in trajs])
        share = _rhs_share(names, xi[i], placed, trajs[0], x, u)
        if share >= POSITION_SHARE:
            held = [f"{xi[i, j]:.4g} {names[j]}" for j in placed]
            found.append(f"{state}' ({', '.join(held[:3])}{', ...' if len(held) > 3 else ''}: "
                         f"{share:.0%} of its rhs)")  # fmt: skip
    if not found:
        return None
    return (
        f"the vehicle's equations of motion hold its position: {'; '.join(found)}. A "
        "free-flying vehicle's accelerations do not depend on where it is, so these stand for "
        "a force field (ground effect near the floor, a tether, a wall) or for unmeasured "
        "forces its controller answers around its set points (wind, gusts); the model will "
        "not hold elsewhere: fly away from such effects, or log them"
    )


def state_bias_note(
    xi: np.ndarray, names: Sequence[str], state_names: Sequence[str], spread: np.ndarray
) -> str | None:
    """A note where the model holds a state ``v`` only as ``v - b``: a logged bias of ``v``.

    A rate gyro that reads p + b turns every ``R p`` of the dynamics into ``R p - b R``: a
    trial's 0.01 rad/s gave ``phi' = phi_dot - 0.01`` (planar) and, in 6-DOF, ``-0.01
    cos(theta)`` beside ``p cos(theta)`` in phi', ``-0.01 tan(phi) sin(theta)`` in theta'
    and ``-0.008571 r`` beside ``0.8571 p r`` in q', with no note (2 % of the range off at
    1 s on flights without the bias). For each pair ``c1 R v``, ``c0 R`` in one equation
    the bias is ``b = -c0 / c1``; where every pair of a state agrees on it (within 10 %),
    one of them is a kinematic relation (:func:`_kinematic`: ``c1`` within 2 % of +-1, as
    ``phi' = phi_dot``: a drag term ``-k v`` beside a wind constant is not) and ``|b|``
    exceeds :data:`BIAS_FLOOR` of the state's spread, the state is named with ``b``.

    Args:
        xi: Coefficients (states x features).
        names: Feature names.
        state_names: State names.
        spread: Each state's standard deviation on the data.
    """
    angles = trig_variables(names)
    moving = set(state_names) - angles
    for k, v in enumerate(state_names):
        found: list[tuple[str, float, float]] = []
        kinematic = False
        for i, state in enumerate(state_names):
            terms = {parse_term(names[j]): float(xi[i, j]) for j in np.flatnonzero(xi[i])}
            for term, c1 in terms.items():
                plain = [f for f in term if f.var == v]  # v itself, to the first power, once
                if len(plain) != 1 or (plain[0].kind, plain[0].k) != ("pow", 1):
                    continue
                rest = tuple(f for f in term if f.var != v)
                if rest in terms:
                    found.append((state, c1, -terms[rest] / c1))
                    kinematic = kinematic or _kinematic(term, c1, moving, angles)
        if not kinematic:
            continue
        biases = np.array([b for _, _, b in found])
        bias = float(np.mean(biases))
        if abs(bias) <= BIAS_FLOOR * float(spread[k]) or np.ptp(biases) > 0.1 * abs(bias):
            continue
        where = list(dict.fromkeys(f"{state}'" for state, _, _ in found))
        held = f"{v} - {bias:.4g}" if bias > 0 else f"{v} + {-bias:.4g}"
        return (
            f"{', '.join(where)} {'hold' if len(where) > 1 else 'holds'} {v} only as {held}: "
            f"the logged {v} may carry a constant bias of {bias:.4g} (a rate gyro's or an "
            "estimator's; subtract it and identify again), and the model is right only for "
            "logs with it"
        )
    return None


def _rhs_share(
    names: Sequence[str], row: np.ndarray, part: list[int], like: Trajectory, x: np.ndarray,
    u: np.ndarray,
) -> float:  # fmt: skip
    """The share of one equation's rhs that its terms ``part`` carry (standard deviations).

    ``row`` is the equation's coefficients, x and u the data; only the equation's own terms
    are evaluated (memory of a few columns).
    """
    cols = np.flatnonzero(row)
    with np.errstate(all="ignore"):
        theta = compile_features([names[j] for j in cols], like.state_names, like.input_names)(x, u)
    mine = np.isin(cols, part)
    whole = float(np.std(theta @ row[cols]))
    return float(np.std(theta[:, mine] @ row[cols[mine]])) / max(whole, 1e-300)


KINEMATIC_INPUT_SHARE, KINEMATIC_INPUT_MAX = 3e-3, 0.5
"""An input's share of a kinematic relation's rhs (standard deviations) that is named; from
``KINEMATIC_INPUT_MAX`` on the inputs carry the equation, which is then a dynamic one that
holds a term of a kinematic form (a trial's `w' = ... + 0.987 cos(psi) sin(theta) u`, a
spurious term beside the thrust, 68.7 % of the rhs, was named as a logging fault)."""


def kinematic_input_note(
    trajs: Sequence[Trajectory], names: Sequence[str], xi: np.ndarray
) -> str | None:
    """A note where an input enters an equation that is a kinematic relation.

    ``phi' = phi_dot`` (or ``phi' = p cos(theta) + r sin(theta)``: one state times functions
    of the angles, coefficient +-1) takes no input. Where the fit adds one (a trial's
    ``phi' = phi_dot + 0.0918 u2``), the input that acted over a step is not the logged one:
    a controller faster than the log, whose logged input is a sample of a command that
    changed within the step (the trial's 500 Hz controller logged at 100 Hz: 30 % of the
    range off at 1 s, with notes that pointed elsewhere; inputs logged a whole row late leave
    the kinematics clean, and the trial's `--input-shift 1` made it worse). Named
    where the input terms carry more than :data:`KINEMATIC_INPUT_SHARE` of the equation's
    rhs on the data (0.02 to 0.04 on the trial's sampled inputs, 0.005 to 0.008 on most of
    its logs of the latest command; state noise correlated in time put up to 0.0013 there).
    The angles are the variables the library takes trig functions of.
    """
    states, inputs = trajs[0].state_names, trajs[0].input_names
    angles = trig_variables(names)
    moving = set(states) - angles
    x = np.concatenate([t.x for t in trajs])
    u = np.concatenate([t.u for t in trajs])
    where: list[str] = []
    for i, state in enumerate(states):
        cols = np.flatnonzero(xi[i])
        terms = [parse_term(names[j]) for j in cols]
        kinematic = any(_kinematic(term, xi[i, j], moving, angles)
                        for j, term in zip(cols, terms, strict=True))  # fmt: skip
        driven = [j for j, t in zip(cols, terms, strict=True) if any(f.var in inputs for f in t)]
        if not (kinematic and driven):
            continue
        share = _rhs_share(names, xi[i], driven, trajs[0], x, u)
        if KINEMATIC_INPUT_SHARE < share < KINEMATIC_INPUT_MAX:
            terms_text = ", ".join(names[j] for j in driven)
            where.append(f"{state}' ({terms_text}: {share:.1%} of its rhs)")
    if not where:
        return None
    return (
        f"an input in a kinematic relation (a state's derivative that is another state, as "
        f"phi' = phi_dot): {'; '.join(where)}. The input that acted over each step is not the "
        "one logged: a command that changed within the step, as from a controller faster than "
        "the log (log the command held over each step, its mean over the step, or log at the "
        "control rate; shifting the inputs by whole rows does not fix it)"
    )


def empty_equation_note(trajs: Sequence[Trajectory], xi: np.ndarray) -> str | None:
    """A note for each equation left empty although its state varies.

    An empty equation holds its state constant. That is right for a state that does not
    change and a data limit where the state hardly moves past its noise: a judge's 6-DOF
    flights held their altitude within 5 cm at sigma = 1e-2, and `z' = 0` came back with
    no word (28 % of the range off at 1 s on flights that climb). The note gives the
    state's spread beside its noise, read off its second differences (white noise sigma
    gives sqrt(6) sigma there; a smooth flight's are far smaller), so the user can tell
    the two cases apart.
    """
    x = [t.x for t in trajs if len(t) > 2]
    if not x:
        return None
    rows = np.concatenate(x)
    second = np.concatenate([xs[2:] - 2 * xs[1:-1] + xs[:-2] for xs in x])
    spread = rows.std(axis=0)
    noise = np.sqrt(np.mean(second**2, axis=0) / 6.0)
    states = trajs[0].state_names
    empty = [i for i in range(xi.shape[0]) if not np.any(xi[i]) and spread[i] > 0]
    if not empty:
        return None
    said = ", ".join(f"{states[i]} (spread {spread[i]:.2g}, noise about {noise[i]:.2g})"
                     for i in empty)  # fmt: skip
    which = ", ".join(f"{states[i]}'" for i in empty)
    return (
        f"{which} left empty, the model holding {'it' if len(empty) == 1 else 'them'} "
        f"constant: no term explains the changes past the bar: {said}. Where the spread is "
        "not much above the noise the data hardly move the state (fly more of its range to "
        "settle its equation); where it is, the library may lack its terms"
    )


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
    if stamped <= STAMP_FLOOR or drop <= significance_bar(len(own_eq)):
        return list(trajs), None
    worst = max(float(np.max(np.abs(a.t - b.t))) for a, b in zip(trajs, regular, strict=True))
    return regular, (
        f"the time stamps jitter (up to {worst:.3g} s off a regular clock) but the data fit "
        f"a regular clock better (residual {clocked / stamped:.2g} of the stamps' own steps'): "
        "read as each segment's regular clock (stamps with noise, such as message arrival "
        "times)"
    )


CLOCK_TOLERANCE = 1e-6
"""A variable off a straight line in time by at most this share of its range is a clock."""


def _clocks(trajs: Sequence[Trajectory]) -> list[str]:
    """Notes naming a variable that rises at one fixed rate in time in every log: a clock.

    A log's second time stamp (a trial's epoch milliseconds beside ``t``) taken for a state
    is fitted as ``stamp_ms' = 1000`` and its rounding fills the outlier notes, with no word
    that it is a clock. A state that moves at a constant speed in one flight does not move
    at the same rate in every flight, so the rate must agree across logs (or there is one).
    """
    names = [*trajs[0].state_names, *trajs[0].input_names]
    rates = np.full((len(trajs), len(names)), np.nan)
    for k, tr in enumerate(trajs):
        if len(tr) < 3:
            continue
        values = np.column_stack([tr.x, tr.u])
        t = tr.t - tr.t.mean()
        slope = t @ (values - values.mean(axis=0)) / (t @ t)
        off = values - values.mean(axis=0) - np.outer(t, slope)
        span = np.ptp(values, axis=0)
        line = (span > 0) & (np.abs(off).max(axis=0) <= CLOCK_TOLERANCE * span)
        rates[k, line] = slope[line]
    notes = []
    for j, name in enumerate(names):
        rate = rates[:, j]
        if np.all(np.isfinite(rate)) and np.ptp(rate) <= CLOCK_TOLERANCE * abs(rate[0]):
            notes.append(
                f"{name} rises by {rate[0]:.6g} per second of the time column in every log: a "
                "clock, not a variable of the dynamics (give it as the time column, --time "
                f"{name}, or leave it out: --states, --inputs)"
            )
    return notes


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
            notes.append((where, said, against))
    if len(paths) > 2 and 2 * len(notes) > len(paths):  # no majority to be the usual unit
        # (a trial pooled a 27 g and a 9 kg vehicle's files: each was named as in another
        # unit, and the pooling only 20 warnings later)
        listed = "; ".join(f"{where}: {', '.join(said)}" for where, said, _ in notes)
        return [
            f"{len(notes)} of {len(paths)} files differ from the files' median ({listed}): logs "
            "of different vehicles pooled (masses, inertias), or in several units? Identify "
            "each vehicle's logs on their own, or convert them"
        ]
    return [
        f"{where}: {'; '.join(said)}, against {against}: logged in another unit (mm for m, g "
        "for N, degrees for radians)? Convert it, or leave the file out"
        for where, said, against in notes
    ]
