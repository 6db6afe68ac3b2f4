"""Feature names: a small grammar shared by libraries, models and model files.

A feature is a product of factors separated by spaces, e.g. ``u1 sin(phi)`` or pysindy's own
``u1 sin(1 phi)``. A factor is one of

    1 | v | v^k | sin(v) | cos(v) | tan(v) | sec(v) | sin(k v) | cos(k v) | abs(v)
      | norm(v w ...)

where ``v`` names a state or an input. ``abs(v)`` is |v| and ``norm(v w ...)`` the Euclidean
norm sqrt(v^2 + w^2 + ...) of the listed variables (space-separated, canonically sorted; a
norm of one variable is ``abs``): ``y_dot norm(y_dot z_dot)`` is a quadratic-drag term.

Parsing gives a canonical form (sorted factors), so
``sin(1 phi) u1`` and ``u1 sin(phi)`` are the same feature. Compiling turns a list of names
(and optionally a coefficient matrix) into generated numpy or torch code: a model's ``rhs``
costs microseconds, not pysindy's ``predict`` milliseconds.
"""

from __future__ import annotations

import functools
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from quad_envs.dynamics import components

_TOKEN = re.compile(r"[A-Za-z_]\w*\([^)]*\)|\S+")
_FUNC = re.compile(r"^(sin|cos|tan|sec)\((?:(\d+)\s+)?([A-Za-z_]\w*)\)$")
_POWER = re.compile(r"^([A-Za-z_]\w*)(?:\^(\d+))?$")
_NORM = re.compile(r"^(abs|norm)\(\s*([A-Za-z_]\w*(?:\s+[A-Za-z_]\w*)*)\s*\)$")


@dataclass(frozen=True, order=True)
class Factor:
    """One factor: ``kind`` is ``pow``, ``sin``, ``cos``, ``tan``, ``sec``, ``abs`` or ``norm``.

    For ``norm``, ``var`` holds the sorted variable names separated by single spaces.
    """

    var: str
    kind: str
    k: int  # power for pow, frequency for trig, 1 for abs and norm

    def variables(self) -> tuple[str, ...]:
        """The variables the factor reads (several for ``norm``)."""
        return tuple(self.var.split()) if self.kind == "norm" else (self.var,)

    def name(self) -> str:
        """Canonical text of the factor."""
        if self.kind in ("abs", "norm"):
            return f"{self.kind}({self.var})"
        if self.kind == "pow":
            return self.var if self.k == 1 else f"{self.var}^{self.k}"
        return f"{self.kind}({self.var})" if self.k == 1 else f"{self.kind}({self.k} {self.var})"

    def latex(self) -> str:
        """LaTeX of the factor."""
        if self.kind == "norm":
            inner = ", ".join(_latex_var(v) for v in self.variables())
            return f"\\left\\|({inner})\\right\\|"
        var = _latex_var(self.var)
        if self.kind == "abs":
            return f"\\left|{var}\\right|"
        if self.kind == "pow":
            return var if self.k == 1 else f"{var}^{{{self.k}}}"
        arg = var if self.k == 1 else f"{self.k}{var}"
        return f"\\{self.kind}({arg})"


Term = tuple[Factor, ...]
"""A feature in canonical form; the empty tuple is the constant 1."""


_GREEK = {
    "alpha", "beta", "gamma", "delta", "epsilon", "zeta", "eta", "theta", "iota", "kappa",
    "lambda", "mu", "nu", "xi", "pi", "rho", "sigma", "tau", "upsilon", "phi", "chi", "psi",
    "omega", "Gamma", "Delta", "Theta", "Lambda", "Xi", "Pi", "Sigma", "Phi", "Psi", "Omega",
}  # fmt: skip


def _latex_symbol(text: str, subscript: bool = True) -> str:
    """A name as one symbol: Greek letters as such, one letter in italics, words upright."""
    digits = re.fullmatch(r"([A-Za-z]+)(\d+)", text)
    if digits and subscript:  # u1 -> u_{1}
        return f"{_latex_symbol(digits.group(1))}_{{{digits.group(2)}}}"
    if text in _GREEK:
        return f"\\{text}"
    return text if len(text) <= 1 else "\\mathrm{" + text.replace("_", "\\_") + "}"


def _latex_var(var: str) -> str:
    base, _, sub = var.partition("_")
    out = _latex_symbol(base, subscript=sub in ("", "dot", "ddot"))
    if sub == "dot":
        return f"\\dot{{{out}}}"
    if sub == "ddot":
        return f"\\ddot{{{out}}}"
    if sub.isdigit():
        return f"{out}_{{{sub}}}"
    return out if not sub else f"{out}_{{{_latex_symbol(sub)}}}"


def parse_term(name: str, variables: Sequence[str] | None = None) -> Term:
    """Parses a feature name into its canonical factors.

    Args:
        name: Feature text, e.g. ``"u1 sin(1 phi)"``.
        variables: If given, every variable must be one of these.

    Returns:
        Sorted tuple of factors (powers of the same variable merged).

    Raises:
        ValueError: The text is not in the grammar or names an unknown variable.
    """
    term = _parse_factors(name)
    if variables is not None:
        unknown = sorted({v for f in term for v in f.variables()} - set(variables))
        if unknown:
            raise ValueError(f"feature {name!r} uses unknown variable(s) {unknown}")
    return term


@functools.lru_cache(maxsize=65536)
def _parse_factors(name: str) -> Term:
    # cached: a 6-DOF selection parses the same few hundred names tens of thousands of times
    text = name.strip()
    if not text:
        raise ValueError("empty feature name")
    powers: dict[str, int] = {}
    trig: list[Factor] = []
    for token in _TOKEN.findall(text):
        if token == "1":
            continue
        norm = _NORM.match(token)
        if norm:
            names = sorted(norm.group(2).split())
            if len(set(names)) != len(names):
                raise ValueError(f"repeated variable in factor {token!r} of feature {name!r}")
            kind = "abs" if len(names) == 1 else "norm"
            trig.append(Factor(" ".join(names), kind, 1))
            continue
        func = _FUNC.match(token)
        if func:
            kind, freq, var = func.group(1), int(func.group(2) or 1), func.group(3)
            trig.append(Factor(var, kind, freq))
            continue
        power = _POWER.match(token)
        if not power:
            raise ValueError(
                f"cannot parse factor {token!r} in feature {name!r}: a feature is factors "
                "separated by spaces, each a variable with a whole power (x, x^2), sin, cos, "
                "tan or sec of a whole multiple of one (sin(x), cos(2 x)), abs(x) or "
                "norm(x y)"
            )
        var, k = power.group(1), int(power.group(2) or 1)
        powers[var] = powers.get(var, 0) + k
    factors = [Factor(v, "pow", k) for v, k in powers.items()] + trig
    return tuple(sorted(factors))


def term_name(term: Term) -> str:
    """Canonical text of a term (``1`` for the constant)."""
    return " ".join(f.name() for f in term) or "1"


def term_latex(term: Term) -> str:
    """LaTeX of a term."""
    return " ".join(f.latex() for f in term) or "1"


def _factor_expr(factor: Factor, index: dict[str, str]) -> str:
    if factor.kind == "norm":
        squares = " + ".join(f"{index[v]} ** 2" for v in factor.variables())
        return f"xp.sqrt({squares})"
    var = index[factor.var]
    if factor.kind == "abs":
        return f"xp.abs({var})"
    arg = var if factor.k == 1 or factor.kind == "pow" else f"{factor.k} * {var}"
    if factor.kind == "pow":
        return arg if factor.k == 1 else f"{arg} ** {factor.k}"
    if factor.kind == "sec":
        return f"(1.0 / xp.cos({arg}))"
    return f"xp.{factor.kind}({arg})"


def _term_expr(term: Term, index: dict[str, str], cache: dict[str, str], lines: list[str]) -> str:
    parts = []
    for factor in term:
        key = factor.name()
        if key not in cache:
            cache[key] = f"f{len(cache)}"
            lines.append(f"    {cache[key]} = {_factor_expr(factor, index)}")
        parts.append(cache[key])
    return " * ".join(parts) if parts else "one"


def _header(
    state_names: Sequence[str], input_names: Sequence[str], xp: Any
) -> tuple[list[str], dict[str, str]]:
    # numpy: ``.T`` puts the variable axis first (fastest for one state and for batches),
    # after broadcasting the batch axes of X and U (only when they differ);
    # torch: ``movedim`` does the same without the deprecated n-d ``.T``.
    if xp is np:
        lines = ["    X, U = components(X, U)"]
    else:
        lines = [
            "    batch = xp.broadcast_shapes(X.shape[:-1], U.shape[:-1])",
            "    X, U = X.expand(*batch, X.shape[-1]), U.expand(*batch, U.shape[-1])",
            "    X = X.movedim(-1, 0)",
            "    U = U.movedim(-1, 0)",
        ]
    index = {name: f"X[{i}]" for i, name in enumerate(state_names)}
    index.update({name: f"U[{j}]" for j, name in enumerate(input_names)})
    return lines, index


def _finish(lines: list[str], exprs: list[str], xp: Any, into: bool = False) -> None:
    """Defines ``one`` if used, then stacks the expressions into (..., k).

    ``into`` (numpy): each expression is written into the output as it is computed, so the
    columns are not all held at once before they are stacked (a library of 519 terms on
    7,700 rows: 32 MB at the peak instead of 64).
    """
    if any("one" in e for e in exprs):
        lines.insert(1 if xp is np else 4, "    one = xp.ones_like(X[0])")
    if xp is np and into:
        lines.append(f"    out = xp.empty(({len(exprs)},) + xp.shape(X[0]))")
        lines.extend(f"    out[{j}] = {e}" for j, e in enumerate(exprs))
        lines.append("    return out.T")
    elif xp is np:
        lines.append(f"    return xp.array(({', '.join(exprs)},)).T")
    else:
        lines.append(f"    return xp.stack(xp.broadcast_tensors({', '.join(exprs)}), -1)")


def compile_features(
    names: Sequence[str], state_names: Sequence[str], input_names: Sequence[str], xp: Any = np
) -> Callable[[Any, Any], Any]:
    """Compiles Theta(X, U): features of states (..., n) and inputs (..., m) -> (..., p).

    Args:
        names: Feature names.
        state_names: Names of the state columns.
        input_names: Names of the input columns.
        xp: ``numpy`` or ``torch``.

    Returns:
        The feature function.
    """
    variables = [*state_names, *input_names]
    terms = [parse_term(n, variables) for n in names]
    lines, index = _header(state_names, input_names, xp)
    cache: dict[str, str] = {}
    exprs = [_term_expr(t, index, cache, lines) for t in terms]
    _finish(lines, exprs, xp, into=True)
    return _build("theta", lines, xp)


def compile_rhs(
    names: Sequence[str],
    coefficients: np.ndarray,
    state_names: Sequence[str],
    input_names: Sequence[str],
    xp: Any = np,
) -> Callable[[Any, Any], Any]:
    """Compiles dx/dt = Xi Theta(x, u) into straight-line code using only non-zero terms.

    Args:
        names: Feature names, length p.
        coefficients: Array (n_states, p).
        state_names: Names of the states (length n_states).
        input_names: Names of the inputs.
        xp: ``numpy`` or ``torch``.

    Returns:
        rhs(X, U) batched over leading axes, shape (..., n_states).
    """
    variables = [*state_names, *input_names]
    terms = [parse_term(n, variables) for n in names]
    lines, index = _header(state_names, input_names, xp)
    cache: dict[str, str] = {}
    rows = []
    for i in range(len(state_names)):
        parts = []
        for j, term in enumerate(terms):
            c = float(coefficients[i, j])
            if c != 0.0:
                parts.append(f"({c!r}) * {_term_expr(term, index, cache, lines)}")
        rows.append(" + ".join(parts) if parts else "0.0 * one")
    _finish(lines, rows, xp)
    return _build("rhs", lines, xp)


def _build(fname: str, lines: list[str], xp: Any) -> Callable[[Any, Any], Any]:
    source = f"def {fname}(X, U):\n" + "\n".join(lines) + "\n"
    namespace: dict[str, Any] = {"xp": xp, "components": components}
    exec(compile(source, f"<quad-sindy {fname}>", "exec"), namespace)  # noqa: S102 (names are parsed)
    func = namespace[fname]
    func.source = source
    return func
