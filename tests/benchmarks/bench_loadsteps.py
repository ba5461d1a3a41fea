"""Benchmark: cable load stepping on the muscle experiments, on the design meshes and the prototypes' finer ones.

For every case of ``one_muscle``, ``two_muscles`` and ``four_muscles`` (20-50 % contractions) at medium
resolution, solves the internal driving from rest with the exact cable on the scene's mesh and on its
virtual prototype's (3x finer, perturbed material), and prints IPOPT iterations, accepted load steps, CPU
seconds and the energy. The totals are the figures of issue 13's load-stepping changes (a KKT prediction
that moves a rope away from its target is dropped; a solve stopped by its iteration cap is not repeated in
inequality form).

Run:  python tests/benchmarks/bench_loadsteps.py
      python tests/benchmarks/bench_loadsteps.py --tree /tmp/old   # an older tree (git archive REV mdsr_opt problems)
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="+", default=["one_muscle", "two_muscles", "four_muscles"],
                    help="library scenes with internal-driving cases (default: the three muscle experiments)")
    ap.add_argument("--resolution", default="medium", help="mesh resolution of the scenes (default medium)")
    ap.add_argument("--tree", default=str(ROOT), help="source tree to measure (default: this script's)")
    a = ap.parse_args(argv)
    sys.path.insert(0, a.tree)
    import mdsr_opt
    from mdsr_opt import get_problem, solve_internal
    from mdsr_opt.scenes.cases import prepare_case
    from mdsr_opt.scenes.prototype import VirtualPrototype

    print(f"mdsr_opt from {mdsr_opt.__file__}")
    print(f"{'scene':<13} {'case':<5} {'mesh':<9} {'nodes':>6} {'iters':>6} {'steps':<20} {'cpu s':>6} {'energy':>12}")
    tot_it, tot_t = 0, 0.0
    for name in a.scenes:
        sc = get_problem(name, resolution=a.resolution)
        vp = VirtualPrototype.for_scene(sc)
        for case in sc.cases:
            setup = prepare_case(sc, case)
            fine = [vp.transfer_muscle(m) for m in setup.muscles]
            for label, mesh, mat, mus in (("design", sc.mesh, sc.material, setup.muscles),
                                          ("prototype", vp.mesh, vp.material, fine)):
                t0 = time.process_time()
                r = solve_internal(mesh, mat, mus, case.contractions)
                dt = time.process_time() - t0
                tot_it += r.iterations
                tot_t += dt
                steps = ",".join(f"{s:g}" for s in r.steps) + ("" if r.success else " FAILED")
                print(f"{name:<13} {case.name:<5} {label:<9} {mesh.n_nodes:>6} {r.iterations:>6} {steps:<20} "
                      f"{dt:>6.2f} {r.energy:>12.6g}", flush=True)
    print(f"total: {tot_it} IPOPT iterations, {tot_t:.2f} s CPU")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
