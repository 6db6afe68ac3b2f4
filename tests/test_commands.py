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
