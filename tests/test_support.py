"""Settling a model's support on the normal equations (identification.support): F-tests."""

import numpy as np
import pytest

from identification.data import (
    Trajectory,
)
from identification.experiments.synthetic import (
    OTHER_PLANAR,
    add_noise,
    truth_planar,
)
from identification.libraries import planar_library
from quad_envs.dynamics import PLANAR_STATE_NAMES as PS


def test_long_run_ratio_is_one_for_white_residuals_and_the_bartlett_sum_for_smooth_ones():
    from identification.support import long_run_ratio

    rng = np.random.default_rng(0)
    n, dt, phi = 40_000, 0.01, 0.8
    white = rng.normal(size=n)
    smooth = np.zeros(n)
    for k in range(1, n):
        smooth[k] = phi * smooth[k - 1] + white[k]
    trajs = []
    for rate in (white, smooth):
        x = np.concatenate([[0.0], np.cumsum(rate * dt)])[:, None]  # x' = rate (residual)
        t = np.arange(n + 1) * dt
        trajs.append(Trajectory(t, x, np.ones((n + 1, 1)), ("x",), ("u1",)))
    xi = np.zeros((1, 1))  # the model x' = 0 * 1: the residual is the rate itself
    assert long_run_ratio(trajs[:1], ["1"], xi, 1)[0] == pytest.approx(1.0, abs=0.05)
    lags = 8  # window 1: Bartlett weights up to lag 8
    expected = 1 + 2 * sum((1 - k / lags) * phi**k for k in range(1, lags))
    assert long_run_ratio(trajs[1:], ["1"], xi, 1)[0] == pytest.approx(expected, rel=0.1)


def test_pruning_drops_noise_terms_and_keeps_small_real_ones_against_the_long_run_variance():
    from identification.fit import Gram
    from identification.support import prune_insignificant

    rng = np.random.default_rng(1)
    n = 5000
    theta = rng.normal(size=(n, 4))  # a1 (large), a2 (noise), a3 (small but real), a4 (noise)
    y = 2.0 * theta[:, 0] + 0.05 * theta[:, 2] + 0.1 * rng.normal(size=n)
    gram = Gram.from_rows(theta, y[:, None])
    names = ["x", "y", "z", "w"]
    xi = np.linalg.lstsq(theta, y, rcond=None)[0][None, :]  # all four in the model
    pruned, notes = prune_insignificant(xi, gram, np.ones(1), names, ["s"])
    assert list(np.flatnonzero(pruned[0])) == [0, 2]  # a3 costs ~1250 variances: kept
    assert "'y'" in notes[0] and "'w'" in notes[0]
    # residuals 100 times more variable in the long run (smooth): a3 is no longer resolved
    pruned, _ = prune_insignificant(xi, gram, np.array([100.0]), names, ["s"])
    assert list(np.flatnonzero(pruned[0])) == [0]
    np.testing.assert_allclose(pruned[0, 0], np.linalg.lstsq(theta[:, :1], y, rcond=None)[0])


def test_growth_replaces_a_wrong_twin_and_adds_the_small_term_a_greedy_stop_missed():
    """A support holding the twin `cos(phi) b` of the true `b` and missing the small `c`: the
    best 3-term support in the pool is the truth; a support that is already right, beside 20
    noise columns, does not grow."""
    from identification.fit import Gram
    from identification.support import grow_significant

    rng = np.random.default_rng(0)
    a, b, e, c = rng.normal(size=(4, 4000))
    theta = np.column_stack([a, b, b + 0.01 * e, c, rng.normal(size=(4000, 20))])
    names = ["a", "b", "cos(phi) b", "c", *(f"n{k}" for k in range(20))]
    y = 3 * a + b + 0.1 * c + 0.05 * rng.normal(size=4000)
    start = np.zeros((1, len(names)))
    start[0, [0, 2]] = [3.0, 1.0]
    xi, notes = grow_significant(start, Gram.from_rows(theta, y[:, None]), np.ones(1), names, ["s"])
    assert list(np.flatnonzero(xi[0])) == [0, 1, 3]
    np.testing.assert_allclose(xi[0, [0, 1, 3]], [3.0, 1.0, 0.1], rtol=1e-2)
    assert "holds 'b', 'c' in place of 'b cos(phi)'" in notes[0]
    right = np.zeros((1, len(names)))
    right[0, [0, 1]] = [3.0, 1.0]
    y = 3 * a + b + 0.05 * rng.normal(size=4000)
    xi, notes = grow_significant(right, Gram.from_rows(theta, y[:, None]), np.ones(1), names, ["s"])
    assert list(np.flatnonzero(xi[0])) == [0, 1] and notes == []


def test_simpler_twins_are_taken_only_while_the_swaps_together_pass_the_f_test():
    """Each swap to the simpler twin costs 8.6 and 6.6 residual variances alone (under the
    F-test's 10.83), both together 15.1: one is taken, not both (before, each swap was tested
    against the support left by the one before, and both were)."""
    from identification.fit import Gram
    from identification.support import resolve_collinear

    rng = np.random.default_rng(1)
    b1, b2, d1, d2 = rng.normal(size=(4, 4000))
    c1, c2 = b1 + 0.02 * d1, b2 + 0.02 * d2  # |cos| = 0.9998 to their simple twins
    theta = np.column_stack([b1, c1, b2, c2])
    y = 0.095 * c1 + 0.12 * c2 + 0.05 * rng.normal(size=4000)
    xi = np.zeros((1, 4))
    xi[0, [1, 3]] = [0.095, 0.12]
    names = ["u1", "cos(phi) u1", "u2", "cos(phi) u2"]
    out, notes = resolve_collinear(xi, Gram.from_rows(theta, y[:, None]), names, ["s"], 1)
    assert list(np.flatnonzero(out[0])) == [0, 3] and len(notes) == 1


def test_a_simple_twin_gives_way_to_a_complex_one_the_data_prefer_past_the_f_test():
    """The fit holds `u1`, the data were made by its twin `cos(phi) u1` (|cos| = 0.9998),
    which fits about 57 residual variances better: exchanged, and not reported as a twin
    that fits equally well (before, any twin that fit better was reported so)."""
    from identification.fit import Gram
    from identification.support import indistinguishable_twins, resolve_collinear

    rng = np.random.default_rng(1)
    b1, d1, noise = rng.normal(size=(3, 4000))
    theta = np.column_stack([b1, b1 + 0.02 * d1])
    y = 0.3 * theta[:, 1] + 0.05 * noise
    gram = Gram.from_rows(theta, y[:, None])
    xi = np.array([[0.3, 0.0]])
    names = ["u1", "cos(phi) u1"]
    notes, _ = indistinguishable_twins(xi, gram, names, ["s"], 1)
    assert notes == []
    out, resolved = resolve_collinear(xi, gram, names, ["s"], 1)
    assert list(np.flatnonzero(out[0])) == [1] and abs(out[0, 1] / 0.3 - 1) < 1e-2
    assert "kept 'cos(phi) u1' in place of" in resolved[0, 0, 1]


def test_growth_takes_the_complex_twins_the_data_prefer_together():
    """Both chosen terms are the simpler twins of the true ones; the best support of the same
    size (the complex pair) fits 15 residual variances better, past the F-test: taken."""
    from identification.fit import Gram
    from identification.support import grow_significant

    rng = np.random.default_rng(1)
    b1, b2, d1, d2 = rng.normal(size=(4, 4000))
    theta = np.column_stack([b1, b1 + 0.02 * d1, b2, b2 + 0.02 * d2])
    y = 0.095 * theta[:, 1] + 0.12 * theta[:, 3] + 0.05 * rng.normal(size=4000)
    xi = np.zeros((1, 4))
    xi[0, [0, 2]] = [0.095, 0.12]
    names = ["u1", "cos(phi) u1", "u2", "cos(phi) u2"]
    out, notes = grow_significant(xi, Gram.from_rows(theta, y[:, None]), np.ones(1), names, ["s"])
    assert list(np.flatnonzero(out[0])) == [1, 3] and "in place of 'u1', 'u2'" in notes[0]


def test_one_warning_names_every_twin_the_data_cannot_tell_from_a_kept_term():
    from identification.fit import Gram
    from identification.support import indistinguishable_twins

    rng = np.random.default_rng(4)
    a, b, d1, d2 = rng.normal(size=(4, 4000))
    theta = np.column_stack([a, b, b + 1e-3 * d1, b + 1e-3 * d2])
    names = ["a", "b", "cos(phi) b", "sin(phi) b"]
    y = 2 * a + b + 0.05 * rng.normal(size=4000)
    xi = np.array([[2.0, 1.0, 0.0, 0.0]])
    notes, covered = indistinguishable_twins(xi, Gram.from_rows(theta, y[:, None]), names,
                                             ["s"], 1)  # fmt: skip
    assert len(notes) == 1 and covered == {(0, 1, 2), (0, 1, 3)}
    assert notes[0].startswith("s': kept 'b'; its nearly collinear twins")
    assert "'b cos(phi)' (" in notes[0] and "'b sin(phi)' (" in notes[0]


def test_centred_restart_replaces_a_support_built_around_a_cancelling_pair():
    """Thrust and gravity: `u1` and `cos(a)` both far from zero, the target their difference.
    A support that builds the difference from yaw-modulated columns (what the greedy path did
    on a held-out 6-DOF trial) is replaced by the true pair; the true support, and exact
    clean data (round-off residuals), are left alone."""
    from identification.fit import Gram
    from identification.support import restart_centred

    rng = np.random.default_rng(0)
    n = 3000
    t = np.arange(n) * 0.01
    psi = 0.8 * np.sin(0.3 * t) + 0.5
    c = np.cos(0.25 * np.sin(1.3 * t) * np.cos(0.7 * t))
    u1 = 15 + 1.5 * np.sin(2.1 * t) + 0.3 * np.sin(5.3 * t)
    cols = {"1": np.ones(n), "u1": u1, "cos(a)": c, "cos(b) u1": np.cos(psi) * u1,
            "sin(b) u1": np.sin(psi) * u1, "cos(a) cos(b)": np.cos(psi) * c,
            "cos(a) sin(b)": np.sin(psi) * c, "cos(b)": np.cos(psi),
            "sin(b)": np.sin(psi)}  # fmt: skip
    names = list(cols)
    theta = np.column_stack(list(cols.values()))
    exact = u1 / 1.5 - 9.81 * c
    for noise in (1e-2, 0.0):
        gram = Gram.from_rows(theta, (exact + noise * rng.normal(size=n))[:, None])
        wrong = np.zeros((1, len(names)))
        wrong[0, 3:9] = np.linalg.lstsq(theta[:, 3:9], exact, rcond=None)[0]
        xi, notes = restart_centred(wrong, gram, np.ones(1), names, ["w"])
        assert list(np.flatnonzero(xi[0])) == [1, 2], noise
        np.testing.assert_allclose(xi[0, [1, 2]], [1 / 1.5, -9.81], rtol=1e-3)
        assert "centred columns" in notes[0] and "in place of the path" in notes[0]
        right = np.zeros((1, len(names)))
        right[0, [1, 2]] = [1 / 1.5, -9.81]
        same, notes = restart_centred(right, gram, np.ones(1), names, ["w"])
        assert np.array_equal(same, right) and notes == []


def test_an_equation_left_empty_is_filled_by_the_centred_path_only_past_the_threshold():
    """Hover: ``w' = u1 / m - g`` with u1 near m g, so neither the constant nor u1 gains
    anything alone and the greedy path leaves the equation empty. The centred path fills it
    with the true pair where its first entry passes the chosen threshold; a threshold above
    that entry's share, a pure-noise target and no ``fill`` leave it empty."""
    from identification.fit import Gram
    from identification.support import restart_centred

    rng = np.random.default_rng(1)
    n = 3000
    t = np.arange(n) * 0.01
    u1 = 1.3 * 9.81 * (1 + 0.05 * np.sin(1.7 * t) + 0.02 * rng.normal(size=n))
    cols = {"1": np.ones(n), "u1": u1, "z": np.sin(0.4 * t), "z_dot": np.cos(0.9 * t),
            "phi": 0.1 * np.sin(2.3 * t)}  # fmt: skip
    names = list(cols)
    theta = np.column_stack(list(cols.values()))
    exact = u1 / 1.3 - 9.81
    one = lambda i, row: 1.0  # noqa: E731  (white residuals)
    gram = Gram.from_rows(theta, (exact + 0.3 * rng.normal(size=n))[:, None])  # share ~0.75
    empty = np.zeros((1, len(names)))
    xi, notes = restart_centred(empty, gram, np.ones(1), names, ["w"], (0.3, one))
    assert list(np.flatnonzero(xi[0])) == [0, 1]
    np.testing.assert_allclose(xi[0, :2], [-9.81, 1 / 1.3], rtol=3e-2)
    assert "left it empty" in notes[0] and "'1', 'u1'" in notes[0]
    for fill in ((0.95, one), None):  # above the first entry's share of the target; no fill
        same, notes = restart_centred(empty, gram, np.ones(1), names, ["w"], fill)
        assert not np.any(same) and notes == []
    noise = Gram.from_rows(theta, rng.normal(size=(n, 1)))
    same, notes = restart_centred(empty, noise, np.ones(1), names, ["w"], (1e-3, one))
    assert not np.any(same) and notes == []


def test_exchange_and_add_replaces_a_stand_in_that_holds_two_true_terms(monkeypatch):
    """`a` stands in for the true `b` and the small `c` together (the best single column, and
    neither exchanging it for `b` nor adding `c` alone gains enough); one exchange plus one
    addition reaches the exact pair. With the growth's pool cut to the chosen terms, only
    that move can find it."""
    import identification.support as support
    from identification.fit import Gram

    rng = np.random.default_rng(0)
    n = 4000
    b, c, hidden = rng.normal(size=(3, n))
    c *= 0.3
    theta = np.column_stack([b + c + 0.25 * hidden, b, c, rng.normal(size=(n, 8))])
    names = ["a", "b", "c", *(f"n{k}" for k in range(8))]
    gram = Gram.from_rows(theta, (b + c + 0.05 * rng.normal(size=n))[:, None])
    unit = gram.r / gram.col_norms
    free = np.ones(len(names), dtype=bool)
    none = np.zeros((len(names), len(names)), dtype=bool)
    assert support.exchange_and_add(unit, gram.z[:, 0], [0], free, none)[1] == (1, 2)
    monkeypatch.setattr(support, "GROW_POOL", 0)
    start = np.zeros((1, len(names)))
    start[0, 0] = 1.0
    xi, notes = support.grow_significant(start, gram, np.ones(1), names, ["s"])
    assert list(np.flatnonzero(xi[0])) == [1, 2]
    np.testing.assert_allclose(xi[0, [1, 2]], [1.0, 1.0], rtol=5e-3)
    assert "holds 'b', 'c' in place of 'a'" in notes[0]


def test_a_grown_term_that_fits_the_noise_bias_is_dropped_and_a_real_one_kept(other_clean):
    """State noise biases a short window's fit (errors in variables): `sin(phi)` in `phi'`
    took -0.077 at window 1 on 100 noisy flights and the growth kept it. Its coefficient
    collapses at a wider window; a real term the growth added (`u2` in `phi_dot'`) keeps its."""
    from identification.experiments.truth import truth_matrix
    from identification.fit import Gram, grams
    from identification.support import drop_window_bias, refit_support

    noisy = add_noise(other_clean, 1e-2, seed=3)
    names = planar_library()
    path = truth_matrix(truth_planar(OTHER_PLANAR), PS, names)
    gram = Gram.stack(grams(noisy, names, "rk4", 1, path))
    phi, j = PS.index("phi"), names.index("sin(phi)")
    grown = path.copy()
    grown[phi] = refit_support(gram, phi, [*np.flatnonzero(path[phi]), j])
    assert grown[phi, j] < -0.01  # the bias at window 1
    xi, notes = drop_window_bias(grown, path, gram, noisy, names, 4, PS, 1)
    assert xi[phi, j] == 0 and "dropped 'sin(phi)', which the growth added" in notes[0]
    rate, u2 = PS.index("phi_dot"), names.index("u2")
    without = path.copy()
    without[rate, u2] = 0.0
    xi, notes = drop_window_bias(path, without, gram, noisy, names, 4, PS, 1)
    assert xi[rate, u2] != 0 and notes == []


def test_near_twin_rotor_terms_both_enter_and_a_cancelling_or_noise_twin_does_not(monkeypatch):
    """Per-rotor thrusts make `f1 sin(phi)` and `f2 sin(phi)` near twins (|cos| > 0.998 here)
    that both belong in `y_dot'`. A trial's clean log with a noisy battery voltage taken for
    a state (its noise lifts the chosen threshold) kept one rotor with twice the coefficient:
    the growth never puts two columns above |cos| 0.999 together. Reinforcing twins are added
    where the data need them; a cancelling pair, a twin that only fits noise, or one that is a
    small correction of its partner (2 %, yet significant) is not."""
    import identification.support as support
    from identification.experiments.synthetic import FlightSpec, planar_flights
    from identification.selection import select_model

    rng = np.random.default_rng(0)
    data = []
    for tr in planar_flights(OTHER_PLANAR, FlightSpec(flights=3, steps=600)):
        u1, u2 = tr.u[:, 0], tr.u[:, 1] / OTHER_PLANAR.arm_length
        volts = 12.6 - 0.05 * tr.t + 0.01 * rng.standard_normal(len(tr))
        data.append(Trajectory(tr.t, np.column_stack([tr.x, volts]),
                               np.column_stack([(u1 - u2) / 2, (u1 + u2) / 2]),
                               [*tr.state_names, "volts"], ["f1", "f2"]))  # fmt: skip

    def y_dot(model):
        row = model.coefficients[model.state_names.index("y_dot")]
        return {model.feature_names[j]: row[j] for j in np.flatnonzero(row)}

    with pytest.warns(UserWarning):
        model, _ = select_model(data, "degree=1;angles=phi", n_models=0)
    rate = 1 / OTHER_PLANAR.mass
    assert y_dot(model) == pytest.approx({"f1 sin(phi)": -rate, "f2 sin(phi)": -rate}, rel=1e-6)
    monkeypatch.setattr(support, "add_reinforcing_twins", lambda a, b, s, *_: list(s))
    with pytest.warns(UserWarning):
        without, _ = select_model(data, "degree=1;angles=phi", n_models=0)
    assert len(y_dot(without)) == 1  # one rotor for two: what the twins' step undoes
    monkeypatch.undo()

    n = 4000
    s = rng.standard_normal(n)
    cols = np.column_stack([s, s + 0.03 * rng.standard_normal(n), rng.standard_normal(n)])
    a = cols / np.linalg.norm(cols, axis=0)
    twin = np.abs(a.T @ a) > 0.999
    np.fill_diagonal(twin, False)
    assert twin[0, 1]
    usable = np.ones(3, dtype=bool)
    noise = 0.01 * rng.standard_normal(n)
    bar = support.significance_bar(3)
    for b, added in ((a[:, 0] + a[:, 1] + noise, [0, 1]),  # reinforcing and needed
                     (40 * (a[:, 0] - a[:, 1]) + noise, [0]),  # needed but cancelling
                     (a[:, 0] + noise, [0]),  # noise only
                     (a[:, 0] + 0.02 * a[:, 1] + 1e-4 * noise, [0])):  # small  # fmt: skip
        total = float(b @ b)
        assert support.add_reinforcing_twins(a, b, [0], usable, twin, bar, total, n) == added


def test_one_rotor_for_two_is_named_where_the_data_cannot_split_the_pair():
    """PD flights with per-rotor thrusts (f1 ~ f2): `f1 sin(phi)` and `f2 sin(phi)` are near
    twins that both belong in `y_dot'`. At sigma = 1e-2 the fit keeps one rotor with twice the
    coefficient (the twin's entry is under the bar for a term), and no warning named the pair
    (the twin rule only took pairs where one term is the other times more factors). Now a
    warning names both where the data cannot tell the kept term alone from the two sharing
    its weight; a twin the data rule out is not named."""
    from identification.experiments.synthetic import FlightSpec, add_noise, planar_flights
    from identification.fit import Gram
    from identification.selection import select_model
    from identification.support import unsplit_twins

    data = []
    spec = FlightSpec(flights=4, steps=600, excitation=0.0, seed=2)
    for tr in add_noise(planar_flights(OTHER_PLANAR, spec), 1e-2, 2):
        u1, u2 = tr.u[:, 0], tr.u[:, 1] / OTHER_PLANAR.arm_length
        data.append(Trajectory(tr.t, tr.x, np.column_stack([(u1 - u2) / 2, (u1 + u2) / 2]),
                               tr.state_names, ["f1", "f2"]))  # fmt: skip
    with pytest.warns(UserWarning):
        model, report = select_model(data, "degree=2;angles=phi", n_models=0)
    row = model.coefficients[model.state_names.index("y_dot")]
    kept = {model.feature_names[j] for j in np.flatnonzero(row)}
    rotors = {"f1 sin(phi)", "f2 sin(phi)"}
    assert kept & rotors
    if not rotors <= kept:  # one rotor for two: a warning must name the pair
        named = [w for w in report.warnings if w.startswith("y_dot'")
                 and all(f"'{t}'" in w for t in rotors)]  # fmt: skip
        assert len(named) == 1 and "sharing its weight" in named[0]

    # the same pair in isolation: named where the noise hides the split, not where it shows
    rng = np.random.default_rng(0)
    n = 4000
    s = rng.standard_normal(n)
    theta = np.column_stack([s, s + 0.03 * rng.standard_normal(n)])
    names = ["f1 sin(phi)", "f2 sin(phi)"]
    xi = np.array([[-2.0, 0.0]])
    for sigma, warned in ((1.0, True), (0.02, False)):
        y = -(theta[:, 0] + theta[:, 1]) if warned else -2.0 * theta[:, 0]
        y = y + sigma * rng.standard_normal(n)
        gram = Gram.from_rows(theta, y[:, None])
        notes = unsplit_twins(xi, gram, np.ones(1), names, ["s"])
        assert len(notes) == int(warned)
    # a pair where one term is the other times more factors is the simpler-twin rule's
    notes = unsplit_twins(xi, gram, np.ones(1), ["u1", "cos(phi) u1"], ["s"])
    assert notes == []


def test_a_twin_kept_out_by_the_ratio_of_the_residual_without_it_is_measured_by_its_own():
    """The long-run ratio is measured on the path's residual; where that lacks a true twin,
    its smooth signal inflates the ratio (a trial's one-rotor residual: 51.7 against the
    pair's 10.3) and the raised bar kept the twin out. The pair's own ratio admits it, and
    the pruning after gets that ratio."""
    from identification.fit import Gram
    from identification.support import grow_significant

    rng = np.random.default_rng(0)
    n = 4000
    s = rng.standard_normal(n)
    theta = np.column_stack([s, s + 0.03 * rng.standard_normal(n)])
    y = -(theta[:, 0] + theta[:, 1]) + 0.2 * rng.standard_normal(n)
    gram = Gram.from_rows(theta, y[:, None])
    names = ["f1 sin(phi)", "f2 sin(phi)"]
    start = np.array([[-2.0, 0.0]])
    ratio = np.array([20.0])  # the one-term residual's, inflated by the missing twin
    xi, _ = grow_significant(start.copy(), gram, ratio, names, ["s"])
    assert np.count_nonzero(xi) == 1 and ratio[0] == 20.0  # the raised bar keeps it out
    asked = []
    xi, _ = grow_significant(start.copy(), gram, ratio, names, ["s"],
                             lambda i, row: asked.append(row) or 1.0)  # fmt: skip
    assert np.all(xi != 0) and np.allclose(xi, -1.0, atol=0.15) and ratio[0] == 1.0
    assert len(asked) == 1 and np.all(asked[0] != 0)  # asked once, for the pair


def test_the_growth_wald_test_is_a_chi_square_where_wide_windows_make_columns_smooth():
    """Under the truth, the statistic of a term the truth lacks (``u2`` in ``z'``) over 200
    noise draws: at window 64 the RK4 rows' column and residual are both smooth, and the
    residual-variance statistic averages 1.44 (a chi-square(1) averages 1; it passed a
    growth bar on 3 of 46 low-excitation trials). The Wald test with the residual's
    autocovariance against the column's lagged products averages 1 and exceeds its 5 % point
    on about 5 % of the draws."""
    from identification.experiments.synthetic import FlightSpec, planar_flights
    from identification.experiments.truth import truth_matrix
    from identification.fit import iter_rows
    from identification.support import wald_chi2

    names = planar_library()
    clean = planar_flights(OTHER_PLANAR, FlightSpec(seed=3, excitation=0.015))
    xi = truth_matrix(truth_planar(OTHER_PLANAR), PS, names)
    z_dot, u2 = names.index("z_dot"), names.index("u2")
    plain, score = [], []
    for seed in range(200):
        data = add_noise(clean, 3e-3, seed=seed)
        score.append(wald_chi2(data, names, xi, 64, 1, [z_dot], [z_dot, u2])[0])
        rows = [(theta[:, [z_dot, u2]], y[:, 1]) for _, theta, y in
                iter_rows(data, names, "rk4", 64, xi)]  # fmt: skip
        theta = np.concatenate([r[0] for r in rows])
        y = np.concatenate([r[1] for r in rows])
        base = theta[:, :1]
        e = y - base @ np.linalg.lstsq(base, y, rcond=None)[0]
        x = theta[:, 1] - base @ np.linalg.lstsq(base, theta[:, 1], rcond=None)[0]
        plain.append((x @ e) ** 2 / (x @ x) / (e @ e / (len(e) - 2)))
    plain, score = np.array(plain), np.array(score)
    assert plain.mean() > 1.3 and np.mean(plain > 3.84) > 0.08, plain.mean()
    assert score.mean() == pytest.approx(1.0, abs=0.2) and np.mean(score > 3.84) < 0.08
    assert wald_chi2(data, names, xi, 64, 1, [z_dot], [z_dot]) == (0.0, 0)
