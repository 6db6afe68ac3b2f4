"""Response plots in the style of the paper's figures 3-5."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from quad_envs.simulate import ClosedLoopRun


def plot_response(run: ClosedLoopRun, path: str | Path, title: str = "") -> Path:
    """States against the reference, and the inputs, for one closed-loop run (PNG)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    veh = run.vehicle
    names = veh.state_names
    n = len(names) + veh.n_inputs
    ncols = 3 if n <= 9 else 4
    nrows = int(np.ceil(n / ncols))
    fig, axes = plt.subplots(nrows, ncols, figsize=(4 * ncols, 2.6 * nrows), sharex=True)
    axes = axes.ravel()
    ref_of = {name: i for i, name in enumerate(veh.position_names)}
    for i, name in enumerate(names):
        ax = axes[i]
        ax.plot(run.t, run.states[:, i], label=name)
        if name in ref_of:
            ax.plot(run.t, run.refs[:, ref_of[name]], "--", color="tab:gray", label="reference")
            ax.legend(fontsize=7)
        ax.set_ylabel(name)
    for j, name in enumerate(veh.input_names):
        ax = axes[len(names) + j]
        ax.plot(run.t, run.commanded[:, j], color="tab:gray", lw=0.8, label="commanded")
        ax.plot(run.t, run.applied[:, j], color="tab:red", label="applied")
        ax.legend(fontsize=7)
        ax.set_ylabel(name)
    for ax in axes[n:]:
        ax.set_visible(False)
    for ax in axes[-ncols:]:
        ax.set_xlabel("t [s]")
    fig.suptitle(title)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
