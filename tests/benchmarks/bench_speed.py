"""Speed of the equilibrium solve against the projected-Newton baseline and the sparse-Newton floor.

For each size (about 1k, 3k, 10k nodes; 30k with ``--big``) on a 4 x 1 strip (``--scene stretch`` or
``bend``), in one process and interleaved, ``--repeat`` times (medians reported):

* IPOPT (the default backend) on a fresh mesh object: model build, solve, iterations; then a repeated solve
  on the built model (new drags);
* the ``newton`` backend (:mod:`mdsr_opt.mechanics.newton`) on a fresh mesh object, same tolerance, through the same
  ``solve_external`` pipeline (predictor, load steps, stability check): its wall time, its solver time
  alone, and the ratio IPOPT fresh / newton fresh;
* the floor ``(iterations + 1) x (assembly + factorisation)``: the time of one vectorised assembly of the
  gradient and Hessian plus one sparse factorisation (and solve) with the mesh's reused ordering, at the
  solution, with one BLAS thread as the solves run (:func:`mdsr_opt.mechanics.newton.step_seconds`), times
  IPOPT's iterations plus one; and the multiples of the floor of the fresh and the repeated solve;
* peak memory (unless ``--no-memory``): each backend's fresh solve runs alone in a new Python process,
  which reports its resident set after the imports and the mesh, and its peak during the solve. The
  whole process is measured, not ``tracemalloc``: that sees only allocations through Python's allocator
  (numpy arrays), not the C/C++ heap of CasADi, IPOPT, MUMPS and SuperLU where a solver's memory goes. The
  table gives both peaks and the ratio of the solves' own memory (peak minus the after-import level,
  which is the same ~100 MB of libraries for both), the stricter of the two comparisons. The
  high-water mark is reset before the solve (``/proc/self/clear_refs``), so the imports' transient peak
  does not hide a small solve's.

Prints one table (also as markdown) and writes ``speed.csv`` and ``speed.png`` (time against nodes, log-log,
with the fitted slope of the fresh IPOPT time) into ``--out``.

    python tests/benchmarks/bench_speed.py --out bench_out
    python tests/benchmarks/bench_speed.py --big --repeat 3
"""

from __future__ import annotations

import argparse
import csv
import os
import json
import resource
import statistics
import subprocess
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


def _status_mb(field: str) -> float:
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith(field + ":"):
                return float(line.split()[1]) / 1024.0  # kB
    raise KeyError(field)


def _memory_child(backend: str, target: int, kind: str, tol: float) -> None:
    """Run in a fresh process: one fresh solve; print the resident set (MB) before it and its peak during it.

    The peak is the kernel's high-water mark ``VmHWM``, reset just before the solve by writing 5 to
    ``/proc/self/clear_refs`` (Linux), so a transient peak of the imports does not hide the solve's; where
    that is not possible, ``ru_maxrss`` (the peak since the process started)."""
    base = strip_mesh(target)
    mesh = Mesh(base.points, base.triangles)
    anchors, drags = scene(mesh, kind)
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
        before, peak_of = _status_mb("VmRSS"), (lambda: _status_mb("VmHWM"))
    except OSError:
        before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
        peak_of = (lambda: resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0)
    res = solve_external(mesh, MAT, anchors, drags, tol=tol, backend=backend)
    print(json.dumps({"before": before, "peak": peak_of(), "success": bool(res.success)}))


def peak_memory(backend: str, target: int, kind: str, tol: float) -> dict:
    """``{"before", "peak"}`` MB of a fresh solve in its own process (see the module docstring)."""
    out = subprocess.run([sys.executable, os.path.abspath(__file__), "--memory-child", backend, "--sizes",
                          str(target), "--scene", kind, "--tol", repr(tol)],
                         capture_output=True, text=True, check=True)
    rec = json.loads(out.stdout.strip().splitlines()[-1])
    if not rec["success"]:
        raise RuntimeError(f"{backend} failed in the memory run at {target} nodes")
    return rec


def measure(target: int, kind: str, repeat: int, tol: float, log=print, memory: bool = True) -> dict:
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
    if memory:
        mi, mn = peak_memory("ipopt", target, kind, tol), peak_memory("newton", target, kind, tol)
        row.update(ipopt_peak_mb=mi["peak"], newton_peak_mb=mn["peak"], import_mb=mn["before"],
                   mem_ratio=mi["peak"] / mn["peak"],
                   ipopt_own_mb=mi["peak"] - mi["before"], newton_own_mb=mn["peak"] - mn["before"],
                   mem_ratio_solve=(mi["peak"] - mi["before"]) / max(mn["peak"] - mn["before"], 1.0))
    log(f"{row['nodes']:>6} build {row['build_s']:.3f} s  solve {row['solve_s']:.3f} s  it {it}  fresh "
        f"{row['fresh_s']:.3f} s  repeat {row['repeat_s']:.3f} s  newton {row['newton_s']:.3f} s (solve "
        f"{row['newton_solve_s']:.3f} s)  ratio "
        f"{row['ratio']:.2f}  floor {floor:.3f} s  x floor {row['fresh_x_floor']:.1f} / "
        f"{row['repeat_x_floor']:.1f}  |dE|/E {row['energy_rel_diff']:.1e}"
        + (f"  peak MB {row['ipopt_peak_mb']:.0f} / {row['newton_peak_mb']:.0f} (solve's own: ratio "
           f"{row['mem_ratio_solve']:.2f})" if memory else ""))
    return row


def slope(rows, key="fresh_s") -> float:
    n = np.log([r["nodes"] for r in rows])
    t = np.log([r[key] for r in rows])
    return float(np.polyfit(n, t, 1)[0]) if len(rows) > 1 else float("nan")


def markdown(rows) -> str:
    mem = "ipopt_peak_mb" in rows[0]
    head = ("| nodes | build s | solve s | iterations | fresh s | repeated s | newton s | ratio fresh/newton | "
            "floor s | fresh / floor | repeated / floor |" + (" peak MB ipopt / newton | memory ratio (solve's "
                                                             "own) |" if mem else ""))
    lines = [head, "|" + "---:|" * (13 if mem else 11)]
    for r in rows:
        lines.append(f"| {r['nodes']:,} | {r['build_s']:.3f} | {r['solve_s']:.3f} | {r['iterations']} | "
                     f"{r['fresh_s']:.3f} | {r['repeat_s']:.3f} | {r['newton_s']:.3f} | {r['ratio']:.2f} | "
                     f"{r['floor_s']:.3f} | {r['fresh_x_floor']:.1f} | {r['repeat_x_floor']:.1f} |"
                     + (f" {r['ipopt_peak_mb']:.0f} / {r['newton_peak_mb']:.0f} | {r['mem_ratio_solve']:.2f} |"
                        if mem else ""))
    return "\n".join(lines)


def chart(rows, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = [r["nodes"] for r in rows]
    mem = "ipopt_peak_mb" in rows[0]
    fig, axes = plt.subplots(1, 2 if mem else 1, figsize=(11.5 if mem else 6.5, 4.2), squeeze=False)
    ax = axes[0, 0]
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
    if mem:
        bx = axes[0, 1]
        bx.loglog(n, [max(r["ipopt_own_mb"], 0.1) for r in rows], "o-", label="IPOPT fresh")
        bx.loglog(n, [max(r["newton_own_mb"], 0.1) for r in rows], "^-", label="newton baseline, fresh")
        bx.set_xlabel("mesh nodes")
        bx.set_ylabel(f"MB above the process before the solve (~{rows[0]['import_mb']:.0f} MB)")
        bx.set_title("peak memory of a fresh solve (VmHWM, own process)", fontsize=9)
        bx.grid(True, which="both", alpha=0.3)
        bx.legend(fontsize=7, loc="upper left")
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
    ap.add_argument("--no-memory", action="store_true", help="skip the peak-memory runs")
    ap.add_argument("--memory-child", default=None, help=argparse.SUPPRESS)  # internal: one solve, print RSS
    a = ap.parse_args(argv)
    sizes = [int(s) for s in a.sizes.split(",") if s.strip()] + ([30000] if a.big else [])
    if a.memory_child:
        return _memory_child(a.memory_child, sizes[0], a.scene, a.tol)
    rows = [measure(s, a.scene, max(1, a.repeat), a.tol, memory=not a.no_memory) for s in sizes]
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
    print(f"wrote {os.path.join(a.out, 'speed.csv')} and {os.path.join(a.out, 'speed.png')}")
    return rows


if __name__ == "__main__":
    main()
