"""Identify a Crazyflie from the shared flights and run the nano-drone benchmark (thin script).

Usage: python scripts/nanodrone_benchmark.py [DATA_DIR] [OUT_DIR] [TEST_FILE ...]
"""

import argparse
from pathlib import Path

from identification.experiments.nanodrone import run_benchmark

if __name__ == "__main__":
    repo = Path(__file__).resolve().parents[1]
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("data", nargs="?", default=repo.parent / "shared/data/nanodrone",
                        type=Path, help="folder of the flights")  # fmt: skip
    parser.add_argument("out", nargs="?", default=repo / "out/nanodrone", type=Path)
    parser.add_argument("tests", nargs="*", help="test flights (default: the protocol's)")
    args = parser.parse_args()
    data, out = args.data, args.out
    metrics = run_benchmark(data, args.tests or None, out)
    print((out / "report.md").read_text())
