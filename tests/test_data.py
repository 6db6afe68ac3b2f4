"""Reading and cleaning logs (identification.data): formats, stamps, gaps, stale rows, units."""

import warnings

import numpy as np
import pytest
from typer.testing import CliRunner

from identification.data import (
    Trajectory,
    clean,
    load_data,
    write_trajectory_csv,
)
from identification.experiments.synthetic import (
    OTHER_PLANAR,
    check_support,
    planar_drag_rhs,
    rhs_error,
    truth_planar,
)
from identification.libraries import library_from_spec, planar_library
from identification.model import load_model
from identification.selection import select_model
from quad_envs.dynamics import PLANAR_INPUT_NAMES as PI
from quad_envs.dynamics import PLANAR_STATE_NAMES as PS
from quad_sindy.cli import app

FAST = {"windows": (1, 4), "n_models": 5}
"""Selection settings for tests that need a model, not the default windows' search."""


def test_logged_resolution_reads_decimals_float32_and_float64():
    from identification.data import logged_resolution

    v = 5.9 + 0.1 * np.random.default_rng(0).standard_normal(500)
    assert logged_resolution(np.round(v, 4)) == 1e-4
    assert logged_resolution(np.round(v * 100)) == 1.0  # integer counts (PWM)
    single = float(np.spacing(np.float32(v.max())))
    assert logged_resolution(v.astype(np.float32)) == single
    assert logged_resolution(np.round(v.astype(np.float32).astype(float), 10)) == single
    shortest = [float(np.format_float_positional(a, unique=True)) for a in v.astype(np.float32)]
    assert logged_resolution(np.array(shortest)) == single  # float32 written as short text
    assert logged_resolution(v) == np.spacing(np.abs(v).max())
    tiny = 1e-7 * v  # kN m of a 28 g vehicle: not integers because they round to 0
    assert logged_resolution(tiny) == np.spacing(np.abs(tiny).max())
    with warnings.catch_warnings():  # beyond float32 (a fuzzed stamp): no overflow warning
        warnings.simplefilter("error")
        assert 0 < logged_resolution(np.array([0.01, 0.02, 1e300])) < np.inf


def test_a_clock_that_never_runs_is_named(other_clean):
    """All stamps equal (a zeroed time column): refused as such, not as "no segment of at
    least 20 clean rows", which sent a judge looking for gaps."""
    tr = other_clean[0]
    with pytest.raises(ValueError, match=r"time stamps never increase \(every stamp is 0"):
        clean(np.zeros(len(tr)), tr.x, tr.u, tr.state_names, tr.input_names)


def test_clean_bridges_a_lost_sample_and_a_glitch_and_splits_at_gaps(other_clean):
    tr = other_clean[0]
    t, x = tr.t.copy(), tr.x.copy()
    x[100] = x[99]  # the logger re-sent a sample
    x[300, 2] += 0.5  # a glitch in phi
    t[450:] += 0.2  # a 0.2 s gap
    segs, report = clean(t, x, tr.u, PS, PI)
    assert (report.stale_rows, report.outlier_rows, report.gaps, report.bridged) == (1, 1, 1, 2)
    assert report.segments == len(segs) == 2 and report.rows_out == len(tr)
    assert all(np.all(np.diff(s.t) < 0.02) for s in segs)
    # the two rows keep their time and input, their states are marked missing
    assert np.flatnonzero(segs[0].missing).tolist() == [100, 300]
    assert np.array_equal(segs[0].u, tr.u[:450]) and segs[1].missing is None
    # without bridging, each lost row splits the log
    segs, report = clean(t, x, tr.u, PS, PI, bridge=0)
    assert report.segments == len(segs) == 4 and report.rows_out == len(tr) - 2


def test_a_log_that_lost_a_quarter_of_its_rows_still_gives_the_exact_model(other_clean):
    """A quarter of the rows re-sent by the logger (single rows, inputs and time fresh):
    split at each, nothing longer than 3 rows would be left; bridged, the lost states are
    predicted by the model being fitted, so the fit stays exact (the held input over a
    doubled step instead gave 10 wrong terms and an 11 % rhs error)."""
    rng = np.random.default_rng(0)
    segments = []
    for tr in other_clean:
        x = tr.x.copy()
        lost = rng.choice(np.arange(2, len(tr) - 1, 2), len(tr) // 4, replace=False)
        x[lost] = x[lost - 1]
        segs, report = clean(tr.t, x, tr.u, PS, PI)
        assert report.stale_rows == report.bridged == len(tr) // 4 and len(segs) == 1
        segments += segs
    model, _ = select_model(segments, planar_library(), **FAST)
    check = check_support(model, truth_planar(OTHER_PLANAR))
    assert check.exact_support, (check.missed, check.spurious)
    assert rhs_error(model, planar_drag_rhs(OTHER_PLANAR, 0.0), other_clean) < 1e-6


def test_a_run_of_resent_rows_inside_motion_is_stale_and_a_rest_is_not(other_clean):
    """20 rows re-sent by a stalled logger (time advancing) froze z_dot' to 0 before: a run
    entered while moving is dropped whole; identical rows entered at rest are an equilibrium."""
    tr = other_clean[0]
    x = tr.x.copy()
    x[301:321] = x[300]  # states frozen, time and inputs advance
    x[450] = np.nan
    segs, report = clean(tr.t, x, tr.u, PS, PI)
    assert (report.stale_rows, report.nonfinite_rows, report.bridged) == (20, 1, 1)
    assert report.rows_out == len(tr) - 20 and report.segments == 2
    assert all(not np.any(np.all(s.x[1:] == s.x[:-1], axis=1)) for s in segs)
    rest = tr.x.copy()
    rest[:40] = rest[0]  # on the ground before take-off: entered at rest (the log's start)
    segs, report = clean(tr.t, rest, tr.u, PS, PI)
    assert report.stale_rows == 0 and segs[0].t[0] == 0.0 and len(segs[0]) >= 40


def test_identify_drops_a_stalled_logger_run_and_finds_gravity(other_clean, tmp_path):
    paths = []
    for i, tr in enumerate(other_clean):
        x = tr.x.copy()
        if i == 0:
            x[301:321] = x[300]
        paths.append(
            str(write_trajectory_csv(tmp_path / f"f{i}.csv", Trajectory(tr.t, x, tr.u, PS, PI)))
        )
    out = tmp_path / "m.json"
    result = CliRunner().invoke(app, ["identify", *paths, "--out", str(out), "--system", "planar"])
    assert result.exit_code == 0, result.output
    assert "dropped 20 stale/repeated" in result.output
    check = check_support(load_model(out), truth_planar(OTHER_PLANAR))
    assert check.exact_support, (check.missed, check.spurious)


def test_a_wrapped_angle_is_unwrapped_and_reported(other_clean, tmp_path):
    """A logger wrapping phi to [-pi, pi] (here: 2 pi jumps at rows 200, 400 and 500): the
    jumps were bridged as outliers and every row after them left 2 pi off (a pendulum gave
    ``theta' = 0`` with exit 0). Declared angles are unwrapped; the repair is reported even
    though no row is lost, and stored in the model."""
    paths = []
    for i, tr in enumerate(other_clean):
        x = tr.x.copy()
        x[200:400, 2] += 2 * np.pi
        x[500:, 2] -= 2 * np.pi
        paths.append(
            str(write_trajectory_csv(tmp_path / f"f{i}.csv", Trajectory(tr.t, x, tr.u, PS, PI)))
        )
        segs, report = clean(tr.t, x, tr.u, PS, PI, angles=("phi",))
        assert report.unwrapped == 3 and report.outlier_rows == 0 and len(segs) == 1
        assert np.allclose(segs[0].x, tr.x, rtol=0, atol=1e-12)
    out = tmp_path / "m.json"
    result = CliRunner().invoke(app, ["identify", *paths, "--out", str(out), "--system", "planar",
                                      "--window", "4"])  # fmt: skip
    assert result.exit_code == 0, result.output
    assert "unwrapped 9 jump(s) of 2 pi" in result.output
    model = load_model(out)
    assert model.meta["data"]["unwrapped"] == 9 and model.meta["data"]["rows_out"] == 1800
    check = check_support(model, truth_planar(OTHER_PLANAR))
    assert check.exact_support, (check.missed, check.spurious)


def test_a_row_written_twice_is_removed_without_splitting_the_log(other_clean):
    tr = other_clean[0]
    keep = np.insert(np.arange(len(tr)), 300, 299)  # row 299 written twice
    segs, report = clean(tr.t[keep], tr.x[keep], tr.u[keep], PS, PI)
    assert (report.rows_in, report.stale_rows, report.segments) == (len(tr) + 1, 1, 1)
    assert np.array_equal(segs[0].t, tr.t) and segs[0].missing is None


def test_timestamps_and_npz_columns_are_read_exactly(other_clean, tmp_path):
    """Epoch timestamps kept their steps to 2.5e-5 relative only (float64 seconds since 1970);
    an NPZ file of named 1-D columns is a log like a CSV, and any other NPZ layout is refused
    naming the array that does not fit."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from identification.data import read_table

    tr = other_clean[0]
    ns = np.int64(1_764_000_000_000_000_000) + np.round(tr.t * 1e9).astype(np.int64)
    pq.write_table(pa.table({"stamp": pa.array(ns, pa.timestamp("ns")), "y": tr.x[:, 0]}),
                   tmp_path / "log.parquet")  # fmt: skip
    stamp = read_table(tmp_path / "log.parquet")["stamp"]
    assert stamp[0] == 0.0 and np.allclose(np.diff(stamp), np.diff(tr.t), rtol=1e-12, atol=0)
    columns = dict(zip(("t", *PS, *PI), np.column_stack([tr.t, tr.x, tr.u]).T, strict=True))
    np.savez(tmp_path / "log.npz", **columns)
    segs, _ = load_data([tmp_path / "log.npz"], system="planar")
    assert np.array_equal(segs[0].x, tr.x) and segs[0].input_names == PI
    # a parquet duration column (a fuzz trial's duration[ns] was read as seconds)
    since = pa.array(np.round(tr.t * 1e9).astype(np.int64), pa.duration("ns"))
    pq.write_table(pa.table({"t": since, **{n: columns[n] for n in (*PS, *PI)}}),
                   tmp_path / "dur.parquet")  # fmt: skip
    segs, _ = load_data([tmp_path / "dur.parquet"], system="planar")
    assert np.allclose(segs[0].t, tr.t - tr.t[0], rtol=0, atol=1e-9)
    np.savez(tmp_path / "matrix.npz", t=tr.t, X=tr.x, U=tr.u)
    with pytest.raises(ValueError, match="one 1-D array per column.*'X' has shape"):
        load_data([tmp_path / "matrix.npz"], system="planar")
    # a .npy under an .npz name and a truncated archive: one line each, no traceback
    np.save(tmp_path / "array.npy", tr.x)
    (tmp_path / "array.npz").write_bytes((tmp_path / "array.npy").read_bytes())
    with pytest.raises(ValueError, match="a single NumPy array, not an NPZ archive"):
        load_data([tmp_path / "array.npz"], system="planar")
    whole = (tmp_path / "log.npz").read_bytes()
    (tmp_path / "cut.npz").write_bytes(whole[: len(whole) // 2])
    with pytest.raises(ValueError, match="cut.npz: cannot read the NPZ file"):
        load_data([tmp_path / "cut.npz"], system="planar")


def test_a_measured_attitude_as_input_is_interpolated_within_the_step(other_clean, tmp_path):
    """The translational planar model with the logged attitude as an input (a new-user log):
    held over the step like a command, the tilt changing within it left a fake drag term
    (y_dot' = -0.032 y_dot - 1.9994 sin(phi) u1); declared measured, the RK4 stages see phi
    interpolated and the model is exact."""
    names, inputs = ("y", "z", "y_dot", "z_dot"), ("u1", "phi")
    library = library_from_spec("degree=1;angles=phi", names, inputs)

    def sub(tr: Trajectory, measured: tuple[str, ...]) -> Trajectory:
        u = np.column_stack([tr.u[:, 0], tr.x[:, 2]])
        return Trajectory(tr.t, tr.x[:, [0, 1, 3, 4]], u, names, inputs, measured=measured)

    plain, _ = select_model([sub(tr, ()) for tr in other_clean], library, **FAST,
                            prewhiten=False)  # fmt: skip
    assert plain.coefficients[2, plain.feature_names.index("y_dot")] != 0
    # the fake term's residual is correlated in time: the default's prewhitened fit (kept,
    # as sparse) has no fake drag, but only declaring the input measured makes it exact
    held, report = select_model([sub(tr, ()) for tr in other_clean], library, **FAST)
    assert report.ar1 > 0.9 and held.coefficients[2, held.feature_names.index("y_dot")] == 0
    paths = [
        str(write_trajectory_csv(tmp_path / f"f{i}.csv", sub(tr, ())))
        for i, tr in enumerate(other_clean)
    ]
    out = tmp_path / "m.json"
    args = ["identify", *paths, "--out", str(out), "--states", ",".join(names), "--inputs",
            "u1,phi", "--measured", "phi", "--library", "degree=1;angles=phi"]  # fmt: skip
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    assert "look like a logged attitude" not in result.output  # declared
    model = load_model(out)
    assert model.meta["measured_inputs"] == ["phi"]
    held_args = ["identify", *paths, "--out", str(tmp_path / "held.json"), "--states",
                 ",".join(names), "--inputs", "u1,phi", "--library", "degree=1;angles=phi",
                 "--lambda", "0.001"]  # fmt: skip
    hint = CliRunner().invoke(app, held_args)
    assert "note: input(s) phi look like a logged attitude" in hint.output
    g, inv_m = 9.81, 1.0 / OTHER_PLANAR.mass
    truth = {(0, "y_dot"): 1.0, (1, "z_dot"): 1.0, (2, "sin(phi) u1"): -inv_m,
             (3, "1"): -g, (3, "cos(phi) u1"): inv_m}  # fmt: skip
    found = {(i, model.feature_names[j]): model.coefficients[i, j]
             for i, j in zip(*np.nonzero(model.coefficients), strict=True)}  # fmt: skip
    assert set(found) == set(truth)
    assert all(abs(found[k] / truth[k] - 1) < 1e-5 for k in truth)
    # simulate interpolates the measured input as the fit did: 1 s ahead on the data,
    # 30 times closer than with the input held
    flight = sub(other_clean[0], ())
    err = np.abs(model.simulate(flight.x[0], flight.u[:100], flight.dt)[-1] - flight.x[100])
    model.meta.pop("measured_inputs")
    held = np.abs(model.simulate(flight.x[0], flight.u[:100], flight.dt)[-1] - flight.x[100])
    assert err.max() < 1e-4 and held.max() > 10 * err.max()  # 4.5e-5 m against 1.4e-3 m
    with pytest.raises(ValueError, match=r"measured input\(s\) \['u2'\] are not inputs"):
        sub(other_clean[0], ("u2",))


def test_stage_inputs_hold_commands_and_follow_a_measured_cubic_on_jittery_steps():
    rng = np.random.default_rng(1)
    t = np.cumsum(rng.uniform(0.008, 0.012, 40))
    cubic = 2.0 - t + 3.0 * t**2 - 5.0 * t**3
    tr = Trajectory(t, np.sin(t)[:, None], np.column_stack([cubic, cubic]), ("x",),
                    ("held", "signal"), measured=("signal",))  # fmt: skip
    rows = np.arange(len(t) - 1)
    u0, um, u1 = tr.stage_inputs(rows)
    mid = 0.5 * (t[:-1] + t[1:])
    assert np.array_equal(um[:, 0], cubic[:-1]) and np.array_equal(u1[:, 0], cubic[:-1])
    exact = 2.0 - mid + 3.0 * mid**2 - 5.0 * mid**3
    np.testing.assert_allclose(um[1:-1, 1], exact[1:-1], rtol=1e-12)  # cubic: exact inside
    assert np.array_equal(u1[:, 1], cubic[1:])
    plain = Trajectory(t, tr.x, tr.u, ("x",), ("held", "signal"))
    a, b, c = plain.stage_inputs(rows)
    assert a is b is c


def _csv_text(tr: Trajectory, delimiter: str = ",", header: list[str] | None = None) -> str:
    names = header or ["t", *PS, *PI]
    rows = np.column_stack([tr.t, tr.x, tr.u])
    lines = [delimiter.join(map(repr, r)) for r in rows.tolist()]
    return "\n".join([delimiter.join(names), *lines])


@pytest.mark.parametrize(
    "variant",
    ["bom", "quoted", "semicolon", "tab", "spaces", "typeset_minus", "empty_cells",
     "overflowing", "text_column", "iso_time"],
)  # fmt: skip
def test_common_csv_forms_are_read_as_written(other_clean, tmp_path, variant):
    """Forms a new user's real logs came in, each refused before: Excel's byte-order mark,
    a quoted header, ';' or tab delimiters, empty cells (pandas' NaN), an unused text column,
    ISO timestamps; a cell of 1e300 (a fuzz trial's: overflow warnings, then a refusal as
    collinear) is a lost value like an empty cell; single spaces as the delimiter and
    typeset minus signs (a fuzz trial's: refused, and six columns left out as text)."""
    tr = other_clean[0]
    text = _csv_text(tr, {"semicolon": ";", "tab": "\t", "spaces": " "}.get(variant, ","))
    lines = text.split("\n")
    if variant == "typeset_minus":  # U+2212, as a spreadsheet may typeset it
        text = "\n".join([lines[0]] + [ln.replace("-", "\u2212") for ln in lines[1:]])
    elif variant == "bom":
        text = "\ufeff" + text
    elif variant == "quoted":
        text = "\n".join([",".join(f'"{c}"' for c in lines[0].split(","))] + lines[1:])
    elif variant in ("empty_cells", "overflowing"):
        cells = lines[101].split(",")
        cells[2] = "" if variant == "empty_cells" else "1e300"
        text = "\n".join(lines[:101] + [",".join(cells)] + lines[102:])
    elif variant == "text_column":
        text = "\n".join([lines[0] + ",mode"] + [ln + ",hover" for ln in lines[1:]])
    elif variant == "iso_time":
        stamps = np.datetime64("2026-11-25T10:00:00") + np.round(tr.t * 1e6).astype(
            "timedelta64[us]"
        )
        text = "\n".join(
            [lines[0]]
            + [f"{s}," + ln.split(",", 1)[1] for s, ln in zip(stamps, lines[1:], strict=True)]
        )
    path = tmp_path / "log.csv"
    path.write_text(text, encoding="utf-8")
    segs, report = load_data([path], system="planar")
    assert segs[0].state_names == PS and report.rows_out == len(tr)
    assert np.allclose(np.concatenate([s.t for s in segs])[:50], tr.t[:50], rtol=0, atol=1e-9)
    if variant in ("empty_cells", "overflowing"):  # a lost state: bridged
        assert (report.nonfinite_rows, report.bridged) == (1, 1)
    else:
        assert np.array_equal(segs[0].x, tr.x)


@pytest.mark.parametrize(
    "variant", ["text_cell", "decimal_comma", "unsorted", "half_rate_input", "extra_columns",
                "header_only", "empty_column", "mode_column", "input_dropouts", "clock_back",
                "input_random_loss", "newest_first", "junk_cells", "thousands", "units",
                "list_input", "shuffled", "label_digits"],
)  # fmt: skip
def test_real_log_pathologies_are_repaired_and_said_or_refused_by_name(
    other_clean, tmp_path, variant
):
    """What a trial's real-log exports did (each gave a wrong model with exit 0, a false
    refusal or a message that named the wrong thing): a '-' cell made a column text, left
    out without a word; decimal commas; rows written out of time order (dropped as stale);
    50 Hz commands beside 100 Hz states, every other input cell empty (refused); columns the
    preset does not name (refused); a header without rows; an empty column. And what an
    adversarial trial then found the first repairs doing wrong: a flight-mode column of
    codes and words read as a state; sporadic empty input cells held (a command that
    changes every row: wrong model); a clock set back 25 ms sorted into interleaved rows."""
    tr = other_clean[0]
    text = _csv_text(tr)
    lines = text.split("\n")
    if variant == "text_cell":
        cells = lines[301].split(",")
        cells[5] = "-"  # z_dot
        lines[301] = ",".join(cells)
    elif variant == "decimal_comma":
        lines = [lines[0].replace(",", ";")] + [
            ";".join(repr(v).replace(".", ",") for v in row)
            for row in np.column_stack([tr.t, tr.x, tr.u]).tolist()
        ]
    elif variant == "unsorted":
        lines[101], lines[102] = lines[102], lines[101]
    elif variant == "half_rate_input":
        for k in range(2, len(lines), 2):
            cells = lines[k].split(",")
            lines[k] = ",".join(cells[:-2] + ["", ""])
    elif variant == "extra_columns":
        lines = [lines[0] + ",armed,"] + [ln + ",1," for ln in lines[1:]]
    elif variant == "header_only":
        lines = lines[:1]
    elif variant == "empty_column":
        lines = [",".join(ln.split(",")[:6] + [""] + ln.split(",")[7:]) if k else ln
                 for k, ln in enumerate(lines)]  # fmt: skip
    elif variant == "mode_column":  # codes, and a word near the end
        lines = [lines[0] + ",mode"] + [ln + ("," + ("LAND" if k > 580 else str(1 + k // 200)))
                                        for k, ln in enumerate(lines[1:])]  # fmt: skip
    elif variant == "input_dropouts":
        for k in (101, 250, 377):
            cells = lines[k].split(",")
            lines[k] = ",".join(cells[:-2] + ["", cells[-1]])
    elif variant == "input_random_loss":  # a quarter of u1's cells lost at random: no rate
        rng = np.random.default_rng(0)
        for k in 1 + np.flatnonzero(rng.uniform(size=len(tr)) < 0.25):
            cells = lines[k].split(",")
            lines[k] = ",".join(cells[:-2] + ["", cells[-1]])
    elif variant == "newest_first":
        lines = [lines[0], *lines[:0:-1]]
    elif variant == "label_digits":  # labels with a digit are labels, not numbers with marks
        lines = [lines[0] + ",imu"] + [ln + f",IMU{k % 2}" for k, ln in enumerate(lines[1:])]
    elif variant == "shuffled":  # a fuzz trial's: read as appended logs, 119 of 600 rows kept
        order = np.random.default_rng(2).permutation(len(lines) - 1) + 1
        lines = [lines[0], *(lines[k] for k in order)]
    elif variant == "junk_cells":  # five 'x' in z_dot, read with no states named
        for k in (50, 150, 250, 350, 450):
            cells = lines[k].split(",")
            cells[5] = "x"
            lines[k] = ",".join(cells)
    elif variant in ("thousands", "units"):  # a fuzz trial's cells: the column was left out
        u1 = [f"{v * 1e3:,.3f}" if variant == "thousands" else f"{v}N" for v in tr.u[:, 0]]
        rows = np.column_stack([tr.t, tr.x]).tolist()
        lines = [lines[0].replace(",", ";")] + [
            ";".join([*map(repr, r), a, repr(b)]) for r, a, b in zip(rows, u1, tr.u[:, 1],
                                                                  strict=True)]  # fmt: skip
    elif variant == "clock_back":  # stamps set back 25 ms at row 300: the rows are in order
        lines = [lines[0]] + [f"{float(tr.t[k] - 0.025 * (k >= 300))!r},"
                              + ln.split(",", 1)[1] for k, ln in enumerate(lines[1:])]  # fmt: skip
    path = tmp_path / "log.csv"
    path.write_text("\n".join(lines), encoding="utf-8")
    refused = {"decimal_comma": r"column 't' holds numbers written with decimal commas "
                                r"\(e\.g\. '0,0'\)",
               "header_only": "has a header but no rows",
               "empty_column": r"column\(s\) \['phi_dot'\] hold no numbers",
               "junk_cells": r"column 'z_dot' holds numbers and 5 cell\(s\) of words "
                             r"\(e\.g\. 'x'\)"}  # fmt: skip
    refused["thousands"] = r"column 'u1' holds numbers written with thousands separators"
    refused["units"] = r"column 'u1' holds numbers in a form that is not read \(e\.g\. '\S+N'"
    refused["list_input"] = r"column 'u1' is not numeric \(of type list"
    if variant == "list_input":  # a parquet column of lists where u1 belongs
        import pyarrow as pa
        import pyarrow.parquet as pq

        columns = dict(zip(("t", *PS, "u2"), np.column_stack([tr.t, tr.x, tr.u[:, 1]]).T,
                           strict=True))  # fmt: skip
        columns["u1"] = pa.array([[v] for v in tr.u[:, 0]])
        path = tmp_path / "log.parquet"
        pq.write_table(pa.table(columns), path)
    if variant in refused:  # with no states named, as identify reads a log it is given
        auto = variant in ("junk_cells", "thousands", "units", "list_input")
        with pytest.raises(ValueError, match=refused[variant]):
            load_data([path], system=None if auto else "planar")
        return
    if variant == "mode_column":  # with no states named: a label or a state? Asked
        with pytest.raises(ValueError, match=r"column 'mode' holds numbers and 19 cell"):
            load_data([path])
    segs, report = load_data([path], system="planar")
    summary = report.summary()
    assert segs[0].state_names == PS and segs[0].input_names == PI
    if variant == "text_cell":  # the column kept, the cell missing (bridged)
        assert report.bridged == 1
        assert "1 cell(s) of column 'z_dot' that are not numbers ('-') read as missing" in summary
    elif variant == "unsorted":
        assert report.reordered == 2 and report.stale_rows == 0
        assert np.array_equal(segs[0].x, tr.x) and np.array_equal(segs[0].t, tr.t)
    elif variant == "half_rate_input":
        held = len(tr) // 2
        assert report.held_inputs == 2 * held and len(segs) == 1 and len(segs[0]) == len(tr)
        np.testing.assert_array_equal(segs[0].u[1::2], tr.u[0:-1:2])  # the row before's
    elif variant == "extra_columns":
        assert "column(s) ['armed', '(unnamed)'] are not the planar preset's" in summary
        assert np.array_equal(segs[0].x, tr.x)
    elif variant == "mode_column":  # categorical: text, not a state
        assert "text column 'mode' left out" in summary and report.rows_out == len(tr)
    elif variant == "label_digits":  # with no states named too
        _, auto = load_data([path])
        assert "text column 'imu' left out" in auto.summary()
    elif variant == "input_dropouts":  # lost samples, not a rate: the rows go
        assert report.held_inputs == 0 and report.nonfinite_rows == 3
    elif variant == "input_random_loss":  # a quarter, but not a rate: not held either
        assert report.held_inputs == 0 and report.nonfinite_rows > 100
    elif variant in ("newest_first", "shuffled"):  # dropping the rows behind would leave few
        assert report.reordered > 0.9 * len(tr) and np.array_equal(segs[0].x, tr.x)
    elif variant == "clock_back":  # not sorted: the rows stamped behind are dropped
        assert report.reordered == 0 and report.stale_rows == 2  # stamped before 2.99 s
        assert np.array_equal(np.concatenate([s.x for s in segs]),
                              np.delete(tr.x, [300, 301], axis=0))  # fmt: skip


def test_float32_time_stamps_are_read_as_the_regular_clock_they_round(other_clean, tmp_path):
    """Time stored as float32 at t = 1e4 s rounds every stamp to 1e-3 s; each row's own step
    then jittered 10 % and a trial got 12 terms for 7. Steps that vary only by the stamps'
    resolution are read as a regular grid, and the model is exact again."""
    paths = []
    for i, tr in enumerate(other_clean):
        stamps = (1e4 + tr.t).astype(np.float32).astype(np.float64)
        assert np.ptp(np.diff(stamps)) > 5e-4  # the rounding's jitter
        paths.append(write_trajectory_csv(tmp_path / f"f{i}.csv",
                                          Trajectory(stamps, tr.x, tr.u, PS, PI)))  # fmt: skip
    segs, report = load_data(paths, system="planar")
    assert report.regular == 3 and "as a regular grid" in report.summary()
    for seg in segs:
        assert np.ptp(np.diff(seg.t)) < 1e-9 and abs(np.median(np.diff(seg.t)) - 0.01) < 2e-6
    model, _ = select_model(segs, planar_library(), **FAST)
    assert check_support(model, truth_planar(OTHER_PLANAR)).exact_support
    # irregular steps stamped to 1 ms vary within a resolution here and there, but drift off
    # any regular line: kept (an adversarial trial's were read as a grid, 2.5 times worse)
    rng = np.random.default_rng(1)
    stamps = np.round(np.cumsum(rng.uniform(0.009, 0.011, 600)), 3)
    _, report = clean(stamps, other_clean[0].x, other_clean[0].u, PS, PI)
    assert report.regular == 0 and report.jitter > 0.05


def test_rows_the_logger_lost_split_the_log_and_a_jittery_clock_does_not(other_clean):
    """A clean log with 1 % of its rows deleted (a trial's: each lost row's input unknown,
    the logged one held over two periods; `phi_dot'` 9 % off, reported as 100 % jitter) is
    split at each lost row and the model is exact; +-20 % jitter and a logger of two rates
    split nothing. A log with
    every stamp written twice is refused naming the repeated stamps."""
    rng = np.random.default_rng(3)
    segs, lost = [], 0
    for tr in other_clean:
        keep = np.ones(len(tr), dtype=bool)
        keep[rng.choice(np.arange(5, len(tr) - 5), 6, replace=False)] = False
        parts, report = clean(tr.t[keep], tr.x[keep], tr.u[keep], PS, PI)
        segs += parts
        lost += report.skipped
        assert "row(s) the logger lost" in report.summary() and report.jitter < 1e-9
    assert lost == 18
    model, _ = select_model(segs, planar_library(), **FAST)
    check = check_support(model, truth_planar(OTHER_PLANAR))
    assert check.exact_support and check.max_rel_error < 1e-6
    tr = other_clean[0]
    twice = np.repeat(tr.t[::2], 2)[: len(tr)]  # every stamp written twice, the rows differ
    with pytest.raises(ValueError, match="rows stamped at or before the row before"):
        clean(twice, tr.x, tr.u, PS, PI)
    jittery = tr.t[0] + np.concatenate([[0.0], np.cumsum(rng.uniform(0.008, 0.012, len(tr) - 1))])
    parts, report = clean(jittery, tr.x, tr.u, PS, PI)
    assert len(parts) == 1 and report.skipped == 0
    # a logger of two rates (steps of 0.01 and 0.02 s in turn: a recheck trial's, refused as
    # rows lost): its rates, kept whole
    two_rates = tr.t[0] + np.concatenate([[0.0], np.cumsum(np.tile([0.01, 0.02], len(tr)))])
    parts, report = clean(two_rates[: len(tr)], tr.x, tr.u, PS, PI)
    assert len(parts) == 1 and report.skipped == 0 and len(parts[0]) == len(tr)


def test_time_unit_restarts_and_mixed_units_between_files(other_clean, tmp_path):
    tr = other_clean[0]
    ms = Trajectory(np.round(1_764_000_000_000 + tr.t * 1000), tr.x, tr.u, PS, PI)
    path = str(write_trajectory_csv(tmp_path / "ms.csv", ms))
    segs, _ = load_data([path], system="planar", time_unit=1e-3)
    assert np.allclose(segs[0].t, tr.t - tr.t[0], rtol=0, atol=1e-12)
    # one file in ms among files in s: refused, naming both (a model with no term before)
    good = str(write_trajectory_csv(tmp_path / "s.csv", other_clean[1]))
    with pytest.raises(ValueError, match=r"ms\.csv steps 10 per row but .*s\.csv steps 0\.01"):
        load_data([good, path], system="planar")
    # two flights appended in one file, the time starting again at 0: both kept (the second
    # was dropped as 'stale' before, silently)
    two = [other_clean[0], other_clean[1]]
    t, x, u = (np.concatenate([getattr(f, k) for f in two]) for k in ("t", "x", "u"))
    segs, report = clean(t, x, u, PS, PI)
    assert report.restarts == 1 and report.stale_rows == 0
    assert [len(s) for s in segs] == [len(two[0]), len(two[1])]
    assert "time goes back" in report.summary()


def test_an_input_spike_is_dropped_and_steps_and_pulses_are_kept(other_clean):
    """A real motor-speed log held 5 glitch rows of 1e5 rad/s (one of them 3 rows long): the
    model lost gravity. Spikes far outside the input's range are dropped; a command step and
    the one-row pulses of a binary excitation stay."""
    tr = other_clean[0]
    u = tr.u.copy()
    u[200, 0] = 1e3  # a lone glitch
    u[400:403, 0] = -1e3  # one re-sent for three rows
    u[500:, 1] += 0.5 * np.ptp(u[:, 1])  # a step in the command
    u[600::40, 1] += 0.3 * np.ptp(u[:, 1])  # pulses inside the range
    segs, report = clean(tr.t, tr.x, u, PS, PI)
    assert report.input_spikes == 4 and report.rows_out == len(tr) - 4
    assert report.cuts == 2 and "4 rows with an input spike" in report.summary()


def test_column_names_that_cannot_be_variables_are_refused_in_one_line(other_clean, tmp_path):
    path = tmp_path / "units.csv"
    path.write_text(_csv_text(other_clean[0], header=["t", "y (m)", *PS[1:], *PI]))
    with pytest.raises(ValueError, match=r"column name\(s\) \['y \(m\)'\] cannot name variables"):
        load_data([path], system=None)


def test_load_data_leaves_out_a_short_file_and_names_one_that_logs_other_variables(
    other_clean, tmp_path
):
    """Episodes of a random or OU policy often end within 20 rows: such a file is left out
    and named (a trial's 26 short episodes of 40 refused the whole data set); only short
    files are refused, naming the first."""
    good = str(write_trajectory_csv(tmp_path / "good.csv", other_clean[0]))
    tr = other_clean[1]
    short = [str(write_trajectory_csv(tmp_path / f"short{k}.csv",
                                      Trajectory(tr.t[:5], tr.x[:5], tr.u[:5], PS, PI)))
             for k in range(2)]  # fmt: skip
    trajs, report = load_data([short[0], good, short[1]], system="planar")
    assert len(trajs) == 1 and np.array_equal(trajs[0].x, other_clean[0].x)
    said = report.summary()
    assert (
        "left out 2 file(s) with no segment long enough to fit (short0.csv, short1.csv; the "
        "first: no segment of at least 20 clean rows)" in said
    ), said
    empty = tmp_path / "empty.csv"
    empty.write_text(open(good).readline())  # a header and no rows: left out too
    trajs, report = load_data([good, str(empty)], system="planar")
    assert len(trajs) == 1 and "(empty.csv; the first: has a header but no rows)" in (
        report.summary()
    )
    with pytest.raises(ValueError, match=r"short0\.csv: no segment of at least 20 .*the 1 other"):
        load_data(short, system="planar")
    fewer = Trajectory(tr.t, tr.x[:, :5], tr.u, PS[:5], PI)
    path = str(write_trajectory_csv(tmp_path / "fewer.csv", fewer))
    with pytest.raises(ValueError, match=r"no column\(s\) \['phi_dot'\] \(the planar preset"):
        load_data([good, path], system="planar")
    with pytest.raises(ValueError, match=r"fewer\.csv has the variables .* but .*good\.csv has"):
        load_data([good, path], system=None)


# -- noise and near-collinear terms (stepwise selection) ---------------------------------
def test_logs_in_degrees_and_milliseconds_give_the_si_model_and_score_reads_them_alike(
    tmp_path, other_clean
):
    """--angle-unit deg converts the angles before unwrapping (a trial: tilts under 6.3 deg
    passed every check and gave a flipped thrust term, 11.5 % at 1 s); the units are stored
    in the model and ``score`` reads held-out logs in them by default."""
    si, odd = [], []
    for k, t in enumerate(other_clean):
        x = t.x.copy()
        x[:, 2] = np.degrees(x[:, 2])
        si.append(str(write_trajectory_csv(tmp_path / f"si{k}.csv", t)))
        odd.append(str(write_trajectory_csv(tmp_path / f"odd{k}.csv",
                                            Trajectory(1000 * t.t, x, t.u, PS, PI))))  # fmt: skip
    fixed = ["--system", "planar", "--lambda", "1e-3", "--window", "1"]
    runs = {}
    for name, paths, units in (("si", si, []), ("odd", odd, ["--angle-unit", "deg",
                                                               "--time-unit", "ms"])):  # fmt: skip
        out = tmp_path / f"{name}.json"
        done = CliRunner().invoke(app, ["identify", *paths[:2], "--out", str(out), *fixed, *units])
        assert done.exit_code == 0, done.output
        runs[name] = load_model(out)
    np.testing.assert_allclose(runs["odd"].coefficients, runs["si"].coefficients,
                               rtol=1e-6, atol=1e-9)  # fmt: skip
    assert runs["odd"].meta["units"] == {"time": "ms", "angles": "deg"}
    scored = CliRunner().invoke(app, ["score", str(tmp_path / "odd.json"), odd[2]])
    same = CliRunner().invoke(app, ["score", str(tmp_path / "si.json"), si[2]])
    assert scored.exit_code == 0 and "data: time in ms and angles in deg" in scored.output

    def scores(output: str) -> list[float]:  # the score and holding the state's
        line = next(line for line in output.splitlines() if line.startswith("score"))
        return [float(part.split(";")[0]) for part in line.split(": ")[1:]]

    (ours, hold), (theirs, hold_si) = scores(scored.output), scores(same.output)
    assert ours < 1e-9 and theirs < 1e-9 and hold == pytest.approx(hold_si, rel=1e-9)
    damaged = runs["odd"]
    for bad in ("hours", ["ms"]):
        damaged.meta["units"] = {"time": bad, "angles": "deg"}
        damaged.save(tmp_path / "damaged.json")
        refused = CliRunner().invoke(app, ["score", str(tmp_path / "damaged.json"), odd[2]])
        assert refused.exit_code == 2 and "units.time must be one of s, ms" in refused.output
    # a refusal comes after the data's notes: they may name its cause
    tr = other_clean[0]
    stuck = Trajectory(1000 * tr.t, tr.x, np.column_stack([np.full(len(tr), 4.9), tr.u[:, 1]]),
                       PS, PI)  # fmt: skip
    path = str(write_trajectory_csv(tmp_path / "stuck.csv", stuck))
    said = CliRunner().invoke(app, ["identify", path, "--out", str(tmp_path / "x.json")])
    lines = said.output.strip().splitlines()
    assert said.exit_code == 2 and lines[-1].startswith("error: input 'u1' is constant")
    assert any("a log in milliseconds" in line for line in lines[:-1]), said.output
    # without the unit, a log in microseconds is named as such
    micro = Trajectory(1e6 * other_clean[0].t, other_clean[0].x, other_clean[0].u, PS, PI)
    path = str(write_trajectory_csv(tmp_path / "us.csv", micro))
    said = CliRunner().invoke(app, ["identify", path, "--out", str(tmp_path / "us.json"), *fixed])
    assert "a log in microseconds" in said.output and "--time-unit us" in said.output


def test_lagged_inputs_follow_a_first_order_actuator_exactly():
    """``a' = (c - a) / tau`` with each command held over its own step: the rows, the RK4
    stage points and a model's simulation against scipy's integration of the actuator."""
    from scipy.integrate import solve_ivp

    from identification.data import LAG_SETTLE, lag_stages, lagged_inputs
    from identification.model import IdentifiedModel

    rng = np.random.default_rng(4)
    tau, n = 0.03, 60
    for steps in (np.full(n - 1, 0.01), rng.uniform(0.005, 0.015, n - 1)):  # jitter too
        t = np.concatenate([[0.0], np.cumsum(steps)])
        c = rng.normal(size=(n, 2))
        a, ref, mid = lagged_inputs(t, c, tau), [c[0]], []
        for k in range(n - 1):
            sol = solve_ivp(lambda s, y, k=k, c=c: (c[k] - y) / tau, (0, steps[k]), ref[-1],
                            t_eval=[steps[k] / 2, steps[k]], rtol=1e-12, atol=1e-14)  # fmt: skip
            mid.append(sol.y[:, 0])
            ref.append(sol.y[:, 1])
        np.testing.assert_allclose(a, ref, atol=1e-10)
        rows = np.arange(n - 1)
        half, end = lag_stages(t, a, c, tau, rows)
        np.testing.assert_allclose(half, mid, atol=1e-10)
        np.testing.assert_allclose(end, ref[1:], atol=1e-10)
    # a model fitted on lagged inputs is given commands: y_dot' = u1, phi_dot' = 200 u2
    xi = np.array([[1.0, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 200]])
    model = IdentifiedModel(["y_dot", "phi_dot", "u1", "u2"], xi, ("y", "phi", "y_dot",
                            "phi_dot"), ("u1", "u2"), None, {"input_lag": tau})  # fmt: skip
    z, ref = np.array([0, 0, 0, 0, *c[0]]), [np.zeros(4)]
    for k in range(20):  # the states and the actuators, one held command at a time
        z = solve_ivp(lambda s, z, k=k: [z[2], z[3], z[4], 200 * z[5], *(c[k] - z[4:]) / tau],
                      (0, 0.01), z, rtol=1e-12, atol=1e-14).y[:, -1]  # fmt: skip
        ref.append(z[:4])
    got = model.simulate(np.zeros(4), c[:20], 0.01)
    np.testing.assert_allclose(got, ref, rtol=1e-4, atol=1e-8)  # (RK4's own error: (h/tau)^5)
    # actuators that start elsewhere (at hover, or where a longer flight left them)
    start, z, other = np.array([0.7, -0.4]), np.array([0, 0, 0, 0, 0.7, -0.4]), [np.zeros(4)]
    for k in range(20):
        z = solve_ivp(lambda s, z, k=k: [z[2], z[3], z[4], 200 * z[5], *(c[k] - z[4:]) / tau],
                      (0, 0.01), z, rtol=1e-12, atol=1e-14).y[:, -1]  # fmt: skip
        other.append(z[:4])
    started = model.simulate(np.zeros(4), c[:20], 0.01, actuators=start)
    np.testing.assert_allclose(started, other, rtol=1e-3, atol=1e-8)  # (a steeper transient)
    assert np.abs(got - other).max() > 100 * np.abs(started - other).max()
    with pytest.raises(ValueError, match="one finite value per held input"):
        model.simulate(np.zeros(4), c[:20], 0.01, actuators=[0.7])
    model.meta.pop("input_lag")  # the commands taken as acting at once: far off
    assert (
        np.abs(model.simulate(np.zeros(4), c[:20], 0.01) - ref).max()
        > 1e3 * np.abs(got - ref).max()
    )
    # the trajectory keeps its commands: lagging again starts from them, and 0 undoes it
    t = np.arange(n) * 0.01
    tr = Trajectory(t, rng.normal(size=(n, 4)), c, ("y", "phi", "y_dot", "phi_dot"),
                    ("u1", "u2"), measured=("u1",))  # fmt: skip
    once = tr.lag_inputs(tau)
    settle = int(np.searchsorted(t, LAG_SETTLE * tau))
    assert len(once) == n - settle and once.meta["input_lag"] == tau
    np.testing.assert_array_equal(once.u[:, 0], c[settle:, 0])  # measured: a signal, kept
    np.testing.assert_allclose(once.u[:, 1], lagged_inputs(t, c[:, 1:], tau)[settle:, 0])
    again = once.lag_inputs(2 * tau, settle=False)
    np.testing.assert_allclose(again.u[:, 1], lagged_inputs(t[settle:], c[settle:, 1:],
                                                            2 * tau)[:, 0])  # fmt: skip
    back = once.lag_inputs(0.0)
    np.testing.assert_array_equal(back.u, c[settle:])
    assert back.commands is None and "input_lag" not in back.meta
    with pytest.raises(ValueError, match="too short for its actuators to settle"):
        tr.slice(0, 22).lag_inputs(tau)
    with pytest.raises(ValueError, match="different lags"):
        select_model([once, tr], planar_library())


def test_a_drift_of_the_inputs_gain_scales_each_logs_held_inputs_from_its_first_row(tmp_path):
    """A battery that sags: the vehicle applies ``1 + rate tau`` times each logged input,
    ``tau`` from its log's first row (a file's segments share their file's start), moving
    within each step as a battery's charge does. Held inputs only; a second drift replaces
    the first; a gain under the floor is refused."""
    from identification.data import drift_segments, input_drift_of, load_data

    rng = np.random.default_rng(3)
    t = np.arange(400) * 0.01
    x, u = rng.normal(size=(400, 6)), rng.normal(size=(400, 2)) + 2.0
    tr = Trajectory(t + 5.0, x, u, PS, PI, measured=("u2",))
    drifted = tr.drift_inputs(-0.04)
    np.testing.assert_allclose(drifted.u[:, 0], u[:, 0] * (1 - 0.04 * t), rtol=1e-14)
    np.testing.assert_array_equal(drifted.u[:, 1], u[:, 1])  # a measured signal
    np.testing.assert_array_equal(drifted.x, x)
    _, mid, end = drifted.stage_inputs(np.arange(10))  # the gain moves within each step
    np.testing.assert_allclose(mid[:, 0], u[:10, 0] * (1 - 0.04 * (t[:10] + 0.005)), rtol=1e-14)
    np.testing.assert_allclose(end[:, 0], u[:10, 0] * (1 - 0.04 * t[1:11]), rtol=1e-14)
    again = drifted.drift_inputs(0.02)  # from the logged inputs, not the drifted ones
    np.testing.assert_allclose(again.u[:, 0], u[:, 0] * (1 + 0.02 * t), rtol=1e-14)
    np.testing.assert_allclose(again.drift_inputs(0.0).u, u, rtol=1e-14)
    assert input_drift_of([again]) == (0.02, 0.0)
    assert input_drift_of([again.drift_inputs(0.0)]) == (0.0, 0.0)
    curved = tr.drift_inputs((-0.01, -0.002))  # a sag that speeds up: 1 - 0.01 t - 0.002 t^2
    np.testing.assert_allclose(curved.u[:, 0], u[:, 0] * (1 - 0.01 * t - 0.002 * t**2))
    assert curved.meta["input_drift"] == [-0.01, -0.002]
    with pytest.raises(ValueError, match=r"1 - 0.2 t \(t in seconds .* falls to 0.202 at t = 8.99"):
        tr.drift_inputs(-0.2)
    with pytest.raises(TypeError, match="an input drift is a1"):
        tr.drift_inputs((0.1, 0.2, 0.3))
    # a file split at a gap: the second segment's gain continues from the file's start
    rows = np.column_stack([t, x, u])
    path = tmp_path / "gap.csv"
    np.savetxt(path, np.delete(rows, range(200, 210), axis=0), delimiter=",", comments="",
               header="t,y,z,phi,y_dot,z_dot,phi_dot,u1,u2")  # fmt: skip
    segments, _ = load_data([path], system="planar")
    assert len(segments) == 2
    for seg in drift_segments(segments, -0.04):
        np.testing.assert_allclose(seg.u / (1 - 0.04 * seg.t)[:, None],
                                   u[np.searchsorted(t, seg.t)], rtol=1e-12)  # fmt: skip
