"""Trajectories of (t, states, inputs): validation, CSV/NPZ I/O and rollout collection.

``u[k]`` is the input *applied* (held) over [t_k, t_k+1): for environment rollouts this is
the saturated action from ``info["action"]``. The authors' CSV records the commanded input,
which equals the applied one wherever the rotors do not saturate (all of case C).
"""

from __future__ import annotations

import io
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from quad_envs.fileio import atomic_write_bytes, write_csv
from quad_envs.simulate import ClosedLoopRun
from quad_envs.vehicles import get_vehicle


@dataclass
class Trajectory:
    """One sampled trajectory.

    Attributes:
        t: Uniformly spaced, increasing times, shape (N,).
        x: States, shape (N, n).
        u: Inputs held over each step, shape (N, m).
        state_names: Names of the n states.
        input_names: Names of the m inputs.
        refs: Optional reference at each sample (for closed-loop replays), shape (N, r).
        meta: Free-form provenance (case, seed, policy, ...).
    """

    t: np.ndarray
    x: np.ndarray
    u: np.ndarray
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    refs: np.ndarray | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.t = np.asarray(self.t, dtype=np.float64)
        self.x = np.atleast_2d(np.asarray(self.x, dtype=np.float64))
        self.u = np.atleast_2d(np.asarray(self.u, dtype=np.float64))
        self.state_names, self.input_names = tuple(self.state_names), tuple(self.input_names)
        validate(self)

    @property
    def dt(self) -> float:
        """The sample period [s]."""
        return float(self.t[1] - self.t[0])

    def __len__(self) -> int:
        return self.t.size

    @classmethod
    def from_run(cls, run: ClosedLoopRun, inputs: str = "applied", **meta: Any) -> Trajectory:
        """From a closed-loop simulation (applied inputs by default)."""
        u = run.applied if inputs == "applied" else run.commanded
        names = (run.vehicle.state_names, run.vehicle.input_names)
        return cls(run.t, run.states, u, *names, refs=run.refs, meta=meta)


def validate(traj: Trajectory) -> None:
    """Raises ValueError naming the problem: shapes, NaN/inf, time grid, names."""
    t, x, u = traj.t, traj.x, traj.u
    if t.ndim != 1 or t.size < 3:
        raise ValueError(f"t must be 1-D with at least 3 samples, got shape {t.shape}")
    if x.shape[0] != t.size or u.shape[0] != t.size:
        raise ValueError(
            f"mismatched lengths: t has {t.size} samples, x {x.shape[0]}, u {u.shape[0]}"
        )
    if x.shape[1] != len(traj.state_names):
        raise ValueError(f"x has {x.shape[1]} columns but {len(traj.state_names)} state names")
    if u.shape[1] != len(traj.input_names):
        raise ValueError(f"u has {u.shape[1]} columns but {len(traj.input_names)} input names")
    for name, arr in (("t", t), ("x", x), ("u", u)):
        bad = ~np.isfinite(arr)
        if bad.any():
            row = int(np.argwhere(bad)[0][0])
            raise ValueError(f"{name} contains NaN or infinite values (first at sample {row})")
    steps = np.diff(t)
    if np.any(steps <= 0):
        raise ValueError(f"time must be strictly increasing (sample {int(np.argmin(steps)) + 1})")
    if np.abs(steps - steps.mean()).max() > 1e-6 * max(steps.mean(), 1e-12) + 1e-9:
        raise ValueError(
            f"time must be uniformly spaced: steps range from {steps.min():g} to {steps.max():g} s"
        )


def _split_columns(
    columns: Sequence[str], system: str
) -> tuple[int, list[int], list[int], list[str], list[str]]:
    sys_ = get_vehicle(system)
    known_states, known_inputs = set(sys_.state_names), set(sys_.input_names)
    if "t" not in columns:
        raise ValueError(f"columns must include 't', got {list(columns)}")
    ignored = set(sys_.ref_names) | {f"{name}_cmd" for name in sys_.input_names} | {"_"}
    unknown = [c for c in columns if c not in known_states | known_inputs | ignored | {"t"}]
    if unknown:
        valid = ["t", *sys_.state_names, *sys_.input_names, "_", *sys_.ref_names]
        raise ValueError(f"unknown column name(s) {unknown}; valid names: {valid}")
    states = [c for c in sys_.state_names if c in columns]
    inputs = [c for c in sys_.input_names if c in columns]
    if not states or not inputs:
        raise ValueError(f"columns name no states or no inputs of the {system} system")
    return (
        list(columns).index("t"),
        [list(columns).index(c) for c in states],
        [list(columns).index(c) for c in inputs],
        states,
        inputs,
    )


def read_csv(
    path: str | Path, columns: Sequence[str] | None = None, system: str = "planar"
) -> Trajectory:
    """Reads a CSV trajectory.

    With a header (``t,y,z,...``), columns are found by name. A headerless file needs
    ``columns`` naming every column in order; ``_`` (and reference names) mark ignored ones.

    Args:
        path: CSV file.
        columns: Column names in order, for headerless files.
        system: ``planar`` or ``quad6dof``: which names are states and inputs.

    Returns:
        The trajectory.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no such data file: {path}")
    text = path.read_text()
    first = text.splitlines()[0] if text.strip() else ""
    has_header = any(ch.isalpha() for ch in first.replace("e-", "").replace("e+", ""))
    if columns is None:
        if not has_header:
            raise ValueError(f"{path} has no header: pass columns= (--columns) naming its columns")
        columns = [c.strip() for c in first.split(",")]
    try:
        data = np.loadtxt(
            io.StringIO(text), delimiter=",", skiprows=1 if has_header else 0, ndmin=2
        )
    except ValueError as exc:
        raise ValueError(f"{path}: not a numeric CSV ({exc})") from None
    if data.shape[1] != len(columns):
        raise ValueError(f"{path} has {data.shape[1]} columns but {len(columns)} names were given")
    ti, si, ui, states, inputs = _split_columns(columns, system)
    return Trajectory(
        data[:, ti], data[:, si], data[:, ui], states, inputs, meta={"source": str(path)}
    )


def write_trajectory_csv(path: str | Path, traj: Trajectory) -> Path:
    """Writes t, states, inputs with a header (atomically)."""
    header = ["t", *traj.state_names, *traj.input_names]
    return write_csv(path, header, np.column_stack([traj.t, traj.x, traj.u]))


def save_npz(path: str | Path, trajs: Sequence[Trajectory]) -> Path:
    """Saves several trajectories to one ``.npz`` (atomically)."""
    arrays: dict[str, np.ndarray] = {"count": np.array(len(trajs))}
    for i, tr in enumerate(trajs):
        arrays[f"t_{i}"], arrays[f"x_{i}"], arrays[f"u_{i}"] = tr.t, tr.x, tr.u
        arrays[f"state_names_{i}"] = np.array(tr.state_names)
        arrays[f"input_names_{i}"] = np.array(tr.input_names)
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    return atomic_write_bytes(path, buffer.getvalue())


def load_npz(path: str | Path) -> list[Trajectory]:
    """Loads trajectories saved by :func:`save_npz`."""
    try:
        with np.load(path, allow_pickle=False) as data:
            count = int(data["count"])
            return [
                Trajectory(
                    data[f"t_{i}"],
                    data[f"x_{i}"],
                    data[f"u_{i}"],
                    tuple(data[f"state_names_{i}"]),
                    tuple(data[f"input_names_{i}"]),
                )  # fmt: skip
                for i in range(count)
            ]
    except KeyError as exc:
        raise ValueError(f"{path} is not a quad-sindy trajectory archive (missing {exc})") from None


def load_data(
    paths: Sequence[str | Path], columns: Sequence[str] | None = None, system: str = "planar"
) -> list[Trajectory]:
    """Reads CSV and NPZ files into one list of trajectories."""
    trajs: list[Trajectory] = []
    for path in paths:
        if str(path).endswith(".npz"):
            trajs.extend(load_npz(path))
        else:
            trajs.append(read_csv(path, columns, system))
    return trajs
