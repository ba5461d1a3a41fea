"""Write jobs beside the solves (mdsr_opt.core.jobs): a standard process pool, or each job here and now."""

from __future__ import annotations

import multiprocessing
import os
import signal
import subprocess
import sys
import time
import types
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import pytest

from mdsr_opt.core.jobs import Jobs, available_cores, process_pool, start_method, worker_environment


@pytest.fixture(scope="module")
def pool():
    """One worker (so that jobs queue behind each other), started as process_pool starts them."""
    from mdsr_opt.core.jobs import _start_worker

    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context(start_method()), initializer=_start_worker,
                             initargs=(worker_environment(), ())) as p:
        yield p


def _pid_and(value):
    return os.getpid(), value


def _fail(message):
    raise ValueError(message)


def _touch_after(path, seconds):
    time.sleep(seconds)
    Path(path).write_text("done")
    return str(path)


def _seen_by_worker():
    import matplotlib

    return {k: os.environ.get(k) for k in ("OPENBLAS_NUM_THREADS", "MPLBACKEND")} | {
        "backend": matplotlib.get_backend().lower()}


def test_without_a_pool_each_job_runs_here_and_now():
    done = []
    with Jobs() as jobs:
        assert not jobs.parallel
        jobs.submit(_pid_and, 3, on_done=done.append)
        assert done == [(os.getpid(), 3)]  # at once, in this process
        with pytest.raises(ValueError, match="broke here"):
            jobs.submit(_fail, "broke here")
        jobs.submit(lambda: 1, on_done=done.append)  # nothing is pickled here
    assert done[-1] == 1


def test_jobs_run_in_a_worker_and_report_in_the_order_they_were_sent(pool):
    done = []
    with Jobs(pool) as jobs:
        assert jobs.parallel
        for k in range(5):
            jobs.submit(_pid_and, k, on_done=done.append)
    assert [v for _, v in done] == list(range(5))
    assert {pid for pid, _ in done} != {os.getpid()} and len({pid for pid, _ in done}) == 1


def test_a_job_gets_its_arguments_as_they_were_when_it_was_sent(pool):
    done, arg = [], [1, 2]
    with Jobs(pool) as jobs:
        jobs.submit(_touch_after, os.devnull, 0.3)  # the next job waits behind this one
        jobs.submit(_pid_and, arg, on_done=done.append)
        arg.append(3)
    assert done[0][1] == [1, 2]


def _started_at(name, seconds=0.0):
    start = time.time()
    time.sleep(seconds)
    return name, start


def _started(pool) -> None:
    """Wait until ``pool``'s workers are started (a job sent through its queue has run)."""
    with Jobs(pool) as jobs:
        jobs.submit(os.getpid)


def test_a_free_worker_takes_the_costliest_job_waiting_and_reports_keep_the_order_sent():
    # one worker: the first job holds it while the others wait in the queue; then the costliest starts
    # first (ties: the first sent), whatever order they were sent in; on_done still sees the order sent
    done = []
    with process_pool(1) as one:
        if one is None:
            pytest.skip("a single core: no pool (each job runs at once, in order)")
        _started(one)
        with Jobs(one) as jobs:
            jobs.submit(_started_at, "first", 0.5, on_done=done.append)
            for name, cost in (("cheap", 1.0), ("dear", 9.0), ("middle", 3.0), ("middle too", 3.0)):
                jobs.submit(_started_at, name, cost=cost, on_done=done.append)
    assert [n for n, _ in done] == ["first", "cheap", "dear", "middle", "middle too"]
    assert [n for n, _ in sorted(done, key=lambda d: d[1])] == ["first", "dear", "middle", "middle too", "cheap"]


def test_jobs_sharing_a_pool_share_its_queue():
    # two runs' Jobs on one pool of one worker: the costliest waiting job of either starts first
    done = []
    with process_pool(1) as one:
        if one is None:
            pytest.skip("a single core: no pool")
        _started(one)
        with Jobs(one) as a, Jobs(one) as b:
            a.submit(_started_at, "a first", 0.5, on_done=done.append)
            a.submit(_started_at, "a cheap", cost=1.0, on_done=done.append)
            b.submit(_started_at, "b dear", cost=5.0, on_done=done.append)
    assert [n for n, _ in sorted(done, key=lambda d: d[1])] == ["a first", "b dear", "a cheap"]


def test_jobs_sent_while_the_workers_start_wait_in_the_queue_and_start_costliest_first(monkeypatch):
    # the caller goes on while the pool starts its workers: its jobs wait in the queue meanwhile (none is
    # sent to the executor, which would make the caller wait for the workers), then start costliest first
    import threading

    from mdsr_opt.core import jobs as jobs_module

    go, start = threading.Event(), jobs_module._start_workers
    monkeypatch.setattr(jobs_module, "_start_workers", lambda *a: (go.wait(30), start(*a)))  # slow to start
    done = []
    with process_pool(1) as one:
        if one is None:
            pytest.skip("a single core: no pool")
        with Jobs(one) as jobs:
            for name, cost in (("cheap", 1.0), ("dear", 9.0), ("middle", 3.0)):
                jobs.submit(_started_at, name, cost=cost, on_done=done.append)
            assert not any(f.running() or f.done() for f, _ in jobs._pending)  # still starting: all queued
            go.set()
    assert [n for n, _ in done] == ["cheap", "dear", "middle"]  # reported in the order sent
    assert [n for n, _ in sorted(done, key=lambda d: d[1])] == ["dear", "middle", "cheap"]


def test_a_pools_queue_does_not_keep_the_pool_alive():
    import gc
    import weakref

    with process_pool(1) as one:
        if one is None:
            pytest.skip("a single core: no pool")
        with Jobs(one) as jobs:
            jobs.submit(os.getpid, cost=1.0)
        ref = weakref.ref(one)
        del jobs
    del one
    gc.collect()
    assert ref() is None


def test_a_failed_job_raises_its_own_error_with_the_workers_traceback(pool):
    with pytest.raises(ValueError, match="the writer broke") as info:
        with Jobs(pool) as jobs:
            jobs.submit(_fail, "the writer broke")
    assert "_fail" in str(info.value.__cause__)  # the worker's traceback


def test_a_job_that_cannot_be_sent_is_refused_at_once(pool):
    with Jobs(pool) as jobs:
        with pytest.raises(TypeError, match="cannot be sent to a worker process .*module-level function"):
            jobs.submit(lambda: 1)
        with pytest.raises(TypeError, match="'_pid_and' cannot be sent"):
            jobs.submit(_pid_and, (x for x in ()))  # a generator does not pickle


def test_leaving_by_an_error_cancels_the_jobs_not_started(pool, tmp_path):
    with pytest.raises(KeyboardInterrupt):
        with Jobs(pool) as jobs:
            jobs.submit(_touch_after, tmp_path / "first", 0.5)
            for k in range(6):
                jobs.submit(_touch_after, tmp_path / f"later{k}", 0.0)
            time.sleep(0.2)  # the first job runs
            raise KeyboardInterrupt
    # the running job finished before the block was left, and so did those the pool had already put in its
    # workers' queue (concurrent.futures counts them as running: at most one more than there are workers);
    # the others never started
    written = sorted(p.name for p in tmp_path.iterdir())
    assert written in (["first"], ["first", "later0"], ["first", "later0", "later1"])
    time.sleep(0.3)
    assert sorted(p.name for p in tmp_path.iterdir()) == written


@pytest.mark.parametrize("asked", [None, "3"])
def test_workers_run_with_one_blas_thread_and_agg_unless_asked(monkeypatch, asked):
    if asked is None:
        monkeypatch.delenv("OPENBLAS_NUM_THREADS", raising=False)
    else:
        monkeypatch.setenv("OPENBLAS_NUM_THREADS", asked)
    monkeypatch.setenv("MPLBACKEND", "svg")  # this process's choice is not the workers'
    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as plain:
        from mdsr_opt.core.jobs import _start_worker

        plain.submit(_start_worker, worker_environment(), ()).result()  # as process_pool's initializer does
        seen = plain.submit(_seen_by_worker).result()
    assert seen == {"OPENBLAS_NUM_THREADS": asked or "1", "MPLBACKEND": "Agg", "backend": "agg"}


def test_process_pool_has_workers_only_where_they_pay():
    with process_pool(0) as none:
        assert none is None
    with process_pool(2) as pool:
        assert (pool is None) is (available_cores() < 2)
        if pool is not None:
            assert pool.submit(os.getpid).result() != os.getpid()
    for bad, kind, words in ((-1, ValueError, "workers must be an integer >= 0, got -1"),
                             (True, TypeError, "workers must be an integer, got bool"),
                             (1.5, TypeError, "workers must be an integer, got float")):
        with pytest.raises(kind, match=words):
            with process_pool(bad):
                pass
    assert start_method() in multiprocessing.get_all_start_methods()


def test_the_forkserver_preloads_this_package_only_where_it_would_import_this_copy(tmp_path, monkeypatch):
    # the server starts in the working folder: the checkout holding this copy gives this copy; a folder
    # holding another copy of the package gives that one (never preloaded); a folder holding none leaves the
    # search to the site folders (this copy preloaded only when installed there)
    import site

    import mdsr_opt
    from mdsr_opt.core.jobs import server_imports_this_package

    root = Path(mdsr_opt.__file__).resolve().parents[1]
    monkeypatch.chdir(root)
    assert server_imports_this_package()
    (tmp_path / "other" / "mdsr_opt").mkdir(parents=True)
    (tmp_path / "other" / "mdsr_opt" / "__init__.py").write_text("")
    monkeypatch.chdir(tmp_path / "other")
    assert not server_imports_this_package()
    monkeypatch.chdir(tmp_path)
    installed = str(root) in {os.path.realpath(f) for f in site.getsitepackages() + [site.getusersitepackages()]}
    assert server_imports_this_package() is installed
    # Python 3.10's sys.flags has no safe_path (the package supports 3.10): the working folder is searched
    flags = types.SimpleNamespace(**{k: getattr(sys.flags, k) for k in dir(sys.flags)
                                     if not k.startswith("_") and k != "safe_path"})
    monkeypatch.setattr(sys, "flags", flags)
    monkeypatch.chdir(root)
    assert server_imports_this_package()


_KILLED = """
import multiprocessing, os, time
from concurrent.futures import ProcessPoolExecutor
from mdsr_opt.core.jobs import _start_worker, start_method, worker_environment
pool = ProcessPoolExecutor(2, mp_context=multiprocessing.get_context(start_method()), initializer=_start_worker,
                           initargs=(worker_environment(), ()))
busy = pool.submit(time.sleep, 30)  # one worker in a job
idle = pool.submit(os.getpid).result()  # the other done with its job
print(idle, *[p.pid for p in multiprocessing.active_children()], flush=True)
time.sleep(60)
"""


def _exists(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


@pytest.mark.skipif(sys.platform == "win32", reason="looks processes up with os.kill(pid, 0)")
def test_a_process_killed_outright_leaves_no_worker_behind():
    """The process that made the pool dies without shutting it down (SIGKILL): its workers, the busy one and
    the idle one, end within seconds instead of waiting for jobs for ever."""
    proc = subprocess.Popen([sys.executable, "-c", _KILLED], stdout=subprocess.PIPE, text=True,
                            cwd=Path(__file__).resolve().parents[1])
    try:
        idle, *pids = [int(p) for p in proc.stdout.readline().split()]
    finally:
        proc.kill()
        proc.wait()
    assert len(pids) == 2 and idle in pids and proc.pid not in pids
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and any(map(_exists, pids)):
        time.sleep(0.05)
    assert [p for p in pids if _exists(p)] == []


def _niceness():
    return os.nice(0)


@pytest.mark.skipif(not hasattr(os, "nice"), reason="process priorities are POSIX's (Windows: normal priority)")
def test_workers_keep_the_priority_of_the_process_that_waits_for_them(pool):
    # a lowered priority starves the jobs (and the run waiting for them) on a machine other processes share
    assert pool.submit(_niceness).result(timeout=60) == os.nice(0)


def test_run_scene_from_a_plain_script_without_a_main_guard_runs_once(tmp_path):
    """Pool workers ('spawn'/'forkserver') run a plain script again as they start; run_scene called from an
    unguarded script therefore keeps its jobs in this process (the README's code blocks are such scripts),
    and the script's own lines run once."""
    script = tmp_path / "design.py"
    script.write_text(
        "from mdsr_opt import get_problem, run_scene\n"
        "from mdsr_opt.core.jobs import main_is_plain_script\n"
        "print('START', main_is_plain_script(), flush=True)\n"
        "scene = get_problem('one_muscle', resolution='coarse')\n"
        "report = run_scene(scene, 'out', cases=['a30'], photos=False, animations=False, log=None)\n"
        "print('DONE', report.success, flush=True)\n")
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]), OPENBLAS_NUM_THREADS="1")
    proc = subprocess.run([sys.executable, str(script)], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.count("START") == 1 and "START True" in proc.stdout
    assert "DONE True" in proc.stdout and (tmp_path / "out" / "a30" / "design.png").is_file()



def _import_broken_by(interrupt: bool):
    """What an extension module's import raises when Ctrl-C arrives during its initialisation."""
    try:
        raise KeyboardInterrupt if interrupt else OSError("no such library")
    except BaseException as exc:
        raise ImportError("initialization failed") from exc


_BROKEN_START = """
import multiprocessing, sys
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from mdsr_opt.core.jobs import _start_worker, start_method, worker_environment
sys.path.insert(0, {tests!r})
from test_jobs import _import_broken_by
if __name__ == "__main__":
    pool = ProcessPoolExecutor(1, mp_context=multiprocessing.get_context(start_method()), initializer=_start_worker,
                               initargs=(worker_environment(), (), (_import_broken_by, ({interrupt},))))
    try:
        pool.submit(sum, [1]).result(timeout=60)
    except BrokenProcessPool:
        print("broken")
"""


@pytest.mark.parametrize("interrupt", [True, False])
def test_a_worker_whose_start_ctrl_c_broke_ends_quietly_other_errors_are_reported(tmp_path, interrupt):
    """Ctrl-C while a worker imports a C extension surfaces as that import's ImportError (caused by the
    KeyboardInterrupt): the worker ends without the pool's traceback; an ImportError of its own is reported."""
    script = tmp_path / "start.py"
    script.write_text(_BROKEN_START.format(tests=str(Path(__file__).parent), interrupt=interrupt))
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120,
                          cwd=Path(__file__).resolve().parents[1])
    assert done.stdout.strip() == "broken"
    assert ("Exception in initializer" in done.stderr) is (not interrupt), done.stderr[-2000:]


_BUSY_POOL = """
import multiprocessing, os, time
from mdsr_opt.core.jobs import Jobs, process_pool
if __name__ == "__main__":
    with process_pool(2) as pool, Jobs(pool) as jobs:
        for _ in range(12):
            jobs.submit(time.sleep, 30)  # two running, ten waiting
        time.sleep(1.0)
        print(*[p.pid for p in multiprocessing.active_children()], flush=True)
        time.sleep(60)
"""


@pytest.mark.skipif(sys.platform == "win32", reason="signals a process group")
def test_ctrl_c_to_the_whole_group_stops_a_busy_pool_at_once():
    """A terminal's Ctrl-C reaches the workers too, with jobs running and jobs waiting: the process stops
    within seconds (the workers are ended, not waited for; no job is cancelled under a breaking pool, which
    stopped the pool's manager thread with InvalidStateError and hung the shutdown), and no worker is left."""
    proc = subprocess.Popen([sys.executable, "-c", _BUSY_POOL], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, cwd=Path(__file__).resolve().parents[1], start_new_session=True)
    try:
        pids = [int(p) for p in proc.stdout.readline().split()]
        t0 = time.monotonic()
        os.killpg(proc.pid, signal.SIGINT)
        proc.wait(timeout=20)
        elapsed = time.monotonic() - t0
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    err = proc.stderr.read()
    assert len(pids) == 2 and elapsed < 10 and "KeyboardInterrupt" in err, err[-2000:]
    assert "InvalidStateError" not in err and "Exception in thread" not in err, err[-2000:]
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and any(map(_exists, pids)):
        time.sleep(0.05)
    assert [p for p in pids if _exists(p)] == []


def test_a_block_left_by_an_error_while_its_workers_start_starts_no_more_of_them(monkeypatch):
    """Bad input found while the pool starts its workers (``mdsr run`` of a scene file it refuses) ends the
    block at once: the worker being started is the last one, and every worker is ended before the block is
    left. A worker started after the others were ended is one that the broken pool's shutdown waits for,
    for ever, while it waits for a job (the run, and the interpreter's exit, hung)."""
    from concurrent.futures import process as cfp

    spawned = []
    real = cfp.ProcessPoolExecutor._spawn_process

    def slow_spawn(self):  # a forkserver still importing its preloaded modules
        time.sleep(0.3)
        real(self)
        spawned.append(time.monotonic())

    monkeypatch.setattr(cfp.ProcessPoolExecutor, "_spawn_process", slow_spawn)
    before = set(multiprocessing.active_children())  # other tests' pools
    with pytest.raises(ValueError, match="bad input"):
        with process_pool(2) as two:
            if two is None:
                pytest.skip("a single core: no pool")
            time.sleep(0.1)  # the first worker is being started
            raise ValueError("bad input")
    left = time.monotonic()
    assert len(spawned) == 1 and spawned[0] <= left
    assert set(multiprocessing.active_children()) <= before


_REFUSED_RUNS = """
import contextlib, io, json, pathlib, sys, tempfile
from mdsr_opt.cli.main import main
if __name__ == "__main__":
    scene = json.loads(pathlib.Path(sys.argv[1]).read_text())
    scene.setdefault("design", {})["a_max"] = 1.5
    for i in range(int(sys.argv[2])):
        d = pathlib.Path(tempfile.mkdtemp())
        (d / "scene.json").write_text(json.dumps(scene))
        err = io.StringIO()
        with contextlib.redirect_stderr(err):
            code = main(["run", str(d / "scene.json"), "--out", str(d / "out")])
        print(code, len(err.getvalue().strip().splitlines()), (d / "out").exists(), flush=True)
"""


def test_mdsr_run_refuses_a_bad_scene_file_again_and_again_in_one_process(tmp_path):
    """``main`` of ``mdsr run`` called over and over in one process (as a test suite does), each time with a
    scene file it refuses while its pool starts: each call returns 2 with one line and no folder, at once."""
    import json

    tomllib = pytest.importorskip("tomllib")  # Python 3.11+ (the scene file is read by the package either way)
    base = tmp_path / "finger.json"
    base.write_text(json.dumps(tomllib.loads((Path(__file__).parent / "data" / "finger.toml").read_text())))
    n = 12
    done = subprocess.run([sys.executable, "-c", _REFUSED_RUNS, str(base), str(n)], capture_output=True,
                          text=True, timeout=120, cwd=Path(__file__).resolve().parents[1])
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.split("\n")[:n] == ["2 1 False"] * n, done.stdout + done.stderr[-2000:]
