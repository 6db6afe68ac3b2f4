"""The true coefficients of the ground-truth models, and comparisons against them."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from identification.features import Term, parse_term, term_name
from identification.libraries import default_library
from identification.model import IdentifiedModel
from quad_envs.params import PAPER_6DOF, PAPER_PLANAR, PlanarQuadParams, Quad6DOFParams
from quad_envs.vehicles import get_vehicle


def planar_truth(params: PlanarQuadParams = PAPER_PLANAR) -> dict[str, dict[str, float]]:
    """True planar model as {state: {feature: coefficient}} (7 terms)."""
    m = params.mass
    return {
        "y": {"y_dot": 1.0},
        "z": {"z_dot": 1.0},
        "phi": {"phi_dot": 1.0},
        "y_dot": {"u1 sin(phi)": -1.0 / m},
        "z_dot": {"1": -params.gravity, "u1 cos(phi)": 1.0 / m},
        "phi_dot": {"u2": 1.0 / params.Ixx},
    }


def quad6dof_truth(params: Quad6DOFParams = PAPER_6DOF) -> dict[str, dict[str, float]]:
    """True 6-DOF model (paper section 2) as {state: {feature: coefficient}}.

    36 terms; fewer for a symmetric vehicle, whose zero gyroscopic terms (``p q`` in ``r'``
    when Jxx = Jyy) are left out.
    """
    g, m = params.gravity, params.mass
    jx, jy, jz = params.Jxx, params.Jyy, params.Jzz
    truth = {
        "x": {
            "cos(psi) cos(theta) u": 1, "sin(phi) sin(psi) sin(theta) u": -1,
            "cos(phi) sin(psi) v": -1, "cos(psi) sin(theta) w": 1,
            "cos(theta) sin(phi) sin(psi) w": 1,
        },
        "y": {
            "cos(theta) sin(psi) u": 1, "cos(psi) sin(phi) sin(theta) u": 1,
            "cos(phi) cos(psi) v": 1, "sin(psi) sin(theta) w": 1,
            "cos(psi) cos(theta) sin(phi) w": -1,
        },
        "z": {"cos(phi) sin(theta) u": -1, "sin(phi) v": 1, "cos(phi) cos(theta) w": 1},
        "phi": {"cos(theta) p": 1, "sin(theta) r": 1},
        "theta": {"q": 1, "tan(phi) sin(theta) p": 1, "tan(phi) cos(theta) r": -1},
        "psi": {"sec(phi) sin(theta) p": -1, "sec(phi) cos(theta) r": 1},
        "u": {"cos(phi) sin(theta)": g, "r v": 1, "q w": -1},
        "v": {"sin(phi)": -g, "p w": 1, "r u": -1},
        "w": {"cos(phi) cos(theta)": -g, "u1": 1 / m, "q u": 1, "p v": -1},
        "p": {"u2": 1 / jx, "q r": -(jz - jy) / jx},
        "q": {"u3": 1 / jy, "p r": -(jx - jz) / jy},
        "r": {"u4": 1 / jz, "p q": -(jy - jx) / jz},
    }  # fmt: skip
    return {state: {f: c for f, c in terms.items() if c != 0} for state, terms in truth.items()}


def truth_for(system: str) -> dict[str, dict[str, float]]:
    """The true model of ``planar`` or ``quad6dof`` with the paper's parameters."""
    if system == "planar":
        return planar_truth()
    if system == "quad6dof":
        return quad6dof_truth()
    raise ValueError(f"unknown system {system!r}; valid choices: planar, quad6dof")


def truth_matrix(
    truth: dict[str, dict[str, float]], state_names: Sequence[str], feature_names: Sequence[str]
) -> np.ndarray:
    """True coefficients in a library's columns, shape (n_states, n_features).

    Raises:
        ValueError: A true term is missing from the library (the truth is not in it).
    """
    column: dict[Term, int] = {}
    for j, name in enumerate(feature_names):
        column.setdefault(parse_term(name), j)
    xi = np.zeros((len(state_names), len(feature_names)))
    for i, state in enumerate(state_names):
        for name, value in truth.get(state, {}).items():
            term = parse_term(name)
            if term not in column:
                raise ValueError(f"true term {term_name(term)!r} of {state}' is not in the library")
            xi[i, column[term]] = value
    return xi


@dataclass
class Comparison:
    """Identified coefficients against the truth in the same library.

    Attributes:
        true: True coefficients (n_states, p).
        found: Identified coefficients (n_states, p).
        rel_error: |found - true| / |true| on true terms (NaN elsewhere).
        n_true: Number of true terms.
        missed: True terms the fit set to zero.
        spurious: Terms the fit kept that are zero in the truth.
    """

    true: np.ndarray
    found: np.ndarray
    rel_error: np.ndarray
    n_true: int
    missed: list[tuple[str, str]]
    spurious: list[tuple[str, str, float]]

    @property
    def max_rel_error(self) -> float:
        """Largest relative error over the true terms (inf if one was missed)."""
        if self.missed:
            return float("inf")
        return float(np.nanmax(self.rel_error)) if self.n_true else 0.0

    @property
    def exact_support(self) -> bool:
        """No missed and no spurious terms."""
        return not self.missed and not self.spurious

    def support_dict(self) -> dict[str, int]:
        """Counts of true, missed and spurious terms."""
        return {"true": self.n_true, "missed": len(self.missed), "spurious": len(self.spurious)}


def compare_coefficients(
    found: np.ndarray,
    truth: dict[str, dict[str, float]],
    state_names: Sequence[str],
    feature_names: Sequence[str],
) -> Comparison:
    """Compares identified coefficients with the truth (duplicate columns are summed)."""
    # Merge duplicate columns (the paper's library has sin(phi) twice).
    canon = [parse_term(n) for n in feature_names]
    unique = list(dict.fromkeys(canon))
    merge = np.zeros((len(feature_names), len(unique)))
    for j, term in enumerate(canon):
        merge[j, unique.index(term)] = 1.0
    found_u = found @ merge
    names_u = [term_name(t) for t in unique]
    true_u = truth_matrix(truth, state_names, names_u)
    is_true = true_u != 0
    rel = np.full(true_u.shape, np.nan)
    rel[is_true] = np.abs(found_u[is_true] - true_u[is_true]) / np.abs(true_u[is_true])
    missed = [
        (state_names[i], names_u[j])
        for i, j in zip(*np.nonzero(is_true & (found_u == 0)), strict=True)
    ]
    spurious = [
        (state_names[i], names_u[j], float(found_u[i, j]))
        for i, j in zip(*np.nonzero(~is_true & (found_u != 0)), strict=True)
    ]
    return Comparison(true_u, found_u, rel, int(is_true.sum()), missed, spurious)


def model_from_truth(system: str, feature_names: Sequence[str] | None = None) -> IdentifiedModel:
    """The ground truth written as a model in a library (default: the system's library)."""
    sys_ = get_vehicle(system)
    names = list(feature_names) if feature_names is not None else default_library(system)
    xi = truth_matrix(truth_for(system), sys_.state_names, names)
    return IdentifiedModel(
        names, xi, sys_.state_names, sys_.input_names, system, {"method": "truth"}
    )
