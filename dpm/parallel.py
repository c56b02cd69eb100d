"""Fanning independent jobs out over Ray tasks: this machine's cores by default, a cluster by
address.

`fan_out(fn, jobs, address=None, cpus=N)` runs `fn(*job)` for every job as a Ray task and
yields `(job index, result)` as each finishes. Without an address it starts a local Ray
runtime of `cpus` worker processes (no setup) and stops it afterwards; with one
(`ray://HOST:10001` or `HOST:6379`, from `ray start --head`) the cluster's CPUs run the tasks,
each needing `dpm` installed on its node. A task whose worker process dies (killed, out of
memory, a lost node) is run again, up to RETRIES times, so a job is never lost or half done;
an exception raised by `fn` itself is not retried (it would fail again) and is raised here.
Jobs write nothing themselves: they return their results to the caller, which writes them,
so a cluster needs no shared file system.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable, Iterator
from typing import Any

from dpm.errors import InputError

RETRIES = 3  # reruns of a task whose worker died


def fan_out(
    fn: Callable[..., Any],
    jobs: Iterable[tuple],
    address: str | None = None,
    cpus: int = 1,
) -> Iterator[tuple[int, Any]]:
    """(job index, fn(*job)) for every job, in the order they finish, run as Ray tasks of one
    CPU each on a local runtime of `cpus` workers or on the cluster at `address`."""
    try:
        import ray
    except ImportError:
        raise InputError("Ray is not installed (pip install 'ray>=2.40,<3')") from None
    jobs = list(jobs)
    if not jobs:  # nothing to start a runtime for
        return
    started = not ray.is_initialized()
    if started:
        try:
            ray.init(
                address=address or None,
                num_cpus=None if address else cpus,
                include_dashboard=False,
                log_to_driver=False,
                logging_level=logging.WARNING,
            )
        except (ConnectionError, ValueError, RuntimeError) as exc:
            raise InputError(f"cannot start or reach Ray at {address or 'local'}: {exc}") from None
    task = ray.remote(num_cpus=1, max_retries=RETRIES, retry_exceptions=False)(fn)
    pending = {task.remote(*job): i for i, job in enumerate(jobs)}
    try:
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            for ref in done:
                i = pending.pop(ref)
                try:
                    result = ray.get(ref)
                except ray.exceptions.RayTaskError as exc:  # fn raised: raise its own error
                    raise (getattr(exc, "cause", None) or exc) from None
                yield i, result
    finally:
        for ref in pending:
            ray.cancel(ref, force=True)
        if started:
            ray.shutdown()
