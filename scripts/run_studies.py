"""Run the identification studies (lambda, dt, samples, noise) and print their tables.

    python scripts/run_studies.py [OUT] [STUDY ...]     (default docs/study, all four)

Each study writes ``OUT/STUDY.csv`` row by row (an interrupted run resumes) and a plot.
"""

import csv
import sys
from pathlib import Path

from identification.experiments.study import STUDIES, run_study

out = Path(sys.argv[1] if len(sys.argv) > 1 else "docs/study")
for name in sys.argv[2:] or STUDIES:
    path = run_study(name, out)
    with path.open() as handle:
        rows = list(csv.DictReader(handle))
    print(f"\n{name}: {len(rows)} rows -> {path}")
    columns = list(rows[0]) if rows else []
    print("  ".join(f"{c:>12}" for c in columns))
    for row in rows:
        print("  ".join(f"{row[c][:12]:>12}" for c in columns))
