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
3. **Score** (:mod:`identification.scoring`). Multi-step open-loop prediction on the
   held-out data: from start points spread
   over each held-out trajectory, the candidate is integrated by RK4 with the *recorded*
   inputs for ``horizon`` steps (rows a logger lost are predicted through, not compared);
   the error of every state, divided by that state's scale (the smaller of its standard
   deviation over the data and the error of holding it over the horizon:
   :func:`score_scale`), is averaged over states, steps and starts (root mean square).
   The windows and the horizon are sized to the segments that hold half and most of the data
   (:func:`~identification.scoring.window_cap`, :func:`~identification.scoring.typical_length`).
   A prediction that leaves finite numbers or grows past 1e3 state deviations scores inf.
4. **Rule: one standard error.** Among candidates whose mean fold score is within one
   standard error (over folds) of the best mean, the one with the fewest terms (fitted on all
   data) wins; ties go to the lower mean. Sparser models that predict as well as the best,
   within what the folds can resolve, are preferred.
5. **Final model** (:mod:`identification.support`). The chosen window and threshold are
   refitted on all data (full RK4 fixed
   point). Where the greedy path stopped short holding a wrong twin, each equation's best
   support one term larger (or of the same size) within its terms' near twins and best next
   entries is taken when the data need it (:func:`grow_significant`; a larger one also by a
   Wald test on the rows with their long-run covariance, :func:`wald_chi2`). Near-collinear pairs
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

7. **Correlated equation errors.** Where the plain selection's window-1 residuals are
   correlated in time (unmeasured forces such as gusts, which a controller answers, bias a
   plain fit), the selection runs again on prewhitened rows (AR(1), window 1:
   :data:`identification.fit.AR1`) and that model is kept unless it needs more than
   :data:`AR1_EXTRA_TERMS` terms beyond the plain one (``prewhiten``).

Scores, the rule and the warnings go into ``model.meta["selection"]`` (JSON-safe). The notes on
the log (outlying steps, lags, offsets, stamp noise, units) come from
:mod:`identification.diagnostics`.
"""

from __future__ import annotations

import dataclasses
import io
import warnings
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from identification.data import (
    IdentificationWarning,
    Trajectory,
    as_trajectories,
    check_glitches,
    data_ranges,
    drift_gain,
    drift_meta,
    drift_segments,
    drift_terms,
    drift_text,
    input_drift_of,
    input_lag_of,
    lag_segments,
    log_starts,
)
from identification.diagnostics import (
    AR1_MAX,
    AR1_MIN,
    INPUT_SHIFTS,
    REST_ROWS,
    InputTiming,
    angle_offset_note,
    cut_rows,
    cut_steps,
    data_warnings,
    disagreement_note,
    empty_equation_note,
    equation_error_ar1,
    held_blocks,
    input_drift,
    input_saturation,
    input_timing,
    kinematic_input_note,
    misfit_note,
    outlier_note,
    outlying_steps,
    position_terms_note,
    refined_lag,
    stamp_jitter,
    state_bias_note,
    state_shift_note,
    still_blocks,
)
from identification.features import compile_rhs
from identification.fit import (
    AR1,
    TALLY,
    FitConfig,
    Gram,
    check_identifiable,
    fit_coefficients,
    grams,
    serial_blas,
    solve,
    solve_lambdas,
)
from identification.libraries import PRESETS, library_from_spec
from identification.model import IdentifiedModel
from identification.scoring import (
    integrator_resolution,
    long_enough,
    prediction_score,
    score_scale,
    start_spans,
    start_states,
    validation_units,
    window_cap,
)
from identification.support import (
    F_CRITICAL,
    drop_window_bias,
    grow_significant,
    indistinguishable_twins,
    least_squares,
    long_run_ratio,
    prune_insignificant,
    refit_support,
    residual_variance,
    resolve_collinear,
    restart_centred,
    significance_bar,
    unsplit_twins,
    wald_confirmation,
)
from quad_envs.fileio import jsonable

SATURATION_CUTS = 4
"""Times :func:`select_model` cuts the steps beyond the hinges it found with ``drop_outliers``
(each time all :func:`~identification.diagnostics.input_saturation` names)."""

SELECT_LAMBDAS: tuple[float, ...] = tuple(float(v) for v in np.logspace(-6, 0, 13))
"""Scaled thresholds tried by default (half decades from 1e-6 to 1)."""

WINDOWS: tuple[int, ...] = (1, 4, 16, 64)
"""Integral windows tried by default (1: clean data; longer: noise; a window of
:func:`window_cap` or more, a quarter of the segments that hold half of the rows, is skipped).
64 lets the validation average sigma = 1e-2 noise."""

BAG_T = 2.0
"""A kept term's coefficient must exceed this many standard deviations of its bootstrap fits,
or the full data must reject its removal (F-test), to stay in the model."""

POOR_FIT = 0.5
"""A chosen model whose held-out score is above this fraction of holding the state's is
reported as a poor fit (a warning; the model is still returned)."""


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


class NoModelError(ValueError):
    """The selection's refusal where no model with terms predicts better than holding the state.

    Attributes:
        timing: The shift or lag of the inputs the least sparse fit named (None: none).
    """

    def __init__(self, message: str, timing: InputTiming | None = None) -> None:
        super().__init__(message)
        self.timing = timing


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
        error_ar1: Lag-1 autocorrelation of the plain selection's window-1 residuals (its
            least sparse window-1 fit's: :func:`equation_error_ar1`; None: at round-off, or
            not an integral formulation).
        ar1: The coefficient the rows were prewhitened with (0: not prewhitened).
        timing: The shift or lag of the inputs the timing check named on the model
            (:func:`~identification.diagnostics.input_timing`; None: none).
        prewhitened_timing: The same on the prewhitened selection's model, where one ran.
        start_spans: Per state, the half-width in rows of the local quadratic the scores'
            predictions start from (:func:`~identification.scoring.start_spans`; 0: the
            logged row).
        drift: The drift ``(a1, a2)`` of the inputs' gain that the model's own terms fit best
            (:func:`~identification.diagnostics.input_drift`) where the halves of the logs
            disagree on an input's gain, the data carry a drift, or the drift passes its own
            test; else None.
    """

    candidates: list[Candidate]
    chosen: int
    folds: int
    horizon: int
    rule: str
    warnings: list[str] = field(default_factory=list)
    hold: float = float("nan")
    final_terms: int | None = None
    error_ar1: float | None = None
    ar1: float = 0.0
    timing: InputTiming | None = None
    prewhitened_timing: InputTiming | None = None
    start_spans: dict[str, int] = field(default_factory=dict)
    drift: tuple[float, float] | None = None

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
                "error_ar1": self.error_ar1,
                "prewhitened_ar1": self.ar1,
                "start_spans": self.start_spans,
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
        from quad_envs.fileio import atomic_write_bytes

        return atomic_write_bytes(path, self.plot_png())

    def plot_png(self) -> bytes:
        """:meth:`plot`'s figure as PNG bytes (to write beside the model at the same moment)."""
        import matplotlib

        matplotlib.use("Agg", force=False)
        import matplotlib.pyplot as plt
        from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

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
        return buffer.getvalue()


# -- folds and scores -------------------------------------------------------------------
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
    prewhiten: bool | None = None,
    input_lag: float | None = None,
    keep_rest: bool = False,
    input_drift: float | Sequence[float] | None = None,
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
            once more; cut the steps beyond the hinges where the states respond less to
            extreme inputs (:func:`~identification.diagnostics.input_saturation`) and select
            again, up to :data:`SATURATION_CUTS` times. By default they are only reported.
        prewhiten: Whether to prewhiten the rows for equation errors correlated in time
            (:data:`identification.fit.AR1`; window 1). None (default): where the plain
            model's window-1 residuals are (:func:`equation_error_ar1`), a prewhitened
            selection is run too and kept unless it needs more than
            :data:`AR1_EXTRA_TERMS` terms beyond the plain one; True: the prewhitened model
            wherever the errors are positively correlated; False: never. Prewhitened fits
            are at window 1, whatever ``windows`` holds.
        input_lag: The time constant [s] of a first-order lag the held inputs act through
            (:meth:`Trajectory.lag_inputs`; 0: they act as given). None (default): as
            given, and where the timing check names a lag on the model (or, where no model
            predicts better than holding the state, on the least sparse fit) and the data
            carry none of their own, the selection runs again with it and keeps it (a log of
            the commands of motors that lag them; :data:`INPUT_LAGS` tried).
        keep_rest: Keep rows where the states stay still while the model says they would
            move (:func:`held_blocks`: a vehicle resting on the ground before take-off or
            after landing). By default they are left out, with a note.
        input_drift: A drift of the held inputs' gain: the vehicle applies ``1 + a1 tau +
            a2 tau^2`` times each logged input, ``tau`` the time since its log's first row;
            ``a1`` [1/s] or ``(a1, a2)`` (:meth:`Trajectory.drift_inputs`; 0: none). None
            (default): as given,
            and where the halves of the logs disagree on an input's gain and the data carry
            no drift of their own, the drift the model's terms fit best is tried and kept
            where its selection predicts the held-out parts better (a battery that sags;
            :func:`_select_drifted`).

    Returns:
        The model (scores in ``meta["selection"]``, ensemble statistics attached) and the
        report. Each of the report's notes is also issued as an
        :class:`identification.data.IdentificationWarning`.

    Raises:
        ValueError: Unidentifiable data (see :func:`identification.fit.check_identifiable`),
            every candidate with terms diverged, or the chosen model has no term (nothing
            predicts the held-out data better than holding the state).
    """
    if prewhiten is not None and not isinstance(prewhiten, bool | np.bool_):
        raise TypeError(f"prewhiten must be None, True or False, got {prewhiten!r}")
    prewhiten = None if prewhiten is None else bool(prewhiten)  # np.False_ is not False
    trajs = as_trajectories(trajs)  # (read once: an iterator is selected from twice)
    # the data as given (the pieces the selection cuts out of them are not judged again: a
    # ground trial's 20 rows of idle thrust and one step were called a glitch)
    check_glitches(trajs)
    if input_drift is not None:  # the gain scales what was logged, before any lag
        trajs = drift_segments(trajs, input_drift)
    if input_lag is not None:
        trajs, _ = lag_segments(trajs, input_lag)
    settings = dict(config=config, lambdas=lambdas, windows=windows, folds=folds,
                    horizon=horizon, n_models=n_models, seed=seed, system=system,
                    progress=progress, drop_outliers=drop_outliers)  # fmt: skip
    auto = input_lag is None and not input_lag_of(trajs)
    chain = _select_timed if keep_rest else _select_unheld

    def select(data: list[Trajectory]) -> tuple[IdentifiedModel, SelectionReport]:
        return chain(data, library, settings, prewhiten, auto)

    drifting = input_drift is None and not any(input_drift_of(trajs))
    return _finished(*_select_drifted(trajs, select, drifting))


DRIFT_ROUNDS = 2
"""Selections :func:`_select_drifted` runs with a drift: the one named, then the one its
model's own terms refine it to (where that moves it by more than :data:`DRIFT_MOVED`)."""

DRIFT_MOVED = 1e-3
"""A refined drift whose gain moves by this share of the drift's change over the longest log
(at its middle or end) is selected again."""


def _select_drifted(
    trajs: list[Trajectory],
    select: Callable[[list[Trajectory]], tuple[IdentifiedModel, SelectionReport]],
    auto: bool,
) -> tuple[IdentifiedModel, SelectionReport]:
    """The selection as logged, or with the drift of the inputs' gain its model names.

    A battery that sags turns each command into less force as a flight goes on: a trial's
    15 % over each flight gave 10 terms for 7, 43 % off at 1 s, and a note that the halves
    of the logs disagree. Where they disagree on an input's gain, or a drift passes its own
    test on the model's terms, the drift rate those terms fit best
    (:func:`~identification.diagnostics.input_drift`) is applied to the logged inputs and
    the selection runs again (refined once on its own model), and is kept where it predicts
    its held-out data better, as a share of holding the state.
    """
    model, report = select(trajs)
    if not auto or not report.drift:
        return model, report
    terms, kept = report.drift, None
    span = max(float(t.t[-1]) - s for t, s in zip(trajs, log_starts(trajs), strict=True))
    for _ in range(DRIFT_ROUNDS):
        try:
            again = select(drift_segments(trajs, terms))
        except ValueError:
            break
        if kept is not None and _relative_score(again[1]) > _relative_score(kept[1]):
            break
        kept = again
        refined = again[1].drift
        change = abs(float(drift_gain(terms, span)) - 1.0)
        if refined is None or max(abs(float(drift_gain(refined, tau) - drift_gain(terms, tau)))
                                  for tau in (span / 2, span)) <= DRIFT_MOVED * change:  # fmt: skip
            break
        terms = refined
    theirs = _relative_score(report)
    if kept is None:
        report.warnings.append(f"the model's terms fit {drift_text(terms)} to the inputs, and "
                               "the selection with it failed: the inputs are kept as "
                               "logged")  # fmt: skip
        return model, report
    ours, terms = _relative_score(kept[1]), drift_terms(kept[0].meta["input_drift"])
    if ours > theirs:  # a drift that predicts the held-out parts worse is not the vehicle's
        report.warnings.append(
            f"the model's terms fit {drift_text(terms)} to the inputs, but the model selected "
            f"with it predicts its held-out data worse ({ours:.3g} of holding the state, "
            f"against {theirs:.3g}): the inputs are kept as logged"
        )
        return model, report
    model, report = kept
    change = float(drift_gain(terms, span)) - 1.0
    report.warnings.insert(0, (
        f"the inputs act with {drift_text(terms)}, {change:+.1%} over the longest log "
        f"({span:.3g} s): a battery that sags, fuel or a payload that changes. The model's "
        "terms fit it (the halves of the logs disagree on an input's gain, or its drop in "
        "the residual passes the bar), and the model selected with it predicts its held-out "
        f"data better ({ours:.3g} of holding the state, against {theirs:.3g} as logged). The "
        "model is the vehicle at the start of its logs (gain 1): simulate and the surrogate "
        "env fly it so, and score applies the drift (meta.input_drift) to held-out logs as "
        "in training (--input-drift 0 there reads them as logged; here, --input-drift 0 or "
        "input_drift=0 keeps the inputs as logged)"
    ))  # fmt: skip
    return model, report


def _select_unheld(
    trajs: list[Trajectory], library: Sequence[str], settings: dict, prewhiten: bool | None,
    auto: bool,
) -> tuple[IdentifiedModel, SelectionReport]:  # fmt: skip
    """The selection without the rows where something held the vehicle still.

    A log that starts on the ground (motors idle, then spinning up while the thrust is
    under the weight) or ends there holds its states still while the inputs move: a
    held-out trial's flights with 10 to 50 % of their rows on the ground gave gravity 27 %
    to 36 times off with exit 0, and no note named the ground. Where still blocks
    (:func:`still_blocks`) exist, a selection without them judges them: the chunks in which
    its model says the states would have moved (:func:`held_blocks`) are left out, with the
    steps that stand out beside them, and the selection runs once more; the blocks it
    predicts still (a hover) stay in, and where none is held every row does.
    """
    blocks = still_blocks(trajs)
    cut = cut_rows(trajs, blocks)[0] if blocks else []
    # where the vehicle met the ground it moved (a touchdown, its bounces, a lift-off from
    # a soft contact): those steps stand out of the model's residuals and are cut too (a
    # trial's landing bounces left gravity 15 times off, and a model bent by them misses
    # every chunk, so that the held ones no longer stand out)
    cutting = {**settings, "drop_outliers": True}
    try:
        trial = _select_timed(cut, library, cutting, prewhiten, auto) if cut else None
    except ValueError:
        trial = None
    held = held_blocks(trial[0], trajs, blocks) if trial else []
    if not held:  # nothing held the vehicle: every row stays in
        return _select_timed(trajs, library, settings, prewhiten, auto)
    rows = sum(b - a for _, a, b, *_ in held)
    kept, _ = cut_rows(trajs, held)  # hover blocks stay in
    try:
        trial = _select_timed(kept, library, cutting, prewhiten, auto)
    except ValueError:
        pass  # the selection without every still block stands
    model, report = trial
    report.warnings.insert(0, _rest_note(trajs, held, rows))
    return model, report


def _rest_note(trajs: list[Trajectory], held: list, rows: int) -> str:
    """What :func:`_select_unheld` left out, and why."""
    several = len(trajs) > 1
    spans: list[list[int]] = []
    for i, a, b, *_ in sorted(held):  # consecutive chunks as one span
        if spans and spans[-1][0] == i and spans[-1][2] == a:
            spans[-1][2] = b
        else:
            spans.append([i, a, b])
    shown = []
    for i, a, b in spans[:6]:
        source = trajs[i].meta.get("source")
        where = f" of {source}" if source else (f" (segment {i + 1})" if several else "")
        shown.append(f"t = {trajs[i].t[a]:.4g} to {trajs[i].t[b - 1]:.4g} s{where}")
    more = ", ..." if len(spans) > 6 else ""
    _, _, _, state, moved = max(held, key=lambda h: h[4])
    return (
        f"{rows} row(s) in {len(spans)} block(s) ({', '.join(shown)}{more}) hold every state "
        "still (or all but one, drifting steadily as an estimate on the ground does) while "
        f"the model says they would move ({state} by {moved:.2g} of its spread "
        f"within {REST_ROWS} rows at most): something held the vehicle there (the ground "
        "before take-off or after landing, a stand, a tether), which the equations do not "
        "describe; those rows were left out, and the steps that stand out of the model's "
        "residuals (a touchdown, its bounces, a lift-off) were cut as --drop-outliers does "
        "(keep_rest=True / --keep-rest keeps them all)"
    )


def _select_timed(
    trajs: list[Trajectory], library: Sequence[str], settings: dict, prewhiten: bool | None,
    auto: bool,
) -> tuple[IdentifiedModel, SelectionReport]:  # fmt: skip
    """The selection as logged, or with the lag of the inputs its timing check names.

    With ``auto``, a lag named on the plain model, on the prewhitened one or (where no model
    predicts better than holding the state) on the least sparse fit is fitted: the
    selection runs again on the lagged inputs and is kept where it predicts its held-out
    data at least as well, as a share of holding the state.
    """
    try:
        plain = _select_model(trajs, library, **settings)
    except NoModelError as refusal:
        lag = _named_lag(refusal.timing) if auto else None
        if lag is None:
            raise
        how = _how_named(refusal.timing)
        try:
            model, report = _select_prewhitened(lag_segments(trajs, lag)[0], library, settings,
                                                prewhiten)  # fmt: skip
        except ValueError:
            raise refusal from None
        model, report, lag = _refine_lag(trajs, library, settings, prewhiten, model, report, lag)
        report.warnings.insert(0, _lag_note(lag, "no model of the inputs as logged predicted "
                                                 "better than holding the state", how))  # fmt: skip
        return model, report
    named = plain[1].timing
    lag = _named_lag(named) if auto else None
    kept = None  # the selection as logged, prewhitened where it calls for it
    if lag is None:  # a prewhitened selection's model may still name a lag (gusts beside it)
        kept = _select_prewhitened(trajs, library, settings, prewhiten, plain)
        named = kept[1].prewhitened_timing
        lag = _named_lag(named) if auto else None
        if lag is None:
            return kept
    how = _how_named(named)

    def as_logged(note: str) -> tuple[IdentifiedModel, SelectionReport]:
        model, report = kept or _select_prewhitened(trajs, library, settings, prewhiten, plain)
        report.warnings.append(note)
        return model, report

    try:
        model, report = _select_prewhitened(lag_segments(trajs, lag)[0], library, settings,
                                            prewhiten)  # fmt: skip
    except ValueError as exc:
        return as_logged(f"{how} a first-order lag of the inputs of {lag:.3g} s, and the "
                         f"selection with it failed ({exc}): the inputs are kept as "
                         "logged")  # fmt: skip
    model, report, lag = _refine_lag(trajs, library, settings, prewhiten, model, report, lag)
    logged = kept or plain
    ours, theirs = _relative_score(report), _relative_score(logged[1])
    if ours > theirs:  # a lag that predicts the held-out parts worse is not the vehicle's
        return as_logged(f"{how} a first-order lag of the inputs of {lag:.3g} s, but the "
                         f"model selected with it predicts its held-out data worse "
                         f"({ours:.3g} of holding the state, against {theirs:.3g}): the inputs "
                         "are kept as logged")  # fmt: skip
    also = ""  # the shift's score, where one was named first
    if named is not None and named.kind == "shift":  # the shift named first may be the truth
        rows = int(named.value)
        try:
            shifted = _select_prewhitened([t.shift_inputs(rows) for t in trajs
                                           if len(t) - abs(rows) >= 3], library, settings,
                                          prewhiten)  # fmt: skip
        except ValueError:
            shifted = None
        if shifted is not None and _relative_score(shifted[1]) < ours:
            return as_logged(f"{how} a first-order lag of the inputs of {lag:.3g} s, but the "
                             f"inputs taken {abs(rows)} row(s) earlier predict the held-out "
                             f"data better ({_relative_score(shifted[1]):.3g} of holding the "
                             f"state, against {ours:.3g} with the lag): the inputs are kept as "
                             f"logged (--input-shift {rows} fits them so)")  # fmt: skip
        if shifted is not None:
            also = (f", with the inputs taken {abs(rows)} row(s) earlier "
                    f"{_relative_score(shifted[1]):.3g}")  # fmt: skip
    why = f"the model of the inputs as logged had {logged[0].n_terms} terms, score {theirs:.3g}"
    report.warnings.insert(0, _lag_note(lag, f"{why} of holding the state{also}; with the lag "
                                             f"{ours:.3g}", how))  # fmt: skip
    return model, report


def _refine_lag(
    trajs: list[Trajectory], library: Sequence[str], settings: dict, prewhiten: bool | None,
    model: IdentifiedModel, report: SelectionReport, lag: float,
) -> tuple[IdentifiedModel, SelectionReport, float]:  # fmt: skip
    """The selection with the lag refined on the terms of the model selected with ``lag``.

    The timing check's lag comes from the model of the inputs as logged and lands a few per
    cent off (:func:`~identification.diagnostics.refined_lag`); where the model selected with
    it fits its own terms best at another lag (3 significant digits), the selection runs
    again with that one and is kept where it predicts its held-out data at least as well.
    """
    window = int(model.meta["window"])
    better = refined_lag(trajs, model.feature_names, window, model.coefficients, lag)
    better = float(f"{better:.3g}")
    if better == lag:
        return model, report, lag
    try:
        again = _select_prewhitened(lag_segments(trajs, better)[0], library, settings, prewhiten)
    except ValueError:
        return model, report, lag
    if _relative_score(again[1]) > _relative_score(report):
        return model, report, lag
    return *again, better


def _relative_score(report: SelectionReport) -> float:
    """The chosen candidate's score as a share of holding the state's (lower is better)."""
    return report.best.mean / report.hold if report.hold > 0 else float("inf")


def _named_lag(timing: InputTiming | None) -> float | None:
    """The lag a timing check named, or that passed beside the shift it named (else None).

    A lag that passed beside a shift to earlier rows is tried too: under state noise of
    1e-2 a held-out trial's 40 ms lag fitted in-sample a little worse than inputs taken 3
    rows earlier, and its model predicted the held-out parts better (0.173 of holding the
    state against 0.199). The selection keeps it only so, and only where the shift's own
    selection predicts worse (a 2-row dead time: 0.026 with a lag, 3e-10 with the shift).
    """
    if timing and timing.kind == "lag" and timing.value > 0:
        return timing.value
    return timing.lag if timing and timing.kind == "shift" and timing.lag > 0 else None


def _how_named(timing: InputTiming | None) -> str:
    """How the timing check came to a lag (it named one, or one passed beside a shift)."""
    if timing and timing.kind == "shift":
        rows = abs(int(timing.value))
        return f"beside inputs taken {rows} row(s) earlier, the timing check passed"
    return "the timing check named"


def _lag_note(lag: float, why: str, how: str = "the timing check named") -> str:
    """The note of a selection run again with the lag the timing check came to."""
    return (
        f"the inputs act through a first-order lag of {lag:.3g} s (the actuators lag their "
        f"commands): {how} it and the model was selected with it ({why}; "
        "--input-lag 0 or input_lag=0 keeps the inputs as logged). Where the states are "
        "instead filtered estimates that lag the inputs, the lag stands in for the filter: "
        "the model then predicts logs filtered alike, not the vehicle's own states"
    )


def _select_prewhitened(
    trajs: list[Trajectory],
    library: Sequence[str],
    settings: dict,
    prewhiten: bool | None,
    plain: tuple[IdentifiedModel, SelectionReport] | None = None,
) -> tuple[IdentifiedModel, SelectionReport]:
    """The plain selection, and the prewhitened one where the equation errors call for it.

    ``plain``: the plain selection, already run.
    """
    model, report = plain or _select_model(trajs, library, **settings)
    rho = report.error_ar1
    if prewhiten is False and rho is not None and rho > AR1_MIN:
        report.warnings.append(_ar1_note(rho, report, None, None))
    if prewhiten is False or rho is None or rho <= (0.0 if prewhiten else AR1_MIN):
        if prewhiten:  # asked for, and nothing to prewhiten
            why = "at round-off" if rho is None else f"lag-1 autocorrelation {rho:.2f}"
            report.warnings.append(
                f"prewhitening was asked for, but the equation errors are not correlated in "
                f"time ({why}): the plain fit is kept"
            )
        return model, report
    ar1 = min(rho, AR1_MAX)
    try:
        white, white_report = _select_model(trajs, library, **settings, _ar1=ar1)
    except ValueError as exc:
        report.warnings.append(_ar1_note(rho, report, None, f"it failed: {exc}"))
    else:
        report.prewhitened_timing = white_report.prewhitened_timing = white_report.timing
        if prewhiten or white.n_terms <= model.n_terms + AR1_EXTRA_TERMS:
            white_report.error_ar1 = rho
            white_report.warnings.append(_ar1_note(rho, report, white.n_terms, None))
            if white_report.drift is None:  # a gain's drift the plain model's halves showed
                white_report.drift = report.drift  # (a sag's correlated errors, prewhitened)
            model, report = white, white_report
        else:
            report.warnings.append(_ar1_note(rho, report, white.n_terms, "kept"))
    return model, report


def _finished(
    model: IdentifiedModel, report: SelectionReport
) -> tuple[IdentifiedModel, SelectionReport]:
    """The notes in their order, in the model's metadata, and issued."""
    report.warnings = _fit_notes_first(report.warnings, model.state_names)
    model.meta["selection"] = report.to_meta()
    return _warned(model, report)


def _is_vehicle(system: str | None) -> bool:
    """Whether the model's label names a vehicle (a preset or an env's vehicle)."""
    from quad_envs.vehicles import VEHICLES

    return system is not None and (system in PRESETS or system in VEHICLES)


def _fit_notes_first(notes: list[str], states: Sequence[str]) -> list[str]:
    """The notes on the data and the whole fit before those on single equations' terms.

    A trial's disturbed 6-DOF runs printed 32 to 43 notes, most on near twins of single
    terms (``x': kept ...``), with the two that questioned the model (misfit, logs
    disagree) last.
    """
    own = _equation_prefixes(states)
    return [n for n in notes if not n.startswith(own)] + [n for n in notes if n.startswith(own)]


def term_note_count(notes: Sequence[str], states: Sequence[str]) -> int:
    """How many notes are on single equations' terms (they come after the others)."""
    return sum(n.startswith(_equation_prefixes(states)) for n in notes)


def _equation_prefixes(states: Sequence[str]) -> tuple[str, ...]:
    """How a note on one equation's terms begins (``x': ``)."""
    return tuple(f"{s}': " for s in states)


AR1_EXTRA_TERMS = 2
"""Where the equation errors are correlated in time, the prewhitened model is kept unless it
needs more than this many terms beyond the plain one. On 13 planar and 6-DOF data sets
with unmeasured gusts (a held-out trial's simulators and our own) the prewhitened model had
from 17 fewer terms to 2 more (a small spurious term) and its coefficients were nearer the
truth; with effects the library lacks it needed 5 to 16 more on the cases where it
predicted held-out flights worse (a sagging battery, ground effect, unlogged actuator lag),
and -7 to +1 where it predicted as well or better (docs/identification.md, "Unmeasured
forces and drifting parameters"). A recheck trial's slow strong gusts (6 % m g, 1 s) needed
3 more and its 6-DOF gust set 16 more, so their biased plain fits were kept (misses)."""


def _ar1_note(rho: float, plain: SelectionReport, white_terms: int | None, kept: str | None) -> str:
    """The note on equation errors correlated in time, and which fit was kept."""
    seen = (
        f"the equation errors are correlated in time (lag-1 autocorrelation {rho:.2f} at "
        "window 1, where white measurement noise gives about -0.5): unmeasured forces (wind, "
        "gusts) that a controller answers bias a plain fit, and so may effects the library "
        "lacks (a sagging battery, ground effect); "
    )
    plain_terms = plain.final_terms
    if kept is None and white_terms is None:
        return seen + (
            "prewhitening was not tried (prewhiten=False / --no-prewhiten, or a window "
            "other than 1 asked for); it may remove such a bias"
        )
    if kept is None:
        return seen + (
            f"the rows were prewhitened (AR(1), Prais-Winsten, window 1), which needs "
            f"{white_terms} terms against {plain_terms} for the plain fit "
            "(prewhiten=False / --no-prewhiten keeps the plain fit)"
        )
    if white_terms is None:
        return seen + f"a prewhitened fit was tried and {kept}; the plain fit is kept"
    return seen + (
        f"a prewhitened fit (AR(1), window 1) needs {white_terms} terms against "
        f"{plain_terms}, so the plain fit is kept (if the vehicle flew in wind or gusts, "
        "compare with prewhiten=True / --prewhiten)"
    )


def _select_model(
    trajs: Sequence[Trajectory],
    library: Sequence[str],
    *,
    config: FitConfig | None,
    lambdas: Sequence[float],
    windows: Sequence[int],
    folds: int,
    horizon: int,
    n_models: int,
    seed: int,
    system: str | None,
    progress: bool,
    drop_outliers: bool,
    _cut: tuple[str, ...] = (),
    _ar1: float = 0.0,
    _outliers: bool = True,
) -> tuple[IdentifiedModel, SelectionReport]:
    """:func:`select_model` on one formulation; its notes are in the report, not yet issued.

    ``_ar1``: prewhitened rows at window 1; ``_cut``: the notes of steps already cut (the
    second selection of ``drop_outliers``); ``_outliers``: False once the model's outlying
    steps were cut (``drop_outliers`` then cuts only the hinges of saturated inputs).
    """
    from tqdm import tqdm

    first = trajs[0]
    if any((t.state_names, t.input_names) != (first.state_names, first.input_names) for t in trajs):
        raise ValueError("all trajectories must have the same state and input names")
    lambdas, windows = _settings_lists(lambdas, windows)
    _check_settings(folds, lambdas, windows, horizon, n_models)
    if _ar1:  # window 1: a wider window's rows hold states its own errors moved
        trajs = [dataclasses.replace(t, meta={**t.meta, AR1: _ar1}) for t in trajs]
        windows = [1]
    if config is not None and not isinstance(config, FitConfig):
        raise TypeError(f"config must be a FitConfig, got {type(config).__name__}")
    if library is None:
        raise ValueError("the library is empty: give feature names, a preset or a spec")
    # a preset, a spec ("degree=2;angles=phi") or terms (canonical, each once)
    names = library_from_spec(library, first.state_names, first.input_names)
    if not names:
        raise ValueError("the library is empty: give feature names, a preset or a spec")
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
    if drop_outliers and _outliers:
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
            f"every window asked ({asked}) is too long for this data: windows under "
            f"{window_cap(trajs)} (a quarter of the segments that hold half of the rows) fit; "
            f"window {max(windows)} does"
        )
    k = min(folds, len(units))
    fold_of = np.arange(len(units)) % k
    scale = score_scale(units, horizon)
    spans = start_spans(units)
    starts = start_states(units, spans)

    def fold_part(items: Sequence, f: int) -> list:
        return [item for item, fo in zip(items, fold_of, strict=True) if fo == f]

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
        # the candidates' rows are the pilot's last pass's (the stage points of the pilot
        # before its last step, which changes it little): no pass of their own
        rows: list[Gram] = []
        pilot = fit_coefficients(long_enough(units, w), names, pilot_cfg, pilot, rows)
        pilots[w] = pilot
        fitted = iter(rows or grams(long_enough(units, w), names, base.derivative, w, pilot))
        unit_grams = [next(fitted) if len(u) > w else Gram.zeros(len(names), len(first.state_names))
                      for u in units]  # fmt: skip
        # candidates are the forward paths; the chosen one is refitted with the backward check
        grid_cfg = dataclasses.replace(base, window=w, backward=False)
        scores = np.full((len(lambdas), k), np.inf)
        fold_eqs = np.zeros((len(lambdas), len(first.state_names)))  # folds with terms there
        for f in range(k):
            train = Gram.stack([g for g, fo in zip(unit_grams, fold_of, strict=True) if fo != f])
            held, held_starts = fold_part(units, f), fold_part(starts, f)
            try:
                fold_xis = solve_lambdas(train, grid_cfg, lambdas, names)
            except (np.linalg.LinAlgError, ValueError, FloatingPointError):
                steps.update()
                continue
            fold_eqs += np.any(fold_xis != 0, axis=2)
            for li, xi in enumerate(fold_xis):
                try:
                    rhs = compile_rhs(names, xi, first.state_names, first.input_names)
                    scores[li, f] = prediction_score(rhs, held, scale, horizon,
                                                     starts=held_starts)  # fmt: skip
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
        "over the horizon), each prediction started from the state's local quadratic over "
        "the span its noise and curvature favour; chosen: the fewest terms within one "
        "standard error of the best mean score plus the scores' own integrator error "
        f"({resolution:.2g}); "
        "refitted on all data with the backward-elimination check; an equation replaced by a "
        "path on centred columns where that has no more terms and a penalised residual lower "
        "by the F-test's bar; each equation grown to its "
        "best support one term larger among its terms' near twins and best next entries (or "
        "one exchange plus one addition) where that passes the Bonferroni bar (a grown term "
        "kept only where its coefficient holds at the next wider window); terms that do "
        "not pass the bar against the residuals' long-run variance dropped"
    )
    report = SelectionReport(candidates, chosen, k, horizon, rule)
    report.start_spans = dict(zip(first.state_names, (int(m) for m in spans), strict=True))
    report.warnings += data_warnings(trajs, names)
    report.warnings += [*([stamped] if stamped else []), *_cut,
                        *([outliers] if outliers else [])]  # fmt: skip
    still = lambda x, u: np.zeros_like(x)  # noqa: E731
    report.hold = float(np.mean([
        prediction_score(still, fold_part(units, f), scale, horizon, starts=fold_part(starts, f))
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
    rows: list[Gram] = []
    xi = fit_coefficients(used, names, final_cfg, pilots[best.window], rows)
    if base.derivative != "rk4" or not rows:  # else the last pass's rows: xi solves them
        rows = grams(used, names, "rk4", best.window, xi)
    final_gram = Gram.stack(rows)
    ratio = long_run_ratio(used, names, xi, best.window)
    path_xi = xi

    def ratio_of(i: int, row: np.ndarray) -> float:
        trial = xi.copy()
        trial[i] = row
        return float(long_run_ratio(used, names, trial, best.window)[i])

    xi, notes = restart_centred(xi, final_gram, ratio, names, first.state_names,
                                (best.lam, ratio_of))  # fmt: skip
    report.warnings += notes
    ratio = ratio.copy()  # the pruning's: an equation grown by a twin takes the pair's
    confirm = wald_confirmation(used, names, xi, best.window)
    xi, notes = grow_significant(xi, final_gram, ratio, names, first.state_names, ratio_of,
                                 confirm)  # fmt: skip
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
    report.warnings += unsplit_twins(xi, final_gram, ratio, names, first.state_names)
    std = prob = None
    if n_models > 0:
        xi, std, prob, held, dropped = _bootstrap(used, names, final_cfg, xi, n_models, seed,
                                                  grown, ratio)  # fmt: skip
        report.warnings += dropped
        # a term whose near twin the other bags hold is not unsettled (its twin note says so)
        report.warnings += _weak_terms_note(xi, std, held, names, first.state_names)
    xi, note = _predicts_as_validated(xi, models[chosen], units, scale, horizon, resolution,
                                      names, first, starts)  # fmt: skip
    if note:  # the checks' model is not returned: neither its notes nor statistics apply
        report.warnings = [*report.warnings[:validated], note]
        std = prob = None
    else:  # a growth note describes its support: drop it where later checks changed that
        moved = [i for i, cols in grown.items() if set(np.flatnonzero(xi[i])) != set(cols)]
        stale = tuple(f"{first.state_names[i]}': the best support of" for i in moved)
        report.warnings = [w for w in report.warnings if not w.startswith(stale)]
    if not np.any(xi):  # the least sparse fit may still tell inputs logged out of time
        hint = _pilot_timing(used, names, pilots)
        said = f"; {hint.note}" if hint else ""
        raise NoModelError(_empty_model_message(candidates, report.hold) + said, hint)
    # An input in a kinematic relation is the sign of inputs that changed within the step;
    # whole-row shifts fit such logs a little better and worse predict (a trial: 30 % -> 35 %
    # at 1 s with the shift advised), so the input-shift note is not given beside it.
    # (a first-order lag of the actuators puts inputs there too, and is still named)
    driven = kinematic_input_note(used, names, xi)
    report.timing = input_timing(used, names, best.window, xi, ratio,
                                 shifts=() if driven else INPUT_SHIFTS)  # fmt: skip
    if report.timing is None and best.mean > POOR_FIT * report.hold:
        # a model that predicts little may lack the very input terms the check refits (our
        # own flights at 80 ms and noise 1e-2: phi_dot' = sin(phi) u1): ask the least sparse fit
        report.timing = _pilot_timing(used, names, pilots)
    shifted = report.timing.note if report.timing else None
    shifted = shifted or state_shift_note(used, names, best.window, xi, ratio)
    shifted = shifted or angle_offset_note(xi, names, first.state_names)
    for note in (shifted, driven):  # before the notes they cause (outlying steps, misfit)
        if note:
            report.warnings.append(note)
    spread = np.concatenate([t.x for t in used]).std(axis=0)
    biased = state_bias_note(xi, names, first.state_names, spread)
    if biased:
        report.warnings.append(biased)
    placed = position_terms_note(used, names, xi) if _is_vehicle(system) else None
    if placed:
        report.warnings.append(placed)

    def again(kept: list[Trajectory], cut: str, outliers_again: bool) -> tuple:
        """The selection once more on the pieces left by a cut, the cut's note carried."""
        return _select_model(
            kept, names, config=config, lambdas=lambdas, windows=asked, folds=folds,
            horizon=horizon_asked, n_models=n_models, seed=seed, system=system,
            progress=progress, drop_outliers=True, _outliers=outliers_again,
            _cut=(*_cut, *([outliers] if outliers else []), cut), _ar1=_ar1,
        )  # fmt: skip

    if base.derivative in ("rk4", "forward"):
        # The returned model's own residuals: sparse, it cannot bend to bad steps as a fit of
        # the whole library does (4 % of the steps with a wrong input hid from such a fit).
        flagged = outlying_steps(trajs, names, base.derivative, xi)
        if flagged and drop_outliers and _outliers:  # cut these too and select once more
            kept, lost = cut_steps(trajs, flagged)
            if kept:  # (the steps beyond a saturated input's hinge may still be cut there)
                return again(kept, outlier_note(trajs, flagged, True, lost), outliers_again=False)
        if flagged:
            note = outlier_note(trajs, flagged, False)
            report.warnings.append(f"after cutting, still: {note}" if _cut else note)
    saturation = input_saturation(used, names, xi)
    if saturation:
        beyond = saturation.flagged(trajs)
        steps = int(sum(f.any(axis=1).sum() for f in beyond.values()))
        times = sum("respond less to the inputs" in note for note in _cut)  # hinge cuts
        cut = drop_outliers and times < SATURATION_CUTS
        kept, lost = cut_steps(trajs, beyond) if cut else ([], 0)
        hinges = "the hinge" if len(saturation.hinges) == 1 else f"{len(saturation.hinges)} hinges"
        if kept:  # cut the steps beyond the hinges and select again (other limits may show)
            short = f"; {lost} rows in pieces too short to keep" if lost else ""
            return again(kept, f"cut out before selecting: {steps} steps beyond {hinges} "
                               f"where {saturation.note}{short}", outliers_again=True)  # fmt: skip
        report.warnings.append(
            f"after cutting hinges {times} time(s), still: {saturation.note}" if times else
            f"{saturation.note} (or --drop-outliers, drop_outliers=True, cuts the {steps} "
            f"steps beyond {hinges} out)"
        )  # fmt: skip
    named = any("robust deviations" in w for w in report.warnings)
    misfit = misfit_note(used, names, base.derivative, xi, outliers=named)
    if misfit:
        report.warnings.append(misfit)
    disagree, drifting = disagreement_note(used, names, best.window, xi)
    if disagree:
        report.warnings.append(disagree)
    # named by the halves, refined on the terms of a drift's own model, or tested
    report.drift = input_drift(used, names, best.window, xi,
                               named=drifting or any(input_drift_of(used)))  # fmt: skip
    empty = empty_equation_note(used, xi)
    if empty:
        report.warnings.append(empty)
    report.final_terms = int(np.count_nonzero(xi))
    report.ar1 = _ar1
    if not _ar1:  # read off the least sparse fit at window 1 where there is one (it leaves
        # less of the library's own terms in the residual than the sparse model)
        report.error_ar1, _ = equation_error_ar1(used, names, base.derivative,
                                                 pilots.get(1, xi))  # fmt: skip
    tally = TALLY.summary()
    if tally:
        report.warnings.append(tally)
    meta = {
        **final_cfg.label,
        "n_trajectories": len(trajs),
        **({"measured_inputs": list(trajs[0].measured)} if trajs[0].measured else {}),
        **({"input_lag": lag} if (lag := input_lag_of(trajs)) else {}),
        **({"input_drift": drift_meta(rate)} if any(rate := input_drift_of(trajs)) else {}),
        "n_samples": int(sum(len(t) for t in trajs)),
        "dt": first.dt,
        "ranges": data_ranges(trajs),
        "selection": report.to_meta(),
    }
    model = IdentifiedModel(names, xi, first.state_names, first.input_names, system, meta,
                            std, prob)  # fmt: skip
    return model, report


def _pilot_timing(
    used: Sequence[Trajectory], names: Sequence[str], pilots: dict[int, np.ndarray]
) -> InputTiming | None:
    """The input timing the least sparse fit (the narrowest window's pilot) names."""
    w0 = min(pilots)
    hint = input_timing(used, names, w0, pilots[w0], long_run_ratio(used, names, pilots[w0], w0))
    if hint is None:
        return None
    return dataclasses.replace(hint, note=f"the least sparse fit says: {hint.note}")


def _warned(
    model: IdentifiedModel, report: SelectionReport
) -> tuple[IdentifiedModel, SelectionReport]:
    """Issues each of the report's notes as an :class:`IdentificationWarning`.

    API users see them without reading ``report.warnings``; the CLI prints the list instead.
    """
    for note in report.warnings:
        warnings.warn(note, IdentificationWarning, stacklevel=5)  # past _finished and serial_blas
    return model, report


def _settings_lists(lambdas: Any, windows: Any) -> tuple[list, list]:
    """The grids as lists (a generator or an array is read once); a single value is refused."""

    def grid(name: str, value: Any) -> list:
        scalar = isinstance(value, np.ndarray) and value.ndim == 0  # iterable to isinstance
        if isinstance(value, str) or not isinstance(value, Iterable) or scalar:
            raise ValueError(f"{name} must be a sequence of numbers ([{value!r}] for one), got "
                             f"{value!r}")  # fmt: skip
        return list(value)

    return grid("lambdas", lambdas), grid("windows", windows)


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
    starts: Sequence[np.ndarray] | None = None,
) -> tuple[np.ndarray, str]:
    """The checked model, or the chosen candidate's fit where the checks broke its predictions.

    The refit, growth, pruning and bootstrap steps after the selection change terms that no
    fold scored. On data the library cannot hold (motor lag with the commands logged, a
    new-user trial) they grew a validated 17-term model to 44 terms that diverged on its own
    training flights. Both are fitted on all data, so both are scored on all of it (from
    ``starts``, the units' start states: :func:`~identification.scoring.start_states`), over
    twice the selection's horizon.
    """

    def score(coefficients: np.ndarray) -> float:
        rhs = compile_rhs(names, coefficients, first.state_names, first.input_names)
        try:  # twice the horizon: the grown 47-term model of the trial held 50 steps, not 100
            return prediction_score(rhs, units, scale, 2 * horizon, starts=starts)
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
        "inputs do not explain the states (lagged: --input-lag SECONDS fits commands that "
        "act through a first-order lag; mislabelled or closed-loop inputs, or commands the "
        "actuators did not follow: log the applied inputs)"
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
    bar = significance_bar(len(names))
    for _ in range(n_models):
        weights = rng.multinomial(len(blocks), np.full(len(blocks), 1.0 / len(blocks)))
        bag_gram = Gram.stack(block_grams, list(weights.astype(float)))
        bag = solve(bag_gram, config, names)
        for i, support in (grown or {}).items():
            own = list(np.flatnonzero(bag[i]))
            rss_own = least_squares(bag_gram.r, bag_gram.z[:, i], own)[0]
            rss_new, sigma2 = residual_variance(bag_gram, i, support)
            extra = max(len(support) - len(own), 0)
            scale = 1.0 if ratio is None else max(float(ratio[i]), 1.0)
            if rss_own - rss_new > bar * scale * sigma2 * extra:
                bag[i] = refit_support(bag_gram, i, support)
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
            rss, sigma2 = residual_variance(full, i, support)
            for j in np.flatnonzero(weak[i]):
                trial = [c for c in support if c != j]
                if least_squares(full.r, full.z[:, i], trial)[0] - rss > F_CRITICAL * sigma2:
                    weak[i, j] = False
    xi_in = xi
    if weak.any():
        xi = xi.copy()
        for i in np.unique(np.nonzero(weak)[0]):
            xi[i] = refit_support(full, i, [c for c in np.flatnonzero(xi[i]) if not weak[i, c]])
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
