"""Independent runs in worker processes, stopped at once by Ctrl-C.

The experiments and the bank run many in-process runs, each a pure function of its task.
``parallel(fn, tasks, jobs)`` yields (task, fn(task)) in task order (or as each finishes,
``ordered=False``) from ``jobs`` worker processes -- in this process when ``jobs`` <= 1,
easier to debug and profile. The workers ignore SIGINT, so Ctrl-C in a terminal reaches
this process alone; it terminates the workers at once (the runs under way are lost, the
finished ones are the caller's) and raises KeyboardInterrupt, rather than wait, as a
process pool does on exit, for its whole queue. SIGTERM (``kill``, a job scheduler's
stop) unwinds the same way while the workers run, so no worker is left to finish its run
and die on a broken pipe. With ``cluster`` (fleet.experiments.cluster) the same calls go
to a Dask cluster instead, under the same signals.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import signal
import threading
from collections.abc import Callable, Iterable, Iterator
from typing import TypeVar

from ...agent.planner import warm_compiled
from .cluster import Cluster

Task = TypeVar("Task")
Result = TypeVar("Result")


def parallel(fn: Callable[[Task], Result], tasks: Iterable[Task], jobs: int, ordered: bool = True,
             cluster: Cluster | None = None) -> Iterator[tuple[Task, Result]]:
    tasks = list(tasks)
    if cluster is not None:
        with _terminate_interrupts():
            yield from cluster.map(fn, tasks, ordered)
        return
    if jobs <= 1:
        for task in tasks:
            yield task, fn(task)
        return
    warm_compiled()  # the planner's compiled loops, made once before the workers fork
    pool = multiprocessing.Pool(jobs, initializer=signal.signal, initargs=(signal.SIGINT, signal.SIG_IGN))
    with _terminate_interrupts():  # after the fork: not the workers'
        try:
            calls = [(fn, index, task) for index, task in enumerate(tasks)]
            for index, result in (pool.imap if ordered else pool.imap_unordered)(_call, calls):
                yield tasks[index], result
            pool.close()
        finally:
            pool.terminate()  # Ctrl-C, an error, or the caller stopped early: no worker outlives us
            pool.join()


@contextlib.contextmanager
def _terminate_interrupts() -> Iterator[None]:
    """SIGTERM raises KeyboardInterrupt (Python's own Ctrl-C handler) in the block, on the
    main thread, where Python runs handlers."""
    on_main = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, signal.default_int_handler) if on_main else None
    try:
        yield
    finally:
        if on_main and previous is not None:  # None: set outside Python, nothing to put back
            signal.signal(signal.SIGTERM, previous)


def _call(call: tuple[Callable, int, object]) -> tuple[int, object]:
    fn, index, task = call
    return index, fn(task)
