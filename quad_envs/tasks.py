"""Reward and termination as pure, batched functions shared by every quadrotor env.

Reward (per step, in (0, 1]): ``exp(-cost)`` with

    cost = |e_pos|^2 + 0.1 |e_vel|^2 + 0.1 |tilt|^2 + 0.01 |rates|^2 + 0.1 e_yaw^2

where e_pos, e_vel are the reference minus the vehicle's position [m] and velocity [m/s],
tilt the roll (and pitch) [rad], rates the body angular rates [rad/s] and e_yaw the yaw error
(6-DOF only). The cost is a weighted sum of squared observation entries, so each vehicle
states it as one weight per observation entry. A perfect tracker earns 1 per step; a crash
ends the episode and forfeits all later reward, so staying aloft is always worth more.

Termination: the state leaves a box (the flight volume, the attitude limit, speed limits) or
becomes non-finite.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quad_envs.types import FloatArray

COST_WEIGHTS = {"pos": 1.0, "vel": 0.1, "tilt": 0.1, "rates": 0.01, "yaw": 0.1}
"""Weights of the tracking cost, by kind of observation entry."""


def tracking_reward(obs: FloatArray, weights: FloatArray) -> FloatArray:
    """exp(-sum(weights * obs**2)) over the last axis (batched)."""
    return np.exp(-((obs * obs) @ weights))


def out_of_bounds(states: FloatArray, low: FloatArray, high: FloatArray) -> FloatArray:
    """True where a state leaves [low, high] or is non-finite (NaN fails every comparison)."""
    return ~np.all((states >= low) & (states <= high), axis=-1)


@dataclass(frozen=True)
class FlightVolume:
    """Box the vehicle must stay in, and the attitude and speed limits.

    Attributes:
        lateral: Largest |x| and |y| [m].
        z_min: Ground level [m]; the paper's references live at z >= 0, so the ground sits
            1 m below the origin.
        z_max: Ceiling [m].
        max_tilt: Largest |roll| and |pitch| [rad] (80 degrees).
        max_speed: Largest |velocity| component [m/s].
        max_rate: Largest |angular rate| component [rad/s].
    """

    lateral: float = 5.0
    z_min: float = -1.0
    z_max: float = 6.0
    max_tilt: float = 1.4
    max_speed: float = 20.0
    max_rate: float = 100.0
