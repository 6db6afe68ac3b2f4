"""The motor-speed Crazyflie env and the model identified from real flights flying it."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import identification  # noqa: F401  (registers CrazyflieSINDy-v0)
import quad_envs  # noqa: F401
from identification.rotorcraft import load_rotorcraft

MODEL = Path(__file__).resolve().parents[1] / "docs" / "nanodrone" / "model.json"
IDS = ("CrazyflieMotors-v0", "CrazyflieSINDy-v0")


def _make(env_id: str, **kwargs):
    if env_id == "CrazyflieSINDy-v0":
        kwargs["model"] = str(MODEL)
    return gym.make(env_id, **kwargs)


@pytest.mark.parametrize("env_id", IDS)
@pytest.mark.parametrize("normalize", [False, True])
def test_gymnasium_and_sb3_checkers_pass(env_id, normalize):
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = _make(env_id, normalize_actions=normalize, trajectory="random")
    check_env(env.unwrapped, skip_render_check=True)
    sb3_check_env(env, warn=False)
    if not normalize:  # the box covers the logged motor speeds, 500-2,600 rad/s
        assert env.action_space.low.max() <= 500.0 and env.action_space.high.min() >= 2600.0
    assert env.observation_space.shape == (23,)


def test_hover_speeds_keep_the_identified_model_aloft():
    model = load_rotorcraft(MODEL)
    hover = model.hover_speeds()
    # The identified thrust balances gravity: the speeds agree with sqrt(g / (4 Kt/m)).
    balance = np.sqrt(-model.coefficients[2, 3] / (4 * model.thrust_coefficient))
    np.testing.assert_allclose(hover, balance, rtol=0.01)
    env = _make("CrazyflieSINDy-v0")
    obs, _ = env.reset(seed=0)
    np.testing.assert_allclose(obs[19:], hover)
    start = env.unwrapped.state.copy()
    for _ in range(100):  # 1 s open loop at the hover command
        obs, _, terminated, _, _ = env.step(hover)
        assert not terminated
    assert np.linalg.norm(env.unwrapped.state[:3] - start[:3]) < 0.1


def test_nominal_vehicle_hovers_exactly():
    env = _make("CrazyflieMotors-v0", normalize_actions=False)
    env.reset(seed=0)
    hover = env.unwrapped.params.motor_speeds_hover
    for _ in range(50):
        env.step(hover)
    np.testing.assert_allclose(env.unwrapped.state[:12], [0, 0, 1] + [0] * 9, atol=1e-9)


@pytest.mark.parametrize("env_id", IDS)
def test_vector_env_equals_single_envs(env_id):
    kwargs = {"model": str(MODEL)} if env_id == "CrazyflieSINDy-v0" else {}
    vec = gym.make_vec(env_id, num_envs=2, vectorization_mode="vector_entry_point",
                       normalize_actions=True, init_state_scale=0.1, **kwargs)  # fmt: skip
    singles = [_make(env_id, normalize_actions=True, init_state_scale=0.1) for _ in range(2)]
    obs, _ = vec.reset(seed=3)
    for i, env in enumerate(singles):
        np.testing.assert_allclose(env.reset(seed=3 + i)[0], obs[i])
    rng = np.random.default_rng(0)
    for _ in range(5):
        actions = rng.uniform(-0.2, 0.2, (2, 4)).astype(np.float32)
        obs, reward, *_ = vec.step(actions)
        for i, env in enumerate(singles):
            o, r, *_ = env.step(actions[i])
            np.testing.assert_allclose(o, obs[i], rtol=1e-10, atol=1e-10)
            assert r == pytest.approx(reward[i])


def test_ppo_learns_a_few_steps_on_the_identified_crazyflie():
    from stable_baselines3 import PPO

    from agents.train import quiet_logger

    env = _make("CrazyflieSINDy-v0", normalize_actions=True)
    agent = PPO("MlpPolicy", env, n_steps=128, batch_size=64, n_epochs=1, seed=0,
                policy_kwargs={"net_arch": [16]}, device="cpu")  # fmt: skip
    quiet_logger(agent).learn(256)
    action, _ = agent.predict(env.reset(seed=0)[0], deterministic=True)
    assert env.action_space.contains(action)
