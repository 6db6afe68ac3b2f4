"""Data from environments: rollouts of any policy in any registered env, recorded as trajectories.

By default (``record="truth"``) a rollout records the true state (``info["state"]``) and the
input the vehicle *applied* (``info["action"]``, after saturation); what the policy commanded
is kept in ``Trajectory.meta["commanded"]``. That is what a simulator can give and a real
vehicle cannot. ``record="measured"`` records what a flight log holds instead: the state as
the sensors report it (the observation's state entries, with the env's noise, bias and delay;
angles unwrapped) and the commanded input.

With rotor dynamics (``effects=["rotor_dynamics"]``) the collective input changes within
each step as the rotors follow their commands, so no held input describes a step: ``truth``
then records the rotor thrusts as states ``T1..Tk`` after the rigid-body ones and, as the
inputs, the thrusts the rotors were commanded over each step (after their limits)
``Tc1..Tck``, the data of ``--library planar_rotors`` / ``quad6dof_rotors``.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np

import quad_envs  # noqa: F401 (registers the ids)
from identification.data import IdentificationWarning, Trajectory
from identification.libraries import rotor_names
from quad_envs.controllers import LAG_GAINS_6DOF, LAG_GAINS_PLANAR, PlanarPD, Quad6DOFPD
from quad_envs.trajectories import RandomWaypoints

LAG_GAINS = {PlanarPD: LAG_GAINS_PLANAR, Quad6DOFPD: LAG_GAINS_6DOF}
"""The gains :func:`excitation_rollouts` flies a controller with where the env's rotors lag
by more than :data:`LAG_TAU`."""

LAG_TAU = 0.03
"""Rotor time constant [s] up to which the controllers' own gains fly: the paper vehicle's
0.02 s with ``max_tilt=0.6`` kept 11 of 12 flights of 1000 rows over three action modes
(the soft gains lost 2 of 8 planar ones to the flight volume); the Crazyflie's 0.072 s
lost every flight after 62 to 274 rows with them and keeps 14 of 16 with the soft ones."""

Policy = Callable[[np.ndarray, dict[str, Any]], np.ndarray]
"""A policy maps (observation, info) to an action of the env's action space."""

RECORDS = ("truth", "measured")
"""What a rollout records: the true state and applied input, or the sensors' and commands."""


def collect_rollouts(
    env_id: str,
    policy: Policy,
    episodes: int = 1,
    seed: int = 0,
    action_noise: float = 0.0,
    max_steps: int | None = None,
    env_kwargs: dict[str, Any] | None = None,
    reset_options: Callable[[int, np.random.Generator], dict[str, Any]] | None = None,
    record: str = "truth",
    rotor_states: bool | None = None,
) -> list[Trajectory]:
    """Runs a policy in a registered env and records states and inputs.

    Args:
        env_id: Any registered id (``PlanarQuad-v0``, a surrogate, ...).
        policy: (obs, info) -> action.
        episodes: Number of episodes; episode i is reset with seed + i.
        seed: Base seed.
        action_noise: Gaussian noise on the action, as a fraction of the action box half-width.
        max_steps: Cap on steps per episode (the env's time limit otherwise).
        env_kwargs: Passed to ``gym.make``.
        reset_options: (episode, rng) -> options for that episode's ``reset``.
        record: ``truth`` (the true state and the applied input; with rotor dynamics the
            rotor thrusts too, and their commands as the inputs) or ``measured`` (the
            observed state and the commanded input: what a real log holds).
        rotor_states: Record the rotor thrusts ``T1..Tk`` and their commands ``Tc1..Tck``
            (default: where the env has rotor dynamics and ``record`` is ``truth``). False
            records the collective input (with rotor lag: the one applied at the end of
            each step), the variables a surrogate env steps.

    Returns:
        One trajectory per episode (at least 3 samples each).
    """
    if record not in RECORDS:
        raise ValueError(f"record must be one of {RECORDS}, got {record!r}")
    try:
        env = gym.make(env_id, **(env_kwargs or {}))
    except gym.error.Error as exc:
        raise ValueError(f"unknown or unusable env id {env_id!r}: {exc}") from None
    base = env.unwrapped
    vehicle = base.vehicle
    n = len(vehicle.state_names)
    state_names, input_names = vehicle.state_names, vehicle.input_names
    lagging = bool(base.effects.rotor_dynamics) and record == "truth"
    if rotor_states and not lagging:
        raise ValueError(
            "rotor_states=True needs an env with rotor dynamics (effects=['rotor_dynamics']) "
            "and record='truth'"
        )
    rotors = lagging if rotor_states is None else rotor_states
    if rotors:  # the rotors' thrusts are states; their commands, held over a step, the inputs
        thrusts, input_names = rotor_names(int(base.params.mixer.shape[1]))
        state_names = (*state_names, *thrusts)
    angles = [vehicle.state_names.index(a) for a in vehicle.angle_names]
    measured = record == "measured"
    rng = np.random.default_rng(seed)
    space = env.action_space
    half = 0.5 * (space.high - space.low)
    trajs = []
    for ep in range(episodes):
        options = reset_options(ep, rng) if reset_options else None
        obs, info = env.reset(seed=seed + ep, options=options)
        ts, xs, us, commanded, refs = [], [], [], [], []
        steps, terminated = 0, False
        while True:
            action = np.asarray(policy(obs, info), dtype=np.float64)
            if action_noise > 0:
                action = np.clip(action + action_noise * half * rng.standard_normal(half.shape),
                                 space.low, space.high)  # fmt: skip
            ts.append(info["time"])
            if measured:
                xs.append(np.array(obs[:n], dtype=np.float64))
            else:
                xs.append(np.concatenate([info["state"], info["rotor_thrusts"]]) if rotors
                          else info["state"])  # fmt: skip
            refs.append(info["reference"])
            obs, _, terminated, truncated, info = env.step(action.astype(space.dtype))
            applied = info["rotor_commands"] if rotors else info["action"]
            commanded.append(info.get("commanded", info["action"]))
            us.append(commanded[-1] if measured else applied)
            steps += 1
            if terminated or truncated or (max_steps is not None and steps >= max_steps):
                break
        if len(us) >= 3:
            meta = {"env": env_id, "seed": seed + ep, "commanded": np.array(commanded),
                    "record": record, "terminated": bool(terminated)}  # fmt: skip
            x = np.array(xs)
            if measured:  # observations wrap the heading into [-pi, pi)
                x[:, angles] = np.unwrap(x[:, angles], axis=0)
            trajs.append(
                Trajectory(
                    np.array(ts),
                    x,
                    np.array(us),
                    state_names,
                    input_names,
                    refs=np.array(refs),
                    meta=meta,
                )  # fmt: skip
            )
    env.close()
    return trajs


def excitation_rollouts(
    env_id: str = "Quad6DOF-v0",
    episodes: int = 4,
    seed: int = 0,
    steps: int = 1000,
    noise: float = 0.15,
    env_kwargs: dict[str, Any] | None = None,
    record: str = "truth",
    max_tilt: float | None = None,
    rotor_states: bool | None = None,
) -> list[Trajectory]:
    """The vehicle's own controller tracking random waypoints plus exploration noise.

    In 6-DOF the references sweep the yaw (amplitude 1.5 rad) so that every trig factor of
    the library varies; without it cos(psi) f and f are collinear.

    Args:
        env_id: ``PlanarQuad-v0``, ``Quad6DOF-v0`` or a surrogate of them.
        episodes: Number of flights.
        seed: Seed of waypoints, noise and resets.
        steps: Steps per flight.
        noise: Action noise as a fraction of the action box half-width.
        env_kwargs: Passed to ``gym.make`` (``params=`` flies another vehicle; any
            ``action_mode`` and ``normalize_actions``: the controller's collective command
            goes through the env's :meth:`action_from_input`).
        record: ``truth`` or ``measured`` (see :func:`collect_rollouts`).
        max_tilt: Largest tilt the controller commands [rad]; unlimited by default (the
            waypoints can command several radians: a Pelican fell after 90 rows). A flight
            that ends early is named in a warning. Where the env's rotors lag by more than
            :data:`LAG_TAU`, the PD flies :data:`LAG_GAINS`.
        rotor_states: See :func:`collect_rollouts`.

    Returns:
        The recorded trajectories.
    """
    env_kwargs = {"duration": steps * 0.01 + 1.0, **(env_kwargs or {})}
    try:
        probe = gym.make(env_id, **env_kwargs)
    except gym.error.Error as exc:
        raise ValueError(f"unknown or unusable env id {env_id!r}: {exc}") from None
    vehicle = probe.unwrapped.vehicle
    # the controller commands the collective input; the env's action may be rotor thrusts,
    # motor speeds or normalised to [-1, 1] (a trial's flights fell in 8 rows without this).
    # The collective action goes as it is: the noise is added before the box's clipping.
    base = probe.unwrapped
    plain = base.action_mode == "collective" and not base.normalize_actions
    to_action = (lambda u: u) if plain else base.action_from_input
    # softer gains where the rotors lag by more than LAG_TAU (the paper's gains lost the
    # Crazyflie's flights, tau = 0.072 s, after 62 to 274 rows)
    lag = base.effects.rotor_dynamics and base.params.rotor_time_constant > LAG_TAU
    pd = vehicle.default_controller(max_tilt, LAG_GAINS.get(vehicle.controller) if lag else None)
    planar = vehicle.ndim == 2
    ndim = vehicle.ndim

    def options(ep: int, rng: np.random.Generator) -> dict[str, Any]:
        low = (-1.5, 0.5) if planar else (-1.5, -1.5, 0.5)
        high = (1.5, 2.0) if planar else (1.5, 1.5, 2.0)
        ref = RandomWaypoints.sample(
            rng, ndim=ndim, num_waypoints=int(steps * 0.01 / 1.5) + 2, low=low, high=high,
            segment_time=1.5, yaw_amplitude=0.0 if planar else 1.5, yaw_period=4.0 + ep,
        )  # fmt: skip
        return {"trajectory": ref}

    try:
        trajs = collect_rollouts(
            env_id,
            lambda obs, info: to_action(pd(info["state"], info["reference"])),
            episodes=episodes,
            seed=seed,
            action_noise=noise,
            max_steps=steps,
            env_kwargs=env_kwargs,
            reset_options=options,
            record=record,
            rotor_states=rotor_states,
        )
    finally:
        probe.close()
    fell = [f"seed {t.meta['seed']} after {len(t)} rows" for t in trajs if t.meta["terminated"]]
    if fell:  # short flights are data too, but the controller lost the vehicle there
        warnings.warn(
            f"{len(fell)} of {episodes} flight(s) ended early, the vehicle out of the flight "
            f"volume, tilted past 80 degrees or non-finite ({', '.join(fell)}): the vehicle's "
            "controller does not hold it on these references with this excitation (limit "
            "its commanded tilt: max_tilt=0.6, or lower the noise)",
            IdentificationWarning,
            stacklevel=2,
        )
    return trajs
