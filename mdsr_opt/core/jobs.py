"""Write jobs beside the solves: a standard process pool, or the jobs one after the other in this process.

``mdsr run`` alternates solves (CasADi and IPOPT, one core) with drawing and writing their results
(matplotlib, GIFs, meshes, photographs). Threads do not help (CasADi and matplotlib's Agg hold the GIL);
worker processes do. :func:`process_pool` makes a :class:`concurrent.futures.ProcessPoolExecutor` with an
explicit start method (:func:`start_method`: never a plain fork of a process that runs solver threads);
:class:`Jobs` sends a run's jobs to it, or runs each at once in this process when there is no pool. The
files are the same either way.

A pool's jobs wait in one queue per pool (shared by every :class:`Jobs` sending to it) and start longest
first: each job says its estimated ``cost`` and a worker that becomes free takes the costliest job waiting
(the longest-processing-time rule). The executor only ever holds as many jobs as it has workers, so a long
job sent late does not wait behind short ones sent before it, and does not end the run alone.

A job is a module-level function with picklable arguments, pickled when it is submitted (so that it sees
its arguments as they were then) and run in a worker; its return value comes back pickled. A worker runs
with one OpenBLAS thread unless ``OPENBLAS_NUM_THREADS`` says otherwise (CasADi's bundled OpenBLAS, which
threadpoolctl does not see, reads the variable when it loads) and with matplotlib's Agg backend.

Example
-------
>>> done = []
>>> with Jobs() as jobs:  # no pool: each job here and now
...     jobs.submit(sum, [1, 2, 3], on_done=done.append)
>>> done
[6]
"""

from __future__ import annotations

import collections
import contextlib
import functools
import heapq
import importlib
import itertools
import os
import pickle
import signal
import sys
import threading
import weakref
from concurrent.futures import BrokenExecutor, CancelledError, Executor, Future, wait as wait_for
from typing import Any, Callable, Iterator, Sequence

from .checks import check_int

__all__ = ["Jobs", "available_cores", "main_is_plain_script", "process_pool", "server_imports_this_package",
           "start_method"]


def start_method() -> str:
    """The start method of the pool's workers: 'forkserver' on Linux (each worker forked from a server
    process that has imported the jobs' modules once), 'spawn' elsewhere (macOS's system libraries are not
    safe to fork, Windows cannot). Neither shares threads or locks with this process."""
    return "forkserver" if sys.platform.startswith("linux") else "spawn"


def main_is_plain_script() -> bool:
    """Whether this process runs a plain script file (``python my_design.py``): the pool's workers ('spawn'
    or 'forkserver') run such a script again as they start, so one without an ``if __name__ ==
    "__main__":`` guard would start its work again in every worker. Interactive sessions, notebooks and
    modules run with ``python -m`` are not plain scripts."""
    main = sys.modules.get("__main__")
    return getattr(main, "__spec__", None) is None and getattr(main, "__file__", None) is not None


def available_cores() -> int:
    """The cores this process may run on (its affinity where the platform tells, else the machine's)."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # macOS, Windows
        return os.cpu_count() or 1


def server_imports_this_package() -> bool:
    """Whether a forkserver started now would import this very copy of the package. The server is a new
    interpreter in this process's working folder with the interpreter's default search path: the working
    folder first (unless ``-I``/``-P``), then ``PYTHONPATH`` and the site folders, not the folder of this
    process's script nor what it added to ``sys.path`` itself. So: the package found in the working folder
    is this one, or none is found there and this one lies in a site folder (an installed package)."""
    import site
    from importlib.machinery import PathFinder

    name = __name__.split(".")[0]
    here = os.path.realpath(sys.modules[name].__file__ or "")
    if not (sys.flags.isolated or getattr(sys.flags, "safe_path", False)):  # safe_path: Python 3.11+
        there = PathFinder.find_spec(name, [os.getcwd()])
        if there is not None:
            return os.path.realpath(there.origin or "") == here
    folders = list(site.getsitepackages()) + ([site.getusersitepackages()] if site.ENABLE_USER_SITE else [])
    return os.path.dirname(os.path.dirname(here)) in {os.path.realpath(f) for f in folders}


def worker_environment() -> dict[str, str]:
    """What a worker sets before its first import: one OpenBLAS thread (unless this process's environment
    asks for another count) and matplotlib's Agg backend (workers only write files)."""
    return {"OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS", "1"), "MPLBACKEND": "Agg"}


def _exit_with_parent() -> None:
    """Wait for the process that started this worker to end, then end this worker at once: a run killed
    outright (no shutdown of its pool) leaves no worker behind, idle or writing into its folder."""
    import multiprocessing

    multiprocessing.parent_process().join()
    os._exit(1)


def _start_worker(env: dict[str, str], modules: tuple[str, ...], setup: tuple | None = None) -> None:
    """A worker's initializer: a watch on its parent (:func:`_exit_with_parent`), :func:`worker_environment`'s
    variables, the jobs' ``modules``, then ``setup`` (a picklable ``(function, args)``), if given."""
    # Ctrl-C is the run's to handle: a terminal sends it to the workers too, and a worker it ended would break
    # the pool under the run's feet; the run ends its workers itself (process_pool). One that arrives before
    # this line ends the worker quietly (the run reports the interrupt; the pool's report would be a traceback)
    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        threading.Thread(target=_exit_with_parent, name="exit-with-parent", daemon=True).start()
        _prepare_worker(env, modules, setup)
    except BaseException as exc:  # noqa: B036 - a Ctrl-C may surface as the error of the import it broke
        if _interrupted(exc):  # (an extension module's "ImportError: initialization failed" caused by it)
            os._exit(1)
        raise


def _interrupted(exc: BaseException | None) -> bool:
    """Whether ``exc`` is a KeyboardInterrupt or was raised while handling or because of one."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False


def _prepare_worker(env: dict[str, str], modules: tuple[str, ...], setup: tuple | None) -> None:
    """:func:`_start_worker`'s work after its watch and handler are set. The worker keeps the command's
    priority: a lowered one starves its jobs, and the run waiting for them, whenever other processes
    share the cores."""
    os.environ.update(env)
    from .warnlines import one_line_warnings

    one_line_warnings()  # a job's warning: one line beside the run's log lines, not a path and source
    if "numpy" in sys.modules:  # preloaded by the server: its BLAS read the variable before it was set
        from threadpoolctl import threadpool_limits

        threadpool_limits(int(env["OPENBLAS_NUM_THREADS"]), user_api="blas")
    if "matplotlib" in sys.modules:
        import matplotlib

        matplotlib.use("Agg")
    for name in modules:
        importlib.import_module(name)
    if setup is not None:
        fn, args = setup
        fn(*args)


@contextlib.contextmanager
def process_pool(workers: int | None = None, modules: Sequence[str] = (),
                 setup: tuple | None = None) -> Iterator[Executor | None]:
    """A pool of ``workers`` processes for write jobs (default: one per available core), or None with
    ``workers`` 0 or a single core (nothing to gain beside this process). ``modules``: what the jobs
    import, imported by each worker as it starts; with 'forkserver' they are imported once by the server
    the workers are forked from, except this package's own where the server would not import this very
    copy of it (:func:`server_imports_this_package`): the workers then import those from this process's
    ``sys.path``. ``setup``: a picklable ``(function, args)`` each worker calls after those imports. Shut
    down when the block ends: jobs not started are cancelled, running ones finish.
    """
    if workers is None:
        workers = available_cores()
    workers = check_int(workers, "workers", 0)
    if workers == 0 or available_cores() < 2:
        yield None
        return
    import multiprocessing  # here: `mdsr list` and the serial paths need neither
    from concurrent.futures import ProcessPoolExecutor

    context = multiprocessing.get_context(start_method())
    if context.get_start_method() == "forkserver":
        ours = __name__.split(".")[0]
        mine = server_imports_this_package()
        context.set_forkserver_preload([m for m in modules if mine or m.split(".")[0] != ours])
    before = {p.pid for p in multiprocessing.active_children()}
    pool = ProcessPoolExecutor(workers, mp_context=context, initializer=_start_worker,
                               initargs=(worker_environment(), tuple(modules), setup))
    _SLOTS[pool] = workers
    # start the workers now, from a thread: starting one waits until the forkserver has imported the
    # preloaded modules, and the caller's own work (building the scenes, the first solves) goes on meanwhile;
    # its jobs wait in the pool's queue until the workers are started (a job sent to the executor itself
    # before would wait, in the caller's thread, for the workers it starts)
    _STARTING[pool] = threading.Event()
    starter = threading.Thread(target=_start_workers, args=(pool, workers), name="start-workers", daemon=True)
    _ENDERS[pool] = functools.partial(_end_workers, pool, before, starter)
    starter.start()
    try:
        yield pool
    except BaseException:
        _ENDERS.pop(pool, lambda: None)()  # unless a Jobs block ended them already
        raise
    finally:
        starter.join()
        # jobs are never cancelled here: a cancelled job of a pool that breaks meanwhile (a worker ended by a
        # signal) stops the pool's own manager thread (InvalidStateError in CPython's terminate_broken) and
        # the shutdown then waits for ever; a block left by an exception ends the workers instead, and the
        # pool fails its jobs not yet done (BrokenProcessPool)
        pool.shutdown(wait=True)
        _ENDERS.pop(pool, None)


#: the pools made by process_pool, each with the function that ends its workers
_ENDERS: "weakref.WeakKeyDictionary[Executor, Callable[[], None]]" = weakref.WeakKeyDictionary()
#: the pools made by process_pool, each with its number of workers
_SLOTS: "weakref.WeakKeyDictionary[Executor, int]" = weakref.WeakKeyDictionary()
#: the pools made by process_pool whose workers are being started, each with the event set once they are
_STARTING: "weakref.WeakKeyDictionary[Executor, threading.Event]" = weakref.WeakKeyDictionary()
#: per pool, the queue of its jobs not yet started (:class:`_Queue`)
_QUEUES: "weakref.WeakKeyDictionary[Executor, _Queue]" = weakref.WeakKeyDictionary()
_QUEUES_LOCK = threading.Lock()


def _end_workers(pool: Executor, before: set[int], starter: threading.Thread) -> None:
    """End ``pool``'s worker processes at once (SIGTERM): its jobs not yet done fail (BrokenProcessPool).
    ``before``: the process ids of this process's children before the pool was made (where the pool has no
    ``terminate_workers``, Python < 3.14, its workers are the children made since). ``starter``: the thread
    starting the workers (:func:`_start_workers`), which starts no more once the pool's queue is closed; it
    is waited for (at most the start of the worker it is starting) before any worker is ended: a worker
    started after the others were ended would be one the broken pool waits for at its shutdown, for ever,
    while it waits for a job that never comes."""
    import multiprocessing

    _queue(pool).close()
    while starter.is_alive():  # a Ctrl-C now (the run is already stopping, by an error or an interrupt that
        with contextlib.suppress(KeyboardInterrupt):  # its caller raises again) does not cut this short
            starter.join(0.05)
    terminate = getattr(pool, "terminate_workers", None)
    if terminate is not None:
        with contextlib.suppress(Exception):
            terminate()
        return
    for proc in multiprocessing.active_children():
        if proc.pid not in before:
            with contextlib.suppress(Exception):
                proc.terminate()


def _start_workers(pool: Executor, workers: int) -> None:
    """Make ``pool`` start its ``workers`` worker processes (by jobs that do nothing; the executor starts a
    worker for a job that finds none idle), then send it the jobs that its queue holds meanwhile; once the
    queue is closed (the workers are being ended), start no more and send nothing. This
    thread blocks Ctrl-C (SIGINT) where the platform can: the processes it starts (the forkserver, which
    imports the preloaded modules, and through it the workers) inherit the block, so that a terminal's
    Ctrl-C, which the run handles in its main thread, does not interrupt them with a traceback of their
    own."""
    if hasattr(signal, "pthread_sigmask"):  # POSIX; this thread only (the main thread still gets the signal)
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    queue = _queue(pool)
    try:
        for _ in range(workers):
            if queue.closed:
                break
            pool.submit(os.getpid)
    except Exception:  # the pool was shut down first (its block ended at once), or broken by a Ctrl-C: the
        pass  # run reports that itself (its jobs, sent now, fail with the pool's error)
    finally:
        _STARTING.pop(pool).set()
        queue.start()  # (nothing once closed)


def _call(job: bytes) -> Any:
    """Run a pickled job in a worker."""
    fn, args, kwargs = pickle.loads(job)
    return fn(*args, **kwargs)


#: the error of a job that a closed queue (:meth:`_Queue.close`) never started
_NOT_STARTED = "the pool's workers were ended; the job was not started"


class _Queue:
    """The jobs of one pool not yet started, costliest first (ties: the first sent); at most ``slots`` of
    them are in the pool at a time. Each job's outcome goes to a :class:`concurrent.futures.Future` of
    this queue's own, made when the job is sent (cancelled while the job waits here: it never starts)."""

    def __init__(self, pool: Executor, slots: int):
        self.pool, self.slots = weakref.ref(pool), slots  # weak: the queue is the value of _QUEUES[pool]
        self._heap: list = []
        self._count = itertools.count()
        self._running = 0
        self._closed = False
        self._lock = threading.Lock()

    def put(self, job: bytes, cost: float) -> Future:
        outer: Future = Future()
        with self._lock:
            if self._closed:
                outer.set_exception(BrokenExecutor(_NOT_STARTED))
                return outer
            heapq.heappush(self._heap, (-cost, next(self._count), outer, job))
        self.start()
        return outer

    def close(self) -> None:
        """Send no more jobs to the pool (its workers are being ended): the jobs waiting, and any sent
        later, fail with :class:`~concurrent.futures.BrokenExecutor` without starting."""
        with self._lock:
            self._closed = True
            waiting, self._heap = self._heap, []
        for _, _, outer, _ in waiting:
            if outer.set_running_or_notify_cancel():
                outer.set_exception(BrokenExecutor(_NOT_STARTED))

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` was called."""
        return self._closed

    def start(self) -> None:
        """Send the costliest waiting jobs to the pool while it has a free worker (none while its workers
        are being started: :func:`_start_workers` calls this once they are)."""
        pool = self.pool()
        if pool is not None and pool in _STARTING:
            return
        while True:
            with self._lock:
                if self._closed or self._running >= self.slots or not self._heap:
                    return
                _, _, outer, job = heapq.heappop(self._heap)
                if not outer.set_running_or_notify_cancel():  # cancelled while it waited
                    continue
                self._running += 1
            try:
                pool = self.pool()
                if pool is None:  # pragma: no cover - a pool is kept by its Jobs until their jobs are done
                    raise RuntimeError("the pool of this job is gone")
                inner = pool.submit(_call, job)
            except BaseException as exc:  # noqa: B036 - a pool shut down or broken: the job's outcome
                with self._lock:
                    self._running -= 1
                outer.set_exception(exc)
                continue
            inner.add_done_callback(functools.partial(self._finished, outer))

    def _finished(self, outer: Future, inner: Future) -> None:
        with self._lock:
            self._running -= 1
        if inner.cancelled():
            outer.set_exception(CancelledError())
        elif inner.exception() is not None:
            outer.set_exception(inner.exception())
        else:
            outer.set_result(inner.result())
        self.start()


def _queue(pool: Executor) -> _Queue:
    """The queue of ``pool``'s jobs (made at the first job): as many at a time in the pool as it has
    workers (a pool not made by :func:`process_pool`: as many as there are cores)."""
    with _QUEUES_LOCK:
        q = _QUEUES.get(pool)
        if q is None:
            q = _QUEUES[pool] = _Queue(pool, _SLOTS.get(pool) or available_cores())
        return q


class Jobs:
    """A run's write jobs: sent to ``pool`` (a :class:`concurrent.futures.Executor`), or with None each
    run at once in this process.

    :meth:`submit` sends a job and collects the jobs done so far; :meth:`wait` collects all of them. The
    pool's workers start the costliest job waiting first (each job's ``cost``, see the module's
    docstring). A job's ``on_done`` gets its return value, in the order the jobs were submitted; a job's
    exception is raised again here (with the worker's traceback as its cause). Leaving the ``with`` block waits for every
    job; leaving it by an exception (a failed job, Ctrl-C) cancels the jobs not yet started and waits for
    the running ones, whose outcome is dropped.
    """

    def __init__(self, pool: Executor | None = None):
        self.pool = pool
        self._pending: collections.deque = collections.deque()

    @property
    def parallel(self) -> bool:
        """Whether jobs run in other processes."""
        return self.pool is not None

    def submit(self, fn: Callable[..., Any], *args, on_done: Callable[[Any], None] | None = None,
               cost: float = 0.0, **kwargs) -> None:
        """Run ``fn(*args, **kwargs)``: in the pool, or here and now without one. ``on_done`` receives the
        return value (for a pool's job, at a later :meth:`submit` or at :meth:`wait`). ``cost``: the job's
        estimated run time in any unit the run's jobs share (a pool's free worker takes the costliest job
        waiting; equal costs in the order sent)."""
        if self.pool is None:
            value = fn(*args, **kwargs)
            if on_done is not None:
                on_done(value)
            return
        try:
            job = pickle.dumps((fn, args, kwargs), protocol=pickle.HIGHEST_PROTOCOL)
        except (pickle.PicklingError, AttributeError, TypeError) as exc:
            raise TypeError(f"the job {getattr(fn, '__name__', fn)!r} cannot be sent to a worker process (a job "
                            f"is a module-level function with picklable arguments): {exc}") from exc
        self._pending.append((_queue(self.pool).put(job, float(cost)), on_done))
        self._collect(block=False)

    def wait(self) -> None:
        """Wait for every job submitted; pass each one's value to its ``on_done``."""
        self._collect(block=True)

    def _collect(self, block: bool) -> None:
        while self._pending and (block or self._pending[0][0].done()):
            future, on_done = self._pending[0]
            value = future.result()
            self._pending.popleft()
            if on_done is not None:
                on_done(value)

    def stop(self, exc: BaseException | None = None) -> None:
        """Drop the jobs' results. After Ctrl-C, SIGTERM or a broken pool (``exc``), the workers of a pool
        made by :func:`process_pool` are ended at once (its jobs not yet done fail); otherwise the jobs not yet
        started are cancelled and the running ones waited for."""
        pending, self._pending = self._pending, collections.deque()
        end = _ENDERS.get(self.pool) if self.pool is not None else None
        if end is not None and isinstance(exc, (KeyboardInterrupt, BrokenExecutor)):
            _ENDERS.pop(self.pool, None)
            end()
            return
        futures = [f for f, _ in pending if not f.cancel()]
        wait_for(futures)

    def __enter__(self) -> "Jobs":
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            try:
                self.wait()
            except BaseException as failed:
                self.stop(failed)
                raise
        else:
            self.stop(exc)
        return False
