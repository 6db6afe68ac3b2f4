import json
import pickle
import warnings

import numpy as np
import pytest
import torch

from identification.data import (
    IdentificationWarning,
    Trajectory,
    load_npz,
    read_csv,
    save_npz,
    write_trajectory_csv,
)
from identification.experiments.paper import fit_paper
from identification.experiments.truth import (
    compare_coefficients,
    model_from_truth,
    planar_truth,
    quad6dof_truth,
    truth_matrix,
)
from identification.features import compile_features, compile_rhs, parse_term, term_name
from identification.fit import FitConfig, fit
from identification.libraries import (
    generic_library,
    library_names,
    paper_planar_library,
    planar_library,
    quad6dof_library,
)
from identification.model import IdentifiedModel, load_model
from identification.rollouts import excitation_rollouts
from quad_envs.dynamics import (
    PLANAR_INPUT_NAMES as PI,
)
from quad_envs.dynamics import (
    PLANAR_STATE_NAMES as PS,
)
from quad_envs.dynamics import (
    QUAD6DOF_INPUT_NAMES,
    planar_rhs,
    quad6dof_rhs,
)
from quad_envs.dynamics import (
    QUAD6DOF_STATE_NAMES as QS,
)
from quad_envs.params import PAPER_6DOF, PAPER_PLANAR
from quad_envs.simulate import simulate_case

AUTHORS_COLUMNS = "t,y,z,phi,y_dot,z_dot,phi_dot,u1,u2,_,_,_,_,_,_".split(",")
warnings.filterwarnings("ignore", module="pysindy")


@pytest.fixture(scope="module")
def case_c():
    return Trajectory.from_run(simulate_case("C"))


# -- features ---------------------------------------------------------------------------
def test_feature_names_are_canonical():
    assert parse_term("u1 sin(1 phi)") == parse_term("sin(phi) u1")
    assert parse_term("y y") == parse_term("y^2")
    assert term_name(parse_term("1 cos(1 phi)")) == "cos(phi)"
    assert parse_term("sin(2 phi)") != parse_term("sin(phi)")
    with pytest.raises(ValueError, match="unknown variable"):
        parse_term("u9 sin(phi)", PS + PI)
    with pytest.raises(ValueError, match="cannot parse"):
        parse_term("exp(phi)")


def test_compiled_features_equal_pysindy_transform():
    """Our compiler evaluates pysindy's own feature names exactly as pysindy does."""
    lib = paper_planar_library()
    names = library_names(lib, PS, PI)
    data = np.random.default_rng(0).normal(size=(40, 8))
    ours = compile_features(names, PS, PI)(data[:, :6], data[:, 6:])
    np.testing.assert_allclose(ours, np.asarray(lib.transform(data)), rtol=1e-13, atol=1e-13)


def test_factors_streamed_in_two_threads_are_those_of_all_rows_at_once(monkeypatch):
    """grams() builds and factors chunks in worker threads: combined in chunk order, the
    factor is bit for bit the one-thread one, and R^T R is Theta^T Theta of every row."""
    import identification.fit as fit_module

    rng = np.random.default_rng(3)
    logs = [Trajectory(np.arange(n) * 0.01, 0.3 * rng.standard_normal((n, 6)),
                       rng.standard_normal((n, 2)), PS, PI) for n in (2600, 1700)]  # fmt: skip
    names = planar_library()
    xi = 0.01 * rng.standard_normal((len(PS), len(names)))
    monkeypatch.setattr(fit_module, "CHUNK_ELEMENTS", 1)  # chunks of 500 rows: 6 and 4
    two = fit_module.grams(logs, names, "rk4", 4, xi)
    monkeypatch.setattr(fit_module, "WORKERS", 1)
    one = fit_module.grams(logs, names, "rk4", 4, xi)
    assert all(np.array_equal(a.r_aug, b.r_aug) for a, b in zip(two, one, strict=True))
    for log, factor in zip(logs, two, strict=True):
        theta, y = fit_module.regression_rows([log], names, "rk4", 4, xi)
        rows = np.hstack([theta, y])
        assert factor.rows == len(rows) == len(log) - 4
        gram = rows.T @ rows
        assert np.abs(factor.r_aug.T @ factor.r_aug - gram).max() < 1e-12 * np.abs(gram).max()


def test_compiled_features_keep_the_batch_shape_and_windows_are_weighted_means():
    """Theta of one state, of rows and of a (2, 20) batch agree; the integral window's rows
    are the h-weighted means of w consecutive rows, computed here by a plain loop."""
    import identification.fit as fit_module

    rng = np.random.default_rng(4)
    names = planar_library()
    theta = compile_features(names, PS, PI)
    x, u = rng.standard_normal((40, 6)), rng.standard_normal((40, 2))
    rows = theta(x, u)
    assert rows.shape == (40, len(names))
    np.testing.assert_array_equal(theta(x[7], u[7]), rows[7])
    np.testing.assert_array_equal(theta(x.reshape(2, 20, 6), u.reshape(2, 20, 2)),
                                  rows.reshape(2, 20, -1))  # fmt: skip
    h, w = rng.uniform(0.5, 1.5, 40), 5
    loop = [np.average(rows[i : i + w], axis=0, weights=h[i : i + w]) for i in range(36)]
    np.testing.assert_allclose(fit_module._window_mean(rows.copy(), h, w), loop, rtol=1e-12)


def test_prewhitened_rows_are_the_plain_rows_quasi_differenced_across_chunks(monkeypatch):
    """meta["ar1"] = rho: row r becomes row r - rho row r-1 and the first row sqrt(1 - rho^2)
    times itself (Prais-Winsten), the same in chunks of 500 rows as in one; rows that touch a
    step without observed states go, as their plain rows do, and the row after them starts
    the chain anew, so the rows stay in step with the plain ones (a trial's log with re-sent
    rows failed where a note maps rows to steps)."""
    import dataclasses

    import identification.fit as fit_module

    rng = np.random.default_rng(6)
    names = planar_library()
    missing = np.zeros(1300, bool)
    missing[700] = True
    log = Trajectory(np.arange(1300) * 0.01, 0.3 * rng.standard_normal((1300, 6)),
                     rng.standard_normal((1300, 2)), PS, PI, missing=missing)  # fmt: skip
    xi = 0.01 * rng.standard_normal((len(PS), len(names)))
    rho = 0.9
    white = dataclasses.replace(log, meta={fit_module.AR1: rho})
    theta, y = fit_module.regression_rows([log.slice(0, 700)], names, "rk4", 1, xi)
    expect = np.vstack([np.sqrt(1 - rho**2) * theta[:1], theta[1:] - rho * theta[:-1]])
    monkeypatch.setattr(fit_module, "CHUNK_ELEMENTS", 1)  # chunks of 500 rows
    chunked, y_chunked = fit_module.regression_rows([white], names, "rk4", 1, xi)
    plain, _ = fit_module.regression_rows([log], names, "rk4", 1, xi)
    assert len(plain) == 1299 - 2 and len(chunked) == len(plain)
    np.testing.assert_allclose(chunked[:699], expect, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(chunked[699], np.sqrt(1 - rho**2) * plain[699], rtol=1e-12)
    np.testing.assert_allclose(chunked[700:], plain[700:] - rho * plain[699:-1], rtol=1e-12,
                               atol=1e-12)  # fmt: skip
    np.testing.assert_allclose(y_chunked[:699],
                               np.vstack([np.sqrt(1 - rho**2) * y[:1], y[1:] - rho * y[:-1]]),
                               rtol=1e-12, atol=1e-12)  # fmt: skip
    monkeypatch.setattr(fit_module, "CHUNK_ELEMENTS", 10**9)
    whole, _ = fit_module.regression_rows([white], names, "rk4", 1, xi)
    np.testing.assert_allclose(whole, chunked, rtol=1e-12, atol=1e-12)


def test_a_chunk_of_rows_holds_about_two_chunk_sized_arrays_at_its_peak(monkeypatch):
    """Memory of the streamed fit: building one chunk's RK4 rows of the 6-DOF library (four
    stages, the window means) and factoring them peaks near two arrays of the chunk's size,
    not four (temporaries freed as they go; tracemalloc sees numpy's allocations)."""
    import tracemalloc

    import identification.fit as fit_module
    from quad_envs.dynamics import QUAD6DOF_INPUT_NAMES, QUAD6DOF_STATE_NAMES

    rng = np.random.default_rng(5)
    names, n = quad6dof_library(), len(QUAD6DOF_STATE_NAMES)
    log = Trajectory(np.arange(2001) * 0.01, 0.2 * rng.standard_normal((2001, n)),
                     rng.standard_normal((2001, 4)), QUAD6DOF_STATE_NAMES,
                     QUAD6DOF_INPUT_NAMES)  # fmt: skip
    xi = np.zeros((n, len(names)))
    xi[np.arange(n), rng.choice(len(names), n)] = 0.01  # a quick compile; stages all move
    monkeypatch.setattr(fit_module, "WORKERS", 1)
    monkeypatch.setattr(fit_module, "CHUNK_ELEMENTS", 2000 * len(names))  # one chunk
    chunk = (2000 - 16) * (len(names) + n) * 8
    tracemalloc.start()
    try:
        fit_module.grams([log], names, "rk4", 16, xi)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 2.75 * chunk, peak / chunk  # 4.1 before the temporaries were freed


def test_truth_in_the_libraries_is_the_physics_and_torch_matches():
    rng = np.random.default_rng(1)
    for system, rhs, params, n, m in (
        ("planar", planar_rhs, PAPER_PLANAR, 6, 2),
        ("quad6dof", quad6dof_rhs, PAPER_6DOF, 12, 4),
    ):
        model = model_from_truth(system)
        x, u = rng.normal(size=(64, n)) * 0.4, rng.uniform(0, 1, size=(64, m))
        np.testing.assert_allclose(model.rhs(x, u), rhs(x, u, params), rtol=1e-12, atol=1e-9)
        f_t = model.torch_rhs()
        for dtype in (torch.float64, torch.float32):
            out = f_t(torch.tensor(x, dtype=dtype), torch.tensor(u, dtype=dtype))
            assert out.dtype == dtype
            np.testing.assert_allclose(
                out.numpy(),
                model.rhs(x, u),
                rtol=1e-4 if dtype == torch.float32 else 1e-12,
                atol=1e-3 if dtype == torch.float32 else 1e-9,
            )
    assert model_from_truth("planar").n_terms == 7 and model_from_truth("quad6dof").n_terms == 36


def test_truth_of_a_symmetric_vehicle_leaves_out_its_zero_terms():
    # Jxx = Jyy: no gyroscopic p q in r'; a zero "true" term would count as missed
    symmetric = PAPER_6DOF.replace(Jxx=2e-5, Jyy=2e-5, Jzz=3e-5)
    truth = quad6dof_truth(symmetric)
    assert "p q" not in truth["r"] and sum(len(t) for t in truth.values()) == 35
    assert all(c != 0 for terms in truth.values() for c in terms.values())
    x, u = np.random.default_rng(2).normal(size=(32, 12)) * 0.4, np.ones((32, 4))
    names = sorted({f for terms in truth.values() for f in terms})
    xi = truth_matrix(truth, QS, names)
    model = IdentifiedModel(names, xi, QS, QUAD6DOF_INPUT_NAMES)
    np.testing.assert_allclose(model.rhs(x, u), quad6dof_rhs(x, u, symmetric), atol=1e-9)


# -- data -------------------------------------------------------------------------------
def test_authors_file_loads_with_columns(reference_case_c, tmp_path):
    from tests.conftest import REFERENCE_CSV

    tr = read_csv(REFERENCE_CSV, AUTHORS_COLUMNS)
    assert tr.x.shape == (1001, 6) and tr.u.shape == (1001, 2) and tr.dt == pytest.approx(0.01)
    np.testing.assert_array_equal(tr.x, reference_case_c[:, 1:7])
    path = write_trajectory_csv(tmp_path / "c.csv", tr)
    again = read_csv(path)  # with its header now
    np.testing.assert_array_equal(again.x, tr.x)
    save_npz(tmp_path / "c.npz", [tr, again])
    both = load_npz(tmp_path / "c.npz")
    assert len(both) == 2 and both[1].state_names == PS


@pytest.mark.parametrize(
    "mutate,message",
    [
        (
            lambda t, x, u: (t, np.where(np.arange(x.size).reshape(x.shape) == 7, np.nan, x), u),
            "NaN",
        ),
        (lambda t, x, u: (t, x[:-1], u), "mismatched lengths"),
        (lambda t, x, u: (t[::-1], x, u), "increasing"),
        (lambda t, x, u: (np.concatenate([t[:5], t[4:-1]]), x, u), "strictly increasing"),
        (lambda t, x, u: (t, x[:, :5], u), "columns"),
        # an API trial's: values numpy would have turned into floats, or kept as huge ones
        (lambda t, x, u: (t, x + 0j, u), "x holds complex numbers"),
        (lambda t, x, u: (t, x, u > 0), "u holds booleans"),
        (lambda t, x, u: (t, x.astype(str), u), "x holds text"),
        (lambda t, x, u: (t, np.where(x == x[9, 1], 1e200, x), u), "1e\\+200 at sample 9 \\(z\\)"),
        (lambda t, x, u: (t, x[:, 0], u), "x must be 2-D .* 6 columns"),
    ],
)
def test_bad_data_raises_clear_errors(case_c, mutate, message):
    t, x, u = mutate(case_c.t + 1.0, case_c.x, case_c.u)
    with pytest.raises(ValueError, match=message):
        Trajectory(t, x, u, PS, PI)


@pytest.mark.parametrize(
    "states,message",
    [
        ("yz", "a sequence of names, got the string 'yz'"),
        (["1", "z"], r"\['1'\] cannot name variables"),  # the constant term's name
        (["y pos", "z"], "cannot name variables"),
        ([3, "z"], r"\[3\] cannot name variables"),
        (None, "got None"),
    ],
)
def test_names_that_cannot_name_variables_are_refused_when_the_trajectory_is_built(states, message):
    t = np.arange(5) * 0.1
    with pytest.raises(ValueError, match=message):
        Trajectory(t, np.ones((5, 2)), np.ones((5, 1)), states, ["u1"])


def test_one_variable_may_be_a_plain_sequence_and_no_inputs_may_be_none():
    t = np.arange(5) * 0.1
    one = Trajectory(t, np.ones((5, 2)), [1.0, 2.0, 3.0, 4.0, 5.0], ["a", "b"], ["f"])
    assert one.u.shape == (5, 1) and one.u[3, 0] == 4.0
    for none in (None, []):
        free = Trajectory(t, np.ones(5), none, ["a"], [])
        assert free.x.shape == (5, 1) and free.u.shape == (5, 0)
    with pytest.raises(ValueError, match="u holds booleans"):
        Trajectory(t, np.ones((5, 2)), np.array([np.bool_(True)] * 5, dtype=object), ["a", "b"],
                   ["f"])  # fmt: skip
    with pytest.raises(ValueError, match="u is None"):
        Trajectory(t, np.ones((5, 2)), None, ["a", "b"], ["f"])


def test_every_name_the_package_exports_resolves():
    """An API trial: identification.held_out_errors raised AttributeError (wrong module)."""
    import identification

    for name in identification.__all__:
        assert getattr(identification, name) is not None, name


def test_jittery_time_is_accepted_and_each_row_uses_its_own_step(case_c):
    """Non-uniform stamps are data, not an error: the RK4 rows use each row's own step."""
    tr = Trajectory(case_c.t**1.01, case_c.x, case_c.u, PS, PI)
    assert not tr.uniform and tr.steps.max() > tr.steps.min() * 1.01


def test_unknown_columns_and_missing_header(tmp_path):
    path = tmp_path / "x.csv"
    path.write_text("0,1,2\n1,2,3\n2,3,4\n")
    with pytest.raises(ValueError, match="no header"):
        read_csv(path)
    # a preset's names missing: the columns it does not know are named as the likely cause
    with pytest.raises(ValueError, match=r"no column\(s\) \['z', .*the columns \['banana'\] "
                       "are not its names: rename them with --columns"):  # fmt: skip
        read_csv(path, ["t", "y", "banana"], system="planar")


def test_rollouts_record_applied_inputs():
    trajs = excitation_rollouts("PlanarQuad-v0", episodes=2, seed=0, steps=200)
    assert len(trajs) == 2 and all(len(t) == 200 for t in trajs)
    f1 = 0.5 * (trajs[0].u[:, 0] - trajs[0].u[:, 1] / PAPER_PLANAR.arm_length)
    assert f1.min() >= -1e-12 and f1.max() <= PAPER_PLANAR.rotor_force_max + 1e-12
    # applied inputs reproduce the recorded states through the truth
    model = model_from_truth("planar")
    states = model.simulate(trajs[0].x[0], trajs[0].u[:-1], trajs[0].dt)
    np.testing.assert_allclose(states, trajs[0].x, atol=1e-9)


@pytest.mark.parametrize("env_kwargs", [{"action_mode": "rotor_thrusts"},
                                        {"normalize_actions": True}])  # fmt: skip
def test_excitation_rollouts_fly_every_action_mode_as_the_collective_one(env_kwargs):
    """The controller's collective command goes through the env's action mapping (a trial's
    rotor-thrust and normalised flights fell after 8 to 112 rows, exit 0): without noise
    the flights are the collective mode's, input for input."""
    base = excitation_rollouts("PlanarQuad-v0", episodes=1, seed=3, steps=300, noise=0.0)
    other = excitation_rollouts("PlanarQuad-v0", episodes=1, seed=3, steps=300, noise=0.0,
                                env_kwargs=env_kwargs)  # fmt: skip
    assert len(other[0]) == len(base[0]) == 300
    np.testing.assert_allclose(other[0].u, base[0].u, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(other[0].x, base[0].x, rtol=1e-4, atol=1e-5)


def test_excitation_flights_that_end_early_are_named():
    """A Pelican's third flight with 5 % excitation leaves the flight volume after 90 rows
    (the waypoints command tilts of several radians); before, the user got two long
    flights and one short one with no word. The short flight is kept (it is data) and
    named; with the commanded tilt limited the flights run their length, and flights that
    all run their length are not named."""
    ended = r"1 of 3 flight\(s\) ended early.*after 90 rows"
    with pytest.warns(IdentificationWarning, match=ended):
        trajs = excitation_rollouts("Quad6DOF-v0", episodes=3, seed=0, noise=0.05,
                                    env_kwargs={"vehicle": "pelican"})  # fmt: skip
    assert [len(t) for t in trajs] == [1000, 1000, 90]
    with warnings.catch_warnings():  # the tilt it is commanded limited, it stays up
        warnings.simplefilter("error", IdentificationWarning)
        held = excitation_rollouts("Quad6DOF-v0", episodes=3, seed=0, noise=0.05,
                                   env_kwargs={"vehicle": "pelican"}, max_tilt=0.6)  # fmt: skip
    assert [len(t) for t in held] == [1000] * 3
    assert max(float(np.abs(t.x[:, 3:5]).max()) for t in held) < 0.8
    with warnings.catch_warnings():
        warnings.simplefilter("error", IdentificationWarning)
        assert all(len(t) == 200 for t in excitation_rollouts("PlanarQuad-v0", 2, steps=200))


def test_simulate_takes_each_rows_own_step():
    """A log's jittery steps: step k lasts dt[k] (a fixed step only, before)."""
    model = model_from_truth("planar")
    rng = np.random.default_rng(0)
    u = PAPER_PLANAR.mass * 9.81 * np.array([1.0, 0.0]) + rng.normal(0, 0.05, size=(40, 2))
    x0 = np.array([0.0, 1.0, 0.05, 0.1, 0.0, 0.2])
    steps = 0.01 * (1 + 0.3 * rng.uniform(-1, 1, size=40))
    whole = model.simulate(x0, u, steps)
    # the same as stepping row by row, each with its own step
    x = x0
    for k in range(40):
        x = model.simulate(x, u[k : k + 1], steps[k])[-1]
        np.testing.assert_allclose(whole[k + 1], x, rtol=0, atol=1e-14)
    np.testing.assert_array_equal(model.simulate(x0, u, np.full(40, 0.01)),
                                  model.simulate(x0, u, 0.01))  # fmt: skip
    with pytest.raises(ValueError, match="one per input row"):
        model.simulate(x0, u, steps[:-1])


# -- fitting ----------------------------------------------------------------------------
def _check(model, truth, names, rel):
    comp = compare_coefficients(model.coefficients, truth, names, model.feature_names)
    assert comp.exact_support, (comp.missed, comp.spurious)
    assert comp.max_rel_error < rel, comp.max_rel_error
    return comp


@pytest.mark.parametrize("optimizer", ["sr3", "stlsq", "ensemble"])
def test_ours_recovers_the_planar_model_exactly(case_c, optimizer):
    model = fit(
        [case_c], planar_library(), FitConfig(lam=1e-3, optimizer=optimizer, n_models=5), "planar"
    )
    _check(model, planar_truth(), PS, 1e-10)


def test_generic_library_holds_the_truth_and_recovers_it(case_c):
    lib = generic_library(PS, PI, angle_names=["phi"], degree=2, n_frequencies=2)
    assert len(lib) == len(set(lib)) and "sin(phi) u1" in lib and "phi" not in lib
    model = fit([case_c], lib, FitConfig(lam=1e-3), "planar")
    _check(model, planar_truth(), PS, 1e-8)


def test_ours_on_the_authors_file(reference_case_c):
    from tests.conftest import REFERENCE_CSV

    model = fit(
        [read_csv(REFERENCE_CSV, AUTHORS_COLUMNS)], planar_library(), FitConfig(lam=1e-3), "planar"
    )
    _check(model, planar_truth(), PS, 1e-4)


def test_paper_method_reproduces_the_published_coefficients(reference_case_c):
    from tests.conftest import REFERENCE_CSV

    model = fit_paper([read_csv(REFERENCE_CSV, AUTHORS_COLUMNS)])
    coef = {
        (s, term_name(parse_term(n))): model.coefficients[i, j]
        for i, s in enumerate(PS)
        for j, n in enumerate(model.feature_names)
        if model.coefficients[i, j]
    }
    assert coef[("phi", "cos(phi) phi_dot")] == pytest.approx(0.993, abs=5e-4)
    assert coef[("y_dot", "sin(phi) u1")] == pytest.approx(-5.549, abs=5e-4)
    assert coef[("z_dot", "1")] == pytest.approx(-9.811, abs=5e-4)
    assert coef[("z_dot", "cos(phi) u1")] == pytest.approx(5.556, abs=5e-4)
    assert coef[("phi_dot", "u2")] == pytest.approx(4000.0, abs=0.5)


def test_forward_and_central_differences_are_biased_on_zoh_data(case_c):
    for derivative in ("forward", "central"):
        model = fit(
            [case_c], planar_library(), FitConfig(derivative=derivative, lam=1e-3), "planar"
        )
        comp = compare_coefficients(model.coefficients, planar_truth(), PS, model.feature_names)
        assert not comp.exact_support or comp.max_rel_error > 1e-3


def test_noisy_data_with_the_integral_form():
    trajs = [Trajectory.from_run(simulate_case("C"))] + excitation_rollouts(
        "PlanarQuad-v0", episodes=4, seed=0
    )
    rng = np.random.default_rng(0)
    noisy = [
        Trajectory(t.t, t.x + 1e-3 * rng.standard_normal(t.x.shape), t.u, PS, PI) for t in trajs
    ]
    model = fit(noisy, planar_library(), FitConfig(lam=0.1, window=20), "planar")
    _check(model, planar_truth(), PS, 0.01)


def test_6dof_identification_from_env_rollouts():
    trajs = excitation_rollouts("Quad6DOF-v0", episodes=4, seed=0, steps=1000)
    model = fit(trajs, quad6dof_library(), FitConfig(lam=1e-3), "quad6dof")
    _check(model, quad6dof_truth(), QS, 1e-3)


# -- model files ------------------------------------------------------------------------
def test_model_round_trip_and_pickle(tmp_path, case_c):
    model = fit([case_c], planar_library(), FitConfig(lam=1e-3), "planar")
    model.rhs(case_c.x[:2], case_c.u[:2])  # compile
    path = model.save(tmp_path / "m.json")
    again = load_model(path)
    np.testing.assert_array_equal(again.coefficients, model.coefficients)
    np.testing.assert_array_equal(again.rhs(case_c.x, case_c.u), model.rhs(case_c.x, case_c.u))
    # the compiled straight-line rhs is the library times the coefficients
    np.testing.assert_allclose(
        model.rhs(case_c.x, case_c.u),
        model.theta(case_c.x, case_c.u) @ model.coefficients.T,
        rtol=1e-12,
        atol=1e-9,
    )
    clone = pickle.loads(pickle.dumps(model))
    np.testing.assert_array_equal(clone.rhs(case_c.x, case_c.u), model.rhs(case_c.x, case_c.u))
    assert "\\dot{\\phi}" in "\n".join(model.equations(latex=True))
    assert model.equations()[3] == "y_dot' = -5.556 sin(phi) u1"


@pytest.mark.parametrize(
    "edit,message",
    [
        (lambda d: "{not json", "malformed JSON"),
        (lambda d: json.dumps([1, 2]), "JSON object"),
        (lambda d: json.dumps({**d, "schema": "other"}), "not a model written by quad-sindy"),
        (lambda d: json.dumps({**d, "schema_version": 99}), "schema_version"),
        (lambda d: json.dumps({**d, "coefficients": d["coefficients"][:-1]}), "shape"),
        (
            lambda d: json.dumps({**d, "feature_names": ["banana"] + d["feature_names"][1:]}),
            "unknown variable",
        ),
        (
            lambda d: json.dumps({k: v for k, v in d.items() if k != "coefficients"}),
            "missing field",
        ),
        (lambda d: json.dumps({**d, "system": "quad6dof"}), "do not match"),
        (lambda d: "[" * 100_000 + "]" * 100_000, "nested too deeply"),
        (lambda d: json.dumps({**d, "feature_names": [1] + d["feature_names"][1:]}), "strings"),
        (lambda d: json.dumps({**d, "coefficient_std": [[0.0]]}), r"coefficient_std has shape"),
        (lambda d: json.dumps({**d, "meta": {"window": 10**9}}), "meta.window must be"),
        (lambda d: json.dumps({**d, "meta": {"measured_inputs": 5}}), "meta.measured_inputs"),
        (lambda d: json.dumps({**d, "meta": {"measured_inputs": ["v9"]}}), "some of the inputs"),
        (lambda d: json.dumps({**d, "meta": {"units": "ms"}}), "meta.units must be a JSON object"),
    ],
)
def test_malformed_model_files_get_clear_errors(tmp_path, edit, message):
    data = model_from_truth("planar").to_dict()
    path = tmp_path / "bad.json"
    path.write_text(edit(data))
    with pytest.raises(ValueError, match=message):
        load_model(path)
    with pytest.raises(FileNotFoundError):
        load_model(tmp_path / "missing.json")


def test_compiled_rhs_skips_zero_terms():
    xi = np.zeros((6, 24))
    f = compile_rhs(planar_library(), xi, PS, PI)
    assert "sin" not in f.source
    np.testing.assert_array_equal(f(np.ones((3, 6)), np.ones((3, 2))), 0)


def test_model_rejects_bad_shapes():
    with pytest.raises(ValueError, match="shape"):
        IdentifiedModel(["1", "y"], np.zeros((6, 3)), PS, PI)
    with pytest.raises(ValueError, match="NaN"):
        IdentifiedModel(["1"], np.full((6, 1), np.nan), PS, PI)


@pytest.mark.parametrize(
    "case,vehicle", [("C", "quad6dof"), ("random", "quad6dof"), ("C", "planar")]
)
def test_cleaning_keeps_every_row_of_clean_closed_loop_flights(case, vehicle):
    """Control kinks at reference corners are not outliers; a spike still is.

    (A kink from full rotor saturation, as at the start of case A, can still be flagged.)
    """
    from identification.data import clean

    run = simulate_case(case, vehicle)
    names = (run.vehicle.state_names, run.vehicle.input_names)
    segments, report = clean(run.t, run.states, run.applied, *names)
    assert report.outlier_rows == 0 and len(segments) == 1 and len(segments[0]) == len(run.t)
    spiked = run.states.copy()
    spiked[500, 0] += 10 * run.states[:, 0].std() + 1.0
    _, report = clean(run.t, spiked, run.applied, *names)
    assert report.outlier_rows == 1
