"""Benchmark of muscle routing: time of ``route_muscles`` against mesh size.

Three targets on unstructured (Triangle) meshes of growing size:

* ``arc``      - an 8 x 2 strip bent onto a circular arc (one long muscle on the inner side);
* ``oblique``  - a 4 x 2 plate shortened by 20 % along a direction at 35 degrees (many zig-zag muscles);
* ``uneven``   - the 8 x 2 strip bent with a curvature that grows fourfold along it.

The budget is 0.5 s for a 3k-node mesh. Timed: ``route_muscles`` as a user calls it (input checks,
contraction graph, seeds, growth, stats), once on a fresh mesh ("cold": the mesh's cached edge data are
built inside the call) and as the best of ``--repeat`` further calls ("warm"). "K_h=0 s" is the warm
time without the growth heuristic (no shortest-path fields at all), so the difference to "warm s" is
what the heuristic costs; "fields" counts the Dijkstra runs (one per endpoint whose distance field
was needed).

Usage::

    python tests/benchmarks/bench_routing.py --out bench_out
    python tests/benchmarks/bench_routing.py --quality --out bench_out   # routing-quality table
    python tests/benchmarks/bench_routing.py --ka-sweep                  # K_a sweep of the Figure 6 targets

``--quality`` runs :func:`mdsr_opt.studies.routing_quality.routing_quality` over every case of the problem library
(coarse, or ``--resolution``) and writes ``routing_quality.csv`` and ``routing_quality.md``. ``--ka-sweep``
routes the five Figure 6 targets at K_a = 0.5 .. 32 and prints the muscle counts and edge counts, the
sweep the Figure 6 K_a pairs were chosen from.

prints a table and writes ``routing_timing.png`` (time against nodes, with the budget) and
``routing_examples.png`` (contraction graph and muscles of the 3k-node cases) to ``--out``.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time

import numpy as np

from mdsr_opt import Mesh
from mdsr_opt.synthesis import routing
from mdsr_opt.synthesis import routing_search
from mdsr_opt.synthesis.routing import contraction_graph, route_muscles

BUDGET_S = 0.5
BUDGET_NODES = 3000


def _bend(X, kappa, length, y_axis):
    s = np.linspace(0.0, length, 4001)
    k = kappa(s)
    th = np.concatenate([[0.0], np.cumsum(0.5 * (k[1:] + k[:-1]) * np.diff(s))])
    cx = np.concatenate([[0.0], np.cumsum(0.5 * (np.cos(th[1:]) + np.cos(th[:-1])) * np.diff(s))])
    cy = np.concatenate([[0.0], np.cumsum(0.5 * (np.sin(th[1:]) + np.sin(th[:-1])) * np.diff(s))])
    T = np.interp(X[:, 0], s, th)
    y = X[:, 1] - y_axis
    return np.column_stack([np.interp(X[:, 0], s, cx) - y * np.sin(T), np.interp(X[:, 0], s, cy) + y * np.cos(T)])


def _arc(X):
    return _bend(X, lambda s: np.full_like(s, 1.0 / 6.0), 8.0, 1.0)


def _uneven(X):
    return _bend(X, lambda s: 0.08 * (1.0 + 3.0 * s / 8.0), 8.0, 1.0)


def _oblique(X):
    d = np.array([np.cos(np.radians(35.0)), np.sin(np.radians(35.0))])
    return X @ (np.eye(2) - 0.2 * np.outer(d, d)).T


CASES = {
    "arc": ([[0, 0], [8, 0], [8, 2], [0, 2]], _arc),
    "oblique": ([[0, 0], [4, 0], [4, 2], [0, 2]], _oblique),
    "uneven": ([[0, 0], [8, 0], [8, 2], [0, 2]], _uneven),
}


def _mesh(outline, n_nodes):
    """A Triangle mesh of ``outline`` with about ``n_nodes`` nodes."""
    p = np.asarray(outline, dtype=float)
    area = 0.5 * abs(float(np.dot(p[:, 0], np.roll(p[:, 1], -1)) - np.dot(p[:, 1], np.roll(p[:, 0], -1))))
    return Mesh.from_polygon(outline, max_area=0.8 * area / n_nodes)


def _count_fields(mesh, target) -> int:
    """Number of Dijkstra runs (distance fields) in one routing call."""
    calls = [0]
    real = routing_search.dijkstra

    def counting(*args, **kwargs):
        calls[0] += 1
        return real(*args, **kwargs)

    routing_search.dijkstra = counting
    try:
        route_muscles(mesh, target)
    finally:
        routing_search.dijkstra = real
    return calls[0]


def _ka_sweep(resolution) -> int:
    """Muscle counts and edge counts of the Figure 6 targets routed at K_a = 0.5 .. 32."""
    import warnings

    from mdsr_opt.mechanics.equilibrium import solve_external
    from mdsr_opt.scenes.library import get_problem, problems_dir

    fig6 = __import__("importlib").import_module("problems.figure6") if problems_dir() else None
    kas = (0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0)
    print("target".ljust(20) + "".join(f"K_a={k:g}".ljust(16) for k in kas))
    for name, cname, pair in fig6.TARGETS:
        scene = get_problem(name, resolution=resolution)
        case = scene.case(cname)
        x = solve_external(scene.mesh, scene.material, case.anchors, case.drags).x
        cells = []
        for k in kas:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", routing.RoutingWarning)
                r = route_muscles(scene.mesh, x, K_a=k, **fig6.ROUTING)
            cells.append(f"{len(r)}:" + ",".join(str(s.n_edges) for s in r.stats))
        print(f"{name}/{cname}".ljust(20) + "".join(c.ljust(16) for c in cells) + f"  (chosen {pair})")
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="bench_out", help="output directory for the PNG charts")
    ap.add_argument("--sizes", default="500,1000,2000,3000,5000", help="target node counts")
    ap.add_argument("--repeat", type=int, default=3, help="warm repetitions (best is reported)")
    ap.add_argument("--quality", action="store_true", help="write the routing-quality table of the library")
    ap.add_argument("--ka-sweep", action="store_true", help="print the K_a sweep of the Figure 6 targets")
    ap.add_argument("--resolution", default="coarse", help="scene resolution for --quality / --ka-sweep")
    args = ap.parse_args(argv)
    res_arg = int(args.resolution) if args.resolution.isdigit() else args.resolution
    if args.quality:
        from mdsr_opt.studies.routing_quality import routing_quality, write_quality_table

        rows = routing_quality(resolution=res_arg, log=lambda s: print(s, flush=True))
        paths = write_quality_table(rows, os.path.join(args.out, "routing_quality.csv"),
                                    os.path.join(args.out, "routing_quality.md"))
        print("wrote " + ", ".join(paths))
        return 0 if all(r.success for r in rows) else 1
    if args.ka_sweep:
        return _ka_sweep(res_arg)
    sizes = [int(s) for s in args.sizes.split(",")]
    os.makedirs(args.out, exist_ok=True)

    print(f"python {platform.python_version()}, numpy {np.__version__}, {platform.machine()}")
    head = (f"{'case':<8} {'nodes':>6} {'edges':>6} {'muscles':>7} {'edges in':>8} {'graph s':>8} "
            f"{'cold s':>8} {'warm s':>8} {'K_h=0 s':>8} {'fields':>6}")
    print(head)
    print("-" * len(head))
    rows, examples = [], {}
    for name, (outline, make_target) in CASES.items():
        for n in sizes:
            mesh = _mesh(outline, n)
            target = make_target(mesh.points)
            t0 = time.perf_counter()
            res = route_muscles(mesh, target)  # cold: fresh mesh, its edge caches are built in here
            cold = time.perf_counter() - t0
            warm = []
            for _ in range(args.repeat):
                t0 = time.perf_counter()
                route_muscles(mesh, target)
                warm.append(time.perf_counter() - t0)
            no_h = []
            for _ in range(args.repeat):
                t0 = time.perf_counter()
                route_muscles(mesh, target, K_h=0.0)
                no_h.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            contraction_graph(mesh, target)
            graph_s = time.perf_counter() - t0
            n_in = sum(s.n_edges for s in res.stats)
            rows.append((name, mesh.n_nodes, cold, min(warm)))
            print(f"{name:<8} {mesh.n_nodes:>6d} {len(mesh.edges):>6d} {len(res):>7d} {n_in:>8d} "
                  f"{graph_s:>8.3f} {cold:>8.3f} {min(warm):>8.3f} {min(no_h):>8.3f} "
                  f"{_count_fields(mesh, target):>6d}")
            if abs(n - BUDGET_NODES) < 1:
                examples[name] = (mesh, target, res)

    from mdsr_opt.plot.design import plot_contraction_graph, plot_routing, plot_routing_timings
    from mdsr_opt.plot.common import save_figure
    import matplotlib.pyplot as plt

    series = {}
    for name in CASES:
        pts = [r for r in rows if r[0] == name]
        series[f"{name} cold"] = ([r[1] for r in pts], [r[2] for r in pts])
        series[f"{name} warm"] = ([r[1] for r in pts], [r[3] for r in pts])
    fig = plot_routing_timings(series, budget=BUDGET_S, budget_nodes=BUDGET_NODES)
    path = save_figure(fig, os.path.join(args.out, "routing_timing.png"))
    print(f"wrote {path}")
    if examples:
        fig, axs = plt.subplots(len(examples), 3, figsize=(17, 3.6 * len(examples)), squeeze=False)
        for row, (name, (mesh, target, res)) in zip(axs, examples.items()):
            plot_contraction_graph(mesh, target, res.graph, ax=row[0], seeds=res.seeds, lw=0.6)
            plot_routing(mesh, target, res, axes=row[1:], title=None)
            row[0].set_ylabel(f"{name}, {mesh.n_nodes} nodes")
        path = save_figure(fig, os.path.join(args.out, "routing_examples.png"))
        print(f"wrote {path}")

    at_budget = [r for r in rows if abs(r[1] - BUDGET_NODES) <= 0.25 * BUDGET_NODES]
    worst = max((max(r[2], r[3]) for r in at_budget), default=float("nan"))
    ok = worst <= BUDGET_S
    print(f"budget: routing on ~{BUDGET_NODES} nodes <= {BUDGET_S} s: worst {worst:.3f} s -> "
          f"{'PASS' if ok else 'FAIL'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
