"""Run the identification studies (lambda, dt, samples, noise) and print their tables.

    python scripts/run_studies.py [OUT] [STUDY ...]     (default docs/study, all four)

Each study writes ``OUT/STUDY.csv`` row by row (an interrupted run resumes) and a plot.
"""

import argparse
import csv
from pathlib import Path

from identification.experiments.study import STUDIES, run_study


def _short(text: str) -> str:
    """A CSV cell for the table: numbers to 5 significant digits, text as it is."""
    try:
        return f"{float(text):.5g}"
    except ValueError:
        return text


parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("out", nargs="?", default="docs/study", help="output folder (resumes)")
parser.add_argument("studies", nargs="*", help=f"any of {', '.join(STUDIES)} (default: all)")
args = parser.parse_args()
unknown = sorted(set(args.studies) - set(STUDIES))
if unknown:
    parser.error(f"unknown stud(ies) {unknown}; valid: {', '.join(STUDIES)}")
out = Path(args.out)
for name in args.studies or STUDIES:
    path = run_study(name, out)
    with path.open() as handle:
        rows = list(csv.DictReader(handle))
    print(f"\n{name}: {len(rows)} rows -> {path}")
    columns = list(rows[0]) if rows else []
    print("  ".join(f"{c:>12}" for c in columns))
    for row in rows:  # whole values: a cut 1.6278204656e-06 read as 1.6278204656
        print("  ".join(f"{_short(row[c]):>12}" for c in columns))
