"""Benchmark of driving-quantity design: flattened NLP vs nested (adjoint) vs derivative-free.

For 1, 2, 4 and 8 muscles on rectangle meshes of about 300, 1k and 3k nodes, a target is made by contracting
the muscles by known amounts, rotating and shifting the result; each method designs the contractions from
the same initial guess. Prints a table, writes ``design_bench.csv`` and ``design_bench.png`` (difference
against time) to ``--out``. Also measures the flattened NLP's sensitivity to scaling, warm start, Hessian
(exact vs Gauss-Newton) and derivatives (numpy callbacks, MX assembled term by term, CasADi's symbolic
ones) on the 1k-node, 4-muscle case.

Run:  python tests/benchmarks/bench_design.py --out bench_out
      python tests/benchmarks/bench_design.py --quick          # 300 nodes only, 1-4 muscles
      python tests/benchmarks/bench_design.py --sizes 1k 3k --muscles 4 --methods flattened --variants
                                                          # flattened only: build and solve, and the variants
      python tests/benchmarks/bench_design.py --quick --derivatives casadi   # the flattened NLP's SX path
      python tests/benchmarks/bench_design.py --sizes 1k 3k --muscles 4 --methods flattened --models cable springs
                                                          # exact cable vs dummy springs: build, solve, verify
      python tests/benchmarks/bench_design.py --case 3k4 --repeats 5 --against HEAD~3
                                                          # the README's design figure: one fresh flattened
                                                          # design (new mesh, verification included), stages,
                                                          # medians, paired against an older commit

``--case 3k4`` is the target of issue 13: a fresh flattened design at 3k nodes with 4 muscles, verification
included. Each repeat runs in its own process (so nothing is cached but the imports and IPOPT's plugin, which
the target's forward solve loads): the target is made, then the design is timed on a new Mesh of the same
geometry. The stages are ``build`` (energy model, muscle constraints, NLP; ``DesignResult.build_time``),
``warm start`` (the forward solve at the initial contractions), ``IPOPT`` (the rest of the solve time),
``verify`` (``verification.time``), ``total`` (wall time of the call, verification included) and ``cpu``
(the process's CPU time over the call: on a shared machine nearer the quiet wall time than ``total``). With
``--against REF`` the same case runs with the package as committed at ``REF`` (extracted with ``git archive``),
in alternating processes, and the results are compared (contractions, strokes, difference).
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

from mdsr_opt import Mesh, Muscle, NeoHookean, solve_internal
from mdsr_opt.synthesis.contractions import design_contractions
from mdsr_opt.mechanics.model import get_model

MAT = NeoHookean(E=1.0, nu=0.3)
SIZES = {"300": 9, "1k": 16, "3k": 27}  # rectangle 4 x 1 with (4 ny) x ny square cells


def muscles_for(nx: int, ny: int, m: int) -> list[Muscle]:
    """Grid-line muscles: halves of the bottom and top rows first, then of two inner rows."""
    def row(j, i0, i1, name):
        return Muscle([j * (nx + 1) + i for i in range(i0, i1 + 1)], name=name)

    h = nx // 2
    j1, j2 = ny // 3, (2 * ny) // 3
    all_m = [row(0, 1, h, "bottom-left"), row(ny, h, nx - 1, "top-right"), row(0, h, nx - 1, "bottom-right"),
             row(ny, 1, h, "top-left"), row(j1, 2, h - 1, "inner1-left"), row(j2, h + 1, nx - 2, "inner2-right"),
             row(j1, h + 1, nx - 2, "inner1-right"), row(j2, 2, h - 1, "inner2-left")]
    return all_m[:m]


def make_case(size: str, m: int, seed: int = 0, model: str = "cable"):
    ny = SIZES[size]
    nx = 4 * ny
    mesh = Mesh.rectangle(4.0, 1.0, nx, ny)
    mus = muscles_for(nx, ny, m)
    rng = np.random.default_rng(seed + 17 * m)
    a_true = rng.uniform(0.05, 0.25, size=m)
    fwd = solve_internal(mesh, MAT, mus, a_true, muscle_model=model)
    if not fwd.success:
        raise RuntimeError(f"forward solve for the target failed: {fwd.status}")
    th = 0.4
    R = np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])
    target = fwd.x @ R.T + [1.0, -0.5]
    if model == "cable":  # a rope the body left slack is designed at the contraction it reached
        a_true = np.where(fwd.slack, fwd.achieved, a_true)
    return mesh, mus, a_true, target


def time_to_reach(history, level):
    for t, d in history:
        if d <= level:
            return t
    return float("nan")


def run(args):
    os.makedirs(args.out, exist_ok=True)
    sizes = ["300"] if args.quick else args.sizes
    counts = [1, 2, 4] if args.quick else args.muscles
    rows, traces = [], {}
    head = (f"{'mesh':>5} {'nodes':>6} {'m':>2} {'model':>7} {'method':>16} {'ok':>3} {'build s':>8} {'solve s':>8} "
            f"{'verify s':>8} {'iters':>6} {'fwd':>5} {'difference':>11} {'|a-a*|max':>10}")
    print(head)
    print("-" * len(head))
    for size in sizes:
        for m, model in [(c, md) for c in counts for md in args.models]:
            mesh, mus, a_true, target = make_case(size, m, seed=args.seed, model=model)
            get_model(mesh, MAT)  # the energy model is shared by all methods: build it before timing
            for method in args.methods:
                kw = {"muscle_model": model}
                if args.start != "geometric":  # the cable's geometric guess is the answer of a reachable target
                    kw["initial_guess"] = np.full(m, float(args.start))
                if method == "derivative-free":
                    kw["max_iter"] = args.df_evals * m
                if method == "flattened":
                    kw["derivatives"] = args.derivatives
                res = design_contractions(mesh, MAT, mus, target, method=method, **kw)
                err = float(np.abs(res.contractions - a_true).max())
                row = {"mesh": size, "nodes": mesh.n_nodes, "muscles": m, "model": model, "method": method,
                       "derivatives": kw.get("derivatives", ""),
                       "success": res.success, "build_time": res.build_time, "solve_time": res.solve_time,
                       "time": res.time, "iterations": res.iterations, "n_forward": res.n_forward,
                       "difference": res.difference, "rel_difference": res.difference / mesh.size,
                       "contraction_error": err, "initial_difference": res.initial_difference,
                       "verify_gap": res.verification.gap, "verify_time": res.verification.time,
                       "status": res.status}
                rows.append(row)
                if model == args.models[0]:
                    traces[(size, m, method)] = res.history
                print(f"{size:>5} {mesh.n_nodes:>6} {m:>2} {model:>7} {method:>16} {'y' if res.success else 'n':>3} "
                      f"{res.build_time:>8.3f} {res.solve_time:>8.3f} {res.verification.time:>8.3f} "
                      f"{res.iterations:>6d} {res.n_forward:>5d} "
                      f"{res.difference:>11.3e} {err:>10.2e}", flush=True)
    # speed-up of flattened over the rivals at equal difference
    print("\nflattened speed-up at equal difference (rival's time to reach the flattened difference, or its "
          "own final one if worse, over flattened solve time):")
    for size in sizes:
        for m in counts:
            fl = [r for r in rows if r["mesh"] == size and r["muscles"] == m and r["method"] == "flattened"
                  and r["model"] == args.models[0]]
            if not fl:
                continue
            fl = fl[0]
            for rival in ("nested", "derivative-free"):
                rv = [r for r in rows if r["mesh"] == size and r["muscles"] == m and r["method"] == rival
                      and r["model"] == args.models[0]]
                if not rv:
                    continue
                level = max(fl["difference"], rv[0]["difference"]) * 1.01 + 1e-12
                t = time_to_reach(traces[(size, m, rival)], level)
                fl_t = fl["solve_time"]  # its iterates are not equilibria: only the end counts
                for r in rows:
                    if r is rv[0]:
                        r["time_to_flattened_difference"] = t
                        r["speedup_of_flattened"] = t / fl_t
                print(f"  {size:>4} m={m}: vs {rival:<16} {t / fl_t:7.1f}x  ({t:.3f} s vs {fl_t:.3f} s)")
    # sensitivity of the flattened NLP on the 1k-node, 4-muscle case
    sens = []
    if args.variants or (not args.quick and not args.no_variants and "1k" in sizes and 4 in counts):
        print("\nflattened NLP on 1k nodes, 4 muscles: scaling, warm start, Hessian, derivatives")
        mesh, mus, a_true, target = make_case("1k", 4)
        get_model(mesh, MAT)  # as in the table: the energy model is built before timing
        for label, kw in [("auto scaling, warm, exact", {}),
                          ("size scaling, warm, exact", {"scaling": "size"}),
                          ("auto scaling, cold, exact", {"warm_start": False}),
                          ("size scaling, cold, exact", {"scaling": "size", "warm_start": False}),
                          ("auto scaling, warm, Gauss-Newton", {"hessian": "gauss-newton"}),
                          ("MX-assembled derivatives, exact", {"derivatives": "assembled"}),
                          ("CasADi derivatives (SX), exact", {"derivatives": "casadi"}),
                          ("CasADi derivatives, Gauss-Newton", {"derivatives": "casadi",
                                                                "hessian": "gauss-newton"}),
                          ("stiffness 100", {"stiffness": 100.0}),
                          ("stiffness 1", {"stiffness": 1.0})]:
            if "stiffness" in kw:  # a target made with the same stiffness
                fwd = solve_internal(mesh, MAT, mus, a_true, stiffness=kw["stiffness"])
                tgt = fwd.x
            else:
                tgt = target
            kw.setdefault("derivatives", args.derivatives)
            res = design_contractions(mesh, MAT, mus, tgt, **kw)
            err = float(np.abs(res.contractions - a_true).max())
            sens.append({"variant": label, "derivatives": kw["derivatives"], "success": res.success,
                         "iterations": res.iterations,
                         "build_time": res.build_time, "solve_time": res.solve_time,
                         "difference": res.difference, "contraction_error": err, "status": res.status})
            print(f"  {label:<34} ok={'y' if res.success else 'n'} iters={res.iterations:>4d} "
                  f"build={res.build_time:6.2f}s solve={res.solve_time:6.3f}s diff={res.difference:.2e} "
                  f"|a-a*|={err:.1e}  {res.status[:40]}", flush=True)
    path = os.path.join(args.out, "design_bench.csv")
    keys = sorted({k for r in rows for k in r}, key=lambda k: list(rows[0]).index(k) if k in rows[0] else 99)
    with open(path + ".tmp", "w", newline="") as fh:
        wr = csv.DictWriter(fh, fieldnames=keys)
        wr.writeheader()
        wr.writerows(rows)
    os.replace(path + ".tmp", path)
    if sens:
        spath = os.path.join(args.out, "design_bench_flattened_variants.csv")
        with open(spath + ".tmp", "w", newline="") as fh:
            wr = csv.DictWriter(fh, fieldnames=list(sens[0]))
            wr.writeheader()
            wr.writerows(sens)
        os.replace(spath + ".tmp", spath)
    from mdsr_opt.plot.design import plot_design_benchmark
    from mdsr_opt.plot.common import save_figure

    fig = plot_design_benchmark(rows, traces)
    png = save_figure(fig, os.path.join(args.out, "design_bench.png"))
    print(f"\nwrote {path} and {png}")
    return rows


# ---------------------------------------------------------------------------------------------- --case 3k4
STAGES = ("build", "warm start", "IPOPT", "verify", "total", "cpu")


def case_worker(size: str, m: int) -> dict:
    """One fresh flattened design (new mesh, verification included) timed by stage; returns a dict."""
    from mdsr_opt.synthesis import problem as problem_mod

    mesh0, mus, a_true, target = make_case(size, m)
    warm = [0.0]
    solve0 = problem_mod.ForwardSolver.solve

    def timed_solve(self, a, **kw):  # the flattened design's only forward solve is its warm start
        t0, b0 = time.perf_counter(), self.build_time
        try:
            return solve0(self, a, **kw)
        finally:  # its model build is counted in build_time: the warm start is the rest
            warm[0] += time.perf_counter() - t0 - (self.build_time - b0)

    problem_mod.ForwardSolver.solve = timed_solve
    ny = SIZES[size]
    mesh = Mesh.rectangle(4.0, 1.0, 4 * ny, ny)  # a new mesh: no model, constraints or solver cached on it
    t0, c0 = time.perf_counter(), time.process_time()
    res = design_contractions(mesh, MAT, mus, target)
    total, cpu = time.perf_counter() - t0, time.process_time() - c0
    v = res.verification
    return {"build": res.build_time, "warm start": warm[0], "IPOPT": res.solve_time - warm[0],
            "verify": v.time, "total": total, "cpu": cpu, "success": bool(res.success), "passed": bool(v.passed),
            "iterations": int(res.iterations), "nodes": int(mesh.n_nodes), "difference": float(res.difference),
            "contractions": [float(c) for c in res.contractions], "stroke": [float(c) for c in res.stroke],
            "contraction_error": float(np.abs(res.contractions - a_true).max()), "gap": float(v.gap)}


def _package_at(ref: str, dest: str) -> str:
    """Extract the package as committed at ``ref`` into ``dest``; returns the folder to put on sys.path."""
    root = subprocess.run(["git", "rev-parse", "--show-toplevel"], capture_output=True, text=True, check=True,
                          cwd=os.path.dirname(os.path.abspath(__file__))).stdout.strip()
    arch = subprocess.run(["git", "archive", ref, "mdsr_opt"], capture_output=True, check=True, cwd=root).stdout
    subprocess.run(["tar", "-x", "-C", dest], input=arch, check=True)
    return dest


def _run_worker(pkg_root: str, size: str, m: int) -> dict:
    env = dict(os.environ, PYTHONPATH=pkg_root + os.pathsep + os.environ.get("PYTHONPATH", ""))
    out = subprocess.run([sys.executable, os.path.abspath(__file__), "--worker", size, str(m)], env=env,
                         capture_output=True, text=True)
    if out.returncode != 0:
        raise RuntimeError(f"worker failed ({pkg_root}):\n{out.stderr[-3000:]}")
    return json.loads([ln for ln in out.stdout.splitlines() if ln.startswith("{")][-1])


def run_case(args):
    """``--case``: stage breakdown of fresh designs, medians over ``--repeats`` processes, paired with REF."""
    size, m = {"3k4": ("3k", 4), "1k4": ("1k", 4), "300x4": ("300", 4)}[args.case]
    here = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    versions = [("now", here)]
    tmp = None
    if args.against:
        tmp = tempfile.TemporaryDirectory()
        versions.insert(0, (args.against, _package_at(args.against, tmp.name)))
    runs = {label: [] for label, _ in versions}
    for r in range(args.repeats):
        for label, root in versions:  # alternate, so both versions see the same machine load
            runs[label].append(_run_worker(root, size, m))
            rr = runs[label][-1]
            print(f"  repeat {r + 1} {label:>12}: " + " ".join(f"{k} {rr[k]:.3f}" for k in STAGES) +
                  f"  it {rr['iterations']} ok {rr['success']}", flush=True)
    print(f"\nfresh flattened design, {runs[versions[0][0]][0]['nodes']} nodes, {m} muscles, verification "
          f"included: medians of {args.repeats} runs, seconds")
    print(f"{'version':>12} " + " ".join(f"{k:>10}" for k in STAGES) + f" {'iters':>6} {'ok':>3}")
    med = {}
    for label, _ in versions:
        med[label] = {k: statistics.median(r[k] for r in runs[label]) for k in STAGES}
        print(f"{label:>12} " + " ".join(f"{med[label][k]:>10.3f}" for k in STAGES) +
              f" {runs[label][0]['iterations']:>6d} {'y' if all(r['success'] for r in runs[label]) else 'n':>3}")
    if len(versions) == 2:
        a, b = versions[0][0], versions[1][0]
        print(f"{'ratio':>12} " + " ".join(f"{med[a][k] / max(med[b][k], 1e-12):>10.2f}" for k in STAGES)
              + f"   ({a} / now)")
        ra, rb = runs[a][0], runs[b][0]
        rel = lambda u, v: float(np.max(np.abs(np.subtract(u, v)) / np.maximum(np.abs(v), 1e-12)))  # noqa: E731
        print(f"agreement: contractions {rel(rb['contractions'], ra['contractions']):.2e} rel, strokes "
              f"{rel(rb['stroke'], ra['stroke']):.2e} rel, difference {rel([rb['difference']], [ra['difference']]):.2e} "
              "rel (differences near zero are compared in absolute terms below)")
        print(f"  difference {ra['difference']:.6e} -> {rb['difference']:.6e}; |a - a_true| "
              f"{ra['contraction_error']:.2e} -> {rb['contraction_error']:.2e}; gap {ra['gap']:.2e} -> {rb['gap']:.2e}")
    os.makedirs(args.out, exist_ok=True)
    path = os.path.join(args.out, f"design_case_{args.case}.json")
    with open(path, "w") as fh:
        json.dump({"case": args.case, "repeats": args.repeats, "medians": med, "runs": runs}, fh, indent=1)
    print(f"wrote {path}")
    if tmp is not None:
        tmp.cleanup()


def main(argv=None):
    if argv is None and len(sys.argv) == 4 and sys.argv[1] == "--worker":  # one timed design, JSON on stdout
        print(json.dumps(case_worker(sys.argv[2], int(sys.argv[3]))))
        return
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="bench_out", help="output folder (default bench_out)")
    ap.add_argument("--sizes", nargs="+", default=list(SIZES), choices=list(SIZES), help="mesh sizes to run")
    ap.add_argument("--muscles", nargs="+", type=int, default=[1, 2, 4, 8], help="muscle counts to run")
    ap.add_argument("--methods", nargs="+", default=["flattened", "nested", "derivative-free"],
                    help="design methods to compare")
    ap.add_argument("--df-evals", type=int, default=300, help="derivative-free evaluations per muscle (cap)")
    ap.add_argument("--quick", action="store_true", help="the smallest size and fewer muscles only")
    ap.add_argument("--seed", type=int, default=0, help="seed of the true contractions")
    ap.add_argument("--start", default="geometric",
                    help="initial contractions: 'geometric' (each muscle's 1 - L_target/L0) or one number for all")
    ap.add_argument("--models", nargs="+", default=["cable"], choices=["cable", "springs"],
                    help="muscle models (the target is made with the same model); rival comparisons use the first")
    ap.add_argument("--derivatives", default="numeric", choices=["numeric", "assembled", "casadi"],
                    help="the flattened NLP's derivatives (see design_contractions)")
    ap.add_argument("--no-variants", action="store_true", help="skip the flattened variants")
    ap.add_argument("--variants", action="store_true",
                    help="run the flattened variants on 1k nodes, 4 muscles whatever the sizes")
    ap.add_argument("--case", choices=["3k4", "1k4", "300x4"],
                    help="one fresh flattened design by stage (see the module docstring); 3k4: issue 13's target")
    ap.add_argument("--repeats", type=int, default=5, help="--case: processes per version (median reported)")
    ap.add_argument("--against", metavar="REF", help="--case: also run the package as committed at this git ref")
    args = ap.parse_args(argv)
    if args.case:
        run_case(args)
    else:
        run(args)


if __name__ == "__main__":
    t0 = time.perf_counter()
    main()
    print(f"total {time.perf_counter() - t0:.0f} s")
