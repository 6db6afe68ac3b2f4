"""The identified model: coefficients over named features, compiled, simulated, saved."""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from identification.features import compile_features, compile_rhs, parse_term, term_latex, term_name
from quad_envs.fileio import jsonable, write_json
from quad_envs.integrators import rk4_step
from quad_envs.vehicles import get_vehicle

SCHEMA = "quad-sindy/model"
SCHEMA_VERSION = 1


@dataclass
class IdentifiedModel:
    """dx/dt = Xi Theta(x, u): a sparse model over named features.

    Attributes:
        feature_names: Library terms (grammar of :mod:`identification.features`).
        coefficients: Xi, shape (n_states, n_features).
        state_names: Names of the states (rows of Xi).
        input_names: Names of the inputs.
        system: An optional label of the vehicle (``planar``/``quad6dof`` are checked against
            the presets' variable names; any other label is kept as given), or None.
        meta: Provenance: method, lambda, optimizer, dt, data size, selection scores, ...
        coefficient_std: Ensemble (bootstrap) spread of each coefficient, shape of Xi, or None.
        inclusion_probability: Fraction of ensemble fits that kept each term, or None.
    """

    feature_names: list[str]
    coefficients: np.ndarray
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    system: str | None = None
    meta: dict[str, Any] = field(default_factory=dict)
    coefficient_std: np.ndarray | None = None
    inclusion_probability: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.feature_names = list(self.feature_names)
        self.state_names, self.input_names = tuple(self.state_names), tuple(self.input_names)
        self.coefficients = np.asarray(self.coefficients, dtype=np.float64)
        expected = (len(self.state_names), len(self.feature_names))
        if self.coefficients.shape != expected:
            raise ValueError(
                f"coefficients must have shape {expected} (states x features), "
                f"got {self.coefficients.shape}"
            )
        if not np.isfinite(self.coefficients).all():
            raise ValueError("coefficients contain NaN or infinite values")
        variables = [*self.state_names, *self.input_names]
        for name in self.feature_names:
            parse_term(name, variables)  # raises on unknown variables or bad syntax
        if self.system is not None:
            sys_ = get_vehicle(self.system)
            if (sys_.state_names, sys_.input_names) != (self.state_names, self.input_names):
                raise ValueError(
                    f"model variables {self.state_names} / {self.input_names} do not match the "
                    f"{self.system} system's {sys_.state_names} / {sys_.input_names}"
                )
        self._rhs: Callable | None = None
        self._theta: Callable | None = None

    # -- evaluation -------------------------------------------------------------------
    def rhs(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """dx/dt for states (..., n) and inputs (..., m): compiled straight-line numpy."""
        if self._rhs is None:
            self._rhs = compile_rhs(
                self.feature_names, self.coefficients, self.state_names, self.input_names
            )
        self._check_shapes(x, u)
        return self._rhs(x, u)

    def theta(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """The library evaluated at (x, u), shape (..., n_features)."""
        if self._theta is None:
            self._theta = compile_features(self.feature_names, self.state_names, self.input_names)
        self._check_shapes(x, u)
        return self._theta(x, u)

    def _check_shapes(self, x: Any, u: Any) -> None:
        """Raises ValueError unless x is (..., n) and u is (..., m) with the same leading axes."""
        xs, us = np.shape(x), np.shape(u)
        n, m = len(self.state_names), len(self.input_names)
        if not xs or xs[-1] != n or (us[-1:] != (m,) and not (m == 0 and not us)):
            raise ValueError(
                f"the model takes states of shape (..., {n}) and inputs of shape (..., {m}) "
                f"({', '.join(self.state_names)} / {', '.join(self.input_names) or 'no inputs'}), "
                f"got {xs} and {us}"
            )
        if us and xs[:-1] != us[:-1]:
            raise ValueError(
                f"states {xs} and inputs {us} must have the same leading axes (one input row "
                "per state row)"
            )

    def torch_rhs(self) -> Callable[[Any, Any], Any]:
        """A batched torch version of :meth:`rhs`: differentiable, on any device and dtype.

        The coefficients are baked into the generated code as Python numbers, so the function
        runs on whatever device its input tensors live and returns their dtype.

        Returns:
            rhs(x, u) on tensors of shape (..., n) and (..., m).
        """
        import torch

        return compile_rhs(
            self.feature_names, self.coefficients, self.state_names, self.input_names, xp=torch
        )

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_rhs"] = state["_theta"] = None  # compiled code is rebuilt on demand
        return state

    @property
    def n_terms(self) -> int:
        """Number of non-zero coefficients."""
        return int(np.count_nonzero(self.coefficients))

    def used_variables(self) -> set[str]:
        """The states and inputs the model's non-zero terms read."""
        names = (*self.state_names, *self.input_names)
        terms = np.flatnonzero(np.any(self.coefficients != 0, axis=0))
        return {f.var for j in terms for f in parse_term(self.feature_names[j], names)}

    def training_box(self) -> tuple[np.ndarray, np.ndarray] | None:
        """Lowest and highest value of each state and input the model was trained on.

        From ``meta["ranges"]`` (:func:`identification.data.data_ranges`), over the states
        then the inputs. A state no term reads (a position) is unbounded (-inf, inf); every
        input is bounded, read or not: a model without an input's terms claims it has no
        effect, which its data tested only over their range (a closed-loop trial's
        ``y_dot' = -9.8 sin(phi)``, the thrust's twin at hover thrust, drifted 3 % in 1 s on
        flights that left it). A variable without a valid entry is unbounded. None where the
        model has no ranges (files before 2026-11-26) or none of them bounds a variable.
        """
        ranges = self.meta.get("ranges")
        if not isinstance(ranges, dict):
            return None
        names = (*self.state_names, *self.input_names)
        used = self.used_variables()
        low, high = np.full(len(names), -np.inf), np.full(len(names), np.inf)
        for k, name in enumerate(names):
            if (name in used or k >= len(self.state_names)) and _is_range(ranges.get(name)):
                low[k], high[k] = ranges[name]
        return (low, high) if np.isfinite(low).any() else None

    # -- text -------------------------------------------------------------------------
    def equations(
        self, precision: int = 4, latex: bool = False, uncertainty: bool = True
    ) -> list[str]:
        """One equation per state, in plain text or LaTeX.

        Args:
            precision: Significant digits of the coefficients.
            latex: LaTeX instead of plain text.
            uncertainty: Where the model carries ensemble statistics, show each coefficient's
                spread and inclusion probability: ``-2 (+-1e-05, P=1.00) sin(phi) u1``.

        Returns:
            The equations, one string per state.
        """
        if (
            isinstance(precision, bool)
            or not isinstance(precision, int | np.integer)
            or not (1 <= precision <= 17)
        ):
            raise ValueError(f"precision must be an integer from 1 to 17, got {precision!r}")
        number = _latex_number if latex else (lambda v, digits: f"{v:.{digits}g}")
        stats = uncertainty and self.coefficient_std is not None
        lines = []
        for i, state in enumerate(self.state_names):
            rhs = ""
            for j, name in enumerate(self.feature_names):
                c = self.coefficients[i, j]
                if c == 0:
                    continue
                term = parse_term(name)
                text = term_latex(term) if latex else term_name(term)
                coef = number(abs(c), precision)
                if stats:
                    std = number(self.coefficient_std[i, j], 2)  # type: ignore[index]
                    prob = (
                        self.inclusion_probability[i, j]
                        if self.inclusion_probability is not None
                        else float("nan")
                    )
                    if latex:
                        coef = f"({coef} \\pm {std})_{{P={prob:.2f}}}"
                    else:
                        coef = f"{coef} (+-{std}, P={prob:.2f})"
                part = coef if text == "1" else f"{coef} {text}"
                sign = "-" if c < 0 else "+"
                rhs = f"{rhs} {sign} {part}" if rhs else (f"-{part}" if c < 0 else part)
            rhs = rhs or "0"
            if latex:
                lhs = "\\dot{" + term_latex(parse_term(state)) + "}"
                lines.append(f"{lhs} = {rhs}")
            else:
                lines.append(f"{state}' = {rhs}")
        return lines

    # -- simulation -------------------------------------------------------------------
    def simulate(
        self,
        x0: np.ndarray,
        inputs: np.ndarray | None,
        dt: float | np.ndarray,
        substeps: int = 1,
        actuators: np.ndarray | None = None,
    ) -> np.ndarray:
        """Open loop by RK4, input row k over step k. Returns states, shape (len(inputs)+1, n).

        Args:
            x0: Initial state.
            inputs: One row per step (None for a model without inputs: one dt per step then).
            dt: The step, or one step per input row (a log's own steps, jitter and all:
                ``np.diff(t, append=2 * t[-1] - t[-2])``).
            substeps: RK4 substeps per step.
            actuators: For a model with an input lag, the actuators' output at the start,
                one value per held input (default: the first command; a vehicle whose
                rotors start at hover, or a piece cut from a longer flight, starts elsewhere).

        Commands are held over their step. Inputs the model was identified with as measured
        signals (``meta.measured_inputs``) are interpolated within each step as in the fit
        (the last step holds them). A model identified with its inputs acting through a lag
        (``meta.input_lag``, :meth:`~identification.data.Trajectory.lag_inputs`) is given the
        commands and lags them as the fit did, its actuators starting at the first command.
        """
        if isinstance(substeps, bool) or not isinstance(substeps, int | np.integer) or substeps < 1:
            raise ValueError(f"substeps must be a positive integer, got {substeps!r}")
        x0 = np.asarray(x0, dtype=np.float64)
        if inputs is None:  # a model without inputs: the steps give the length
            if self.input_names:
                raise ValueError(f"inputs needed: one row of {list(self.input_names)} per step")
            if np.ndim(dt) != 1:
                raise ValueError(
                    "a model without inputs needs one dt per step (an array) to know how many "
                    "steps to take, or inputs=np.zeros((steps, 0))"
                )
            inputs = np.zeros((len(dt), 0))
        inputs = np.asarray(inputs, dtype=np.float64)
        if inputs.ndim == 1 and len(self.input_names) == 1:
            inputs = inputs[:, None]  # one input: a plain sequence of its values
        inputs = np.atleast_2d(inputs)
        if x0.shape != (len(self.state_names),):
            raise ValueError(f"x0 must have shape ({len(self.state_names)},), got {x0.shape}")
        for name, values in (("x0", x0), ("inputs", inputs)):
            if not np.all(np.isfinite(values)):
                raise ValueError(f"{name} holds NaN or infinite values: every state would be NaN")
        if inputs.shape[1] != len(self.input_names):
            raise ValueError(
                f"inputs must have {len(self.input_names)} columns, got {inputs.shape}"
            )
        steps = np.asarray(dt, dtype=np.float64)
        if steps.ndim == 0:
            steps = np.full(len(inputs), float(steps))
        if steps.shape != (len(inputs),) or not np.all(np.isfinite(steps) & (steps > 0)):
            raise ValueError(
                f"dt must be one positive step or one per input row ({len(inputs)}), got "
                f"{np.asarray(dt).ravel()[:5]} (shape {np.shape(dt)})"
            )
        out = np.empty((len(inputs) + 1, x0.size))
        out[0] = x = x0
        measured = [self.input_names.index(n) for n in self.meta.get("measured_inputs", ())]
        lag = float(self.meta.get("input_lag", 0.0))
        held = [k for k in range(inputs.shape[1]) if k not in measured]
        lagged = lag > 0 and bool(held)
        if actuators is not None:
            actuators = np.asarray(actuators, dtype=np.float64).ravel()
            if not lagged or actuators.shape != (len(held),) or not np.isfinite(actuators).all():
                raise ValueError(
                    "actuators= is the start of the lagged actuators, one finite value per held "
                    f"input ({len(held) if lagged else 0} here: the model's input lag is {lag:g} s)"
                )
        if measured or lagged:  # inputs that move within each step, as in the fit
            from identification.data import lag_stages, lagged_inputs, stage_inputs
            from identification.fit import rk4_steps

            t = np.concatenate([[0.0], np.cumsum(steps)])  # (one more: the last step's end)
            commands = inputs
            if lagged:  # commands: the actuators' output at each row, and within the step
                inputs = inputs.copy()
                inputs[:, held] = lagged_inputs(t[:-1], commands[:, held], lag, actuators)
            um, u1 = inputs.copy(), inputs.copy()  # the last step holds measured signals
            inner = np.arange(len(inputs) - 1)
            _, um[inner], u1[inner] = stage_inputs(t[:-1], inputs, inner, measured)
            if lagged:
                every = np.arange(len(inputs))
                um[:, held], u1[:, held] = lag_stages(t, inputs[:, held], commands[:, held],
                                                      lag, every)  # fmt: skip
            for k in range(len(inputs)):
                x = rk4_steps(self.rhs, x[None, :], (inputs[k : k + 1], um[k : k + 1],
                              u1[k : k + 1]), steps[k : k + 1], substeps)[0]  # fmt: skip
                out[k + 1] = x
            return out
        for k, u in enumerate(inputs):
            x = rk4_step(self.rhs, x, u, steps[k], substeps)
            out[k + 1] = x
        return out

    # -- persistence ------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary (schema-versioned)."""
        return {
            "schema": SCHEMA,
            "schema_version": SCHEMA_VERSION,
            "system": self.system,
            "state_names": list(self.state_names),
            "input_names": list(self.input_names),
            "feature_names": self.feature_names,
            "coefficients": self.coefficients.tolist(),
            "coefficient_std": None
            if self.coefficient_std is None
            else self.coefficient_std.tolist(),
            "inclusion_probability": None
            if self.inclusion_probability is None
            else self.inclusion_probability.tolist(),
            "equations": self.equations(precision=8, uncertainty=False),
            "meta": jsonable(self.meta),
        }

    @classmethod
    def from_dict(cls, data: Any, source: str = "model") -> IdentifiedModel:
        """Builds a model from :meth:`to_dict` output, with errors naming what is wrong."""
        if not isinstance(data, dict):
            raise ValueError(
                f"{source}: a model file holds a JSON object, got {type(data).__name__}"
            )
        if data.get("schema") == "quad-sindy/rotorcraft":
            raise ValueError(
                f"{source}: a rotorcraft model (motor speeds to rigid body), not an identified "
                "SINDy model: load it with identification.rotorcraft.load_rotorcraft"
            )
        if data.get("schema") != SCHEMA:
            raise ValueError(
                f"{source}: not a model written by quad-sindy identify (schema "
                f"{data.get('schema')!r}, expected {SCHEMA!r})"
            )
        version = data.get("schema_version")
        if version != SCHEMA_VERSION:
            raise ValueError(
                f"{source}: schema_version {version!r} is not supported (expected {SCHEMA_VERSION})"
            )
        missing = [
            k
            for k in ("state_names", "input_names", "feature_names", "coefficients")
            if k not in data
        ]
        if missing:
            raise ValueError(f"{source}: missing field(s) {missing}")
        if not isinstance(data.get("meta") or {}, dict):
            raise ValueError(
                f"{source}: meta must be a JSON object, got {type(data['meta']).__name__}"
            )
        for key in ("state_names", "input_names", "feature_names"):
            names = data[key]
            if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
                raise ValueError(f"{source}: {key} must be a list of names (strings)")
        _check_meta(dict(data.get("meta") or {}), data["input_names"], source)
        try:
            coefficients = np.array(data["coefficients"], dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"{source}: coefficients must be a numeric matrix") from None
        extras = {}
        for key in ("coefficient_std", "inclusion_probability"):
            try:
                extras[key] = _optional_array(data.get(key))
            except (TypeError, ValueError):
                raise ValueError(f"{source}: {key} must be a numeric matrix or null") from None
            shape = None if extras[key] is None else extras[key].shape
            if shape is not None and shape != coefficients.shape:
                raise ValueError(f"{source}: {key} has shape {shape}, the coefficients "
                                 f"{coefficients.shape}")  # fmt: skip
        try:
            return cls(
                data["feature_names"], coefficients, tuple(data["state_names"]),
                tuple(data["input_names"]), data.get("system"), dict(data.get("meta") or {}),
                extras["coefficient_std"], extras["inclusion_probability"],
            )  # fmt: skip
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{source}: {exc}") from None

    def save(self, path: str | Path) -> Path:
        """Writes the model as JSON, atomically."""
        return write_json(path, self.to_dict())


def load_model(path: str | Path) -> IdentifiedModel:
    """Reads a model written by :meth:`IdentifiedModel.save`.

    Raises:
        FileNotFoundError: No such file.
        ValueError: The file is not valid JSON or not a valid model (the message says why).
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no such model file: {path}")
    if not path.is_file():
        raise ValueError(f"{path} is not a file (a model is a JSON file)")
    try:
        data = json.loads(path.read_text())
    except UnicodeDecodeError:
        raise ValueError(f"{path} is not a model file: not text (binary?)") from None
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: malformed JSON ({exc})") from None
    except RecursionError:
        raise ValueError(f"{path} is not a model file: JSON nested too deeply") from None
    return IdentifiedModel.from_dict(data, source=str(path))


def _check_meta(meta: dict[str, Any], inputs: Sequence[str], source: str) -> None:
    """Refuses, in one line, a damaged entry of the meta fields that commands read."""
    measured = meta.get("measured_inputs", [])
    if not isinstance(measured, list) or not all(m in inputs for m in measured):
        raise ValueError(f"{source}: meta.measured_inputs must list some of the inputs "
                         f"{list(inputs)}, got {measured!r}")  # fmt: skip
    for key in ("window", "input_shift"):
        value = meta.get(key, 1)
        low = 1 if key == "window" else -(10**6)
        if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= 10**6:
            raise ValueError(f"{source}: meta.{key} must be a whole number from {low} to "
                             f"{10**6}, got {value!r}")  # fmt: skip
    lag = meta.get("input_lag", 0.0)
    if isinstance(lag, bool) or not isinstance(lag, int | float) or not 0 <= lag < 1e6:
        raise ValueError(f"{source}: meta.input_lag must be a time constant >= 0 [s], "
                         f"got {lag!r}")  # fmt: skip
    drift = meta.get("input_drift", 0.0)
    drift = drift if isinstance(drift, list) else [drift]
    if not (1 <= len(drift) <= 2 and all(isinstance(a, int | float) and not isinstance(a, bool)
                                         and math.isfinite(a) for a in drift)):  # fmt: skip
        raise ValueError(f"{source}: meta.input_drift must be a1 or [a1, a2] (the inputs' "
                         f"gain 1 + a1 t + a2 t^2), got {meta['input_drift']!r}")  # fmt: skip
    if not isinstance(meta.get("time_column", "t"), str):
        raise ValueError(f"{source}: meta.time_column must be a column name (a string)")
    if not isinstance(meta.get("units", {}), dict):  # (a string was read as seconds, silently)
        raise ValueError(f"{source}: meta.units must be a JSON object ({{\"time\": \"s\", "
                         f"\"angles\": \"rad\"}}), got {meta['units']!r}")  # fmt: skip


def _is_range(bounds: Any) -> bool:
    """``[low, high]``: two finite numbers in order (a damaged entry is not a range)."""
    return (
        isinstance(bounds, list | tuple)
        and len(bounds) == 2
        and all(isinstance(b, int | float) and not isinstance(b, bool) for b in bounds)
        and bool(np.all(np.isfinite(bounds)))
        and bounds[0] <= bounds[1]
    )


def _latex_number(value: float, digits: int) -> str:
    r"""``1.1e-14`` as ``1.1 \times 10^{-14}``; plain digits where no exponent is needed."""
    text = f"{value:.{digits}g}"
    if "e" not in text:
        return text
    mantissa, exponent = text.split("e")
    return f"{mantissa} \\times 10^{{{int(exponent)}}}"


def _optional_array(value: Any) -> np.ndarray | None:
    return None if value is None else np.array(value, dtype=np.float64)
