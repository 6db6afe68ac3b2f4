"""Run independent jobs in process or as Ray tasks, with the same results either way.

Ray is an optional extra (``pip install quad-sindy[ray]``). ``workers=1`` without an
``address`` runs in this process and needs no Ray; ``workers > 1`` starts a local Ray with
that many CPUs on demand; ``address`` joins an existing cluster. Each job must be a pure
function of its arguments (seeded), so where it ran does not change what it returns.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any


def ray_available() -> bool:
    """Whether the optional Ray extra is installed."""
    try:
        import ray  # noqa: F401
    except ImportError:
        return False
    return True


def run_jobs(
    job: Callable[..., Any],
    arguments: Sequence[tuple[Any, ...]],
    workers: int = 1,
    address: str | None = None,
    on_done: Callable[[int, Any], None] | None = None,
) -> list[Any]:
    """Calls ``job(*args)`` for every tuple of ``arguments``; results in the same order.

    Args:
        job: A module-level (picklable) function.
        arguments: One tuple of positional arguments per job.
        workers: Parallel workers (1: in process, sequentially).
        address: A Ray cluster to join (``auto`` or ``ray://host:port``).
        on_done: Called with (index, result) as each job finishes (to save it at once).

    Returns:
        The results.

    Raises:
        ValueError: ``workers < 1``, or Ray was asked for and is not installed.
    """
    if int(workers) != workers or workers < 1:
        raise ValueError(f"workers must be a positive integer, got {workers!r}")
    if workers == 1 and address is None:
        results = []
        for index, args in enumerate(arguments):
            results.append(job(*args))
            if on_done:
                on_done(index, results[-1])
        return results
    if not ray_available():
        raise ValueError("parallel runs need Ray: pip install 'quad-sindy[ray]' (or --workers 1)")
    import ray

    started_here = not ray.is_initialized()
    if started_here:
        if address is not None:
            ray.init(address=address, log_to_driver=False)
        else:
            # A local Ray talks over loopback only.
            ray.init(
                num_cpus=int(workers), include_dashboard=False, log_to_driver=False,
                _node_ip_address="127.0.0.1",
            )  # fmt: skip
    try:
        remote = ray.remote(num_cpus=1)(job)
        pending = {remote.remote(*args): index for index, args in enumerate(arguments)}
        results: list[Any] = [None] * len(pending)
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            index = pending.pop(done[0])
            results[index] = ray.get(done[0])
            if on_done:
                on_done(index, results[index])
        return results
    finally:
        if started_here:
            ray.shutdown()
