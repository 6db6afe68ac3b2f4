"""What the identifier gets from a simulator's privileged data and from what a log holds.

Run: .venv/bin/python scripts/measured_vs_truth.py

A 0.5 kg planar vehicle (not the paper's) flies its PD controller to random waypoints with
exploration noise (3 flights of 1000 steps) under sensor effects. Each case is recorded twice
(:func:`identification.rollouts.collect_rollouts`): ``truth`` (the true state and the applied
input, what ``mbrl --data truth`` identifies from) and ``measured`` (the sensors' state and
the commanded input, ``mbrl --data measured``). Each is identified with the data-alone
selection and scored on two held-out flights of the true state (``held_out_errors``: open
loop with the applied inputs, RMS error after 1 s as a share of each state's range; the
worst state is printed). Prints a Markdown table.
"""

import warnings

import numpy as np

from identification.experiments.synthetic import check_support, truth_planar
from identification.libraries import planar_library
from identification.rollouts import excitation_rollouts
from identification.scoring import held_out_errors
from identification.selection import select_model
from quad_envs.params import PlanarQuadParams

VEHICLE = {"mass": "0.5", "Ixx": "3e-3", "arm_length": "0.15", "rotor_force_max": "4.905"}
CASES = {
    "sensor bias 0.01, 1-step delay": {"effects": ["sensor"]},
    "sensor noise 1e-3": {"obs_noise_std": 1e-3},
    "sensor noise 1e-2": {"obs_noise_std": 1e-2},
}


def main() -> None:
    warnings.simplefilter("ignore")
    truth = truth_planar(PlanarQuadParams(mass=0.5, Ixx=3e-3, arm_length=0.15,
                                          rotor_force_max=4.905))  # fmt: skip
    held = excitation_rollouts("PlanarQuad-v0", 2, seed=99, env_kwargs={"params": VEHICLE})
    print("| case | recorded | terms | missed + spurious | worst 1 s error (state) |")
    print("|---|---|---|---|---|")
    for case, options in CASES.items():
        for record in ("truth", "measured"):
            data = excitation_rollouts("PlanarQuad-v0", 3, seed=1, record=record,
                                       env_kwargs={"params": VEHICLE, **options})  # fmt: skip
            model, _ = select_model(data, planar_library(), n_models=0)
            check = check_support(model, truth)
            errors = held_out_errors(model, held, 100)
            worst = int(np.argmax(errors.relative))
            print(f"| {case} | {record} | {model.n_terms} | "
                  f"{len(check.missed)} + {len(check.spurious)} | "
                  f"{errors.relative[worst]:.2%} ({model.state_names[worst]}) |")  # fmt: skip


if __name__ == "__main__":
    main()
