"""Effects, presets and action modes against independent references."""

import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import quad_envs
from quad_envs.params import CRAZYFLIE_6DOF, PAPER_6DOF, PAPER_PLANAR, PRESETS
from quad_envs.physics import MODES, Effects

IDS = quad_envs.ENV_IDS
NORMALIZE_ADVICE = "symmetric and normalized space"


def _hover_rotor_thrusts(env):
    u = np.zeros(env.unwrapped._m)
    u[0] = env.unwrapped.params.hover_thrust
    return np.linalg.solve(env.unwrapped.params.mixer, u)


def test_rotor_lag_follows_the_closed_form_step_response():
    """dT/dt = (T_cmd - T)/tau from hover: T(t) = T_cmd + (T0 - T_cmd) exp(-t/tau)."""
    env = gym.make(
        "Quad6DOF-v0", vehicle="crazyflie", action_mode="rotor_thrusts", substeps=5,
        effects={"rotor_dynamics": True},
    )  # fmt: skip
    _, info = env.reset(seed=0)
    t0 = info["rotor_thrusts"]
    np.testing.assert_allclose(t0, _hover_rotor_thrusts(env), rtol=1e-12)
    command = t0 * np.array([1.3, 0.7, 1.1, 0.9])
    tau = CRAZYFLIE_6DOF.rotor_time_constant
    for k in range(1, 31):
        *_, info = env.step(command)
        expected = command + (t0 - command) * np.exp(-k * 0.01 / tau)
        np.testing.assert_allclose(info["rotor_thrusts"], expected, rtol=1e-7)
    # the applied collective input is the mixer times the rotor states
    np.testing.assert_allclose(
        info["action"], CRAZYFLIE_6DOF.mixer @ info["rotor_thrusts"], rtol=1e-12, atol=1e-15
    )
    obs = env.unwrapped.observation_space.shape[0]
    assert obs == 19 + 4  # rotor thrusts observed


def _drag_delta(env_id, state, drag_effects, dt=1e-4, **kwargs):
    """(v_dot with drag - v_dot without) from one tiny RK4 step at ``state``."""
    out = []
    for effects in (None, drag_effects):
        env = gym.make(env_id, dt=dt, effects=effects, **kwargs)
        env.reset(seed=0, options={"state": state})
        hover = np.zeros(env.action_space.shape)
        hover[0] = env.unwrapped.params.hover_thrust
        *_, info = env.step(hover)
        out.append(info["state"])
    return (out[1] - out[0]) / dt


def test_6dof_drag_matches_the_hand_computed_force():
    p = PAPER_6DOF
    x = np.zeros(12)
    x[2], x[6:9] = 1.0, [3.0, -1.0, 0.5]  # level, body velocity (3, -1, 0.5) m/s
    speed = np.sqrt(9 + 1 + 0.25)
    force = np.array(
        [
            -(p.drag_linear_xy + p.drag_quadratic_xy * speed) * 3.0,
            -(p.drag_linear_xy + p.drag_quadratic_xy * speed) * -1.0,
            -(p.drag_linear_z + p.drag_quadratic_z * speed) * 0.5,
        ]
    )
    delta = _drag_delta("Quad6DOF-v0", x, {"drag": True})
    np.testing.assert_allclose(delta[6:9], force / p.mass, rtol=2e-3)
    # wind equal to the inertial velocity cancels the drag
    still = _drag_delta("Quad6DOF-v0", x, {"drag": True, "wind_mean": (3.0, -1.0, 0.5)})
    np.testing.assert_allclose(still[6:9], 0.0, atol=1e-6)


def test_planar_drag_acts_along_the_tilted_body_axes():
    p = PAPER_PLANAR
    phi, v = 0.4, np.array([2.0, -1.0])
    x = np.array([0.0, 1.0, phi, *v, 0.0])
    b_lat, b_up = np.array([np.cos(phi), np.sin(phi)]), np.array([-np.sin(phi), np.cos(phi)])
    speed = np.linalg.norm(v)
    force = (
        -(p.drag_linear_xy + p.drag_quadratic_xy * speed) * (v @ b_lat) * b_lat
        - (p.drag_linear_z + p.drag_quadratic_z * speed) * (v @ b_up) * b_up
    )
    delta = _drag_delta("PlanarQuad-v0", x, {"drag": True})
    np.testing.assert_allclose(delta[3:5], force / p.mass, rtol=2e-3)


@pytest.mark.parametrize("env_id", IDS)
def test_crazyflie_hovers_at_its_weight(env_id):
    """Motor speeds with Kt sum(omega^2) = m g hold the Crazyflie still."""
    p = PRESETS["crazyflie"]["quad6dof"]
    omega_hover = np.sqrt(p.mass * p.gravity / (4 * p.thrust_coefficient))
    assert 500 < omega_hover < 2500  # inside the benchmark's flown speeds
    assert 4 * p.thrust_coefficient * omega_hover**2 == pytest.approx(0.045 * 9.81)
    env = gym.make(env_id, vehicle="crazyflie", action_mode="motor_speeds")
    _, info = env.reset(seed=0)
    x0 = info["state"]
    action = np.full(env.action_space.shape, omega_hover)
    for _ in range(100):
        *_, info = env.step(action)
    np.testing.assert_allclose(info["state"], x0, atol=1e-9)
    assert info["action"][0] == pytest.approx(0.045 * 9.81, rel=1e-12)


def test_per_rotor_limits_clip_each_rotor():
    env = gym.make(
        "Quad6DOF-v0", action_mode="rotor_thrusts", effects={"rotor_max_fraction": (1, 1, 1, 0.5)}
    )
    env.reset(seed=0)
    f_max = PAPER_6DOF.rotor_force_max
    *_, info = env.step(np.full(4, f_max))
    np.testing.assert_allclose(
        info["action"], PAPER_6DOF.mixer @ (f_max * np.array([1, 1, 1, 0.5]))
    )


def test_sensor_bias_is_constant_and_delay_shifts_whole_steps():
    kwargs = dict(trajectory="figure8", init_state_scale=0.5)
    clean = gym.make("PlanarQuad-v0", **kwargs)
    biased = gym.make("PlanarQuad-v0", effects={"obs_bias_std": 0.05}, **kwargs)
    delayed = gym.make("PlanarQuad-v0", effects={"obs_delay_steps": 3}, **kwargs)
    outs = []
    for env in (clean, biased, delayed):
        obs, _ = env.reset(seed=5)
        seq = [obs]
        for _ in range(20):
            seq.append(env.step(np.array([1.9, 0.001]))[0])
        outs.append(np.array(seq))
    clean_obs, biased_obs, delayed_obs = outs
    offsets = biased_obs - clean_obs
    np.testing.assert_allclose(offsets, np.broadcast_to(offsets[0], offsets.shape), atol=1e-12)
    assert np.abs(offsets[0]).max() > 1e-3
    np.testing.assert_array_equal(delayed_obs[3:], clean_obs[:-3])
    np.testing.assert_array_equal(delayed_obs[:3], np.broadcast_to(clean_obs[0], (3, 10)))


def test_kernel_normals_are_standard_normal_including_the_tails():
    import numba
    from scipy import stats

    from quad_envs import physics

    @numba.njit
    def draw(n, seed):
        rng = np.array([seed], dtype=np.uint64)
        out = np.zeros(n)
        physics._add_noise(rng, 0, 1.0, out)
        return out

    z = draw(2_000_000, 2024)
    assert stats.kstest(z, "norm").pvalue > 1e-3
    # Every region of the ziggurat: the boxes, the wedges (chi-square over fine bins) and
    # the tail beyond r = 3.654 (its own rejection sampler).
    edges = np.r_[-np.inf, np.linspace(-4.5, 4.5, 181), np.inf]
    expected = np.diff(stats.norm.cdf(edges)) * z.size
    counts, _ = np.histogram(z, edges)
    chi2 = ((counts - expected) ** 2 / expected).sum()
    assert stats.chi2.sf(chi2, edges.size - 2) > 1e-3
    tail = np.abs(z) > physics._ZIG_R
    assert tail.sum() == pytest.approx(2 * stats.norm.sf(physics._ZIG_R) * z.size, rel=0.2)
    assert (z[tail] > 0).mean() == pytest.approx(0.5, abs=0.1)
    assert np.array_equal(draw(1000, 7), draw(1000, 7))
    assert not np.array_equal(draw(1000, 7), draw(1000, 8))


def test_observation_noise_has_the_requested_standard_deviation():
    kwargs = dict(trajectory="figure8", init_state_scale=0.5)
    clean = gym.make("Quad6DOF-v0", **kwargs)
    noisy = gym.make("Quad6DOF-v0", obs_noise_std=0.01, **kwargs)
    hover = np.array([PAPER_6DOF.hover_thrust, 0, 0, 0])
    diffs = []
    for env in (clean, noisy):
        env.reset(seed=3)
    for _ in range(300):
        diffs.append(noisy.step(hover)[0] - clean.step(hover)[0])
    z = np.array(diffs).ravel() / 0.01
    assert z.std() == pytest.approx(1.0, rel=0.05)
    assert abs(z.mean()) < 0.05


def test_gusts_have_the_stationary_standard_deviation():
    env = gym.make(
        "Quad6DOF-v0", effects={"drag": True, "gust_std": 0.8, "gust_time_constant": 0.05}
    )
    env.reset(seed=1)
    core = env.unwrapped
    hover = np.array([core.params.hover_thrust, 0, 0, 0])
    samples = []
    for _ in range(4000):
        core.step(hover)  # bypass the time limit
        core._X[:] = core._X * 0 + np.r_[np.zeros(2), 1.0, np.zeros(9)]  # stay in the volume
        samples.append(core._gust[0].copy())
    samples = np.array(samples)
    assert samples.std(axis=0) == pytest.approx(np.full(3, 0.8), rel=0.1)
    lag = np.exp(-0.01 / 0.05)
    corr = np.corrcoef(samples[1:, 0], samples[:-1, 0])[0, 1]
    assert corr == pytest.approx(lag, abs=0.03)


def _rollout(env, seed, n=80):
    obs, _ = env.reset(seed=seed)
    env.action_space.seed(seed)
    out = [obs]
    for _ in range(n):
        obs, rew, term, trunc, info = env.step(env.action_space.sample() * 0.3)
        out.append(np.concatenate([obs, [rew], info["state"]]))
        if term or trunc:
            break
    return out


@pytest.mark.parametrize("env_id", IDS)
def test_every_effect_on_is_deterministic_per_seed(env_id):
    kwargs = dict(
        normalize_actions=True, effects="all", obs_noise_std=0.01, param_randomization=0.1,
        vehicle="crazyflie", trajectory="random", init_state_scale=0.3,
    )  # fmt: skip
    a = _rollout(gym.make(env_id, **kwargs), 3)
    b = _rollout(gym.make(env_id, **kwargs), 3)
    c = _rollout(gym.make(env_id, **kwargs), 4)
    assert len(a) == len(b) and all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    assert not np.array_equal(a[1], c[1])


@pytest.mark.parametrize("env_id", IDS)
def test_vector_equals_single_with_every_effect_and_randomisation(env_id):
    n, seed = 3, 7
    kwargs = dict(
        effects="all", obs_noise_std=0.01, param_randomization=0.1, trajectory="random",
        init_state_scale=0.3,
    )  # fmt: skip
    venv = gym.make_vec(env_id, num_envs=n, max_episode_steps=40, **kwargs)
    singles = [gym.make(env_id, max_episode_steps=40, **kwargs) for _ in range(n)]
    vobs, _ = venv.reset(seed=seed)
    sobs = [env.reset(seed=seed + i)[0] for i, env in enumerate(singles)]
    np.testing.assert_array_equal(vobs, np.stack(sobs))
    rng = np.random.default_rng(0)
    lo, hi = venv.single_action_space.low, venv.single_action_space.high
    done = np.zeros(n, dtype=bool)
    resets = 0
    for _ in range(90):
        actions = rng.uniform(lo, hi, size=(n, lo.size)) * 0.3 + 0.7 * (lo + hi) / 2
        vobs, vrew, vterm, vtrunc, vinfo = venv.step(actions)
        for i, env in enumerate(singles):
            if done[i]:
                obs, rew, term, trunc = env.reset()[0], 0.0, False, False
                resets += 1
            else:
                obs, rew, term, trunc, info = env.step(actions[i])
                np.testing.assert_array_equal(vinfo["rotor_thrusts"][i], info["rotor_thrusts"])
            np.testing.assert_array_equal(vobs[i], obs)
            assert vrew[i] == rew and vterm[i] == term and vtrunc[i] == trunc
        done = vterm | vtrunc
    assert resets > 0


def _valid_combinations():
    for env_id in IDS:
        for preset in PRESETS:
            for mode in MODES:
                if mode == "motor_speeds" and preset == "paper":
                    continue  # the paper gives no thrust coefficient
                yield env_id, preset, mode


@pytest.mark.parametrize("env_id,preset,mode", list(_valid_combinations()))
def test_check_env_for_every_preset_and_action_mode(env_id, preset, mode):
    kwargs = dict(vehicle=preset, action_mode=mode, effects=["rotor_dynamics", "drag"])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        gym_check_env(gym.make(env_id, normalize_actions=True, **kwargs).unwrapped)
        gym_check_env(gym.make(env_id, **kwargs).unwrapped)
    bad = [str(w.message) for w in caught if NORMALIZE_ADVICE not in str(w.message)]
    assert not bad, bad
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sb3_check_env(gym.make(env_id, normalize_actions=True, **kwargs), warn=True)


@pytest.mark.parametrize("preset", list(PRESETS))
def test_presets_hover_with_the_default_controller_in_collective_mode(preset):
    env = gym.make("Quad6DOF-v0", vehicle=preset, trajectory="figure8")
    obs, info = env.reset(seed=0)
    ctrl = env.unwrapped.vehicle.default_controller()
    total = 0.0
    for _ in range(300):
        obs, rew, term, trunc, info = env.step(
            env.unwrapped.action_from_input(ctrl(info["state"], info["reference"]))
        )
        total += rew
        assert not term
    assert total > 0.8 * 300


def test_action_from_input_inverts_every_mode():
    u = np.array([0.5, 0.001, -0.002, 0.0001])
    for mode in MODES:
        for normalize in (False, True):
            env = gym.make(
                "Quad6DOF-v0", vehicle="crazyflie", action_mode=mode, normalize_actions=normalize
            )
            env.reset(seed=0)
            *_, info = env.step(env.unwrapped.action_from_input(u))
            tol = 1e-6 if normalize else 1e-12  # float32 actions when normalised
            np.testing.assert_allclose(info["commanded"], u, rtol=tol, atol=tol * 1e-2)


def test_bad_effects_and_modes_raise_one_line_errors():
    with pytest.raises(ValueError, match="unknown effect 'fog'"):
        gym.make("PlanarQuad-v0", effects=["fog"])
    with pytest.raises(ValueError, match="wind acts through drag"):
        gym.make("PlanarQuad-v0", effects={"wind_mean": (1.0, 0.0)})
    with pytest.raises(ValueError, match="needs 3 components"):
        gym.make("Quad6DOF-v0", effects={"drag": True, "wind_mean": (1.0, 0.0)})
    with pytest.raises(ValueError, match="thrust coefficient"):
        gym.make("Quad6DOF-v0", action_mode="motor_speeds")
    with pytest.raises(ValueError, match="valid choices"):
        gym.make("Quad6DOF-v0", vehicle="mavic")
    with pytest.raises(ValueError, match="valid choices"):
        gym.make("Quad6DOF-v0", action_mode="throttle")
    with pytest.raises(ValueError, match="rotor_max_fraction needs 2"):
        gym.make("PlanarQuad-v0", effects={"rotor_max_fraction": (1, 1, 1, 1)})
    with pytest.raises(ValueError, match="one number per axis or rotor"):  # was a TypeError
        gym.make("PlanarQuad-v0", effects={"rotor_max_fraction": 0.9})
    # 0.5 kg on the paper's rotors (3.53 N at most): every episode was a silent fall
    with pytest.raises(ValueError, match=r"cannot hover: its largest thrust 3.532 N .* 4.905 N"):
        gym.make("PlanarQuad-v0", params={"mass": "0.5"})
    with pytest.raises(ValueError, match="rhs="):
        gym.make("PlanarQuad-v0", rhs=lambda x, u: x * 0, effects=["drag"])
    assert Effects.from_spec(None, 2, 2) == Effects()


def test_trajectory_reset_option_applies_to_that_episode_only():
    env = gym.make("PlanarQuad-v0", trajectory="hover")
    _, info = env.reset(seed=0, options={"trajectory": "C"})
    np.testing.assert_allclose(info["reference"][:2], [0, 1.8])
    _, info = env.reset()
    np.testing.assert_allclose(info["reference"][:2], [0, 1])


def test_vector_env_validates_reset_option_shapes():
    venv = gym.make_vec("Quad6DOF-v0", num_envs=3)
    with pytest.raises(ValueError, match="shape"):
        venv.reset(seed=0, options={"state": np.zeros((2, 12))})
    with pytest.raises(ValueError, match="shape"):
        venv.reset(seed=0, options={"state": np.zeros(11)})
    with pytest.raises(ValueError, match="valid options"):
        venv.reset(seed=0, options={"sate": np.zeros(12)})
    states = np.zeros((3, 12))
    states[:, 2] = [0.5, 1.0, 1.5]
    _, _ = venv.reset(seed=0, options={"state": states})
    _, _, _, _, info = venv.step(np.tile([PAPER_6DOF.hover_thrust, 0, 0, 0], (3, 1)))
    np.testing.assert_allclose(info["state"][:, 2], [0.5, 1.0, 1.5], atol=1e-12)


def test_a_reset_state_without_rotor_thrusts_starts_them_at_each_members_hover():
    from quad_envs.physics import P_MASS

    kwargs = dict(effects={"rotor_dynamics": True}, param_randomization=0.2)
    venv = gym.make_vec("Quad6DOF-v0", num_envs=3, **kwargs)
    states = np.zeros((3, 12))
    states[:, 2] = 1.0
    obs, _ = venv.reset(seed=4, options={"state": states})
    mass = venv.unwrapped._P[:, P_MASS]  # each member's randomised mass
    assert np.ptp(mass) > 1e-3
    hover = np.zeros((4, 3))
    hover[0] = mass * PAPER_6DOF.gravity
    expected = np.linalg.solve(PAPER_6DOF.mixer, hover).T
    np.testing.assert_allclose(obs[:, -4:], expected, rtol=1e-12)  # the observed rotor thrusts
    np.testing.assert_array_equal(obs[:, :12], states)
    single = gym.make("Quad6DOF-v0", **kwargs)
    obs_1, _ = single.reset(seed=5, options={"state": states[1]})
    np.testing.assert_array_equal(obs_1, obs[1])


@pytest.mark.parametrize("env_id", IDS)
def test_env_pickles_after_render(env_id):
    env = gym.make(env_id, render_mode="rgb_array", effects="all")
    env.reset(seed=0)
    env.step(env.action_space.sample())
    frame = env.render()
    assert frame.ndim == 3
    clone = pickle.loads(pickle.dumps(env))
    action = env.action_space.sample()
    o1, *_ = env.step(action)
    o2, *_ = clone.step(action)
    np.testing.assert_array_equal(o1, o2)
    assert clone.render().shape == frame.shape


@pytest.mark.parametrize("system", ["planar", "quad6dof"])
def test_compiled_surrogate_point_equals_the_model_rhs(system):
    from identification.compiled import compiled_rhs
    from identification.experiments.truth import model_from_truth

    model = model_from_truth(system)
    rhs = compiled_rhs(model)
    rng = np.random.default_rng(0)
    n, m = len(model.state_names), len(model.input_names)
    for _ in range(5):
        x, u = rng.normal(size=n) * 0.5, rng.normal(size=m)
        out = np.empty(n)
        rhs.point(x, u, out)
        np.testing.assert_allclose(out, model.rhs(x, u), rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(rhs(x, u), model.rhs(x, u))


@pytest.mark.slow
def test_compiled_surrogate_env_follows_the_truth():
    from identification.compiled import compiled_rhs
    from identification.experiments.truth import model_from_truth

    truth = gym.make("PlanarQuad-v0", trajectory="figure8")
    surrogate = gym.make(
        "PlanarQuad-v0", trajectory="figure8", rhs=compiled_rhs(model_from_truth("planar"))
    )
    truth.reset(seed=0)
    surrogate.reset(seed=0)
    for _ in range(300):
        action = np.array([1.8, 0.0005])
        *_, info = truth.step(action)
        *_, sinfo = surrogate.step(action)
    np.testing.assert_allclose(sinfo["state"], info["state"], atol=1e-9)


def test_measured_rollouts_record_what_a_log_holds():
    """``record="measured"``: the sensors' state (bias, delay) and the commanded input; the
    default records the true state and the applied (saturated) input."""
    from identification.rollouts import collect_rollouts

    kw = {"effects": {"obs_bias_std": 0.01, "obs_delay_steps": 1, "rotor_max_fraction": (1, 0.6)}}
    hover = PAPER_PLANAR.hover_thrust

    def policy(obs, info):  # saturates the weaker rotor: applied differs from commanded
        return np.array([1.3 * hover, 0.002])

    truth = collect_rollouts("PlanarQuad-v0", policy, 1, seed=4, max_steps=40, env_kwargs=kw)[0]
    log = collect_rollouts("PlanarQuad-v0", policy, 1, seed=4, max_steps=40, env_kwargs=kw,
                           record="measured")[0]  # fmt: skip
    assert truth.meta["record"] == "truth" and log.meta["record"] == "measured"
    bias = log.x[1] - truth.x[0]  # one step late, offset by the episode's bias
    assert np.abs(bias).max() > 1e-4
    np.testing.assert_allclose(log.x[1:], truth.x[:-1] + bias, atol=1e-12)
    np.testing.assert_allclose(log.u, truth.meta["commanded"])
    assert np.abs(truth.u - truth.meta["commanded"]).max() > 1e-3  # the rotor limit bit
    # the observation wraps the heading; the log unwraps it (a turning vehicle stays smooth)
    start = np.zeros(12)
    start[2], start[5], start[11] = 1.0, 3.1, 2.0  # psi near pi, turning at 2 rad/s
    turn = collect_rollouts(
        "Quad6DOF-v0", lambda o, i: np.array([PAPER_6DOF.hover_thrust, 0, 0, 0]), 1,
        max_steps=20, reset_options=lambda ep, rng: {"state": start}, record="measured",
    )[0]  # fmt: skip
    assert turn.x[-1, 5] > np.pi and np.abs(np.diff(turn.x[:, 5])).max() < 0.1
    with pytest.raises(ValueError, match="record must be one of"):
        collect_rollouts("PlanarQuad-v0", policy, record="sensors")


@pytest.mark.parametrize("mode", ["collective", "rotor_thrusts", "motor_speeds"])
def test_rotor_commands_are_the_targets_the_rotor_states_follow(mode):
    """info['rotor_commands']: with an action held, the rotor states relax toward it as
    T_cmd + (T0 - T_cmd) exp(-dt / tau); the vector env gives the single env's, member by
    member (zeros for a member being reset)."""
    kw = dict(vehicle="crazyflie", action_mode=mode, substeps=5, effects={"rotor_dynamics": True})
    env = gym.make("Quad6DOF-v0", **kw)
    _, info = env.reset(seed=2)
    action = env.action_space.sample()
    *_, info = env.step(action)
    t0, command = info["rotor_thrusts"], info["rotor_commands"]
    lo, hi = CRAZYFLIE_6DOF.rotor_force_min, CRAZYFLIE_6DOF.rotor_force_max
    assert np.all((command >= lo) & (command <= hi)) and np.ptp(command) > 1e-3
    tau = CRAZYFLIE_6DOF.rotor_time_constant
    for k in range(1, 6):
        *_, info = env.step(action)
        np.testing.assert_array_equal(info["rotor_commands"], command)
        expected = command + (t0 - command) * np.exp(-k * 0.01 / tau)
        np.testing.assert_allclose(info["rotor_thrusts"], expected, rtol=1e-7)
    vec = gym.make_vec("Quad6DOF-v0", num_envs=2, vectorization_mode="vector_entry_point", **kw)
    vec.reset(seed=2)
    actions = np.stack([action, vec.single_action_space.sample()])
    *_, vinfo = vec.step(actions)
    single = gym.make("Quad6DOF-v0", **kw)
    for i in range(2):
        single.reset(seed=2)
        *_, sinfo = single.step(actions[i])
        np.testing.assert_allclose(vinfo["rotor_commands"][i], sinfo["rotor_commands"])
    plain = gym.make("Quad6DOF-v0")
    plain.reset(seed=0)
    assert "rotor_commands" not in plain.step(np.array([3.0, 0, 0, 0]))[4]


def test_rollouts_with_rotor_dynamics_record_the_rotors_and_identify_exactly():
    """With rotor lag the collective input changes within each step; the rollouts record the
    rotor thrusts as states and their commands as inputs, and the planar_rotors preset (the
    library identify takes for such data) gives the exact model of a vehicle that is not the
    paper's, lag included."""
    from identification.experiments.synthetic import check_support
    from identification.libraries import library_from_spec
    from identification.rollouts import excitation_rollouts
    from identification.selection import select_model

    params = {"mass": 0.5, "Ixx": 1e-3, "rotor_time_constant": 0.03, "rotor_force_max": 4.0}
    kw = {"params": params, "effects": ["rotor_dynamics"], "action_mode": "rotor_thrusts"}
    trajs = excitation_rollouts("PlanarQuad-v0", episodes=3, seed=1, steps=600, env_kwargs=kw)
    first = trajs[0]
    assert first.state_names[-2:] == ("T1", "T2") and first.input_names == ("Tc1", "Tc2")
    np.testing.assert_allclose(first.u.sum(axis=1)[:5], first.meta["commanded"][:5, 0])
    lib = library_from_spec("planar_rotors", first.state_names, first.input_names)
    model, _ = select_model(trajs, lib, n_models=5, seed=0)
    arm = PAPER_PLANAR.arm_length
    truth = {
        "y": {"y_dot": 1.0},
        "z": {"z_dot": 1.0},
        "phi": {"phi_dot": 1.0},
        "y_dot": {"T1 sin(phi)": -2.0, "T2 sin(phi)": -2.0},
        "z_dot": {"1": -PAPER_PLANAR.gravity, "T1 cos(phi)": 2.0, "T2 cos(phi)": 2.0},
        "phi_dot": {"T1": -arm / 1e-3, "T2": arm / 1e-3},
        "T1": {"T1": -1 / 0.03, "Tc1": 1 / 0.03},
        "T2": {"T2": -1 / 0.03, "Tc2": 1 / 0.03},
    }
    check = check_support(model, truth)
    assert check.exact_support, (check.missed, check.spurious)
    assert check.max_rel_error < 1e-6
    with pytest.raises(ValueError, match="rotor-thrust states .* has no surrogate env"):
        gym.make("PlanarQuadSINDy-v0", model=model)


def test_a_rotor_lag_faster_than_the_step_is_integrated_in_substeps():
    """tau = 2 ms at 10 ms steps: one RK4 step per period diverged (a recheck trial's thrusts
    of -1800 N after 3 steps, below the rotor's minimum); the env raises its substeps to
    dt / tau and follows the exact step response."""
    env = gym.make("PlanarQuad-v0", params={"rotor_time_constant": 0.002}, trajectory="hover",
                   effects=["rotor_dynamics"], action_mode="rotor_thrusts")  # fmt: skip
    assert env.unwrapped.substeps == 5
    _, info = env.reset(seed=0)
    t0 = info["rotor_thrusts"]
    action = 0.9 * env.action_space.high
    for k in range(1, 4):
        *_, info = env.step(action)
        exact = info["rotor_commands"] + (t0 - info["rotor_commands"]) * np.exp(-k * 5.0)
        np.testing.assert_allclose(info["rotor_thrusts"], exact, rtol=1e-2)
    # randomised parameters reach (1 - spread) tau: 20 ms at a 60 % spread needs 2 substeps
    spread = gym.make("PlanarQuad-v0", effects=["rotor_dynamics"], param_randomization=0.6)
    assert spread.unwrapped.substeps == 2


def test_excitation_flights_of_a_lagging_vehicle_fly_softer_gains():
    """The Crazyflie's rotors lag 0.072 s: the paper's PD gains lost every flight after 62 to
    274 rows; excitation_rollouts flies the soft gains there (LAG_GAINS) and keeps them up."""
    from identification.rollouts import LAG_TAU, excitation_rollouts

    assert CRAZYFLIE_6DOF.rotor_time_constant > LAG_TAU
    kw = {"effects": ["rotor_dynamics"], "vehicle": "crazyflie"}
    trajs = excitation_rollouts("PlanarQuad-v0", episodes=4, seed=1, env_kwargs=kw, max_tilt=0.6)
    assert [len(t) for t in trajs] == [1000] * 4
