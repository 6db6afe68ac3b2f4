"""Matplotlib renderer: the vehicle, its reference and its trail.

The vehicle record says which projections to draw (planar: the y-z plane; 6-DOF: a side
view y-z and a top view x-y) and where its rotors are.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from quad_envs.types import FloatArray
from quad_envs.vehicles import Vehicle


class QuadRenderer:
    """Draws frames into an off-screen (``rgb_array``) or on-screen (``human``) figure.

    Args:
        vehicle: The vehicle (its views, rotor positions and parameters).
        mode: ``rgb_array`` or ``human``.
    """

    def __init__(self, vehicle: Vehicle, mode: str, metadata: dict | None = None) -> None:
        import matplotlib

        if mode == "rgb_array":
            matplotlib.use("Agg", force=False)
        import matplotlib.pyplot as plt

        self.vehicle, self.mode, self._plt = vehicle, mode, plt
        ncols = len(vehicle.views)
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
        veh = self.vehicle
        position = [veh.state_names.index(n) for n in veh.position_names]
        centre = np.asarray(state)[position]
        rotors = centre + 3.0 * (veh.rotor_points(state, veh.params) - centre)  # drawn 3x larger
        path = trail[:, position]
        for ax, view in zip(self.axes, veh.views, strict=True):
            cols = list(view.axes)
            arms = np.concatenate([[rotor, centre[cols]] for rotor in rotors[:, cols]])
            self._draw_view(ax, path[:, cols], refs[:, cols], arms, view.labels)
        self.axes[0].set_title(f"t = {t:.2f} s")
        self.fig.canvas.draw()
        if self.mode == "human":
            self._plt.pause(0.001)
            return None
        return np.asarray(self.fig.canvas.buffer_rgba())[..., :3].copy()

    def close(self) -> None:
        """Closes the figure."""
        self._plt.close(self.fig)
