"""Matplotlib renderer: the vehicle, its reference and its trail.

Planar: the y-z plane. 6-DOF: a side view (y-z) and a top view (x-y) of the same scene.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from quad_envs.dynamics import rotation_zxy
from quad_envs.types import FloatArray


class QuadRenderer:
    """Draws frames into an off-screen (``rgb_array``) or on-screen (``human``) figure.

    Args:
        vehicle: ``planar`` or ``quad6dof``.
        params: Vehicle parameters (the arm length sets the drawn size).
        mode: ``rgb_array`` or ``human``.
    """

    def __init__(self, vehicle: str, params: Any, mode: str) -> None:
        import matplotlib

        if mode == "rgb_array":
            matplotlib.use("Agg", force=False)
        import matplotlib.pyplot as plt

        self.vehicle, self.params, self.mode, self._plt = vehicle, params, mode, plt
        ncols = 1 if vehicle == "planar" else 2
        self.fig, axes = plt.subplots(1, ncols, figsize=(4.8 * ncols, 4.8), dpi=80)
        self.axes = np.atleast_1d(axes)
        if mode == "human":
            plt.ion()
            plt.show(block=False)

    def _draw_view(
        self, ax: Any, trail: FloatArray, refs: FloatArray, body: FloatArray, labels: tuple
    ) -> None:
        ax.clear()
        ax.plot(refs[:, 0], refs[:, 1], "--", color="tab:gray", lw=1, label="reference")
        ax.plot(trail[:, 0], trail[:, 1], color="tab:blue", lw=1.2, label="flown")
        ax.plot(body[:, 0], body[:, 1], "-o", color="k", lw=2.5, ms=4)
        centre = body.mean(axis=0)
        span = max(1.0, float(np.ptp(np.concatenate([trail, refs]), axis=0).max()) * 0.6)
        ax.set_xlim(centre[0] - span, centre[0] + span)
        ax.set_ylim(centre[1] - span, centre[1] + span)
        ax.set_aspect("equal")
        ax.set_xlabel(labels[0])
        ax.set_ylabel(labels[1])
        ax.grid(alpha=0.3)

    def draw(self, state: FloatArray, trail: FloatArray, refs: FloatArray, t: float) -> Any:
        """Draws one frame; returns an (H, W, 3) uint8 image in ``rgb_array`` mode."""
        arm = self.params.arm_length * 3.0  # drawn 3x larger to be visible
        if self.vehicle == "planar":
            y, z, phi = state[0], state[1], state[2]
            d = arm * np.array([np.cos(phi), np.sin(phi)])
            body = np.array([[y, z] - d, [y, z] + d])
            self._draw_view(self.axes[0], trail[:, :2], refs[:, :2], body, ("y [m]", "z [m]"))
        else:
            rot = rotation_zxy(state[3], state[4], state[5])
            tips = (
                state[0:3] + arm * np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]]) @ rot.T
            )
            side = tips[[2, 3]][:, [1, 2]]
            top = tips[[0, 1]][:, [0, 1]]
            self._draw_view(
                self.axes[0], trail[:, [1, 2]], refs[:, [1, 2]], side, ("y [m]", "z [m]")
            )
            self._draw_view(
                self.axes[1], trail[:, [0, 1]], refs[:, [0, 1]], top, ("x [m]", "y [m]")
            )
        self.axes[0].set_title(f"t = {t:.2f} s")
        self.fig.canvas.draw()
        if self.mode == "human":
            self._plt.pause(0.001)
            return None
        return np.asarray(self.fig.canvas.buffer_rgba())[..., :3].copy()

    def close(self) -> None:
        """Closes the figure."""
        self._plt.close(self.fig)
