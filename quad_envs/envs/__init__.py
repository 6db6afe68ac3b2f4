"""Gymnasium environments: ground truth (and, with ``rhs=``, surrogates)."""

from quad_envs.envs.base import QuadrotorEnv, QuadrotorVectorEnv
from quad_envs.envs.planar import PlanarQuadEnv, PlanarQuadVectorEnv
from quad_envs.envs.quad6dof import Quad6DOFEnv, Quad6DOFVectorEnv

__all__ = [
    "PlanarQuadEnv",
    "PlanarQuadVectorEnv",
    "Quad6DOFEnv",
    "Quad6DOFVectorEnv",
    "QuadrotorEnv",
    "QuadrotorVectorEnv",
]
