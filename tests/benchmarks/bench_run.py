"""Benchmark: where the time of ``mdsr run`` goes, per scene and per stage (issue 13).

Targets (issue 13): ``mdsr run gecko`` and ``mdsr run humanoid`` at medium resolution with figures in under
4 s each on a quiet machine, ``mdsr run all`` in under 90 s.

For each scene this builds it (medium resolution, timed apart as ``build``), then times
:func:`mdsr_opt.scenes.runscene.run_scene` into a fresh temporary folder with everything on (photographs,
virtual prototype, figures, animations, gait) and splits its time (wall clock, or with ``--clock cpu`` this
process's CPU time, steadier when other jobs share the cores) into stages by wrapping the functions that do
the work (each wrapper's *exclusive* time goes to its stage, so nothing is counted twice):

- ``solves``: targets, routing, designs (their verification included), prototype solves, gait layouts;
- ``anim solves``: the forward solves of the animation frames and of the gait schedule;
- ``photos/contours``: synthetic photographs, contour extraction and loop comparison;
- ``figures``: PNG figures (building and saving);
- ``GIFs``: the animated GIFs;
- ``writing``: meshes, photographs, JSON and fabrication files;
- ``waiting``: waiting for the figure jobs running in worker processes beside the solves (``run_scene``'s
  ``background``; a job's own stages run in its worker and are not seen here, so with the pool
  ``figures``, ``GIFs`` and most ``writing`` show only what is left in this process);
- ``other``: the rest (prototype mesh building, bookkeeping).

``cpu`` is the CPU time of this process and of its finished children, so it measures the work done, where
``wall`` measures the wait (a pool's workers are not counted): on two cores a run cannot end before its CPU
seconds over two. ``--serial`` runs with ``background=False`` (everything in this
process, one after the other), for a side-by-side comparison.

``--repeats`` runs each scene that many times (in one process, after a warm-up run that pays the imports
and CasADi's first-call costs) and reports medians, with the whole run's ``wall`` and ``cpu`` seconds beside
the per-stage clock's total (``run_scene``). The medians per stage are printed as a table, written
to ``run.csv`` and drawn as a stacked bar chart ``run.png`` (``run_<label>.*`` with ``--label``; in ``--out``,
default ``bench_out``). ``--cli`` additionally times the command itself (``python -m mdsr_opt run NAME``,
imports and scene building included, with the modules' bytecode written first as an installation has it),
the median of ``--repeats`` runs (at most 3) per scene, with its CPU time (``cli cpu``: that of the command's
process and of the processes it reaped, see :func:`time_cli`), and ``--all`` times ``mdsr run all`` once.
``--against REF`` runs the command as committed at ``REF`` too, alternating with this tree, ``--repeats`` times
each, and prints both medians and their ratio.

The package and the problem library are imported from the source tree this script lives in (or ``--tree``,
e.g. an exported older commit, to measure before and after with the same script).

Run:  python tests/benchmarks/bench_run.py                       # gecko and humanoid, 3 repeats
      python tests/benchmarks/bench_run.py --scenes gecko --repeats 1
      python tests/benchmarks/bench_run.py --cli --all
      python tests/benchmarks/bench_run.py --scenes gecko --repeats 2 --cli --all --against main   # run all vs main
      python tests/benchmarks/bench_run.py --scenes gecko humanoid --repeats 8 --cli --against main
      python tests/benchmarks/bench_run.py --tree /tmp/base --clock cpu --label before   # an older tree
"""

from __future__ import annotations

import argparse
import csv
import functools
import importlib
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
STAGES = ("solves", "anim solves", "photos/contours", "figures", "GIFs", "writing", "waiting", "other")

# (module, attribute, stage): the stage None inherits the enclosing wrapper's stage ("solves" at top level)
WRAPS = [
    ("mdsr_opt.scenes.runner", "prepare_case", "solves"),
    ("mdsr_opt.synthesis.contractions", "design_contractions", "solves"),
    ("mdsr_opt.mechanics.equilibrium", "solve_internal", None),
    ("mdsr_opt.mechanics.equilibrium", "solve_external", None),
    ("mdsr_opt.synthesis.poses", "design_poses", "solves"),
    ("mdsr_opt.scenes.prototype", "VirtualPrototype.for_scene", "other"),
    ("mdsr_opt.scenes.runscene", "animate", "anim solves"),
    ("mdsr_opt.synthesis.gait", "gait_schedule", "anim solves"),
    ("mdsr_opt.photos.camera", "render_photo", "photos/contours"),
    ("mdsr_opt.photos.contours", "contour_loops_from_image", "photos/contours"),
    ("mdsr_opt.photos.loops", "compare_loops", "photos/contours"),
    ("mdsr_opt.photos.loops", "simulated_loops", "photos/contours"),
    ("mdsr_opt.scenes.runner", "write_case", "figures"),
    ("mdsr_opt.scenes.runscene", "write_case", "figures"),  # older trees: runscene calls it by its own name
    ("mdsr_opt.core.jobs", "Jobs.submit", "figures"),  # a job run here, or sending it to the pool
    ("mdsr_opt.plot", "plot_scene", "figures"),
    ("mdsr_opt.plot", "save_figure", "figures"),
    ("mdsr_opt.plot.common", "save_figure", "figures"),
    ("mdsr_opt.plot.design", "plot_schedule", "figures"),
    ("mdsr_opt.plot", "save_animation", "GIFs"),
    ("mdsr_opt.body.io", "write_mesh", "writing"),
    ("mdsr_opt.body.io", "write_json", "writing"),
    ("mdsr_opt.photos.camera", "SyntheticPhoto.save", "writing"),
    ("mdsr_opt.synthesis.export", "export_fabrication", "writing"),
    ("mdsr_opt.synthesis.poses", "PosesResult.save", "writing"),
    ("mdsr_opt.core.jobs", "Jobs.wait", "waiting"),
]


class StageClock:
    """Exclusive time per stage, from wrapped functions (a stack of open calls); ``clock`` is
    ``time.perf_counter`` (wall) or ``time.process_time`` (CPU of this process: steadier on a busy machine)."""

    clock = staticmethod(time.perf_counter)

    def __init__(self):
        self.stack: list[list] = []  # [stage, start, child seconds]
        self.totals = dict.fromkeys(STAGES, 0.0)

    def wrap(self, fn, stage):
        @functools.wraps(fn)
        def inner(*args, **kwargs):
            st = stage or (self.stack[-1][0] if self.stack else "solves")
            self.stack.append([st, self.clock(), 0.0])
            try:
                return fn(*args, **kwargs)
            finally:
                s, t0, child = self.stack.pop()
                dt = self.clock() - t0
                self.totals[s] += dt - child
                if self.stack:
                    self.stack[-1][2] += dt

        return inner

    def install(self):
        undo = []
        for modname, attr, stage in WRAPS:
            try:
                mod = importlib.import_module(modname)
            except ImportError:  # an older tree (--tree) without this module
                continue
            owner, name = mod, attr
            if "." in attr:
                cls, name = attr.split(".")
                owner = getattr(mod, cls, None)
            if owner is None or not hasattr(owner, name):  # another tree (--tree) without it
                continue
            raw = owner.__dict__.get(name) if isinstance(owner, type) else getattr(owner, name)
            fn = getattr(owner, name)
            new = self.wrap(fn, stage)
            if isinstance(raw, classmethod):
                new = classmethod(self.wrap(raw.__func__, stage))
            undo.append((owner, name, raw))
            setattr(owner, name, new)
        return undo

    @staticmethod
    def uninstall(undo):
        for owner, name, raw in reversed(undo):
            setattr(owner, name, raw)


def _cpu() -> float:
    """CPU seconds of this process and its finished (reaped) children."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def time_scene(name: str, repeats: int, log=None, serial: bool = False) -> dict:
    """Medians over ``repeats`` runs of ``run_scene(name)`` (after one warm-up run): total and per stage."""
    return time_modes(name, repeats, (serial,), log)[serial]


def time_modes(name: str, repeats: int, modes=(False, True), log=None) -> dict:
    """:func:`time_scene` for each mode of ``modes`` (``serial`` True or False), the modes alternating
    within each repeat (a fair comparison on a shared machine): ``{serial: medians}``."""
    rows: dict = {m: [] for m in modes}
    for r in range(repeats + 1):
        for serial in modes:
            row = _one_run(name, serial)
            if r == 0:
                row["warm-up"] = True
            rows[serial].append(row)
            if log:
                log(f"  {name}{' serial' if serial else ''} run {r}{' (warm-up)' if r == 0 else ''}: "
                    f"{row['total']:.2f} s (" + ", ".join(f"{k} {row[k]:.2f}" for k in STAGES) + ")")
    keys = STAGES + ("total", "build", "wall", "cpu")
    out = {}
    for m in modes:
        timed = rows[m][1:] if repeats else rows[m]
        out[m] = {k: statistics.median(row[k] for row in timed) for k in keys}
    return out


def _one_run(name: str, serial: bool) -> dict:
    """One timed ``run_scene(name)`` at medium resolution: seconds per stage and in all."""
    from mdsr_opt.scenes.library import get_problem
    from mdsr_opt.scenes.runscene import run_scene

    t0 = time.perf_counter()
    scene = get_problem(name, resolution="medium")
    t_build = time.perf_counter() - t0
    clock = StageClock()
    undo = clock.install()
    try:
        with tempfile.TemporaryDirectory() as d:
            t0, w0, c0 = clock.clock(), time.perf_counter(), _cpu()
            rep = run_scene(scene, Path(d) / name, log=None, **({"background": False} if serial else {}))
            total = clock.clock() - t0
            wall, cpu = time.perf_counter() - w0, _cpu() - c0
    finally:
        clock.uninstall(undo)
    if not rep.success:
        print(f"  warning: a run of {name} did not succeed", file=sys.stderr)
    row = dict(clock.totals)
    row["other"] += total - sum(clock.totals.values())
    row.update(total=total, build=t_build, wall=wall, cpu=cpu)
    return row


def compile_tree(root: Path) -> None:
    """Write the bytecode of the measured tree's modules (``__pycache__``), as ``pip install`` does for an
    installed package: a process that finds none compiles every module it imports from source (0.3-0.5 s
    of ``mdsr run``, measured with ``PYTHONDONTWRITEBYTECODE=1``, which some environments set)."""
    import compileall

    for sub in ("mdsr_opt", "problems"):
        compileall.compile_dir(str(root / sub), quiet=1)


def time_cli(args: list[str], root: Path | None = None) -> tuple[float, float]:
    """``(wall, cpu)`` seconds of ``python -m mdsr_opt -q run ARGS --out <tmp>`` (imports included), from the
    tree ``root`` (default: the measured one), with the tree's bytecode written (:func:`compile_tree`); ``cpu``
    is the user and system time of the command's process and of the processes it reaped. The worker processes
    of a ``forkserver`` pool (Linux) are children of the pool's server, which the command never reaps: their
    CPU, and the server's, are not in ``cpu``, so it is the command's own process only, while a tree whose job
    processes the command reaps itself (a fork server of the command's own) counts them: compare such trees by
    wall time, or by the CPU of ``--serial`` runs (every job in the command's process)."""
    import resource

    root = Path(os.environ["MDSR_PROBLEMS"]).parent if root is None else Path(root)
    compile_tree(root)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(root)] + [v for v in [os.environ.get("PYTHONPATH")] if v]),
               MDSR_PROBLEMS=str(root / "problems"))  # the tree's own problem library
    with tempfile.TemporaryDirectory() as d:
        r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        p = subprocess.run([sys.executable, "-m", "mdsr_opt", "-q", "run", *args, "--out", os.path.join(d, "out")],
                           cwd=root, capture_output=True, text=True, env=env)
        dt = time.perf_counter() - t0
        r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
    if p.returncode != 0:
        print(f"  warning: mdsr run {' '.join(args)} exited with {p.returncode}\n{p.stdout[-2000:]}{p.stderr[-2000:]}",
              file=sys.stderr)
    return dt, cpu


def tree_at(ref: str, dest: str) -> Path:
    """The package and the problem library as committed at ``ref`` (``git archive``), extracted into ``dest``."""
    arch = subprocess.run(["git", "archive", ref, "mdsr_opt", "problems"], capture_output=True, check=True,
                          cwd=ROOT).stdout
    subprocess.run(["tar", "-x", "-C", dest], input=arch, check=True)
    return Path(dest)


def cli_against(name: str, ref_root: Path, repeats: int) -> dict:
    """The command on ``name`` from the measured tree and from ``ref_root``, alternating, ``repeats`` times
    each: medians and minima of wall and CPU seconds of both (a comparison on a shared machine)."""
    runs: dict = {"now": [], "ref": []}
    for _ in range(repeats):
        runs["ref"].append(time_cli([name], root=ref_root))
        runs["now"].append(time_cli([name]))
    out = {}
    for k, v in runs.items():
        out[k] = {"wall": statistics.median(t for t, _ in v), "min": min(t for t, _ in v),
                  "cpu": statistics.median(c for _, c in v)}
    return out


def load() -> str:
    try:
        return "load averages " + ", ".join(f"{v:.2f}" for v in os.getloadavg())
    except OSError:  # pragma: no cover
        return "load unknown"


def use_tree(root: Path) -> None:
    """Import ``mdsr_opt`` and the problems from the source tree ``root`` (not an installed copy)."""
    sys.path.insert(0, str(root))
    os.environ["PYTHONPATH"] = os.pathsep.join([str(root)] + [v for v in [os.environ.get("PYTHONPATH")] if v])
    os.environ["MDSR_PROBLEMS"] = str(root / "problems")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--tree", default=str(ROOT), help="source tree to measure (default: this script's)")
    p.add_argument("--scenes", nargs="+", default=["gecko", "humanoid"], help="library scenes (default gecko humanoid)")
    p.add_argument("--repeats", type=int, default=3, help="timed runs per scene after the warm-up (median)")
    p.add_argument("--cli", action="store_true", help="also time `python -m mdsr_opt run NAME` per scene")
    p.add_argument("--all", action="store_true", help="also time `python -m mdsr_opt run all` once (with --against:"
                   " --repeats times here and at REF, alternating)")
    p.add_argument("--against", default=None, metavar="REF",
                   help="with --cli: time the command also as committed at REF (git), alternating with this "
                        "tree, --repeats times each (not capped at 3)")
    p.add_argument("--out", default="bench_out", help="folder of the CSV and chart (default bench_out)")
    p.add_argument("--label", default="", help="a label for this measurement in the CSV and chart")
    p.add_argument("--before", default=None,
                   help="a CSV of an earlier measurement (run_<label>.csv) drawn beside this one in the chart")
    p.add_argument("--serial", action="store_true",
                   help="run_scene(background=False): figures drawn in this process after each solve")
    p.add_argument("--both", action="store_true",
                   help="time the background and the serial run alternately (rows NAME and NAME serial)")
    p.add_argument("--clock", choices=("wall", "cpu"), default="wall",
                   help="wall clock (default) or this process's CPU time (steadier when other jobs share the cores)")
    a = p.parse_args(argv)
    if a.against and not a.cli:
        p.error("--against compares the command: give --cli too")
    use_tree(Path(a.tree).resolve())
    ref_root = tree_at(a.against, tempfile.mkdtemp(prefix="bench_run_ref_")) if a.cli and a.against else None
    if a.clock == "cpu":
        StageClock.clock = staticmethod(time.process_time)
    import mdsr_opt

    print(f"mdsr_opt from {Path(mdsr_opt.__file__).parent}")

    print(f"bench_run: {', '.join(a.scenes)}, {a.repeats} repeat(s) after a warm-up, {a.clock} clock"
          f"{', serial' if a.serial else ''}; {load()}")
    results = {}
    for name in a.scenes:
        if a.both:
            got = time_modes(name, a.repeats, (False, True), log=print)
            results[name], results[f"{name} serial"] = got[False], got[True]
        else:
            results[name] = time_scene(name, a.repeats, log=print, serial=a.serial)
        if a.cli and a.against:  # the command from this tree and from REF, alternating
            got = cli_against(name, ref_root, max(1, a.repeats))
            results[name]["cli"], results[name]["cli cpu"] = got["now"]["wall"], got["now"]["cpu"]
            results[name]["cli ref"], results[name]["cli ref cpu"] = got["ref"]["wall"], got["ref"]["cpu"]
            print(f"  {name}: `mdsr run {name}` {got['now']['wall']:.2f} s wall (fastest {got['now']['min']:.2f}), "
                  f"CPU {got['now']['cpu']:.2f} s (the command and what it reaped); at {a.against} "
                  f"{got['ref']['wall']:.2f} s (fastest "
                  f"{got['ref']['min']:.2f}), CPU {got['ref']['cpu']:.2f} s: ratio "
                  f"{got['now']['wall'] / got['ref']['wall']:.2f}; medians of {a.repeats} alternating runs ({load()})")
        elif a.cli:  # the command's wall clock is as noisy as the runs': the median of --repeats (at most 3)
            runs = [time_cli([name]) for _ in range(min(3, max(1, a.repeats)))]
            results[name]["cli"] = statistics.median(t for t, _ in runs)
            results[name]["cli cpu"] = statistics.median(c for _, c in runs)
            print(f"  {name}: `mdsr run {name}` {results[name]['cli']:.2f} s wall, median of "
                  + ", ".join(f"{t:.2f}" for t, _ in runs) + f"; CPU {results[name]['cli cpu']:.2f} s of the command "
                  f"and the processes it reaped ({load()})")
    t_all = None
    if a.all and ref_root is not None:  # this tree and REF, alternating: medians of --repeats runs each
        got = {"now": [], "ref": []}
        for _ in range(max(1, a.repeats)):
            print(f"  mdsr run all: starting at {a.against} and here ({load()})")
            got["ref"].append(time_cli(["all"], root=ref_root))
            got["now"].append(time_cli(["all"]))
            print(f"    {a.against} {got['ref'][-1][0]:.1f} s, here {got['now'][-1][0]:.1f} s wall")
        t_all, c_all = (statistics.median(v[i] for v in got["now"]) for i in (0, 1))
        t_ref = statistics.median(t for t, _ in got["ref"])
        print(f"  mdsr run all: {t_all:.1f} s wall here, {t_ref:.1f} s at {a.against}: ratio {t_all / t_ref:.2f} "
              f"(medians of {len(got['now'])} alternating runs; {load()})")
    elif a.all:
        print(f"  mdsr run all: starting ({load()})")
        t_all, c_all = time_cli(["all"])
        print(f"  mdsr run all: {t_all:.1f} s wall, {c_all:.1f} s CPU ({load()})")

    cli_cols = (["cli", "cli cpu"] if a.cli or a.all else []) + (["cli ref", "cli ref cpu"] if a.against else [])
    cols = ["scene", *STAGES, "run_scene", "wall", "cpu", "build"] + cli_cols
    print("\n| " + " | ".join(cols) + " |\n|" + "---|" + "---:|" * (len(cols) - 1))
    for name, r in results.items():
        vals = [r[k] for k in STAGES] + [r["total"], r["wall"], r["cpu"], r["build"]] \
            + [r.get(k, float("nan")) for k in cli_cols]
        print(f"| {name} | " + " | ".join(f"{v:.2f}" for v in vals) + " |")
    if t_all is not None:
        print(f"\nmdsr run all: {t_all:.1f} s")
    print(f"({a.clock} seconds, medians of {a.repeats}; target: run_scene/cli < 4 s per scene, run all < 90 s; {load()})")

    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    stem = f"run_{a.label}" if a.label else "run"
    with open(out / f"{stem}.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["label", *cols])
        for name, r in results.items():
            w.writerow([a.label, name] + [f"{r[k]:.4f}" for k in STAGES + ("total", "wall", "cpu", "build")]
                       + [f"{r.get(k, float('nan')):.4f}" for k in cli_cols])
        if t_all is not None:
            w.writerow([a.label, "all"] + [""] * (len(STAGES) + 4) + [f"{t_all:.4f}", f"{c_all:.4f}"])
    bars = dict(results)
    if a.before:
        with open(a.before, newline="") as fh:
            old = [r for r in csv.DictReader(fh) if r["scene"] in results and r["solves"]]
        bars = {}
        for name in results:
            for r in old:
                if r["scene"] == name:
                    bars[f"{name} ({r['label'] or 'before'})"] = {k: float(r.get(k) or 0) for k in STAGES}
                    if r.get("cli"):
                        bars[f"{name} ({r['label'] or 'before'})"]["cli"] = float(r["cli"])
            bars[f"{name} ({a.label or 'now'})"] = results[name]
    _chart(bars, out / f"{stem}.png", a.label, a.repeats, a.clock, a.against)
    print(f"wrote {out / (stem + '.csv')} and {out / (stem + '.png')}")
    return 0


def _chart(results: dict, path: Path, label: str, repeats: int, clock: str, against: str | None = None) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(results)
    fig, ax = plt.subplots(figsize=(7, 1.2 + 0.7 * len(names)))
    left = [0.0] * len(names)
    cmap = plt.get_cmap("tab10")
    for i, st in enumerate(STAGES):
        v = [results[n][st] for n in names]
        ax.barh(names, v, left=left, color=cmap(i), label=st)
        left = [l + x for l, x in zip(left, v)]
    cli = [(i, results[n]["cli"]) for i, n in enumerate(names) if results[n].get("cli", float("nan")) > 0]
    if cli:  # the whole command (imports, scene building, exit) where it was timed
        ax.plot([v for _, v in cli], [i for i, _ in cli], "kD", ms=6, label="mdsr run (command)")
    ref = [(i, results[n]["cli ref"]) for i, n in enumerate(names) if results[n].get("cli ref", float("nan")) > 0]
    if ref:  # --against: the command as committed at REF, alternating with it in the same run
        ax.plot([v for _, v in ref], [i for i, _ in ref], "D", mfc="white", mec="k", ms=6,
                label=f"mdsr run at {against} (same run)")
    ax.axvline(4.0, color="k", ls="--", lw=1, label="target 4 s")
    ax.set_xlabel(f"seconds (run_scene by stage, and the command, median of {repeats}; {clock} clock)")
    ax.set_title(f"mdsr run per stage{' - ' + label if label else ''}", fontsize=10)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    ax.invert_yaxis()
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
