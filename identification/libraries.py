"""Candidate libraries, as pysindy objects (the paper's) and as feature-name lists (ours).

Every library used for fitting is a list of feature names in the grammar of
:mod:`identification.features`; :func:`library_names` turns a pysindy library into such a list,
so the paper's exact pysindy library and our physics-informed ones are interchangeable.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence

import numpy as np
import pysindy as ps

from identification.features import parse_term, term_name
from quad_envs.dynamics import (
    PLANAR_INPUT_NAMES,
    PLANAR_STATE_NAMES,
    QUAD6DOF_INPUT_NAMES,
)


def paper_planar_library(include_duplicate: bool = True) -> ps.GeneralizedLibrary:
    """The paper's pysindy library: degree-1 polynomials of every variable but phi, Fourier(phi).

    With ``include_duplicate`` (the authors' setting) the Fourier library is kept beside the
    tensor product, so ``sin(phi)`` and ``cos(phi)`` appear twice: 26 columns. Without it: 24.
    """
    non_angles = [0, 1, 3, 4, 5, 6, 7]  # y, z, y_dot, z_dot, phi_dot, u1, u2
    return ps.GeneralizedLibrary(
        [ps.PolynomialLibrary(degree=1), ps.FourierLibrary(n_frequencies=1)],
        tensor_array=[[1, 1]],
        inputs_per_library=[non_angles, [2]],
        exclude_libraries=[] if include_duplicate else [1],
    )


def library_names(
    library: ps.feature_library.base.BaseFeatureLibrary,
    state_names: Sequence[str],
    input_names: Sequence[str],
) -> list[str]:
    """Feature names of a pysindy library over (states, inputs), in its column order."""
    names = [*state_names, *input_names]
    library.fit(np.random.default_rng(0).normal(size=(8, len(names))))
    return list(library.get_feature_names(names))


def planar_library() -> list[str]:
    """Default planar library: the paper's 24 distinct terms (canonical names).

    1, y, z, y_dot, z_dot, phi_dot, u1, u2 and each of them times sin(phi) and cos(phi).
    """
    raw = library_names(paper_planar_library(False), PLANAR_STATE_NAMES, PLANAR_INPUT_NAMES)
    return [term_name(parse_term(n)) for n in raw]


def quad6dof_library() -> list[str]:
    """Default 6-DOF library (519 terms): trig products times velocities, rates, inputs.

    Every product f(phi) g(theta) h(psi) with f in {1, sin, cos, tan, sec}, g and h in
    {1, sin, cos}, times one of {1, u, v, w, p, q, r, u1..u4}; the 21 quadratic products of
    velocities and rates (gyroscopic and Coriolis terms); and x, y, z as distractors.
    The true 6-DOF model (36 terms) lies in it.
    """
    phi = ["", "sin(phi)", "cos(phi)", "tan(phi)", "sec(phi)"]
    theta = ["", "sin(theta)", "cos(theta)"]
    psi = ["", "sin(psi)", "cos(psi)"]
    mult = ["", "u", "v", "w", "p", "q", "r", *QUAD6DOF_INPUT_NAMES]
    names = []
    for f, g, h, m in itertools.product(phi, theta, psi, mult):
        names.append(" ".join(x for x in (f, g, h, m) if x) or "1")
    moving = ["u", "v", "w", "p", "q", "r"]
    names += [
        f"{a} {b}" if a != b else f"{a}^2"
        for a, b in itertools.combinations_with_replacement(moving, 2)
    ]
    names += ["x", "y", "z"]
    return [term_name(parse_term(n)) for n in names]


def generic_library(
    state_names: Sequence[str],
    input_names: Sequence[str],
    angle_names: Sequence[str] = (),
    degree: int = 2,
    n_frequencies: int = 1,
) -> list[str]:
    """A configurable polynomial/Fourier library.

    Polynomials up to ``degree`` in the non-angle variables (states and inputs), Fourier
    terms sin(k a), cos(k a) up to ``n_frequencies`` of each angle, and the products of each
    Fourier term with every degree-1 monomial.
    """
    plain = [v for v in [*state_names, *input_names] if v not in angle_names]
    monomials = ["1"]
    for d in range(1, degree + 1):
        for combo in itertools.combinations_with_replacement(plain, d):
            monomials.append(" ".join(combo))
    fourier = [
        f"{fn}({k} {a})" if k > 1 else f"{fn}({a})"
        for a in angle_names
        for k in range(1, n_frequencies + 1)
        for fn in ("sin", "cos")
    ]
    names = monomials + [f"{m} {f}" if m != "1" else f for f in fourier for m in ["1", *plain]]
    canonical = [term_name(parse_term(n)) for n in names]
    return list(dict.fromkeys(canonical))  # drop duplicates, keep order


def default_library(system: str) -> list[str]:
    """The physics-informed default library of ``planar`` or ``quad6dof``."""
    if system == "planar":
        return planar_library()
    if system == "quad6dof":
        return quad6dof_library()
    raise ValueError(f"unknown system {system!r}; valid choices: planar, quad6dof")
