import csv
import json

import numpy as np
import pytest

from identification.experiments import study
from identification.experiments.reproduce import PAPER_PUBLISHED_RMSE, run


def test_reproduce_end_to_end(tmp_path, reference_case_c):
    from tests.conftest import REFERENCE_CSV

    metrics = run(tmp_path, authors_csv=REFERENCE_CSV, echo=lambda s: None)
    saved = json.loads((tmp_path / "metrics.json").read_text())
    assert saved["support"] == {"true": 7, "missed": 0, "spurious": 0}
    assert saved["max_rel_coef_error"] < 1e-4
    for case in "AB":
        for state, published in PAPER_PUBLISHED_RMSE.items():
            assert saved["rmse"][case][state] < published
    assert metrics["authors_file"]["ours"]["support"]["spurious"] == 0
    for name in (
        "report.md",
        "model.json",
        "lambda_scan_ours.png",
        "abs_error_ours.png",
        "response_ours_A.png",
    ):
        assert (tmp_path / name).stat().st_size > 0


def test_study_writes_rows_as_it_goes_and_resumes(tmp_path, monkeypatch):
    calls = []

    def fake_cases(name):
        def row(x):
            calls.append(x)
            return {
                "study": name,
                "method": "m",
                "x": x,
                "lambda": 0.1,
                "n_terms": 7,
                "missed": 0,
                "spurious": int(x),
                "max_rel_error": 10.0**-x,
            }

        return [("m", x, lambda x=x: row(x)) for x in (1.0, 2.0, 3.0)]

    monkeypatch.setattr(study, "_cases", fake_cases)
    path = study.run_study("noise", tmp_path, progress=False)
    assert calls == [1.0, 2.0, 3.0]
    rows = list(csv.DictReader(path.open()))
    # simulate an interruption after the second row, then resume
    path.write_text("\n".join(path.read_text().splitlines()[:3]) + "\n")
    calls.clear()
    study.run_study("noise", tmp_path, progress=False)
    assert calls == [3.0]
    again = list(csv.DictReader(path.open()))
    assert [r["x"] for r in again] == [r["x"] for r in rows]
    assert (tmp_path / "noise.png").exists()
    with pytest.raises(ValueError, match="valid choices"):
        study.run_study("colour", tmp_path)
    assert np.isclose(float(again[2]["max_rel_error"]), 1e-3)


HEADER = "study,method,x,lambda,n_terms,missed,spurious,max_rel_error,error"


@pytest.mark.parametrize(
    "text,problem",
    [
        ("t,y\n0,1\n", "is not a table of the lambda study (its header is not"),
        (f"{HEADER}\nlambda,ours,abc,0,1,0,0,1,\n", "line 2 is not a row of the lambda study"),
        (f"{HEADER}\nlambda,ours,1\n", "line 2 is not a row of the lambda study (not 9 cells)"),
        (f"{HEADER}\ndt,ours,1,0,1,0,0,1,\n", "(study 'dt', not 'lambda')"),
    ],
)
def test_study_names_a_foreign_or_corrupt_table_and_keeps_it(
    monkeypatch, capsys, tmp_path, text, problem
):
    """A user's lambda.csv in --out gave KeyError 'method'; a corrupt row "could not convert
    string to float" without the file's name."""
    from tests.test_cli import assert_one_line_error, run_cli

    monkeypatch.setattr(study, "_cases", lambda name: pytest.fail("the study started"))
    (tmp_path / "lambda.csv").write_text(text)
    code, _, err = run_cli(monkeypatch, capsys, "study", "lambda", "--out", str(tmp_path))
    assert_one_line_error(code, err, f"{tmp_path / 'lambda.csv'}", problem)
    assert (tmp_path / "lambda.csv").read_text() == text


@pytest.mark.parametrize("command", ["envs", "surrogate"])
@pytest.mark.parametrize("seconds", ["nan", "0", "-1", "inf"])
def test_bench_refuses_a_timing_that_never_ends_or_is_not_positive(
    monkeypatch, capsys, command, seconds
):
    """``--seconds nan`` hung forever."""
    from quad_sindy import bench
    from tests.test_cli import assert_one_line_error, run_cli

    code, _, err = run_cli(monkeypatch, capsys, "bench", command, "--seconds", seconds)
    assert_one_line_error(code, err, "--seconds must be a positive finite number")
    with pytest.raises(ValueError, match="must be positive and finite"):
        bench.bench_envs(("PlanarQuad-v0",), min_seconds=float(seconds))


def test_train_names_a_bad_seed_before_making_its_folder(monkeypatch, capsys, tmp_path):
    from tests.test_cli import assert_one_line_error, run_cli

    out = tmp_path / "t"
    code, _, err = run_cli(monkeypatch, capsys, "train", "--out", str(out), "--seed", "-1")
    assert_one_line_error(code, err, "--seed must be an integer from 0 to 2**32 - 1, got -1")
    assert not out.exists()
