"""An identified model's vector field compiled by numba, for the environments' kernels.

:func:`compiled_rhs` turns a model into a callable that is the model's own batched numpy
``rhs(x, u)`` and also carries ``point(x, u, out)``: the same sum of terms generated as
straight-line scalar code (``point_source``) and compiled by numba. The environments run a
``rhs`` with a ``point_source`` attribute inside their compiled step kernel
(:mod:`quad_envs.physics`), so a surrogate steps about as fast as the ground truth.
"""

from __future__ import annotations

import math
from typing import Any

import numba
import numpy as np

from identification.features import Factor, parse_term
from identification.model import IdentifiedModel


def _factor_code(factor: Factor, index: dict[str, str]) -> str:
    """Scalar Python code of one factor (every kind of the feature grammar)."""
    if factor.kind == "norm":
        return f"math.sqrt({' + '.join(f'{index[v]} ** 2' for v in factor.variables())})"
    var, kind, k = index[factor.var], factor.kind, factor.k
    if kind == "abs":
        return f"abs({var})"
    if kind == "pow":
        return var if k == 1 else f"{var} ** {k}"
    arg = var if k == 1 else f"{k} * {var}"
    if kind == "sec":
        return f"(1.0 / math.cos({arg}))"
    return f"math.{kind}({arg})"


def point_source(model: IdentifiedModel) -> str:
    """Python source of ``point(X, U, out)`` writing dx/dt for one state and input."""
    names = [*model.state_names, *model.input_names]
    index = {n: f"X[{i}]" for i, n in enumerate(model.state_names)}
    index.update({n: f"U[{j}]" for j, n in enumerate(model.input_names)})
    lines = ["def point(X, U, out):"]
    factors: dict[tuple, str] = {}
    terms = [parse_term(name, names) for name in model.feature_names]
    for i in range(len(model.state_names)):
        parts = []
        for j, term in enumerate(terms):
            c = float(model.coefficients[i, j])
            if c == 0.0:
                continue
            codes = []
            for f in term:
                key = (f.var, f.kind, f.k)
                if key not in factors:
                    factors[key] = f"f{len(factors)}"
                    lines.append(f"    {factors[key]} = {_factor_code(f, index)}")
                codes.append(factors[key])
            parts.append(" * ".join([f"({c!r})", *codes]))
        lines.append(f"    out[{i}] = {' + '.join(parts) if parts else '0.0'}")
    return "\n".join(lines) + "\n"


class CompiledRhs:
    """A model's ``rhs(x, u)`` (numpy, batched) plus the source of its scalar point rhs.

    The environments see ``point_source`` and compile it into their step kernel
    (:func:`quad_envs.physics.point_rhs_kernels`: written to the kernel cache folder and
    cached on disk by numba, so a model is compiled once per machine, not per process).
    """

    def __init__(self, model: IdentifiedModel) -> None:
        self.model = model
        self.source = point_source(model)
        self.point_source = self.source
        self._point: Any = None

    @property
    def point(self) -> Any:
        """The point rhs ``point(x, u, out)`` compiled alone by numba (for checks)."""
        if self._point is None:
            namespace: dict[str, Any] = {"math": math}
            exec(compile(self.source, "<quad-sindy point rhs>", "exec"), namespace)  # noqa: S102
            self._point = numba.njit(namespace["point"])
        return self._point

    def __call__(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """dx/dt for states (..., n) and inputs (..., m) (the model's numpy rhs)."""
        return self.model.rhs(x, u)

    def __getstate__(self) -> dict[str, Any]:
        return {"model": self.model}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__init__(state["model"])


def compiled_rhs(model: IdentifiedModel) -> CompiledRhs:
    """The model's vector field with a numba point function (see the module docstring)."""
    return CompiledRhs(model)
