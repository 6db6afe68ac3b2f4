"""Vehicles by name: a new vehicle is one module here plus one line in :data:`VEHICLES`."""

from __future__ import annotations

from collections.abc import Sequence

from quad_envs.vehicles.base import Controller, Vehicle, View
from quad_envs.vehicles.crazyflie_motors import CRAZYFLIE_MOTORS
from quad_envs.vehicles.planar import PLANAR
from quad_envs.vehicles.quad6dof import QUAD6DOF

VEHICLES: dict[str, Vehicle] = {v.name: v for v in (PLANAR, QUAD6DOF, CRAZYFLIE_MOTORS)}
"""Every registered vehicle with its default (the paper's) parameters."""


def get_vehicle(name: str) -> Vehicle:
    """The vehicle registered as ``name`` (``planar``, ``quad6dof``, ...)."""
    try:
        return VEHICLES[name]
    except KeyError:
        raise ValueError(
            f"unknown vehicle {name!r}; valid choices: {', '.join(VEHICLES)}"
        ) from None


def vehicles_with(state_names: Sequence[str], input_names: Sequence[str]) -> list[str]:
    """The registered vehicles whose states and inputs are these, in any order."""
    wanted = (set(state_names), set(input_names))
    return [name for name, v in VEHICLES.items()
            if (set(v.state_names), set(v.input_names)) == wanted]  # fmt: skip


__all__ = [
    "CRAZYFLIE_MOTORS",
    "PLANAR",
    "QUAD6DOF",
    "VEHICLES",
    "Controller",
    "Vehicle",
    "View",
    "get_vehicle",
    "vehicles_with",
]
