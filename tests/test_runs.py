"""Runs of ``mdsr run``: interrupts, output folders (locks, stale files, crashed runs) and a bad ``--out``."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from mdsr_opt import scenes
from mdsr_opt.cli.main import main
from mdsr_opt.scenes.rundir import LOCK_NAME, MANIFEST_NAME, FolderBusy, OutputFolderError, RunFolder, check_out_path

ROOT = Path(__file__).resolve().parents[1]
FINGER = ROOT / "tests" / "data" / "finger.toml"
STRIP = {"name": "strip", "body": {"outline": [[0, 0], [4, 0], [4, 1], [0, 1]], "resolution": 60},
         "regions": {"base": {"box": [-1, -1, 0, 2]}, "end": {"box": [4, -1, 5, 2]}},
         "cases": [{"name": "bend", "anchors": "base", "drags": [{"nodes": "end", "by": [-0.8, 1.2]}]}]}


def _start(*args) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=str(ROOT), PYTHONUNBUFFERED="1")
    return subprocess.Popen([sys.executable, "-m", "mdsr_opt", "run", *map(str, args)], cwd=ROOT, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _wait_for_line(proc: subprocess.Popen, words: str, timeout: float = 60.0) -> list[str]:
    lines = []
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        line = proc.stdout.readline()
        if not line:
            break
        lines.append(line)
        if words in line:
            return lines
    proc.kill()
    raise AssertionError(f"no line with {words!r} from the run; got {lines}")


def _files(folder: Path) -> list[str]:
    return sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file())


# ---------------------------------------------------------------------------------------------- interrupts
def test_ctrl_c_stops_a_real_run_with_exit_130(tmp_path):
    out = tmp_path / "out"
    proc = _start(FINGER, "--out", out, "--resolution", "400")
    # after the first design: the run is rendering the photograph and writing figures now (an interrupt inside
    # an IPOPT solve is the solvers' part, tested with them; the swallowed case is the next test)
    _wait_for_line(proc, "[finger 1/2 bend] design")
    t0 = time.monotonic()
    proc.send_signal(signal.SIGINT)
    _stdout, err = proc.communicate(timeout=60)
    took = time.monotonic() - t0
    assert proc.returncode == 130
    assert took < 5.0, f"took {took:.1f} s to stop"
    assert err.strip().splitlines()[-1] == "mdsr run: interrupted (Ctrl-C); files already complete are kept"
    assert "Traceback" not in err
    files = _files(out)
    assert not [f for f in files if Path(f).name.startswith(".tmp-")]       # nothing partial
    assert "summary.json" not in files                                      # the case is not "failed"
    manifest = json.loads((out / MANIFEST_NAME).read_text())
    assert manifest["status"] == "interrupted"
    assert not (out / LOCK_NAME).exists()


def test_an_interrupt_swallowed_by_a_solver_still_stops_the_run(tmp_path, monkeypatch):
    """CasADi turns Ctrl-C inside IPOPT into a failed solve; the run must stop, not record a failed case."""
    from mdsr_opt.scenes import rundir

    real = scenes.prepare_case

    def swallowed(*a, **k):
        setup = real(*a, **k)
        rundir._INTERRUPTED.set()            # what the SIGINT handler does when the solver eats the exception
        return setup

    monkeypatch.setattr("mdsr_opt.scenes.runner.prepare_case", swallowed)
    out = tmp_path / "out"
    with rundir.noting_interrupts():
        assert main(["run", str(FINGER), "--out", str(out), "--resolution", "coarse", "--no-figures"]) == 130
    assert json.loads((out / MANIFEST_NAME).read_text())["status"] == "interrupted"
    assert not (out / "summary.json").exists()


def test_keyboard_interrupt_is_not_caught_as_a_case_failure(tmp_path, monkeypatch):
    def boom(*a, **k):
        raise KeyboardInterrupt

    scene = scenes.get_problem(str(FINGER), resolution="coarse")
    monkeypatch.setattr("mdsr_opt.synthesis.contractions.design_contractions", boom)
    with pytest.raises(KeyboardInterrupt):
        scenes.run_case(scene, "bend", photo=False)


# ---------------------------------------------------------------------------------------------- folders
def test_two_concurrent_runs_cannot_mix_and_a_crashed_run_leaves_no_lock(tmp_path):
    out = tmp_path / "out"
    strip = tmp_path / "strip.json"
    strip.write_text(json.dumps(STRIP))
    first = _start(FINGER, "--out", out, "--resolution", "1200", "--overwrite")
    _wait_for_line(first, "target by external driving")
    second = _start(strip, "--out", out, "--overwrite", "--no-photos")
    _out2, err2 = second.communicate(timeout=60)
    assert second.returncode == 2
    assert f"another mdsr run is writing into this folder (pid {first.pid}" in err2
    assert "strip" not in (out / MANIFEST_NAME).read_text()
    first.send_signal(signal.SIGKILL)                  # a crash: the lock goes with the process
    first.wait(timeout=30)
    assert json.loads((out / MANIFEST_NAME).read_text())["status"] == "running"
    # the next run takes the folder over and replaces the crashed run's files completely
    assert main(["run", str(strip), "--out", str(out), "--overwrite", "--no-photos"]) == 0
    files = _files(out)
    assert all(f in (MANIFEST_NAME, "rest.png", "summary.json", "summary.md") or f.startswith("bend/")
               for f in files), files
    assert json.loads((out / "summary.json").read_text())["scene"] == "strip"
    assert json.loads((out / MANIFEST_NAME).read_text())["status"] == "complete"


def test_a_second_run_is_refused_without_overwrite_and_replaces_the_first_with_it(tmp_path, capsys):
    out = tmp_path / "out"
    strip = tmp_path / "strip.json"
    strip.write_text(json.dumps(STRIP))
    assert main(["run", str(strip), "--out", str(out), "--no-photos"]) == 0
    first = _files(out)
    assert main(["run", str(strip), "--out", str(out), "--no-photos"]) == 2
    err = capsys.readouterr().err
    assert f"--out {out} holds an earlier mdsr run (`mdsr run {strip}" in err
    assert "complete); pass --overwrite to replace it, or choose a new folder" in err
    assert _files(out) == first
    # a re-run whose case now fails leaves nothing of the earlier run beside its summary
    failing = dict(STRIP, material={"nu": 0.0},
                   cases=[{"name": "stretch", "anchors": "base", "drags": [{"nodes": "end", "by": [0.5, 0]}]}])
    strip.write_text(json.dumps(failing))
    capsys.readouterr()
    assert main(["run", str(strip), "--out", str(out), "--no-photos", "--overwrite"]) == 1
    assert not (out / "bend").exists()
    assert json.loads((out / "summary.json").read_text())["success"] is False


def test_refusal_message_and_foreign_files(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    assert main(["run", str(FINGER), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "already holds 1 entry ('notes.txt'); choose a new or empty folder" in err
    assert main(["run", str(FINGER), "--out", str(out), "--overwrite"]) == 2
    assert "holds 'notes.txt', which no earlier mdsr run wrote there" in capsys.readouterr().err
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt"]     # untouched, no lock left


def test_a_stale_lock_file_does_not_block(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / LOCK_NAME).write_text(json.dumps({"pid": 999999, "host": "gone"}))
    with RunFolder(out) as f:
        f.begin(["x"])
    assert not (out / LOCK_NAME).exists()


def test_a_held_lock_names_the_holder(tmp_path):
    with RunFolder(tmp_path / "out", command="mdsr run gecko") as f:
        with pytest.raises(FolderBusy, match=rf"another mdsr run is writing .*pid {os.getpid()}.*mdsr run gecko"):
            RunFolder(tmp_path / "out").__enter__()
        f.begin([])


@pytest.mark.parametrize("out, words", [
    ("", "--out is empty"),
    ("   ", "--out is empty"),
    ("FILE", "is an existing file, not a folder"),
    ("FILE/sub", "is a file, not a folder"),
])
def test_bad_out_is_one_line_before_any_work(tmp_path, capsys, monkeypatch, out, words):
    (tmp_path / "FILE").write_text("x")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr("mdsr_opt.cli.run.get_problem", lambda *a, **k: pytest.fail("work started"))
    monkeypatch.setattr("mdsr_opt.cli.run.process_pool", lambda *a, **k: pytest.fail("the workers' pool started"))
    assert main(["run", str(FINGER), "--out", out]) == 2
    err = capsys.readouterr().err
    assert words in err and len(err.strip().splitlines()) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["FILE"]


def test_unwritable_out(tmp_path, capsys, monkeypatch):
    locked = tmp_path / "ro"
    locked.mkdir()
    monkeypatch.setattr(os, "access", lambda p, mode: Path(p) != locked)   # as root, chmod would not bite
    with pytest.raises(OutputFolderError, match=r"cannot write into .*ro \(permission denied\)"):
        check_out_path(locked / "out")
    assert main(["run", str(FINGER), "--out", str(locked / "out")]) == 2
    assert "permission denied" in capsys.readouterr().err
    assert not (locked / "out").exists()


def test_os_errors_are_one_line(tmp_path, capsys, monkeypatch):
    def denied(*a, **k):
        raise PermissionError(13, "Permission denied", str(tmp_path / "x"))

    monkeypatch.setattr("mdsr_opt.cli.run.get_problem", denied)
    assert main(["run", str(FINGER), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.strip() == f"mdsr run: error: Permission denied: {tmp_path / 'x'}"
    assert not (tmp_path / "o").exists()                              # the folder it made is gone again


def test_problem_scripts_refuse_a_used_folder_and_take_overwrite(tmp_path, capsys):
    from mdsr_opt.scenes.library import load_problem_module
    from mdsr_opt.scenes.runscene import run_main

    build = load_problem_module(ROOT / "problems" / "gripper.py").build
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    assert run_main(build, ["--out", str(out), "--resolution", "coarse", "--overwrite"]) == 2
    assert "holds 'notes.txt', which no earlier mdsr run wrote there" in capsys.readouterr().err
    assert run_main(build, ["--out", str(tmp_path / "o2"), "--case", "nope"]) == 2
    assert "has no case 'nope'" in capsys.readouterr().err
    assert not (tmp_path / "o2").exists()


def test_several_scenes_write_tables_2_to_4_in_tables_md(tmp_path, capsys):
    """``mdsr run A B`` writes one folder per scene and ``tables.md`` with the paper's Tables 2-4 (external
    cases in Tables 2 and 4, internal ones in Table 3), a row per case of every scene."""
    finger = (Path(__file__).parent / "data" / "finger.toml").read_text()
    a, b = tmp_path / "finger.toml", tmp_path / "thumb.toml"
    a.write_text(finger)
    b.write_text(finger.replace('name = "finger"', 'name = "thumb"', 1))
    out = tmp_path / "out"
    code = main(["run", str(a), str(b), "--out", str(out), "--resolution", "coarse", "--no-figures",
                 "--no-animations", "--photo-size", "200x200", "--quiet"])
    assert code == 0, capsys.readouterr().err
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == ["finger", "tables.md", "thumb"]
    text = (out / "tables.md").read_text()
    sections = text.split("Table ")
    assert [s[0] for s in sections[1:]] == ["2", "3", "4"], text[:400]
    for scene in ("finger", "thumb"):  # finger: bend is external (Tables 2, 4), contract internal (Table 3)
        assert f"| {scene} | bend |" in sections[1] and f"| {scene} | bend |" in sections[3]
        assert f"| {scene} | contract |" in sections[2] and f"| {scene} | contract |" not in sections[1]


# ------------------------------------------------------------------------------------ figures beside solves
def _without_times(v):
    if isinstance(v, dict):
        return {k: _without_times(x) for k, x in v.items() if k not in ("time", "times", "out")}
    if isinstance(v, list):
        return [_without_times(x) for x in v]
    return v


def test_figures_drawn_beside_the_solves_are_the_files_of_a_serial_run(tmp_path):
    """``run_scene(background=True)`` (figure jobs in a pool of worker processes, where the machine has two
    cores) writes the same files, the same summary and the same file lists as the serial run; the gecko has
    cases, an animation and a gait, so every kind of job is in it."""
    from mdsr_opt.scenes.runscene import run_scene

    # on one core both runs are serial and this compares a run with itself; CI and the development
    # machines have two cores, where the pool runs the jobs
    scene = scenes.get_problem("gecko", resolution="coarse")
    reports = {bg: run_scene(scene, tmp_path / str(bg), log=None, background=bg, prototype=False)
               for bg in (True, False)}
    a, b = tmp_path / "True", tmp_path / "False"
    assert _files(a) == _files(b)
    assert {"bend_left/design.png", "rest.png", "gait.gif", "walk/schedule.png", "walk/walk.gif"} <= set(_files(a))
    assert [c.files for c in reports[True].cases] == [c.files for c in reports[False].cases]
    assert all(c.files for c in reports[True].cases)
    sa, sb = (json.loads((d / "summary.json").read_text()) for d in (a, b))
    assert _without_times(sa) == _without_times(sb)
    # in the same order too (an animation's entry is filled in when its job is done)
    assert json.dumps(_without_times(sa)) == json.dumps(_without_times(sb))
    assert list(sa["animations"]) == ["gait", "walk"]
    for name in ("bend_left/target.vtu", "walk/schedule.csv"):
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    la, lb = (json.loads((d / "walk" / "layout.json").read_text()) for d in (a, b))
    assert _without_times(la) == _without_times(lb)


def test_a_parallel_run_validates_against_the_prototype_as_a_serial_run(tmp_path):
    """The photograph jobs get the prototype pickled and solve its drivings in a worker: the validation
    tables and the summary are the serial run's."""
    from mdsr_opt.scenes.runscene import run_scene

    scene = scenes.get_problem("gecko", resolution="coarse")
    serial = run_scene(scene, tmp_path / "serial", cases=["bend_left"], log=None, background=False)
    parallel = run_scene(scene, tmp_path / "parallel", cases=["bend_left"], log=None)
    assert parallel.success and serial.success
    a, b = tmp_path / "parallel", tmp_path / "serial"
    assert (a / "validation.md").read_text() == (b / "validation.md").read_text()
    sa, sb = (json.loads((d / "summary.json").read_text()) for d in (a, b))
    assert json.dumps(_without_times(sa)) == json.dumps(_without_times(sb))
    assert sa["cases"][0]["photo"]["prototype"]["driving"]["success"]
    assert _files(a) == _files(b)


def test_a_pool_that_is_not_an_executor_is_refused_before_any_work(tmp_path):
    from mdsr_opt.scenes.runscene import write_scene

    scene = scenes.get_problem("one_muscle", resolution="coarse")
    with pytest.raises(TypeError, match="pool must be a concurrent.futures.Executor or None, got int"):
        write_scene(scene, tmp_path / "out", pool=2)
    assert not (tmp_path / "out").exists()


def _rest_and_pid(scene, path):
    """rest.png's job, which also leaves the id of its process next to the figure."""
    from mdsr_opt import plot

    Path(path).with_suffix(".pid").write_text(str(os.getpid()))
    return plot.save_figure(plot.plot_scene(scene.mesh, scene.regions), path, close=True)


@pytest.mark.parametrize("flags, parallel", [([], True), (["--serial"], False)])
def test_the_figures_are_drawn_in_workers_unless_serial(tmp_path, monkeypatch, flags, parallel):
    """`mdsr run` sends its figure jobs to a pool of worker processes (on two or more cores), shared by its
    scenes; `--serial` draws them in the command's own process. The files are there either way."""
    import mdsr_opt.cli.run as cli_run
    from mdsr_opt.core.jobs import available_cores
    from mdsr_opt.scenes import runscene

    seen = {}
    real = cli_run.write_scene

    def spy(*args, **kwargs):
        seen.update(kwargs)
        return real(*args, **kwargs)

    monkeypatch.setattr(cli_run, "write_scene", spy)
    monkeypatch.setattr(runscene, "_write_rest", _rest_and_pid)
    out = tmp_path / "o"
    assert main(["run", str(FINGER), "--out", str(out), "--resolution", "coarse", "--no-photos", *flags]) == 0
    pooled = parallel and available_cores() >= 2
    assert seen["background"] is pooled and (seen["pool"] is not None) is pooled
    assert (int((out / "rest.pid").read_text()) != os.getpid()) is pooled
    assert (out / "bend" / "target.png").is_file() and (out / "rest.png").is_file()


def _children(pid: int) -> list[int]:
    """The processes whose parent is ``pid`` (from /proc)."""
    out = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                stat = Path(f"/proc/{entry}/stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                out.append(int(entry))
    return out


def _descendants(pid: int) -> list[int]:
    """The processes below ``pid``: its children (the pool's server among them), theirs (the workers), ..."""
    out, todo = [], [pid]
    while todo:
        kids = _children(todo.pop())
        out += kids
        todo += kids
    return out


def _alive(pid: int) -> bool:
    try:
        return "zombie" not in Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="finds the run's processes in /proc")
def test_ctrl_c_in_the_terminal_stops_the_run_and_its_workers(tmp_path):
    """Ctrl-C in a terminal reaches the whole process group: the run and its worker processes. The run
    exits with 130 within seconds, its processes are gone, no temporary file stays, the manifest says so."""
    out = tmp_path / "out"
    env = dict(os.environ, PYTHONPATH=str(ROOT), PYTHONUNBUFFERED="1")
    proc = subprocess.Popen([sys.executable, "-m", "mdsr_opt", "run", "gecko", "--out", str(out)], cwd=ROOT,
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            start_new_session=True)
    try:
        t0, kids = time.monotonic(), []
        # until a worker runs: the pool's server (a child) has forked one (a grandchild)
        while time.monotonic() - t0 < 60 and not any(_children(k) for k in _children(proc.pid)) \
                and proc.poll() is None:
            time.sleep(0.02)
        kids = _descendants(proc.pid)
        assert len(kids) >= 2, f"no worker was started: {kids}"
        os.killpg(proc.pid, signal.SIGINT)
        assert proc.wait(timeout=30) == 130
    finally:
        if proc.poll() is None:
            proc.kill()
    assert "interrupted (Ctrl-C)" in proc.stdout.read()
    t0 = time.monotonic()
    while time.monotonic() - t0 < 10 and any(_alive(k) for k in kids):
        time.sleep(0.05)
    assert [k for k in kids if _alive(k)] == []
    assert [p.name for p in out.rglob(".tmp-*")] == []
    assert json.loads((out / MANIFEST_NAME).read_text())["status"] == "interrupted"


def test_an_animation_is_sent_as_soon_as_its_last_case_is_designed(tmp_path, monkeypatch):
    """The run's longest job (an animation's frames and GIF) goes out right after the design of the last
    case it shows, ahead of that case's own figure jobs; the summary keeps the scene's order of animations."""
    import numpy as np

    from mdsr_opt import Mesh, NeoHookean
    from mdsr_opt.body.muscles import Muscle
    from mdsr_opt.core.jobs import Jobs
    from mdsr_opt.scenes import runscene
    from mdsr_opt.scenes.scene import Animation, Case, Scene

    mesh = Mesh.rectangle(4.0, 1.0, 12, 3)
    P = mesh.points
    row = lambda y: Muscle([int(i) for i in np.argsort(P[:, 0]) if P[i, 1] == y])  # noqa: E731
    scene = Scene(name="s", mesh=mesh, material=NeoHookean(1.0, 0.3), muscles=(row(0.0), row(1.0)),
                  cases=(Case("a", contractions=[0.1, 0.0]), Case("b", contractions=[0.0, 0.1])),
                  animations=(Animation("both", (("rest", 1.0), ("a", 1.0), ("b", 1.0)), frames_per_step=2),
                              Animation("first", (("rest", 1.0), ("a", 1.0)), frames_per_step=2),
                              Animation("still", (("rest", 1.0), ("rest", 1.0)), frames_per_step=1)))
    sent = []
    real = Jobs.submit

    def submit(self, fn, *args, **kwargs):
        name = getattr(fn, "__name__", None) or fn.func.__name__
        sent.append((name, args[1].name if name == "_animation_job" else None))
        return real(self, fn, *args, **kwargs)

    monkeypatch.setattr(Jobs, "submit", submit)
    rep = runscene.run_scene(scene, tmp_path / "out", log=None, photos=False, background=False)
    assert rep.success
    shapes = [i for i, (n, _) in enumerate(sent) if n == "_write_shapes"]  # case a's, then case b's
    first, both = sent.index(("_animation_job", "first")), sent.index(("_animation_job", "both"))
    assert len(shapes) == 2 and shapes[0] > first and shapes[0] < both < shapes[1]
    assert sent.index(("_animation_job", "still")) < sent.index(("_write_shapes", None))  # no case: at once
    assert list(rep.animations) == ["both", "first", "still"]
    assert all(rep.animations[k]["success"] and rep.animations[k]["gif"] == f"{k}.gif" for k in rep.animations)
    # with no case run, the animation of the rest shape alone is still made
    rest_only = runscene.run_scene(scene, tmp_path / "none", cases=[], log=None, photos=False, figures=False,
                                   background=False)
    assert list(rest_only.animations) == ["still"] and rest_only.animations["still"]["n_frames"] == 2
