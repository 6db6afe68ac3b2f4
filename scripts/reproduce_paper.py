"""Reproduce Manaa et al. end to end and print the headline numbers.

    python scripts/reproduce_paper.py [OUT]      (default out/reproduce)

The same as ``quad-sindy reproduce``: simulate cases A, B, C with the paper's PD, identify
from case C (ours and the paper's method), fly A and B on the identified models, write the
report, and print what a reader of the paper compares.
"""

import argparse
from pathlib import Path

from identification.experiments.reproduce import run

SHARED_CSV = Path(__file__).resolve().parents[2] / "shared/reference/paper_diamond_case_c.csv"

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("out", nargs="?", default="out/reproduce", help="output folder")
out = Path(parser.parse_args().out)
metrics = run(out, authors_csv=SHARED_CSV if SHARED_CSV.exists() else None)
for label in ("ours", "paper_method"):
    result = metrics[label]
    worst_rmse = max(max(case.values()) for case in result["rmse"].values())
    print(
        f"{label:<13} terms {result['n_terms']:>3}  support {result['support']}  "
        f"worst coefficient error {result['max_rel_coef_error']:.2e}  "
        f"worst RMSE on A, B {worst_rmse:.2e}"
    )
print(f"report: {out / 'report.md'}")
