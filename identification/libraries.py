"""Candidate libraries, as pysindy objects (the paper's) and as feature-name lists (ours).

Every library used for fitting is a list of feature names in the grammar of
:mod:`identification.features`; :func:`library_names` turns a pysindy library into such a list,
so the paper's exact pysindy library and our physics-informed ones are interchangeable.
"""

from __future__ import annotations

import itertools
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pysindy as ps

from identification.features import parse_term, term_name


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


PRESETS = ("planar", "quad6dof", "planar_drag", "quad6dof_drag")
"""Names of the preset libraries."""


def default_library(system: str) -> list[str]:
    """The library of a preset (:data:`PRESETS`) or of any registered vehicle's record."""
    from quad_envs.vehicles import VEHICLES

    if system == "planar_drag":
        return planar_drag_library()
    if system == "quad6dof_drag":
        return quad6dof_drag_library()
    if system in VEHICLES:
        return vehicle_library(system)
    valid = ", ".join(dict.fromkeys([*PRESETS, *VEHICLES]))
    raise ValueError(f"unknown system {system!r}; valid choices: {valid}")


@dataclass(frozen=True)
class LibrarySpec:
    """A library described by a few choices instead of a list of terms.

    Attributes:
        degree: Largest total degree of the polynomials in the non-angle variables.
        angles: Angle variables: they enter through sin(k a), cos(k a) only.
        frequencies: Largest k of the Fourier terms.
        trig_products: Multiply each Fourier term by every degree-1 monomial (states and inputs).
        input_products: Multiply each Fourier term by each input only (when not trig_products).
        extra: Further named features in the grammar of :mod:`identification.features`.
        drag: Velocity variables that get drag terms (:func:`drag_terms`); empty for none.
        drag_angle: The body angle turning inertial drag velocities (planar ``phi``); empty
            for body-frame velocities.
    """

    degree: int = 2
    angles: tuple[str, ...] = ()
    frequencies: int = 1
    trig_products: bool = True
    input_products: bool = True
    extra: tuple[str, ...] = field(default_factory=tuple)
    drag: tuple[str, ...] = field(default_factory=tuple)
    drag_angle: str = ""

    def build(self, state_names: Sequence[str], input_names: Sequence[str]) -> list[str]:
        """The feature names for these variables (duplicates removed, order kept)."""
        variables = [*state_names, *input_names]
        unknown = [a for a in self.angles if a not in variables]
        if unknown:
            raise ValueError(f"angle(s) {unknown} are not variables of the data {variables}")
        if self.degree < 0 or self.frequencies < 0:
            raise ValueError("degree and frequencies must be >= 0")
        plain = [v for v in variables if v not in self.angles]
        names = ["1"]
        for d in range(1, self.degree + 1):
            names += [" ".join(c) for c in itertools.combinations_with_replacement(plain, d)]
        fourier = [
            f"{fn}({k} {a})" if k > 1 else f"{fn}({a})"
            for a in self.angles
            for k in range(1, self.frequencies + 1)
            for fn in ("sin", "cos")
        ]
        mult = plain if self.trig_products else (input_names if self.input_products else [])
        mult = [m for m in mult if m not in self.angles]
        names += [f"{m} {f}" if m else f for f in fourier for m in ["", *mult]]
        names += list(self.extra)
        if self.drag:
            names += drag_terms(self.drag, self.drag_angle or None)
        canonical = [term_name(parse_term(n, variables)) for n in names]
        return list(dict.fromkeys(canonical))


def _parse_spec_text(text: str) -> dict[str, object]:
    """``degree=2;angles=phi,theta;extra=u1 sin(phi),y_dot^3`` -> a dict for LibrarySpec."""
    out: dict[str, object] = {}
    for item in filter(None, (p.strip() for p in text.split(";"))):
        key, sep, value = item.partition("=")
        if not sep:
            raise ValueError(
                f"library spec item {item!r} is not key=value (items are separated by ';')"
            )
        out[key.strip()] = value.strip()
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
        if key in ("degree", "frequencies"):
            text = value.strip() if isinstance(value, str) else value
            if isinstance(text, str) and text.lstrip("+-").isdigit():
                text = int(text)
            if isinstance(text, bool) or not isinstance(text, int):
                split = isinstance(value, str) and ("," in value or "=" in value)
                hint = " (items are separated by ';')" if split else ""
                raise ValueError(f"{source}: {key} must be an integer, got {value!r}{hint}")
            out[key] = text
        elif key in ("trig_products", "input_products"):
            if isinstance(value, str) and value.strip().lower() in _TRUE + _FALSE:
                value = value.strip().lower() in _TRUE
            if not isinstance(value, bool):
                raise ValueError(f"{source}: {key} must be true or false, got {value!r}")
            out[key] = value
        elif key in ("angles", "extra", "drag"):
            items = value.split(",") if isinstance(value, str) else value
            if not isinstance(items, list | tuple) or not all(isinstance(v, str) for v in items):
                raise ValueError(
                    f"{source}: {key} must be a list of names (or one comma-separated "
                    f"string), got {value!r}"
                )
            out[key] = tuple(v.strip() for v in items if v.strip())
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
        spec: ``planar`` / ``quad6dof`` (presets); a path to a TOML file with a ``[library]``
            table (keys of :class:`LibrarySpec`); a string such as
            ``degree=2;angles=phi;extra=u1 sin(phi);drag=y_dot,z_dot;drag_angle=phi``; a
            :class:`LibrarySpec`; a list of
            feature names; or None (``degree=2`` with the declared ``angles``).
        state_names: The data's states.
        input_names: The data's inputs.
        angles: Declared angle variables (used when the spec names none).

    Returns:
        Feature names.
    """
    variables = [*state_names, *input_names]
    if isinstance(spec, LibrarySpec):
        return spec.build(state_names, input_names)
    if spec is None:
        return LibrarySpec(angles=tuple(angles)).build(state_names, input_names)
    if isinstance(spec, str):
        if spec in PRESETS:
            names = default_library(spec)
            for name in names:
                parse_term(name, variables)  # raises naming a variable the data lack
            return names
        if spec.lower().endswith(".toml"):
            return LibrarySpec(**_read_toml(Path(spec), angles)).build(state_names, input_names)
        fields = _parse_spec_text(spec)
        fields.setdefault("angles", tuple(angles))
        return LibrarySpec(**fields).build(state_names, input_names)  # type: ignore[arg-type]
    names = [term_name(parse_term(n, variables)) for n in spec]
    return list(dict.fromkeys(names))


def spec_angles(spec: str | None) -> tuple[str, ...]:
    """The angles a spec string or TOML file declares (none for presets and None)."""
    if not spec or spec in PRESETS:
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
    if not isinstance(table, dict):
        raise ValueError(f"{path}: needs a [library] table")
    out = _check_fields(table, str(path))
    out.setdefault("angles", tuple(angles))
    return out
