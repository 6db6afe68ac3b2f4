"""The nano-drone benchmark: identify a Crazyflie from flight logs and score it on test flights.

Protocol (Busetto et al., "Nonlinear System Identification for a Nano-drone Benchmark",
2025): from every sample i of a test flight with i + H < N, start at the measured state,
integrate the model open loop for H = 50 steps (0.5 s) with the measured motor speeds
omega[i .. i+H-1], and compare with x[i+1 .. i+H]. Error norms per window and step: position
[m], world-frame velocity [m/s], attitude as the geodesic angle [rad], body rates [rad/s];
MAE_h is their mean over all windows of all test flights at step h, and SimErr = sum_h MAE_h.

Models scored:

``sindy``
    :mod:`identification.rotorcraft`: exact kinematics, sparse identified accelerations
    refined on simulation error, chosen on held-out *training* flights only.
``physics``
    The benchmark's nominal rigid body (thrust Kt sum Omega^2 clipped at 2 m g, world-frame
    velocity, quaternion attitude, RK4) with the angular acceleration set to zero.
``hold``
    The state held at its start value.

All three see the same repaired flights (:mod:`identification.logs`).
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from identification.data import Trajectory
from identification.logs import read_flight
from identification.rotorcraft import (
    FEATURES as FEATURES_DOC,
)
from identification.rotorcraft import (
    GROUPS,
    NANODRONE_NOMINAL,
    NominalRotorcraft,
    RotorcraftModel,
    Windows,
    fit_equation_error,
    group_errors,
    make_windows,
    prune,
    prune_to,
    refine,
    rotation_zxy_torch,
)
from quad_envs.fileio import atomic_write_text, write_json

HORIZON = 50
REPORT_HORIZONS = (1, 10, 25, 50)
PUBLISHED: dict[str, dict[str, tuple[float, float, float, float]]] = {
    # h = 50 MAE and SimErr (position, velocity, attitude, rates) on `melon`, from the paper.
    "hold the state": {"h50": (0.680, 1.475, 0.304, 0.884), "simerr": (17.8, 38.9, 8.21, 29.1)},
    "nominal physics": {"h50": (0.127, 0.578, 0.254, 0.884), "simerr": (2.32, 10.6, 5.10, 29.1)},
    "neural residual (MLP)": {
        "h50": (0.171, 0.572, 0.227, 0.901),
        "simerr": (4.05, 12.6, 6.06, 35.6),
    },
    "physics + neural residual": {
        "h50": (0.112, 0.556, 0.231, 0.598),
        "simerr": (2.36, 10.4, 6.15, 29.0),
    },
    "LSTM": {"h50": (0.257, 0.741, 0.233, 1.241), "simerr": (5.97, 16.7, 5.65, 35.8)},
}
"""Published results on the benchmark's test flight (data README)."""

_RUN = re.compile(r"^(?P<family>[A-Za-z0-9]+)_.*run(?P<run>\d+)$")


# -- flights ----------------------------------------------------------------------------
def flight_family(path: str | Path) -> tuple[str, int]:
    """(family, run) of a file named like ``square_20251017_run3.parquet``; run -1 if none."""
    stem = Path(path).stem
    match = _RUN.match(stem)
    if match:
        return match["family"], int(match["run"])
    return stem.split("_")[0], -1


def split_flights(paths: Sequence[Path]) -> tuple[list[Path], list[Path]]:
    """Holds out the highest-numbered run of every family: (kept, held out)."""
    last: dict[str, Path] = {}
    for path in sorted(paths):
        fam, run = flight_family(path)
        if fam not in last or run > flight_family(last[fam])[1]:
            last[fam] = path
    held = sorted(last.values())
    return [p for p in sorted(paths) if p not in held], held


# -- baselines --------------------------------------------------------------------------
def _quat_from_rotation(rot: torch.Tensor) -> torch.Tensor:
    from identification.logs import rotation_to_quaternion

    return torch.as_tensor(rotation_to_quaternion(rot.numpy()))


def _quat_rotate(q: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    qv, qw = q[..., :3], q[..., 3:4]
    t = 2.0 * torch.cross(qv, v, dim=-1)
    return v + qw * t + torch.cross(qv, t, dim=-1)


def _quat_derivative(q: torch.Tensor, omega: torch.Tensor) -> torch.Tensor:
    qv, qw = q[..., :3], q[..., 3:4]
    dqv = 0.5 * (qw * omega + torch.cross(qv, omega, dim=-1))
    dqw = -0.5 * (qv * omega).sum(-1, keepdim=True)
    return torch.cat((dqv, dqw), -1)


def physics_rollout(
    x0: np.ndarray,
    omega: np.ndarray,
    vehicle: NominalRotorcraft = NANODRONE_NOMINAL,
    dt: float = 0.01,
) -> torch.Tensor:
    """The benchmark's nominal physics with zero angular acceleration, as 6-DOF states.

    Position, world velocity and a unit quaternion are integrated by RK4 (quaternion
    renormalised at every stage, as the benchmark does); the body rates stay at their start.

    Args:
        x0: Start states (B, 12) (toolkit representation).
        omega: Motor speeds (B, H, 4) [rad/s].
        vehicle: Nominal parameters.
        dt: Step [s].

    Returns:
        States (B, H, 12).
    """
    x0 = torch.as_tensor(x0, dtype=torch.float64)
    omega = torch.as_tensor(omega, dtype=torch.float64)
    rot0 = rotation_zxy_torch(x0[:, 3], x0[:, 4], x0[:, 5])
    pos, rates = x0[:, 0:3], x0[:, 9:12]
    vel = (rot0 @ x0[:, 6:9, None])[..., 0]
    quat = _quat_from_rotation(rot0)
    g = torch.tensor([0.0, 0.0, vehicle.gravity], dtype=torch.float64)
    t_max = vehicle.thrust_to_weight * vehicle.mass * vehicle.gravity
    from identification.logs import quaternion_to_rotation, rotation_to_euler_zxy

    def f(vel, quat, thrust):
        thrust_b = torch.zeros_like(vel)
        thrust_b[:, 2] = thrust
        acc = _quat_rotate(quat, thrust_b) / vehicle.mass - g
        return vel, acc, _quat_derivative(quat, rates)

    def unit(q):
        return q / torch.linalg.vector_norm(q, dim=-1, keepdim=True)

    out = []
    for k in range(omega.shape[1]):
        thrust = torch.clamp(vehicle.kt * (omega[:, k] ** 2).sum(-1), 0.0, t_max)
        v1, a1, q1 = f(vel, quat, thrust)
        v2, a2, q2 = f(vel + 0.5 * dt * a1, unit(quat + 0.5 * dt * q1), thrust)
        v3, a3, q3 = f(vel + 0.5 * dt * a2, unit(quat + 0.5 * dt * q2), thrust)
        v4, a4, q4 = f(vel + dt * a3, unit(quat + dt * q3), thrust)
        pos = pos + dt / 6.0 * (v1 + 2 * v2 + 2 * v3 + v4)
        vel = vel + dt / 6.0 * (a1 + 2 * a2 + 2 * a3 + a4)
        quat = unit(quat + dt / 6.0 * (q1 + 2 * q2 + 2 * q3 + q4))
        rot = torch.as_tensor(quaternion_to_rotation(quat.numpy()))
        phi, theta, psi = (torch.as_tensor(a) for a in rotation_to_euler_zxy(rot.numpy()))
        v_body = (rot.transpose(-1, -2) @ vel[..., None])[..., 0]
        out.append(torch.cat((pos, torch.stack((phi, theta, psi), -1), v_body, rates), -1))
    return torch.stack(out, 1)


def hold_rollout(x0: np.ndarray, omega: np.ndarray) -> torch.Tensor:
    """The state held: (B, H, 12)."""
    x0 = torch.as_tensor(x0, dtype=torch.float64)
    return x0[:, None, :].expand(-1, omega.shape[1], -1)


# -- the protocol -----------------------------------------------------------------------
Predictor = Callable[[Windows], torch.Tensor]


def mae_by_horizon(
    predict: Predictor, windows: Windows, chunk: int = 4096, tick: Callable[[], None] | None = None
) -> dict[str, np.ndarray]:
    """MAE at every step h = 1..H of each group over all windows (chunked, no gradients)."""
    sums = {g: np.zeros(windows.truth.shape[1]) for g in GROUPS}
    with torch.no_grad():
        for start in range(0, len(windows), chunk):
            arrays = (windows.x0, windows.a0, windows.omega, windows.truth)
            part = Windows(*(arr[start : start + chunk] for arr in arrays))
            errs = group_errors(predict(part), torch.as_tensor(part.truth))
            for g in GROUPS:
                err = errs[g].numpy()
                err = np.where(np.isfinite(err), err, 1e3)  # a diverged rollout counts, large
                sums[g] += err.sum(axis=0)
            if tick is not None:
                tick()
    return {g: s / len(windows) for g, s in sums.items()}


def summarise(mae: dict[str, np.ndarray], horizons: Sequence[int] = REPORT_HORIZONS) -> dict:
    """metrics.json entry: MAE at the report horizons and SimErr per group."""
    return {
        "mae": {str(h): {g: float(mae[g][h - 1]) for g in GROUPS} for h in horizons},
        "simerr": {g: float(mae[g].sum()) for g in GROUPS},
    }


def rotorcraft_predictor(model: RotorcraftModel) -> Predictor:
    """Windows -> predicted states of an identified model (actuator state from the windows)."""
    return lambda w: model.rollout(w.x0, w.a0, w.omega)


# -- identification ---------------------------------------------------------------------
def loss_scales(windows: Windows) -> dict[str, float]:
    """Per-group error scale: the hold baseline's mean error over the windows."""
    errs = group_errors(hold_rollout(windows.x0, windows.omega), torch.as_tensor(windows.truth))
    return {g: float(errs[g].mean()) for g in GROUPS}


class _Progress:
    """One tqdm bar over the whole run; ``step`` for work units, ``say`` for stage names."""

    def __init__(self, total: int, enabled: bool) -> None:
        from tqdm.auto import tqdm

        self.bar = tqdm(total=total, disable=not enabled, unit="step", dynamic_ncols=True)
        self.log: list[str] = []

    def step(self, n: int = 1) -> None:
        self.bar.update(n)

    def say(self, message: str) -> None:
        self.log.append(message)
        self.bar.set_description_str(message[:60])
        if not self.bar.disable:
            self.bar.write(message)

    def close(self) -> None:
        self.bar.close()


def identify(
    train: Sequence[Trajectory],
    validation: Sequence[Trajectory],
    taus: Sequence[float] = (0.0, 0.02, 0.04),
    prune_fractions: Sequence[float] = (0.05, 0.1),
    max_terms: int = 60,
    threshold: float = 0.02,
    horizon: int = HORIZON,
    stride: int = 25,
    iterations: int = 25,
    progress: _Progress | None = None,
) -> tuple[RotorcraftModel, list[dict[str, Any]]]:
    """Fits candidates on ``train``; chooses on ``validation`` (held-out training flights).

    Stage 1, for every actuator time constant in ``taus``: equation-error STLSQ, then
    ``iterations // 2`` refinement steps on ``horizon``-step windows (every ``stride``-th
    sample). Stage 2, for the best tau: prune at each of ``prune_fractions`` and refine for
    ``iterations`` steps; if the gentlest pruning leaves more than ``max_terms`` terms, the
    ``max_terms`` largest terms (:func:`~identification.rotorcraft.prune_to`) are a further
    candidate. The score is the mean over
    groups of SimErr / hold SimErr on the validation flights; among candidates with at most
    ``max_terms`` terms (else the sparsest) the lowest score wins.

    Returns:
        The chosen model (coefficients fitted on ``train``) and one record per candidate.
    """
    prog = progress or _Progress(0, False)
    records: list[dict[str, Any]] = []
    val_hold: dict | None = None

    def score(cand: RotorcraftModel, label: str) -> float:
        nonlocal val_hold
        val_windows = make_windows(validation, horizon, 5, cand.actuator_states)
        if val_hold is None:
            val_hold = summarise(mae_by_horizon(lambda w: hold_rollout(w.x0, w.omega), val_windows))
        val = summarise(mae_by_horizon(rotorcraft_predictor(cand), val_windows))
        value = float(np.mean([val["simerr"][g] / val_hold["simerr"][g] for g in GROUPS]))
        records.append(
            {"tau": cand.tau, "candidate": label, "n_terms": cand.n_terms, "score": value, **val}
        )
        prog.say(f"tau {cand.tau * 1e3:.0f} ms, {label}: {cand.n_terms} terms, score {value:.3f}")
        return value

    def fit_refine(model: RotorcraftModel, steps: int) -> RotorcraftModel:
        windows = make_windows(train, horizon, stride, model.actuator_states)
        return refine(model, windows, loss_scales(windows), steps, progress=_ticker(prog))

    stage1 = []
    for tau in taus:
        prog.say(f"tau {tau * 1e3:.0f} ms: equation error + simulation-error refinement")
        # Half the iterations to rank the time constants; the winner is refined further.
        model = fit_refine(fit_equation_error(train, tau, threshold), max(iterations // 2, 1))
        stage1.append((score(model, "refined"), model))
    _, best = min(stage1, key=lambda pair: pair[0])
    candidates = [(records[taus.index(best.tau)]["score"], best)]
    for frac in prune_fractions:
        pruned = prune(best, train, frac)
        prog.say(f"tau {best.tau * 1e3:.0f} ms: pruned at {frac:g} to {pruned.n_terms} terms")
        pruned = fit_refine(pruned, iterations)
        pruned.meta["pruned_fraction"] = frac
        candidates.append((score(pruned, f"pruned {frac:g}"), pruned))
    gentlest = candidates[1] if len(candidates) > 1 else candidates[0]
    if gentlest[1].n_terms > max_terms:
        # The gentlest pruning left too many terms: also try the best max_terms terms.
        capped = prune_to(best, train, max_terms)
        prog.say(f"tau {best.tau * 1e3:.0f} ms: the {capped.n_terms} largest terms")
        capped = fit_refine(capped, iterations)
        candidates.append((score(capped, f"largest {max_terms}"), capped))
    eligible = [c for c in candidates if c[1].n_terms <= max_terms]
    if eligible:
        chosen = min(eligible, key=lambda pair: pair[0])[1]
    else:
        chosen = min(candidates, key=lambda pair: pair[1].n_terms)[1]
    return chosen, records


def _ticker(prog: _Progress) -> Callable[[int, float], None]:
    def tick(_call: int, loss: float) -> None:
        prog.step()
        prog.bar.set_postfix_str(f"loss {loss:.4f}")

    return tick


# -- the command ------------------------------------------------------------------------
def _digest(path: Path) -> str:
    """The file's SHA-256: two names of one flight are one flight."""
    import hashlib

    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _resolve_test(
    data_dir: Path, test_files: Sequence[str | Path] | None
) -> tuple[list, list, str]:
    paths = sorted(data_dir.glob("*.parquet"))
    if test_files:
        tests = []
        for f in test_files:
            path = Path(f)
            if not path.exists() and (data_dir / path).exists():
                path = data_dir / path
            if not path.exists():
                raise FileNotFoundError(f"no such test flight: {f}")
            tests.append(path)
        test_set = {p.resolve() for p in tests}
        # a test flight copied into the data folder under another name is the same flight:
        # by content, not path, it stays out of training (a judge's renamed copy leaked)
        digests = {_digest(p) for p in tests}
        train = [p for p in paths if p.resolve() not in test_set and _digest(p) not in digests]
        return train, tests, "the given test flights"
    train, tests = split_flights(paths)
    return train, tests, "flights held out from the training families (last run of each)"


def run_benchmark(
    data_dir: str | Path,
    test_files: Sequence[str | Path] | None,
    out: str | Path,
    horizon: int = HORIZON,
    taus: Sequence[float] = (0.0, 0.02, 0.04),
    prune_fractions: Sequence[float] = (0.05, 0.1),
    max_terms: int = 60,
    stride: int = 25,
    iterations: int = 25,
    refit_all: bool = True,
    figures: bool = True,
    progress: bool = True,
) -> dict[str, Any]:
    """Identifies a model from the training flights and runs the protocol on the test flights.

    Args:
        data_dir: Folder of training flights (``*.parquet``, benchmark format).
        test_files: Test flights (any parquet of this format); None: hold out the last run of
            every family in ``data_dir`` (and say so in the report).
        out: Output folder: ``metrics.json``, ``report.md``, ``model.json``, figures.
        horizon: Steps per open-loop window (the benchmark's 50).
        taus: Actuator time constants tried [s].
        prune_fractions: Pruning levels tried for the best tau.
        max_terms: Largest number of identified terms a chosen model may have.
        stride: Training windows start every ``stride`` samples.
        iterations: L-BFGS iterations per refinement.
        refit_all: After selection, refine the chosen model on all training flights
            (selection flights included).
        figures: Write the figures.
        progress: Show a progress bar.

    Returns:
        The metrics dictionary (also written to ``metrics.json``).
    """
    t_start = time.perf_counter()
    data_dir, out = Path(data_dir), Path(out)
    if not data_dir.is_dir():
        raise FileNotFoundError(f"no such data folder: {data_dir}")
    train_paths, test_paths, split = _resolve_test(data_dir, test_files)
    fit_paths, val_paths = split_flights(train_paths)
    if not fit_paths or not val_paths:
        raise ValueError(
            f"need at least two training flights of some family in {data_dir}, got "
            f"{len(train_paths)} after holding out the test flight(s) "
            f"{', '.join(p.name for p in test_paths)}"
        )
    steps = len(taus) * (iterations // 2 + 3)
    steps += (len(prune_fractions) + int(refit_all)) * (iterations + 6) + 12
    prog = _Progress(steps, progress)
    threads = torch.get_num_threads()
    # Small batched ops: one thread is fastest, and it does not fight other jobs for cores.
    torch.set_num_threads(1)
    try:
        fit = [read_flight(p) for p in fit_paths]
        val = [read_flight(p) for p in val_paths]
        tests = [read_flight(p) for p in test_paths]
        prog.say(f"read {len(fit)} fit, {len(val)} selection and {len(tests)} test flights")
        model, records = identify(
            fit, val, taus, prune_fractions, max_terms, horizon=horizon, stride=stride,
            iterations=iterations, progress=prog,
        )  # fmt: skip
        if refit_all:
            prog.say("refining the chosen model on all training flights")
            everything = fit + val
            windows = make_windows(everything, horizon, stride, model.actuator_states)
            meta = dict(model.meta)
            model = refine(model, windows, loss_scales(windows), iterations, progress=_ticker(prog))
            model.meta = dict(meta, refit_all=True)
        t_identified = time.perf_counter()
        model.meta.update(
            {
                "train_files": [p.name for p in train_paths],
                "selection_files": [p.name for p in val_paths],
            }
        )
        prog.say("benchmark protocol on the test flights")
        windows = make_windows(tests, horizon, 1, model.actuator_states)
        tick = prog.step
        results = {
            "sindy": mae_by_horizon(rotorcraft_predictor(model), windows, tick=tick),
            "physics": mae_by_horizon(lambda w: physics_rollout(w.x0, w.omega), windows, tick=tick),
            "hold": mae_by_horizon(lambda w: hold_rollout(w.x0, w.omega), windows, tick=tick),
        }
    finally:
        prog.close()
        torch.set_num_threads(threads)
    t_end = time.perf_counter()
    metrics: dict[str, Any] = {
        "models": {name: summarise(mae) for name, mae in results.items()},
        "test_files": [str(p) for p in test_paths],
        "windows": len(windows),
    }
    metrics["models"]["sindy"] = {"n_terms": model.n_terms, **metrics["models"]["sindy"]}
    metrics.update(
        {
            "split": split,
            "train_files": [p.name for p in train_paths],
            "selection_files": [p.name for p in val_paths],
            "thrust_coefficient": model.thrust_coefficient,
            "thrust_coefficient_nominal": NANODRONE_NOMINAL.thrust_coefficient,
            "tau": model.tau,
            "selection": records,
            "cleaning": {
                p.name: tr.meta["cleaning"] for p, tr in zip(test_paths, tests, strict=True)
            },
            "seconds": {"identify": t_identified - t_start, "total": t_end - t_start},
        }
    )
    out.mkdir(parents=True, exist_ok=True)
    model.save(out / "model.json")
    write_json(out / "metrics.json", metrics)
    write_json(
        out / "mae_by_horizon.json",
        {name: {g: mae[g].tolist() for g in GROUPS} for name, mae in results.items()},
    )
    if figures:
        plot_error_vs_horizon(results, out / "error_vs_horizon.png")
        plot_windows(model, tests, out / "windows.png", horizon)
    atomic_write_text(out / "report.md", report_markdown(metrics, model))
    return metrics


# -- report and figures -----------------------------------------------------------------
def comparison_rows(metrics: dict[str, Any]) -> list[tuple[str, list[float], list[float]]]:
    """(model, h = 50 MAE per group, SimErr per group): ours first, then the published ones."""
    labels = {"sindy": "SINDy rotorcraft (ours)", "physics": "nominal physics (ours)"}
    labels["hold"] = "hold the state (ours)"
    rows = []
    for key, label in labels.items():
        m = metrics["models"][key]
        rows.append((label, [m["mae"]["50"][g] for g in GROUPS], [m["simerr"][g] for g in GROUPS]))
    for label, pub in PUBLISHED.items():
        rows.append((f"{label} (published, melon)", list(pub["h50"]), list(pub["simerr"])))
    return rows


def beats_published(metrics: dict[str, Any]) -> dict[str, dict[str, bool]]:
    """Whether ours beats every published model at h = 50 and in SimErr, per group."""
    ours = metrics["models"]["sindy"]
    out: dict[str, dict[str, bool]] = {"h50": {}, "simerr": {}}
    for i, g in enumerate(GROUPS):
        out["h50"][g] = all(ours["mae"]["50"][g] < p["h50"][i] for p in PUBLISHED.values())
        out["simerr"][g] = all(ours["simerr"][g] < p["simerr"][i] for p in PUBLISHED.values())
    return out


def report_markdown(metrics: dict[str, Any], model: RotorcraftModel) -> str:
    """The report: split, comparison table, short horizons, equations, timings."""

    def fmt(values: Sequence[float], digits: int) -> str:
        return " / ".join(f"{v:.{digits}f}" for v in values)

    def verdict(flags: dict[str, bool]) -> str:
        return ", ".join(f"{g} {'yes' if ok else 'NO'}" for g, ok in flags.items())

    lines = [
        "# Nano-drone benchmark: SINDy rotorcraft model",
        "",
        f"Test flights ({metrics['split']}): "
        + ", ".join(Path(p).name for p in metrics["test_files"])
        + f"; {metrics['windows']} windows of 50 steps.",
        "Training flights: "
        + ", ".join(metrics["train_files"])
        + "; model selection on "
        + ", ".join(metrics["selection_files"])
        + " only.",
        "",
        "Published rows are the paper's numbers on its test flight `melon`"
        + (
            "; ours are on the same flight(s)"
            if any(flight_family(p)[0] == "melon" for p in metrics["test_files"])
            else " (not among the test flights here, so compare with care)"
        )
        + ". All our rows are scored on the same repaired logs.",
        "",
        "| model | h = 50 MAE: position / velocity / attitude / rates | SimErr |",
        "|---|---|---|",
    ]
    for label, h50, sim in comparison_rows(metrics):
        lines.append(f"| {label} | {fmt(h50, 3)} | {fmt(sim, 2)} |")
    hold_ours = [metrics["models"]["hold"]["mae"]["50"][g] for g in GROUPS]
    hold_pub = PUBLISHED["hold the state"]["h50"]
    lines += [
        "",
        "The same h = 50 MAE divided by holding the state on the same flights (a rough way to "
        "compare across different test flights; lower is better):",
        "",
        "| model | position / velocity / attitude / rates |",
        "|---|---|",
    ]
    for label, h50, _ in comparison_rows(metrics):
        ref = hold_pub if "published" in label else hold_ours
        lines.append(f"| {label} | {fmt([a / b for a, b in zip(h50, ref, strict=True)], 2)} |")
    lines += ["", "Short horizons (MAE, position / velocity / attitude / rates):", ""]
    lines += ["| model | h = 1 | h = 10 | h = 25 |", "|---|---|---|---|"]
    for key in ("sindy", "physics", "hold"):
        m = metrics["models"][key]["mae"]
        row = [fmt([m[h][g] for g in GROUPS], 4) for h in ("1", "10", "25")]
        lines.append(f"| {key} | " + " | ".join(row) + " |")
    beats = beats_published(metrics)
    short = {
        h: {g: metrics["models"]["sindy"]["mae"][h][g] <= metrics["models"]["hold"]["mae"][h][g]
            for g in GROUPS}
        for h in ("1", "10")
    }  # fmt: skip
    kc = metrics["thrust_coefficient"] / metrics["thrust_coefficient_nominal"] - 1.0
    lines += [
        "",
        "Figures to reach:",
        "",
        f"- beats every published model at h = 50: {verdict(beats['h50'])}",
        f"- beats every published model in SimErr: {verdict(beats['simerr'])}",
        f"- no worse than holding the state at h = 1: {verdict(short['1'])}; "
        f"at h = 10: {verdict(short['10'])}",
        f"- identified terms: {model.n_terms} (at most 60)",
        f"- thrust term (w' per W): {metrics['thrust_coefficient']:.4g} m/rad^2, "
        f"{100 * kc:+.1f} % from Kt/m = {metrics['thrust_coefficient_nominal']:.4g}",
        f"- actuator time constant chosen: {1e3 * model.tau:.0f} ms",
        f"- time: identify {metrics['seconds']['identify']:.0f} s, "
        f"total {metrics['seconds']['total']:.0f} s",
        "",
        "## Identified model",
        "",
        "```",
        *model.equations(),
        "```",
        "",
        "Terms: " + "; ".join(f"`{k}` {v}" for k, v in FEATURES_DOC.items()),
        "",
        "## Model selection (validation flights, score = mean SimErr / hold SimErr)",
        "",
        "| tau [ms] | candidate | terms | score |",
        "|---|---|---|---|",
    ]
    for rec in metrics["selection"]:
        cells = [f"{1e3 * rec['tau']:.0f}", rec["candidate"], str(rec["n_terms"])]
        lines.append("| " + " | ".join([*cells, f"{rec['score']:.3f}"]) + " |")
    lines += ["", "## Log repairs (test flights)", ""]
    from identification.logs import CleaningReport

    for name, cleaning in metrics["cleaning"].items():
        lines.append(f"- {name}: {CleaningReport(**cleaning).summary()}")
    return "\n".join(lines) + "\n"


def plot_error_vs_horizon(results: dict[str, dict[str, np.ndarray]], path: Path) -> Path:
    """MAE against horizon per group, with the published h = 50 values as markers."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    units = {"position": "m", "velocity": "m/s", "attitude": "rad", "rates": "rad/s"}
    fig, axes = plt.subplots(1, 4, figsize=(16, 3.6))
    for i, (ax, g) in enumerate(zip(axes, GROUPS, strict=True)):
        for name, mae in results.items():
            ax.plot(np.arange(1, mae[g].size + 1), mae[g], label=name)
        for label, pub in PUBLISHED.items():
            ax.plot([50], [pub["h50"][i]], "x", label=f"{label} (published, h=50)")
        ax.set_title(g)
        ax.set_xlabel("horizon h [steps of 10 ms]")
        ax.set_ylabel(f"MAE [{units[g]}]")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    return _save(fig, path)


def plot_windows(
    model: RotorcraftModel, trajs: Sequence[Trajectory], path: Path, horizon: int = HORIZON
) -> Path:
    """Predicted against measured over one 0.5 s window of each test flight (up to four).

    The window of a flight starts where its roll and pitch rates are largest (the hardest
    part for the rotational dynamics), away from the ends.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = [(0, "x [m]"), (2, "z [m]"), (3, "phi [rad]"), (4, "theta [rad]")]
    panels += [(9, "p [rad/s]"), (10, "q [rad/s]")]
    flights = list(trajs)[:4]
    fig, axes = plt.subplots(
        len(panels), len(flights), figsize=(3.6 * len(flights), 1.7 * len(panels)),
        sharex=True, squeeze=False,
    )  # fmt: skip
    steps = np.arange(horizon + 1) * model.dt
    with torch.no_grad():
        for c, traj in enumerate(flights):
            n = len(traj)
            rate = np.abs(traj.x[:, 9]) + np.abs(traj.x[:, 10])
            lo, hi = min(100, n // 4), max(n - horizon - 100, n // 4 + 1)
            s = lo + int(np.argmax(rate[lo:hi]))
            act = model.actuator_states(traj.u)
            u_seq = traj.u[None, s : s + horizon]
            pred = model.rollout(traj.x[s : s + 1], act[s : s + 1], u_seq)[0].numpy()
            phys = physics_rollout(traj.x[s : s + 1], u_seq)[0].numpy()
            pred = np.vstack([traj.x[s], pred])
            phys = np.vstack([traj.x[s], phys])
            for r, (col, label) in enumerate(panels):
                ax = axes[r, c]
                ax.plot(steps, traj.x[s : s + horizon + 1, col], "k", lw=1.2, label="measured")
                ax.plot(steps, pred[:, col], "C0", label="SINDy rotorcraft")
                ax.plot(steps, phys[:, col], "C1--", label="nominal physics")
                if c == 0:
                    ax.set_ylabel(label)
                ax.grid(alpha=0.3)
            name = Path(traj.meta.get("source", "")).stem
            axes[0, c].set_title(f"{name}, t0 = {traj.t[s]:.2f} s", fontsize=9)
            axes[-1, c].set_xlabel("time in window [s]")
    axes[0, 0].legend(fontsize=7)
    fig.tight_layout()
    return _save(fig, path)


def _save(fig: Any, path: Path) -> Path:
    import io

    import matplotlib.pyplot as plt

    from quad_envs.fileio import atomic_write_bytes

    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=110)
    plt.close(fig)
    return atomic_write_bytes(path, buffer.getvalue())
