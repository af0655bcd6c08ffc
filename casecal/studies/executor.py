"""Where a study's independent trials run: local processes, this process, or dask.

Every study splits into trials that share nothing but their inputs (a robot, a seed, a
setting); `Executor.map` spreads them over the workers and returns their results in order,
so a study written once runs on one core, on all local cores, or on a cluster. Workers get
one BLAS thread each: two workers that each start a BLAS thread per core thrash.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from ..errors import CalibrationError

EXECUTORS = ("processes", "serial", "dask")


@dataclass
class Executor:
    """How to run a study's trials.

    Attributes
    ----------
    kind : {"processes", "serial", "dask"}
        Local processes (`workers` of them, default the number of cores), this process,
        or a dask.distributed cluster (``pip install casecal[distributed]``).
    workers : int, optional
    scheduler : str or dask Client, optional
        For ``"dask"``: a scheduler address (``"tcp://host:8786"``) or a Client; None
        starts a LocalCluster.
    progress : callable(done, total), optional
        Called after each task finishes (the core itself never prints).

    Local worker processes start at the first `map` and serve every later one, keeping
    what they loaded; `close` (or ``with Executor(...) as run:``) stops them.
    """

    kind: str = "processes"
    workers: int | None = None
    scheduler: object = None
    progress: Callable[[int, int], None] | None = None
    _pool: object = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.kind not in EXECUTORS:
            raise CalibrationError(f"unknown executor {self.kind!r}; use {', '.join(EXECUTORS)}")

    @property
    def n_workers(self) -> int:
        """How many trials run at once (1 for ``"serial"``)."""
        if self.kind == "serial":
            return 1
        return self.workers or os.cpu_count() or 1

    def map(self, func: Callable, tasks: Sequence, cost: Callable | None = None) -> list:
        """``[func(t) for t in tasks]``, spread over the workers, in the order of `tasks`.

        `func` must be a module-level function (it is pickled to the workers); `cost`,
        optional, estimates a task's run time so that the longest start first.
        """
        tasks = list(tasks)
        if not tasks:
            return []
        if self.kind == "serial" or (self.kind == "processes" and self.n_workers == 1):
            results = []
            for k, task in enumerate(tasks):
                results.append(func(task))
                self._tick(k + 1, len(tasks))
            return results
        order = sorted(range(len(tasks)), key=lambda i: -cost(tasks[i])) if cost else None
        if self.kind == "processes":
            return self._local(func, tasks, order or range(len(tasks)))
        return self._dask(func, tasks, order or range(len(tasks)))

    def __call__(self, grid):
        """Run a study `Grid` (see `casecal.studies.engine.run_study`)."""
        from .engine import run_study

        return run_study(grid, executor=self)

    def _tick(self, done: int, total: int) -> None:
        if self.progress is not None:
            self.progress(done, total)

    def _local(self, func, tasks, order):
        from concurrent.futures import ProcessPoolExecutor, as_completed

        # one pool for every map of this executor: the workers keep what they built
        # (kernels loaded, chains that are hot) from one study to the next
        if self._pool is None:
            self._pool = ProcessPoolExecutor(max_workers=self.n_workers, initializer=_worker_start)
        results: list = [None] * len(tasks)
        futures = {self._pool.submit(func, tasks[i]): i for i in order}
        try:
            for done, fut in enumerate(as_completed(futures), start=1):
                results[futures[fut]] = fut.result()
                self._tick(done, len(tasks))
        except BaseException:
            self.close()  # a failed or interrupted study leaves no workers behind
            raise
        return results

    def close(self) -> None:
        """Stop the worker processes, if any (a later `map` starts new ones)."""
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None

    def __enter__(self) -> Executor:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _dask(self, func, tasks, order):
        try:
            from dask.distributed import Client, LocalCluster, as_completed
        except ImportError:
            raise CalibrationError(
                "the dask executor needs dask.distributed: pip install 'casecal[distributed]'"
            ) from None
        own = None
        if self.scheduler is None:
            own = LocalCluster(n_workers=self.n_workers, threads_per_worker=1)
            client = Client(own)
        elif isinstance(self.scheduler, str):
            client = Client(self.scheduler)
        else:
            client = self.scheduler
        try:
            client.run(_worker_start)
            futures = {client.submit(func, tasks[i], pure=False): i for i in order}
            results: list = [None] * len(tasks)
            by_key = {f.key: i for f, i in futures.items()}
            for done, fut in enumerate(as_completed(list(futures)), start=1):
                results[by_key[fut.key]] = fut.result()
                self._tick(done, len(tasks))
            return results
        finally:
            if own is not None:
                client.close()
                own.close()


def _worker_start() -> None:
    """Each worker: one BLAS thread and no kernel threads for its whole life (the workers
    already share the machine's cores)."""
    os.environ["CASECAL_THREADS"] = "1"
    for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[name] = "1"  # for BLAS libraries loaded later
    try:
        from threadpoolctl import threadpool_limits

        threadpool_limits(1)
    except ImportError:
        pass
