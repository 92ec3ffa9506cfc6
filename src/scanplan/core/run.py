"""The one place work is mapped over processes or a Dask cluster: independent tasks
(perturbation trials, defect trials, a catalogue's parts) in task order.
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager
from typing import Any

CLUSTER_HINT = "--scheduler needs the cluster extra: pip install 'scanplan[cluster]'"


@contextmanager
def task_runner(scheduler: str | None, tasks: int) -> Iterator[Any]:
    """A map(function, tasks) for independent tasks: on the Dask scheduler at `scheduler`,
    else over worker processes, one per core (one after another if one suffices)."""
    if scheduler is not None:
        try:
            from dask.distributed import Client  # deferred: the optional cluster extra
        except ImportError:
            raise ValueError(CLUSTER_HINT) from None
        try:
            with Client(scheduler) as client:
                yield lambda f, items: client.gather(client.map(f, items, pure=False))
        except (OSError, TimeoutError) as exc:  # no scheduler there, or it went away
            raise ValueError(f"--scheduler {scheduler}: {exc}".splitlines()[0]) from None
        return
    workers = min(os.cpu_count() or 1, tasks)
    if workers == 1:
        yield map
        return
    # Spawned, not forked: the parent already runs Embree's threads.
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(workers, mp_context=context) as pool:
        yield pool.map


def counted(run: Any, progress: Callable[[int, int], None] | None) -> Any:
    """`run` that reports each finished task to `progress` (results stay in task order)."""
    if progress is None:
        return run

    def counting(f: Any, tasks: Any) -> Iterator[Any]:
        for i, result in enumerate(run(f, tasks)):
            progress(i + 1, len(tasks))
            yield result

    return counting
