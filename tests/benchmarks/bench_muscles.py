"""Internal driving: the exact cable against the dummy-spring penalty, side by side in one process.

For each mesh size (a 4 x 1 strip meshed by Triangle) and scene it solves internal driving with

- ``cable``: the exact cable (rope-length constraints, default anchor patches) — the default model;
- ``springs``: the dummy springs per unit rest length, with the same anchor patches (rigid constraints);
- ``springs-plain``: the dummy springs without anchor patches (``anchor_radius=0``): no constraints at all,
  the penalty model as it was before the exact cable;

first on a fresh mesh object (model and solver built: "first" wall time), then ``--repeat`` more times on
the built model ("solve" = the median of the solver's own time, "wall" = the median wall time of the
whole ``solve_internal`` call). The models take turns within each repeat so drifts in machine load hit
them alike. It prints a table with the ratio of each model's median to that of ``springs-plain`` and writes
``muscles.csv`` into ``--out``.

    python tests/benchmarks/bench_muscles.py --sizes 1000,3000 --repeat 7 --out bench_out
"""

from __future__ import annotations

import argparse
import csv
import os
import statistics
import time

import numpy as np

from mdsr_opt import Mesh, Muscle, NeoHookean, solve_internal

MODELS = {"cable": dict(muscle_model="cable"), "springs": dict(muscle_model="springs"),
          "springs-plain": dict(muscle_model="springs", anchor_radius=0.0)}


def strip_mesh(nodes: int) -> Mesh:
    # Triangle with q30 on a 4 x 1 strip gives about 3.3 / max_area nodes
    return Mesh.from_polygon([[0, 0], [4, 0], [4, 1], [0, 1]], max_area=3.3 / nodes)


def side(mesh: Mesh, y: float) -> Muscle:
    """The boundary chain along y = const, left to right (boundary edges are mesh edges)."""
    P = mesh.points
    return Muscle(sorted((int(i) for i in mesh.boundary_nodes if abs(P[i, 1] - y) < 1e-9), key=lambda i: P[i, 0]))


def scene(mesh: Mesh, kind: str):
    if kind == "one":  # one muscle along the bottom: the strip curls
        return [side(mesh, 0.0)], [0.3]
    return [side(mesh, 0.0), side(mesh, 1.0)], [0.3, 0.1]  # "two": bottom and top pull against each other


def run(sizes, scenes, repeat, log=print):
    mat = NeoHookean(E=1.0, nu=0.3)
    rows = []
    for target in sizes:
        base = strip_mesh(target)
        for kind in scenes:
            first, wall, solve, last = {}, {m: [] for m in MODELS}, {m: [] for m in MODELS}, {}
            for name, kw in MODELS.items():
                mesh = Mesh(base.points, base.triangles)  # fresh object: nothing cached
                mus, a = scene(mesh, kind)
                t0 = time.perf_counter()
                res = solve_internal(mesh, mat, mus, a, **kw)
                first[name] = (time.perf_counter() - t0, mesh, mus, a)
            for _ in range(repeat):
                for name, kw in MODELS.items():
                    _, mesh, mus, a = first[name]
                    t0 = time.perf_counter()
                    res = solve_internal(mesh, mat, mus, a, **kw)
                    wall[name].append(time.perf_counter() - t0)
                    solve[name].append(res.solve_time)
                    last[name] = res
            ref_wall = statistics.median(wall["springs-plain"])
            ref_solve = statistics.median(solve["springs-plain"])
            for name in MODELS:
                res = last[name]
                row = {"nodes": base.n_nodes, "scene": kind, "model": name, "success": res.success,
                       "iterations": res.iterations, "steps": len(res.steps),
                       "achieved": ";".join(f"{v:.4f}" for v in res.achieved),
                       "first_s": first[name][0], "wall_median_s": statistics.median(wall[name]),
                       "solve_median_s": statistics.median(solve[name]),
                       "wall_ratio": statistics.median(wall[name]) / ref_wall,
                       "solve_ratio": statistics.median(solve[name]) / ref_solve}
                rows.append(row)
                log(f"{row['nodes']:>6} {kind:<4} {name:<14} ok={str(res.success):<5} it={row['iterations']:>3} "
                    f"steps={row['steps']} achieved={row['achieved']:<15} first={row['first_s']:.3f}s "
                    f"wall={row['wall_median_s']:.3f}s ({row['wall_ratio']:.2f}x) "
                    f"solve={row['solve_median_s']:.3f}s ({row['solve_ratio']:.2f}x)")
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", default="1000,3000", help="approximate node counts")
    ap.add_argument("--scenes", default="one,two", help="comma-separated scenes to time (one, two)")
    ap.add_argument("--repeat", type=int, default=7, help="timed repetitions per case (the median is printed)")
    ap.add_argument("--out", default="bench_out", help="folder for the CSV and the chart")
    a = ap.parse_args(argv)
    rows = run([int(s) for s in a.sizes.split(",")], a.scenes.split(","), a.repeat)
    os.makedirs(a.out, exist_ok=True)
    with open(os.path.join(a.out, "muscles.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    print(f"wrote {os.path.join(a.out, 'muscles.csv')}")


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
