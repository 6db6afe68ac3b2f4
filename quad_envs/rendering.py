"""Renderer: the vehicle, its reference and its trail, rasterised with numpy.

The vehicle record says which projections to draw (planar: the y-z plane; 6-DOF: a side
view y-z and a top view x-y) and where its rotors are. Frames are drawn straight into a
uint8 image (a few hundred microseconds each), so ``rgb_array`` keeps up with the env's
``render_fps`` (one frame per control step: 100 fps at dt = 0.01 s) and ``RecordVideo``
writes real-time videos. ``human`` mode shows the same frames in a matplotlib window and
waits so that it plays no faster than ``render_fps``; it needs a display (an interactive
matplotlib backend): without one it shows nothing, and ``render()`` returns None in ``human``
mode as Gymnasium's API says. It does not warn: Gymnasium's ``check_env`` renders every
mode, and a warning there fails a checker run under warnings-as-errors on headless machines.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from quad_envs.types import FloatArray
from quad_envs.vehicles import Vehicle

SIZE = 320
"""Pixels per side of one view."""

_BACKGROUND = np.array([255, 255, 255], dtype=np.uint8)
_GRID = np.array([232, 232, 232], dtype=np.uint8)
_REFERENCE = np.array([150, 150, 150], dtype=np.uint8)
_TRAIL = np.array([31, 119, 180], dtype=np.uint8)
_BODY = np.array([0, 0, 0], dtype=np.uint8)
_ROTOR = np.array([214, 39, 40], dtype=np.uint8)


def _polyline_pixels(points: FloatArray, step: float = 0.7) -> FloatArray:
    """Pixel coordinates sampled densely along a polyline (n, 2) -> (k, 2)."""
    if len(points) < 2:
        return points
    seg = np.diff(points, axis=0)
    lengths = np.maximum(np.hypot(seg[:, 0], seg[:, 1]), 1e-9)
    counts = np.minimum(np.ceil(lengths / step).astype(int), 4 * SIZE)
    starts = np.repeat(points[:-1], counts, axis=0)
    deltas = np.repeat(seg / counts[:, None], counts, axis=0)
    offsets = np.concatenate([np.arange(c) for c in counts]) if counts.size else np.zeros(0)
    return np.vstack([starts + deltas * offsets[:, None], points[-1:]])


class QuadRenderer:
    """Draws frames of one vehicle (``rgb_array`` returns them, ``human`` shows them).

    Args:
        vehicle: The vehicle (its views, rotor positions and parameters).
        mode: ``rgb_array`` or ``human``.
        metadata: The env's metadata (``render_fps`` paces ``human`` mode).
    """

    def __init__(self, vehicle: Vehicle, mode: str, metadata: dict | None = None) -> None:
        self.vehicle, self.mode = vehicle, mode
        self.fps = float((metadata or {}).get("render_fps", 50))
        self._window: Any = None
        self._last_show = 0.0

    def _view(
        self, trail: FloatArray, refs: FloatArray, arms: FloatArray, rotors: FloatArray
    ) -> FloatArray:
        """One view: world coordinates centred on the vehicle, 1 m grid lines."""
        img = np.empty((SIZE, SIZE, 3), dtype=np.uint8)
        img[:] = _BACKGROUND
        centre = arms[-1]
        span = max(1.0, float(np.ptp(np.concatenate([trail, refs]), axis=0).max()) * 0.6)
        scale = (SIZE - 1) / (2 * span)

        def to_px(world: FloatArray) -> FloatArray:
            px = (world - centre) * scale + (SIZE - 1) / 2
            return np.column_stack([px[:, 0], (SIZE - 1) - px[:, 1]])  # y axis up

        for k in range(int(np.floor(centre[0] - span)), int(np.ceil(centre[0] + span)) + 1):
            col = int(round(to_px(np.array([[k, centre[1]]]))[0, 0]))
            if 0 <= col < SIZE:
                img[:, col] = _GRID
        for k in range(int(np.floor(centre[1] - span)), int(np.ceil(centre[1] + span)) + 1):
            row = int(round(to_px(np.array([[centre[0], k]]))[0, 1]))
            if 0 <= row < SIZE:
                img[row, :] = _GRID
        self._paint(img, _polyline_pixels(to_px(refs)), _REFERENCE, 0)
        self._paint(img, _polyline_pixels(to_px(trail)), _TRAIL, 1)
        for rotor in arms[:-1]:
            self._paint(img, _polyline_pixels(to_px(np.array([rotor, centre]))), _BODY, 1)
        self._paint(img, to_px(rotors), _ROTOR, 3)
        return img

    @staticmethod
    def _paint(img: FloatArray, px: FloatArray, color: FloatArray, radius: int) -> None:
        if len(px) == 0:
            return
        ij = np.round(px).astype(int)
        for di in range(-radius, radius + 1):
            for dj in range(-radius, radius + 1):
                if di * di + dj * dj > radius * radius + 1:
                    continue
                cols, rows = ij[:, 0] + dj, ij[:, 1] + di
                ok = (cols >= 0) & (cols < SIZE) & (rows >= 0) & (rows < SIZE)
                img[rows[ok], cols[ok]] = color

    def draw(self, state: FloatArray, trail: FloatArray, refs: FloatArray, t: float) -> Any:
        """Draws one frame; returns an (H, W, 3) uint8 image in ``rgb_array`` mode."""
        veh = self.vehicle
        position = [veh.state_names.index(n) for n in veh.position_names]
        centre = np.asarray(state)[position]
        rotors = centre + 3.0 * (veh.rotor_points(state, veh.params) - centre)  # drawn 3x larger
        path = trail[:, position]
        views = []
        for view in veh.views:
            cols = list(view.axes)
            arms = np.vstack([rotors[:, cols], centre[cols]])
            views.append(self._view(path[:, cols], refs[:, cols], arms, rotors[:, cols]))
        frame = np.concatenate(views, axis=1)
        if self.mode == "human":
            self._show(frame, t)
            return None
        return frame

    def _show(self, frame: FloatArray, t: float) -> None:
        import matplotlib.pyplot as plt

        if self._window is None:
            fig, ax = plt.subplots(figsize=(frame.shape[1] / 80, frame.shape[0] / 80), dpi=80)
            ax.set_axis_off()
            self._window = (fig, ax, ax.imshow(frame))
            plt.ion()
            plt.show(block=False)
        fig, ax, image = self._window
        image.set_data(frame)
        ax.set_title(f"t = {t:.2f} s")
        wait = self._last_show + 1.0 / self.fps - time.perf_counter()
        plt.pause(max(wait, 1e-3))
        self._last_show = time.perf_counter()

    def close(self) -> None:
        """Closes the window (human mode)."""
        if self._window is not None:
            import matplotlib.pyplot as plt

            plt.close(self._window[0])
            self._window = None
