"""Writing figures beside the solves: :class:`BackgroundWriter` runs write jobs in a forked child process.

``mdsr run`` alternates solves (CasADi and IPOPT, one core) with drawing and writing their results
(matplotlib, GIFs, meshes): half of a scene's time went to drawing while the second core stood idle. Threads
do not help (neither CasADi nor matplotlib's Agg lets go of the GIL: a figure job in a thread beside a solve
took as long as the two in a row). A forked child does: it starts with a copy of the parent's memory, so a
job needs no pickling of results or scenes (unless a server forks it: see below), draws on the second core
while the parent solves the next case, and sends back only the job's return value.

Rules that keep this safe and honest:

- **A job runs in the background only where a fork is safe and pays**: on Linux, with at least two cores
  available to this process, from the main thread with no other Python thread running (a thread holding a
  lock at the fork would leave the child waiting for ever). Native threads idle in OpenBLAS's pool are
  handled by OpenBLAS's own fork handlers. Anywhere else, and with ``enabled=False``, :meth:`submit` runs the
  job at once in this process: the same files, the same results, only later.
- **Jobs can start from a warm server** (``server=True``; :mod:`mdsr_opt.core.forkserver`): a process
  forked early does the ``prepare`` work (matplotlib's import and warm-up, about 1 s) on the second core
  while this process goes on with its own start (building the scene, the first solves), and forks each
  job, which it receives pickled (a scene and a case pickle in a few milliseconds; a mesh leaves its
  solver caches behind; the copies drew as fast as the originals). A job that does not pickle, or that the
  server's process cannot load, is forked from this process as before.
- **At most ``jobs`` children at a time**; a further :meth:`submit` first waits for one to finish (with a
  server, the job waits in the server instead, and this process goes on at once).
  The default, three, lets ``mdsr run`` hand over a case's two jobs while the previous case's photograph
  job still runs, so the parent goes on solving instead of waiting (``run_scene`` at medium resolution on
  two cores, the settings alternating in one process: gecko 3.70 s with three, 3.80 s with two, 4.6 s with
  one; humanoid 2.86, 3.05 and 4.1 s; medians of 8 runs, of 4 with one).
- **Nothing is lost or hidden.** :meth:`wait` collects every finished job: its ``on_done`` callback gets the
  job's return value; an exception in the child is raised again here (the child's traceback attached as a
  note). Leaving the ``with`` block waits for every job; leaving it by an exception (Ctrl-C included) first
  interrupts the children (SIGINT, so their atomic writes remove their temporary files), and a child that
  has not stopped after ``grace`` seconds is killed. A child dies with its parent (a run killed outright
  leaves no child writing into its folder; a server's child is interrupted when its server dies, which
  dies with the run); the run folder's lock goes with the run's own process (:mod:`mdsr_opt.scenes.rundir`).

Example
-------
>>> done = []
>>> with BackgroundWriter() as bg:
...     bg.submit(sum, [1, 2, 3], on_done=done.append)
>>> done
[6]
"""

from __future__ import annotations

import atexit
import contextlib
import gc
import os
import pickle
import select
import signal
import time
from dataclasses import dataclass, field
from typing import Any, Callable

from .forking import child_main, fork_is_safe, fork_quietly, read_all, reap, send_signal
from .forkserver import ForkServer, JobNotLoadable, shared_server

__all__ = ["BackgroundWriter", "fork_is_safe", "frozen_heap", "skip_final_collection"]


@contextlib.contextmanager
def frozen_heap():
    """Within the block, the objects alive at its start are left out of garbage collection (``gc.freeze``);
    at its end they are handed back to the collector (``gc.unfreeze``), so nothing is kept for ever.

    A run's long-lived objects (modules, the scene, caches: some 150,000 in ``mdsr run gecko``) made each
    full collection cost 0.1-0.25 s in the parent, and a forked child's collections would write to every
    one of them and so copy their memory pages. When the caller has frozen objects already (the ``mdsr``
    command freezes its imports), the objects made since join them, and the caller's unfreeze hands all
    back: freezing keeps nothing alive (reference counting still frees), it only spares the collections.
    """
    if gc.get_freeze_count():
        gc.freeze()
        yield
        return
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


def skip_final_collection() -> None:
    """When the interpreter exits, leave every object then alive out of its final garbage collections: an
    exit handler (``atexit``) that freezes the heap (``gc.freeze``). For a command's process.

    At exit the interpreter runs full collections while it tears its modules down, each walking every
    object a run has left (some 150,000 after ``mdsr run gecko``): 0.45-0.5 s of the command's wall time,
    against 0.08-0.09 s with the objects frozen (time from the command's return to the process's end,
    three alternating runs). Memory is the system's to reclaim at exit; every file the commands write is
    closed by then (atomic writes in ``with`` blocks). Nothing is frozen before the exit itself, so a
    process that goes on (a script run inside IPython, ``runpy``) collects its garbage as before.
    """
    atexit.register(gc.freeze)


@dataclass
class _Job:
    pid: int
    fd: int
    name: str
    on_done: Callable[[Any], None] | None
    chunks: list = field(default_factory=list)  # the child's answer as read so far
    served: tuple | None = None  # a ForkServer's job: (fn, args, kwargs), for a fork from here if need be
    ended: bool = False  # its pipe has been read to its end

    def served_pid(self) -> int:
        """A served job's child, once its pid has arrived (its answer's first 8 bytes; 0 before)."""
        head = b"".join(self.chunks)[:8]
        return int.from_bytes(head, "little") if len(head) == 8 else 0


class BackgroundWriter:
    """Run write jobs (figures, animations, files) in forked child processes, ``jobs`` at a time.

    Parameters
    ----------
    enabled : bool, default True
        Fork where it is safe (:func:`fork_is_safe`); ``False`` runs every job at once in this process.
    jobs : int, default 3
        Children running at once: forked from here, or by a server this writer starts (a shared server
        keeps to its own limit). At most ``4 * jobs`` jobs sent to a server are outstanding (running or
        waiting there); a further :meth:`submit` waits for one.
    grace : float, default 10
        Seconds an interrupted child gets to stop (and remove its temporary files) before it is killed.
    prepare : callable, optional
        Called once in this process before the first fork: work every job would otherwise repeat in its
        child and lose with it (imports, caches; for figures :func:`mdsr_opt.plot.common.warm_up`). With
        ``server`` it is the server's to call, beside this process's own work.
    server : bool, default False
        Fork the jobs from a :class:`~mdsr_opt.core.forkserver.ForkServer`: the one
        :func:`~mdsr_opt.core.forkserver.serving` has started (which then calls ``prepare`` too), or else
        one started now. A job that does not pickle, or that the server cannot load or start, is forked
        from this process (which then calls ``prepare`` first). :meth:`stop` kills the server (a shared
        one too: later writers with ``server=True`` start their own).

    Notes
    -----
    A job must not depend on anything the parent does after :meth:`submit` (the child sees the parent's
    memory as it was at the fork) and must report through its return value, which is pickled back (file
    names, small dicts); what it writes to disk is the point of it. ``background`` says whether jobs fork.
    A served job gets its arguments as they were at :meth:`submit` (pickled) and everything else (modules,
    their globals) as it was when the server started: a job must not depend on module state changed
    after that either.
    """

    def __init__(self, enabled: bool = True, grace: float = 10.0, prepare: Callable[[], Any] | None = None,
                 jobs: int = 3, server: bool = False):
        if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
            raise ValueError(f"jobs must be a positive integer, not {jobs!r}")
        self.jobs = jobs
        self.background = bool(enabled) and fork_is_safe()
        self.grace = float(grace)
        self._prepare = prepare
        self._jobs: list[_Job] = []
        self._server: ForkServer | None = None
        self._own_server = False
        if self.background and server:
            self._server = shared_server()
            if self._server is not None:
                if prepare is not None:
                    self._server.prepare(prepare)  # what this writer's jobs need beyond the server's warm-up
            else:
                self._server, self._own_server = ForkServer(prepare, jobs), True
        #: ``(job name, CPU seconds)`` of every child collected so far (user and system time of the forked
        #: process with the processes it waited for: from the kernel's accounting, or for a served job from
        #: the child's own, which it sends with its answer; NaN when it sent none): what the figure jobs
        #: cost beside the parent's own time
        self.job_cpu: list[tuple[str, float]] = []

    # -- the caller's side ------------------------------------------------------------------------------
    def submit(self, fn: Callable[..., Any], *args, on_done: Callable[[Any], None] | None = None,
               **kwargs) -> None:
        """Run ``fn(*args, **kwargs)``: in a forked child when :attr:`background` (after waiting for a child
        to finish when ``jobs`` are running; with a server, without waiting for a slot: the job waits there,
        unless ``4 * jobs`` are outstanding), otherwise here and now. ``on_done`` receives the return value
        (at :meth:`wait`, or a later :meth:`submit`, for a child's job)."""
        if not self.background or not fork_is_safe():  # a thread started since: no fork from here on
            result = fn(*args, **kwargs)
            if on_done is not None:
                on_done(result)
            return
        if self._server is not None and self._server.alive:
            # no waiting for a slot: the server starts its jobs as its own limit allows, and this process
            # goes on (with the next solves); what has ended by now is collected. At most 4 x jobs wait in
            # the server (its queue, and the descriptors it holds, stay small)
            self._collect_ended()
            self._wait_until(lambda: sum(job.served is not None for job in self._jobs) < 4 * self.jobs)
            # Ctrl-C is held back until the job is on the books (as for a fork): stop() must know of every
            # job the server may start
            mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
            try:
                fd = self._server.spawn(fn, args, kwargs)
                if fd is not None:
                    self._jobs.append(_Job(0, fd, _name_of(fn), on_done, served=(fn, args, kwargs)))
                    return
            finally:
                signal.pthread_sigmask(signal.SIG_SETMASK, mask)
        self._wait_until(self._own_slot_free)
        self._fork(fn, args, kwargs, on_done)

    def prepare(self, fn: Callable[[], Any]) -> bool:
        """Have the server this writer's jobs fork from call ``fn()`` in its own process, before it forks
        the jobs submitted after this: work those jobs share, done once there (a run's virtual prototype,
        say). True when sent; False (and nothing done) without a server, or when ``fn`` does not pickle:
        the jobs then do the work themselves. A failure in ``fn`` is ignored there."""
        if not self.background or self._server is None or not self._server.alive:
            return False
        return self._server.prepare(fn)

    def _own_slot_free(self) -> bool:
        """Fewer than ``jobs`` children of this process itself are running (a server's do not count)."""
        return sum(job.served is None for job in self._jobs) < self.jobs

    def _fork(self, fn, args, kwargs, on_done) -> None:
        """Fork a child of this process for the job (after ``prepare``, the first time)."""
        if self._prepare is not None:
            prepare, self._prepare = self._prepare, None
            prepare()
        r, w = os.pipe()
        parent = os.getpid()
        # Ctrl-C is held back from the fork until the child is on the books: an interrupt inside the fork's
        # own handlers (logging's, threading's) was printed as "Exception ignored" and lost, and one landing
        # before the job is recorded would leave a child that stop() cannot reach
        mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            pid = fork_quietly()
            if pid == 0:  # pragma: no cover - the child (coverage does not follow it); never returns
                try:
                    os.close(r)
                    child_main(w, fn, args, kwargs, parent, mask)
                finally:
                    os._exit(1)  # child_main leaves by os._exit itself; this is for anything raised before it
            os.close(w)
            self._jobs.append(_Job(pid, r, _name_of(fn), on_done))
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)  # a Ctrl-C held back arrives here

    def _collect_ended(self) -> None:
        """Collect the jobs whose children have ended, without waiting for any (read what is there)."""
        while self._read_ready(0):
            pass
        while done := [i for i, job in enumerate(self._jobs) if job.ended]:
            self._finish(done[0])

    def _wait_until(self, ready: Callable[[], bool]) -> None:
        """Collect jobs as they end until ``ready()``."""
        while not ready():
            self._finish(self._first_done())

    def wait(self, limit: int = 0) -> None:
        """Wait until at most ``limit`` jobs are running; collect the finished ones (their ``on_done``
        callbacks, and the first failure raised again with the child's traceback as a note).

        Jobs are collected as they finish, the oldest first among those done: a short job submitted after a
        long one frees its place at once (collected in submission order, a finished job waited behind a
        running one, and the parent with it)."""
        while len(self._jobs) > limit:
            self._finish(self._first_done())

    def _finish(self, i: int) -> None:
        """Collect the ended job ``i``: its ``on_done`` gets its value, its failure is raised; a served job
        that was never started, or that the server's process could not load, is forked from here."""
        job = self._jobs.pop(i)
        status, value = self._collect(job, i)
        if status == "interrupted":  # the server dropped it at a Ctrl-C (which a solver may have swallowed)
            raise KeyboardInterrupt(f"the background job {job.name} was dropped by an interrupt")
        if status == "not started" or (status == "error" and isinstance(value, JobNotLoadable)):
            if status == "not started":  # the server died or could not fork: it may take no more jobs
                self._server.check()
            fn, args, kwargs = job.served
            self._wait_until(self._own_slot_free)
            self._fork(fn, args, kwargs, job.on_done)
            return
        if status == "error":
            raise value
        if job.on_done is not None:
            job.on_done(value)

    def __enter__(self) -> "BackgroundWriter":
        return self

    def __exit__(self, exc_type, exc, tb):
        try:
            if exc_type is None:
                try:
                    self.wait(0)
                except BaseException:  # a job's failure or Ctrl-C while waiting: the other children stop too
                    self.stop()
                    raise
            else:
                self.stop()
        finally:
            if self._own_server:
                self._server.close()  # every job it forked has been collected or stopped
        return False

    def stop(self) -> None:
        """Interrupt every running child (SIGINT), wait ``grace`` seconds for it, then kill it; their
        results are dropped."""
        jobs, self._jobs = self._jobs, []
        if self._server is not None and any(job.served is not None for job in jobs):
            # no job it still holds starts now, and those it forked are interrupted (their death signal)
            self._server.kill()
        for job in jobs:
            if job.served is None:
                send_signal(job.pid, signal.SIGINT)
        deadline = time.monotonic() + self.grace
        for job in jobs:
            if job.served is not None:
                _drain(job, deadline)
            else:
                while reap(job.pid, block=False) is None:
                    if time.monotonic() > deadline:
                        send_signal(job.pid, signal.SIGKILL)
                        reap(job.pid, block=True)
                        break
                    time.sleep(0.01)
            os.close(job.fd)

    # -- internals --------------------------------------------------------------------------------------
    def _first_done(self) -> int:
        """Index of the oldest job whose child has answered to the end (its pipe closed), waiting until one
        has; what the children send meanwhile is read into their jobs (a served child sends its pid first,
        and an answer larger than the pipe's buffer comes in parts)."""
        while True:
            done = [i for i, job in enumerate(self._jobs) if job.ended]
            if done:
                return done[0]
            self._read_ready(None)

    def _read_ready(self, timeout_ms: int | None) -> bool:
        """Read what the running children have sent (waiting up to ``timeout_ms``; None: until one has);
        whether anything was read."""
        poll = select.poll()  # not select.select: it refuses descriptors from 1024 on
        for job in self._jobs:
            if not job.ended:
                poll.register(job.fd, select.POLLIN | select.POLLHUP | select.POLLERR)
        ready = {fd for fd, _ in poll.poll(timeout_ms)}
        for job in self._jobs:
            if job.fd in ready:
                chunk = os.read(job.fd, 1 << 16)
                if chunk:
                    job.chunks.append(chunk)
                else:
                    job.ended = True
        return bool(ready)

    def _collect(self, job: _Job, index: int = 0) -> tuple[str, Any]:
        try:
            read_all(job.fd, job.chunks)
        except BaseException:  # Ctrl-C while waiting: the child is still ours to stop, its answer kept so far
            self._jobs.insert(index, job)
            raise
        data = b"".join(job.chunks)
        os.close(job.fd)
        if job.served is not None:  # a server's child: its pid first, its own CPU time in its answer
            if len(data) < 8:  # no child ever started it (the server died, or could not fork)
                return "not started", None
            job.pid = job.served_pid()
            if not job.pid:  # pid 0: the server dropped it, at a Ctrl-C
                return "interrupted", None
            data, cpu = data[8:], float("nan")
            code = "unknown: a child of the jobs' server"
        else:
            code, cpu = reap(job.pid, block=True)
        try:
            status, value, text, own_cpu = pickle.loads(data)
        except Exception:  # noqa: BLE001 - no answer: the child died before it could send one
            self.job_cpu.append((job.name, cpu))
            return "error", RuntimeError(f"the background job {job.name} (pid {job.pid}) ended without a "
                                         f"result (exit status {code})")
        self.job_cpu.append((job.name, own_cpu if job.served is not None else cpu))
        if status == "error" and text and hasattr(value, "add_note"):
            value.add_note(f"in the background job {job.name} (pid {job.pid}):\n{text.rstrip()}")
        return status, value


def _drain(job: _Job, deadline: float, after_kill: float = 5.0) -> None:
    """Read a stopped served job's pipe to its end (its child has exited, or was never forked), killing the
    child once ``deadline`` has passed; gives up ``after_kill`` seconds later (a child whose pid never
    came cannot be killed from here, nor waited for without end)."""
    poll = select.poll()
    poll.register(job.fd, select.POLLIN | select.POLLHUP | select.POLLERR)
    killed = False
    while True:
        wait_ms = max(0, int(1000 * ((deadline + (after_kill if killed else 0.0)) - time.monotonic())))
        if poll.poll(wait_ms):
            chunk = os.read(job.fd, 1 << 16)
            if not chunk:
                return
            job.chunks.append(chunk)
        elif not killed:
            pid = job.served_pid()
            if pid:
                send_signal(pid, signal.SIGKILL)
            killed = True
        else:
            return


def _name_of(fn) -> str:
    """A job's name in messages and :attr:`BackgroundWriter.job_cpu`: the function's (a partial's too)."""
    while not hasattr(fn, "__name__") and hasattr(fn, "func"):  # functools.partial
        fn = fn.func
    return getattr(fn, "__name__", "job")


