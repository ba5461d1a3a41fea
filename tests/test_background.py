"""The background writer (mdsr_opt.core.background): figure jobs in forked children beside the solves.

Every test states what it expects both where this machine may fork (Linux, two or more cores, one thread)
and where it may not (the jobs then run in this process): nothing is skipped.
"""

from __future__ import annotations

import os
import threading
import time
from pathlib import Path

import pytest

from mdsr_opt.body.io import atomic_path
from mdsr_opt.core.background import BackgroundWriter, fork_is_safe



@pytest.fixture
def forks():
    """Whether jobs fork in this test (a stray thread left by an earlier test would keep them here)."""
    return fork_is_safe()


def _pid(*_):
    return os.getpid()


def test_jobs_run_in_a_child_where_fork_is_safe_and_report_back(tmp_path, forks):
    got = []
    with BackgroundWriter() as bg:
        assert bg.background == forks
        bg.submit(_pid, on_done=got.append)
        bg.submit(lambda p: Path(p).write_text("x") and str(p), tmp_path / "a.txt", on_done=got.append)
    assert len(got) == 2
    assert (got[0] != os.getpid()) == forks  # the job ran elsewhere exactly when a fork was safe
    assert got[1] == str(tmp_path / "a.txt") and (tmp_path / "a.txt").read_text() == "x"


def _spin(seconds):
    t0 = time.process_time()
    while time.process_time() - t0 < seconds:
        pass
    return seconds


def test_each_collected_child_reports_its_cpu_time(forks):
    import functools

    with BackgroundWriter() as bg:
        bg.submit(_spin, 0.2)
        bg.submit(functools.partial(_pid, 1))
    if not forks:  # jobs ran here: no child to account for
        assert bg.job_cpu == []
        return
    cpu = dict(bg.job_cpu)
    assert sorted(cpu) == ["_pid", "_spin"]  # a partial goes by its function's name
    assert 0.2 <= cpu["_spin"] < 2.0 and cpu["_pid"] < cpu["_spin"]  # each child's own CPU, from the kernel


def _nap(seconds, name):
    time.sleep(seconds)
    return name


def test_a_finished_job_frees_its_place_before_an_older_running_one(forks):
    # two places: the third job starts when the short second one is done, not after the long first one
    done = []
    with BackgroundWriter(jobs=2) as bg:
        bg.submit(_nap, 1.5, "long", on_done=done.append)
        bg.submit(_nap, 0.0, "short", on_done=done.append)
        bg.submit(_nap, 0.0, "third", on_done=done.append)
    # in submission order where jobs run here (no fork), and where the oldest was always awaited first
    assert done == (["short", "third", "long"] if forks else ["long", "short", "third"])


def _late_file(path, seconds):
    time.sleep(seconds)
    Path(path).write_text("late")
    return str(path)


def _fail_now():
    raise RuntimeError("this job failed")


def test_a_failed_job_at_the_blocks_end_stops_the_other_children(tmp_path, forks):
    # the failure is raised while the with-block's end waits: the job still running is interrupted, not left
    # writing after the caller has been told the work failed
    with pytest.raises(RuntimeError, match="this job failed"):
        with BackgroundWriter() as bg:
            bg.submit(_late_file, tmp_path / "late.txt", 1.5)
            bg.submit(_fail_now)
    time.sleep(2.0)
    assert (tmp_path / "late.txt").exists() == (not forks)  # here (no fork) the first job ran to its end


def test_disabled_writer_runs_each_job_at_once_in_this_process():
    got = []
    bg = BackgroundWriter(enabled=False)
    bg.submit(_pid, on_done=got.append)
    assert got == [os.getpid()] and not bg.background  # done before submit returned


def test_a_second_thread_keeps_jobs_in_this_process():
    stop = threading.Event()
    t = threading.Thread(target=stop.wait)
    t.start()
    try:
        assert not fork_is_safe()
        got = []
        with BackgroundWriter() as bg:
            bg.submit(_pid, on_done=got.append)
        assert got == [os.getpid()]
    finally:
        stop.set()
        t.join()


def _fail():
    raise ValueError("the figure could not be drawn")


def test_a_failing_job_raises_its_own_exception_with_the_childs_traceback(forks):
    with pytest.raises(ValueError, match="could not be drawn") as info:
        with BackgroundWriter() as bg:
            bg.submit(_fail)
    if forks:
        notes = "\n".join(getattr(info.value, "__notes__", []))
        assert "in the background job _fail" in notes and "test_background.py" in notes


def test_an_unpicklable_result_and_a_dead_child_are_reported_not_lost(forks):
    if not forks:  # in this process the result needs no pickling and nothing can die apart
        got = []
        with BackgroundWriter() as bg:
            bg.submit(lambda: threading.Lock(), on_done=got.append)
        assert len(got) == 1
        return
    with pytest.raises(RuntimeError, match="unpicklable result"):
        with BackgroundWriter() as bg:
            bg.submit(lambda: threading.Lock())
    with pytest.raises(RuntimeError, match=r"ended without a result \(exit status 3\)"):
        with BackgroundWriter() as bg:
            bg.submit(os._exit, 3)


def _slow(path, seconds):
    with atomic_path(path) as tmp:
        Path(tmp).write_text("partial")
        time.sleep(seconds)
    return (time.monotonic(), str(path))


def test_leaving_by_an_exception_stops_the_children_and_leaves_no_temporaries(tmp_path):
    t0 = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        with BackgroundWriter(grace=5.0) as bg:
            bg.submit(_slow, tmp_path / "late.txt", 30.0)
            time.sleep(0.3)  # the child is inside its atomic write
            raise KeyboardInterrupt
    assert time.monotonic() - t0 < 10.0  # not the job's 30 s
    assert list(tmp_path.iterdir()) == []  # no file, no .tmp-* left by the interrupted child


def _interval(seconds):
    t = time.monotonic()
    time.sleep(seconds)
    return (t, time.monotonic())


def test_at_most_jobs_children_run_at_once_and_prepare_runs_once_here(forks):
    prepared, spans = [], []
    with BackgroundWriter(jobs=2, prepare=lambda: prepared.append(os.getpid())) as bg:
        for _ in range(4):
            bg.submit(_interval, 0.3, on_done=spans.append)
    assert prepared == ([os.getpid()] if forks else [])  # in the parent, before the first fork only
    assert len(spans) == 4
    for t in (s for s, _ in spans):  # no moment covered by three jobs
        assert sum(a <= t < b for a, b in spans) <= 2
    if forks:  # two at a time: four 0.3 s jobs in about 0.6 s, not 1.2 s
        assert max(b for _, b in spans) - min(a for a, _ in spans) < 1.1


@pytest.mark.parametrize("jobs", [0, -1, 1.5, True, "2"])
def test_bad_job_counts_are_refused(jobs):
    with pytest.raises(ValueError, match="jobs must be a positive integer"):
        BackgroundWriter(jobs=jobs)


def test_a_child_dies_with_its_parent(tmp_path):
    """A run killed outright (SIGKILL) leaves no figure job writing on into its folder."""
    import signal
    import subprocess
    import sys

    script = tmp_path / "parent.py"
    script.write_text(
        "import os, sys, time\n"
        "from mdsr_opt.core.background import BackgroundWriter\n"
        "def job():\n"
        "    print(os.getpid(), flush=True)\n"
        "    time.sleep(60)\n"
        "bg = BackgroundWriter()\n"
        "print('forks' if bg.background else 'inline', flush=True)\n"
        "bg.submit(job)\n")
    root = Path(__file__).resolve().parents[1]
    proc = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, text=True,
                            env=dict(os.environ, PYTHONPATH=str(root)))
    try:
        mode = proc.stdout.readline().strip()
        child = int(proc.stdout.readline())
        if mode == "inline":  # no fork here: the job is the parent itself
            assert child == proc.pid
        else:
            assert child != proc.pid
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
        t0 = time.monotonic()
        while time.monotonic() - t0 < 10:
            try:
                os.kill(child, 0)
            except ProcessLookupError:
                break
            time.sleep(0.05)
        else:
            raise AssertionError(f"the job's process {child} outlived its parent by 10 s")
    finally:
        proc.kill()


def _sleep_and_report(seconds):
    time.sleep(seconds)
    return os.getpid()


def test_a_child_does_not_keep_the_run_folders_lock(tmp_path, forks):
    """The lock of an output folder goes with the run's own process: once the run has let the folder go, a
    figure job it forked that is still running does not keep the next run out."""
    from mdsr_opt.scenes.rundir import RunFolder

    out = tmp_path / "out"
    bg = BackgroundWriter()
    with RunFolder(out) as folder:
        folder.begin([])
        bg.__enter__()
        bg.submit(_sleep_and_report, 1.0, on_done=lambda _: None)
    try:
        t0 = time.monotonic()
        with RunFolder(out, overwrite=True) as again:  # the job is still sleeping
            again.begin([])
        assert time.monotonic() - t0 < 0.5
    finally:
        bg.__exit__(None, None, None)


def test_a_drawn_progress_bar_starts_no_thread(forks):
    """`mdsr run` in a terminal draws a tqdm bar; tqdm's monitor thread would stop every fork."""
    import io

    from mdsr_opt.core.progress import Progress

    n = threading.active_count()
    with Progress(3, "run", enabled=True, stream=io.StringIO()) as log:
        log("a stage")
        assert threading.active_count() == n
        assert fork_is_safe() == forks
