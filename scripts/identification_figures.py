"""Figures of docs/identification.md: truth-free identification on non-paper vehicles.

Run: MPLBACKEND=Agg .venv/bin/python scripts/identification_figures.py [--quick]
Run with --optimizer stlsq for the figures before stepwise selection.
Prints one row per case: data, selection time, chosen window/lambda, support against the truth
(missed/spurious), worst coefficient error, rhs error, 1 s simulation error / state range.
"""

import argparse
import time
import warnings

import numpy as np
import pysindy as ps

from identification.experiments.synthetic import (
    OTHER_6DOF,
    OTHER_PLANAR,
    FlightSpec,
    add_noise,
    check_support,
    planar_drag_rhs,
    planar_flights,
    quad6dof_drag_rhs,
    quad6dof_flights,
    rhs_error,
    truth_planar,
    truth_quad6dof,
)
from identification.fit import FitConfig
from identification.libraries import planar_library, quad6dof_library
from identification.selection import select_model


def sim_error_1s(model, clean_trajs, steps=100):
    """Open-loop error after 1 s from the clean states, as a fraction of each state's range."""
    worst = 0.0
    for tr in clean_trajs:
        span = np.ptp(tr.x, axis=0)
        span = np.where(span > 0, span, 1.0)
        for start in range(0, len(tr) - steps, 200):
            with np.errstate(all="ignore"):
                pred = model.simulate(tr.x[start], tr.u[start : start + steps], tr.dt)
            err = np.abs(pred[-1] - tr.x[start + steps]) / span
            worst = max(worst, float(np.nanmax(err)) if np.isfinite(err).all() else np.inf)
    return worst


def pysindy_pipeline(trajs, state_names, input_names, library):
    """pysindy's own noise pipeline: SmoothedFiniteDifference + STLSQ (defaults) + bagging."""
    from identification.features import compile_features

    theta = compile_features(library, state_names, input_names)
    rng_state = np.random.get_state()  # noqa: NPY002 (pysindy bags with the global RNG)
    np.random.seed(0)  # noqa: NPY002
    try:
        opt = ps.EnsembleOptimizer(ps.STLSQ(), bagging=True, n_models=20)
        dx = [ps.SmoothedFiniteDifference()(tr.x, tr.t) for tr in trajs]
        big = np.concatenate([theta(tr.x, tr.u) for tr in trajs])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            opt.fit(big, np.concatenate(dx))
    finally:
        np.random.set_state(rng_state)  # noqa: NPY002
    from identification.model import IdentifiedModel

    return IdentifiedModel(library, np.atleast_2d(opt.coef_), state_names, input_names)


def row(label, model, truth, rhs, clean, seconds, report=None):
    check = check_support(model, truth)
    choice = f"w={report.best.window} lam={report.best.lam:.1e}" if report else "-"
    print(
        f"| {label} | {seconds:.1f} | {choice} | {check.n_terms} | {len(check.missed)} | "
        f"{len(check.spurious)} | {check.max_rel_error:.1e} | {rhs_error(model, rhs, clean):.1e} | "
        f"{sim_error_1s(model, clean):.1e} |",
        flush=True,
    )


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--quick", action="store_true", help="planar only")
    parser.add_argument(
        "--optimizer",
        default="stepwise",
        help="stepwise (default) | stlsq | sr3 (stlsq: the figures before stepwise)",
    )
    args = parser.parse_args()
    config = FitConfig(optimizer=args.optimizer)
    print(
        "| case | time [s] | choice | terms | missed | spurious | worst coef err | "
        "rhs err | 1 s sim err / range |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    lib = planar_library()
    cases = [
        ("planar m=0.5 clean, RK4", FlightSpec(), 0.0),
        ("planar clean, RK4 x10 substeps", FlightSpec(integrator="rk4x10"), 0.0),
        ("planar clean, solve_ivp DOP853 + ZOH", FlightSpec(integrator="solve_ivp"), 0.0),
        ("planar open loop + drag 0.3", FlightSpec(open_loop=True, drag=0.3), 0.0),
        ("planar sigma=1e-3", FlightSpec(), 1e-3),
        ("planar sigma=1e-2", FlightSpec(), 1e-2),
    ]
    for label, spec, sigma in cases:
        clean = planar_flights(OTHER_PLANAR, spec)
        data = add_noise(clean, sigma) if sigma else clean
        truth = truth_planar(OTHER_PLANAR, spec.drag)
        rhs = planar_drag_rhs(OTHER_PLANAR, spec.drag)
        t0 = time.perf_counter()
        model, report = select_model(data, lib, config=config)
        row(f"ours: {label}", model, truth, rhs, clean, time.perf_counter() - t0, report)
        if sigma:
            t0 = time.perf_counter()
            base = pysindy_pipeline(data, clean[0].state_names, clean[0].input_names, lib)
            row(f"pysindy SFD+STLSQ+bagging: {label}", base, truth, rhs, clean,
                time.perf_counter() - t0)  # fmt: skip
    big = planar_flights(OTHER_PLANAR, FlightSpec(flights=10, steps=10_000))
    t0 = time.perf_counter()
    model, report = select_model(big, lib, config=config)
    row("ours: planar 1e5 rows clean", model, truth_planar(OTHER_PLANAR),
        planar_drag_rhs(OTHER_PLANAR, 0.0), big[:1], time.perf_counter() - t0, report)  # fmt: skip
    if args.quick:
        return
    clean6 = quad6dof_flights(OTHER_6DOF, FlightSpec(flights=4))
    t0 = time.perf_counter()
    model, report = select_model(
        clean6, quad6dof_library(), config=config, windows=(1,), n_models=5
    )
    row("ours: 6-DOF m=0.8 clean, RK4", model, truth_quad6dof(OTHER_6DOF),
        quad6dof_drag_rhs(OTHER_6DOF, 0.0), clean6, time.perf_counter() - t0, report)  # fmt: skip


if __name__ == "__main__":
    main()
