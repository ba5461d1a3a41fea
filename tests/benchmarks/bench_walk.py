"""The gecko's walk under mesh refinement, with one layout: the muscles are designed once on the coarse mesh, the
gait's strokes are scheduled once, and the same ropes, strokes and feet are walked on a base mesh and on nested
refinements of it (every triangle split into four, :mod:`mdsr_opt.synthesis.walkstudy`). The base mesh is the
coarse one refined twice near the ropes' ends (within 0.4 and 0.2 cm): the end patches (radius 0.19 cm) hold
one node on the coarse mesh (0.43 cm edges), a point force that sinks further into every refinement, so the
body bends less for the same strokes until the patches are resolved (10-18 nodes each). Weight on two diagonal
feet at a time (front left and hind right for the first half of the cycle, the other pair for the second),
mu 0.5. Prints the distance per cycle on each mesh, its changes and their Richardson estimate, and writes the
chart. The coarse mesh's legs are about one element wide, so its far field bends too stiffly as well: a round
with a distance beyond the body's size splits every triangle (``--local 20 0.3``: the coarse mesh split once,
then refined near the ends: 795, 3000, 11643 nodes).

    python tests/benchmarks/bench_walk.py                     # 3 levels (411, 1543, 5973 nodes), 2 cycles
    python tests/benchmarks/bench_walk.py --local             # the coarse mesh's own refinements (146, 496, 1811)
    python tests/benchmarks/bench_walk.py --levels 2 --cycles 1 --out bench_out
"""

from __future__ import annotations

import argparse
import importlib.util
import time
from pathlib import Path

import numpy as np


def gecko(resolution="coarse"):
    spec = importlib.util.spec_from_file_location("gecko_scene", Path(__file__).parents[2] / "problems" / "gecko.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.build(resolution)


def layout_of(sc):
    """The gecko's shared muscle layout of its two bends (designed once)."""
    from mdsr_opt.scenes.runner import run_case
    from mdsr_opt.synthesis.poses import design_poses

    targets = {c: run_case(sc, c, photo=False).setup.target for c in sc.gait.poses}
    return design_poses(sc.mesh, sc.material, targets, max_muscles=sc.gait.max_muscles,
                        routing_options=sc.routing_options, design_options=sc.design_options, compare=False)


def diagonal_touching(sc) -> np.ndarray:
    """Feet 1 and 4 down for the first half of the cycle, feet 2 and 3 for the second."""
    F = len(sc.gait.sequence) * sc.gait.frames_per_step
    T = np.zeros((F, 4), dtype=bool)
    T[: F // 2, [0, 3]] = True
    T[F // 2:, [1, 2]] = True
    return T


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--levels", type=int, default=3, help="meshes: the scene's and its nested refinements")
    ap.add_argument("--cycles", type=int, default=2, help="gait cycles walked on each mesh")
    ap.add_argument("--mu", type=float, default=0.5, help="the table's Coulomb friction coefficient")
    ap.add_argument("--anchor-radius", type=float, default=None,
                    help="the ropes' end patches (cm; the walk then starts from rest); default the layout's")
    ap.add_argument("--local", type=float, nargs="*", default=[0.4, 0.2],
                    help="distances (cm) of the rounds of refinement near the ropes' ends that make the base mesh; "
                         "none: the coarse mesh")
    ap.add_argument("--out", default="bench_out",
                    help="folder for the chart of distance per cycle against nodes (walk_refinement.png)")
    a = ap.parse_args(argv)
    out = Path(a.out)
    if out.exists() and not out.is_dir():  # at the door, not after the study's minutes
        ap.error(f"--out {a.out}: not a folder")
    out.mkdir(parents=True, exist_ok=True)

    from mdsr_opt.plot.common import save_figure
    from mdsr_opt.plot.walk import plot_walk_refinement
    from mdsr_opt.synthesis.walkstudy import richardson, walk_scene_refinement

    sc = gecko("coarse")
    t0 = time.perf_counter()
    lay = layout_of(sc)
    print(f"layout: {len(lay.muscles)} muscles designed once on {sc.mesh.n_nodes} nodes "
          f"({time.perf_counter() - t0:.0f} s)")

    radius = lay.anchor_radius if a.anchor_radius is None else a.anchor_radius

    def report(level, mesh, r):
        d = r.distance
        slid = sorted(k for k, v in r.feet_slipping.items() if v.any())
        print(f"  level {level}: {mesh.n_nodes:5d} nodes (smallest angle {mesh.quality()['min_angle_deg']:.1f} deg), "
              f"{int(r.frame_success.sum())}/{len(r.frame_success)} frames solved, distance per cycle "
              f"{', '.join(f'{v:.4f}' for v in d)} {r.units}, rotation per cycle "
              f"{', '.join(f'{v:.2f}' for v in np.degrees(r.rotation))} deg, feet sliding as a whole: "
              f"{', '.join(slid) or 'none'} ({r.time:.0f} s)", flush=True)

    print(f"anchor radius {radius:.3g} {sc.units} (coarse mean edge {sc.mesh.edge_lengths.mean():.3g}); base mesh: "
          + (f"coarse refined near the ropes' ends within {', '.join(f'{d:g}' for d in a.local)} {sc.units}"
             if a.local else "coarse"))
    _, runs = walk_scene_refinement(sc, lay, levels=a.levels, mu=a.mu, cycles=a.cycles,
                                    touching=diagonal_touching(sc), progress=report, anchor_radius=radius,
                                    from_rest=a.anchor_radius is not None, local=a.local or ())
    last = np.array([r.distance[-1] for _, r in runs])
    for (m, r) in runs:
        if not r.frame_success.all():
            print(f"WARNING: {m.n_nodes} nodes: {int((~r.frame_success).sum())} frame(s) not solved: its distance is not a "
                  "figure to trust, nor the estimate below")
    print("distance in the last cycle: " + ", ".join(f"{m.n_nodes} nodes {v:.4f}" for (m, _), v in zip(runs, last)))
    est = None
    if len(last) > 1:
        est = richardson(last)
        print("change from one level to the next: " + ", ".join(f"{v:+.4f}" for v in est["changes"])
              + "".join(f" (ratio {q:.2f})" for q in est["ratios"]))
        if est["extrapolated"] is not None:
            print(f"limit {est['extrapolated']:.4f} +- {est['error']:.4f} {runs[0][1].units} per cycle "
                  + (f"(Richardson, observed order {est['order']:.2f})" if est["order"] is not None
                     else "(the last change: the changes alternate in sign)"))
    import matplotlib
    matplotlib.use("Agg")
    fig = plot_walk_refinement([(m.n_nodes, r) for m, r in runs], estimate=est)
    print("chart:", save_figure(fig, out / "walk_refinement.png", close=True))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
