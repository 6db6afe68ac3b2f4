"""The model-based RL figures of docs/mbrl.md: each task over 5 seeds against model-free PPO.

    python scripts/mbrl_experiments.py OUT [TASK ...] [--workers N]

TASK is ``ENV:TASK`` (default: PlanarQuad-v0:figure8 Quad6DOF-v0:hover Quad6DOF-v0:random).
Each experiment resumes where it stopped; the summary line is what docs/mbrl.md reports.
"""

import sys
from pathlib import Path

from agents.mbrl import MBRLConfig, run_experiment

args = sys.argv[1:]
workers = 1
if "--workers" in args:
    at = args.index("--workers")
    workers = int(args[at + 1])
    del args[at : at + 2]
out = Path(args[0] if args else "out/mbrl")
tasks = args[1:] or ["PlanarQuad-v0:figure8", "Quad6DOF-v0:hover", "Quad6DOF-v0:random"]
for spec in tasks:
    env_id, task = spec.split(":")
    folder = out / f"{env_id}_{task}"
    result = run_experiment(MBRLConfig(env_id=env_id, task=task), folder, 5, workers)
    summary = result["summary"]
    eff = summary["sample_efficiency"]
    print(
        f"{env_id} {task}: model-free final {summary['model_free_final_return']['mean']:.0f}, "
        f"SINDy best {summary['sindy_best_return']['mean']:.0f}, "
        f"{eff['mean']}x fewer real steps [{eff['low']}, {eff['high']}] "
        f"({summary['reached']}/5 seeds reached 95 %) -> {folder}/mbrl.json"
    )
