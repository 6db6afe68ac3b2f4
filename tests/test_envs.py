import pickle
import subprocess
import sys
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import quad_envs
import quad_envs.vehicles
from quad_envs.controllers import PlanarPD, Quad6DOFPD

IDS = quad_envs.ENV_IDS
NORMALIZE_ADVICE = "symmetric and normalized space"


def _check_all_warnings_errors(env, allow=()):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        gym_check_env(env.unwrapped, skip_render_check=False)
    bad = [w for w in caught if not any(a in str(w.message) for a in allow)]
    assert not bad, [str(w.message) for w in bad]


@pytest.mark.parametrize("env_id", IDS)
@pytest.mark.parametrize("kwargs", [
    {"normalize_actions": True},
    {"normalize_actions": True, "trajectory": "random", "init_state_scale": 1.0,
     "obs_noise_std": 0.01, "param_randomization": 0.1},
])  # fmt: skip
def test_gymnasium_check_env_without_warnings(env_id, kwargs):
    _check_all_warnings_errors(gym.make(env_id, render_mode="rgb_array", **kwargs))


@pytest.mark.parametrize("env_id", IDS)
def test_physical_units_default_only_warns_about_normalisation(env_id):
    """Physical thrust bounds exceed [-1, 1] by design: that advice is the only warning."""
    _check_all_warnings_errors(gym.make(env_id), allow=(NORMALIZE_ADVICE,))


@pytest.mark.parametrize("env_id", IDS)
def test_sb3_check_env(env_id):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sb3_check_env(gym.make(env_id, normalize_actions=True), warn=True)
    sb3_check_env(gym.make(env_id), warn=False)


def _rollout(env, seed, n=60):
    obs, _ = env.reset(seed=seed)
    env.action_space.seed(seed)
    out = [obs]
    for _ in range(n):
        obs, rew, term, trunc, _ = env.step(env.action_space.sample())
        out.append(np.append(obs, rew))
        if term or trunc:
            break
    return out


@pytest.mark.parametrize("env_id", IDS)
def test_seeded_determinism(env_id):
    kwargs = dict(
        normalize_actions=True, trajectory="random", init_state_scale=0.5, obs_noise_std=0.01
    )
    a = _rollout(gym.make(env_id, **kwargs), 3)
    b = _rollout(gym.make(env_id, **kwargs), 3)
    c = _rollout(gym.make(env_id, **kwargs), 4)
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    assert not np.array_equal(a[0], c[0])


@pytest.mark.parametrize("env_id", IDS)
def test_pickle_round_trip(env_id):
    env = gym.make(env_id, trajectory="figure8")
    env.reset(seed=0)
    action = np.zeros(env.action_space.shape)
    action[0] = env.unwrapped.params.hover_thrust
    env.step(action)
    clone = pickle.loads(pickle.dumps(env))
    for _ in range(5):
        o1, r1, *_ = env.step(action)
        o2, r2, *_ = clone.step(action)
        np.testing.assert_array_equal(o1, o2)
        assert r1 == r2


@pytest.mark.parametrize("env_id", IDS)
@pytest.mark.parametrize("trajectory", ["diamond", "random"])
def test_vector_env_equals_single_envs(env_id, trajectory):
    n, seed = 4, 11
    kwargs = dict(
        trajectory=trajectory, init_state_scale=0.3, obs_noise_std=0.001, param_randomization=0.05
    )
    venv = gym.make_vec(env_id, num_envs=n, **kwargs)
    assert isinstance(venv.unwrapped, quad_envs.envs.QuadrotorVectorEnv)
    singles = [gym.make(env_id, **kwargs) for _ in range(n)]
    vobs, _ = venv.reset(seed=seed)
    sobs = [env.reset(seed=seed + i)[0] for i, env in enumerate(singles)]
    np.testing.assert_allclose(vobs, np.stack(sobs), rtol=0, atol=1e-12)
    rng = np.random.default_rng(0)
    lo, hi = venv.single_action_space.low, venv.single_action_space.high
    done = np.zeros(n, dtype=bool)
    resets = 0
    for _ in range(80):
        actions = rng.uniform(lo, hi, size=(n, lo.size)) * 0.2 + 0.8 * (lo + hi) / 2
        vobs, vrew, vterm, vtrunc, _ = venv.step(actions)
        for i, env in enumerate(singles):
            if done[i]:  # NEXT_STEP autoreset: the member resets from its own generator
                obs, rew, term, trunc = env.reset()[0], 0.0, False, False
                resets += 1
            else:
                obs, rew, term, trunc, _ = env.step(actions[i])
            np.testing.assert_allclose(vobs[i], obs, rtol=0, atol=1e-9)
            assert vrew[i] == pytest.approx(rew, abs=1e-12)
            assert vterm[i] == term and vtrunc[i] == trunc
        done = vterm | vtrunc
    assert resets > 0  # the aggressive random moments crash some members


def test_vector_env_truncates_and_autoresets_next_step():
    venv = gym.make_vec("PlanarQuad-v0", num_envs=2, max_episode_steps=5)
    venv.reset(seed=0)
    action = np.tile([quad_envs.params.PAPER_PLANAR.hover_thrust, 0.0], (2, 1))
    for _ in range(4):
        _, _, term, trunc, _ = venv.step(action)
        assert not trunc.any() and not term.any()
    _, _, term, trunc, _ = venv.step(action)
    assert trunc.all()
    _, rew, term, trunc, info = venv.step(action)  # the reset step
    assert not trunc.any() and np.all(rew == 0) and np.all(info["time"] == 0)


@pytest.mark.parametrize(
    "env_id,ctrl", [("PlanarQuad-v0", PlanarPD()), ("Quad6DOF-v0", Quad6DOFPD())]
)
def test_pd_flies_the_env_and_time_limit_truncates(env_id, ctrl):
    env = gym.make(env_id, trajectory="diamond")
    obs, info = env.reset(seed=0)
    total, steps = 0.0, 0
    while True:
        obs, rew, term, trunc, info = env.step(ctrl(info["state"], info["reference"]))
        total, steps = total + rew, steps + 1
        if term or trunc:
            break
    assert trunc and not term and steps == quad_envs.MAX_EPISODE_STEPS
    assert total > 0.95 * steps  # tracking reward close to 1 per step
    assert info["time"] == pytest.approx(10.0)


@pytest.mark.parametrize("env_id", IDS)
def test_falling_terminates_with_finite_observation(env_id):
    env = gym.make(env_id)
    env.reset(seed=0)
    zero = env.action_space.low.copy()  # no thrust at all
    zero[1:] = 0
    for step in range(1000):  # noqa: B007 (used after the loop)
        obs, rew, term, trunc, info = env.step(zero)
        if term:
            break
    assert term and not trunc and info["out_of_bounds"]
    assert np.all(np.isfinite(obs)) and obs in env.observation_space and rew == 0
    # free fall from 1 m to the ground at -1 m: sqrt(2 * 2 / g) s
    assert step * 0.01 == pytest.approx(np.sqrt(4 / 9.81), abs=0.02)


@pytest.mark.parametrize("env_id", IDS)
def test_bad_actions_and_options_raise_clear_errors(env_id):
    env = gym.make(env_id)
    env.reset(seed=0)
    m = env.action_space.shape[0]
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(m + 1))
    with pytest.raises(ValueError, match="finite"):
        env.step(np.full(m, np.nan))
    with pytest.raises(ValueError, match="finite"):
        env.step(np.full(m, np.inf))
    with pytest.raises(ValueError, match="valid choices"):
        env.reset(options={"trajectory": "circle"})
    with pytest.raises(ValueError, match="valid options"):
        env.reset(options={"trajectroy": "hover"})
    with pytest.raises(ValueError, match="valid choices"):
        gym.make(env_id, trajectory="loop")
    venv = gym.make_vec(env_id, num_envs=3)
    venv.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        venv.step(np.zeros((2, m)))


def test_reset_options_choose_trajectory_and_state():
    env = gym.make("PlanarQuad-v0")
    obs, info = env.reset(seed=0, options={"trajectory": "C"})
    np.testing.assert_allclose(info["reference"][:2], [0, 1.8])
    x0 = np.array([0.1, 0.5, 0.0, 0, 0, 0])
    obs, info = env.reset(options={"state": x0})
    np.testing.assert_array_equal(obs[:6], x0)
    np.testing.assert_allclose(obs[6:8], info["reference"][:2] - x0[:2])


def test_domain_randomisation_changes_the_vehicle():
    env = gym.make("PlanarQuad-v0", param_randomization=0.2)
    env.reset(seed=0)
    action = np.array([quad_envs.params.PAPER_PLANAR.hover_thrust, 0.0])
    *_, info = env.step(action)
    # with the nominal mass the hover thrust holds z; a randomised mass drifts
    assert abs(info["state"][4]) > 1e-4


def test_make_without_import_and_render():
    code = (
        "import gymnasium as gym\n"
        "env = gym.make('quad_envs:PlanarQuad-v0', render_mode='rgb_array')\n"
        "env.reset(seed=0)\n"
        "env.step(env.action_space.sample())\n"
        "img = env.render()\n"
        "assert img.ndim == 3 and img.shape[2] == 3 and img.dtype.name == 'uint8'\n"
        "assert img.std() > 0\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, env={"MPLBACKEND": "Agg", "PATH": ""})


@pytest.mark.parametrize("env_id", IDS)
def test_record_video_writes_a_real_time_video(env_id, tmp_path):
    env = gym.make(env_id, render_mode="rgb_array")
    assert env.metadata["render_fps"] == 100  # one frame per 0.01 s control step
    env = gym.wrappers.RecordVideo(env, str(tmp_path), disable_logger=True)
    env.reset(seed=0)
    for _ in range(10):
        env.step(env.action_space.sample())
    env.close()
    videos = list(tmp_path.glob("*.mp4"))
    assert len(videos) == 1 and videos[0].stat().st_size > 0


@pytest.mark.parametrize("name", sorted(quad_envs.vehicles.VEHICLES))
def test_kernel_observation_equals_the_vehicle_observe(name):
    """The kernels' numba observation and the numpy ``vehicle.observe`` agree on random states."""
    vehicle = quad_envs.vehicles.get_vehicle(name)
    rng = np.random.default_rng(0)
    n, n_ref = vehicle.n_states, len(vehicle.ref_names)
    states = rng.normal(size=(50, n)) * 3.0
    refs = rng.normal(size=(50, n_ref)) * 3.0
    expected = vehicle.observe(states, refs)
    out = np.empty(expected.shape[1])
    for x, ref, row in zip(states, refs, expected, strict=True):
        vehicle.point_observe(x, ref, out)
        np.testing.assert_allclose(out, row, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("name", sorted(quad_envs.vehicles.VEHICLES))
def test_kernel_field_equals_the_vehicle_rhs(name):
    """Without effects the point field is the vehicle's numpy rhs (the same equations)."""
    from quad_envs import physics

    vehicle = quad_envs.vehicles.get_vehicle(name)
    rng = np.random.default_rng(1)
    p = physics.pack_params(vehicle.params)
    c = physics.pack_consts(0.01, 1, "collective", False, physics.Effects(), 0.0, vehicle.ndim)
    k = vehicle.n_rotors
    for _ in range(20):
        x, u = rng.normal(size=vehicle.n_states), rng.normal(size=vehicle.n_inputs)
        out = np.empty(vehicle.n_states)
        vehicle.point_field(x, u, np.zeros(k), np.zeros(vehicle.ndim), p, c, out)
        np.testing.assert_allclose(out, vehicle.rhs(x, u), rtol=1e-12, atol=1e-12)


def test_kernels_are_built_from_the_vehicle_record_into_the_cache(tmp_path, monkeypatch):
    """A vehicle record is all the kernel factory needs; the module is readable by others."""
    import dataclasses
    import os
    import stat

    from quad_envs import physics

    monkeypatch.setenv("QUAD_SINDY_CACHE", str(tmp_path / "cache"))
    vehicle = dataclasses.replace(quad_envs.vehicles.PLANAR, name="planar_copy")
    kernels = physics.vehicle_kernels(vehicle)
    path = kernels.module.__file__
    assert os.path.dirname(path) == str(tmp_path / "cache")
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(os.stat(path).st_mode) == 0o666 & ~umask
    text = open(path).read()
    assert "planar_point as _field" in text and "planar_observe_point as _observe" in text


@pytest.mark.parametrize("env_id,field", [("PlanarQuad-v0", "Ixx"), ("Quad6DOF-v0", "Jyy")])
def test_a_vehicle_that_cannot_exist_is_refused_by_name(env_id, field):
    """Zero or negative masses and inertias, NaN, and rotor limits out of order raise a
    ValueError naming the field (a negative inertia would fly a roll that runs away)."""
    from quad_envs.params import PAPER_6DOF, PAPER_PLANAR

    base = PAPER_PLANAR if env_id == "PlanarQuad-v0" else PAPER_6DOF
    for bad in ({"mass": 0.0}, {field: -1e-3}, {"arm_length": float("nan")},
                {"rotor_force_max": base.rotor_force_min}):  # fmt: skip
        name = next(iter(bad))
        with pytest.raises(ValueError, match=name):
            gym.make(env_id, params=base.replace(**bad))
    # a batch of vehicles (arrays, as domain randomisation builds them) is checked per member
    ok = base.replace(mass=np.array([0.1, 0.2]))
    assert ok.mass.shape == (2,)
    with pytest.raises(ValueError, match="mass"):
        base.replace(mass=np.array([0.1, -0.2]))


@pytest.mark.parametrize("env_id", IDS)
def test_vector_reset_info_is_the_single_envs_member_by_member(env_id):
    """A policy reading ``info`` (the PD policies) can act on a vector env's first step."""
    venv = gym.make_vec(env_id, 3)
    _, infos = venv.reset(seed=5)
    for i in range(3):
        _, info = gym.make(env_id).reset(seed=5 + i)
        assert set(info) <= set(infos)
        for key, value in info.items():
            np.testing.assert_allclose(infos[key][i], value, err_msg=key)
    single = gym.make(env_id)
    single.reset(seed=5)
    action = single.action_space.sample()
    *_, info = single.step(action)
    *_, infos = venv.step(np.tile(action, (3, 1)))
    assert set(info) <= set(infos)  # out_of_bounds was missing from the vector env's step
    np.testing.assert_allclose(infos["state"][0], info["state"])


@pytest.mark.parametrize(
    "kwargs,problem",
    [
        ({"normalize_actions": "no"}, "normalize_actions must be True or False, got 'no'"),
        ({"dt": "abc"}, "dt must be a number, got 'abc'"),
        ({"substeps": "2"}, "substeps must be a number"),
        ({"params": [1, 2]}, "params must be a mapping of changes"),
        ({"effects": {"drag": "abc"}}, "effects.drag must be True or False"),
        ({"effects": {"drag": True, "gust_std": "abc"}}, "effects.gust_std must be a number"),
    ],
)
@pytest.mark.parametrize("vector", [False, True])
def test_options_of_the_wrong_type_are_refused_by_name(kwargs, problem, vector):
    """A truthy string switched normalisation on; other types failed deep inside numpy."""
    with pytest.raises(ValueError, match=problem.replace("(", r"\(")):
        if vector:
            gym.make_vec("PlanarQuad-v0", num_envs=2, vectorization_mode="vector_entry_point",
                         **kwargs)  # fmt: skip
        else:
            gym.make("PlanarQuad-v0", **kwargs)


def test_reset_options_and_params_of_another_kind_are_refused_by_name():
    from quad_envs.params import PAPER_6DOF

    with pytest.raises(ValueError, match="reset options must be a dict"):
        gym.make("PlanarQuad-v0").reset(options=5)
    with pytest.raises(ValueError, match="reset options must be a dict"):
        gym.make_vec("PlanarQuad-v0", num_envs=2).reset(options=[("state", 0)])
    with pytest.raises(ValueError, match="PlanarQuadParams, got Quad6DOFParams"):
        gym.make("PlanarQuad-v0", params=PAPER_6DOF)
    env = gym.make("CrazyflieMotors-v0", params={"mass": 0.05})  # changes, as the others take
    assert env.unwrapped.params.mass == 0.05


def test_a_tilt_limit_bounds_the_commanded_tilt_and_is_off_by_default():
    """`max_tilt` scales the position loop's horizontal command (6-DOF) or clips the roll
    command (planar) so that the attitude it asks for stays within the limit; left out, the
    commands are the paper's law, bit for bit."""
    rng = np.random.default_rng(0)
    far = rng.normal(0.0, 3.0, size=(200, 11))  # references metres away: tilts of radians
    state = rng.normal(0.0, 0.1, size=(200, 12))
    pd, limited = Quad6DOFPD(), Quad6DOFPD(max_tilt=0.5)
    np.testing.assert_array_equal(Quad6DOFPD(max_tilt=np.inf)(state, far), pd(state, far))
    # the attitude loop's moment is J Kp (angle_c - angle) + ...: read angle_c back off it
    k = np.asarray(pd.gains.kp_att)[:2]
    rate = np.asarray(pd.gains.kv_att)[:2] * state[:, 9:11]
    angle_c = (limited(state, far)[:, 1:3] / pd.params.inertia[:2] + rate) / k + state[:, 3:5]
    assert np.all(np.hypot(angle_c[:, 0], angle_c[:, 1]) <= 0.5 + 1e-9)
    free = (pd(state, far)[:, 1:3] / pd.params.inertia[:2] + rate) / k + state[:, 3:5]
    assert np.hypot(free[:, 0], free[:, 1]).max() > 2.0  # the limit acted
    planar_state, planar_ref = state[:, :6], far[:, :6]
    np.testing.assert_array_equal(PlanarPD(max_tilt=np.inf)(planar_state, planar_ref),
                                  PlanarPD()(planar_state, planar_ref))  # fmt: skip
    # planar: where the free roll command passes the limit, the limit is held (its rate 0)
    g, ixx = PlanarPD().gains, PlanarPD().params.Ixx
    y, y_dot, phi, phi_dot = (planar_state[:, j] for j in (0, 3, 2, 5))
    free_phi = -(planar_ref[:, 4] + g.kv_y * (planar_ref[:, 2] - y_dot)
                 + g.kp_y * (planar_ref[:, 0] - y)) / 9.81  # fmt: skip
    over = np.abs(free_phi) > 0.3
    assert over.sum() > 50
    u = PlanarPD(max_tilt=0.3)(planar_state, planar_ref)
    phi_c = (u[:, 1] / ixx + g.kv_phi * phi_dot) / g.kp_phi + phi
    np.testing.assert_allclose(phi_c[over], 0.3 * np.sign(free_phi[over]), atol=1e-9)
