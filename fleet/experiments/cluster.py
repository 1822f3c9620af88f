"""Independent runs on a Dask cluster: the calls of fleet.experiments.workers, sent to its workers.

``--cluster ADDRESS`` names a Dask scheduler (``tcp://host:8786``) or ``local``: a
LocalCluster of --jobs worker processes on this machine. :class:`Cluster` connects at its
first :meth:`Cluster.map` and yields (task, fn(task)) in task order or as each finishes,
as the local pool does. Every worker must run this code: at the connection each worker
says which trustfg it runs (:class:`Identity`) and one whose Python source differs is
refused, and each call checks it again where it runs (a worker that joins later). A
journal entry names the environment it ran in, so a run on another machine says so.
Leaving early (Ctrl-C, an error) cancels the futures: a local cluster's processes stop
at once; a remote worker finishes the run under way and drops it. Needs Dask's
``distributed`` (``pip install 'trustfg[cluster]'``).
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import logging
import signal
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

from ... import __version__
from ...agent.planner import warm_compiled
from . import run_environment

Task = TypeVar("Task")
Result = TypeVar("Result")

LOCAL = "local"
"""The --cluster address of a LocalCluster on this machine."""
CONNECT_TIMEOUT_S = 30.0
"""How long to try reaching the scheduler, s."""
WORKERS_TIMEOUT_S = 60.0
"""How long to wait for the cluster's first worker, s."""
LAYERS = ("agent", "bridge", "fleet", "mocap_sim", "dashboard")
"""The package's folders whose Python source a worker must share with the client (and its
top-level modules)."""


class ClusterError(RuntimeError):
    """The cluster cannot run these runs: unreachable, no worker, or a worker with other code."""


@dataclass(frozen=True)
class Identity:
    """Which trustfg a process runs, and in which environment."""

    version: str
    """trustfg.__version__."""
    code: str
    """run_environment.code_version(): the commit, or the installed version."""
    source: str
    """:func:`source_digest`: equal digests, the same Python source."""
    env: str
    """run_environment.digest of the process's environment."""

    def __str__(self) -> str:
        return f"trustfg {self.version} ({self.code}, source {self.source})"


def source_digest() -> str:
    """A digest of the package's Python files (:data:`LAYERS` and the top level), the same
    for a checkout and an installed copy of one tree."""
    root = Path(__file__).resolve().parents[2]
    files = sorted(root.glob("*.py")) + sorted(p for layer in LAYERS for p in (root / layer).rglob("*.py"))
    digest = hashlib.sha256()
    for path in files:
        digest.update(path.relative_to(root).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()[:12]


def identity() -> Identity:
    return Identity(__version__, run_environment.code_version(), source_digest(),
                    run_environment.digest(run_environment.environment()))


def cluster_option(parser) -> None:
    """The --cluster option every command with --jobs takes."""
    parser.add_argument("--cluster", default=None, metavar="ADDRESS",
                        help="run on a Dask cluster instead of local worker processes: a scheduler's address "
                             f"(tcp://host:8786) or '{LOCAL}' (a cluster of --jobs processes on this machine); "
                             "every worker must run this trustfg (pip install 'trustfg[cluster]')")


def cluster_at(address: str | None, jobs: int) -> contextlib.AbstractContextManager[Cluster | None]:
    """For a ``with`` block: the :class:`Cluster` at ``address`` (``--cluster``), closed at
    the block's end; None (the local pool) without an address."""
    return Cluster(address, jobs) if address else contextlib.nullcontext()


class Cluster:
    """A Dask cluster the runs go to: connected at the first :meth:`map`, closed by
    :meth:`close` (or the end of a ``with`` block)."""

    def __init__(self, address: str, jobs: int = 1):
        self.address, self.jobs = address, max(1, jobs)
        self.here: Identity | None = None
        """This process's :class:`Identity`, once connected."""
        self.workers: dict[str, Identity] = {}
        """Each worker's :class:`Identity`, by its address, once connected."""
        self._local = None
        self._client = None
        self._log_level: int | None = None

    def __enter__(self) -> Cluster:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def environments(self) -> set[str]:
        """The digests of the workers' environments (connects first)."""
        self._connected()
        return {worker.env for worker in self.workers.values()}

    def map(self, fn: Callable[[Task], Result], tasks: list[Task], ordered: bool = True) -> Iterator[tuple[Task, Result]]:
        """(task, fn(task)) for every task, computed on the workers; in task order, or as
        each finishes (``ordered=False``). Leaving the loop early cancels what is left."""
        from distributed import as_completed

        client = self._connected()
        futures = client.map(_checked, tasks, fn=fn, source=self.here.source, pure=False)
        index = {future.key: i for i, future in enumerate(futures)}
        try:
            for future in (futures if ordered else as_completed(futures, loop=client.loop)):
                yield tasks[index[future.key]], future.result()
                future.release()  # its result is the caller's now: the cluster's memory is freed
        finally:
            client.cancel([future for future in futures if not future.done()])  # Ctrl-C, an error, an early stop

    def close(self) -> None:
        """Disconnect; a local cluster's processes and ports are gone when this returns."""
        client, local, self._client, self._local = self._client, self._local, None, None
        if client is not None:
            client.close()
        if local is not None:
            local.close()
        if self._log_level is not None:
            logging.getLogger("distributed").setLevel(self._log_level)
            self._log_level = None

    def _connected(self):
        if self._client is not None:
            return self._client
        try:
            from distributed import Client, LocalCluster
        except ImportError:
            raise ClusterError("--cluster needs Dask's distributed: pip install 'trustfg[cluster]'") from None
        quiet = logging.getLogger("distributed")  # workers coming, going and stopped are not the command's output
        self._log_level = quiet.level
        quiet.setLevel(logging.ERROR)
        try:
            if self.address == LOCAL:
                warm_compiled()  # compiled and cached once here, not by every worker at once
                self._local = LocalCluster(n_workers=self.jobs, threads_per_worker=1, processes=True,
                                           host="127.0.0.1", dashboard_address=None)
                self._client = Client(self._local, set_as_default=False)
                self._client.run(_local_worker)
            else:
                self._client = Client(self.address, timeout=CONNECT_TIMEOUT_S, set_as_default=False)
            self._client.wait_for_workers(1, timeout=WORKERS_TIMEOUT_S)
            self.here = identity()
            try:
                self.workers = self._client.run(identity)
            except Exception as exc:  # a worker without this module: Dask hands its ImportError on as an Exception
                raise ClusterError(f"cluster {self.address}: a worker cannot load this code ({exc}); install "
                                   f"{self.here} on every worker") from None
        except OSError as exc:  # unreachable (distributed's TimeoutError is one too)
            self.close()
            raise ClusterError(f"cluster {self.address}: {exc}") from None
        except BaseException:
            self.close()
            raise
        other = {address: worker for address, worker in self.workers.items() if worker.source != self.here.source}
        if other:
            self.close()
            raise ClusterError(f"cluster {self.address}: " + "; ".join(f"worker {a} runs {w}" for a, w in other.items())
                               + f", this client {self.here}: install the same trustfg on every worker")
        threads = self._client.nthreads()
        envs = sorted({worker.env for worker in self.workers.values()})
        print(f"cluster {self.address}: {len(threads)} workers, {sum(threads.values())} threads, {self.here}, "
              f"environments {', '.join(envs)}", file=sys.stderr)
        return self._client


@functools.lru_cache(maxsize=1)
def _worker_source() -> str:
    """The worker's source digest, taken at its first run."""
    return source_digest()


def _checked(task, fn: Callable, source: str):
    """``fn(task)`` on a worker whose Python source is the client's (``source``)."""
    if _worker_source() != source:
        raise ClusterError(f"a worker runs {identity()}, not the client's source {source}: "
                           "install the same trustfg on every worker")
    return fn(task)


def _local_worker() -> None:
    """A local cluster's worker: Ctrl-C in a terminal reaches the command alone (which
    stops the cluster), and the worker's stop is not the command's output."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    logging.getLogger("distributed").setLevel(logging.ERROR)
