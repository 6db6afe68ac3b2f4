"""The model-based RL figures of docs/mbrl.md: each task over 5 seeds against model-free PPO.

    python scripts/mbrl_experiments.py OUT [TASK ...] [--workers N]

TASK is ``ENV:TASK`` (default: PlanarQuad-v0:figure8 Quad6DOF-v0:hover Quad6DOF-v0:random).
Each experiment resumes where it stopped; the summary line is what docs/mbrl.md reports.
"""

import argparse
from pathlib import Path

from agents.mbrl import MBRLConfig, run_experiment

TASKS = ["PlanarQuad-v0:figure8", "Quad6DOF-v0:hover", "Quad6DOF-v0:random"]

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("out", nargs="?", default="out/mbrl", help="output folder (resumes)")
parser.add_argument("tasks", nargs="*", default=TASKS, help="ENV:TASK pairs")
parser.add_argument("--workers", type=int, default=1, help="parallel jobs (>1 needs Ray)")
args = parser.parse_args()
out, workers = Path(args.out), args.workers
for spec in args.tasks:
    if spec.count(":") != 1:
        parser.error(f"a task is ENV:TASK (PlanarQuad-v0:figure8), got {spec!r}")
    env_id, task = spec.split(":")
    folder = out / f"{env_id}_{task}"
    try:
        result = run_experiment(MBRLConfig(env_id=env_id, task=task), folder, 5, workers)
    except ValueError as exc:  # bad settings: one line, no traceback
        parser.exit(2, f"error: {exc}\n")
    summary = result["summary"]
    eff = summary["sample_efficiency"]
    print(
        f"{env_id} {task}: model-free final {summary['model_free_final_return']['mean']:.0f}, "
        f"SINDy best {summary['sindy_best_return']['mean']:.0f}, "
        f"{eff['mean']}x fewer real steps [{eff['low']}, {eff['high']}] "
        f"({summary['reached']}/5 seeds reached 95 %) -> {folder}/mbrl.json"
    )
