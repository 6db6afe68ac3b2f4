"""Named RL tasks: the environment options that define what the agent must do.

A task is reference-and-start options for any quadrotor env id (``PlanarQuad-v0``,
``Quad6DOF-v0``, their surrogates); actions are normalised to [-1, 1] as RL libraries expect.
The reward is the env's tracking reward (:mod:`quad_envs.tasks`), so the same task on the
ground truth and on a surrogate is the same problem.
"""

from __future__ import annotations

from typing import Any

TASKS: dict[str, dict[str, Any]] = {
    "hover": {"trajectory": "hover", "init_state_scale": 1.0},
    "figure8": {"trajectory": "figure8", "init_state_scale": 0.2},
    "random": {"trajectory": "random", "init_state_scale": 0.2},
}
"""hover: hold the hover point from a perturbed start; figure8: track the lemniscate (8 s
period); random: track smooth random waypoints drawn per episode."""


def task_kwargs(task: str, **extra: Any) -> dict[str, Any]:
    """The env options of a named task (normalised actions), updated with ``extra``."""
    if task not in TASKS:
        raise ValueError(f"unknown task {task!r}; valid choices: {', '.join(TASKS)}")
    return {"normalize_actions": True, **TASKS[task], **extra}


HOVER_TASK = task_kwargs("hover")
"""The hover task's options (the default task of ``train`` and ``evaluate``)."""
