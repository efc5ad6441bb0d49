"""Where a sweep's trials run: this process (serial), a local process pool, a Dask cluster.

Each executor maps `run_trial` over trial dicts and yields the rows as they finish (any
order; the runner writes them as they come and orders them by the manifest). Pool workers
use one BLAS thread each (one trial per core; threads would fight over the cores), set
before numpy loads in the worker; Dask's nanny sets the same variables on its workers by
default (`distributed.nanny.pre-spawn-environ`). Dask is an optional extra, imported only
when asked for.
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor
from concurrent.futures import wait as wait_futures
from contextlib import AbstractContextManager
from typing import Any

from omnisort_hw.errors import ExecutorTimeoutError, InputError, MissingExtraError
from omnisort_hw.sweeps.provenance import BLAS_THREAD_VARIABLES

EXECUTORS = ("serial", "pool", "dask")
TrialFn = Callable[[Any], dict[str, Any]]


def one_blas_thread() -> None:
    """Pool worker initializer: one thread per BLAS library (threadpoolctl, when installed,
    also limits a library already loaded)."""
    for name in BLAS_THREAD_VARIABLES:
        os.environ[name] = "1"
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        return
    threadpool_limits(1)


class SerialExecutor(AbstractContextManager["SerialExecutor"]):
    """Trials one after the other in this process (the tests' default: nothing to start)."""

    workers = 1

    def map_unordered(self, fn: TrialFn, items: Iterable[Any]) -> Iterator[dict[str, Any]]:
        for item in items:
            yield fn(item)

    def __exit__(self, *exc: object) -> None:
        return None


class _FutureExecutor:
    """Shared loop of the pool and Dask executors: submit all, yield as they finish."""

    timeout_s: float | None

    def _submit(self, fn: TrialFn, item: Any) -> Any:
        raise NotImplementedError

    def _wait(self, pending: set[Any]) -> tuple[set[Any], set[Any]]:
        raise NotImplementedError

    def map_unordered(self, fn: TrialFn, items: Iterable[Any]) -> Iterator[dict[str, Any]]:
        pending = {self._submit(fn, item) for item in items}
        try:
            while pending:
                done, pending = self._wait(pending)
                if not done:
                    raise ExecutorTimeoutError(
                        f"no trial finished in {self.timeout_s} s ({len(pending)} pending)"
                    )
                for future in done:
                    yield future.result()
        finally:
            for future in pending:
                future.cancel()


class PoolExecutor(_FutureExecutor, AbstractContextManager["PoolExecutor"]):
    """A local process pool (spawned workers: no forked threads of the parent), one BLAS
    thread per worker; `workers` defaults to the machine's cores."""

    def __init__(self, workers: int | None = None, timeout_s: float | None = None) -> None:
        self.workers = workers or os.cpu_count() or 1
        self.timeout_s = timeout_s
        self._pool = ProcessPoolExecutor(
            self.workers,
            mp_context=multiprocessing.get_context("spawn"),
            initializer=one_blas_thread,
        )

    def _submit(self, fn: TrialFn, item: Any) -> Any:
        return self._pool.submit(fn, item)

    def _wait(self, pending: set[Any]) -> tuple[set[Any], set[Any]]:
        done, rest = wait_futures(pending, timeout=self.timeout_s, return_when=FIRST_COMPLETED)
        return set(done), set(rest)

    def __exit__(self, *exc: object) -> None:
        self._pool.shutdown(wait=True, cancel_futures=True)


def _distributed() -> Any:
    try:
        import distributed
    except ImportError:
        raise MissingExtraError(
            "--executor dask needs Dask: pip install 'omnisort-hw[dask]' "
            "(on this machine and on every worker)"
        ) from None
    return distributed


class DaskExecutor(_FutureExecutor, AbstractContextManager["DaskExecutor"]):
    """A Dask cluster at `scheduler` (tcp://HOST:PORT), or, without one, a LocalCluster of
    `workers` single-threaded worker processes, every port on 127.0.0.1."""

    def __init__(
        self,
        scheduler: str | None = None,
        workers: int | None = None,
        timeout_s: float | None = None,
        connect_timeout_s: float = 60.0,
    ) -> None:
        distributed = _distributed()
        self.timeout_s = timeout_s
        self._distributed = distributed
        self._cluster = None
        try:
            if scheduler:
                self._client = distributed.Client(scheduler, timeout=connect_timeout_s)
            else:
                self._cluster = distributed.LocalCluster(
                    n_workers=workers or os.cpu_count() or 1,
                    threads_per_worker=1,
                    processes=True,
                    host="127.0.0.1",
                    # The scheduler's HTTP server starts even without a dashboard: on
                    # loopback, any free port (not a fixed 8787 another user may hold).
                    dashboard_address="127.0.0.1:0",
                    timeout=connect_timeout_s,
                )
                self._client = distributed.Client(self._cluster, timeout=connect_timeout_s)
        except (OSError, TimeoutError) as exc:
            self.close()
            where = scheduler or "a local cluster"
            raise InputError(f"--scheduler {where}: cannot connect ({exc})") from None
        self.workers = len(self._client.scheduler_info().get("workers", {}))
        if scheduler:
            self._check_versions()

    def _check_versions(self) -> None:
        """Every worker must run the client's package versions, or the rows would mix
        numbers of different code (InputError naming the first worker that differs)."""
        from omnisort_hw.sweeps.provenance import package_versions

        mine = package_versions()
        for worker, theirs in self._client.run(package_versions).items():
            if theirs != mine:
                self.close()
                diff = {
                    k: (mine.get(k), theirs.get(k)) for k in mine if mine.get(k) != theirs.get(k)
                }
                raise InputError(
                    f"--scheduler: worker {worker} runs other versions than this client "
                    f"(client, worker): {diff}; install the same on every worker (docs/sweeps.md)"
                )

    def _submit(self, fn: TrialFn, item: Any) -> Any:
        # pure=False: a trial is never deduplicated or cached by Dask; the sweep's keys do it.
        return self._client.submit(fn, item, pure=False)

    def _wait(self, pending: set[Any]) -> tuple[set[Any], set[Any]]:
        try:
            done, rest = self._distributed.wait(
                list(pending), timeout=self.timeout_s, return_when="FIRST_COMPLETED"
            )
        except TimeoutError:
            return set(), pending
        return set(done), set(rest)

    def close(self) -> None:
        client = getattr(self, "_client", None)
        if client is not None:
            client.close(timeout=30)
        if self._cluster is not None:
            self._cluster.close(timeout=30)

    def __exit__(self, *exc: object) -> None:
        self.close()


def make_executor(
    name: str,
    workers: int | None = None,
    scheduler: str | None = None,
    timeout_s: float | None = None,
) -> SerialExecutor | PoolExecutor | DaskExecutor:
    """The executor called `name` (one of EXECUTORS)."""
    if scheduler and name != "dask":
        raise InputError(f"--scheduler is for --executor dask, not {name}")
    if workers is not None and workers < 1:
        raise InputError(f"--workers must be at least 1, got {workers}")
    if name == "serial":
        return SerialExecutor()
    if name == "pool":
        return PoolExecutor(workers, timeout_s)
    if name == "dask":
        return DaskExecutor(scheduler, workers, timeout_s)
    raise InputError(f"--executor must be one of {', '.join(EXECUTORS)}, got {name!r}")
