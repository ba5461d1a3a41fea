"""Speed of the equilibrium solve against the projected-Newton baseline and the sparse-Newton floor.

For each size (about 1k, 3k, 10k nodes; 30k with ``--big``) on a 4 x 1 strip (``--scene stretch`` or
``bend``), in one process and interleaved, ``--repeat`` times (medians reported):

* IPOPT (the default backend) on a fresh mesh object: model build, solve, iterations; then a repeated solve
  on the built model (new drags);
* the ``newton`` backend (:mod:`mdsr_opt.newton`) on a fresh mesh object, same tolerance, through the same
  ``solve_external`` pipeline (predictor, load steps, stability check; it also builds the CasADi model,
  which the Newton iterations do not use): its wall time, its solver time alone, and the ratio
  IPOPT fresh / newton fresh;
* the floor ``(iterations + 1) x (assembly + factorisation)``: the time of one vectorised assembly of the
  gradient and Hessian plus one sparse factorisation with a reused ordering, at the solution, times IPOPT's
  iterations plus one; and the multiples of the floor of the fresh and the repeated solve.

Prints one table (also as markdown) and writes ``speed.csv`` and ``speed.png`` (time against nodes, log-log,
with the fitted slope of the fresh IPOPT time) into ``--out``.

    python tests/benchmarks/bench_speed.py --out bench_out
    python tests/benchmarks/bench_speed.py --big --repeat 3
"""

from __future__ import annotations

import argparse
import csv
import os
import statistics
import sys
import time

import numpy as np

_HERE = os.path.dirname(os.path.abspath(__file__))
sys.path[:0] = [_HERE, os.path.dirname(os.path.dirname(_HERE))]  # the benchmarks and this checkout's package
from bench_equilibrium import scene, strip_mesh  # noqa: E402

from mdsr_opt import Mesh, NeoHookean, solve_external  # noqa: E402
from mdsr_opt.mechanics.model import get_model  # noqa: E402
from mdsr_opt.mechanics.newton import step_seconds  # noqa: E402

MAT = NeoHookean(E=1.0, nu=0.3)


def floor_unit(mesh: Mesh, x: np.ndarray, fixed: np.ndarray, reps: int = 5) -> float:
    """Median seconds of one assembly (gradient + Hessian blocks + scatter) and one factorisation with a
    reused ordering, at ``x``."""
    model = get_model(mesh, MAT)
    return step_seconds(model, model.params(MAT), x, fixed, repeat=reps)


def measure(target: int, kind: str, repeat: int, tol: float, log=print) -> dict:
    base = strip_mesh(target)
    rec = {k: [] for k in ("build", "solve", "fresh", "repeat", "newton", "newton_solve", "unit")}
    it, energies = None, set()
    for _ in range(repeat):
        mesh = Mesh(base.points, base.triangles)  # fresh object: nothing cached
        anchors, drags = scene(mesh, kind)
        t0 = time.perf_counter()
        res = solve_external(mesh, MAT, anchors, drags, tol=tol)
        rec["fresh"].append(time.perf_counter() - t0)
        rec["build"].append(res.build_time)
        rec["solve"].append(res.solve_time)
        it = res.iterations
        if not res.success:
            raise RuntimeError(f"IPOPT failed at {mesh.n_nodes} nodes: {res.status}")
        a2, d2 = scene(mesh, kind, scale=0.95)
        t0 = time.perf_counter()
        solve_external(mesh, MAT, a2, d2, tol=tol)
        rec["repeat"].append(time.perf_counter() - t0)
        fresh = Mesh(base.points, base.triangles)
        an, dr = scene(fresh, kind)
        t0 = time.perf_counter()
        nres = solve_external(fresh, MAT, an, dr, tol=tol, backend="newton")
        rec["newton"].append(time.perf_counter() - t0)
        rec["newton_solve"].append(nres.solve_time)
        if not nres.success:
            raise RuntimeError(f"newton failed at {mesh.n_nodes} nodes: {nres.status}")
        energies.add(abs(nres.energy - res.energy) / abs(res.energy))
        fixed = np.zeros(2 * mesh.n_nodes, dtype=bool)
        idx = np.concatenate([np.asarray(anchors), np.asarray(drags[0])])
        fixed[2 * idx] = fixed[2 * idx + 1] = True
        rec["unit"].append(floor_unit(mesh, res.x.reshape(-1), fixed))
    med = {k: statistics.median(v) for k, v in rec.items()}
    floor = (it + 1) * med["unit"]
    row = dict(nodes=base.n_nodes, scene=kind, build_s=med["build"], solve_s=med["solve"], iterations=it,
               fresh_s=med["fresh"], repeat_s=med["repeat"], newton_s=med["newton"], newton_solve_s=med["newton_solve"],
               ratio=med["fresh"] / med["newton"], floor_s=floor, fresh_x_floor=med["fresh"] / floor,
               repeat_x_floor=med["repeat"] / floor, energy_rel_diff=max(energies))
    log(f"{row['nodes']:>6} build {row['build_s']:.3f} s  solve {row['solve_s']:.3f} s  it {it}  fresh "
        f"{row['fresh_s']:.3f} s  repeat {row['repeat_s']:.3f} s  newton {row['newton_s']:.3f} s (solve "
        f"{row['newton_solve_s']:.3f} s)  ratio "
        f"{row['ratio']:.2f}  floor {floor:.3f} s  x floor {row['fresh_x_floor']:.1f} / "
        f"{row['repeat_x_floor']:.1f}  |dE|/E {row['energy_rel_diff']:.1e}")
    return row


def slope(rows, key="fresh_s") -> float:
    n = np.log([r["nodes"] for r in rows])
    t = np.log([r[key] for r in rows])
    return float(np.polyfit(n, t, 1)[0]) if len(rows) > 1 else float("nan")


def markdown(rows) -> str:
    head = ("| nodes | build s | solve s | iterations | fresh s | repeated s | newton s | ratio fresh/newton | "
            "floor s | fresh / floor | repeated / floor |")
    lines = [head, "|" + "---:|" * 11]
    for r in rows:
        lines.append(f"| {r['nodes']:,} | {r['build_s']:.3f} | {r['solve_s']:.3f} | {r['iterations']} | "
                     f"{r['fresh_s']:.3f} | {r['repeat_s']:.3f} | {r['newton_s']:.3f} | {r['ratio']:.2f} | "
                     f"{r['floor_s']:.3f} | {r['fresh_x_floor']:.1f} | {r['repeat_x_floor']:.1f} |")
    return "\n".join(lines)


def chart(rows, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = [r["nodes"] for r in rows]
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for key, label, style in (("fresh_s", "IPOPT fresh (build + solve)", "o-"),
                              ("repeat_s", "IPOPT repeated", "s--"),
                              ("newton_s", "newton baseline, fresh", "^-"),
                              ("floor_s", "floor (it + 1) x (assembly + factorisation)", "k:")):
        ax.loglog(n, [r[key] for r in rows], style, label=label)
    ax.set_xlabel("mesh nodes")
    ax.set_ylabel("seconds")
    ax.set_title(f"equilibrium ({rows[0]['scene']}): log-log slope of fresh IPOPT {slope(rows):.2f}", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="upper left")
    fig.savefig(path, dpi=120, bbox_inches="tight")
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", default="1000,3000,10000", help="approximate node counts (comma list)")
    ap.add_argument("--big", action="store_true", help="add the 30,000-node size")
    ap.add_argument("--scene", default="stretch", choices=["stretch", "bend"], help="strip stretched or bent")
    ap.add_argument("--repeat", type=int, default=3, help="paired runs per size (medians are reported)")
    ap.add_argument("--tol", type=float, default=1e-8, help="solver tolerance (both backends)")
    ap.add_argument("--out", default="bench_out", help="output folder for speed.csv and speed.png")
    a = ap.parse_args(argv)
    sizes = [int(s) for s in a.sizes.split(",") if s.strip()] + ([30000] if a.big else [])
    rows = [measure(s, a.scene, max(1, a.repeat), a.tol) for s in sizes]
    os.makedirs(a.out, exist_ok=True)
    with open(os.path.join(a.out, "speed.csv"), "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    chart(rows, os.path.join(a.out, "speed.png"))
    print()
    print(markdown(rows))
    print(f"\nlog-log slope of the fresh IPOPT time: {slope(rows):.2f}; of the newton baseline: "
          f"{slope(rows, 'newton_s'):.2f}")
    return rows


if __name__ == "__main__":
    main()
