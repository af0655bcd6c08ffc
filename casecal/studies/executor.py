"""Where a study's independent trials run: local processes, this process, or dask.

Every study splits into trials that share nothing but their inputs (a robot, a seed, a
setting); `Executor.map` spreads them over the workers and returns their results in order,
so a study written once runs on one core, on all local cores, or on a cluster. Workers get
one BLAS thread each: two workers that each start a BLAS thread per core thrash.
"""

from __future__ import annotations

import os
import re
import signal
import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from ..errors import CalibrationError, Terminated

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
    _sigterm: object = field(default=None, init=False, repr=False, compare=False)
    _cluster: int | None = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.kind not in EXECUTORS:
            raise CalibrationError(f"unknown executor {self.kind!r}; use {', '.join(EXECUTORS)}")
        w = self.workers
        if w is not None and (isinstance(w, bool) or not isinstance(w, int) or w < 1):
            # 0 once meant "all cores" by accident (`workers or cpu_count`): say so instead
            raise CalibrationError(
                f"workers={w!r}: give a positive number of processes, or None for one per core"
            )
        if isinstance(self.scheduler, str):
            self.scheduler = check_scheduler(self.scheduler)

    @property
    def n_workers(self) -> int:
        """How many trials run at once (1 for ``"serial"``): for a dask scheduler, the
        cluster's worker threads, not this machine's cores (the study's tasks are cut to
        keep every worker busy)."""
        if self.kind == "serial":
            return 1
        if self.workers is None and self.kind == "dask" and self.scheduler is not None:
            if self._cluster is None and isinstance(self.scheduler, str):
                self.check_reachable()  # counts the cluster's threads
            elif self._cluster is None:  # a Client
                self._cluster = _threads_of(self.scheduler)
            return self._cluster
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
        from concurrent.futures import as_completed

        # one pool for every map of this executor: the workers keep what they built
        # (kernels loaded, chains that are hot) from one study to the next
        if self._pool is None:
            self._pool = _start_pool(self.n_workers)
            self._sigterm = _raise_on_sigterm()
        results: list = [None] * len(tasks)
        try:
            futures = {self._pool.submit(func, tasks[i]): i for i in order}
            for done, fut in enumerate(as_completed(futures), start=1):
                results[futures[fut]] = fut.result()
                self._tick(done, len(tasks))
        except KeyboardInterrupt:
            # Ctrl-C or SIGTERM: nobody wants the running trials' results, so the workers
            # stop now instead of after them
            self.close(terminate=True)
            raise
        except BaseException:
            self.close()  # a failed study leaves no workers behind
            raise
        return results

    def close(self, terminate: bool = False) -> None:
        """Stop the worker processes, if any (a later `map` starts new ones).

        `terminate` stops them in the middle of their tasks instead of after them.
        """
        _restore_sigterm(self._sigterm)
        self._sigterm = None
        pool, self._pool = self._pool, None
        if pool is None:
            return
        if terminate:
            for process in list(getattr(pool, "_processes", {}).values()):
                process.terminate()
        pool.shutdown(wait=True, cancel_futures=True)

    def __enter__(self) -> Executor:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def check_reachable(self, timeout: float = 10.0) -> None:
        """Connect to the scheduler address once, now, so that an address nothing answers
        at is said before any work, not after the first studies, and count its workers'
        threads (`n_workers`); no-op without one."""
        if not isinstance(self.scheduler, str):
            return
        try:
            from dask.distributed import Client
        except ImportError:
            raise CalibrationError(
                "the dask executor needs dask.distributed: pip install 'casecal[distributed]'"
            ) from None
        try:
            with Client(self.scheduler, timeout=timeout) as client:
                self._cluster = _threads_of(client)
        except (OSError, TimeoutError) as exc:
            raise CalibrationError(
                f"no dask scheduler answers at {self.scheduler!r} within {timeout:g} s "
                f"({' '.join(str(exc).split()) or type(exc).__name__}): start one there "
                "(dask scheduler), check the address, or leave --scheduler out to run on "
                "this machine"
            ) from None

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


def _threads_of(client) -> int:
    """Worker threads of a dask Client's cluster, at least 1."""
    return max(sum(client.nthreads().values()), 1)


_ADDRESS = re.compile(r"(?:(?:tcp|tls)://)?(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9.-]+):([0-9]{1,5})")
_LABEL = re.compile(r"[A-Za-z0-9](?:[A-Za-z0-9-]*[A-Za-z0-9])?")


def check_scheduler(address: str) -> str:
    """`address` if it is a dask scheduler address, ``[tcp://]host:port``, else a
    CalibrationError: refused before a study runs, not after the first one.

    The host is a name (with a letter), a dotted IPv4 address or a bracketed IPv6 one; the
    port is 1 to 65535. ``9:1`` is no address (dask read it as a size: 3 EiB).
    """
    text = address.strip()
    match = _ADDRESS.fullmatch(text)
    ok = match is not None and 1 <= int(match[2]) <= 65535
    if ok and not match[1].startswith("["):
        labels = match[1].split(".")
        ipv4 = len(labels) == 4 and all(p.isdigit() and int(p) <= 255 for p in labels)
        name = all(_LABEL.fullmatch(p) for p in labels) and any(c.isalpha() for c in match[1])
        ok = ipv4 or name
    if not ok:
        raise CalibrationError(
            f"scheduler address {address!r} is not [tcp://]host:port (a host name or IP "
            "address and a port from 1 to 65535); give e.g. --scheduler tcp://localhost:8786"
        )
    return text


def _on_sigterm(signum, frame):
    raise Terminated("terminated (SIGTERM)")


def _raise_on_sigterm():
    """Make SIGTERM raise `Terminated` while the pool lives; returns what to restore.

    Only from the main thread (the only one that may set handlers) and only over the
    default action: a handler the application installed is its own business.
    """
    if threading.current_thread() is not threading.main_thread():
        return None
    if signal.getsignal(signal.SIGTERM) is not signal.SIG_DFL:
        return None
    signal.signal(signal.SIGTERM, _on_sigterm)
    return signal.SIG_DFL


def _restore_sigterm(previous) -> None:
    if previous is not None and threading.current_thread() is threading.main_thread():
        if signal.getsignal(signal.SIGTERM) is _on_sigterm:
            signal.signal(signal.SIGTERM, previous)


def _start_pool(n_workers: int):
    """A process pool whose workers ignore Ctrl-C and die with this process."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    # a worker's parent is this process, unless a fork server starts them; the kernel's
    # death signal follows the thread that forks, so it is asked for from the main one only
    direct = multiprocessing.get_start_method() != "forkserver"
    main = threading.current_thread() is threading.main_thread()
    return ProcessPoolExecutor(
        max_workers=n_workers, initializer=_worker_start, initargs=(os.getpid(), direct, main)
    )


def _die_with(parent: int, direct: bool, deathsig: bool) -> None:
    """End this worker when the process that started it ends (finding: a supervisor's
    SIGKILL of the parent alone left every worker running, re-parented, forever)."""
    forker = os.getppid()
    if direct and forker != parent:  # the parent died before this worker ran
        os._exit(1)
    if deathsig and sys.platform.startswith("linux"):
        try:
            import ctypes

            pr_set_pdeathsig = 1
            ctypes.CDLL(None, use_errno=True).prctl(pr_set_pdeathsig, int(signal.SIGKILL))
        except (OSError, AttributeError):  # no prctl: the watch below suffices
            pass
    if os.getppid() != forker:  # it died before prctl
        os._exit(1)
    # portable, and covers whatever prctl misses: re-parenting means the forker is gone
    threading.Thread(target=_watch_parent, args=(forker,), daemon=True).start()


def _watch_parent(forker: int) -> None:
    while True:
        time.sleep(0.5)
        if os.getppid() != forker:
            os._exit(1)


def _worker_start(parent: int | None = None, direct: bool = True, deathsig: bool = False) -> None:
    """Each worker: one BLAS thread and no kernel threads for its whole life (the workers
    already share the machine's cores).

    A local worker (`parent` given) also ignores Ctrl-C, which the terminal sends to the
    whole process group: the parent answers it and stops the workers, so no worker prints
    a KeyboardInterrupt traceback; and it dies with `parent`.
    """
    if parent is not None:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        # a forked worker inherits the parent's SIGTERM handler: `terminate` must end it
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        _die_with(parent, direct, deathsig)
    os.environ["CASECAL_THREADS"] = "1"
    for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[name] = "1"  # for BLAS libraries loaded later
    try:
        from threadpoolctl import threadpool_limits

        threadpool_limits(1)
    except ImportError:
        pass
