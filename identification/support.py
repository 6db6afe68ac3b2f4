"""The support of a fitted model, settled on the data's normal equations.

Step 5 of :func:`identification.selection.select_model`, on the per-trajectory triangular
factors of :class:`identification.fit.Gram`: near-collinear twins resolved towards the
simpler term by an F-test (:func:`resolve_collinear`, :func:`indistinguishable_twins`), the
greedy path's stand-ins exchanged and supports grown where the data need a term
(:func:`restart_centred`, :func:`grow_significant`), terms the data do not need pruned
(:func:`prune_insignificant`), each against the residuals' long-run variance
(:func:`long_run_ratio`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from identification.data import Trajectory
from identification.features import parse_term, term_name
from identification.fit import (
    Gram,
    grams,
    iter_rows,
)
from identification.scoring import long_enough

PRUNE_P = 1e-3
"""Significance of a kept term (Bonferroni over the library: see :func:`prune_insignificant`)."""

F_CRITICAL = 10.83
"""F(1, inf) quantile at p = 0.001: a swap to the simpler term of a near-collinear pair is
refused when the residual grows by more than this many residual variances."""


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


def least_squares(a: np.ndarray, b: np.ndarray, cols: list[int]) -> tuple[float, np.ndarray]:
    """Least squares of ``b`` on columns ``cols`` of ``a``: (residual sum of squares, coef)."""
    if not cols:
        return float(b @ b), np.zeros(0)
    coef = np.linalg.lstsq(a[:, cols], b, rcond=None)[0]
    resid = b - a[:, cols] @ coef
    return float(resid @ resid), coef


def refit_support(gram: Gram, i: int, support: Sequence[int]) -> np.ndarray:
    """Equation ``i``'s coefficient row: least squares on ``support``, zero elsewhere."""
    row = np.zeros(gram.p)
    row[list(support)] = least_squares(gram.r, gram.z[:, i], list(support))[1]
    return row


def residual_variance(gram: Gram, i: int, support: Sequence[int]) -> tuple[float, float]:
    """RSS of equation ``i`` on ``support``, and its residual variance for the F-tests.

    The variance counts the residual left outside the p-dimensional range of R (total minus
    explained) and every row as an effective sample (under white measurement noise the
    targets of neighbouring rows share no sample).
    """
    rss = least_squares(gram.r, gram.z[:, i], list(support))[0]
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
        rss, sigma2 = residual_variance(gram, i, support) if support else (0.0, 0.0)
        for simple, complex_, cosine in pairs:
            if simple in support and complex_ not in support:
                trial = sorted(complex_ if c == simple else c for c in support)
                if rss - least_squares(a, z[:, i], trial)[0] > F_CRITICAL * sigma2:
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
            rss_new, _ = least_squares(a, z[:, i], trial)
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
            xi[i] = refit_support(gram, i, support)
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
    fill: tuple[float, Callable[[int, np.ndarray], float]] | None = None,
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

    With ``fill`` (the chosen threshold and a function giving the long-run ratio of an
    equation's residual under a trial row), an equation the path left empty is filled by the
    centred path where that path passes the threshold (:func:`_fill_empty`): a quaternion
    rigid body at sigma = 1e-2, hovering, got ``vz' = 0`` (27 % of the vz range off at 1 s
    on held-out flights) because gravity and the nearly constant thrust gain nothing one
    at a time.

    Returns:
        The coefficients (refitted where changed) and one note per equation replaced.
    """
    from identification.stepwise import simpler_twins, stepwise_path

    names = [term_name(parse_term(n)) for n in feature_names]
    if "1" not in names or (not np.any(xi) and fill is None):
        return xi, []
    one = names.index("1")
    bar = significance_bar(gram.p)
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
            filled = [] if fill is None else _fill_empty(gram, i, (centred, q, one), twins,
                                                         bar, *fill)  # fmt: skip
            if filled:
                xi[i] = refit_support(gram, i, filled)
                notes.append(
                    f"{state}': the path left it empty, and a path on centred columns (offsets "
                    f"removed: a cancelling pair such as thrust and gravity enters there) fills "
                    f"it with {len(filled)} terms ({_term_list(feature_names, filled)}), the "
                    f"first explaining more than the threshold lambda of the target"
                )
            continue
        scale = max(float(ratio[i]), 1.0)
        now, _ = _prune_support(gram, i, path_support, scale, bar)  # as the checks prune it
        rss_now, sigma2_now = residual_variance(gram, i, now)
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
        rss_other, sigma2_other = residual_variance(gram, i, other)
        sigma2 = min(sigma2_now, sigma2_other) * scale
        cost_now = rss_now / sigma2 + bar * len(now)
        cost_other = rss_other / sigma2 + bar * len(other)
        if cost_other + F_CRITICAL >= cost_now:
            continue
        xi[i] = refit_support(gram, i, other)
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


def _fill_empty(
    gram: Gram,
    i: int,
    centred: tuple[np.ndarray, np.ndarray, int],
    twins: dict[int, list[int]],
    bar: float,
    lam: float,
    ratio_of: Callable[[int, np.ndarray], float],
) -> list[int]:
    """The support, with the constant, that fills equation ``i`` the path left empty; or [].

    The path on centred columns (see :func:`restart_centred`) runs down to the significance
    bar in the empty equation's residual variance and is pruned to the bar in the long-run
    variance of its own residual (``ratio_of``). It fills the equation only where its first
    entry explains at least ``lam`` of the target's RMS, the selection's threshold (so the
    equation was empty because the path could not enter a cancelling pair, not because the
    threshold stopped it), and its penalised residual beats the empty equation's by more
    than the F-test's bar.
    """
    from identification.stepwise import stepwise_path

    a, q, one = centred
    b = gram.z[:, i]
    total = float(np.linalg.norm(gram.r_aug[:, gram.p + i]) ** 2)
    held, sigma2_empty = residual_variance(gram, i, [])  # the target's part in the range
    path = stepwise_path(a, b - q * (q @ b), min(gram.p, gram.rows), simpler=twins,
                         total=total - float(q @ b) ** 2, n_eff=gram.rows,
                         floor=bar * sigma2_empty)  # fmt: skip
    entered = [list(support) for support, _ in path if len(support)]
    if not entered or not total > 0:
        return []
    first = residual_variance(gram, i, sorted({one, *entered[0]}))[0]
    if held - first < lam**2 * total:
        return []
    start = sorted({one, *entered[-1]})
    scale = max(float(ratio_of(i, refit_support(gram, i, start))), 1.0)
    support, _ = _prune_support(gram, i, start, scale, bar)
    rss, sigma2 = residual_variance(gram, i, support)
    cost = rss / (sigma2 * scale) + bar * len(support)
    return support if cost + F_CRITICAL < held / (sigma2 * scale) else []


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
                explained = float(b @ b) - least_squares(a, b, trial)[0]
                if explained > best[0]:
                    best = (explained, tuple(sorted(trial)))
    return best if best[1] else None


TWIN_KEEP = 0.5
"""A twin is added beside a chosen term where its coefficient is at least this share of the
term's and their joint contribution at least this share of the larger one's (a cancelling pair
of |cos| > 0.999 keeps under 0.05)."""

TWIN_FLOOR = 1e-5
"""A residual under this share of its target's RMS is round-off or integrator error: no twin is
added to explain it (a round-off "gain" passes any bar in its own variances)."""


def add_reinforcing_twins(
    a: np.ndarray,
    b: np.ndarray,
    support: Sequence[int],
    usable: np.ndarray,
    twin: np.ndarray,
    bar: float,
    total: float,
    rows: float,
    own_scale: Callable[[list[int]], float] | None = None,
) -> list[int]:
    """Adds near twins of the support that the data need beside it, where the pair does not cancel.

    The growth's best-subset search never puts two columns with |cos| > 0.999 together, as
    such a pair fits noise with large opposite coefficients. Two true terms can be that
    close: a trial's planar quad with per-rotor thrusts has `f1 sin(phi)` and `f2 sin(phi)`
    at |cos| = 0.9993 (the rotors' thrusts differ little), and clean data kept
    `f2, f1 sin(phi)` for the pair, 0.70 % off at 1 s. Here each twin of a chosen term is
    added, best first, where it explains more than ``bar`` residual variances (the growth's
    bar for a term more), its coefficient is at least :data:`TWIN_KEEP` of each twin's in
    the support (a second term, not a small correction of the first: on 6-DOF data at
    sigma = 1e-3 `tan(phi) ... w` entered at 2 % of its twin `sin(phi) ... w`, P = 0.5), and
    their joint contribution keeps at least :data:`TWIN_KEEP` of the larger (the pair
    reinforces rather than cancels). A term the addition makes redundant is left to the
    pruning. ``own_scale`` (a support -> the factor, at most 1, by which the bar shrinks
    measured on that support's own residual) is asked only where a twin fails ``bar``:
    ``bar`` holds the long-run ratio of the support without the twin, whose residual keeps
    the missing twin's smooth signal (a trial's one-rotor residual: 51.7 against the pair's
    10.3).

    Returns:
        The support, with the twins added.
    """
    support = list(support)
    while True:
        rss_now = least_squares(a, b, support)[0]
        if rss_now <= TWIN_FLOOR**2 * total:
            return support
        best: tuple[float, list[int]] | None = None
        for k in np.flatnonzero(twin[:, support].any(axis=1) & usable):
            if k in support:
                continue
            trial = [*support, int(k)]
            rss, coef = least_squares(a, b, trial)
            sigma2 = (total - float(b @ b) + rss) / max(rows - len(trial), 1.0)
            if rss_now - rss <= bar * sigma2 and (
                own_scale is None or rss_now - rss <= bar * own_scale(trial) * sigma2
            ):
                continue
            kept = all(
                abs(coef[-1]) >= TWIN_KEEP * abs(coef[m])
                and np.linalg.norm(coef[m] * a[:, j] + coef[-1] * a[:, k])
                >= TWIN_KEEP * max(abs(coef[m]), abs(coef[-1]))
                for m, j in enumerate(support)
                if twin[j, k]
            )
            if kept and (best is None or rss < best[0]):
                best = (rss, trial)
        if best is None:
            return support
        support = best[1]


def wald_chi2(
    trajs: Sequence[Trajectory],
    names: Sequence[str],
    xi: np.ndarray,
    window: int,
    i: int,
    support: Sequence[int],
    trial: Sequence[int],
) -> tuple[float, int]:
    """The chi-square of the columns ``trial`` adds to ``support`` in equation ``i``.

    The Wald test on the RK4 rows (``xi`` for the stage points) with a long-run covariance:
    the added columns, their projection on ``support`` removed, against that support's
    residual; the variance of that product from the larger support's residual
    autocovariance (pooled over the trajectories) against the columns' own lagged products,
    Bartlett weights up to lag ``4 window`` (at least 8). Wide windows make columns and
    residuals smooth, and a residual variance counts the rows as independent: under the
    truth a term's statistic then averaged 1.44 where a chi-square's averages 1 (a held-out
    trial's low-excitation flights at window 64: ``u2`` in ``z'`` at 17.8 residual
    variances, 12.7 by this test, past a bar of 16.8). (The products' own long-run variance
    is as well calibrated there but bounds a true term's statistic by the products'
    effective rows; from the larger support's residual it is biased low.) Returns the
    statistic and its degrees of freedom (the added columns).
    """
    added = sorted({int(j) for j in trial} - {int(j) for j in support})
    if not added:
        return 0.0, 0
    cols = sorted({*np.flatnonzero(np.any(xi != 0, axis=0)).tolist(), *support, *added})
    at = {j: k for k, j in enumerate(cols)}
    parts: dict[int, list[tuple[np.ndarray, np.ndarray]]] = {}
    for index, theta, y in iter_rows(trajs, [names[j] for j in cols], "rk4", window, xi[:, cols]):
        parts.setdefault(index, []).append((theta, y[:, i]))
    pieces = [(np.concatenate([t for t, _ in c]), np.concatenate([y for _, y in c]))
              for c in parts.values()]  # fmt: skip
    theta = np.concatenate([t for t, _ in pieces])
    y = np.concatenate([y for _, y in pieces])
    base = theta[:, [at[j] for j in support]]
    extra = theta[:, [at[j] for j in added]]
    if base.shape[1]:
        e = y - base @ np.linalg.lstsq(base, y, rcond=None)[0]
        extra = extra - base @ np.linalg.lstsq(base, extra, rcond=None)[0]
    else:
        e = y
    total = extra.T @ e
    e = e - extra @ np.linalg.lstsq(extra, e, rcond=None)[0]  # the larger support's
    lags = max(4 * window, 8)
    gamma = np.zeros(lags)  # the residual's autocovariance, pooled over the trajectories
    cross = np.zeros((lags, len(added), len(added)))  # the columns' lagged products
    start = 0
    for t, _ in pieces:
        r, x = e[start : start + len(t)], extra[start : start + len(t)]
        start += len(t)
        for lag in range(min(lags, len(r))):
            gamma[lag] += r[lag:] @ r[: len(r) - lag]
            cross[lag] += x[lag:].T @ x[: len(x) - lag]
    gamma /= len(e)
    weights = 1.0 - np.arange(lags) / lags
    cov = weights[0] * gamma[0] * cross[0]
    for lag in range(1, lags):
        cov += weights[lag] * gamma[lag] * (cross[lag] + cross[lag].T)
    solved = np.linalg.lstsq(cov, total, rcond=None)[0]
    return float(total @ solved), len(added)


def wald_confirmation(
    trajs: Sequence[Trajectory], names: Sequence[str], xi: np.ndarray, window: int
) -> Callable[[int, Sequence[int], Sequence[int], int], bool]:
    """The ``confirm`` of :func:`grow_significant` on these rows (``xi`` for the stage points).

    :func:`wald_chi2` beyond the chi-square bar at :data:`PRUNE_P` over the tries.
    """
    from scipy.stats import chi2

    def confirm(i: int, support: Sequence[int], trial: Sequence[int], tries: int) -> bool:
        stat, dof = wald_chi2(trajs, names, xi, window, i, support, trial)
        return dof == 0 or stat > float(chi2.isf(PRUNE_P / max(tries, 1), dof))

    return confirm


def significance_bar(p: int) -> float:
    """Chi-square(1) at :data:`PRUNE_P` / p: the bar for the best of p candidate terms."""
    from scipy.stats import chi2

    return float(chi2.isf(PRUNE_P / max(p, 1), 1))


def _unit_columns(gram: Gram) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The factor's columns scaled to unit norm, their cosines, and which are not all zero."""
    a = gram.r / np.maximum(gram.col_norms, 1e-300)
    g = a.T @ a
    return a, g, np.diag(g) > 0.5  # (an all-zero column has norm 0)


def grow_significant(
    xi: np.ndarray,
    gram: Gram,
    ratio: np.ndarray,
    feature_names: Sequence[str],
    state_names: Sequence[str],
    ratio_of: Callable[[int, np.ndarray], float] | None = None,
    confirm: Callable[[int, Sequence[int], Sequence[int], int], bool] | None = None,
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
    simpler twins only within the F-test of it. Last, :func:`add_reinforcing_twins` adds
    near twins that the data need beside their partners and that do not cancel them; with
    ``ratio_of`` (equation, coefficient row -> its residual's long-run ratio), a twin the
    ratio of the support without it keeps out is measured against the pair's own ratio, and
    where that admits it, ``ratio`` (changed in place) holds the pair's ratio for the
    pruning after. With ``confirm`` (equation, support, larger support, the Bonferroni count
    of its bar -> whether the rows' Wald test passes that bar: :func:`wald_chi2`), a
    larger support must pass it too.

    Returns:
        The coefficients (refitted where changed) and one note per equation grown.
    """
    from identification.stepwise import best_subset

    bar = significance_bar(gram.p)
    moves_bar = bar  # the exchange-and-add bar, for a support of the size it grew from
    a, g, usable = _unit_columns(gram)
    cos = np.abs(g)
    np.fill_diagonal(cos, 0.0)
    near, twin = cos > 0.99, cos > 0.999
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
            explained_now = float(b @ b) - least_squares(a, b, support)[0]
            bigger = best_subset(g, c, pool, len(support) + 1, twin)
            if bigger is not None:
                sigma2 = (total - bigger[0]) / max(float(gram.rows) - len(bigger[1]), 1.0)
                if bigger[0] - max(now[0], explained_now) > bar * scale * sigma2 and (
                    confirm is None or confirm(i, support, bigger[1], gram.p)
                ):
                    support = list(bigger[1])
                    continue
            moved = exchange_and_add(a, b, support, usable, twin)
            if moved is not None:  # its own bar: the best of |S| x SWAP_TOP x p moves
                sigma2 = (total - moved[0]) / max(float(gram.rows) - len(moved[1]), 1.0)
                tries = gram.p * len(support) * SWAP_TOP
                moves_bar = significance_bar(tries)
                if moved[0] - max(now[0], explained_now) > moves_bar * scale * sigma2 and (
                    confirm is None or confirm(i, support, moved[1], tries)
                ):
                    support = list(moved[1])
                    continue
            sigma2 = (total - now[0]) / max(float(gram.rows) - len(now[1]), 1.0)
            if now[0] - explained_now > F_CRITICAL * sigma2:
                support = list(now[1])
            break
        own: dict[tuple[int, ...], float] = {}  # a trial support -> its residual's ratio

        def own_scale(trial: list[int], i: int = i, scale: float = scale, own: dict = own) -> float:
            key = tuple(sorted(trial))
            if key not in own:
                own[key] = max(float(ratio_of(i, refit_support(gram, i, trial))), 1.0)
            return min(own[key] / scale, 1.0)

        asked = own_scale if ratio_of else None
        support = add_reinforcing_twins(a, b, support, usable, twin, bar * scale, total,
                                        float(gram.rows), asked)  # fmt: skip
        if tuple(sorted(support)) in own:  # admitted at the pair's own ratio
            ratio[i] = scale = own[tuple(sorted(support))]
        if sorted(support) != sorted(start):
            xi[i] = refit_support(gram, i, support)
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
        there = refit_support(wide, i, support)
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
        xi[i] = refit_support(gram, i, [j for j in support if j not in gone])
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
        _, sigma2 = residual_variance(gram, i, support)
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
    bar = significance_bar(gram.p)
    xi = xi.copy()
    notes = []
    for i, state in enumerate(state_names):
        scale = max(float(ratio[i]), 1.0)
        support, removed = _prune_support(gram, i, list(np.flatnonzero(xi[i])), scale, bar)
        dropped = [f"{term_name(parse_term(feature_names[j]))!r} ({cost:.3g})"
                   for j, cost in removed]  # fmt: skip
        if dropped:
            xi[i] = refit_support(gram, i, support)
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
        rss, sigma2 = residual_variance(gram, i, support)
        for simple, complex_, cosine in pairs:
            for kept, other in ((simple, complex_), (complex_, simple)):
                if kept not in support or other in support:
                    continue
                trial = [other if c == kept else c for c in support]
                change = least_squares(a, z[:, i], trial)[0] - rss
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


SHARED = 0.25
"""An unsplit twin is named only where the free fit of the pair gives it at least this part of
their weight (on unit columns, reinforcing): the data's own estimate then shares it. Measured:
a per-rotor quad's `f1 sin(th)` / `f2 sin(th)` at 0.34 to 0.55 (four runs at sigma = 1e-2),
the 6-DOF presets' small-angle trig twins (`cos(psi) cos(theta) u` / `cos(phi) cos(psi) u`) at
0.18 and below on a noisy flight set, where nine notes named such pairs without it."""

NEAR_COS = 0.99
"""Two columns at |cos| above this on the data are near twins (the pool of
:func:`grow_significant`; above 0.999 it never puts such a pair together)."""


def unsplit_twins(
    xi: np.ndarray,
    gram: Gram,
    ratio: np.ndarray,
    feature_names: Sequence[str],
    state_names: Sequence[str],
) -> list[str]:
    """Warnings for chosen terms whose dropped near twin the data cannot rule out beside them.

    For a pair of near twins (|cos| > :data:`NEAR_COS`) neither of which is the other times
    further factors (``f1 sin(phi)`` and ``f2 sin(phi)``), no simpler term is preferred (the
    rule of :func:`resolve_collinear`), and the model holding one without the other is a
    choice the data must make: the support with the dropped twin beside the kept term is
    fitted, and its fit with the twin held at :data:`TWIN_KEEP` of the kept term's weight
    (the smallest share that makes it a second term: unit columns, the pair reinforcing) is
    compared with it. Where that costs no more than the F-test's bar (p = 0.001), in residual
    variances of the pair's fit times the long-run ratio (as the pruning counts them), the
    data cannot tell the kept term alone from the two sharing its weight; where the pair's
    free fit also gives the twin a reinforcing :data:`SHARED` part of their weight, one
    warning per kept term names each such twin. A trial's planar quad with per-rotor thrusts
    flown by a PD controller (f1 ~ f2, |cos| 0.9997) kept `vx' = -3.34 f1 sin(th)` for
    `-1.667 (f1 + f2) sin(th)` in 4 runs without a word: the half share cost 0.0004 to
    1.8 variances, the twin's entry 7 to 17 (under the bar of 18.3 for a term).

    Returns:
        The warnings.
    """
    terms = [set(parse_term(n)) for n in feature_names]
    norms = gram.col_norms
    a, cos, usable = _unit_columns(gram)
    np.fill_diagonal(cos, 0.0)
    bar = significance_bar(gram.p)
    notes = []
    for i, state in enumerate(state_names):
        support = [int(j) for j in np.flatnonzero(xi[i])]
        if not support:
            continue
        b = gram.z[:, i]
        scale = max(float(ratio[i]), 1.0)
        rss_now = least_squares(a, b, support)[0]
        found = []
        for kept in support:
            for other in np.flatnonzero((np.abs(cos[kept]) > NEAR_COS) & usable):
                other = int(other)
                if other in support or terms[kept] <= terms[other] or terms[other] <= terms[kept]:
                    continue
                pair, sigma2 = residual_variance(gram, i, [*support, other])
                sigma2 *= scale
                if not sigma2 > 0:
                    continue
                shared = a[:, kept] + TWIN_KEEP * np.sign(cos[kept, other]) * a[:, other]
                rest = [c for c in support if c != kept]
                m = np.column_stack([a[:, rest], shared])
                resid = b - m @ np.linalg.lstsq(m, b, rcond=None)[0]
                cost = (float(resid @ resid) - pair) / sigma2
                if cost > F_CRITICAL:
                    continue
                coef = refit_support(gram, i, [*support, other])
                # on unit columns, the twin's part of the pair's weight in the free fit
                mine, theirs = coef[kept] * norms[kept], coef[other] * norms[other]
                share = abs(theirs) / max(abs(mine) + abs(theirs), 1e-300)
                if share >= SHARED and np.sign(theirs) * np.sign(cos[kept, other]) == np.sign(mine):
                    found.append((kept, other, abs(cos[kept, other]), cost,
                                  (rss_now - pair) / sigma2, coef[kept], coef[other]))  # fmt: skip
        for kept in dict.fromkeys(f[0] for f in found):
            mine = [f for f in found if f[0] == kept]
            listed = "; ".join(
                f"{_term_list(feature_names, [o])} (|cos| = {c:.6f}: the half share costs "
                f"{cost:.3g}, the twin's entry explains {gain:.3g}; together "
                f"{ck:.4g} and {co:.4g})"
                for _, o, c, cost, gain, ck, co in mine
            )
            notes.append(
                f"{state}': kept {_term_list(feature_names, [kept])} without its near "
                f"twin{'s' if len(mine) > 1 else ''} on this data, and the data cannot tell "
                f"it alone from the two sharing its weight: {listed} (residual variances, "
                f"x {scale:.3g} for the residual's correlation over the window; with the twin "
                f"at half its weight the F-test needs {F_CRITICAL} against the pair's fit, "
                f"a term {bar:.3g}); the model may hold one term for two"
            )
    return notes


# -- the entry point --------------------------------------------------------------------
