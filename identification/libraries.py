"""Candidate libraries, as pysindy objects (the paper's) and as feature-name lists (ours).

Every library used for fitting is a list of feature names in the grammar of
:mod:`identification.features`; :func:`library_names` turns a pysindy library into such a list,
so the paper's exact pysindy library and our physics-informed ones are interchangeable.
"""

from __future__ import annotations

import itertools
import math
import os
import re
import sys
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pysindy as ps

from identification.features import Factor, Term, parse_term, term_name


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


def vehicle_library(name: str) -> list[str]:
    """The physics-informed library a registered vehicle's record names, in canonical names."""
    from quad_envs.vehicles import get_vehicle

    return [term_name(parse_term(n)) for n in get_vehicle(name).library()]


def planar_library() -> list[str]:
    """Default planar library: the paper's 24 distinct terms (the planar vehicle's record).

    1, y, z, y_dot, z_dot, phi_dot, u1, u2 and each of them times sin(phi) and cos(phi).
    """
    return vehicle_library("planar")


def quad6dof_library() -> list[str]:
    """Default 6-DOF library (519 terms, from the 6-DOF vehicle's record).

    Trig products of the Euler angles times velocities, rates and inputs, gyroscopic
    products, and distractors.
    """
    return vehicle_library("quad6dof")


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


def drag_terms(velocities: Sequence[str], angle: str | None = None) -> list[str]:
    """Candidate drag terms: linear (rotor) drag and quadratic (body) drag.

    For each velocity v: ``v`` and ``v norm(velocities)`` (force -(D + c |v|) v per axis,
    |v| the speed). If the velocities are inertial and the body axes turn by ``angle`` in
    their plane (the planar vehicle), the drag matrix R diag(D_lat, D_up) R^T also needs
    ``v cos(2 angle)`` and ``v sin(2 angle)`` (each also times the norm); with equal drag on
    both axes their coefficients are zero.

    Args:
        velocities: The air-relative velocity variables (e.g. ``y_dot, z_dot`` or ``u, v, w``).
        angle: The body angle when the velocities are inertial; None for body-frame ones.

    Returns:
        Canonical feature names (duplicates removed).
    """
    speed = f"norm({' '.join(velocities)})" if len(velocities) > 1 else f"abs({velocities[0]})"
    turns = ["", f"cos(2 {angle})", f"sin(2 {angle})"] if angle else [""]
    names = [
        " ".join(x for x in (v, turn, quad) if x)
        for quad in ("", speed)
        for turn in turns
        for v in velocities
    ]
    return list(dict.fromkeys(term_name(parse_term(n)) for n in names))


def planar_drag_library() -> list[str]:
    """The planar library plus drag terms of (y_dot, z_dot) turned by phi (34 terms)."""
    return list(dict.fromkeys([*planar_library(), *drag_terms(["y_dot", "z_dot"], "phi")]))


def quad6dof_drag_library() -> list[str]:
    """The 6-DOF library plus quadratic drag of the body velocities (522 terms)."""
    return list(dict.fromkeys([*quad6dof_library(), *drag_terms(["u", "v", "w"])]))


def rotor_names(rotors: int) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """Names of the rotor thrust states and of their commands: (T1..Tk), (Tc1..Tck)."""
    return (tuple(f"T{i + 1}" for i in range(rotors)),
            tuple(f"Tc{i + 1}" for i in range(rotors)))  # fmt: skip


def rotor_library(system: str) -> list[str]:
    """A preset library with the rotor thrusts and their commands in the inputs' place.

    For data with rotor dynamics (a first-order lag from each command Tc_i to the thrust
    state T_i: ``collect_rollouts`` records them so): every term of the preset that holds
    the thrust ``u1`` is repeated with each of T1..Tk and Tc1..Tck in its place, and the
    terms of the moments (u2..) are dropped, the moments being linear in the thrusts. The
    rest is kept. ``planar``: 18 + 3 x 4 = 30 terms; ``quad6dof``: 339 + 45 x 8 = 699.
    """
    from quad_envs.vehicles import get_vehicle

    record = get_vehicle(system)
    thrusts, commands = rotor_names(int(record.params.mixer.shape[1]))
    variables = (*record.state_names, *thrusts, *commands)
    inputs = "|".join(record.input_names)
    names: list[str] = []
    for name in default_library(system):
        held = re.findall(rf"\b({inputs})\b", name)
        if not held:
            names.append(name)
        elif held == [record.input_names[0]]:
            names += [re.sub(rf"\b{held[0]}\b", rotor, name) for rotor in (*thrusts, *commands)]
    return list(dict.fromkeys(term_name(parse_term(n, variables)) for n in names))


PRESETS = ("planar", "quad6dof", "planar_drag", "quad6dof_drag", "planar_rotors", "quad6dof_rotors")
"""Names of the preset libraries."""

PRESET_SUFFIXES = ("_drag", "_rotors")
"""A preset is its vehicle's name, or that name with one of these suffixes."""


def default_library(system: str) -> list[str]:
    """The library of a preset (:data:`PRESETS`) or of any registered vehicle's record."""
    from quad_envs.vehicles import VEHICLES

    if system == "planar_drag":
        return planar_drag_library()
    if system == "quad6dof_drag":
        return quad6dof_drag_library()
    if system in ("planar_rotors", "quad6dof_rotors"):
        return rotor_library(system.removesuffix("_rotors"))
    if system in VEHICLES:
        return vehicle_library(system)
    valid = ", ".join(dict.fromkeys([*PRESETS, *VEHICLES]))
    raise ValueError(f"unknown system {system!r}; valid choices: {valid}")


TRIG_FUNCTIONS = ("sin", "cos", "tan", "sec")
"""Functions that make an angle's factors in a :class:`LibrarySpec` (``functions``)."""

MAX_TERMS = 5000
"""Largest library a :class:`LibrarySpec` builds (a fit of more columns takes hours)."""

_FUNCTION_ENTRY = re.compile(r"^(sin|cos|tan|sec)(?:\(\s*([A-Za-z_]\w*)\s*\))?$")


def _function_entry(entry: str) -> tuple[str, str]:
    """``tan(theta)`` -> ("tan", "theta"); ``sin`` -> ("sin", "") (every angle)."""
    match = _FUNCTION_ENTRY.match(entry.strip())
    if not match:
        raise ValueError(
            f"functions entry {entry!r} is not one of {', '.join(TRIG_FUNCTIONS)} (every angle) "
            "or one of them of one angle such as tan(theta) (frequencies sets the multiples)"
        )
    return match.group(1), match.group(2) or ""


@dataclass(frozen=True)
class LibrarySpec:
    """A library described by a few choices instead of a list of terms.

    The library is: ``1`` and the polynomials of the non-angle variables up to ``degree``;
    then each trig factor alone and times each monomial of degree 1 to ``trig_degree`` in
    the multipliers; then ``extra`` and the ``drag`` terms. Duplicates are dropped, the
    first kept. A trig factor is one angle's function (``sin(phi)``, ``cos(2 phi)``,
    ``tan(theta)``) or, with ``angle_products``, a product of at most one such function
    per angle (``cos(phi) sin(theta) cos(psi)``). The defaults give the libraries of
    earlier versions, term for term.

    Attributes:
        degree: Largest total degree of the polynomials in the non-angle variables.
        angles: Angle variables: they enter through their functions (``functions``) only.
        frequencies: Largest k of sin(k a) and cos(k a); tan and sec take k = 1 only
            (tan(2 a) has poles inside the range of a tilt). 0: no trig factors.
        trig_products: Multiply the trig factors by every non-angle variable (states and
            inputs).
        input_products: Multiply the trig factors by each input only (when not
            trig_products).
        extra: Further named features in the grammar of :mod:`identification.features`.
        drag: Velocity variables that get drag terms (:func:`drag_terms`); empty for none.
        drag_angle: The body angle turning inertial drag velocities (planar ``phi``); empty
            for body-frame velocities.
        trig_degree: Largest total degree of the monomials of the multipliers that multiply
            each trig factor: 1 gives ``sin(phi) w1``, 2 also ``sin(phi) w1^2`` and
            ``sin(phi) w1 w2`` (thrust k w^2 from motor speeds); 0 leaves the trig factors
            bare.
        functions: Which functions make the angle factors: ``sin``, ``cos``, ``tan``,
            ``sec`` for every angle, or one of them of one angle, e.g.
            ``("sin", "cos", "tan(theta)", "sec(theta)")`` (Z-Y-X Euler rates).
        angle_products: Make the trig factors every product of at most one function per
            angle (the empty product, i.e. the bare multipliers, is the polynomials' part),
            as the rotation matrix of three Euler angles needs: with 3 angles and
            ``sin, cos`` 26 factors instead of 6.
        multipliers: The variables whose monomials multiply the trig factors (e.g. the
            rates and the rotor inputs, leaving positions out); empty: the
            trig_products / input_products rule. When given it replaces that rule.
        exclude: Factors to leave out: every built term that holds one of them is dropped
            (``qw^2`` drops ``qw^2``, ``qw^3`` and ``qw^2 vx`` but not ``qw vx``; ``px``
            drops every term with ``px``; ``1`` drops the constant only). Terms listed in
            ``extra`` are kept. For identities of the variables that no data can break
            (a unit quaternion: ``qw^2 + qx^2 + qy^2 + qz^2 = 1``) and for variables that
            should not enter (positions).
    """

    degree: int = 2
    angles: tuple[str, ...] = ()
    frequencies: int = 1
    trig_products: bool = True
    input_products: bool = True
    extra: tuple[str, ...] = field(default_factory=tuple)
    drag: tuple[str, ...] = field(default_factory=tuple)
    drag_angle: str = ""
    trig_degree: int = 1
    functions: tuple[str, ...] = ("sin", "cos")
    angle_products: bool = False
    multipliers: tuple[str, ...] = field(default_factory=tuple)
    exclude: tuple[str, ...] = field(default_factory=tuple)

    def build(self, state_names: Sequence[str], input_names: Sequence[str]) -> list[str]:
        """The feature names for these variables (duplicates removed, order kept).

        Raises:
            ValueError: An angle or multiplier is not a variable, a value is out of range,
                or the library would hold more than :data:`MAX_TERMS` terms.
        """
        variables = [*state_names, *input_names]
        unknown = [a for a in self.angles if a not in variables]
        if unknown:
            raise ValueError(f"angle(s) {unknown} are not variables of the data {variables}")
        if self.degree < 0 or self.frequencies < 0:
            raise ValueError("degree and frequencies must be >= 0")
        if self.trig_degree < 0:
            raise ValueError(f"trig_degree must be >= 0, got {self.trig_degree}")
        plain = [v for v in variables if v not in self.angles]
        factors = self._angle_factors()
        mult = self._multiplier_variables(plain, input_names, variables)
        self._check_size(len(plain), factors, len(mult))
        names = ["1"]
        for d in range(1, self.degree + 1):
            names += [" ".join(c) for c in itertools.combinations_with_replacement(plain, d)]
        if self.angle_products:
            choices = [["", *f] for f in factors.values()]
            fourier = [" ".join(x for x in c if x) for c in itertools.product(*choices)][1:]
        else:
            fourier = [f for per_angle in factors.values() for f in per_angle]
        monomials = [""]
        for d in range(1, self.trig_degree + 1):
            monomials += [" ".join(c) for c in itertools.combinations_with_replacement(mult, d)]
        names += [f"{m} {f}" if m else f for f in fourier for m in monomials]
        extra = range(len(names), len(names) + len(self.extra))  # kept whatever exclude says
        names += list(self.extra)
        if self.drag:
            names += drag_terms(self.drag, self.drag_angle or None)
        dropped = [parse_term(e, variables) for e in self.exclude]
        terms = [parse_term(n, variables) for n in names]
        kept = [t for i, t in enumerate(terms)
                if i in extra or not any(_holds(t, d) for d in dropped)]  # fmt: skip
        return list(dict.fromkeys(term_name(t) for t in kept))

    def _angle_factors(self) -> dict[str, list[str]]:
        """Each angle's factors: for k = 1..frequencies, each function that applies to it."""
        if not self.functions:
            raise ValueError(f"functions must name at least one of {', '.join(TRIG_FUNCTIONS)}")
        entries = [_function_entry(e) for e in self.functions]
        angles = list(dict.fromkeys(self.angles))
        stray = [f"{fn}({a})" for fn, a in entries if a and a not in angles]
        if stray:
            declared = ",".join(angles) or "none"
            raise ValueError(
                f"functions entry {stray[0]} is of an angle not declared (angles: {declared})"
            )
        factors = {}
        for a in angles:
            fns = list(dict.fromkeys(fn for fn, only in entries if only in ("", a)))
            factors[a] = [
                f"{fn}({k} {a})" if k > 1 else f"{fn}({a})"
                for k in range(1, self.frequencies + 1)
                for fn in fns
                if k == 1 or fn in ("sin", "cos")
            ]
        return factors

    def _multiplier_variables(
        self, plain: Sequence[str], input_names: Sequence[str], variables: Sequence[str]
    ) -> list[str]:
        """The variables whose monomials multiply the trig factors."""
        if not self.multipliers:
            mult = plain if self.trig_products else (input_names if self.input_products else [])
            return [m for m in mult if m not in self.angles]
        unknown = [m for m in self.multipliers if m not in variables]
        if unknown:
            raise ValueError(f"multipliers {unknown} are not variables of the data {variables}")
        angles = [m for m in self.multipliers if m in self.angles]
        if angles:
            raise ValueError(
                f"multipliers {angles} are angles: an angle enters only through its functions"
            )
        return list(dict.fromkeys(self.multipliers))

    def _check_size(self, n_plain: int, factors: dict[str, list[str]], n_mult: int) -> None:
        """Refuses, before building it, a library of more than :data:`MAX_TERMS` terms."""
        counts = [len(f) for f in factors.values()]
        n_trig = math.prod(c + 1 for c in counts) - 1 if self.angle_products else sum(counts)
        n_poly = math.comb(n_plain + self.degree, self.degree)
        n_mono = math.comb(n_mult + self.trig_degree, self.trig_degree)
        n_drag = len(self.drag) * (6 if self.drag_angle else 2)
        total = n_poly + n_trig * n_mono + len(self.extra) + n_drag
        if total > MAX_TERMS:
            raise ValueError(
                f"library spec would build {total} terms, over the limit of {MAX_TERMS}: "
                f"{n_poly} polynomials (degree={self.degree}, {n_plain} variables) and "
                f"{n_trig} trig factors (angles={','.join(factors)}, "
                f"functions={','.join(self.functions)}, frequencies={self.frequencies}, "
                f"angle_products={str(self.angle_products).lower()}) times {n_mono} "
                f"monomials (trig_degree={self.trig_degree}, {n_mult} multipliers); lower "
                "degree, trig_degree or frequencies, name fewer multipliers or functions, or "
                "set angle_products=false"
            )


def _holds(term: Term, part: Term) -> bool:
    """Whether ``term`` holds every factor of ``part`` (a power at least as high).

    The constant (the empty ``part``) is held by the constant only.
    """
    if not part:
        return not term

    def key(f: Factor) -> tuple[str, str, int]:  # a power's degree is compared, not matched
        return f.var, f.kind, 0 if f.kind == "pow" else f.k

    have = {key(f): f.k for f in term}
    return all(have.get(key(f), 0) >= f.k for f in part)


_LIST_KEYS = ("angles", "extra", "drag", "functions", "multipliers", "exclude")
"""Spec keys whose value is a list of names: comma-separated, or the key given again."""


def _parse_spec_text(text: str) -> dict[str, object]:
    """``degree=2;angles=phi,theta;extra=u1 sin(phi),y_dot^3`` -> a dict for LibrarySpec.

    A list key given again adds to its list (``extra=a;extra=b`` is ``extra=a,b``: the docs'
    own commands wrote it so, and only the last one counted).
    """
    out: dict[str, object] = {}
    items = [p.strip() for p in text.split(";") if p.strip()]
    if not items:  # (an empty --library was a library without angles, silently)
        raise ValueError(f"library spec {text!r} is empty: leave --library out for the default")
    for item in items:
        key, sep, value = item.partition("=")
        if not sep:
            from quad_envs.vehicles import VEHICLES

            raise ValueError(
                f"library spec item {item!r} is not key=value (items are separated by ';'); "
                f"a preset is one of {', '.join(dict.fromkeys([*PRESETS, *VEHICLES]))}"
            )
        key = key.strip()
        if key in out and key in _LIST_KEYS:
            out[key] = f"{out[key]},{value.strip()}"
            continue
        if key in out:  # (the last one won, silently)
            raise ValueError(
                f"library spec gives {key!r} twice: give it once (lists such as extra take "
                "names separated by ',')"
            )
        out[key] = value.strip()
    return _check_fields(out, "library spec")


_TRUE, _FALSE = ("1", "true", "yes", "on"), ("0", "false", "no", "off")


def _check_fields(fields: dict[str, object], source: str) -> dict[str, object]:
    """Checks and converts the values of a spec (text values or TOML values) for LibrarySpec."""
    allowed = set(LibrarySpec.__dataclass_fields__)
    unknown = sorted(set(fields) - allowed)
    if unknown:
        raise ValueError(f"{source}: unknown key(s) {unknown}; valid: {sorted(allowed)}")
    out: dict[str, object] = {}
    for key, value in fields.items():
        if key in ("degree", "frequencies", "trig_degree"):
            text = value.strip() if isinstance(value, str) else value
            if isinstance(text, str) and text.lstrip("+-").isdigit():
                text = int(text)
            if isinstance(text, bool) or not isinstance(text, int):
                split = isinstance(value, str) and ("," in value or "=" in value)
                hint = " (items are separated by ';')" if split else ""
                raise ValueError(f"{source}: {key} must be an integer, got {value!r}{hint}")
            out[key] = text
        elif key in ("trig_products", "input_products", "angle_products"):
            if isinstance(value, str) and value.strip().lower() in _TRUE + _FALSE:
                value = value.strip().lower() in _TRUE
            if not isinstance(value, bool):
                raise ValueError(f"{source}: {key} must be true or false, got {value!r}")
            out[key] = value
        elif key in _LIST_KEYS:
            items = value.split(",") if isinstance(value, str) else value
            if not isinstance(items, list | tuple) or not all(isinstance(v, str) for v in items):
                raise ValueError(
                    f"{source}: {key} must be a list of names (or one comma-separated "
                    f"string), got {value!r}"
                )
            out[key] = tuple(v.strip() for v in items if v.strip())
            if key == "functions":
                if not out[key]:
                    raise ValueError(
                        f"{source}: functions must name at least one of {', '.join(TRIG_FUNCTIONS)}"
                    )
                for entry in out[key]:  # type: ignore[union-attr]
                    try:
                        _function_entry(entry)
                    except ValueError as exc:
                        raise ValueError(f"{source}: {exc}") from None
        else:  # drag_angle
            if not isinstance(value, str):
                raise ValueError(f"{source}: {key} must be a variable name, got {value!r}")
            out[key] = value.strip()
    return out


def library_from_spec(
    spec: str | LibrarySpec | Sequence[str] | None,
    state_names: Sequence[str],
    input_names: Sequence[str],
    angles: Sequence[str] = (),
) -> list[str]:
    """A library from a preset name, a spec string, a TOML file, a spec or a list of terms.

    Args:
        spec: A preset (:data:`PRESETS`) or a registered vehicle's name: its own library,
            written for its variable names; a path to a TOML file with a ``[library]``
            table (keys of :class:`LibrarySpec`); a string of ``key=value`` items separated
            by ``;`` such as ``degree=2;angles=phi;extra=u1 sin(phi)``,
            ``degree=2;angles=phi;trig_degree=2;multipliers=w1,w2`` (``sin(phi) w1^2``) or
            ``degree=2;angles=phi,theta,psi;functions=sin,cos,tan(theta),sec(theta);``
            ``angle_products=true;multipliers=p,q,r,f1,f2,f3,f4`` (6-DOF, Z-Y-X angles); a
            :class:`LibrarySpec`; a list of feature names; or None (``degree=2`` with the
            declared ``angles``).
        state_names: The data's states.
        input_names: The data's inputs.
        angles: Declared angle variables (used when the spec names none).

    Returns:
        Feature names.

    Raises:
        ValueError: In one line: a preset whose variables the data lack (naming both sets,
            ``--columns`` and a spec in the data's names), a bad key or value, or a spec of
            more than :data:`MAX_TERMS` terms.
    """
    variables = [*state_names, *input_names]
    if isinstance(spec, LibrarySpec):
        return spec.build(state_names, input_names)
    if spec is None:
        return LibrarySpec(angles=tuple(angles)).build(state_names, input_names)
    if isinstance(spec, str):
        if _is_preset(spec):
            names = default_library(spec)
            _check_preset_variables(spec, names, variables, angles)
            return names
        if spec.lower().endswith(".toml"):
            return LibrarySpec(**_read_toml(Path(spec), angles)).build(state_names, input_names)
        fields = _parse_spec_text(spec)
        fields.setdefault("angles", tuple(angles))
        return LibrarySpec(**fields).build(state_names, input_names)  # type: ignore[arg-type]
    if isinstance(spec, os.PathLike):
        return library_from_spec(os.fspath(spec), state_names, input_names, angles)
    unordered = isinstance(spec, set | frozenset)
    terms = list(spec) if isinstance(spec, Iterable) and not unordered else None
    if terms is None or not all(isinstance(n, str) for n in terms):
        hint = " (a set has no order: give a list)" if unordered else ""
        raise ValueError(
            "a library is a preset name, a spec string, a TOML path, a LibrarySpec or a list "
            f"of term names, got {type(spec).__name__} {str(spec)[:80]!r}{hint}"
        )
    names = [term_name(parse_term(n, variables)) for n in terms]
    return list(dict.fromkeys(names))


def _is_preset(spec: str) -> bool:
    """Whether a library text is a preset or a registered vehicle's name."""
    from quad_envs.vehicles import VEHICLES

    return spec in PRESETS or spec in VEHICLES


def _check_preset_variables(
    preset: str, names: Sequence[str], variables: Sequence[str], angles: Sequence[str]
) -> None:
    """Refuses, in one line, a preset whose variables the data lack, with the ways out."""
    from quad_envs.vehicles import get_vehicle

    used = {v for n in names for f in parse_term(n) for v in f.variables()}
    missing = used - set(variables)
    if not missing:
        return
    base = preset
    for suffix in PRESET_SUFFIXES:
        base = base.removesuffix(suffix)
    record = get_vehicle(base)
    order = [*record.state_names, *record.input_names]
    if preset.endswith("_rotors"):
        thrusts, commands = rotor_names(int(record.params.mixer.shape[1]))
        order = [*record.state_names, *thrusts, *commands]
    own = [v for v in order if v in used] + sorted(used - set(order))
    lacked = [v for v in own if v in missing]
    example = _preset_as_spec(names, record.angle_names, angles)
    raise ValueError(
        f"library {preset!r} is a preset written for the variables {', '.join(own)}; the "
        f"data lack {', '.join(lacked)} (the data's: {', '.join(variables)}): rename the "
        "data's columns to the preset's names with --columns, or write the library in the "
        f'data\'s names, e.g. --library "{example}" (multipliers=... chooses what the trig '
        "factors multiply)"
    )


def _preset_as_spec(
    names: Sequence[str], preset_angles: Sequence[str], angles: Sequence[str]
) -> str:
    """A spec text with a preset's structure, in the declared angles' names if given."""
    terms = [parse_term(n) for n in names]
    trig = [[f for f in t if f.kind in TRIG_FUNCTIONS] for t in terms]
    power = [sum(f.k for f in t if f.kind == "pow") for t in terms]
    uses = {(f.kind, f.var) for fs in trig for f in fs}
    preset_angles = [a for a in preset_angles if any(a == var for _, var in uses)]
    same = len(angles) == len(preset_angles)
    rename = dict(zip(preset_angles, angles, strict=True)) if same else {}
    functions = [fn for fn in TRIG_FUNCTIONS if all((fn, a) in uses for a in preset_angles)]
    functions += [f"{fn}({rename.get(a, a)})" for fn in TRIG_FUNCTIONS for a in preset_angles
                  if fn not in functions and (fn, a) in uses]  # fmt: skip
    degree = max((d for d, fs in zip(power, trig, strict=True) if not fs), default=0)
    trig_degree = max((d for d, fs in zip(power, trig, strict=True) if fs), default=1)
    items = [f"degree={degree}", f"angles={','.join(rename.get(a, a) for a in preset_angles)}"]
    if functions != ["sin", "cos"]:
        items.append(f"functions={','.join(functions)}")
    if any(len({f.var for f in fs}) > 1 for fs in trig):
        items.append("angle_products=true")
    if trig_degree != 1:
        items.append(f"trig_degree={trig_degree}")
    return ";".join(items)


def spec_angles(spec: str | None) -> tuple[str, ...]:
    """The angles a spec string or TOML file declares (none for presets, vehicles and None)."""
    if not spec or _is_preset(spec):
        return ()
    toml = spec.lower().endswith(".toml")
    fields = _read_toml(Path(spec), ()) if toml else _parse_spec_text(spec)
    return tuple(fields.get("angles", ()))  # type: ignore[arg-type]


def _read_toml(path: Path, angles: Sequence[str]) -> dict[str, object]:
    if sys.version_info >= (3, 11):
        import tomllib
    else:  # pragma: no cover
        import tomli as tomllib
    if not path.exists():
        raise FileNotFoundError(f"no such library file: {path}")
    try:
        table = tomllib.loads(path.read_text()).get("library")
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{path}: malformed TOML ({exc})") from None
    except UnicodeDecodeError:
        raise ValueError(f"{path} is not a TOML file: not text (binary?)") from None
    if not isinstance(table, dict):
        raise ValueError(f"{path}: needs a [library] table")
    out = _check_fields(table, str(path))
    out.setdefault("angles", tuple(angles))
    return out
