"""Figures: truth-versus-model responses, absolute errors, lambda scans, study curves."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from identification.experiments.evaluate import ClosedLoopComparison


def pyplot() -> Any:
    """matplotlib.pyplot on the off-screen Agg backend (unless a backend was chosen)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig: Any, path: str | Path) -> Path:
    """Saves a figure as PNG atomically (readable by others) and closes it."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    tmp = path.with_name(f".{path.name}.tmp.png")
    fig.savefig(tmp, dpi=110)
    tmp.replace(path)  # atomic
    pyplot().close(fig)
    return path


def state_grid(names: Sequence[str], ncols: int = 3) -> tuple[Any, np.ndarray]:
    """A figure with one panel per state (shared time axis), panels in reading order."""
    plt = pyplot()
    nrows = int(np.ceil(len(names) / ncols))
    fig, axes = plt.subplots(nrows, ncols, figsize=(12, 2.4 * nrows), sharex=True, squeeze=False)
    for ax in axes.ravel()[len(names) :]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel("t [s]")
    return fig, axes.ravel()


def plot_comparison(comp: ClosedLoopComparison, path: str | Path, title: str = "") -> Path:
    """States of truth and model under the same controller (the paper's response figures)."""
    names = comp.truth.vehicle.state_names
    fig, axes = state_grid(names)
    for i, (ax, name) in enumerate(zip(axes, names, strict=False)):
        ax.plot(comp.truth.t, comp.truth.states[:, i], label="ground truth", lw=2)
        ax.plot(comp.model.t, comp.model.states[:, i], "--", label="identified", lw=1.5)
        ax.set_ylabel(name)
    axes[0].legend(fontsize=8)
    fig.suptitle(title)
    return save_figure(fig, path)


def plot_abs_error(
    comps: dict[str, ClosedLoopComparison], path: str | Path, title: str = ""
) -> Path:
    """|model - truth| over time per state, log scale, one line per run."""
    names = next(iter(comps.values())).truth.vehicle.state_names
    fig, axes = state_grid(names)
    for label, comp in comps.items():
        err = comp.abs_error
        for i, (ax, name) in enumerate(zip(axes, names, strict=False)):
            ax.semilogy(comp.truth.t, np.maximum(err[:, i], 1e-18), label=label)
            ax.set_ylabel(f"|error| {name}")
    axes[0].legend(fontsize=8)
    fig.suptitle(title)
    return save_figure(fig, path)


def plot_curves(
    x: Sequence[float],
    curves: dict[str, Sequence[float]],
    path: str | Path,
    xlabel: str,
    ylabel: str,
    title: str = "",
    logx: bool = True,
    logy: bool = True,
    secondary: dict[str, Sequence[float]] | None = None,
    secondary_label: str = "",
) -> Path:
    """Generic study plot: one or more curves, optionally a second y axis."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 4.2))
    for label, ys in curves.items():
        ys_a = np.asarray(ys, dtype=float)
        if logy:
            ys_a = np.where(np.isfinite(ys_a), np.maximum(ys_a, 1e-18), np.nan)
        ax.plot(x, ys_a, "o-", label=label, ms=3)
    if logx:
        ax.set_xscale("symlog", linthresh=min([v for v in x if v > 0], default=1e-6))
    if logy:
        ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)
    if secondary:
        ax2 = ax.twinx()
        for label, ys in secondary.items():
            ax2.plot(x, ys, "s:", color="tab:red", label=label, ms=3)
        ax2.set_ylabel(secondary_label, color="tab:red")
    ax.legend(fontsize=8, loc="best")
    ax.set_title(title)
    return save_figure(fig, path)
