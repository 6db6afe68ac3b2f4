"""``quad-sindy study``: how identification depends on lambda, sampling step, data size, noise.

Each study is a list of cases (one row each). Rows are appended to ``DIR/<study>.csv`` as they
finish; a rerun skips rows already there, so an interrupted study resumes where it stopped.
The plot ``DIR/<study>.png`` is redrawn from the CSV at the end.

Training data: planar PD flights (case C plus random-waypoint flights with exploration
noise), controlled at the sampling step with the physics integrated by 10 RK4 substeps, so
that no method is handed data from its own integrator.
"""

from __future__ import annotations

import csv
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from identification.data import Trajectory
from identification.experiments.paper import fit_paper
from identification.experiments.plots import plot_curves
from identification.experiments.truth import compare_coefficients, planar_truth
from identification.fit import DEFAULT_LAMBDAS, FitConfig, fit
from identification.libraries import planar_library
from quad_envs.controllers import PlanarPD
from quad_envs.dynamics import PLANAR_STATE_NAMES
from quad_envs.fileio import atomic_write_text
from quad_envs.simulate import simulate_closed_loop
from quad_envs.trajectories import RandomWaypoints, make_trajectory
from quad_envs.vehicles import PLANAR

STUDIES = ("lambda", "dt", "samples", "noise")
FIELDS = (
    "study", "method", "x", "lambda", "n_terms", "missed", "spurious", "max_rel_error", "error",
)  # fmt: skip


def training_data(
    dt: float = 0.01, flights: int = 4, seed: int = 0, duration: float = 10.0
) -> list[Trajectory]:
    """Case C plus random-waypoint PD flights with input noise; 10 RK4 substeps per step."""
    rng = np.random.default_rng(seed)
    pd = PlanarPD()
    refs = [make_trajectory("C")] + [
        RandomWaypoints.sample(rng, 2, 9, (-1.5, 0.5), (1.5, 2.0), 1.5) for _ in range(flights)
    ]
    trajs = []
    for i, ref in enumerate(refs):
        noise = rng.normal(size=(int(duration / dt) + 2, 2)) * np.array([0.2, 0.01]) * (i > 0)
        count = iter(range(noise.shape[0]))

        def ctrl(
            x: np.ndarray, r: np.ndarray, noise: np.ndarray = noise, count: Iterator = count
        ) -> np.ndarray:
            return pd(x, r) + noise[next(count)]

        with np.errstate(all="ignore"):
            run = simulate_closed_loop(PLANAR, ref, ctrl, dt=dt, duration=duration, substeps=10)
        if np.isfinite(run.states).all() and np.abs(run.states[:, 2]).max() < 1.4:
            trajs.append(Trajectory.from_run(run))
    return trajs


def _evaluate(study: str, method: str, x: float, model: Any, lam: float) -> dict[str, Any]:
    comp = compare_coefficients(
        model.coefficients, planar_truth(), PLANAR_STATE_NAMES, model.feature_names
    )
    return {
        "study": study,
        "method": method,
        "x": x,
        "lambda": lam,
        "n_terms": model.n_terms,
        "missed": len(comp.missed),
        "spurious": len(comp.spurious),
        "max_rel_error": comp.max_rel_error,
    }


def _fit_row(
    study: str, method: str, x: float, trajs: list[Trajectory], lam: float, window: int = 1
) -> dict:
    lib = planar_library()
    if method == "paper":
        model = fit_paper(trajs, lam)
    else:
        derivative = "forward" if method == "forward" else "rk4"
        model = fit(trajs, lib, FitConfig(derivative=derivative, lam=lam, window=window), "planar")
    return _evaluate(study, method, x, model, lam)


def _cases(study: str) -> list[tuple[str, float, Callable[[], dict]]]:
    """(method, x, thunk) for every row of a study."""
    cases: list[tuple[str, float, Callable[[], dict]]] = []
    if study == "lambda":
        data = training_data()
        for lam in DEFAULT_LAMBDAS:
            for method in ("ours", "forward"):
                cases.append(
                    (method, lam, lambda m=method, v=lam: _fit_row("lambda", m, v, data, v))
                )
        for lam in np.round(np.arange(0.05, 1.0001, 0.05), 2):
            cases.append(
                ("paper", lam, lambda v=float(lam): _fit_row("lambda", "paper", v, data, v))
            )
    elif study == "dt":
        for dt in (0.005, 0.01, 0.02, 0.05, 0.1):
            cache: dict[str, Any] = {}

            def data(dt: float = dt, cache: dict = cache) -> list[Trajectory]:
                if "d" not in cache:
                    cache["d"] = training_data(dt=dt)
                return cache["d"]

            for method, lam in (("ours", 1e-3), ("forward", 1e-3), ("paper", 0.45)):
                cases.append(
                    (
                        method,
                        dt,
                        lambda m=method, v=dt, lam=lam, d=data: _fit_row("dt", m, v, d(), lam),
                    )
                )
    elif study == "samples":
        full = training_data(flights=4)
        for n in (50, 100, 200, 500, 1000, 2000, 5000):

            def subset(n: int = n) -> list[Trajectory]:
                out, left = [], n
                for tr in full:
                    take = min(left, len(tr))
                    if take >= 3:
                        out.append(
                            Trajectory(
                                tr.t[:take],
                                tr.x[:take],
                                tr.u[:take],
                                tr.state_names,
                                tr.input_names,
                            )
                        )
                    left -= take
                return out

            for method, lam in (("ours", 1e-3), ("forward", 1e-3), ("paper", 0.45)):
                cases.append(
                    (
                        method,
                        n,
                        lambda m=method, v=n, lam=lam, s=subset: _fit_row(
                            "samples", m, v, s(), lam
                        ),
                    )
                )
    elif study == "noise":
        clean = training_data()
        for sigma in (0.0, 1e-5, 1e-4, 1e-3, 3e-3, 1e-2):

            def noisy(sigma: float = sigma) -> list[Trajectory]:
                rng = np.random.default_rng(7)
                return [
                    Trajectory(
                        t.t,
                        t.x + sigma * rng.standard_normal(t.x.shape),
                        t.u,
                        t.state_names,
                        t.input_names,
                    )
                    for t in clean
                ]

            settings = (
                ("ours", 1e-3, 1),
                ("ours-integral-w20", 0.1, 20),
                ("forward", 1e-3, 1),
                ("paper", 0.45, 1),
            )
            for method, lam, window in settings:
                base = "ours" if method.startswith("ours") else method
                cases.append(
                    (
                        method,
                        sigma,
                        lambda m=method, b=base, v=sigma, lam=lam, w=window, d=noisy: {
                            **_fit_row("noise", b, v, d(), lam, w),
                            "method": m,
                        },
                    )
                )
    else:
        raise ValueError(f"unknown study {study!r}; valid choices: {', '.join(STUDIES)}")
    return cases


def _read_done(path: Path, study: str) -> list[dict[str, str]]:
    """The rows of an earlier run of ``study`` in ``path`` (none if there is no file).

    Raises:
        ValueError: ``path`` is not a table of this study (a user's file, never overwritten),
            or a row of it is not (naming the line).
    """
    if not path.exists():
        return []
    with path.open(newline="") as handle:
        reader = csv.DictReader(handle)
        header = reader.fieldnames or []
        if tuple(header) != FIELDS:
            raise ValueError(
                f"{path} is not a table of the {study} study (its header is not "
                f"{','.join(FIELDS)}): move it away, or use another --out"
            )
        rows = list(reader)
    for number, row in enumerate(rows, start=2):
        try:
            if None in row or None in row.values():
                raise ValueError(f"not {len(FIELDS)} cells")
            if row["study"] != study:
                raise ValueError(f"study {row['study']!r}, not {study!r}")
            float(row["x"])
            float(row["max_rel_error"])
            for name in ("missed", "spurious"):
                if row[name] != "":
                    int(row[name])
        except ValueError as exc:
            raise ValueError(
                f"{path} line {number} is not a row of the {study} study ({exc}): repair or "
                "remove that line, and the study reruns that case"
            ) from None
    return rows


def run_study(study: str, out: str | Path, progress: bool = True) -> Path:
    """Runs (or resumes) one study; returns the CSV path."""
    from tqdm import tqdm

    if study not in STUDIES:
        raise ValueError(f"unknown study {study!r}; valid choices: {', '.join(STUDIES)}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"{study}.csv"
    rows = _read_done(path, study)
    done = {(r["method"], float(r["x"])) for r in rows}
    cases = _cases(study)
    todo = [c for c in cases if (c[0], float(c[1])) not in done]
    bar = tqdm(
        todo,
        desc=f"study {study}",
        disable=not progress,
        initial=len(cases) - len(todo),
        total=len(cases),
    )
    for method, x, thunk in bar:
        with np.errstate(all="ignore"):
            try:
                row = thunk()
            except (ValueError, np.linalg.LinAlgError) as exc:
                # Recorded, not fatal: e.g. no stable flight at this sampling step.
                row = {"study": study, "method": method, "x": x, "max_rel_error": float("inf"),
                       "error": str(exc)}  # fmt: skip
        rows.append({k: row.get(k, "") for k in FIELDS})
        _write_rows(path, rows)  # after every case: an interruption loses at most one
    _plot(study, rows, out / f"{study}.png")
    return path


def _write_rows(path: Path, rows: list[dict]) -> None:
    def cell(value: object) -> str:
        return str(value).replace(",", ";").replace("\n", " ")

    lines = [",".join(FIELDS)] + [",".join(cell(r.get(k, "")) for k in FIELDS) for r in rows]
    atomic_write_text(path, "\n".join(lines) + "\n")


def _plot(study: str, rows: list[dict], path: Path) -> None:
    labels = {
        "lambda": "lambda",
        "dt": "sampling step dt [s]",
        "samples": "snapshots",
        "noise": "state noise sigma",
    }
    methods = list(dict.fromkeys(r["method"] for r in rows))
    for metric, ylabel in (("max_rel_error", "worst relative coefficient error"),):
        curves, spurious = {}, {}
        xs = sorted({float(r["x"]) for r in rows})
        for method in methods:
            by_x = {float(r["x"]): r for r in rows if r["method"] == method}
            curves[method] = [float(by_x[x][metric]) if x in by_x else np.nan for x in xs]
            spurious[f"{method}: missed+spurious"] = [
                int(by_x[x]["missed"]) + int(by_x[x]["spurious"])
                if x in by_x and by_x[x]["missed"] != ""
                else np.nan
                for x in xs
            ]
        plot_curves(
            xs, curves, path, labels[study], ylabel, f"Study: {study} (inf = a true term missed)"
        )
        plot_curves(
            xs,
            spurious,
            path.with_name(f"{study}_support.png"),
            labels[study],
            "wrong terms (missed + spurious)",
            f"Study: {study}",
            logy=False,
        )
