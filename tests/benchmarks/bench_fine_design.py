"""Benchmark: the design pipeline on fine meshes, against a Newton solve of the target (issue 32, item 4).

The case: a 4 x 1 strip (structured cells, interior nodes jittered), its left end clamped, its right end
turned by 0.6 rad about its centre and moved by (-0.6, 1.0). The target is that external-driving
equilibrium; no muscle layout reaches it exactly. ``design_pipeline`` with its defaults routes the muscles
and designs their contractions. Beside it, in the same process, the target itself is solved by the
project's Newton backend and by ``solve_external``'s default (IPOPT); the ratio is the pipeline's time over
the faster of the two, in wall time and in process CPU time (single-threaded BLAS: on a shared machine the
CPU time is nearer the quiet wall time).

The budget (issue 32, item 4): the pipeline within 3x the reference solve. The last lines give the CPU ratio
per size against it, and ``--plot FILE`` draws them.

Run:  python tests/benchmarks/bench_fine_design.py                     # 2.4k, 8k, 16k nodes
      python tests/benchmarks/bench_fine_design.py --ny 24 32 36 44 64 70
      python tests/benchmarks/bench_fine_design.py --ny 32 --ipopt-print 5   # the design NLP's log
      python tests/benchmarks/bench_fine_design.py --plot ratios.png         # the ratios per size, drawn
      python tests/benchmarks/bench_fine_design.py --verify rest             # verified by a re-solve from rest
      python tests/benchmarks/bench_fine_design.py --tree /tmp/old           # an older tree (git archive REV mdsr_opt)
      python tests/benchmarks/bench_fine_design.py --stages                  # the pipeline's CPU per stage
      python tests/benchmarks/bench_fine_design.py --repeat 3                # medians of 3 runs per size

``--stages`` times (process CPU) each stage of the pipeline's run: the target's solve, the routing, the design's
warm start (its forward solve from the target), the design NLP (IPOPT, with its build and polish), the
verification and the rest of the design (checks, set-up, reports); each beside the reference solve as a
multiple of it, so what stands between a size and the budget can be read per stage.

Before the first size, both the pipeline and the reference solves run once on a small strip (``ny = 4``), not
timed: the modules they import on a first call and their one-time set-up are then paid by neither side, so the
ratio compares steady-state runs (a first call of the pipeline in a fresh process costs a few hundredths of a
second more, which is most visible at the smallest size). ``--repeat K`` runs each size K times and reports the
median of each time.
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
if __name__ == "__main__":  # the checkout this file is in (or --tree's), not the mdsr_opt installed elsewhere
    _tree = sys.argv[sys.argv.index("--tree") + 1] if "--tree" in sys.argv[:-1] else None
    sys.path.insert(0, str(Path(_tree).resolve()) if _tree else str(ROOT))

import mdsr_opt  # noqa: E402
from mdsr_opt import Mesh, NeoHookean, RigidDrag, solve_external  # noqa: E402
from mdsr_opt.synthesis.pipeline import design_pipeline  # noqa: E402

MAT = NeoHookean(1.0, 0.3)
#: the issue's budget: the whole pipeline within this many times the reference solve of the target
BUDGET = 3.0
LENGTH, WIDTH = 4.0, 1.0
ANGLE, SHIFT = 0.6, (-0.6, 1.0)


def strip(ny: int, jitter: float = 0.2, seed: int = 0) -> Mesh:
    """The 4 x 1 strip with ``4 ny`` x ``ny`` cells; interior nodes moved by up to ``jitter`` cell sizes."""
    nx = 4 * ny
    mesh = Mesh.rectangle(LENGTH, WIDTH, nx, ny)
    p = mesh.points.copy()
    inside = (p[:, 0] > 1e-12) & (p[:, 0] < LENGTH - 1e-12) & (p[:, 1] > 1e-12) & (p[:, 1] < WIDTH - 1e-12)
    rng = np.random.default_rng(seed)
    p[inside] += rng.uniform(-jitter, jitter, size=(int(inside.sum()), 2)) * (WIDTH / ny)
    return Mesh(p, mesh.triangles)


def driving(mesh: Mesh, angle: float = ANGLE, shift=SHIFT):
    """``(anchors, drags)``: the left end clamped, the right end turned by ``angle`` about its centre and
    moved by ``shift``, rigidly."""
    p = mesh.points
    left = np.flatnonzero(p[:, 0] < 1e-12)
    right = np.flatnonzero(p[:, 0] > LENGTH - 1e-12)
    return left, RigidDrag(right, angle, (LENGTH, WIDTH / 2), shift=shift)


def newton_time(ny: int, backend: str) -> tuple[float, bool, np.ndarray]:
    """Seconds of ``solve_external`` of the target by ``backend`` on a new mesh (its model built too)."""
    mesh = strip(ny)
    anchors, drags = driving(mesh)
    t0, c0 = time.perf_counter(), time.process_time()
    ext = solve_external(mesh, MAT, anchors, drags, backend=backend)
    return (time.perf_counter() - t0, time.process_time() - c0), bool(ext.success), ext.x


#: the stages ``--stages`` times: (label, module, attribute) of the function whose calls make the stage; the
#: outermost call counts (a stage inside another is subtracted from it, see :func:`stage_cpu`)
STAGES = (("target", "mdsr_opt.mechanics.equilibrium", "solve_external"),
          ("routing", "mdsr_opt.synthesis.pipeline", "route_for_design"),
          ("design", "mdsr_opt.synthesis.pipeline", "design_active"),
          ("warm start", "mdsr_opt.synthesis.problem", "ForwardSolver.solve"),
          ("NLP", "mdsr_opt.synthesis.contractions", "run_flattened"),
          ("verification", "mdsr_opt.synthesis.contractions", "verify_design"))


@contextlib.contextmanager
def stage_cpu(cpu: dict):
    """Within the block, the process CPU seconds of each of :data:`STAGES` add up in ``cpu`` (by label); the
    functions are wrapped where the pipeline looks them up and restored after. On leaving, ``cpu["NLP"]``
    excludes the warm start inside it and ``cpu["design"]`` becomes the rest of the design (its checks,
    set-up and reports), the NLP and the verification taken out."""
    import importlib

    saved = []

    def wrap(label, f):
        depth = [0]

        @functools.wraps(f)
        def timed(*args, **kwargs):
            depth[0] += 1
            c0 = time.process_time()
            try:
                return f(*args, **kwargs)
            finally:
                depth[0] -= 1
                if not depth[0]:
                    cpu[label] = cpu.get(label, 0.0) + time.process_time() - c0
        return timed

    for label, module, attr in STAGES:
        owner = importlib.import_module(module)
        *path, name = attr.split(".")
        for part in path:
            owner = getattr(owner, part)
        saved.append((owner, name, getattr(owner, name)))
        setattr(owner, name, wrap(label, getattr(owner, name)))
    try:
        yield cpu
    finally:
        for owner, name, f in reversed(saved):
            setattr(owner, name, f)
        for label, *_ in STAGES:
            cpu.setdefault(label, 0.0)
        cpu["NLP"] -= cpu["warm start"]
        cpu["design"] -= cpu["NLP"] + cpu["warm start"] + cpu["verification"]


def warm_up() -> None:
    """One untimed run of the reference solves and of the pipeline on a small strip (the module docstring)."""
    newton_time(4, "newton")
    newton_time(4, "ipopt")
    mesh = strip(4)
    anchors, drags = driving(mesh)
    design_pipeline(mesh, MAT, anchors, drags)


def run_median(ny: int, repeat: int, ipopt_print: int = 0, stages: bool = False, **design_options) -> dict:
    """:func:`run` ``repeat`` times: the last run's row with the median of each time and of the ratios
    (per stage too)."""
    rows = [run(ny, ipopt_print, stages, **design_options) for _ in range(max(1, repeat))]
    out = dict(rows[-1])
    for key in ("design_s", "newton_s", "ipopt_s", "ratio", "design_cpu", "newton_cpu", "ipopt_cpu", "cpu_ratio"):
        out[key] = float(np.median([r[key] for r in rows]))
    out["stage_cpu"] = {k: float(np.median([r["stage_cpu"][k] for r in rows])) for k in rows[-1]["stage_cpu"]}
    out["repeat"] = len(rows)
    return out


def run(ny: int, ipopt_print: int = 0, stages: bool = False, **design_options) -> dict:
    t_newton, ok_n, xn = newton_time(ny, "newton")
    t_ipopt, ok_i, xi = newton_time(ny, "ipopt")
    mesh = strip(ny)  # a new Mesh: nothing cached from the target solves
    anchors, drags = driving(mesh)
    opts = dict(design_options)
    if ipopt_print:
        opts["options"] = {"print_level": ipopt_print}
    cpu = {}
    with stage_cpu(cpu) if stages else contextlib.nullcontext():
        t0, c0 = time.perf_counter(), time.process_time()
        out = design_pipeline(mesh, MAT, anchors, drags, **opts)
        t_design, c_design = time.perf_counter() - t0, time.process_time() - c0
    d = out.design
    ok = [t for t, good in ((t_newton, ok_n), (t_ipopt, ok_i)) if good]
    ref = min(ok) if ok else (math.nan, math.nan)
    cref = min(c for _, c in ok) if ok else math.nan
    return {"ny": ny, "nodes": mesh.n_nodes, "design_s": t_design, "newton_s": t_newton[0], "ipopt_s": t_ipopt[0],
            "ratio": t_design / ref[0], "design_cpu": c_design, "newton_cpu": t_newton[1], "ipopt_cpu": t_ipopt[1],
            "cpu_ratio": c_design / cref, "diff_rel": d.difference / mesh.size, "success": out.success,
            "status": d.status, "iters": d.iterations, "muscles": [len(mu.nodes) for mu in out.muscles],
            "times": out.times, "verified": None if d.verification is None else d.verification.passed,
            "verified_from": None if d.verification is None else d.verification.forward_start,
            "newton_agree": float(np.abs(xn - xi).max()) if ok_n and ok_i else math.nan, "stage_cpu": cpu,
            "strokes": np.asarray(d.stroke, dtype=float).tolist()}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ny", type=int, nargs="+", default=[24, 44, 64], help="cells across (nodes ~ 4 ny^2)")
    ap.add_argument("--ipopt-print", type=int, default=0, help="IPOPT print level of the design NLP (0: silent)")
    ap.add_argument("--plot", default=None, help="draw the ratio per size into this image file")
    ap.add_argument("--verify", default=None, choices=["rest", "design"],
                    help="how the design is verified (default: the pipeline's, from the design's state)")
    ap.add_argument("--stages", action="store_true", help="also the pipeline's CPU per stage (see the module)")
    ap.add_argument("--repeat", type=int, default=1, help="runs per size; the medians are reported")
    ap.add_argument("--tree", default=None,
                    help="import mdsr_opt from this folder (e.g. git archive REV mdsr_opt) instead of this checkout")
    args = ap.parse_args(argv)
    print(f"mdsr_opt from {Path(mdsr_opt.__file__).parent}", flush=True)
    rows = []
    head = f"{'nodes':>6} {'design s':>9} {'newton s':>9} {'ipopt s':>8} {'ratio':>6} {'cpu ratio':>9} " \
           f"{'diff/size':>9} {'ok':>5} {'iters':>5}  muscles / status"
    warm_up()
    print(head, flush=True)
    for ny in args.ny:
        r = run_median(ny, args.repeat, args.ipopt_print, args.stages,
                       **({"verify": args.verify} if args.verify else {}))
        rows.append(r)
        print(f"{r['nodes']:6d} {r['design_s']:9.2f} {r['newton_s']:9.2f} {r['ipopt_s']:8.2f} {r['ratio']:6.2f} "
              f"{r['cpu_ratio']:9.2f} {r['diff_rel']:9.4f} {str(r['success']):>5} {r['iters']:5d}  {r['muscles']} {r['status']}",
              flush=True)
        print(f"{'':6} stages {({k: round(v, 2) for k, v in r['times'].items()})}, verified {r['verified']} "
              f"(from {r['verified_from']}); "
              f"CPU s: design {r['design_cpu']:.2f}, newton {r['newton_cpu']:.2f}, ipopt {r['ipopt_cpu']:.2f}",
              flush=True)
        if r["stage_cpu"]:
            print(f"{'':6} {stage_line(r)}", flush=True)
    print(f"\nCPU ratio per size (pipeline over the faster reference solve; budget {BUDGET:g}x):")
    for r in rows:
        verdict = "within" if r["cpu_ratio"] <= BUDGET else "over"
        print(f"  {r['nodes']:6d} nodes: {r['cpu_ratio']:5.2f}x ({verdict} budget; wall {r['ratio']:.2f}x), "
              f"difference {100 * r['diff_rel']:.2f} % of the size, success {r['success']}")
    if args.plot:
        plot_ratios(rows, args.plot)


def stage_line(r: dict) -> str:
    """The pipeline's CPU per stage of a row of :func:`run` (``--stages``), each in seconds and as a multiple of
    the reference solve."""
    ref = min(c for c in (r["newton_cpu"], r["ipopt_cpu"]) if np.isfinite(c))
    return "CPU per stage, s (x reference): " + ", ".join(
        f"{label} {r['stage_cpu'][label]:.3f} ({r['stage_cpu'][label] / ref:.2f}x)" for label, *_ in STAGES)


def plot_ratios(rows: list, path: str) -> None:
    """The CPU and wall ratios per size against the budget, as a bar chart written to ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    nodes = [f"{r['nodes']}" for r in rows]
    x = np.arange(len(rows))
    fig, ax = plt.subplots(figsize=(5.5, 3.5))
    ax.bar(x - 0.2, [r["cpu_ratio"] for r in rows], 0.4, label="CPU time")
    ax.bar(x + 0.2, [r["ratio"] for r in rows], 0.4, label="wall time")
    ax.axhline(BUDGET, color="k", ls="--", lw=1, label=f"budget {BUDGET:g}x")
    ax.set_xticks(x, nodes)
    ax.set_xlabel("nodes")
    ax.set_ylabel("pipeline / reference solve")
    ax.legend(frameon=False)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
