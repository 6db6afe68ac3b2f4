"""Vehicle parameters as frozen dataclasses (SI units) and the named presets.

The numbers are those of the paper's vehicle (Manaa et al., section 2 and the authors' code):
a 0.18 kg quadrotor with 0.086 m arms.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class PlanarQuadParams:
    """Planar (y-z plane) quadrotor: two rotors at +-L from the centre of mass.

    Attributes:
        mass: Vehicle mass m [kg].
        Ixx: Moment of inertia about the roll (x) axis [kg m^2].
        arm_length: Distance L from the centre of mass to each rotor [m].
        gravity: Gravitational acceleration g [m/s^2].
        rotor_force_min: Lower limit of each rotor's thrust [N].
        rotor_force_max: Upper limit of each rotor's thrust [N]; the authors' code uses
            max_force / 2 with max_force = 2 m g, i.e. m g per rotor.
    """

    mass: float = 0.18
    Ixx: float = 2.5e-4
    arm_length: float = 0.086
    gravity: float = 9.81
    rotor_force_min: float = 0.0
    rotor_force_max: float = 0.18 * 9.81

    @property
    def hover_thrust(self) -> float:
        """Total thrust that balances gravity, m g [N]."""
        return self.mass * self.gravity

    @property
    def thrust_max(self) -> float:
        """Largest total thrust u1 the rotors can produce [N]."""
        return 2.0 * self.rotor_force_max

    @property
    def moment_max(self) -> float:
        """Largest roll moment |u2| the rotors can produce [N m]."""
        return (self.rotor_force_max - self.rotor_force_min) * self.arm_length

    def replace(self, **changes: float) -> PlanarQuadParams:
        """Returns a copy with some fields changed (domain randomisation)."""
        return dataclasses.replace(self, **changes)


@dataclass(frozen=True)
class Quad6DOFParams:
    """Full 6-DOF quadrotor in the '+' configuration (paper section 2).

    Rotors 1..4 sit on the body axes +x, +y, -x, -y (rotor 1 on -x per the mixer
    u3 = L (T3 - T1)); rotors 1 and 3 spin opposite to 2 and 4.

    Attributes:
        mass: Vehicle mass m [kg].
        Jxx: Moment of inertia about body x [kg m^2].
        Jyy: Moment of inertia about body y [kg m^2].
        Jzz: Moment of inertia about body z [kg m^2].
        arm_length: Distance L from the centre of mass to each rotor [m].
        gravity: Gravitational acceleration g [m/s^2].
        gamma: Ratio k_M / k_F of a rotor's drag moment to its thrust [m]; 0.01 m is a
            typical value for small propellers (the paper leaves it symbolic).
        rotor_force_min: Lower limit of each rotor's thrust [N].
        rotor_force_max: Upper limit of each rotor's thrust [N]; m g / 2 gives the same
            thrust-to-weight ratio of 2 as the planar vehicle.
    """

    mass: float = 0.18
    Jxx: float = 2.5e-4
    Jyy: float = 2.32e-4
    Jzz: float = 3.738e-4
    arm_length: float = 0.086
    gravity: float = 9.81
    gamma: float = 0.01
    rotor_force_min: float = 0.0
    rotor_force_max: float = 0.18 * 9.81 / 2.0

    @property
    def inertia(self) -> np.ndarray:
        """Diagonal of the inertia matrix J [kg m^2]."""
        return np.array([self.Jxx, self.Jyy, self.Jzz])

    @property
    def hover_thrust(self) -> float:
        """Total thrust that balances gravity, m g [N]."""
        return self.mass * self.gravity

    @property
    def thrust_max(self) -> float:
        """Largest total thrust u1 [N]."""
        return 4.0 * self.rotor_force_max

    @property
    def mixer(self) -> np.ndarray:
        """Matrix M with u = M @ T: u = [sum T, L(T2-T4), L(T3-T1), gamma(T1-T2+T3-T4)]."""
        arm, gam = self.arm_length, self.gamma
        return np.array(
            [
                [1.0, 1.0, 1.0, 1.0],
                [0.0, arm, 0.0, -arm],
                [-arm, 0.0, arm, 0.0],
                [gam, -gam, gam, -gam],
            ]
        )

    def replace(self, **changes: float) -> Quad6DOFParams:
        """Returns a copy with some fields changed (domain randomisation)."""
        return dataclasses.replace(self, **changes)


PAPER_PLANAR = PlanarQuadParams()
"""The paper's planar vehicle (authors' `get_quad_params.m`)."""

PAPER_6DOF = Quad6DOFParams()
"""The same vehicle in 6-DOF, with J = diag(2.5e-4, 2.32e-4, 3.738e-4) kg m^2."""
