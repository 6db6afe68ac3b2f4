"""Identification of the discrepancy (issue 11 item 4): drag and rotor lag, planar and 6-DOF.

Usage: ``MPLBACKEND=Agg .venv/bin/python scripts/discrepancy_study.py [--only SECTION ...]``
with sections ``drag``, ``rotors``, ``drift`` (planar, clean), ``6dof`` (drag and rotor lag on
Quad6DOF-v0) and ``noise`` (the planar drag and rotor-lag cases with state noise; ``--sigmas``).
Prints Markdown tables (docs/discrepancy.md) and writes the drift plot.
"""

from __future__ import annotations

import argparse
import warnings

from identification.experiments import discrepancy as d

SECTIONS = ("drag", "rotors", "drift", "6dof", "noise")


def main() -> None:
    """Runs the chosen studies and prints their tables."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="+", choices=SECTIONS, default=list(SECTIONS),
                        help="sections to run (default: all)")  # fmt: skip
    parser.add_argument("--plot", default="docs/discrepancy/drift.png")
    parser.add_argument("--steps", type=int, default=1000, help="steps per flight")
    parser.add_argument("--sigmas", type=float, nargs="+", default=[1e-3, 1e-2],
                        help="state-noise standard deviations of the noise section")  # fmt: skip
    parser.add_argument("--rotor-windows", type=int, nargs="+", default=[1],
                        help="integral windows of the 6-DOF rotor-lag selection")  # fmt: skip
    parser.add_argument("--vehicles", nargs="+", choices=("crazyflie", "pelican", "other"),
                        default=["crazyflie", "pelican", "other"])  # fmt: skip
    args = parser.parse_args()
    warnings.filterwarnings("ignore")
    planar = {"crazyflie": "crazyflie", "pelican": "pelican", "other": d.OTHER_VEHICLE}
    spatial = {"crazyflie": "crazyflie", "pelican": "pelican", "other": d.OTHER_VEHICLE_6DOF}
    label = {"crazyflie": "crazyflie", "pelican": "pelican", "other": "other 0.6 kg"}
    vehicles = [(planar[v], label[v]) for v in args.vehicles]
    vehicles6 = [(spatial[v], label[v]) for v in args.vehicles]

    if "drag" in args.only:
        print("## Drag on (3 flights per vehicle)\n")
        drag = [d.drag_study(v, steps=args.steps, label=name) for v, name in vehicles]
        print(d.drag_table(drag))
        print(f"\nEvery drag term, {drag[0].vehicle}:\n")
        print(d.drag_terms_table(drag[0]))

    if "rotors" in args.only:
        print("\n## Rotor dynamics on, rotor thrusts observed\n")
        rotors = [d.rotor_study(v, steps=args.steps, label=name) for v, name in vehicles]
        print(d.rotor_table(rotors))
        print(f"\nIdentified model, {rotors[0].vehicle}:\n")
        print("\n".join(rotors[0].model.equations()))

    if "drift" in args.only:
        print("\n## Rotor dynamics on, rotor thrusts hidden (crazyflie)\n")
        drift = d.drift_study("crazyflie", steps=args.steps)
        print(d.drift_table(drift))
        print(f"\nHidden-rotor model (terms off the lag-free truth: {drift.hidden_support.off}):\n")
        print("\n".join(drift.hidden_model.equations()))
        print("\nIdentification times [s]:", {k: round(v, 1) for k, v in drift.seconds.items()})
        d.plot_drift(drift, args.plot)
        print(f"\nplot: {args.plot}")

    if "6dof" in args.only:
        print("\n## 6-DOF, drag on (4 flights per vehicle, quad6dof_drag library)\n")
        for v, name in vehicles6:
            flights = d.quad6dof_flights(v, steps=args.steps, drag=True).hidden
            tilt, rms = d.max_tilt(flights)
            print(f"- {name}: tilt max {tilt:.2f} rad, RMS {rms:.2f} rad")
        drag6 = [d.drag6_study(v, steps=args.steps, label=name) for v, name in vehicles6]
        print()
        print(d.drag_table(drag6))
        for r in drag6:
            print(f"\nEvery drag term, {r.vehicle}:\n")
            print(d.drag_terms_table(r))
            print()
            print(d.support_lines(r))
        print("\n## 6-DOF, rotor dynamics on, rotor thrusts observed (4 flights per vehicle)\n")
        print(f"Integral windows {args.rotor_windows} (699-term library; see docs).\n")
        rotors6 = [
            d.rotor6_study(v, steps=args.steps, label=name, windows=args.rotor_windows)
            for v, name in vehicles6
        ]
        print(d.rotor_table(rotors6))
        for r in rotors6:
            print()
            print(d.support_lines(r))
        for r in rotors6:
            print(f"\nIdentified model, {r.vehicle}:\n")
            print("\n".join(r.model.equations()))

    if "noise" in args.only:
        for sigma in args.sigmas:
            print(f"\n## Planar, state noise sigma = {sigma:g}: drag on\n")
            noisy = [
                d.drag_study(v, steps=args.steps, label=name, sigma=sigma) for v, name in vehicles
            ]
            print(d.drag_table(noisy))
            for r in noisy:
                print()
                print(d.support_lines(r))
            print(f"\n## Planar, state noise sigma = {sigma:g}: rotor thrusts observed\n")
            noisy_rotors = [
                d.rotor_study(v, steps=args.steps, label=name, sigma=sigma) for v, name in vehicles
            ]
            print(d.rotor_table(noisy_rotors))
            for r in noisy_rotors:
                print()
                print(d.support_lines(r))
                print("\n".join(r.model.equations()[-2:]))


if __name__ == "__main__":
    main()
