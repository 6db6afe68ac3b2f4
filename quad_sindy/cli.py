"""The ``quad-sindy`` command line: thin wrappers that parse arguments and call the library.

A user's mistake (a bad option value, a missing or malformed file, an output that cannot be
written) ends with one line ``error: ...`` on stderr and exit status 2, never a traceback.
Outputs are checked for writability before any long computation starts.
"""

from __future__ import annotations

import math
import os
import re
import stat
import sys
from enum import Enum
from pathlib import Path
from typing import Annotated, Any

import typer

from quad_envs.vehicles import VEHICLES
from quad_sindy import __version__

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="Gymnasium quadrotor environments and SINDy identification from data alone.",
)
bench_app = typer.Typer(no_args_is_help=True, help="Speed benchmarks (numbers and ratios).")
app.add_typer(bench_app, name="bench")


SystemName = Enum("SystemName", {name: name for name in VEHICLES}, type=str)
"""The registered vehicles (``quad_envs.vehicles.VEHICLES``) as command-line choices."""
TimeUnit = Enum("TimeUnit", {name: name for name in ("s", "ms", "us", "ns")}, type=str)
AngleUnit = Enum("AngleUnit", {name: name for name in ("rad", "deg")}, type=str)
RADIANS_PER = {"rad": 1.0, "deg": math.pi / 180.0}
"""Units of a numeric time column."""
SECONDS_PER = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}

PresetName = Enum("PresetName", {name: name for name in ("planar", "quad6dof")}, type=str)
"""The vehicles whose variable names and library ``identify`` knows."""


def _shifted(trajs: list, rows: int) -> tuple[list, str]:
    """The segments with their inputs shifted ``rows`` rows, and a note on those too short."""
    kept = [t.shift_inputs(rows) for t in trajs if len(t) - abs(rows) >= 3]
    if not kept:
        _fail(f"every segment (the longest has {max(len(t) for t in trajs)} rows) is too short "
              f"to shift its inputs {rows} rows")  # fmt: skip
    short = len(trajs) - len(kept)
    return kept, (f"; {short} segment(s) too short for the shift left out" if short else "")


def _lagged(trajs: list, tau: float) -> tuple[list, str]:
    """The segments with their held inputs lagged ``tau`` s, and what was lagged (one line)."""
    from identification.data import LAG_SETTLE, lag_segments

    try:
        kept, short = lag_segments(trajs, tau)
    except ValueError as exc:
        _fail(f"--input-lag: {exc}")
    held = [n for n in trajs[0].input_names if n not in trajs[0].measured]
    short_note = f"; {short} segment(s) too short for it left out" if short else ""
    return kept, (f"{', '.join(held)} acting through a first-order lag of {tau:g} s "
                  f"(--input-lag; each segment's first {LAG_SETTLE * tau:g} s left out, while "
                  f"the actuators' start settles){short_note}")  # fmt: skip


def _drifted(trajs: list, drift: Any) -> tuple[list, str]:
    """The segments with their held inputs' gain drifting, and what (one line)."""
    from identification.data import drift_segments, drift_terms, drift_text

    try:
        kept = drift_segments(trajs, drift_terms(drift))
    except (TypeError, ValueError) as exc:
        _fail(f"--input-drift: {exc}")
    held = [n for n in trajs[0].input_names if n not in trajs[0].measured]
    return kept, f"{', '.join(held)} with {drift_text(drift_terms(drift))} (--input-drift)"


def _drift_option(text: str) -> tuple[float, float] | None:
    """``--input-drift``: None for auto, else ``(a1, a2)`` (refused in one line)."""
    if text.strip().lower() == "auto":
        return None
    parts = text.split(",")
    try:
        values = [float(p) for p in parts]
    except ValueError:
        values = [math.nan]
    if not (1 <= len(values) <= 2 and all(math.isfinite(v) for v in values)):
        _fail(f"--input-drift is 'auto', A1 or A1,A2 (the gain 1 + A1 t + A2 t^2, t in "
              f"seconds from each log's first row), got {text!r}")  # fmt: skip
    return values[0], values[1] if len(values) > 1 else 0.0


def _lag_option(text: str) -> float | None:
    """``--input-lag``: None for auto, else the time constant [s] (refused in one line)."""
    if text.strip().lower() == "auto":
        return None
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value >= 0):
        _fail(f"--input-lag is 'auto' or a time constant >= 0 in seconds, got {text!r}")
    return value


def _names(text: str | None) -> list[str] | None:
    """A comma-separated option as a list of names (None when not given; empty: refused)."""
    if text is None:
        return None
    names = [c.strip() for c in text.split(",") if c.strip()]
    if not names:  # (--states "" counted as not given)
        _fail(f"an option names no column ({text!r}): leave it out, or name the columns")
    return names


def _states_taken(states: tuple[str, ...]) -> str:
    """The line naming the columns taken for states when ``--states`` was not given."""
    return (f"states: {', '.join(states)} (the columns that are not the time or an input; "
            "--states chooses)")  # fmt: skip


def _fail(message: str) -> None:
    typer.secho(f"error: {message}", fg=typer.colors.RED, err=True)
    raise typer.Exit(2)


def _writable_folder(folder: Path) -> None:
    """Fails unless ``folder`` exists or can be created, and can be written."""
    if folder.exists() and not folder.is_dir():
        _fail(f"{folder} is a file, not a folder")
    existing = next((p for p in (folder, *folder.parents) if p.exists()), Path("."))
    if not existing.is_dir():
        _fail(f"cannot write to {folder}: {existing} is a file, not a folder")
    if not os.access(existing, os.W_OK | os.X_OK):
        _fail(f"cannot write to {folder}: {existing} is not writable")


def _writable_file(path: Path, inputs: tuple | list = (), flag: str = "--out") -> None:
    """Fails unless a file can be written at ``path`` (checked before the work starts).

    It fails too where ``path`` is one of the ``inputs``: the user's data would be overwritten.
    """
    if path.is_dir():
        _fail(f"{path} is a directory; give a file name")
    if path.exists() and not path.is_file():
        _fail(f"{path} is not a regular file (a device, FIFO or socket); give a file name")
    if any(p.exists() and path.exists() and os.path.samefile(p, path) for p in inputs):
        _fail(f"{flag} {path} is one of the input files: writing it would overwrite the data")
    _writable_folder(path.parent)


def _file_name(value: str) -> Path:
    """Reads a file option's value; a name ending in a separator names a folder, not a file.

    (``Path`` drops a trailing separator or ``/.``: ``--out models/`` wrote a file ``models``.)
    """
    if value.endswith(("/", os.sep)) or os.path.basename(value) in ("", ".", ".."):
        raise typer.BadParameter(f"{value} names a folder; give a file name")
    return Path(value)


def _finite(flag: str, value: float, low: float = 0.0, strict: bool = True) -> None:
    """Fails unless ``value`` is finite and above ``low`` (or at least ``low``)."""
    if not (math.isfinite(value) and (value > low if strict else value >= low)):
        bound = f"{'above' if strict else 'at least'} {low:g}"
        _fail(f"{flag} must be a finite number {bound}, got {value}")


MAX_ROWS = 10_000_000
"""Most rows one ``simulate`` run writes (a CSV of about 2 GB)."""


def _version(value: bool) -> None:
    if value:
        typer.echo(f"quad-sindy {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[
        bool,
        typer.Option("--version", callback=_version, is_eager=True, help="print the version"),
    ] = False,
) -> None:
    """Gymnasium quadrotor environments and SINDy identification from data."""


VehicleOption = Annotated[
    str | None,
    typer.Option(help="vehicle preset of the env: paper (default), crazyflie or pelican"),
]
ParamOption = Annotated[
    list[str] | None,
    typer.Option(help="NAME=VALUE: set one vehicle parameter of the env (repeat; e.g. mass=0.6)"),
]


def _effects(text: str) -> str | list[str]:
    """``--effects`` text: ``all`` or a list of effect names."""
    names = [e.strip() for e in text.split(",") if e.strip()]
    return "all" if names == ["all"] else names


def _vehicle_options(vehicle: str | None, param: list[str] | None) -> dict[str, object]:
    """Env options for ``--vehicle`` and ``--param`` (the vehicle a model was identified on)."""
    options: dict[str, object] = {"vehicle": vehicle} if vehicle else {}
    changes = {}
    for item in param or []:
        name, sep, value = item.partition("=")
        if not sep or not name.strip() or not value.strip():
            _fail(f"--param takes NAME=VALUE, got {item!r}")
        changes[name.strip()] = value.strip()
    if changes:
        options["params"] = changes
    return options


@app.command()
def simulate(
    out: Annotated[Path, typer.Option(help="CSV file to write", parser=_file_name, metavar="FILE")],
    case: Annotated[str, typer.Option(help="A, B, C or a trajectory name")] = "C",
    system: Annotated[SystemName, typer.Option(help="vehicle model")] = SystemName.planar,
    dt: Annotated[float, typer.Option(help="control and sample period [s]")] = 0.01,
    duration: Annotated[float, typer.Option(help="final time [s]")] = 10.0,
    vehicle: Annotated[
        str | None, typer.Option(help="parameter preset: paper, crazyflie or pelican")
    ] = None,
    param: Annotated[
        list[str] | None,
        typer.Option(help="NAME=VALUE: set one vehicle parameter (repeat; e.g. mass=0.5)"),
    ] = None,
) -> None:
    """Flies a reference under the vehicle's controller; writes t, states, inputs, references.

    The input columns (``u1, u2``) hold the inputs the rotors applied (after saturation);
    the controller's commands follow as ``u1_cmd, u2_cmd``. ``--vehicle`` and ``--param``
    fly another vehicle (the controller's gains scale to it), for example
    ``--param mass=0.5 --param Ixx=3e-3 --param rotor_force_max=4.9``.
    """
    import numpy as np

    from quad_envs.fileio import write_csv
    from quad_envs.params import get_preset, with_changes
    from quad_envs.simulate import simulate_case
    from quad_envs.vehicles import get_vehicle

    _finite("--dt", dt)
    _finite("--duration", duration)
    if duration / dt < 2:  # (a fuzz trial's --dt 5 --duration 1 wrote one row)
        _fail(f"--duration {duration:g} at --dt {dt:g} is under 2 rows: a log needs steps")
    if duration / dt > MAX_ROWS:
        _fail(f"--duration {duration:g} at --dt {dt:g} is {duration / dt:.3g} rows; at most "
              f"{MAX_ROWS:,} per run")  # fmt: skip
    _writable_file(out)
    try:
        veh = get_vehicle(system.value)
        if vehicle is not None:
            if system.value not in ("planar", "quad6dof"):
                _fail(f"--vehicle presets are for planar and quad6dof, not {system.value}")
            veh = veh.with_params(get_preset(vehicle, system.value))
        changes = _vehicle_options(None, param).get("params")
        if changes:
            veh = veh.with_params(with_changes(veh.params, changes))
        run = simulate_case(case, veh, dt=dt, duration=duration)
    except ValueError as exc:
        _fail(str(exc))
    header, rows = run.table()
    bad = ~np.isfinite(rows).all(axis=1)
    if bad.any():
        _fail(f"the simulation gave non-finite numbers at t = {run.t[bad][0]:g} s (--dt "
              f"{dt:g} too coarse for the vehicle, or a parameter it cannot fly with)")  # fmt: skip
    write_csv(out, header, rows)
    typer.echo(f"wrote {len(rows)} rows to {out}")
    angles = [i for i, n in enumerate(run.vehicle.state_names) if n in ("phi", "theta")]
    worst = float(np.max(np.abs(run.states[:, angles]))) if angles else 0.0
    if worst > np.pi / 2:
        typer.echo(f"warning: the vehicle tumbled (a tilt of {worst:.3g} rad): its controller "
                   f"does not hold it on this reference at --dt {dt:g}")  # fmt: skip


FLIGHTS_IGNORE = {
    "rotor_time_constant", "thrust_coefficient", "drag_linear_xy", "drag_linear_z",
    "drag_quadratic_xy", "drag_quadratic_z",
}  # fmt: skip
"""Vehicle parameters of effects that ``flights`` does not fly (it is the rigid body)."""


MAX_FLIGHT_ROWS = 10**7
"""The most rows ``flights`` writes in one run (about 1 GB of CSV; a fuzzed 1e10 asked 75 GB)."""


FLIGHTS_RECORD = "flights.json"
"""What ``flights`` wrote into a folder (its options, its files): flight files beside it may be
replaced by a rerun; others are a user's and never are."""


def _json_object(path: Path) -> dict | None:
    """A JSON file's top-level object (None where it is missing, unreadable or no object)."""
    import json

    try:
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, RecursionError):
        return None
    return data if isinstance(data, dict) else None


def _flights_written(folder: Path) -> set[str]:
    """The flight files a ``flights.json`` in ``folder`` records (none without one)."""
    files = (_json_object(folder / FLIGHTS_RECORD) or {}).get("files")
    return {f for f in files if isinstance(f, str) and re.fullmatch(r"flight_\d+\.csv", f)
            } if isinstance(files, list) else set()  # fmt: skip


@app.command()
def flights(
    out: Annotated[Path, typer.Option(help="folder for the flights (flight_K.csv)")],
    system: Annotated[str, typer.Option(help="planar or quad6dof")] = "planar",
    vehicle: VehicleOption = None,
    param: ParamOption = None,
    count: Annotated[int | None, typer.Option(help="flights (default 3 planar, 4 6-DOF)")] = None,
    steps: Annotated[int, typer.Option(help="samples per flight")] = 1000,
    dt: Annotated[float, typer.Option(help="sample and input-hold period [s]")] = 0.01,
    tilt: Annotated[float, typer.Option(help="tilt amplitude of the references [rad]")] = 0.2,
    excitation: Annotated[
        float, typer.Option(help="random input noise, fraction of the hover thrust")
    ] = 0.05,
    open_loop: Annotated[bool, typer.Option(help="hover thrust plus random sines, no PD")] = False,
    drag: Annotated[float, typer.Option(help="linear drag coefficient [N s/m]")] = 0.0,
    integrator: Annotated[str, typer.Option(help="rk4 | rk4x10 | solve_ivp")] = "rk4",
    noise: Annotated[float, typer.Option(help="Gaussian noise on the logged states")] = 0.0,
    seed: Annotated[int, typer.Option(help="seed of the flights and the noise")] = 0,
) -> None:
    """Identification flights of any vehicle: the data of the docs' figures, one CSV each.

    PD flights to random waypoints with input excitation (6-DOF: with a yaw sweep, which the
    ``simulate`` cases lack, so their 6-DOF data cannot separate the yaw terms), applied
    inputs recorded; identify them with ``quad-sindy identify OUT/flight_*.csv``.
    """
    import dataclasses

    from identification.data import write_trajectory_csv
    from identification.experiments.synthetic import (
        FlightSpec,
        add_noise,
        planar_flights,
        quad6dof_flights,
    )
    from quad_envs.fileio import write_json
    from quad_envs.params import check_can_hover, get_preset, with_changes

    if system not in ("planar", "quad6dof"):
        _fail(f"--system is planar or quad6dof, not {system!r}")
    if (count is not None and count < 1) or steps < 20:
        _fail(f"--count must be positive and --steps at least 20, got {count} and {steps}")
    if (count or 4) * steps > MAX_FLIGHT_ROWS:
        _fail(f"--count x --steps must be at most {MAX_FLIGHT_ROWS:,} rows, got {count or 4} x "
              f"{steps:,} (the docs' figures fly 3 or 4 flights of 1000 rows)")  # fmt: skip
    _finite("--dt", dt)
    _finite("--tilt", tilt)
    for flag, value in (("--noise", noise), ("--excitation", excitation), ("--drag", drag)):
        _finite(flag, value, strict=False)
    if not 1e-4 <= dt <= 1.0 or noise > 1.0:  # (a fuzz trial's 1e-300 s and 1e300 noise)
        _fail(f"--dt must be from 1e-4 to 1 s and --noise at most 1 (a standard deviation "
              f"in the states' units), got {dt:g} and {noise:g}")  # fmt: skip
    if seed < 0:
        _fail(f"--seed must be a non-negative integer, got {seed}")
    _writable_folder(out)
    wanted = count or (3 if system == "planar" else 4)
    ours = _flights_written(out)  # what an earlier flights run wrote here (flights.json)
    stale = sorted(p.name for p in out.glob("flight_*.csv")
                   if p.stem.removeprefix("flight_").isdigit()
                   and int(p.stem.removeprefix("flight_")) >= wanted
                   and p.name not in ours)  # fmt: skip
    if stale:
        _fail(f"{out} holds {', '.join(stale[:3])}{' ...' if len(stale) > 3 else ''} that "
              f"{wanted} flight(s) would not replace, and {out}/flight_*.csv would mix them: "
              "choose a new folder or remove them")  # fmt: skip
    targets = [out / f"flight_{k}.csv" for k in range(wanted)]
    for p in targets:  # checked before any is written (a run refused halfway mixed two)
        if p.exists() and not p.is_file():
            _fail(f"{p} is not a file: choose a new folder or remove it")
        if p.is_file() and not p.stat().st_mode & stat.S_IWUSR:
            _fail(f"{p} is read-only: choose a new folder, or make it writable")
    foreign = [p.name for p in targets if p.exists() and p.name not in ours]
    if foreign:  # a user's own files are never replaced
        _fail(f"{out} holds {len(foreign)} flight file(s) ({', '.join(foreign[:3])}"
              f"{' ...' if len(foreign) > 3 else ''}) that no {FLIGHTS_RECORD} beside them "
              "records as written by flights (your own, or an older version's): choose a new "
              "folder or move them")  # fmt: skip
    try:
        params = get_preset(vehicle or "paper", system)
        changes = _vehicle_options(None, param).get("params")
        if changes:
            params = with_changes(params, changes)
            unused = sorted(set(changes) & FLIGHTS_IGNORE)
            if unused:  # accepted before and the flights were the same byte for byte
                _fail(
                    f"flights fly the rigid body and do not use {', '.join(unused)} (linear "
                    "drag: --drag; rotor lag and the other effects: the envs' effects= option)"
                )
        check_can_hover(params)
        spec = FlightSpec(flights=wanted, steps=steps, dt=dt,
                          integrator=integrator, open_loop=open_loop, tilt=tilt,
                          excitation=excitation, drag=drag, seed=seed)  # fmt: skip
        make = planar_flights if system == "planar" else quad6dof_flights
        trajs = make(params, spec)
    except ValueError as exc:
        _fail(str(exc))
    if noise > 0:
        trajs = add_noise(trajs, noise, seed=100 + seed)
    out.mkdir(parents=True, exist_ok=True)
    names = [p.name for p in targets]
    extra = sorted(ours - set(names))  # an earlier run's further flights: they would mix
    record = {"command": "flights", "system": system, "vehicle": vehicle or "paper",
              "param": list(param or []), "spec": dataclasses.asdict(spec), "noise": noise,
              "files": names + extra}  # fmt: skip
    write_json(out / FLIGHTS_RECORD, record)  # first: it marks the folder's flights as ours
    for k, tr in enumerate(trajs):
        write_trajectory_csv(out / f"flight_{k}.csv", tr)
    if extra:
        for name in extra:
            (out / name).unlink(missing_ok=True)
        write_json(out / FLIGHTS_RECORD, {**record, "files": names})
    tilts = [j for j, n in enumerate(trajs[0].state_names) if n in ("phi", "theta")]
    flown = max(float(abs(tr.x[:, tilts]).max()) for tr in trajs)
    typer.echo(
        f"wrote {len(trajs)} flights of {steps} rows to {out}/ (identify them with: "
        f"quad-sindy identify {out}/flight_*.csv --out model.json); largest tilt flown "
        f"{flown:.2f} rad (--tilt {tilt:g} sets the references' amplitude, the controller's "
        "tracking the tilt)"
    )


@bench_app.command("envs")
def bench_envs_cmd(
    num_envs: Annotated[int, typer.Option(help="vector env size")] = 1024,
    seconds: Annotated[float, typer.Option(help="minimum timing per measurement [s]")] = 2.0,
) -> None:
    """Steps/s of both envs (single, vector; without and with every effect) vs Pendulum-v1.

    A peer (rotorpy's QuadrotorEnv) is measured too where the ``peers`` extra is installed.
    """
    import quad_envs
    from quad_sindy.bench import bench_envs

    if not (math.isfinite(seconds) and seconds > 0):
        _fail(f"--seconds must be a positive finite number, got {seconds:g}")
    rows = bench_envs(quad_envs.ENV_IDS, num_envs, seconds)
    typer.echo(f"{'env':<16} {'mode':<14} {'effects':<8} {'steps/s':>12} {'x Pendulum-v1':>14}")
    for row in rows:
        if "note" in row:
            typer.echo(row["note"])
            continue
        typer.echo(
            f"{row['env']:<16} {row['mode']:<14} {row['effects']:<8} "
            f"{row['steps_per_s']:>12,.0f} {row['ratio']:>14.2f}"
        )


class StudyName(str, Enum):
    """Studies of ``quad-sindy study``."""

    lambda_ = "lambda"
    dt = "dt"
    samples = "samples"
    noise = "noise"


def _shared_reference() -> Path | None:
    """The authors' case C file when ../shared sits beside the working directory or repo."""
    for base in (Path.cwd(), Path(__file__).resolve().parents[1]):
        candidate = base.parent / "shared" / "reference" / "paper_diamond_case_c.csv"
        if candidate.exists():
            return candidate
    return None


ANGLE_NAMES = (
    "phi", "theta", "psi", "alpha", "beta", "gamma", "roll", "pitch", "yaw", "heading", "bank",
    "angle", "ang", "attitude", "azimuth", "elevation", "bearing", "course",
)  # fmt: skip
"""Name parts that suggest an angle (a hint to declare it, nothing more)."""


def _looks_like_angle(name: str) -> bool:
    parts = re.split(r"[^a-z]+", name.lower())
    return any(p in ANGLE_NAMES for p in parts) and not any(
        p in ("dot", "rate", "d", "omega", "vel") for p in parts
    )


def _matching_rotor_preset(
    state_names: tuple[str, ...], input_names: tuple[str, ...]
) -> str | None:
    """The ``_rotors`` preset whose variables these are (a vehicle's states, T1..Tk, Tc1..Tck)."""
    from identification.libraries import rotor_names
    from quad_envs.vehicles import get_vehicle

    for name in ("planar", "quad6dof"):
        record = get_vehicle(name)
        thrusts, commands = rotor_names(int(record.params.mixer.shape[1]))
        if set(state_names) == {*record.state_names, *thrusts} and set(input_names) == set(
            commands
        ):
            return f"{name}_rotors"
    return None


def _with_extra_states(preset: str, extra: tuple[str, ...], angles: list[str]) -> list[str]:
    """A preset's library with the data's other states in the preset's form for a variable.

    Each other state enters alone and times sin and cos of each angle. The other columns
    may be unrelated (a battery voltage, a counter: a trial's clean 6-DOF log with three got
    68 terms for 36 in the generic library) or states the dynamics need (a recheck trial's
    wind state `w` in `y_dot'`: left out, 17 % at 1 s); with the preset's terms and these,
    the selection keeps what the data support.
    """
    from identification.features import parse_term, term_name
    from identification.libraries import default_library

    terms = [*extra, *(f"{fn}({a}) {e}" for e in extra for a in angles for fn in ("sin", "cos"))]
    variables = [*extra, *angles]
    return list(dict.fromkeys([*default_library(preset),
                               *(term_name(parse_term(t, variables)) for t in terms)]))  # fmt: skip


def _containing_vehicle(
    state_names: tuple[str, ...], input_names: tuple[str, ...]
) -> tuple[str | None, tuple[str, ...]]:
    """A preset vehicle whose inputs are these and whose states are among these.

    In any column order. Returns its name and the other columns (none where the variables
    are exactly its), or (None, ()).
    """
    from identification.libraries import PRESETS
    from quad_envs.vehicles import VEHICLES

    for name, record in VEHICLES.items():
        if name in PRESETS and set(record.input_names) == set(input_names):
            if set(record.state_names) <= set(state_names):
                return name, tuple(n for n in state_names if n not in record.state_names)
    return None, ()


@app.command()
def identify(
    data: Annotated[list[Path], typer.Argument(help="CSV, parquet or NPZ trajectory files")],
    out: Annotated[
        Path, typer.Option(help="model JSON to write", parser=_file_name, metavar="FILE")
    ],
    system: Annotated[
        PresetName | None, typer.Option(help="preset vehicle: its variable names and library")
    ] = None,
    columns: Annotated[
        str | None, typer.Option(help="names of a CSV's columns in order (replaces its header)")
    ] = None,
    time: Annotated[str, typer.Option(help="time column")] = "t",
    time_unit: Annotated[
        TimeUnit, typer.Option(help="unit of a numeric time column (timestamps are read as such)")
    ] = TimeUnit.s,
    angle_unit: Annotated[
        AngleUnit,
        typer.Option(
            help="unit of the angle states in the logs (converted to radians; rates keep theirs)"
        ),
    ] = AngleUnit.rad,
    states: Annotated[str | None, typer.Option(help="state columns, comma-separated")] = None,
    inputs: Annotated[str | None, typer.Option(help="input columns, comma-separated")] = None,
    angles: Annotated[str | None, typer.Option(help="angle states (Fourier terms)")] = None,
    measured: Annotated[
        str | None,
        typer.Option(
            help="inputs that are measured signals (a logged attitude), not commands held "
            "over each step: interpolated within the step"
        ),
    ] = None,
    library: Annotated[
        str | None,
        typer.Option(
            help="planar | quad6dof | planar_drag | quad6dof_drag | planar_rotors | "
            "quad6dof_rotors | a vehicle | FILE.toml | "
            "'degree=2;angles=phi;trig_degree=2;angle_products=true;extra=...'"
        ),
    ] = None,
    lam: Annotated[
        str, typer.Option("--lambda", help="'auto' (validated) or a threshold")
    ] = "auto",
    method: Annotated[str, typer.Option(help="rk4 | forward | central | smoothed | paper")] = "rk4",
    optimizer: Annotated[str, typer.Option(help="stepwise | stlsq | sr3 | ensemble")] = "stepwise",
    window: Annotated[str, typer.Option(help="integral window: 'auto' or steps")] = "auto",
    drop_outliers: Annotated[
        bool,
        typer.Option(
            help="cut out the steps whose residual stands out of their neighbours' (inputs "
            "that did not act as logged, glitches), and those beyond the hinges where the "
            "states respond less to extreme inputs (commands a rotor clipped), before "
            "selecting; by default they are reported"
        ),
    ] = False,
    keep_rest: Annotated[
        bool,
        typer.Option(
            help="keep rows where every state stays still while the model says they would "
            "move (a vehicle resting on the ground before take-off or after landing); by "
            "default they are left out with the steps that stand out next to them"
        ),
    ] = False,
    prewhiten: Annotated[
        bool | None,
        typer.Option(
            "--prewhiten/--no-prewhiten",
            help="fit rows prewhitened for equation errors correlated in time (unmeasured "
            "forces such as wind, which a controller answers, bias a plain fit; window 1); "
            "default: tried where the errors are, and kept unless it needs more than two "
            "extra terms",
            show_default=False,
        ),
    ] = None,
    input_shift: Annotated[
        int,
        typer.Option(
            help="take each row's inputs this many rows later (a log that records inputs a "
            "row late: 1; earlier if negative)",
            min=-100,
            max=100,
        ),
    ] = 0,
    input_lag: Annotated[
        str,
        typer.Option(
            help="time constant [s] of a first-order lag the held inputs act through (motors "
            "that lag the commands logged; 0: they act as logged); auto: as logged, and where "
            "the model's terms fit a lag of the inputs better, selected again with it and kept "
            "if it predicts the held-out data at least as well (with a fixed --lambda: named)",
            metavar="auto|SECONDS",
        ),
    ] = "auto",
    input_drift: Annotated[
        str,
        typer.Option(
            help="drift of the held inputs' gain: the vehicle applies 1 + A1 t + A2 t^2 times "
            "each logged input, t in seconds from its log's first row (a battery that sags: "
            "negative; 0: they act as logged); auto: as logged, and where the model's terms "
            "fit a drift (the halves of the logs disagree on an input's gain, or it passes "
            "its bar), selected again with it and kept if it predicts the held-out data "
            "better. The model is the vehicle at gain 1",
            metavar="auto|A1[,A2]",
        ),
    ] = "auto",
    plot: Annotated[
        Path | None,
        typer.Option(help="selection plot (default: OUT.png)", parser=_file_name, metavar="FILE"),
    ] = None,
) -> None:
    """Identifies a SINDy-with-control model from data alone and prints its equations.

    With ``--lambda auto`` the threshold and the integral window are chosen by
    cross-validated multi-step prediction on held-out parts of the data (no simulator).
    """
    import dataclasses

    from identification.data import PRESET_ANGLES, load_data
    from identification.diagnostics import (
        data_warnings,
        stamp_jitter,
        timing_note,
    )
    from identification.features import parse_term
    from identification.fit import FitConfig, fit
    from identification.libraries import library_from_spec, spec_angles
    from identification.scoring import long_enough, window_cap
    from identification.selection import WINDOWS, select_model, term_note_count
    from identification.support import long_run_ratio
    from quad_envs.fileio import atomic_write_bytes

    noted: tuple = ()  # (data, library) once both are known: their notes precede a refusal
    figure: tuple[Path, bytes] | None = None  # the selection plot, written with the model

    if library is not None and not library.strip():  # (read as no library, silently)
        _fail("--library is empty: leave it out for the default, or give a preset or spec")
    # (a scaled threshold: 1 already leaves out a term that explains the whole target)
    lam_value = _number_option("--lambda", lam, float, 0.0, 1e3) if lam != "auto" else None
    lag_value = _lag_option(input_lag)
    drift_value = _drift_option(input_drift)
    window_value = _number_option("--window", window, int, low=1) if window != "auto" else None
    _writable_file(out, data)  # before the selection, which may take a minute
    if lam_value is None and method != "paper":
        figure_path = plot or out.with_suffix(".png")
        if figure_path.resolve() == out.resolve():  # (the plot was written, then the model)
            _fail(f"the selection plot and --out are the same file {out}: give --out a .json "
                  "name, or --plot another file")  # fmt: skip
        _writable_file(figure_path, data, "--plot")

    try:
        preset = system.value if system else None
        if (
            preset is None
            and states is None
            and inputs is None
            and library in ("planar", "quad6dof")
        ):
            preset = library
        in_spec = list(spec_angles(library))
        if _names(angles) and in_spec and set(_names(angles) or ()) != set(in_spec):
            _fail(
                f"--angles {angles} and the library's angles={','.join(in_spec)} disagree: "
                "declare the angles once"
            )
        declared = _names(angles) or in_spec or list(PRESET_ANGLES.get(preset or "", ()))
        read = (data, _names(columns), preset, _names(states), _names(inputs), time.strip())
        unit = SECONDS_PER[time_unit.value]
        turn = RADIANS_PER[angle_unit.value]
        trajs, cleaning = load_data(*read, angles=declared, measured=_names(measured) or (),
                                    time_unit=unit, angle_unit=turn)  # fmt: skip
        first = trajs[0]
        library_note = None
        taken = first.state_names  # printed with the model: every other column is a state
        extended: list[str] | None = None  # a preset's library with the data's other states
        if preset is None and library is None and angles is None:
            owner, extra = _containing_vehicle(first.state_names, first.input_names)
            preset = owner if not extra else None  # exactly a preset's variables
            if extra and states is None:  # a preset's variables and other columns
                declared = list(PRESET_ANGLES.get(owner, ()))
                extended = _with_extra_states(owner, extra, declared)
                library_note = (
                    f"library: the {owner} vehicle's preset, with the other column(s) "
                    f"{', '.join(extra)} as states (each alone and times sin and cos of "
                    f"{', '.join(declared)}; {len(extended)} terms; --states leaves them out, "
                    "--library chooses another)"
                )
                trajs, cleaning = load_data(*read, angles=declared, measured=first.measured,
                                            time_unit=unit, angle_unit=turn)  # fmt: skip
                first = trajs[0]
            elif preset is not None:
                library_note = (
                    f"library: the {preset} vehicle's preset (the data's variables are its "
                    "variables; --library or --angles choose another)"
                )
                declared = list(PRESET_ANGLES.get(preset, ()))
                as_preset = (data, _names(columns), preset, None, None, time.strip())
                trajs, cleaning = load_data(*as_preset, angles=declared, measured=first.measured,
                                            time_unit=unit, angle_unit=turn)  # fmt: skip
                first = trajs[0]
            else:  # the default spec: states named as angles enter through sin and cos
                declared = [n for n in first.state_names if _looks_like_angle(n)]
                library = _matching_rotor_preset(first.state_names, first.input_names)
                if library is not None:  # (rollouts of an env with rotor dynamics)
                    library_note = (
                        f"library: the {library} preset (the data's variables are the "
                        f"{library.removesuffix('_rotors')} vehicle's states, its rotor thrusts "
                        "and their commands; --library or --angles choose another)"
                    )
                if declared:  # (a trial's rotor-thrust log: phi^2 and f1 phi, 1.9 % at 1 s)
                    trajs, cleaning = load_data(*read, angles=declared, measured=first.measured,
                                                time_unit=unit, angle_unit=turn)  # fmt: skip
                    first = trajs[0]
        if cleaning.changed:
            typer.echo(f"data: {cleaning.summary()}")
        if input_shift:
            trajs, dropped = _shifted(trajs, input_shift)
            first = trajs[0]
            typer.echo(f"data: inputs taken {abs(input_shift)} row(s) "
                       f"{'later' if input_shift > 0 else 'earlier'} (--input-shift)"
                       + dropped)  # fmt: skip
        if drift_value is not None and any(drift_value):
            if method == "paper":
                _fail("the paper's method has no input drift: leave out --input-drift")
            trajs, drifted = _drifted(trajs, drift_value)
            first = trajs[0]
            typer.echo(f"data: {drifted}")
        if lag_value:
            if method == "paper":
                _fail("the paper's method has no input lag: leave out --input-lag")
            trajs, lagged = _lagged(trajs, lag_value)
            first = trajs[0]
            typer.echo(f"data: {lagged}")
        if method == "paper":
            from identification.experiments.paper import PAPER_LAMBDA, fit_paper

            if preset != "planar":
                _fail("the paper's method is defined for the planar system only")
            model = fit_paper(trajs, PAPER_LAMBDA if lam_value is None else lam_value)
            for note in data_warnings(trajs):
                typer.echo(f"warning: {note}")
        else:
            lib = extended or library_from_spec(
                library or preset, first.state_names, first.input_names, declared
            )
            noted = (trajs, lib)
            as_power = {f.var for n in lib for f in parse_term(n) if f.kind == "pow"}
            looks = [n for n in first.state_names if _looks_like_angle(n) and n in as_power]
            if looks and not declared and preset is None:  # (a drag preset's angles are trig)
                typer.echo(
                    f"note: {', '.join(looks)} {'looks' if len(looks) == 1 else 'look'} like "
                    f"angle{'s' if len(looks) > 1 else ''} but no angle is declared: "
                    "angles enter only through sin and cos once declared (--angles, or angles= "
                    "in --library)"
                )
            unlike = [n for n in declared if not _looks_like_angle(n)]
            if unlike and preset is None:
                typer.echo(
                    f"note: {', '.join(unlike)} declared an angle without an angle's name: "
                    "a declared angle enters only through sin and cos, never as itself or "
                    "in powers (leave it out of --angles if it is not an angle)"
                )
            held = [n for n in first.input_names
                    if _looks_like_angle(n) and n not in first.measured]  # fmt: skip
            if held and preset is None:
                typer.echo(
                    f"note: input(s) {', '.join(held)} look like a logged attitude: if they are "
                    "measured signals rather than commands held over each step, declare them "
                    "with --measured (held, a changing tilt leaves terms of about g dt / 2)"
                )
            if library is None and preset is None and extended is None:
                trig = (
                    f", sin and cos of {', '.join(declared)} alone and times each variable"
                    + ("" if angles is not None else " (angles by their names; --angles "
                       "names others)")
                    if declared
                    else ""
                )  # fmt: skip
                library_note = (
                    f"library: polynomials of degree 2{trig} ({len(lib)} terms; --library "
                    "chooses another)"
                )
            config = FitConfig(derivative=method, optimizer=optimizer)
            label = preset or (library if library in ("planar", "quad6dof") else None)
            if lam == "auto":
                windows = WINDOWS if window_value is None else (window_value,)
                if window_value is not None and window_value >= window_cap(trajs):
                    _fail(
                        f"--window {window_value} does not fit the data: windows must be under "
                        f"{window_cap(trajs)} (a quarter of the segments that hold half of the "
                        "rows)"
                    )
                if prewhiten is None and window_value not in (None, 1):
                    prewhiten = False  # a prewhitened fit is at window 1: the window asked
                model, report = select_model(
                    trajs, lib, config=config, windows=windows, system=label, progress=True,
                    drop_outliers=drop_outliers, prewhiten=prewhiten, keep_rest=keep_rest,
                    input_lag=0.0 if lag_value == 0 else None,  # (a lag given: the data's)
                    input_drift=0.0 if drift_value == (0.0, 0.0) else None,
                )  # fmt: skip
                noted = ()  # printed with the report
                best = report.best
                if library_note:
                    typer.echo(library_note)
                if states is None and preset is None:
                    typer.echo(_states_taken(taken))
                typer.echo(
                    f"selection: window {best.window}, lambda {best.lam:g}, {best.n_terms} "
                    f"terms (score {best.mean:.3g} +- {best.se:.2g}, holding the state "
                    f"{report.hold:.3g}: {report.horizon}-step prediction error over each "
                    f"state's scale; {report.folds} folds)"
                    + _after_checks(best.n_terms, model.n_terms)
                )
                terms = term_note_count(report.warnings, model.state_names)
                for k, note in enumerate(report.warnings):
                    if terms and k == len(report.warnings) - terms:
                        typer.echo(f"({terms} notes on single equations' terms follow: near "
                                   "twins, terms dropped or kept)")  # fmt: skip
                    typer.echo(f"warning: {note}")
                # rendered now, written with the model (an interrupt left a new plot beside
                # the old model)
                figure = (plot or out.with_suffix(".png"), report.plot_png())
            else:
                if drop_outliers:
                    _fail("--drop-outliers works with the automatic selection (--lambda auto)")
                if keep_rest:
                    _fail("--keep-rest works with the automatic selection (--lambda auto): a "
                          "fixed lambda keeps every row")  # fmt: skip
                if prewhiten:
                    _fail("--prewhiten works with the automatic selection (--lambda auto)")
                config = dataclasses.replace(config, lam=lam_value, window=window_value or 1)
                trajs, stamped = stamp_jitter(trajs, lib)  # as select_model reads them
                if stamped:
                    typer.echo(f"warning: {stamped}")
                model = fit(trajs, lib, config, label)
                noted = ()
                if library_note:
                    typer.echo(library_note)
                if states is None and preset is None:
                    typer.echo(_states_taken(taken))
                notes = data_warnings(trajs, lib)  # select_model reports them itself
                if method in ("rk4", "forward"):
                    names, xi = list(model.feature_names), model.coefficients
                    ratio = long_run_ratio(
                        long_enough(trajs, config.window), names, xi, config.window
                    )
                    notes.append(timing_note(trajs, names, config.window, xi, ratio))
                for note in filter(None, notes):
                    typer.echo(f"warning: {note}")
    except (ValueError, FileNotFoundError) as exc:
        for note in data_warnings(*noted) if noted else ():  # the data's units may be the cause
            typer.echo(f"warning: {note}")
        _fail(str(exc).splitlines()[0] if str(exc) else repr(exc))
    model.meta["data"] = {**dataclasses.asdict(cleaning), "summary": cleaning.summary()}
    if input_shift:
        model.meta["input_shift"] = input_shift
    # how the logs were read: score reads held-out logs the same way by default
    model.meta["units"] = {"time": time_unit.value, "angles": angle_unit.value}
    model.meta["time_column"] = time
    model.save(out)
    if figure is not None:
        atomic_write_bytes(*figure)
    typer.echo("\n".join(model.equations()))
    typer.echo(f"wrote {out}")


@app.command()
def score(
    model: Annotated[Path, typer.Argument(help="identified model JSON")],
    data: Annotated[list[Path], typer.Argument(help="held-out CSV, parquet or NPZ files")],
    seconds: Annotated[float, typer.Option(help="prediction horizon [s]")] = 1.0,
    columns: Annotated[
        str | None,
        typer.Option(help="names of a CSV's columns in order (replaces its header, as identify)"),
    ] = None,
    time: Annotated[
        str | None, typer.Option(help="time column (default: as the model was trained)")
    ] = None,
    time_unit: Annotated[
        TimeUnit | None,
        typer.Option(help="unit of a numeric time column (default: as the model was trained)"),
    ] = None,
    angle_unit: Annotated[
        AngleUnit | None,
        typer.Option(help="unit of the angle states (default: as the model was trained)"),
    ] = None,
    input_shift: Annotated[
        int | None,
        typer.Option(
            help="take each row's inputs this many rows later (default: the model's own "
            "--input-shift from identify)",
            min=-100,
            max=100,
        ),
    ] = None,
    input_lag: Annotated[
        str | None,
        typer.Option(
            help="first-order lag [s] of the held inputs (default, or auto: the model's own, "
            "from identify)",
            metavar="auto|SECONDS",
            show_default=False,
        ),
    ] = None,
    input_drift: Annotated[
        str | None,
        typer.Option(
            help="drift A1[,A2] of the held inputs' gain (default, or auto: the model's own, "
            "from identify; 0: logs whose inputs act as logged, such as a fresh battery's "
            "first seconds or the applied inputs)",
            metavar="auto|A1[,A2]",
            show_default=False,
        ),
    ] = None,
) -> None:
    """Predicts held-out logs open loop with their recorded inputs: error after --seconds.

    From up to 64 evenly spread starts per segment, the model is simulated with the logged
    inputs and compared with the logged state: the RMS error per state as a share of its
    range, and the selection's score against holding the state. The logs are read and
    cleaned as ``identify`` reads them, with the model's variables.
    """
    from identification.data import drift_terms, load_data
    from identification.diagnostics import (
        data_warnings,
        range_note,
        stamp_jitter,
        timing_note,
        trig_variables,
    )
    from identification.model import load_model
    from identification.scoring import held_out_errors, long_enough
    from identification.support import long_run_ratio

    if not (math.isfinite(seconds) and seconds > 0):
        _fail(f"--seconds must be a positive number, got {seconds:g}")
    unit_hint = ""
    try:
        loaded = load_model(model)
        angles = sorted(trig_variables(loaded.feature_names) & set(loaded.state_names))
        units = _trained_units(loaded, model, time_unit, angle_unit)
        if units["time"] != "s":  # a log in seconds read in ms or us has few long steps
            unit_hint = (f" (the logs are read in the model's time unit, {units['time']}: "
                         "--time-unit s if they are in seconds)")  # fmt: skip
        if time is None:  # the training logs' time column (models before 2026-11-26: t)
            time = loaded.meta.get("time_column", "t")
            if not isinstance(time, str) or not time:
                _fail(f"{model}: time_column must be a column name, got {time!r}")
        trajs, cleaning = load_data(
            data, _names(columns), states=loaded.state_names, inputs=loaded.input_names, time=time,
            angles=angles, measured=loaded.meta.get("measured_inputs", ()),
            time_unit=SECONDS_PER[units["time"]], angle_unit=RADIANS_PER[units["angles"]],
        )  # fmt: skip
        trajs, stamped = stamp_jitter(trajs, loaded.feature_names)  # as identify reads them
        if stamped:
            typer.echo(f"warning: {stamped}")
        read_as = [f"{what} in {unit}" for what, unit in units.items()
                   if unit not in ("s", "rad")]  # fmt: skip
        if read_as:
            typer.echo(f"data: {' and '.join(read_as)}, as the model's training logs")
        shift = loaded.meta.get("input_shift", 0) if input_shift is None else input_shift
        if isinstance(shift, bool) or not isinstance(shift, int):
            _fail(f"{model}: input_shift must be a whole number of rows, got {shift!r}")
        if shift:  # the logs are read as the model's training logs were
            trajs, dropped = _shifted(trajs, shift)
            when = "later" if shift > 0 else "earlier"
            source = "as in training" if input_shift is None else "as --input-shift asks"
            typer.echo(f"data: inputs taken {abs(shift)} row(s) {when}, {source}{dropped}")
        drift_given = None if input_drift is None else _drift_option(input_drift)
        rate = loaded.meta.get("input_drift", 0.0) if drift_given is None else drift_given
        if rate != 0.0 and any(drift_terms(rate)):  # the drift the model was identified with
            trajs, drifted = _drifted(trajs, rate)
            source = "as in training" if drift_given is None else "as --input-drift asks"
            typer.echo(f"data: {drifted}, {source}")
        given = None if input_lag is None else _lag_option(input_lag)  # (auto: None)
        lag = loaded.meta.get("input_lag", 0.0) if given is None else given
        if lag:  # the actuators' lag the model was identified with
            trajs, lagged = _lagged(trajs, float(lag))
            source = "as in training" if given is None else "as --input-lag asks"
            typer.echo(f"data: {lagged}, {source}")
        periods = sorted(t.dt for t in trajs)
        if periods[-1] > 1.01 * periods[0]:  # one horizon in steps must be one in seconds
            _fail(f"the logs' sample steps differ ({periods[0]:g} s to {periods[-1]:g} s): "
                  "score logs of one sample step at a time")  # fmt: skip
        dt = periods[len(periods) // 2]
        if not seconds / dt < 1e9:
            _fail(f"--seconds {seconds:g} is {seconds / dt:.3g} steps of {dt:g} s: too "
                  f"many{unit_hint}")  # fmt: skip
        steps = int(round(seconds / dt))
        if steps < 1 or abs(steps * dt - seconds) > 0.25 * seconds:
            _fail(f"--seconds {seconds:g} is not a whole number of the logs' {dt:g} s steps "
                  f"(nearest: {max(steps, 1) * dt:g} s)")  # fmt: skip
        result = held_out_errors(loaded, trajs, steps)
    except (ValueError, FileNotFoundError) as exc:
        text = str(exc).splitlines()[0] if str(exc) else repr(exc)
        if "not in the data" in text and columns is None:
            text += " (logs renamed at identify need the same --columns here)"
        _fail(text + (unit_hint if "steps" in text else ""))
    if cleaning.changed:
        typer.echo(f"data: {cleaning.summary()}")
    window = loaded.meta.get("window", 1)
    window = window if isinstance(window, int) and not isinstance(window, bool) else 1
    # (the notes read the model's window; a log shorter than it gets the longest that fits)
    names, window = list(loaded.feature_names), max(min(window, max(map(len, trajs)) - 1), 1)
    ratio = long_run_ratio(long_enough(trajs, window), names, loaded.coefficients, window)
    late = timing_note(trajs, names, window, loaded.coefficients, ratio, "score again")
    for note in [*data_warnings(trajs, loaded.feature_names), range_note(loaded, trajs), late]:
        if note:
            typer.echo(f"warning: {note}")
    short = [t for t in trajs if len(t) <= steps]
    if short:
        typer.echo(f"note: {len(short)} of {len(trajs)} segment(s) ({sum(map(len, short))} rows) "
                   f"are not longer than {steps} steps and are left out")  # fmt: skip
    typer.echo(
        f"after {steps * dt:g} s ({steps} steps) from {result.starts} starts, RMS error as a "
        "share of each state's range on this data:"
    )
    for name, rel, rms in zip(loaded.state_names, result.relative, result.rms, strict=True):
        typer.echo(f"  {name}: {rel:.2%} ({rms:.3g})")
    typer.echo(
        f"score ({steps}-step prediction error over each state's scale, as identify's "
        f"selection): {result.score:.3g}; holding the state: {result.hold:.3g}"
    )
    if result.score >= result.hold:
        typer.echo(f"warning: the model predicts these logs no better than holding the "
                   f"state ({result.score:.3g} against {result.hold:.3g}): it does not hold "
                   "here")  # fmt: skip
    if result.diverged:
        typer.echo(f"warning: the prediction diverged from {result.diverged} of "
                   f"{result.starts} starts (left out of the errors above)")  # fmt: skip


def _trained_units(
    model: Any, path: Path, time_unit: Any | None, angle_unit: Any | None
) -> dict[str, str]:
    """The time and angle units to read held-out logs in: the options, else the model's."""
    stored = model.meta.get("units")
    stored = stored if isinstance(stored, dict) else {}
    out = {}
    for key, given, table in (("time", time_unit, SECONDS_PER), ("angles", angle_unit,
                                                                 RADIANS_PER)):  # fmt: skip
        unit = given.value if given is not None else stored.get(key, next(iter(table)))
        if not isinstance(unit, str) or unit not in table:
            _fail(f"{path}: units.{key} must be one of {', '.join(table)}, got {unit!r}")
        out[key] = unit
    return out


@app.command()
def show(
    model: Annotated[Path, typer.Argument(help="identified model JSON")],
    latex: Annotated[bool, typer.Option(help="LaTeX instead of plain text")] = False,
    precision: Annotated[int, typer.Option(help="significant digits", min=1, max=17)] = 6,
) -> None:
    """Prints a model's equations with each coefficient's spread and inclusion probability.

    Identified models (``identify``) and rotorcraft models (``benchmark nanodrone``); with
    ``--latex`` the notes below the equations are LaTeX comments.
    """
    from identification.model import load_model
    from identification.rotorcraft import SCHEMA as ROTORCRAFT
    from identification.rotorcraft import load_rotorcraft

    try:
        if _schema_of(model) == ROTORCRAFT:
            if latex:
                _fail(f"{model}: a rotorcraft model is shown as text only (leave out --latex)")
            typer.echo("\n".join(load_rotorcraft(model).equations(precision=precision)))
            return
        loaded = load_model(model)
    except (ValueError, FileNotFoundError) as exc:
        _fail(str(exc))
    typer.echo("\n".join(loaded.equations(precision=precision, latex=latex)))
    note = "% " if latex else ""
    lag = loaded.meta.get("input_lag", 0.0)
    if lag:  # the model's inputs are actuators' outputs: it is given commands
        held = [n for n in loaded.input_names if n not in loaded.meta.get("measured_inputs", ())]
        typer.echo(f"{note}inputs: {', '.join(held)} act through a first-order lag of {lag:g} s "
                   "(the model takes their commands; simulate, score and its surrogate env lag "
                   "them)")  # fmt: skip
    sel = loaded.meta.get("selection")
    chosen = sel.get("chosen") if isinstance(sel, dict) else None
    try:
        line = (f"{note}selected: window {chosen['window']}, lambda {chosen['lambda']:g}, "
                f"{chosen['n_terms']} terms{_after_checks(chosen['n_terms'], loaded.n_terms)}; "
                f"rule: {sel['rule']}")  # fmt: skip
    except (KeyError, TypeError, ValueError):  # no record of a selection, or an edited one
        if sel:
            typer.echo(f"{note}note: {model}: meta.selection is not a selection record; left out")
        return
    typer.echo(line)
    for warning in sel.get("warnings", []):
        typer.echo(f"{note}warning: {warning}")


def _schema_of(path: Path) -> str | None:
    """The ``schema`` field of a JSON model file (None when it has none or is not JSON)."""
    return (_json_object(path) or {}).get("schema")


def _number_option(flag: str, text: str, kind: type, low: float, high: float = math.inf) -> Any:
    """A numeric option's value (``auto`` handled by the caller), or a one-line error."""
    try:
        value = kind(text)
    except ValueError:
        value = None
    if value is None or not low <= value <= high or (kind is float and not math.isfinite(value)):
        what = "an integer" if kind is int else "a number"
        bound = f">= {low:g}" if high == math.inf else f"from {low:g} to {high:g}"
        _fail(f"{flag} takes 'auto' or {what} {bound}, got {text!r}")
    return value


def _after_checks(chosen: int, final: int) -> str:
    """Where the written model's term count differs from the chosen candidate's."""
    return f"; the model has {final} after the refit checks" if final != chosen else ""


@app.command()
def reproduce(
    out: Annotated[Path, typer.Option(help="output folder")] = Path("out/reproduce"),
    authors_csv: Annotated[Path | None, typer.Option(help="the authors' case C file")] = None,
) -> None:
    """The paper end to end: simulate, identify (ours and the paper's method), test, report."""
    from identification.experiments.reproduce import run

    if authors_csv is not None and not authors_csv.is_file():
        _fail(f"no such file: {authors_csv} (--authors-csv)")
    _writable_folder(out)
    run(out, authors_csv=authors_csv or _shared_reference(), echo=typer.echo)


@app.command()
def study(
    name: Annotated[StudyName, typer.Argument(help="which study")],
    out: Annotated[Path, typer.Option(help="output folder")] = Path("out/study"),
) -> None:
    """Coefficient error and support against lambda, dt, data size or noise (CSV + PNG)."""
    from identification.experiments.study import run_study

    _writable_folder(out)
    path = run_study(name.value, out)
    typer.echo(f"wrote {path} and {path.with_suffix('.png')}")


@bench_app.command("surrogate")
def bench_surrogate_cmd(
    seconds: Annotated[float, typer.Option(help="minimum timing per measurement [s]")] = 2.0,
) -> None:
    """Steps/s of a SINDy surrogate (compiled) against the truth and pysindy's predict."""
    from quad_sindy.bench import bench_surrogate

    if not (math.isfinite(seconds) and seconds > 0):
        _fail(f"--seconds must be a positive finite number, got {seconds:g}")
    typer.echo(f"{'env':<36} {'steps/s':>10} {'ratio':>8}")
    for row in bench_surrogate(seconds):
        rate = "" if row["steps_per_s"] != row["steps_per_s"] else f"{row['steps_per_s']:,.0f}"
        ratio = "" if row["ratio"] != row["ratio"] else f"{row['ratio']:.2f}"
        typer.echo(f"{row['env']:<36} {rate:>10} {ratio:>8}")


def _check_model_option(env: str, model: Path | None) -> None:
    """``--model`` belongs to a surrogate id, and a surrogate id needs it."""
    from identification import SURROGATE_IDS

    surrogates = (*SURROGATE_IDS, "CrazyflieSINDy-v0")
    if model is not None and env not in surrogates:
        _fail(f"--model is for the surrogate ids ({', '.join(surrogates)}), not {env}")
    if model is None and env in surrogates:
        _fail(f"{env} is a surrogate: name its model with --model MODEL.json")


class PolicyName(str, Enum):
    """Policies for ``compare``."""

    pd = "pd"
    random = "random"


@app.command()
def compare(
    model: Annotated[Path, typer.Option(help="identified model JSON")],
    out: Annotated[Path, typer.Option(help="output folder")],
    env: Annotated[str, typer.Option(help="ground-truth env id")] = "PlanarQuad-v0",
    policy: Annotated[PolicyName, typer.Option(help="policy flown in both")] = PolicyName.pd,
    case: Annotated[str, typer.Option(help="reference: A, B, C or a trajectory name")] = "A",
    seed: Annotated[int, typer.Option(help="reset seed")] = 0,
    tolerance: Annotated[float, typer.Option(help="state gap that counts as parting")] = 1e-3,
    vehicle: VehicleOption = None,
    param: ParamOption = None,
    effects: Annotated[
        str | None,
        typer.Option(
            help="effects of the ground truth only, e.g. drag or drag,wind or all (the env's "
            "coefficients: --param drag_linear_xy=... ; flights --drag c is drag_linear_xy="
            "drag_linear_z=c, drag_quadratic_xy=drag_quadratic_z=0)"
        ),
    ] = None,
) -> None:
    """The same policy and initial state in the ground truth and in the surrogate.

    Both fly the env's vehicle (``--vehicle``, ``--param``; the paper vehicle by default):
    set it to the vehicle the model was identified on. ``--effects`` switches the ground
    truth's effects on (a model identified on drag data holds the drag itself) with the
    env's coefficients, which ``--param`` sets: the linear drag ``c`` of ``flights --drag``
    is ``drag_linear_xy = drag_linear_z = c`` and no quadratic drag.
    """
    import numpy as np

    from agents.policies import make_policy
    from identification import SURROGATE_IDS
    from identification.experiments.compare import compare_envs, write_comparison
    from identification.model import load_model

    if env in (*SURROGATE_IDS, "CrazyflieSINDy-v0"):
        _fail(f"--env is the ground truth to compare with (PlanarQuad-v0, ...), not {env}; "
              "the model is --model")  # fmt: skip
    if not tolerance > 0:
        _fail(f"--tolerance must be positive, got {tolerance:g}")
    if seed < 0:  # (numpy's own refusal came after the simulation had started)
        _fail(f"--seed must be a non-negative integer, got {seed}")
    import quad_envs

    if env not in (*quad_envs.ENV_IDS, "CrazyflieMotors-v0"):
        _fail(f"--env {env} is not a quadrotor env of this package; valid: "
              f"{', '.join(quad_envs.ENV_IDS)}, CrazyflieMotors-v0")  # fmt: skip
    _writable_folder(out)
    try:
        identified = load_model(model)
        options = _vehicle_options(vehicle, param)
        truth = {"effects": _effects(effects)} if effects else {}
        make_policy(policy.value, env, seed=seed, **options, **truth)  # validates names

        def factory() -> object:
            return make_policy(policy.value, env, seed=seed, **options, **truth)

        comp = compare_envs(identified, env, factory, case, seed, tolerance=tolerance,
                            env_kwargs=options, truth_kwargs=truth)  # fmt: skip
    except (ValueError, FileNotFoundError) as exc:
        _fail(str(exc))
    summary = write_comparison(comp, out)
    for name, value in summary["rmse"].items():
        typer.echo(f"RMSE {name:<8} {value:.3e}")
    parted = summary["divergence_time"]
    typer.echo(
        f"parted by > {tolerance:g}: " + ("never" if parted is None else f"at t = {parted:.2f} s")
    )
    flown = np.flatnonzero(~np.isnan(comp.surrogate).all(axis=1))
    last = int(flown[-1]) if flown.size else 0
    if last + 1 < len(comp.truth):  # the RMSE is over the steps both flew (a trial read 0.47 m)
        typer.echo(
            f"note: the surrogate's episode ended at t = {comp.t[last]:.2f} s (terminated: the "
            f"state left the env's bounds), the truth's ran to {comp.t[-1]:.2f} s; the RMSE "
            "is over the steps both flew"
        )
    typer.echo(f"wrote {out}/abs_error.png, states.csv, summary.json")


class AlgoName(str, Enum):
    """RL algorithms."""

    ppo = "ppo"
    sac = "sac"


@app.command("train")
def train_cmd(
    out: Annotated[Path, typer.Option(help="output folder")],
    env: Annotated[str, typer.Option(help="env id (truth or surrogate)")] = "PlanarQuad-v0",
    algo: Annotated[AlgoName, typer.Option(help="algorithm")] = AlgoName.ppo,
    steps: Annotated[int, typer.Option(help="training steps")] = 200_000,
    seed: Annotated[int, typer.Option(help="seed")] = 0,
    eval_every: Annotated[int, typer.Option(help="evaluate every N steps")] = 10_000,
    model: Annotated[Path | None, typer.Option(help="model JSON for surrogate ids")] = None,
    task: Annotated[str, typer.Option(help="hover | figure8 | random")] = "hover",
    vehicle: VehicleOption = None,
    param: ParamOption = None,
) -> None:
    """Trains PPO or SAC on a task (progress bar, periodic evaluation, curve, model).

    A surrogate flies with the env's vehicle limits (``--vehicle``, ``--param``).
    """
    from agents.train import check_seed, train

    if steps < 1 or eval_every < 1:
        _fail(f"--steps and --eval-every must be positive, got {steps} and {eval_every}")
    try:
        check_seed(seed, "--seed")  # before the output folder is made
    except ValueError as exc:
        _fail(str(exc))
    _check_model_option(env, model)
    _writable_folder(out)
    kwargs = {**({"model": str(model)} if model else {}), **_vehicle_options(vehicle, param)}
    result = train(env, algo.value, steps, out, seed, eval_every, env_kwargs=kwargs, task=task)
    if result["resumed_at"]:
        typer.echo(f"resumed the run in {out} at {result['resumed_at']} steps")
    typer.echo(
        f"final return {result['final_return']:.1f} +- {result['final_std']:.1f}; "
        f"saved {result['model']}"
    )


@app.command("evaluate")
def evaluate_cmd(
    agent: Annotated[Path, typer.Option(help="saved stable-baselines3 model (.zip)")],
    env: Annotated[str, typer.Option(help="env id (truth or surrogate)")] = "PlanarQuad-v0",
    algo: Annotated[
        AlgoName | None, typer.Option(help="algorithm of the saved model (default: detected)")
    ] = None,
    episodes: Annotated[int, typer.Option(help="episodes")] = 10,
    model: Annotated[Path | None, typer.Option(help="model JSON for surrogate ids")] = None,
    task: Annotated[str, typer.Option(help="hover | figure8 | random")] = "hover",
    vehicle: VehicleOption = None,
    param: ParamOption = None,
) -> None:
    """Mean return of a trained agent on a task (ground truth or a surrogate)."""
    from agents.policies import SB3Policy
    from agents.tasks import task_kwargs
    from agents.train import canonical, evaluate, load_agent

    if episodes < 1:
        _fail(f"--episodes must be positive, got {episodes}")
    _check_model_option(env, model)
    loaded = load_agent(agent, algo.value if algo else None)
    options = _vehicle_options(vehicle, param)
    trained = _run_record(agent)
    if trained:
        notes = []
        if trained.get("task") != task:
            notes.append(f"task {trained.get('task')} (here {task})")
        before = {k: v for k, v in trained.get("options", {}).items() if k in ("vehicle", "params")}
        if canonical(before) != canonical(options):
            notes.append(
                f"vehicle options {before or 'the default'} (here {options or 'the default'})"
            )
        if notes:
            typer.echo(f"note: the agent was trained on {trained.get('env')} with "
                       f"{' and '.join(notes)} ({agent.with_name('run.json')})")  # fmt: skip
    kwargs = task_kwargs(task, **({"model": str(model)} if model else {}), **options)
    try:
        mean, std = evaluate(SB3Policy(loaded), env, episodes, **kwargs)
    except ValueError as exc:
        if "observation shape" not in str(exc):
            _fail(str(exc))
        where = f" (it was trained on {trained['env']})" if trained else ""
        _fail(f"this agent does not fit {env}{where}: {str(exc).removeprefix('Error: ')}")
    typer.echo(f"return {mean:.1f} +- {std:.1f} over {episodes} episodes")


def _run_record(agent: Path) -> dict | None:
    """The run record written beside a trained agent (None for agents trained elsewhere)."""
    return _json_object(agent.with_name("run.json"))


class EnsembleMode(str, Enum):
    """How an ensemble flies the surrogate."""

    median = "median"
    sample = "sample"


class DataRecord(str, Enum):
    """What the loop's real rollouts record for identification."""

    truth = "truth"
    measured = "measured"


@app.command()
def mbrl(
    out: Annotated[Path, typer.Option(help="output folder (a rerun resumes)")] = Path("out/mbrl"),
    env: Annotated[str, typer.Option(help="ground-truth env id")] = "PlanarQuad-v0",
    task: Annotated[str, typer.Option(help="hover | figure8 | random")] = "hover",
    algo: Annotated[AlgoName, typer.Option(help="algorithm")] = AlgoName.ppo,
    seeds: Annotated[int, typer.Option(help="seeds for both methods")] = 5,
    workers: Annotated[int, typer.Option(help="parallel jobs (>1 needs Ray)")] = 1,
    address: Annotated[str | None, typer.Option(help="Ray cluster to join")] = None,
    iterations: Annotated[int, typer.Option(help="model-based iterations")] = 4,
    initial_real_steps: Annotated[int, typer.Option(help="random exploration steps")] = 2000,
    real_steps: Annotated[int, typer.Option(help="on-policy real steps per iteration")] = 1000,
    model_steps: Annotated[
        int, typer.Option(help="surrogate training steps per iteration")
    ] = 50_000,
    baseline_steps: Annotated[int, typer.Option(help="model-free baseline steps")] = 200_000,
    ensemble: Annotated[int, typer.Option(help="bagged models (1: single model)")] = 1,
    ensemble_mode: Annotated[
        EnsembleMode, typer.Option(help="median model or a member per episode")
    ] = EnsembleMode.median,
    disagreement: Annotated[
        float, typer.Option(help="end imagined episodes above this member spread (0: never)")
    ] = 0.1,
    effects: Annotated[
        str | None,
        typer.Option(help="effects of the ground truth only, e.g. drag or drag,wind or all"),
    ] = None,
    vehicle: VehicleOption = None,
    param: ParamOption = None,
    data: Annotated[
        DataRecord,
        typer.Option(
            help="identify from the true state and applied input (truth) or from the "
            "sensors' state and the commands (measured: a real log)"
        ),
    ] = DataRecord.truth,
) -> None:
    """SINDy model-based RL against model-free RL over seeds (mean and 95 % intervals)."""
    import gymnasium as gym

    from agents.mbrl import MBRLConfig, run_experiment
    from agents.parallel import ray_available
    from agents.tasks import task_kwargs
    from agents.train import make_env
    from identification import SURROGATE_IDS

    # every option is checked before config.json is written: a failed start left a folder
    # that refused the next, valid run as "another configuration"
    if env in (*SURROGATE_IDS, "CrazyflieSINDy-v0"):
        _fail(f"--env is the ground truth the loop learns from (PlanarQuad-v0, ...), not {env}")
    if not (math.isfinite(disagreement) and disagreement >= 0):
        _fail(f"--disagreement must be a finite number >= 0 (0: never end an imagined "
              f"episode), got {disagreement:g}")  # fmt: skip
    if workers < 1:
        _fail(f"--workers must be a positive integer, got {workers}")
    if (workers > 1 or address) and not ray_available():
        _fail("parallel runs need Ray: pip install 'quad-sindy[ray]' (or --workers 1)")
    env_options: dict[str, object] = _vehicle_options(vehicle, param)
    if effects:
        env_options["effects"] = _effects(effects)
    try:
        gym.spec(env)
    except gym.error.Error as exc:
        _fail(f"--env {env}: {str(exc).removeprefix('Error: ')}")
    try:  # a quadrotor env taking the task's and the vehicle's options
        make_env(env, **task_kwargs(task, **env_options)).close()
    except (ValueError, gym.error.Error) as exc:
        _fail(str(exc))
    config = MBRLConfig(
        env_id=env, task=task, algo=algo.value, iterations=iterations,
        initial_real_steps=initial_real_steps, real_steps_per_iteration=real_steps,
        model_steps_per_iteration=model_steps, baseline_steps=baseline_steps,
        ensemble=ensemble, ensemble_mode=ensemble_mode.value,
        disagreement=disagreement if disagreement > 0 else None, env_options=env_options,
        data=data.value,
    )  # fmt: skip
    _writable_folder(out)
    res = run_experiment(config, out, seeds, workers, address, echo=typer.echo)
    summary = res["summary"]
    eff = summary["sample_efficiency"]
    typer.echo(f"model-free final return: {_fmt_interval(summary['model_free_final_return'])}")
    typer.echo(f"SINDy best return:       {_fmt_interval(summary['sindy_best_return'])}")
    typer.echo(
        f"fewer real steps to 95 % of model-free: {_fmt_interval(eff, 'x')} "
        f"({summary['reached']} of {summary['reached'] + summary['missed']} seeds reached it)"
    )
    if eff.get("mean") is not None and eff["mean"] < 1:
        typer.echo("note: a ratio under 1 means the SINDy loop needed MORE real steps")
    free = res["runs"]["model_free"]
    late = [s["seed"] for s in summary["seeds"] if s["model_free_steps"] is not None
            and s["model_free_steps"] >= free[s["seed"]]["curve"][-1]["real_steps"]]  # fmt: skip
    if late:  # its target is its last point: the baseline may still be learning
        typer.echo(
            f"note: the model-free baseline reached its 95 % target only at its last "
            f"evaluation on seed(s) {late}: it may not have converged, which flatters the "
            "ratio; give it more --baseline-steps"
        )
    typer.echo(f"wrote {out}/mbrl.json and {out}/mbrl.png")


def _fmt_interval(stats: dict, unit: str = "") -> str:
    if stats["mean"] is None:
        return "n/a"
    if stats["low"] is None:
        return f"{stats['mean']:.3g}{unit}"
    return f"{stats['mean']:.3g}{unit} [{stats['low']:.3g}, {stats['high']:.3g}]"


@app.command()
def demo(
    out: Annotated[Path, typer.Option(help="output folder")] = Path("out/demo"),
) -> None:
    """The main job on embedded defaults: ``reproduce`` plus response plots of A, B, C."""
    from quad_envs.plotting import plot_response
    from quad_envs.simulate import simulate_case

    _writable_folder(out)
    for case in "ABC":
        plot_response(simulate_case(case), out / f"case_{case}.png", title=f"Paper case {case}")
    reproduce(out=out, authors_csv=None)


USER_ERRORS = (ValueError, OSError, UnicodeDecodeError)
"""What a user's input can raise inside the library: reported in one line, not a traceback.

The library raises ``ValueError`` naming the problem; the others come from unreadable files.
Programming errors (TypeError, AttributeError, ...) keep their traceback."""


def _one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:  # noqa: ANN001
    """Warnings on the command line: one ``warning: ...`` line, no source location."""
    typer.secho(f"warning: {str(message).strip()}", fg=typer.colors.YELLOW, err=True)


def main() -> None:
    """Console entry point: runs the command, reporting a user's mistake in one line."""
    import warnings

    import gymnasium as gym

    from identification.data import IdentificationWarning

    warnings.showwarning = _one_line_warning
    # The commands print a selection's notes themselves ("warning: ..."), once.
    warnings.simplefilter("ignore", IdentificationWarning)
    # numpy's floating-point notes (an overflow in a diverging rollout) are not the user's:
    # what they lead to is said in words (a score of inf, a refusal)
    warnings.filterwarnings(
        "ignore", "(overflow|underflow|invalid value|divide by zero) encountered", RuntimeWarning
    )
    warnings.filterwarnings("ignore", "(Mean of empty slice|Degrees of freedom)", RuntimeWarning)
    usage_error = typer.BadParameter.__bases__[0]  # click's UsageError, as typer carries it
    try:
        code = app(standalone_mode=False)
    except usage_error as exc:  # an unknown option, a value not among the choices, a missing one
        if type(exc).__name__ == "NoArgsIsHelpError":  # a bare command group: its help
            exc.show()
            sys.exit(2)
        message = exc.format_message().strip().splitlines()
        typer.secho(f"error: {message[0] if message else exc} (see --help)",
                    fg=typer.colors.RED, err=True)  # fmt: skip
        sys.exit(2)
    except typer.Abort:
        sys.exit(1)
    except (*USER_ERRORS, gym.error.Error) as exc:
        message = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        message = message.removeprefix("Error: ")  # stable-baselines3's own prefix
        if isinstance(exc, OSError) and exc.filename is not None and exc.strerror:
            message = f"{exc.filename}: {exc.strerror}"
        elif isinstance(exc, UnicodeDecodeError):
            message = f"an input file is not text ({exc.reason} at byte {exc.start})"
        typer.secho(f"error: {message}", fg=typer.colors.RED, err=True)
        sys.exit(2)
    if code == 130:  # typer's exit for Ctrl-C
        typer.secho("interrupted; what was written is kept (train, mbrl and study resume when "
                    "rerun with the same command)", err=True)  # fmt: skip
    sys.exit(code if isinstance(code, int) else 0)


benchmark_app = typer.Typer(no_args_is_help=True, help="Benchmarks on real flight data.")
app.add_typer(benchmark_app, name="benchmark")


@benchmark_app.command("nanodrone")
def benchmark_nanodrone(
    data: Annotated[Path, typer.Option(help="folder of training flights (*.parquet)")],
    out: Annotated[Path, typer.Option(help="output folder")] = Path("out/nanodrone"),
    test: Annotated[
        list[Path] | None,
        typer.Option(help="test flight(s) (repeat); default: last run of each family held out"),
    ] = None,
    quiet: Annotated[bool, typer.Option(help="no progress bar")] = False,
) -> None:
    """Identifies a Crazyflie from its flight logs and scores it on the nano-drone benchmark."""
    from identification.experiments.nanodrone import beats_published, run_benchmark

    _writable_folder(out)  # before the fits, which take minutes
    try:
        metrics = run_benchmark(data, test, out, progress=not quiet)
    except (ValueError, OSError, FloatingPointError) as exc:
        _fail(str(exc))
    typer.echo(f"test: {metrics['split']}, {metrics['windows']} windows")
    typer.echo("model    h=50 MAE position / velocity / attitude / rates   SimErr")
    for name, entry in metrics["models"].items():
        h50 = " / ".join(f"{v:.3f}" for v in entry["mae"]["50"].values())
        sim = " / ".join(f"{v:.2f}" for v in entry["simerr"].values())
        typer.echo(f"{name:<8} {h50:<42} {sim}")
    for key, label in (("h50", "at h=50"), ("simerr", "in SimErr")):
        verdict = ", ".join(
            f"{g} {'yes' if ok else 'NO'}" for g, ok in beats_published(metrics)[key].items()
        )
        typer.echo(f"beats every published model {label}: {verdict}")
    typer.echo(f"wrote {out}/report.md, metrics.json, model.json and figures")


if __name__ == "__main__":  # ``python -m quad_sindy.cli`` as ``python -m quad_sindy``
    main()
