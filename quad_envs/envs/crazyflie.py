"""CrazyflieMotors-v0: the Crazyflie commanded in motor speeds, motor lag as hidden states."""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Mapping

from quad_envs.envs.base import EnvConfig, QuadrotorEnv, QuadrotorVectorEnv
from quad_envs.integrators import Rhs
from quad_envs.params import with_changes
from quad_envs.vehicles.crazyflie_motors import (
    CRAZYFLIE_MOTOR_SPEEDS,
    CRAZYFLIE_MOTORS,
    motor_speeds_rest_state,
)


class _MotorSpeedCore:
    """Configuration of the motor-speed vehicle (shared by the single and the vector env)."""

    def _configure(self, config: EnvConfig, rhs: Rhs | None) -> None:
        if config.action_mode == "rotor_thrusts":
            raise ValueError(
                "this vehicle is commanded in motor speeds: action_mode must be "
                "'motor_speeds' (or 'collective', the same)"
            )
        params = config.params
        if params is None or isinstance(params, Mapping):  # changes to the nominal vehicle
            if config.vehicle not in ("paper", "crazyflie"):
                raise ValueError(
                    f"this env flies the Crazyflie only, got vehicle={config.vehicle!r}"
                )
            params = (
                with_changes(CRAZYFLIE_MOTOR_SPEEDS, params) if params else CRAZYFLIE_MOTOR_SPEEDS
            )
        # The vehicle's input is the motor speeds: the env's collective path hands them over.
        config = dataclasses.replace(config, action_mode="collective", params=params)
        super()._configure(config, rhs)  # type: ignore[misc]
        if self._rotor_state:  # type: ignore[attr-defined]
            raise ValueError("the motor speeds are already states: rotor_dynamics does not apply")
        rest = functools.partial(
            motor_speeds_rest_state, hover_speeds=self.params.motor_speeds_hover
        )  # type: ignore[attr-defined]
        self.vehicle = dataclasses.replace(self.vehicle, rest_state=rest)


class CrazyflieMotorsEnv(_MotorSpeedCore, QuadrotorEnv):
    """The Crazyflie 2.1 Brushless commanded in motor speeds, tracking a 3-D reference.

    The four motor speeds follow the commands through a first-order lag (time constant
    ``params.rotor_time_constant``) and are states of the vehicle, starting at the hover
    speeds on reset (:mod:`quad_envs.vehicles.crazyflie_motors`). The identified model of
    the real vehicle steps in this env (``CrazyflieSINDy-v0`` of :mod:`identification`).

    ## Observation space (23,)
    | index  | name          | meaning                                   | unit  |
    |--------|---------------|-------------------------------------------|-------|
    | 0-18   |               | as :class:`quad_envs.envs.quad6dof.Quad6DOFEnv` | |
    | 19-22  | a1..a4        | motor speeds (the actuator states)        | rad/s |

    ## Action space (4,)
    | index | name           | meaning                          | unit  | bounds      |
    |-------|----------------|----------------------------------|-------|-------------|
    | 0-3   | omega1..omega4 | commanded motor speeds (X frame) | rad/s | [400, 3000] |

    ``normalize_actions=True`` maps [-1, 1] onto the box. ``action_mode`` is
    ``"motor_speeds"`` (``"collective"``, the vehicle's own input, means the same here;
    ``env.action_mode`` reads ``"collective"``). ``params=`` takes a
    :class:`quad_envs.vehicles.crazyflie_motors.MotorSpeedParams`. Effects: drag, wind,
    gusts, sensor effects and rotor limits apply; ``rotor_dynamics`` does not (the motors
    are states already). Other arguments: see :class:`quad_envs.envs.base.QuadrotorEnv`.
    """

    vehicle = CRAZYFLIE_MOTORS


class CrazyflieMotorsVectorEnv(_MotorSpeedCore, QuadrotorVectorEnv):
    """Native vector version of :class:`CrazyflieMotorsEnv` (the same kernel, batched)."""

    vehicle = CRAZYFLIE_MOTORS
