"""Speed-up of the model-based RL jobs from 1 to N workers (in process against local Ray).

Run: .venv/bin/python scripts/bench_workers.py [--jobs 4] [--workers 2]

Runs the same small SINDy-loop jobs (planar figure-8, seeds 0..jobs-1) once in process and
once on a local Ray with ``--workers`` CPUs, checks that both give the same results, and prints
the wall times, their ratio and the machine's load average (the cores may be shared).
Needs the optional Ray extra (``pip install 'quad-sindy[ray]'``).
"""

import argparse
import dataclasses
import os
import time

from agents.mbrl import MBRLConfig, run_job
from agents.parallel import ray_available, run_jobs

CONFIG = MBRLConfig(
    task="figure8", iterations=2, initial_real_steps=1000, real_steps_per_iteration=500,
    model_steps_per_iteration=8192, baseline_steps=1, eval_episodes=2,
)  # fmt: skip
"""A small SINDy loop: about 20 to 40 s of one core per job."""


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--jobs", type=int, default=4)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument(
        "--model-steps",
        type=int,
        default=CONFIG.model_steps_per_iteration,
        help="surrogate training steps per iteration (longer jobs)",
    )
    args = parser.parse_args()
    config = dataclasses.replace(CONFIG, model_steps_per_iteration=args.model_steps)
    if not ray_available():
        raise SystemExit("error: this benchmark needs Ray: pip install 'quad-sindy[ray]'")
    jobs = [("sindy", config, seed, "out/bench_workers") for seed in range(args.jobs)]
    print(f"load average before: {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    t0 = time.perf_counter()
    serial = run_jobs(run_job, jobs, workers=1)
    one = time.perf_counter() - t0
    t0 = time.perf_counter()
    parallel = run_jobs(run_job, jobs, workers=args.workers)
    many = time.perf_counter() - t0
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    print(f"{args.jobs} jobs, 1 worker (in process): {one:.1f} s")
    print(f"{args.jobs} jobs, {args.workers} workers (local Ray, incl. its start): {many:.1f} s")
    print(f"speed-up: {one / many:.2f}x; same results: {serial == parallel}")


if __name__ == "__main__":
    main()
