"""Independent tasks in this process, on a local cluster or on a ``dask.distributed`` cluster.

A long bake or render is cut into tasks that depend on nothing but their arguments: a top-level
function (pickled by reference, so every worker imports the same code and its cached Numba
kernels) and picklable arguments. Each task is deterministic (its seed is one of its arguments),
so where it runs does not change its bytes.

:class:`Engine` runs them on one of three schedulers (:func:`resolve_scheduler`):

``"synchronous"``
    One after the other in this process (no Dask involved).
``"local"``
    A ``dask.distributed.LocalCluster`` of ``workers`` processes on this machine (one thread
    each: the Numba kernels use the cores themselves), started and stopped by the engine.
an address (``tcp://host:8786``)
    An existing cluster (``dask scheduler`` plus ``dask worker`` on the nodes); the environment
    variable ``DASK_SCHEDULER_ADDRESS`` gives it when no scheduler is named. A scheduler that does
    not answer within ``timeout`` seconds raises a :class:`~prefilter.errors.PrefilterError`.

:meth:`Engine.run` writes each result (a dict of arrays) atomically into a
:class:`~prefilter.fileio.Checkpoints` folder as it arrives and skips the tasks already there, so
a killed bake resumes; a worker lost mid-run has its tasks recomputed elsewhere by the scheduler.
Results travel back to the client, which alone writes files: the workers need no shared disk.
:meth:`Engine.map` (and :func:`task_map`) returns results in order, for bakes that keep their own
files.
"""

from __future__ import annotations

import os
import pickle
import uuid
import warnings
from collections.abc import Callable, Iterable, Sequence

from prefilter.errors import PrefilterError

#: Scheduler names besides addresses.
SYNCHRONOUS = "synchronous"
LOCAL = "local"
#: Environment variable naming the scheduler when none is given.
ENV_ADDRESS = "DASK_SCHEDULER_ADDRESS"
#: Seconds to wait for a scheduler to answer.
CONNECT_TIMEOUT = 10.0

__all__ = ["CONNECT_TIMEOUT", "ENV_ADDRESS", "Engine", "LOCAL", "SYNCHRONOUS",
           "resolve_scheduler", "task_map"]


def resolve_scheduler(scheduler: str | None = None, workers: int | None = None) -> str:
    """The scheduler to use: ``scheduler`` if given, else ``$DASK_SCHEDULER_ADDRESS``, else
    ``"local"`` when ``workers > 1``, else ``"synchronous"``."""
    if scheduler is not None and not isinstance(scheduler, str):
        raise PrefilterError(f"scheduler: expected 'synchronous', 'local' or an address, got "
                             f"{type(scheduler).__name__}")
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int)
                                or workers < 1):
        raise PrefilterError(f"workers: expected an integer >= 1, got {workers!r}")
    s = (scheduler or "").strip() or os.environ.get(ENV_ADDRESS, "").strip()
    if not s:
        return LOCAL if workers is not None and workers > 1 else SYNCHRONOUS
    return s


def _check_task_function(func) -> None:
    """``func`` must pickle by reference (a top-level function): closures and lambdas would be
    pickled by value and run code the workers cannot cache."""
    try:
        pickle.dumps(func)
    except (pickle.PicklingError, AttributeError, TypeError) as exc:
        raise PrefilterError(f"func: expected a top-level function (picklable by reference), got "
                             f"{getattr(func, '__qualname__', func)!r} ({exc})") from None


class Engine:
    """Runs independent tasks on the scheduler ``scheduler`` (see the module docstring).

    Use as a context manager: entering starts the local cluster or connects to the address
    (``timeout`` seconds at most), leaving stops or disconnects. ``workers``: processes of the
    local cluster (default: the machine's cores).
    """

    def __init__(self, scheduler: str | None = None, *, workers: int | None = None,
                 timeout: float | None = None):
        self.scheduler = resolve_scheduler(scheduler, workers)
        if workers is not None and self.scheduler not in (LOCAL, SYNCHRONOUS):
            raise PrefilterError(f"workers: applies to the local cluster only, got {workers} "
                                 f"with scheduler {self.scheduler!r}")
        self.workers = workers
        self.timeout = float(CONNECT_TIMEOUT if timeout is None else timeout)
        self.client = None
        self._cluster = None

    @property
    def synchronous(self) -> bool:
        return self.scheduler == SYNCHRONOUS

    def __enter__(self) -> "Engine":
        if self.synchronous:
            return self
        import logging

        from distributed import Client, LocalCluster

        if self.scheduler == LOCAL:
            n = self.workers or os.cpu_count() or 1
            with warnings.catch_warnings():
                # workers move their status page to a free port when 8787 is taken: no news
                warnings.filterwarnings("ignore", message="Port .* is already in use")
                self._cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                             dashboard_address=None, silence_logs=logging.ERROR)
            self.client = Client(self._cluster)
            return self
        try:
            self.client = Client(self.scheduler, timeout=self.timeout)
        except Exception as exc:  # noqa: BLE001 - refused, timed out, or not a dask scheduler
            raise PrefilterError(
                f"scheduler: expected a dask scheduler answering at {self.scheduler!r} within "
                f"{self.timeout:g} s, got none ({type(exc).__name__}: "
                f"{str(exc).splitlines()[0] if str(exc) else 'no answer'})") from None
        return self

    def __exit__(self, *exc) -> None:
        if self.client is not None:
            self.client.close()
            self.client = None
        if self._cluster is not None:
            self._cluster.close()
            self._cluster = None

    def describe(self) -> str:
        """One line: where the tasks run."""
        if self.synchronous:
            return "this process"
        n = len(self.client.scheduler_info(n_workers=-1)["workers"]) if self.client else 0
        where = "local cluster" if self.scheduler == LOCAL else self.scheduler
        return f"{where} ({n} workers)"

    def scatter(self, obj):
        """``obj`` sent once to every worker (a future to put in task arguments in place of a
        large object shared by all tasks); ``obj`` itself when synchronous."""
        if self.synchronous:
            return obj
        return self.client.scatter(obj, broadcast=True)

    def _completed(self, func, jobs: Sequence[tuple[int, tuple]], desc: str):
        """``(index, result)`` of each job ``(index, args)`` as it finishes."""
        _check_task_function(func)
        if self.synchronous:
            for i, args in jobs:
                yield i, func(*args)
            return
        if self.client is None:
            raise RuntimeError("Engine: use it as a context manager (with Engine(...) as e:)")
        from distributed import as_completed
        from distributed.client import FutureCancelledError
        from distributed.scheduler import KilledWorker

        prefix = f"{desc.replace(' ', '-')}-{uuid.uuid4().hex[:8]}"
        futures = {self.client.submit(func, *args, key=f"{prefix}-{i}", pure=False): i
                   for i, args in jobs}
        try:
            for fut in as_completed(futures):
                try:
                    result = fut.result()
                except KilledWorker as exc:
                    raise PrefilterError(
                        f"{desc} task {futures[fut]}: its workers died repeatedly ({exc}); "
                        f"finished tasks are kept: rerun the same command to resume") from None
                except FutureCancelledError:
                    raise PrefilterError(
                        f"{desc} task {futures[fut]}: cancelled (the scheduler {self.scheduler} "
                        f"was lost); finished tasks are kept: rerun to resume") from None
                fut.release()
                yield futures[fut], result
        finally:
            self.client.cancel(list(futures))

    def map(self, func: Callable, arg_tuples: Iterable[tuple], *, progress: bool = False,
            desc: str = "tasks") -> list:
        """``[func(*args) for args in arg_tuples]``, computed on the engine's scheduler."""
        jobs = list(enumerate(tuple(a) for a in arg_tuples))
        results: list = [None] * len(jobs)
        with _bar(progress, len(jobs), 0, desc) as bar:
            for i, r in self._completed(func, jobs, desc):
                results[i] = r
                bar.update(1)
        return results

    def imap(self, func: Callable, *iterables):
        """``map(func, *iterables)`` on the engine's scheduler: results in order, each yielded
        as soon as it and those before it are done (the ``map_fn`` of
        :func:`prefilter.glints.bake.bake`)."""
        jobs = list(enumerate(zip(*iterables)))
        done: dict = {}
        nxt = 0
        for i, r in self._completed(func, jobs, getattr(func, "__name__", "tasks")):
            done[i] = r
            while nxt in done:
                yield done.pop(nxt)
                nxt += 1

    def run(self, func: Callable, arg_tuples: Sequence[tuple], checkpoints, *,
            progress: bool = False, desc: str = "tasks",
            on_done: Callable[[int], None] | None = None) -> None:
        """Compute ``func(*arg_tuples[i])`` (a dict of arrays) for every ``i`` not yet in
        ``checkpoints`` (a :class:`~prefilter.fileio.Checkpoints`) and save each as it arrives
        (``checkpoints.save(i, **result)``, atomic); ``on_done(i)`` after each save."""
        todo = [(i, tuple(a)) for i, a in enumerate(arg_tuples) if not checkpoints.done(i)]
        with _bar(progress, len(arg_tuples), len(arg_tuples) - len(todo), desc) as bar:
            for i, result in self._completed(func, todo, desc):
                checkpoints.save(i, **result)
                bar.update(1)
                if on_done is not None:
                    on_done(i)


def task_map(func: Callable, arg_tuples: Iterable[tuple], *, scheduler: str | None = None,
             workers: int | None = None, progress: bool = False, desc: str = "tasks") -> list:
    """``[func(*args) for args in arg_tuples]`` on a scheduler started for this call
    (:class:`Engine`); ``func`` a top-level function. A bake that maps several times should
    take ``engine.map`` of one :class:`Engine` instead (one cluster for the whole bake)."""
    with Engine(scheduler, workers=workers) as engine:
        return engine.map(func, arg_tuples, progress=progress, desc=desc)


class _NoBar:
    def update(self, n):
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        pass


def _bar(progress: bool, total: int, initial: int, desc: str):
    if not progress:
        return _NoBar()
    from tqdm import tqdm

    return tqdm(total=total, initial=initial, desc=desc, unit="task")
