"""Equilibrium benchmark: a 4 x 1 strip under a large drag, every backend, growing meshes.

For each mesh size and backend it measures, on a freshly built mesh object (so nothing is cached):
model + solver build time, first solve time, iterations, energy; then the time of repeated solves on
the built model with new drags (best of ``--repeat``). It prints a table, writes ``equilibrium.csv`` and
the chart ``equilibrium.png`` into ``--out``.

    python tests/benchmarks/bench_equilibrium.py --out bench_out
    python tests/benchmarks/bench_equilibrium.py --sizes 200,1000 --backends ipopt,newton --scene bend

Slow backends are capped by node count (``--caps``) so the default run finishes in a few minutes.
"""

from __future__ import annotations

import argparse
import csv
import os
import time

import numpy as np

from mdsr_opt import Mesh, NeoHookean, solve_external
from mdsr_opt.mechanics.backends import available_backends

DEFAULT_CAPS = {"ipopt-lbfgs": 1200, "uno": 400, "scipy": 12000, "sqpmethod": 12000}


def strip_mesh(nodes: int) -> Mesh:
    # Triangle with q30 on a 4 x 1 strip gives about 3.3 / max_area nodes
    return Mesh.from_polygon([[0, 0], [4, 0], [4, 1], [0, 1]], max_area=3.3 / nodes)


def scene(mesh: Mesh, kind: str, scale: float = 1.0):
    P = mesh.points
    left = np.nonzero(P[:, 0] < 1e-9)[0]
    right = np.nonzero(P[:, 0] > 4 - 1e-9)[0]
    if kind == "stretch":  # stretch by the strip's own width
        return left, (right, P[right] + [1.0 * scale, 0.0])
    angle = np.pi / 2 * scale  # bend through 90 degrees
    R = 4.0 / angle
    th = P[right, 0] / 4.0 * angle
    rr = R - P[right, 1]
    return left, (right, np.column_stack([rr * np.sin(th), R - rr * np.cos(th)]))


def run(sizes, backends, scene_kind, repeat, caps, log=print):
    mat = NeoHookean(E=1.0, nu=0.3)
    rows = []
    for target in sizes:
        base = strip_mesh(target)
        for b in backends:
            if base.n_nodes > caps.get(b, 10 ** 9):
                log(f"{base.n_nodes:>6} {b:<12} skipped (cap {caps[b]} nodes; raise with --caps)")
                continue
            mesh = Mesh(base.points, base.triangles)  # fresh object: nothing cached
            anchors, drags = scene(mesh, scene_kind)
            t0 = time.perf_counter()
            res = solve_external(mesh, mat, anchors, drags, backend=b, max_iter=3000)
            wall = time.perf_counter() - t0
            rep = []
            for k in range(repeat if res.solve_time < 5.0 else 1):  # slow backends: one repeat
                a2, d2 = scene(mesh, scene_kind, scale=0.9 - 0.05 * k)
                t1 = time.perf_counter()
                r2 = solve_external(mesh, mat, a2, d2, backend=b, max_iter=3000)
                rep.append((time.perf_counter() - t1, r2.success))
            row = dict(scene=scene_kind, nodes=mesh.n_nodes, backend=b, build_s=res.build_time,
                       solve_s=res.solve_time, fresh_total_s=wall, iterations=res.iterations,
                       load_steps=len(res.steps), energy=res.energy, success=res.success,
                       repeat_s=min(t for t, _ in rep) if rep else float("nan"),
                       repeat_success=all(ok for _, ok in rep))
            rows.append(row)
            log(f"{row['nodes']:>6} {b:<12} build {row['build_s']:7.3f} s  solve {row['solve_s']:7.3f} s  "
                f"fresh total {wall:7.3f} s  it {row['iterations']:>4}  steps {row['load_steps']}  "
                f"E {row['energy']:.10f}  ok {row['success']}  repeat {row['repeat_s']:.3f} s")
    return rows


def chart(rows, path):
    import matplotlib.pyplot as plt

    from mdsr_opt.plot.common import save_figure

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for b in sorted({r["backend"] for r in rows}):
        rr = sorted((r for r in rows if r["backend"] == b), key=lambda r: r["nodes"])
        n = [r["nodes"] for r in rr]
        axes[0].loglog(n, [r["fresh_total_s"] for r in rr], "o-", label=b)
        axes[1].loglog(n, [r["repeat_s"] for r in rr], "o-", label=b)
    axes[0].set_title("fresh: build + solve")
    axes[1].set_title("repeated solve, new drags (model reused)")
    axes[1].axhline(0.15, color="gray", ls=":", lw=1)
    axes[1].text(220, 0.16, "0.15 s target at 3k nodes", color="gray", fontsize=8)
    axes[0].axhline(3.0, color="gray", ls=":", lw=1)
    axes[0].text(220, 3.2, "3 s target at 10k nodes", color="gray", fontsize=8)
    for ax in axes:
        ax.set_xlabel("nodes")
        ax.set_ylabel("seconds")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=8)
    save_figure(fig, path)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", default="200,1000,3000,10000", help="approximate node counts")
    ap.add_argument("--backends", default="all", help="comma list or 'all'")
    ap.add_argument("--scene", default="stretch", choices=["stretch", "bend"],
                    help="strip stretched by its width, or bent through 90 degrees")
    ap.add_argument("--repeat", type=int, default=3, help="repeated solves on the built model (best is reported)")
    ap.add_argument("--caps", default="", help="per-backend node caps, e.g. uno=5000,scipy=20000")
    ap.add_argument("--out", default="bench_out", help="output folder (default bench_out)")
    a = ap.parse_args(argv)
    backends = available_backends() if a.backends == "all" else a.backends.split(",")
    caps = dict(DEFAULT_CAPS)
    for item in filter(None, a.caps.split(",")):
        k, v = item.split("=")
        caps[k] = int(v)
    rows = run([int(s) for s in a.sizes.split(",")], backends, a.scene, a.repeat, caps)
    os.makedirs(a.out, exist_ok=True)
    with open(os.path.join(a.out, f"equilibrium_{a.scene}.csv"), "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    chart(rows, os.path.join(a.out, f"equilibrium_{a.scene}.png"))
    print("\n" + markdown(rows))
    print(f"wrote {a.out}/equilibrium_{a.scene}.csv and .png")


def markdown(rows) -> str:
    """The table as the README shows it (Markdown)."""
    lines = ["| nodes | backend | iterations | fresh: build + solve s | repeat solve s | energy |",
             "| ---: | --- | ---: | ---: | ---: | --- |"]
    for r in rows:
        lines.append(f"| {r['nodes']} | `{r['backend']}` | {r['iterations']} | {r['fresh_total_s']:.2f} | "
                     f"{r['repeat_s']:.3f} | {r['energy']:.10f}" + ("" if r["success"] else " (failed)") + " |")
    return "\n".join(lines)


if __name__ == "__main__":
    main()
