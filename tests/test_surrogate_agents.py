import dataclasses
import sys
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import identification
import quad_envs
from agents.policies import (
    OrnsteinUhlenbeckPolicy,
    PDPolicy,
    SB3Policy,
    UniformRandomPolicy,
    make_policy,
)
from agents.train import HOVER_TASK, evaluate, make_algo
from identification.experiments.compare import compare_envs
from identification.experiments.truth import model_from_truth
from identification.model import IdentifiedModel
from identification.surrogate import make_surrogate, register_surrogate


@pytest.mark.parametrize(
    "surrogate_id,system",
    list(zip(identification.SURROGATE_IDS, ["planar", "quad6dof"], strict=True)),
)
def test_surrogate_ids_pass_check_env(tmp_path, surrogate_id, system):
    path = model_from_truth(system).save(tmp_path / "m.json")
    env = gym.make(surrogate_id, model=str(path), normalize_actions=True)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped)
    venv = gym.make_vec(surrogate_id, num_envs=4, model=str(path))
    obs, _ = venv.reset(seed=0)
    assert obs.shape == (4, env.observation_space.shape[0])


def test_exact_surrogate_follows_the_truth_for_1000_steps():
    env = gym.make("PlanarQuad-v0", trajectory="figure8")
    surrogate = register_surrogate(model_from_truth("planar"), "TestExact-v0", "PlanarQuad-v0")
    senv = gym.make(surrogate, trajectory="figure8")
    pd = PDPolicy(env)
    obs, info = env.reset(seed=0)
    senv.reset(seed=0)
    worst = 0.0
    for _ in range(1000):
        action = pd(obs, info)  # actions from the truth, replayed open-loop on the surrogate
        obs, _, term, trunc, info = env.step(action)
        _, _, sterm, strunc, sinfo = senv.step(action)
        worst = max(worst, np.abs(sinfo["state"] - info["state"]).max())
        assert (term, trunc) == (sterm, strunc)
    assert trunc and worst < 1e-6


def test_a_divergent_model_terminates_cleanly():
    model = model_from_truth("planar")
    coef = model.coefficients.copy()
    coef[3, model.feature_names.index("y_dot")] = 500.0  # y_dot' = 500 y_dot + ...: explodes
    bad = IdentifiedModel(model.feature_names, coef, model.state_names, model.input_names, "planar")
    env = gym.wrappers.TimeLimit(make_surrogate(bad, "PlanarQuad-v0", init_state_scale=0.5), 1000)
    env.reset(seed=0)
    hover = np.array([quad_envs.params.PAPER_PLANAR.hover_thrust, 0.0])
    with np.errstate(all="ignore"):
        for _ in range(1000):
            obs, rew, term, trunc, info = env.step(hover)
            assert np.all(np.isfinite(obs))
            if term:
                break
    assert term and info["out_of_bounds"] and rew == 0.0


def test_surrogate_steps_say_how_far_they_leave_the_training_range():
    """info["outside_training"] is the largest excursion past the model's recorded range, in
    widths of it, over the variables its terms read (positions, read by none, are free)."""
    truth = model_from_truth("planar")
    ranges = {
        "y": [0.0, 0.0],
        "z": [0.0, 0.0],
        "phi": [-0.02, 0.02],
        "y_dot": [-1.0, 1.0],
        "z_dot": [-1.0, 1.0],
        "phi_dot": [-0.5, 0.5],
        "u1": [0.0, 10.0],
        "u2": [-1.0, 1.0],
    }
    model = dataclasses.replace(truth, meta={"ranges": ranges})
    env = make_surrogate(model, "PlanarQuad-v0", trajectory="figure8")
    venv = gym.make_vec("PlanarQuadSINDy-v0", num_envs=2, model=model, trajectory="figure8")
    pd = PDPolicy(env)
    obs, info = env.reset(seed=0)
    venv.reset(seed=0)
    widths = np.array([0.04, 2.0, 2.0, 1.0, 10.0, 2.0])  # phi .. u2
    lows = np.array([-0.02, -1.0, -1.0, -0.5, 0.0, -1.0])
    seen = []
    for _ in range(200):
        action = pd(obs, info)
        obs, _, _, _, info = env.step(action)
        _, _, _, _, vinfo = venv.step(np.stack([action, action]))
        for state, u, flag in [
            (info["state"], info["action"], info["outside_training"]),
            *zip(vinfo["state"], vinfo["action"], vinfo["outside_training"], strict=True),
        ]:
            v = np.concatenate([state[2:], u])
            expected = np.max(np.maximum(np.maximum(lows - v, v - lows - widths), 0.0) / widths)
            assert flag == pytest.approx(expected, abs=1e-12)
            seen.append(expected)
    assert min(seen) == 0.0 and max(seen) > 0.5  # the figure eight tilts past 0.02 rad
    truth_env = gym.make("PlanarQuad-v0")
    truth_env.reset(seed=0)
    assert "outside_training" not in truth_env.step(np.array([5.0, 0.0]))[4]
    with pytest.raises(ValueError, match="training range needs 8"):
        env.set_training_range(np.zeros(3), np.ones(3))


def test_surrogate_rejects_mismatched_models():
    with pytest.raises(ValueError, match="do not match"):
        make_surrogate(model_from_truth("planar"), "Quad6DOF-v0")
    truth = model_from_truth("planar")  # the same model with per-rotor input names
    names = [n.replace("u1", "f1").replace("u2", "f2") for n in truth.feature_names]
    rotors = IdentifiedModel(names, truth.coefficients, truth.state_names, ("f1", "f2"))
    with pytest.raises(ValueError, match=r"info\['action'\].*renamed u1, u2 give a wrong"):
        make_surrogate(rotors, "PlanarQuad-v0")
    with pytest.raises(ValueError, match="needs model"):
        gym.make("PlanarQuadSINDy-v0")
    with pytest.raises(ValueError, match="valid choices"):
        make_surrogate(model_from_truth("planar"), "CartPole-v1")


def test_compare_reports_no_divergence_for_the_exact_model():
    for name in ("pd", "random"):  # a stochastic policy must draw the same actions in both

        def factory(name=name):
            return make_policy(name, "PlanarQuad-v0", seed=5)

        comp = compare_envs(model_from_truth("planar"), "PlanarQuad-v0", factory, "A")
        assert comp.divergence_time is None and max(comp.rmse.values()) < 1e-9
    biased = model_from_truth("planar")
    biased.coefficients[5] *= 1.05  # 5 % error in 1/Ixx
    biased._rhs = None

    def pd():
        return make_policy("pd", "PlanarQuad-v0")

    comp = compare_envs(biased, "PlanarQuad-v0", pd, "A", tolerance=1e-4)
    assert comp.divergence_time is not None and comp.divergence_time < 10.0


@pytest.mark.parametrize("policy_cls", [UniformRandomPolicy, OrnsteinUhlenbeckPolicy])
def test_random_policies_stay_in_the_action_space(policy_cls):
    env = gym.make("Quad6DOF-v0", **HOVER_TASK)
    policy = policy_cls(env, seed=0)
    obs, info = env.reset(seed=0)
    actions = np.array([policy(obs, info) for _ in range(200)])
    assert all(a in env.action_space for a in actions)
    step = np.abs(np.diff(actions, axis=0)).mean()
    if policy_cls is OrnsteinUhlenbeckPolicy:  # smooth: sigma sqrt(dt) = 0.06 per step
        assert step < 0.1
    else:  # independent uniform draws in [-1, 1]: mean jump 2/3
        assert step > 0.5


def test_pd_policy_in_normalised_space_hovers():
    mean, _ = evaluate(
        make_policy("pd", "PlanarQuad-v0", **HOVER_TASK), "PlanarQuad-v0", 2, **HOVER_TASK
    )
    assert mean > 900  # 1000 steps of reward <= 1 each


@pytest.mark.parametrize("algo", ["ppo", "sac"])
def test_sb3_smoke_and_determinism(algo):
    def run():
        env = gym.make("PlanarQuad-v0", **HOVER_TASK)
        kw = (
            {"n_steps": 64, "batch_size": 32}
            if algo == "ppo"
            else {"learning_starts": 16, "batch_size": 16}
        )
        model = make_algo(algo, env, seed=3, **kw)
        model.learn(128)
        obs, _ = env.reset(seed=0)
        return SB3Policy(model)(obs, {})

    a, b = run(), run()
    np.testing.assert_array_equal(a, b)
    assert a.shape == (2,)


def test_training_leaves_no_empty_log_folders_in_the_temporary_directory(monkeypatch, tmp_path):
    """stable-baselines3's default logger makes an empty SB3-<date> folder per learn()."""
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    monkeypatch.delenv("SB3_LOGDIR", raising=False)
    env = gym.make("PlanarQuad-v0", **HOVER_TASK)
    make_algo("ppo", env, seed=0, n_steps=32, batch_size=32).learn(32)
    assert tempfile.gettempdir() == str(tmp_path)
    assert list(tmp_path.iterdir()) == []


def test_surrogates_step_the_compiled_model_and_fall_back_with_a_warning(monkeypatch):
    from identification import surrogate
    from identification.compiled import CompiledRhs
    from identification.experiments.truth import model_from_truth
    from quad_envs import physics

    model = model_from_truth("planar")
    env = gym.make("PlanarQuadSINDy-v0", model=model)
    assert isinstance(env.unwrapped._rhs, CompiledRhs)
    env.close()

    def broken(*args, **kwargs):
        raise RuntimeError("no compiler today")

    monkeypatch.setattr(physics, "point_rhs_kernels", broken)
    with pytest.warns(RuntimeWarning, match="numpy rhs"):
        env = surrogate.make_surrogate(model)
    assert not isinstance(env.unwrapped._rhs, CompiledRhs)
    env.reset(seed=0)
    env.step(env.action_space.sample())


def test_a_surrogate_of_another_vehicle_warns_on_the_paper_vehicle_and_flies_on_its_own(
    tmp_path, monkeypatch, capsys
):
    """The surrogate takes its action limits and trim from the env's vehicle. A 0.5 kg model
    in the paper vehicle's env cannot hover (a new user trained an agent on it, exit 0): a
    warning says so; with the model's vehicle (``params``, or ``--param`` on the command
    line) the surrogate and the truth are the same flight."""
    from identification.experiments.synthetic import OTHER_PLANAR, truth_planar
    from identification.experiments.truth import truth_matrix
    from identification.libraries import planar_library
    from quad_sindy import cli

    names = planar_library()
    veh = quad_envs.vehicles.get_vehicle("planar")
    xi = truth_matrix(truth_planar(OTHER_PLANAR), veh.state_names, names)
    model = IdentifiedModel(names, xi, veh.state_names, veh.input_names, "planar", {})
    with pytest.warns(RuntimeWarning, match="does not hover at this env's vehicle"):
        make_surrogate(model, "PlanarQuad-v0", compiled=False)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        make_surrogate(model, "PlanarQuad-v0", compiled=False, params=OTHER_PLANAR)
    # the right mass but another inertia: it hovers, yet its roll responds 1.5 times too much
    forgot = dataclasses.replace(OTHER_PLANAR, Ixx=1.5 * OTHER_PLANAR.Ixx)
    with pytest.warns(RuntimeWarning, match=r"response to u2 at hover differs .* by 50%"):
        make_surrogate(model, "PlanarQuad-v0", compiled=False, params=forgot)
    changes = {"mass": "0.5", "Ixx": "3e-3", "arm_length": "0.15", "rotor_force_max": "4.905"}
    env = gym.make("PlanarQuad-v0", params=changes)
    assert env.unwrapped.params == OTHER_PLANAR
    path = model.save(tmp_path / "m.json")
    param = [a for k, v in changes.items() for a in ("--param", f"{k}={v}")]
    monkeypatch.setattr(sys, "argv", ["quad-sindy", "compare", "--model", str(path), "--out",
                                      str(tmp_path / "cmp"), *param])  # fmt: skip
    with pytest.raises(SystemExit) as code:
        cli.main()
    out, err = capsys.readouterr()
    assert code.value.code == 0 and "parted by > 0.001: never" in out and "warning" not in err
    # --effects reach the ground truth only: this drag-free model parts from a dragged truth
    argv = ["quad-sindy", "compare", "--model", str(path), "--out", str(tmp_path / "drag")]
    monkeypatch.setattr(sys, "argv", [*argv, *param, "--effects", "drag"])
    with pytest.raises(SystemExit) as code:
        cli.main()
    out, _ = capsys.readouterr()
    assert code.value.code == 0 and "parted by > 0.001: at t = " in out, out


def test_the_learning_curve_counts_the_steps_taken():
    """PPO takes whole rollouts (1024 steps for 100 asked): the last row said 100, after rows
    up to 1020, and mbrl's sample-efficiency ratio was 10 times off (a new-user trial)."""
    import tempfile

    from agents.train import train

    with tempfile.TemporaryDirectory() as out:
        result = train("PlanarQuad-v0", "ppo", 100, out, eval_every=512, eval_episodes=1,
                       progress=False)  # fmt: skip
    steps = [row[0] for row in result["curve"]]
    assert steps == sorted(set(steps)) and steps[-1] == 1024


def test_a_model_in_another_variable_order_steps_and_mismatches_say_why():
    from identification.experiments.truth import model_from_truth
    from identification.surrogate import make_surrogate as make

    model = model_from_truth("planar")
    order = [2, 0, 1, 5, 3, 4]
    shuffled = IdentifiedModel(model.feature_names, model.coefficients[order],
                               tuple(model.state_names[i] for i in order),
                               model.input_names[::-1], None, {})  # fmt: skip
    a, b = make(model, compiled=False), make(shuffled, compiled=False)
    a.reset(seed=0), b.reset(seed=0)
    for _ in range(50):
        action = a.action_space.sample()
        oa, *_ = a.step(action)
        ob, *_ = b.step(action)
    np.testing.assert_allclose(oa, ob, rtol=0, atol=1e-12)
    autonomous = IdentifiedModel(model.feature_names[:6], model.coefficients[:, :6],
                                 model.state_names, (), None, {})  # fmt: skip
    with pytest.raises(ValueError, match="the model has no inputs"):
        make(autonomous, compiled=False)
    with pytest.raises(ValueError, match="a model of the planar vehicle; use that vehicle's env"):
        make(model, "Quad6DOF-v0", compiled=False)


def test_training_resumes_from_its_checkpoint_and_never_starts_over(tmp_path):
    """A killed `train` lost everything and a rerun overwrote a finished agent (a trial)."""
    import json

    from agents.train import CHECKPOINT, RUN_RECORD, train

    out = tmp_path / "run"
    options = {"eval_every": 512, "eval_episodes": 1, "progress": False}
    first = train("PlanarQuad-v0", "ppo", 1024, out, **options)
    assert json.loads((out / RUN_RECORD).read_text())["done"] is True
    assert not (out / CHECKPOINT).exists()
    again = train("PlanarQuad-v0", "ppo", 1024, out, **options)  # done: loaded, not retrained
    assert again["curve"] == first["curve"]
    # killed after its first rollout: the checkpoint and an unfinished record are left
    (out / "model.zip").rename(out / CHECKPOINT)
    record = json.loads((out / RUN_RECORD).read_text())
    (out / RUN_RECORD).write_text(json.dumps({**record, "done": False}))
    resumed = train("PlanarQuad-v0", "ppo", 2048, out, **options)
    steps = [row[0] for row in resumed["curve"]]
    assert steps[: len(first["curve"])] == [row[0] for row in first["curve"]]
    assert steps == sorted(set(steps)) and steps[-1] == 2048
    with pytest.raises(ValueError, match=r"another configuration \(seed: 0 there, 1 here\)"):
        train("PlanarQuad-v0", "ppo", 2048, out, seed=1, **options)


def test_a_surrogate_model_of_another_type_is_refused_by_name():
    for env_id, kind in (("PlanarQuadSINDy-v0", "IdentifiedModel"),
                         ("CrazyflieSINDy-v0", "RotorcraftModel")):  # fmt: skip
        with pytest.raises(ValueError, match=f"model= takes an? {kind} or the path"):
            gym.make(env_id, model=5)


# A vehicle that is not the paper's, whose inputs act through a 40 ms lag (``--input-lag``).
LAGGED_VEHICLE = {"mass": 0.7, "Ixx": 5e-3, "arm_length": 0.15, "rotor_force_max": 6.0}


def _lagged_planar_model(lag=0.04):
    """The exact planar model of LAGGED_VEHICLE, identified as acting through ``lag``."""
    from identification.experiments.synthetic import truth_planar
    from identification.experiments.truth import truth_matrix
    from identification.libraries import planar_library
    from quad_envs.params import PlanarQuadParams

    names, veh = planar_library(), quad_envs.vehicles.get_vehicle("planar")
    xi = truth_matrix(truth_planar(PlanarQuadParams(**LAGGED_VEHICLE)), veh.state_names, names)
    meta = {"input_lag": lag} if lag else {}
    return IdentifiedModel(names, xi, veh.state_names, veh.input_names, "planar", meta)


def _random_commands(steps, seed=0):
    """Collective commands around the vehicle's hover, inside its rotor limits (no clipping)."""
    rng = np.random.default_rng(seed)
    hover = LAGGED_VEHICLE["mass"] * quad_envs.params.PAPER_PLANAR.gravity
    return np.column_stack([hover + rng.uniform(-1, 1, steps), rng.uniform(-0.05, 0.05, steps)])


def _fly(env, commands, **reset):
    env.reset(**reset)
    states = [env.unwrapped.state]
    for u in commands:
        *_, info = env.step(u)
        states.append(info["state"])
    return np.array(states), info


def test_a_lagged_model_steps_with_its_actuators_as_its_own_simulate_does():
    """A model identified with ``--input-lag`` flies its commands through the lag: the
    surrogate (rotor dynamics at the model's lag, the model driven by the mixed rotor
    thrusts) and ``model.simulate`` (the lag in closed form at the RK4 stages) are two
    fourth-order integrations of one flow. Over 2 s of 10 ms steps each is ~5e-6 off it
    (RK4's step error; 4.6e-6 and 5.9e-6 measured); with 8 substeps each is within 1.2e-9
    of it, and of each other. The thrust states start at the first command, as simulate's
    actuators do."""
    model = _lagged_planar_model()
    commands = _random_commands(200)
    x0 = np.array([0.0, 1.0, 0.0, 0.0, 0.0, 0.0])
    params = quad_envs.params.PlanarQuadParams(**LAGGED_VEHICLE)
    start = {"seed": 0, "options": {"state": np.concatenate([x0, np.linalg.solve(
        params.mixer, commands[0])])}}  # fmt: skip
    env = make_surrogate(model, params=LAGGED_VEHICLE)
    assert env.unwrapped.params.rotor_time_constant == 0.04 and env.unwrapped._rotor_state
    states, info = _fly(env, commands, **start)
    assert not info["out_of_bounds"] and np.ptp(states[:, 2]) > 0.5  # it flew, and tilted
    np.testing.assert_allclose(states, model.simulate(x0, commands, 0.01), rtol=0, atol=2e-5)
    # the flow itself: simulate at 1.25 ms steps (the same held commands), and 8 substeps
    fine = model.simulate(x0, np.repeat(commands, 8, axis=0), 0.01 / 8)[::8]
    sub8, _ = _fly(make_surrogate(model, params=LAGGED_VEHICLE, substeps=8), commands, **start)
    np.testing.assert_allclose(sub8, fine, rtol=0, atol=1e-8)
    # the numpy rhs integrated in Python (the compile's fallback) steps the same flight
    numpy_states, numpy_info = _fly(make_surrogate(model, compiled=False, params=LAGGED_VEHICLE),
                                    commands, **start)  # fmt: skip
    np.testing.assert_allclose(numpy_states, states, rtol=0, atol=1e-12)
    for key in ("action", "rotor_thrusts", "rotor_commands"):
        np.testing.assert_allclose(numpy_info[key], info[key], rtol=0, atol=1e-12)


def test_a_lagged_surrogate_is_the_ground_truth_with_rotor_dynamics_and_not_without_its_lag():
    """The vehicle with rotor dynamics (tau = 40 ms) and the surrogate of its exact model
    identified with that lag are one flight; the same model without its lag parts from it
    by tenths (0.40 measured; the lagged one stays within 9e-16): the lag is what the
    surrogate adds."""
    import dataclasses as dc

    model = _lagged_planar_model()
    commands = _random_commands(200, seed=1)
    options = {"trajectory": "figure8"}
    truth = gym.make("PlanarQuad-v0", effects=["rotor_dynamics"],
                     params={**LAGGED_VEHICLE, "rotor_time_constant": 0.04}, **options)  # fmt: skip
    lagged = gym.make("PlanarQuadSINDy-v0", model=model, params=LAGGED_VEHICLE, **options)
    unlagged = gym.make("PlanarQuadSINDy-v0", model=dc.replace(model, meta={}),
                        params=LAGGED_VEHICLE, **options)  # fmt: skip
    assert lagged.observation_space == truth.observation_space  # the rotor thrusts observed
    flights = [_fly(env, commands, seed=3)[0] for env in (truth, lagged, unlagged)]
    assert np.abs(flights[1] - flights[0]).max() < 1e-6
    assert np.abs(flights[2] - flights[0]).max() > 0.05


def test_the_6dof_surrogate_of_a_lagged_model_steps_as_the_vehicle_with_rotor_dynamics():
    import dataclasses as dc

    from identification.experiments.truth import model_from_truth

    model = model_from_truth("quad6dof")
    model = dc.replace(model, meta={**model.meta, "input_lag": 0.03})
    env = gym.make("Quad6DOFSINDy-v0", model=model)
    truth = gym.make("Quad6DOF-v0", effects={"rotor_dynamics": True},
                     params={"rotor_time_constant": 0.03})  # fmt: skip
    assert env.observation_space.shape == truth.observation_space.shape
    hover = quad_envs.params.PAPER_6DOF.hover_thrust
    commands = np.tile([hover, 0.0, 0.0, 0.0], (50, 1)) * [1.1, 0, 0, 0] + [0, 1e-4, -1e-4, 0]
    (states, info), (expected, truth_info) = (
        _fly(env, commands, seed=0),
        _fly(truth, commands, seed=0),
    )
    np.testing.assert_allclose(states, expected, rtol=0, atol=1e-9)
    np.testing.assert_allclose(info["rotor_thrusts"], truth_info["rotor_thrusts"], atol=1e-9)
    assert states[-1, 2] > states[0, 2]  # it climbed


def test_the_vector_surrogate_of_a_lagged_model_equals_single_ones():
    model = _lagged_planar_model()
    options = {"params": LAGGED_VEHICLE, "init_state_scale": 0.3}
    venv = gym.make_vec("PlanarQuadSINDy-v0", num_envs=3, model=model, **options)
    singles = [make_surrogate(model, **options) for _ in range(3)]
    vobs, _ = venv.reset(seed=5)
    for i, env in enumerate(singles):
        obs, _ = env.reset(seed=5 + i)
        np.testing.assert_array_equal(vobs[i], obs)
    commands = np.stack([_random_commands(30, seed=i) for i in range(3)], axis=1)
    for actions in commands:
        vobs, _, _, _, vinfo = venv.step(actions)
        for i, env in enumerate(singles):
            obs, _, _, _, info = env.step(actions[i])
            np.testing.assert_array_equal(vobs[i], obs)
            np.testing.assert_array_equal(vinfo["rotor_commands"][i], info["rotor_commands"])
    assert vobs.shape == (3, 12)


def test_a_lagged_ensemble_predicts_its_steps_with_the_rotors():
    """Each member predicts the step from the state and the rotor thrusts, as a single
    surrogate of it steps; members with different lags are refused."""
    import dataclasses as dc

    from identification.surrogate import make_ensemble_surrogate

    model = _lagged_planar_model()
    other = dc.replace(model, coefficients=model.coefficients * 1.01)
    env = make_ensemble_surrogate([model, other], mode="sample", params=LAGGED_VEHICLE)
    _, info = env.reset(seed=0)
    start = np.concatenate([info["state"], info["rotor_thrusts"]])
    for u in _random_commands(5, seed=2):
        *_, info = env.step(u)
        steps = []
        for member in (model, other):
            single = make_surrogate(member, compiled=False, params=LAGGED_VEHICLE)
            single.reset(seed=0, options={"state": start})
            steps.append(single.step(u)[4]["state"])
        assert info["disagreement"] == pytest.approx(np.abs(steps[0] - steps[1]).max(), rel=1e-9)
        start = np.concatenate([info["state"], info["rotor_thrusts"]])
    with pytest.raises(ValueError, match=r"different input lags \(0.03, 0.04 s\)"):
        make_ensemble_surrogate([model, _lagged_planar_model(0.03)], params=LAGGED_VEHICLE)


def test_a_lagged_model_refuses_effects_and_params_that_contradict_its_lag():
    model = _lagged_planar_model()
    with pytest.raises(ValueError, match=r"lag of 0.04 s .* asks for rotor_dynamics=False$"):
        make_surrogate(model, params=LAGGED_VEHICLE, effects={"rotor_dynamics": False})
    with pytest.raises(ValueError, match=r"lag of 0.04 s .* rotor_time_constant=0.02$"):
        gym.make("PlanarQuadSINDy-v0", model=model,
                 params={**LAGGED_VEHICLE, "rotor_time_constant": 0.02})  # fmt: skip
    with pytest.raises(ValueError, match="drag and wind are part of the ground-truth"):
        make_surrogate(model, params=LAGGED_VEHICLE, effects=["drag"])
    # the same lag, named: accepted; a sensor effect keeps it
    env = make_surrogate(model, params={**LAGGED_VEHICLE, "rotor_time_constant": "0.04"},
                         effects={"obs_delay_steps": 1})  # fmt: skip
    assert env.unwrapped.effects.rotor_dynamics and env.unwrapped.effects.obs_delay_steps == 1


def test_train_checks_its_seed_first_follows_the_umask_and_names_a_corrupt_curve(tmp_path):
    """``--seed -1`` left an empty folder, model.zip was 0644 under umask 077, and a corrupt
    learning curve gave "could not convert string to float" with no file named."""
    import os

    from agents.train import train

    with pytest.raises(ValueError, match=r"seed must be an integer from 0 to 2\*\*32 - 1"):
        train("PlanarQuad-v0", "ppo", 10, tmp_path / "bad", seed=-1)
    assert not (tmp_path / "bad").exists()
    out = tmp_path / "run"
    options = {"eval_every": 1024, "eval_episodes": 1, "progress": False}
    old = os.umask(0o077)
    try:
        train("PlanarQuad-v0", "ppo", 1024, out, **options)
    finally:
        os.umask(old)
    assert {p.name: p.stat().st_mode & 0o777 for p in out.iterdir()} == {
        "model.zip": 0o600, "run.json": 0o600, "learning_curve.csv": 0o600,
    }  # fmt: skip
    (out / "learning_curve.csv").write_text("steps,return_mean,return_std\n1024,abc,1\n")
    with pytest.raises(ValueError, match=r"run/learning_curve.csv line 2 is not a row of numbers"):
        train("PlanarQuad-v0", "ppo", 2048, out, **options)
