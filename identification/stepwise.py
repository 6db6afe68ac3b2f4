"""Greedy stepwise sparse regression on a triangular factor (forward selection, backward pruning).

Each equation is fitted on its own, on the scaled factor ``(A, b)`` of the regression
(:class:`identification.fit.Gram`: ``A = R / column RMS``, ``b = Q^T y / target RMS``), where
the residual sum of squares of any subset of columns is cheap. The path starts empty and

* **forward**: adds the column that lowers the residual sum of squares the most (orthogonal
  least squares, as FROLS: the gain of column j is ``(a_j_perp . r)^2 / |a_j_perp|^2`` with
  ``a_j_perp`` the part of a_j outside the span of the chosen columns and r the residual);
  a column that lies in that span to round-off (``|a_j_perp|^2 < tol |a_j|^2``) is never
  entered, so a cancelling pair of nearly equal columns cannot be built;
* **backward**: after every addition, removes chosen columns whose removal costs less than
  half the gain of that addition (FoBa, Zhang 2011), so an early choice that a later pair of
  columns explains better is undone.

Every support read off the path is then **refined by replacement** (Miller's sequential
replacement for best subsets): a chosen column is exchanged for the column outside that lowers
the residual sum of squares most, as long as the drop is significant with the number of
exchanges tried counted (F-test at p = 0.001, Bonferroni over every chosen column times every
candidate). Greedy entry can settle on one column that stands for two true ones at small
tilt (``tan(phi) r`` for ``tan(phi) cos(theta) r`` beside ``tan(phi) sin(theta) p``); the
exchange undoes that when the data say so, and a noise fit of a few hundred candidates does
not pass the corrected bar.

The stopping rule is the same scaled threshold ``lam`` as thresholded least squares: the
path stops when the next column would explain less than ``lam`` of the target's RMS (gain
below ``lam^2 n``). For unit-RMS orthogonal columns this is exactly a threshold on the
scaled coefficient, so ``lam`` means what it means for STLSQ; for near-collinear columns it
asks what the column adds beyond the ones already chosen, which thresholding cannot. The
whole path is computed once, so every threshold of a grid costs one read-off and one
small least-squares refit.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

COLLINEAR_TOL = 1e-10
"""A column whose part outside the chosen span has squared norm below this fraction of its own
is taken as lying in that span (never entered)."""

F_CRITICAL = 10.83
"""F(1, inf) quantile at p = 0.001: a simpler twin is entered unless the complex column gains
more than this many residual variances over it."""

INSIGNIFICANT_STEPS = 8
"""The path stops after this many forward entries in a row that fail the F-test (noise)."""

REPLACE_P = 1e-3
"""Significance of one replacement, before the Bonferroni correction for the exchanges tried."""

BACKWARD_REACH = 0.1
"""With replacement on, each path runs to this fraction of the smallest threshold: the columns
entered there are where backward elimination starts (see :func:`backward_path`)."""

BACKWARD_FRACTION = 0.5
"""A chosen column is removed when that costs less than this fraction of the last gain (FoBa)."""


def stepwise_path(
    a: np.ndarray,
    b: np.ndarray,
    max_terms: int,
    tol: float = COLLINEAR_TOL,
    simpler: dict[int, list[int]] | None = None,
    total: float | None = None,
    n_eff: float | None = None,
    floor: float = 0.0,
    stop_noise: bool = True,
) -> list[tuple[tuple[int, ...], float]]:
    """The forward-backward greedy path of one target.

    Args:
        a: Scaled regression matrix (rows x p); here the triangular factor.
        b: Scaled target (rows).
        max_terms: Largest support size on the path.
        tol: Collinearity tolerance (see :data:`COLLINEAR_TOL`).
        simpler: For each column, the near-collinear columns whose term is a factor of its
            own (``1`` for ``cos(phi)``, ``u2`` for ``cos(phi) u2``). When the best column
            has such a simpler twin whose gain is not significantly smaller (F-test at
            p = 0.001 against the residual variance), the twin is entered instead.
        total: Total sum of squares of the target over the data rows (default ``|b|^2``).
        n_eff: Effective independent rows for the F-test (default: rows of ``a``).
        floor: The path stops at the first step gaining less (no threshold reads beyond).
        stop_noise: Also stop after :data:`INSIGNIFICANT_STEPS` entries in a row that fail
            the F-test (p = 0.001) against the residual variance.

    Returns:
        One entry per forward step: the support after that step (and its backward pruning),
        and the gain (drop of the residual sum of squares) of the column it added.
    """
    p = a.shape[1]
    a = np.asfortranarray(a)  # the path gathers columns: contiguous ones are 3x faster
    norms2 = np.einsum("ij,ij->j", a, a)
    usable = norms2 > 0
    support: list[int] = []
    basis = np.zeros((a.shape[0], 0))  # orthonormal basis of the chosen columns, in order
    qta = np.zeros((0, p))  # basis^T a: each column's coordinates in that span
    proj2 = np.zeros(p)  # squared norm of each column's part inside that span
    resid = b.copy()
    outside = (float(b @ b) if total is None else total) - float(b @ b)
    n_rows = float(a.shape[0] if n_eff is None else n_eff)
    complex_of = _invert(simpler or {})
    path: list[tuple[tuple[int, ...], float]] = []
    seen: set[tuple[int, ...]] = set()
    quiet = 0
    for _ in range(4 * max_terms):  # forward steps, a few undone by backward ones
        if len(support) >= min(max_terms, p):
            break
        perp2 = norms2 - proj2
        ok = usable & (perp2 > tol * norms2)
        ok[support] = False
        if not ok.any():
            break
        gains = np.zeros(p)
        gains[ok] = (resid @ a)[ok] ** 2 / perp2[ok]  # a_j . r = a_j_perp . r
        if simpler and support:
            # a twin of a chosen term enters beside it only when significant (F-test)
            paired = [t for c in support for t in (*simpler.get(c, ()), *complex_of.get(c, ()))]
            rss_now = outside + float(resid @ resid)
            sigma2 = rss_now / max(n_rows - len(support) - 1, 1.0)
            weak = np.zeros(p, dtype=bool)
            weak[paired] = True
            gains[weak & (gains <= F_CRITICAL * sigma2)] = 0.0
        j = int(np.argmax(gains))
        gain = float(gains[j])
        if gain <= 0 or gain < floor:
            path.append((tuple(sorted(support)), gain))
            break
        # Past INSIGNIFICANT_STEPS entries in a row that are not significant (F-test at
        # p = 0.001 against the residual variance) the path only fits noise: stop there.
        # (One alone is not enough: the first of a cancelling pair, `1` then `cos(phi) u1`
        # in z_dot', gains little until its partner enters.)
        sigma2_now = (outside + float(resid @ resid)) / max(n_rows - len(support) - 1, 1.0)
        quiet = quiet + 1 if gain < F_CRITICAL * sigma2_now else 0
        if stop_noise and quiet > INSIGNIFICANT_STEPS:
            path.append((tuple(sorted(support)), gain))
            break
        twins = [k for k in (simpler or {}).get(j, ()) if ok[k]]
        if twins:
            rss_after = max(outside + float(resid @ resid) - gain, 0.0)
            sigma2 = rss_after / max(n_rows - len(support) - 1, 1.0)
            k = max(twins, key=lambda c: gains[c])
            if gain - gains[k] <= F_CRITICAL * sigma2:
                j, gain = k, float(gains[k])
        support.append(j)
        q = a[:, j] - basis @ (basis.T @ a[:, j])
        q -= basis @ (basis.T @ q)  # twice is enough (Giraud et al.)
        q /= np.linalg.norm(q)
        basis = np.column_stack([basis, q])
        qa = q @ a
        qta = np.vstack([qta, qa])
        proj2 += qa**2
        resid -= q * (q @ resid)
        # backward: drop the cheapest chosen column while it costs < half this gain, on the
        # small factor A_S = basis R (a removal re-triangularises R: rotate = its Q)
        pruned = False
        r = np.triu(qta[:, support])
        qtb = basis.T @ b
        rotate = np.eye(len(support))
        while len(support) > 1:
            loss = _costs_from_factor(r, qtb)
            k = int(np.argmin(loss[:-1]))  # never the column just added
            if loss[k] >= BACKWARD_FRACTION * gain:
                break
            support.pop(k)
            q_k, r = np.linalg.qr(np.delete(r, k, axis=1))
            qtb = q_k.T @ qtb
            rotate = rotate @ q_k
            pruned = True
        if pruned:
            basis = basis @ rotate
            qta = rotate.T @ qta
        # Twin choices are F-tests against the residual variance, which only moves when a
        # significant column enters: re-check them then, not in the noise tail of the path.
        rss_now = outside + float(resid @ resid)
        if simpler and gain > F_CRITICAL * rss_now / max(n_rows - len(support), 1.0):
            if _swap_twins(a, b, support, simpler, complex_of, outside, n_rows, tol, norms2):
                basis = np.linalg.qr(a[:, support])[0]
                qta = basis.T @ a
                pruned = True
        if pruned:
            proj2 = np.einsum("ij,ij->j", qta, qta)
            resid = b - basis @ (basis.T @ b)
        key = tuple(sorted(support))
        path.append((key, gain))
        if key in seen and pruned:
            break  # cycling between supports: stop here
        seen.add(key)
    return path


def _invert(simpler: dict[int, list[int]]) -> dict[int, list[int]]:
    complex_of: dict[int, list[int]] = {}
    for j, ks in simpler.items():
        for k in ks:
            complex_of.setdefault(k, []).append(j)
    return complex_of


def _swap_twins(
    a: np.ndarray,
    b: np.ndarray,
    support: list[int],
    simpler: dict[int, list[int]],
    complex_of: dict[int, list[int]],
    outside: float,
    n_rows: float,
    tol: float = COLLINEAR_TOL,
    norms2: np.ndarray | None = None,
) -> bool:
    """Swaps chosen columns for near-collinear twins in place; returns whether any changed.

    A complex column gives way to its simpler twin unless it explains significantly more
    (F-test, p = 0.001); a simple column gives way to a complex twin only when that explains
    significantly more. Early in the path the residual variance still holds unexplained
    signal, so a choice made then is checked again here with the current variance.
    """
    norms2 = np.einsum("ij,ij->j", a, a) if norms2 is None else norms2
    changed = False
    limit = 2 * len(support)
    history = [tuple(support)]  # support after each swap; a swap depends on the support only
    for step in range(limit):
        twins = {
            pos: ([t for t in simpler.get(c, ()) if t not in support],
                  [t for t in complex_of.get(c, ()) if t not in support])
            for pos, c in enumerate(support)
        }  # fmt: skip
        twins = {pos: st for pos, st in twins.items() if st[0] or st[1]}
        if not twins:
            break
        cols = sorted({t for st in twins.values() for t in (*st[0], *st[1])} | set(support))
        _, table = _exchange_rss(a, b, support, cols, outside, tol, norms2)
        where = {c: i for i, c in enumerate(cols)}
        swap = None
        for pos, (simple, richer) in twins.items():
            idx = [where[t] for t in (support[pos], *simple, *richer)]
            rss = table[pos, idx]  # RSS with each column in c's place (c itself first)
            if not np.isfinite(rss[0]):
                continue  # c itself lies in the span of the others to round-off: no test
            sigma2 = rss[0] / max(n_rows - len(support), 1.0)
            n_simple = len(simple)
            # An invalid column has infinite RSS: inf - inf compares False (no swap), quietly.
            with np.errstate(invalid="ignore"):
                to_simple = rss[1 : 1 + n_simple].min() - rss[0] if n_simple else np.inf
                to_richer = rss[0] - rss[1 + n_simple :].min() if richer else -np.inf
            if to_simple <= F_CRITICAL * sigma2:
                swap = (pos, simple[int(np.argmin(rss[1 : 1 + n_simple]))])
            elif to_richer > F_CRITICAL * sigma2:
                swap = (pos, richer[int(np.argmin(rss[1 + n_simple :]))])
            if swap is not None:
                break
        if swap is None:
            break
        support[swap[0]] = swap[1]
        changed = True
        state = tuple(support)
        if state in history:  # a cycle of swaps: go round it to where the limit would stop
            start = history.index(state)
            period = step + 1 - start
            support[:] = history[start + (limit - start) % period]
            break
        history.append(state)
    return changed


def _exchange_rss(
    a: np.ndarray,
    b: np.ndarray,
    support: list[int],
    cols: Sequence[int],
    outside: float,
    tol: float,
    norms2: np.ndarray,
) -> tuple[float, np.ndarray]:
    """The RSS of ``support``, and the RSS with each of ``cols`` in place of each chosen column.

    Without chosen column c the span loses the direction v_c = Q R^-T e_c (unit), which is
    orthogonal to everything projected off span(Q): a closed form for every exchange.

    Returns:
        The RSS, and the table (chosen position, column); inf where the column would lie in
        the span of the others to round-off (``tol``).
    """
    q, r = np.linalg.qr(a[:, support])
    g = np.linalg.inv(r).T  # columns R^-T e_c
    v = q @ (g / np.linalg.norm(g, axis=0))
    at = a[:, cols]
    perp = at - q @ (q.T @ at)
    resid = b - q @ (q.T @ b)
    va = v.T @ at
    vb = v.T @ b
    p2 = np.einsum("ij,ij->j", perp, perp)[None, :] + va**2  # its part outside the rest
    dot = (perp.T @ resid)[None, :] + va * vb[:, None]
    valid = p2 > tol * norms2[list(cols)][None, :]
    rss = outside + float(resid @ resid)
    gains = np.where(valid, dot**2 / np.maximum(p2, 1e-300), -np.inf)
    return rss, rss + (vb**2)[:, None] - gains


def replace_terms(
    a: np.ndarray,
    b: np.ndarray,
    support: Sequence[int],
    outside: float,
    n_rows: float,
    tol: float = COLLINEAR_TOL,
) -> tuple[int, ...]:
    """Sequential replacement: exchanges chosen columns while the data significantly prefer it.

    Each round finds, over every chosen column and every column outside, the exchange that
    lowers the residual sum of squares most (:func:`_exchange_rss`) and makes it when the drop
    exceeds the chi-square(1) bar at :data:`REPLACE_P` divided by the number of exchanges
    tried, in residual variances. Then pairs that can cancel are exchanged together
    (:func:`_exchange_pairs`). The support size never changes, so the threshold keeps its
    meaning; only which columns carry it does.

    Args:
        a: Scaled regression matrix.
        b: Scaled target.
        support: Chosen columns.
        outside: Residual sum of squares outside the rows of ``a`` (see :class:`Gram`).
        n_rows: Effective independent rows for the test.
        tol: Collinearity tolerance: a column in the span of the others is never entered.

    Returns:
        The refined support, sorted.
    """
    from scipy.stats import chi2

    support = list(support)
    if not support or len(support) >= a.shape[1]:
        return tuple(sorted(support))
    norms2 = np.einsum("ij,ij->j", a, a)
    bar = float(chi2.isf(REPLACE_P / (len(support) * (a.shape[1] - len(support))), 1))
    seen = {tuple(sorted(support))}
    every = list(range(a.shape[1]))
    for _ in range(4 * len(support)):
        rss, table = _exchange_rss(a, b, support, every, outside, tol, norms2)
        table[:, support] = np.inf
        sigma2 = rss / max(n_rows - len(support), 1.0)
        drop = rss - table
        pos, col = np.unravel_index(int(np.argmax(drop)), drop.shape)
        if not drop[pos, col] > bar * sigma2:
            break
        support[pos] = int(col)
        key = tuple(sorted(support))
        if key in seen:
            break
        seen.add(key)
    return _exchange_pairs(a, b, support, outside, n_rows, tol)


PAIR_COSINE = 0.99
"""Near twins for the paired exchange of :func:`_exchange_pairs` (|cos| on the data)."""


def _exchange_pairs(
    a: np.ndarray,
    b: np.ndarray,
    support: list[int],
    outside: float,
    n_rows: float,
    tol: float = COLLINEAR_TOL,
) -> tuple[int, ...]:
    """Exchanges two chosen columns at once for near twins of each, when significant.

    A cancelling pair (gravity and thrust in ``w'``: ``cos(phi) cos(theta)`` and ``u1``) can be
    held as a pair of near twins with a common factor (``cos(psi) cos(theta)`` and
    ``sec(phi) cos(psi) u1``): exchanging either alone breaks the balance, so single
    replacements never leave it. Here two chosen columns nearly parallel to each other (a pair
    that can cancel) are exchanged together, each for a column within |cos| >
    :data:`PAIR_COSINE` of it, under the same Bonferroni-corrected F-test.
    """
    from scipy.stats import chi2

    if len(support) < 2:
        return tuple(sorted(support))
    unit = a / np.maximum(np.linalg.norm(a, axis=0), 1e-300)
    norms2 = np.einsum("ij,ij->j", a, a)
    for _ in range(2 * len(support)):
        cos = np.abs(unit.T @ unit[:, support])  # (p, chosen)
        near = cos > PAIR_COSINE
        near[support, :] = False
        options = [np.flatnonzero(near[:, k]) for k in range(len(support))]
        # only chosen pairs that can cancel: nearly parallel to each other on the data
        pairs = [
            (i, j)
            for i in range(len(support))
            for j in range(i + 1, len(support))
            if cos[support[j], i] > PAIR_COSINE and options[i].size and options[j].size
        ]
        if not pairs:
            break
        rss = _support_rss(a, b, list(support), outside)
        sigma2 = rss / max(n_rows - len(support), 1.0)
        tried = sum(options[i].size * options[j].size for i, j in pairs)
        bar = float(chi2.isf(REPLACE_P / tried, 1)) * sigma2
        best, best_drop = None, bar
        for i, j in pairs:
            rest = [c for k, c in enumerate(support) if k not in (i, j)]
            q = np.linalg.qr(a[:, rest])[0] if rest else np.zeros((a.shape[0], 0))
            resid = b - q @ (q.T @ b)
            ci, cj = options[i], options[j]
            pi = a[:, ci] - q @ (q.T @ a[:, ci])
            pj = a[:, cj] - q @ (q.T @ a[:, cj])
            # RSS with (ci, cj) in place of the pair: project the residual on their 2-D span
            gii = np.einsum("ij,ij->j", pi, pi)[:, None]
            gjj = np.einsum("ij,ij->j", pj, pj)[None, :]
            gij = pi.T @ pj
            di = (pi.T @ resid)[:, None]
            dj = (pj.T @ resid)[None, :]
            det = gii * gjj - gij**2
            valid = (
                (det > tol * norms2[ci][:, None] * norms2[cj][None, :])
                & (gii > tol * norms2[ci][:, None])
                & (gjj > tol * norms2[cj][None, :])
                & (ci[:, None] != cj[None, :])
            )
            with np.errstate(divide="ignore", invalid="ignore"):
                gain = (gjj * di**2 - 2 * gij * di * dj + gii * dj**2) / det
            rss_pair = outside + float(resid @ resid) - np.where(valid, gain, -np.inf)
            k = np.unravel_index(int(np.argmin(rss_pair)), rss_pair.shape)
            drop = rss - float(rss_pair[k])
            if drop > best_drop:
                trial = list(support)
                trial[i], trial[j] = int(ci[k[0]]), int(cj[k[1]])
                best, best_drop = trial, drop
        if best is None:
            break
        support = best
    return tuple(sorted(support))


def support_at(path: Sequence[tuple[tuple[int, ...], float]], floor: float) -> tuple[int, ...]:
    """The support where the path stops: before the first step gaining less than ``floor``."""
    support: tuple[int, ...] = ()
    for step_support, gain in path:
        if gain < floor:
            break
        support = step_support
    return support


def stepwise_coefficients(
    a: np.ndarray,
    b: np.ndarray,
    rows: int,
    lams: Sequence[float],
    max_terms: int | None = None,
    simpler: dict[int, list[int]] | None = None,
    n_eff: float | None = None,
    stop_noise: bool = True,
    replace: bool = True,
    backward: bool = True,
) -> np.ndarray:
    """Scaled coefficients of every target at every threshold (one path per target).

    Args:
        a: Scaled regression matrix (the triangular factor over unit-RMS columns).
        b: Scaled targets, one column per target (unit RMS over the data rows).
        rows: Number of data rows (the gain floor is ``lam^2 rows``).
        lams: Thresholds: fraction of the target RMS a column must explain to enter.
        max_terms: Largest support per target (default: ``min(p, 64)``).
        simpler: Simpler near-collinear twins of each column (see :func:`stepwise_path`).
        n_eff: Effective independent rows for the twin F-test (default: ``rows``).
        stop_noise: End each path after a few insignificant entries (see
            :func:`stepwise_path`).
        replace: Refine each support read off the path by :func:`replace_terms`.
        backward: Take the backward-elimination support (:func:`backward_path`) where it is
            significantly better.

    Returns:
        Shape (len(lams), targets, p), least-squares refits on each support.
    """
    p = a.shape[1]
    max_terms = min(p, 64) if max_terms is None else max_terms
    out = np.zeros((len(lams), b.shape[1], p))
    positive = [float(v) for v in lams if v > 0]
    floor = min(positive) ** 2 * rows if positive and len(positive) == len(lams) else 0.0
    if backward:
        # the path goes a decade further, so that backward elimination (`backward_path`)
        # starts from the columns the data support just below the threshold too
        floor *= BACKWARD_REACH**2
    for i in range(b.shape[1]):
        path = stepwise_path(a, b[:, i], max_terms, simpler=simpler, total=float(rows),
                             n_eff=n_eff or rows, floor=floor, stop_noise=stop_noise)  # fmt: skip
        refits: dict[tuple[int, ...], np.ndarray] = {}
        refined: dict[tuple[int, ...], tuple[int, ...]] = {}
        outside = float(rows) - float(b[:, i] @ b[:, i])
        entered = sorted({c for step, _ in path for c in step})
        back = backward_path(a, b[:, i], entered) if backward else []
        for li, lam in enumerate(lams):
            support = support_at(path, float(lam) ** 2 * rows) if lam > 0 else _last(path)
            if not support:
                continue
            if replace:
                if support not in refined:
                    refined[support] = replace_terms(a, b[:, i], support, outside,
                                                     float(n_eff or rows))  # fmt: skip
                support = refined[support]
            if lam > 0 and back:
                support = _better_support(a, b[:, i], support, back, float(lam) ** 2 * rows,
                                          simpler, outside, float(n_eff or rows))  # fmt: skip
            if support not in refits:
                cols = list(support)
                refits[support] = np.linalg.lstsq(a[:, cols], b[:, i], rcond=None)[0]
            out[li, i, list(support)] = refits[support]
    return out


def backward_path(
    a: np.ndarray, b: np.ndarray, columns: Sequence[int]
) -> list[tuple[tuple[int, ...], float]]:
    """Backward elimination from ``columns``: the path from all of them down to one.

    Each step removes the column whose removal raises the residual sum of squares least
    (``coef^2 / (R^-1 R^-T)_kk``). Greedy entry can go astray when the best single column is
    a blend of true ones (``cos(phi) q`` in ``theta'`` at large tilt): the columns entered
    later then compensate, and the forward support never becomes the true one, though every
    true column entered somewhere on the path. Eliminating from all the columns the forward
    path entered starts from a support that holds them all.

    Returns:
        One entry per removal, largest support first: the support before the removal and the
        removal's cost (increase of the residual sum of squares).
    """
    support = list(columns)
    path: list[tuple[tuple[int, ...], float]] = []
    while support:
        q, r = np.linalg.qr(a[:, support])
        diag = np.abs(np.diag(r))
        if diag.min() <= COLLINEAR_TOL * max(diag.max(), 1e-300):
            # a column in the span of the others (to round-off): it costs nothing to remove
            k = int(np.argmin(diag))
            path.append((tuple(sorted(support)), 0.0))
            support.pop(k)
            continue
        loss = _removal_costs(a, b, support, (q, r))
        k = int(np.argmin(loss))
        path.append((tuple(sorted(support)), float(loss[k])))
        support.pop(k)
    return path


def _better_support(
    a: np.ndarray,
    b: np.ndarray,
    support: tuple[int, ...],
    back: Sequence[tuple[tuple[int, ...], float]],
    floor: float,
    simpler: dict[int, list[int]] | None,
    outside: float,
    n_rows: float,
) -> tuple[int, ...]:
    """The forward support, or the backward one where it is significantly better.

    Both searches aim at the same objective, ``RSS + floor |S|`` (a gain threshold of
    ``floor`` is the greedy solution of that L0 penalty). The backward support at ``floor``
    (the last before a removal costing ``floor`` or more; complex columns given way to simpler
    twins as on the forward path) replaces the forward one only when its objective is lower
    by more than the replacement bar (chi-square(1) at :data:`REPLACE_P` over the number of
    exchanges of one column, in residual variances): near ties keep the forward path's
    choices.
    """
    from scipy.stats import chi2

    candidate: tuple[int, ...] = ()
    for step, loss in back:
        if loss >= floor:
            candidate = step
            break
    if not candidate or candidate == support:
        return support
    chosen = list(candidate)
    if simpler:
        _swap_twins(a, b, chosen, simpler, _invert(simpler), outside, n_rows)
    forward_rss = _support_rss(a, b, list(support), outside)
    backward_rss = _support_rss(a, b, chosen, outside)
    sigma2 = min(forward_rss, backward_rss) / max(n_rows - max(len(support), len(chosen)), 1.0)
    gain = forward_rss + floor * len(support) - (backward_rss + floor * len(chosen))
    k = max(len(support), len(chosen))
    bar = float(chi2.isf(REPLACE_P / max(k * (a.shape[1] - k), 1), 1))
    return tuple(sorted(chosen)) if gain > bar * sigma2 else support


def _removal_costs(
    a: np.ndarray,
    b: np.ndarray,
    support: Sequence[int],
    qr: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """Increase of the RSS when each chosen column is removed: ``coef^2 / (R^-1 R^-T)_kk``."""
    q, r = qr if qr is not None else np.linalg.qr(a[:, list(support)])
    return _costs_from_factor(r, q.T @ b)


def _costs_from_factor(r: np.ndarray, qtb: np.ndarray) -> np.ndarray:
    """:func:`_removal_costs` from the triangular factor R of the chosen columns and Q^T b."""
    r_inv = np.linalg.inv(r)
    coef = r_inv @ qtb
    return coef**2 / np.maximum(np.einsum("ij,ij->i", r_inv, r_inv), 1e-300)


def _support_rss(a: np.ndarray, b: np.ndarray, cols: list[int], outside: float) -> float:
    q = np.linalg.qr(a[:, cols])[0]
    return outside + float(b @ b) - float(np.sum((q.T @ b) ** 2))


def _last(path: Sequence[tuple[tuple[int, ...], float]]) -> tuple[int, ...]:
    return path[-1][0] if path else ()


def simpler_twins(
    a: np.ndarray, feature_names: Sequence[str], threshold: float = 0.999
) -> dict[int, list[int]]:
    """Each column's simpler near-collinear twins.

    A twin is nearly parallel to the column on the data (|cos| > ``threshold``) and its term
    is a proper factor of the column's term (``1`` of ``cos(phi)``, ``u2`` of ``u2 cos(phi)``).
    """
    from identification.features import parse_term

    terms = [set(parse_term(n)) for n in feature_names]
    unit = a / np.maximum(np.linalg.norm(a, axis=0), 1e-300)
    cos = np.abs(unit.T @ unit)
    out: dict[int, list[int]] = {}
    for j, k in zip(*np.nonzero(cos > threshold), strict=True):
        if terms[k] < terms[j]:
            out.setdefault(int(j), []).append(int(k))
    return out


SUBSET_LIMIT = 2_000_000
"""Largest number of supports :func:`best_subset` enumerates (about a second of batched solves)."""


def best_subset(
    gram: np.ndarray, c: np.ndarray, pool: Sequence[int], k: int, twin: np.ndarray
) -> tuple[float, tuple[int, ...]] | None:
    """The k columns of ``pool`` that explain the most of the target (exhaustive).

    Args:
        gram: ``A^T A`` of unit-norm columns (p x p).
        c: ``A^T b``.
        pool: Candidate columns.
        k: Support size.
        twin: Pairs of columns that may not be chosen together (p x p, boolean): near
            twins, whose pair would fit noise with large cancelling coefficients.

    Returns:
        ``(explained sum of squares, support)``, or None where the pool has more than
        :data:`SUBSET_LIMIT` supports of size k.
    """
    import itertools
    from math import comb

    pool = np.asarray(pool)
    if k <= 0 or k > len(pool) or comb(len(pool), k) > SUBSET_LIMIT:
        return None
    g = gram[np.ix_(pool, pool)] + 1e-12 * np.eye(len(pool))
    cp = c[pool]
    banned = twin[np.ix_(pool, pool)]
    combos = itertools.combinations(range(len(pool)), k)
    best: tuple[float, tuple[int, ...]] = (-np.inf, ())
    while chunk := list(itertools.islice(combos, 100_000)):
        s = np.array(chunk)
        ok = np.ones(len(s), dtype=bool)
        for i, j in itertools.combinations(range(k), 2):
            ok &= ~banned[s[:, i], s[:, j]]
        s = s[ok]
        if not len(s):
            continue
        cs = cp[s]
        explained = np.einsum("ij,ij->i", cs, np.linalg.solve(g[s[:, :, None], s[:, None, :]],
                                                              cs[..., None])[..., 0])  # fmt: skip
        j = int(np.argmax(explained))
        if explained[j] > best[0]:
            best = (float(explained[j]), tuple(sorted(int(pool[t]) for t in s[j])))
    return best if best[1] else None
