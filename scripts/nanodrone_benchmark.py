"""Identify a Crazyflie from the shared flights and run the nano-drone benchmark (thin script).

Usage: python scripts/nanodrone_benchmark.py [DATA_DIR] [OUT_DIR] [TEST_FILE ...]
"""

import sys
from pathlib import Path

from identification.experiments.nanodrone import run_benchmark

if __name__ == "__main__":
    repo = Path(__file__).resolve().parents[1]
    data = Path(sys.argv[1]) if len(sys.argv) > 1 else repo.parent / "shared/data/nanodrone"
    out = Path(sys.argv[2]) if len(sys.argv) > 2 else repo / "out/nanodrone"
    metrics = run_benchmark(data, sys.argv[3:] or None, out)
    print((out / "report.md").read_text())
