"""Library specs: today's defaults, the keys for rotor-input vehicles, preset errors.

A new-user trial (motor speeds, thrust = k w^2; a 6-DOF X quad with per-rotor thrusts and
Z-Y-X angles) could write neither ``sin(phi) w1^2`` nor ``cos(phi) sin(theta) cos(psi) f1``
nor ``tan(theta) q`` as a spec; only an ``extra`` list of every term worked.
"""

import itertools
import math

import numpy as np
import pytest

from identification.data import Trajectory
from identification.features import parse_term, term_name
from identification.libraries import (
    MAX_TERMS,
    LibrarySpec,
    generic_library,
    library_from_spec,
    quad6dof_library,
    spec_angles,
)
from identification.selection import select_model

PS = ("y", "z", "phi", "y_dot", "z_dot", "phi_dot")
PI = ("u1", "u2")
Q6S = ("x", "y", "z", "phi", "theta", "psi", "u", "v", "w", "p", "q", "r")
Q6I = ("u1", "u2", "u3", "u4")
"""The 6-DOF preset's own variable names."""
QS = ("x", "y", "z", "phi", "theta", "psi", "vx", "vy", "vz", "p", "q", "r")
QI = ("f1", "f2", "f3", "f4")
"""A Z-Y-X 6-DOF log with world-frame velocities and rotor thrusts (the trial's)."""


def canon(name: str) -> str:
    return term_name(parse_term(name))


def trig_vars(name: str) -> list[str]:
    return [f.var for f in parse_term(name) if f.kind in ("sin", "cos", "tan", "sec")]


# -- defaults: the same lists, in the same order ----------------------------------------
def test_default_specs_give_the_lists_they_gave_before():
    assert library_from_spec("degree=2", ("a", "b"), ()) == ["1", "a", "b", "a^2", "a b", "b^2"]
    assert library_from_spec("degree=1;angles=phi", ("phi", "y"), ("u1",)) == [
        "1", "y", "u1",
        "sin(phi)", "sin(phi) y", "sin(phi) u1",
        "cos(phi)", "cos(phi) y", "cos(phi) u1",
    ]  # fmt: skip
    assert library_from_spec("degree=0;angles=phi;trig_products=no", ("phi", "y"), ("u1",)) == [
        "1", "sin(phi)", "sin(phi) u1", "cos(phi)", "cos(phi) u1",
    ]  # fmt: skip
    # the planar spec of the docs (written out by the code before these keys)
    assert library_from_spec("degree=1;angles=phi", PS, PI) == [
        "1", "y", "z", "y_dot", "z_dot", "phi_dot", "u1", "u2",
        "sin(phi)", "sin(phi) y", "sin(phi) z", "sin(phi) y_dot", "sin(phi) z_dot",
        "sin(phi) phi_dot", "sin(phi) u1", "sin(phi) u2",
        "cos(phi)", "cos(phi) y", "cos(phi) z", "cos(phi) y_dot", "cos(phi) z_dot",
        "cos(phi) phi_dot", "cos(phi) u1", "cos(phi) u2",
    ]  # fmt: skip
    # several angles and frequencies: the generic library, term for term
    for freq in (1, 2):
        spec = f"degree=2;angles=phi,theta,psi;frequencies={freq}"
        expected = generic_library(Q6S, Q6I, ("phi", "theta", "psi"), 2, freq)
        assert library_from_spec(spec, Q6S, Q6I) == expected
    # the new keys at their defaults change nothing
    written = "trig_degree=1;functions=sin,cos;angle_products=false;multipliers="
    for spec in ("degree=1;angles=phi", "degree=3;angles=phi;frequencies=2;trig_products=no"):
        assert library_from_spec(f"{spec};{written}", PS, PI) == library_from_spec(spec, PS, PI)


# -- trig_degree ------------------------------------------------------------------------
def test_trig_degree_multiplies_trig_factors_by_higher_monomials():
    n_plain = len(PS) + len(PI) - 1  # phi is the angle
    for trig_degree in (0, 1, 2, 3):
        lib = library_from_spec(f"degree=0;angles=phi;trig_degree={trig_degree}", PS, PI)
        assert len(lib) == 1 + 2 * math.comb(n_plain + trig_degree, trig_degree)
    lib = library_from_spec("degree=2;angles=phi;trig_degree=2", PS, ("w1", "w2"))
    for term in ("sin(phi) w1^2", "cos(phi) w2^2", "sin(phi) w1 w2", "cos(phi) y_dot^2"):
        assert canon(term) in lib
    assert canon("sin(phi) w1^2") not in library_from_spec("degree=2;angles=phi", PS, ("w1", "w2"))
    bare = library_from_spec("degree=1;angles=phi;trig_degree=0", PS, PI)
    assert [n for n in bare if trig_vars(n)] == ["sin(phi)", "cos(phi)"]


# -- functions --------------------------------------------------------------------------
def test_functions_choose_tan_and_sec_for_all_angles_or_one():
    lib = library_from_spec(
        "degree=1;angles=phi,theta,psi;functions=sin,cos,tan(theta),sec(theta)", QS, QI
    )
    n_plain = len(QS) + len(QI) - 3
    assert len(lib) == 1 + n_plain + (2 + 4 + 2) * (1 + n_plain)
    for term in ("tan(theta) q", "sec(theta) r", "tan(theta)", "sin(psi) f1"):
        assert canon(term) in lib
    assert not any(f.kind in ("tan", "sec") and f.var != "theta"
                   for n in lib for f in parse_term(n))  # fmt: skip
    # for every angle; tan and sec take k = 1 only
    lib = library_from_spec("degree=0;angles=phi;functions=tan,sec,sin;frequencies=3", PS, PI)
    factors = [n for n in lib if len(parse_term(n)) == 1]
    assert factors == ["tan(phi)", "sec(phi)", "sin(phi)", "sin(2 phi)", "sin(3 phi)"]
    assert len(lib) == 1 + 5 * (1 + len(PS) + len(PI) - 1)


# -- angle_products ---------------------------------------------------------------------
def test_angle_products_make_every_product_of_one_factor_per_angle():
    spec = "degree=1;angles=phi,theta,psi;angle_products=true;multipliers=f1,f2,f3,f4"
    lib = library_from_spec(spec, QS, QI)
    trig = [n for n in lib if trig_vars(n)]
    assert len(trig) == (3**3 - 1) * (1 + 4)
    assert len(lib) == 1 + (len(QS) + len(QI) - 3) + len(trig)
    for term in ("cos(phi) sin(theta) cos(psi) f1", "sin(phi) sin(psi) f4", "cos(theta)"):
        assert canon(term) in lib
    assert all(len(set(trig_vars(n))) == len(trig_vars(n)) for n in lib)  # one per angle
    assert not any(trig_vars(n) and {"x", "vx", "p"} & set(n.split()) for n in lib)
    # frequencies and functions multiply in: (1 + 2 k + tan) per angle
    spec = "degree=0;angles=phi,theta;angle_products=true;frequencies=2;functions=sin,cos,tan"
    lib = library_from_spec(f"{spec};trig_degree=0", QS, QI)
    assert len(lib) == 1 + (1 + 2 * 2 + 1) ** 2 - 1
    assert canon("tan(phi) cos(2 theta)") in lib
    # one angle: the same library either way
    one = "degree=1;angles=phi;frequencies=2"
    assert library_from_spec(f"{one};angle_products=true", PS, PI) == library_from_spec(one, PS, PI)


# -- multipliers ------------------------------------------------------------------------
def test_multipliers_choose_what_the_trig_factors_multiply():
    lib = library_from_spec("degree=1;angles=phi;multipliers=u2,y_dot", PS, PI)
    products = [n for n in lib if trig_vars(n) and len(parse_term(n)) > 1]
    assert sorted(products) == sorted(canon(f"{f}(phi) {m}") for f in ("sin", "cos")
                                      for m in ("u2", "y_dot"))  # fmt: skip
    # they replace the trig_products / input_products rule
    off = library_from_spec("degree=1;angles=phi;trig_products=no;multipliers=y", PS, PI)
    assert canon("sin(phi) y") in off and canon("sin(phi) u1") not in off
    two = library_from_spec("degree=0;angles=phi;multipliers=u1,u2;trig_degree=2", PS, PI)
    assert len(two) == 1 + 2 * math.comb(2 + 2, 2)


# -- the two forms, bad values ----------------------------------------------------------
def test_text_and_toml_forms_of_the_new_keys_give_the_same_list(tmp_path):
    text = (
        "degree=1;angles=phi,theta,psi;trig_degree=2;functions=sin,cos,tan(theta),sec(theta);"
        "angle_products=yes;multipliers=p,q,r,f1"
    )
    path = tmp_path / "lib.toml"
    path.write_text(
        '[library]\ndegree = 1\nangles = ["phi", "theta", "psi"]\ntrig_degree = 2\n'
        'functions = ["sin", "cos", "tan(theta)", "sec(theta)"]\nangle_products = true\n'
        'multipliers = "p,q,r,f1"\n'
    )
    from_text = library_from_spec(text, QS, QI)
    assert library_from_spec(str(path), QS, QI) == from_text
    spec = LibrarySpec(
        degree=1, angles=("phi", "theta", "psi"), trig_degree=2,
        functions=("sin", "cos", "tan(theta)", "sec(theta)"), angle_products=True,
        multipliers=("p", "q", "r", "f1"),
    )  # fmt: skip
    assert spec.build(QS, QI) == from_text
    assert len(from_text) == 1 + 13 + (3 * 5 * 3 - 1) * math.comb(4 + 2, 2)
    assert spec_angles(text) == spec_angles(str(path)) == ("phi", "theta", "psi")


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ("angles=phi;trig_degree=-1", "trig_degree must be >= 0, got -1"),
        ("angles=phi;trig_degree=1.5", "trig_degree must be an integer, got '1.5'"),
        ("angles=phi;angle_products=maybe", "angle_products must be true or false"),
        ("angles=phi;functions=exp", "functions entry 'exp' is not one of sin, cos, tan, sec"),
        ("angles=phi;functions=sin(2 phi)", "functions entry 'sin.2 phi.' is not one of"),
        ("angles=phi;functions=", "functions must name at least one of sin, cos, tan, sec"),
        ("angles=phi;functions=sin,tan(theta)", r"tan\(theta\) is of an angle not declared"),
        ("angles=phi;multipliers=u1,w9", r"multipliers \['w9'\] are not variables"),
        ("angles=phi;multipliers=phi,u1", r"multipliers \['phi'\] are angles"),
    ],
)
def test_bad_values_of_the_new_keys_are_one_line_errors(spec, message):
    with pytest.raises(ValueError, match=message) as caught:
        library_from_spec(spec, PS, PI)
    assert "\n" not in str(caught.value)


def test_bad_toml_values_of_the_new_keys_name_the_file(tmp_path):
    path = tmp_path / "lib.toml"
    path.write_text('[library]\nangles = ["phi"]\nfunctions = ["sin", "log"]\n')
    with pytest.raises(ValueError, match=r"lib.toml: functions entry 'log' is not one of"):
        library_from_spec(str(path), PS, PI)
    path.write_text('[library]\nangles = ["phi"]\nangle_products = "sometimes"\n')
    with pytest.raises(ValueError, match="lib.toml: angle_products must be true or false"):
        library_from_spec(str(path), PS, PI)


def test_a_spec_of_too_many_terms_is_refused_naming_the_count_and_keys():
    spec = "degree=3;angles=phi,theta,psi;functions=sin,cos,tan,sec;angle_products=true"
    n_plain = len(QS) + len(QI) - 3
    expected = math.comb(n_plain + 3, 3) + (5**3 - 1) * math.comb(n_plain + 2, 2)
    assert expected > MAX_TERMS
    with pytest.raises(ValueError, match=f"would build {expected} terms") as caught:
        library_from_spec(f"{spec};trig_degree=2", QS, QI)
    text = str(caught.value)
    assert "\n" not in text
    for key in ("degree=3", "trig_degree=2", "angle_products=true", "functions=sin,cos,tan,sec"):
        assert key in text
    assert len(library_from_spec(f"{spec};multipliers=f1,f2", QS, QI)) < MAX_TERMS


# -- presets ----------------------------------------------------------------------------
def test_the_six_dof_preset_structure_is_a_spec():
    """quad6dof: every f(phi) g(theta) h(psi), f in {1, sin, cos, tan, sec}, g and h in
    {1, sin, cos}, times {1, u, v, w, p, q, r, u1..u4}; the quadratics of u..r; x, y, z."""
    preset = set(quad6dof_library())
    spec = (
        "degree=2;angles=phi,theta,psi;functions=sin,cos,tan(phi),sec(phi);angle_products=true;"
        "multipliers=u,v,w,p,q,r,u1,u2,u3,u4"
    )
    built = library_from_spec(spec, Q6S, Q6I)
    assert len(built) == len(set(built))
    # the only difference: degree 2 also makes the products with x, y, z and the inputs
    moving, others = ("u", "v", "w", "p", "q", "r"), ("x", "y", "z", *Q6I)
    pairs = itertools.combinations_with_replacement((*moving, *others), 2)
    more = {canon(f"{a} {b}") for a, b in pairs if a in others or b in others}
    assert len(more) == math.comb(13 + 1, 2) - math.comb(6 + 1, 2) == 70
    assert preset <= set(built) and set(built) - preset == more
    # exactly the preset: degree 1 and the 21 gyroscopic products as extra
    pairs = itertools.combinations_with_replacement(moving, 2)
    quadratics = ",".join(canon(f"{a} {b}") for a, b in pairs)
    exact = library_from_spec(spec.replace("degree=2", "degree=1") + f";extra={quadratics}",
                              Q6S, Q6I)  # fmt: skip
    assert set(exact) == preset and len(exact) == len(preset) == 519


def test_the_trial_six_dof_truth_lies_in_a_short_spec():
    spec = (
        "degree=2;angles=phi,theta,psi;functions=sin,cos,tan(theta),sec(theta);"
        "angle_products=true;multipliers=p,q,r,f1,f2,f3,f4"
    )
    lib = library_from_spec(spec, QS, QI)
    truth = ["vx", "p", "sin(phi) tan(theta) q", "cos(phi) tan(theta) r", "cos(phi) q",
             "sin(phi) r", "sin(phi) sec(theta) q", "cos(phi) sec(theta) r", "1", "q r",
             "p r", "p q", "f3"]  # fmt: skip
    for f in QI:
        truth += [f"cos(phi) sin(theta) cos(psi) {f}", f"sin(phi) sin(psi) {f}",
                  f"cos(phi) sin(theta) sin(psi) {f}", f"sin(phi) cos(psi) {f}",
                  f"cos(phi) cos(theta) {f}"]  # fmt: skip
    assert {canon(t) for t in truth} <= set(lib)
    assert len(lib) == math.comb(13 + 2, 2) + (3 * 5 * 3 - 1) * (1 + 7)


def test_a_preset_on_data_with_other_names_says_how_to_go_on():
    with pytest.raises(ValueError) as caught:
        library_from_spec("quad6dof", QS, QI)
    text = str(caught.value)
    assert "\n" not in text
    assert "preset written for the variables x, y, z, phi, theta, psi, u, v, w" in text
    assert "the data lack u, v, w, u1, u2, u3, u4" in text and "vx, vy, vz" in text
    assert "--columns" in text
    # the example is a spec that builds on these data and has the preset's trig structure
    example = text.split('--library "')[1].split('"')[0]
    lib = library_from_spec(example, QS, QI)
    assert canon("tan(phi) sin(theta) cos(psi) f1") in lib
    # the planar preset's example, in the declared angle's name, is the preset renamed
    names = ("y", "z", "roll", "vy", "vz", "roll_rate")
    with pytest.raises(ValueError, match='--library "degree=1;angles=roll"') as caught:
        library_from_spec("planar", names, ("f1", "f2"), ("roll",))
    rename = dict(zip((*PS, *PI), (*names, "f1", "f2"), strict=True))
    renamed = {
        canon(" ".join(rename.get(t, t) if "(" not in t else t.replace("phi", "roll")
                       for t in n.split()))
        for n in library_from_spec("planar", PS, PI)
    }  # fmt: skip
    assert set(library_from_spec("degree=1;angles=roll", names, ("f1", "f2"))) == renamed
    # a registered vehicle is a preset too (it was read as a malformed spec)
    with pytest.raises(ValueError, match="library 'crazyflie_motors' is a preset written for"):
        library_from_spec("crazyflie_motors", QS, QI)
    assert spec_angles("crazyflie_motors") == spec_angles("quad6dof") == ()
    # on the preset's own names it is still the preset
    assert library_from_spec("quad6dof", Q6S, Q6I) == quad6dof_library()


# -- end to end: motor speeds, thrust = k w^2 -------------------------------------------
MASS, IXX, ARM, K_THRUST, G = 1.2, 1.1e-2, 0.25, 3e-6, 9.81


def motor_speed_rhs(state: np.ndarray, speeds: np.ndarray) -> np.ndarray:
    _, _, phi, y_dot, z_dot, phi_dot = state
    f1, f2 = K_THRUST * speeds**2
    return np.array([
        y_dot, z_dot, phi_dot,
        -(f1 + f2) * np.sin(phi) / MASS,
        (f1 + f2) * np.cos(phi) / MASS - G,
        ARM * (f2 - f1) / IXX,
    ])  # fmt: skip


def rk4_substeps(rhs, state: np.ndarray, u: np.ndarray, dt: float, n: int = 10) -> np.ndarray:
    """The test's own integrator: ``n`` classical RK4 substeps over one sample, input held."""
    h = dt / n
    for _ in range(n):
        k1 = rhs(state, u)
        k2 = rhs(state + h / 2 * k1, u)
        k3 = rhs(state + h / 2 * k2, u)
        k4 = rhs(state + h * k3, u)
        state = state + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return state


def motor_speed_flight(seed: int, rows: int = 600, dt: float = 0.01) -> Trajectory:
    """Own simulator: PD position and attitude control, random thrust excitation, speeds
    held over each step, RK4 with 10 substeps."""
    rng = np.random.default_rng(seed)
    state = np.array([rng.uniform(-0.5, 0.5), rng.uniform(-0.3, 0.3), 0, 0, 0, 0])
    hover = MASS * G / 2
    states, inputs = [state], []
    for k in range(rows - 1):
        if k % 150 == 0:
            ref = rng.uniform([-2, -1], [2, 1])
        if k % 7 == 0:
            excitation = rng.normal(0, 0.08 * hover, 2)
        y, z, phi, y_dot, z_dot, phi_dot = state
        a_y = 1.6 * (ref[0] - y) - 1.8 * y_dot
        a_z = 2.0 * (ref[1] - z) - 2.2 * z_dot
        phi_ref = np.clip(-a_y / G, -0.3, 0.3)
        thrust_total = MASS * (G + a_z) / np.cos(phi)
        moment = IXX * (60.0 * (phi_ref - phi) - 14.0 * phi_dot)
        thrusts = thrust_total / 2 + np.array([-1, 1]) * moment / (2 * ARM) + excitation
        speeds = np.sqrt(np.clip(thrusts, 0.05 * hover, None) / K_THRUST)
        state = rk4_substeps(motor_speed_rhs, state, speeds, dt)
        states.append(state)
        inputs.append(speeds)
    inputs.append(inputs[-1])  # the last row's input acts over no step
    return Trajectory(np.arange(rows) * dt, np.array(states), np.array(inputs), PS, ("w1", "w2"))


def test_motor_speed_flights_give_the_exact_model_with_trig_degree_2():
    trajs = [motor_speed_flight(seed) for seed in (11, 12, 13)]
    assert 0.25 < max(np.abs(tr.x[:, 2]).max() for tr in trajs) < 0.6  # tilts ~0.3 rad
    spec = "degree=2;angles=phi;trig_degree=2;multipliers=w1,w2"
    model, _ = select_model(trajs, spec, windows=(1, 4), n_models=0)
    c = K_THRUST / MASS
    truth = {
        ("y", "y_dot"): 1.0, ("z", "z_dot"): 1.0, ("phi", "phi_dot"): 1.0,
        ("y_dot", "sin(phi) w1^2"): -c, ("y_dot", "sin(phi) w2^2"): -c,
        ("z_dot", "1"): -G, ("z_dot", "cos(phi) w1^2"): c, ("z_dot", "cos(phi) w2^2"): c,
        ("phi_dot", "w1^2"): -K_THRUST * ARM / IXX, ("phi_dot", "w2^2"): K_THRUST * ARM / IXX,
    }  # fmt: skip
    truth = {(s, canon(n)): v for (s, n), v in truth.items()}
    found = {(model.state_names[i], canon(model.feature_names[j])): model.coefficients[i, j]
             for i, j in zip(*np.nonzero(model.coefficients), strict=True)}  # fmt: skip
    assert set(found) == set(truth), (set(found) - set(truth), set(truth) - set(found))
    assert all(abs(found[k] / truth[k] - 1) < 1e-4 for k in truth)


def test_a_list_key_given_again_adds_to_its_list_and_a_number_given_again_is_refused():
    """The docs wrote ``extra=a;extra=b`` (four motors' terms), and only the last counted;
    a trial found it refused later. A list key given again now adds to its list."""
    names, inputs = ["z", "vz", "roll", "pitch"], ["m1", "m2"]
    again = library_from_spec("degree=1;extra=m1^2 cos(roll);extra=m2^2 cos(roll);"
                              "exclude=z;exclude=vz", names, inputs)  # fmt: skip
    commas = library_from_spec("degree=1;extra=m1^2 cos(roll),m2^2 cos(roll);exclude=z,vz",
                               names, inputs)  # fmt: skip
    assert again == commas
    assert canon("m1^2 cos(roll)") in again and canon("m2^2 cos(roll)") in again
    assert "z" not in again and "vz" not in again
    with pytest.raises(ValueError, match="gives 'degree' twice.*separated by ','"):
        library_from_spec("degree=1;degree=2", names, inputs)


def test_exclude_drops_every_built_term_holding_a_factor_and_keeps_extra_terms():
    names = library_from_spec("degree=3;exclude=qw^2,px,1;extra=px qw^2", ["px", "qw", "vx"], [])
    full = library_from_spec("degree=3", ["px", "qw", "vx"], [])
    gone = set(full) - set(names)
    held = {n for n in full if n == "1" or "px" in n or "qw^2" in n or "qw^3" in n}
    assert gone == held - {canon("px qw^2")}
    assert "qw vx" in names and "qw" in names  # a lower power is not the factor qw^2
    assert canon("px qw^2") in names  # listed in extra: kept
    trig = library_from_spec("degree=1;angles=phi;exclude=sin(phi)", ["phi", "w"], ["u"])
    assert "cos(phi) w" in trig and not any("sin" in n for n in trig)
    with pytest.raises(ValueError, match="unknown variable"):
        library_from_spec("degree=2;exclude=nope", ["px", "qw"], [])


QM, QJ = 1.3, np.array([0.011, 0.013, 0.021])
QUAT_STATES = ("vx", "vy", "vz", "qw", "qx", "qy", "qz", "wx", "wy", "wz")


def quaternion_rhs(s: np.ndarray, u: np.ndarray) -> np.ndarray:
    """A rigid body with world velocity, unit quaternion (scalar first, body to world) and
    body rates; collective thrust along body z and body moments (not quad-sindy's model)."""
    (qw, qx, qy, qz), w = s[3:7], s[7:]
    thrust_dir = np.array([2 * (qx * qz + qw * qy), 2 * (qy * qz - qw * qx),
                           1 - 2 * (qx * qx + qy * qy)])  # fmt: skip
    dq = 0.5 * np.array([-qx * w[0] - qy * w[1] - qz * w[2],
                         qw * w[0] + qy * w[2] - qz * w[1],
                         qw * w[1] - qx * w[2] + qz * w[0],
                         qw * w[2] + qx * w[1] - qy * w[0]])  # fmt: skip
    acc = u[0] / QM * thrust_dir - np.array([0.0, 0.0, G])
    return np.concatenate([acc, dq, (u[1:] - np.cross(w, QJ * w)) / QJ])


def quaternion_flight(seed: int, rows: int = 600, dt: float = 0.01) -> Trajectory:
    """Attitude PD to random targets plus input noise, 10 RK4 substeps a sample."""
    rng = np.random.default_rng(seed)
    state = np.zeros(10)
    state[3] = 1.0
    states, inputs = [state], []
    for k in range(rows - 1):
        if k % 150 == 0:
            target = rng.uniform(-0.2, 0.2, 3) * [1, 1, 3]
        qw, qx, qy, qz = state[3:7]
        attitude = 2 * np.array([qx, qy, qz]) * np.sign(qw)  # small-angle attitude
        moments = QJ * (36 * (target - attitude) - 10 * state[7:]) + rng.normal(0, 1.5, 3) * QJ
        thrust = QM * (G - 2 * state[2]) * (1 + rng.normal(0, 0.05))
        u = np.concatenate([[thrust], moments])
        state = rk4_substeps(quaternion_rhs, state, u, dt)
        states.append(state)
        inputs.append(u)
    inputs.append(inputs[-1])
    return Trajectory(np.arange(rows) * dt, np.array(states), np.array(inputs), QUAT_STATES,
                      ("T", "Mx", "My", "Mz"))  # fmt: skip


def test_a_unit_quaternion_identity_is_refused_with_the_way_out_and_excluding_it_is_exact():
    trajs = [quaternion_flight(seed) for seed in (21, 22, 23)]
    norms = np.concatenate([np.linalg.norm(tr.x[:, 3:7], axis=1) for tr in trajs])
    assert np.abs(norms - 1).max() < 1e-9  # the identity holds to round-off
    with pytest.raises(ValueError, match=r"unit quaternion.*exclude=q"):
        select_model(trajs, "degree=3", windows=(1,), n_models=0)
    model, _ = select_model(trajs, "degree=3;exclude=qz^2", windows=(1, 4), n_models=0)
    (jx, jy, jz), m = QJ, QM
    truth = {
        ("vx", "T qw qy"): 2 / m, ("vx", "T qx qz"): 2 / m,
        ("vy", "T qw qx"): -2 / m, ("vy", "T qy qz"): 2 / m,
        ("vz", "1"): -G, ("vz", "T"): 1 / m, ("vz", "T qx^2"): -2 / m, ("vz", "T qy^2"): -2 / m,
        ("qw", "qx wx"): -0.5, ("qw", "qy wy"): -0.5, ("qw", "qz wz"): -0.5,
        ("qx", "qw wx"): 0.5, ("qx", "qy wz"): 0.5, ("qx", "qz wy"): -0.5,
        ("qy", "qw wy"): 0.5, ("qy", "qx wz"): -0.5, ("qy", "qz wx"): 0.5,
        ("qz", "qw wz"): 0.5, ("qz", "qx wy"): 0.5, ("qz", "qy wx"): -0.5,
        ("wx", "Mx"): 1 / jx, ("wx", "wy wz"): (jy - jz) / jx,
        ("wy", "My"): 1 / jy, ("wy", "wx wz"): (jz - jx) / jy,
        ("wz", "Mz"): 1 / jz, ("wz", "wx wy"): (jx - jy) / jz,
    }  # fmt: skip
    truth = {(s, canon(n)): v for (s, n), v in truth.items()}
    found = {(model.state_names[i], canon(model.feature_names[j])): model.coefficients[i, j]
             for i, j in zip(*np.nonzero(model.coefficients), strict=True)}  # fmt: skip
    assert set(found) == set(truth), (set(found) - set(truth), set(truth) - set(found))
    assert all(abs(found[k] / truth[k] - 1) < 1e-6 for k in truth)
