"""Benchmark of driving-quantity design: flattened NLP vs nested (adjoint) vs derivative-free.

For 1, 2, 4 and 8 muscles on rectangle meshes of about 300, 1k and 3k nodes, a target is made by contracting
the muscles by known amounts, rotating and shifting the result; each method designs the contractions from
the same initial guess. Prints a table, writes ``design_bench.csv`` and ``design_bench.png`` (difference
against time) to ``--out``. Also measures the flattened NLP's sensitivity to scaling, warm start, Hessian
(exact vs Gauss-Newton) and derivatives (assembled term by term vs CasADi's symbolic ones) on the 1k-node,
4-muscle case.

Run:  python tests/benchmarks/bench_design.py --out bench_out
      python tests/benchmarks/bench_design.py --quick          # 300 nodes only, 1-4 muscles
      python tests/benchmarks/bench_design.py --sizes 1k 3k --muscles 4 --methods flattened --variants
                                                          # flattened only: build and solve, and the variants
      python tests/benchmarks/bench_design.py --quick --derivatives casadi   # the flattened NLP's SX path
      python tests/benchmarks/bench_design.py --sizes 1k 3k --muscles 4 --methods flattened --models cable springs
                                                          # exact cable vs dummy springs: build, solve, verify
"""

from __future__ import annotations

import argparse
import csv
import math
import os
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
                    kw["initial"] = np.full(m, float(args.start))
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


def main(argv=None):
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
    ap.add_argument("--derivatives", default="assembled", choices=["assembled", "casadi"],
                    help="the flattened NLP's derivatives (see design_contractions)")
    ap.add_argument("--no-variants", action="store_true", help="skip the flattened variants")
    ap.add_argument("--variants", action="store_true",
                    help="run the flattened variants on 1k nodes, 4 muscles whatever the sizes")
    run(ap.parse_args(argv))


if __name__ == "__main__":
    t0 = time.perf_counter()
    main()
    print(f"total {time.perf_counter() - t0:.0f} s")
