"""Benchmark: what the stability check (inertia of a sparse LDL') costs next to the solve it certifies.

Every successful ``solve_external``/``solve_internal`` now ends with a stability check of the returned state:
assembling the Hessian at that state (of the Lagrangian with constraints) and one sparse symmetric
factorisation of its free block (two with constraints, Finsler). The target is at most 10 % of a solve at
3k and 10k nodes. For each size this runs, with the model built beforehand:

- external driving: a 10 x 1 strip, left end anchored, right end moved to (8, 3) (bent, stable);
- internal driving: the exact cable along the top of the strip, contracted by 20 %;

and times the solve (wall clock, median of ``--repeats`` runs) and the stability check alone at the solved
state (uncached: Hessian assembly + check, median of the same number of runs). The ratio printed is
check / (solve - check), the overhead on a solve without the check.

Run:  python tests/benchmarks/bench_stability.py                 # 3k and 10k nodes, 3 repeats
      python tests/benchmarks/bench_stability.py --sizes 3k --repeats 5
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from mdsr_opt import Mesh, Muscle, NeoHookean, get_model, solve_external, solve_internal
from mdsr_opt.mechanics.stability import check_stability

MAT = NeoHookean(E=1.0, nu=0.3)
SIZES = {"3k": (150, 20), "10k": (280, 35)}  # rectangle 10 x 1 with nx x ny cells: 3171 and 10116 nodes


def _check_external(mesh, anchors, dragged, x):
    model = get_model(mesh, MAT)
    p = model.params(MAT)
    nodes = np.r_[anchors, dragged]
    free = np.ones(2 * mesh.n_nodes, bool)
    free[2 * nodes] = free[2 * nodes + 1] = False
    t0 = time.perf_counter()
    chk = check_stability(model.hessian(x.reshape(-1), p), free)
    return time.perf_counter() - t0, chk


def _check_internal(res, mesh, mus):
    """The check exactly as solve_internal runs it (uncached): multipliers, Lagrangian Hessian, Finsler."""
    from mdsr_opt.mechanics.equilibrium import _constrained_model, gauge_coordinates, _muscle_constraints
    from mdsr_opt.mechanics.loadsteps import _stability_at
    from mdsr_opt.mechanics.anchors import check_anchor_radius

    emodel = get_model(mesh, MAT)
    mc = _muscle_constraints(mesh, mus, check_anchor_radius(mesh, None))
    cm = _constrained_model(emodel, mc, True)
    fixed = np.zeros(2 * mesh.n_nodes, bool)
    fixed[list(gauge_coordinates(mesh))] = True
    # the result is aligned to rest; the check is invariant, but the gauge must hold its rest values
    x = res.x.reshape(-1)
    p = cm.params(emodel.params(MAT), (1.0 - res.commanded) * mc.rest_lengths)
    cm.__dict__.pop("_last_stability", None)
    t0 = time.perf_counter()
    chk = _stability_at(cm, p, x, fixed)
    return time.perf_counter() - t0, chk


def run(size: str, repeats: int) -> list[dict]:
    nx, ny = SIZES[size]
    mesh = Mesh.rectangle(10.0, 1.0, nx, ny)
    P = mesh.points
    left = np.flatnonzero(P[:, 0] == 0.0)
    right = np.flatnonzero(P[:, 0] == 10.0)
    drags = {int(i): (P[i, 0] - 2.0, P[i, 1] + 3.0) for i in right}
    top = sorted(np.flatnonzero(P[:, 1] == 1.0), key=lambda i: P[i, 0])
    mus = [Muscle(top[2:-2])]
    rows = []
    # build once (not timed)
    solve_external(mesh, MAT, left, drags)
    solve_internal(mesh, MAT, mus, [0.2])
    for mode in ("external", "internal"):
        t_solve, t_check, res = [], [], None
        for _ in range(repeats):
            t0 = time.perf_counter()
            res = solve_external(mesh, MAT, left, drags) if mode == "external" else \
                solve_internal(mesh, MAT, mus, [0.2])
            t_solve.append(time.perf_counter() - t0)
            tc, chk = _check_external(mesh, left, right, res.x) if mode == "external" else \
                _check_internal(res, mesh, mus)
            t_check.append(tc)
            assert res.success and chk.stable, res.status
        ts, tc = statistics.median(t_solve), statistics.median(t_check)
        rows.append({"size": size, "nodes": mesh.n_nodes, "mode": mode, "solve_s": ts, "check_s": tc,
                     "ratio": tc / max(ts - tc, 1e-12), "method": chk.method})
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", nargs="+", default=list(SIZES), choices=list(SIZES), help="mesh sizes to time")
    ap.add_argument("--repeats", type=int, default=3, help="timed repetitions per case (the median is printed)")
    args = ap.parse_args(argv)
    print(f"{'size':>5} {'nodes':>6} {'mode':>9} {'solve [s]':>10} {'check [s]':>10} {'check/solve':>12}  method")
    for size in args.sizes:
        for r in run(size, args.repeats):
            print(f"{r['size']:>5} {r['nodes']:>6} {r['mode']:>9} {r['solve_s']:>10.3f} {r['check_s']:>10.4f} "
                  f"{100 * r['ratio']:>11.1f}%  {r['method']}", flush=True)


if __name__ == "__main__":
    main()
