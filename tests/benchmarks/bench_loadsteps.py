"""Benchmark: cable load stepping on the muscle experiments, on the design meshes and the prototypes' finer ones.

For every case of ``one_muscle``, ``two_muscles`` and ``four_muscles`` (20-50 % contractions) at medium
resolution, solves the internal driving from rest with the exact cable on the scene's mesh and on its
virtual prototype's (3x finer, perturbed material), and prints IPOPT iterations, accepted load steps, CPU
seconds and the energy. The totals are the figures of issue 13's load-stepping changes (a KKT prediction
that moves a rope away from its target is dropped; a solve stopped by its iteration cap is not repeated in
inequality form).

``--strips`` instead solves 24 strips (4 x 1 rectangles of 1k and 3k nodes; 1, 2, 4 and 8 grid-row
muscles; 3 draws of contractions in [0.05, 0.25]), where with 8 muscles two or three ropes end slack, each
twice in a row, alternating: with the rope forms of :func:`mdsr_opt.mechanics.ropesolve.rope_forms` (a
predictor start that left a rope slack skips the equality form) and with the equality form always tried
first (as before), and prints iterations, seconds and the energies' agreement; then the totals of both for
30 random layouts of 2-4 ropes along rows of a 32 x 8 strip.

Run:  python tests/benchmarks/bench_loadsteps.py
      python tests/benchmarks/bench_loadsteps.py --tree /tmp/old   # an older tree (git archive REV mdsr_opt problems)
      python tests/benchmarks/bench_loadsteps.py --strips
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
    ap.add_argument("--strips", action="store_true",
                    help="rope forms with and without the slack start, on 24 grid-row strips (see above)")
    a = ap.parse_args(argv)
    sys.path.insert(0, a.tree)
    if a.strips:
        return strips()
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


def strips() -> int:
    import numpy as np
    from mdsr_opt import Mesh, Muscle, NeoHookean, solve_internal
    from mdsr_opt.mechanics import ropesolve

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_design import SIZES, muscles_for

    mat, hinted = NeoHookean(1.0, 0.3), ropesolve.rope_forms

    def equality_first(cmodel, p, x0):
        return (True, False) if cmodel.n_targets else (False,)

    def solve(forms, mesh, mus, a):
        """``(result, seconds)`` of one solve with ``forms`` as the rope forms."""
        ropesolve.rope_forms = forms
        try:
            t0 = time.perf_counter()
            r = solve_internal(mesh, mat, mus, a)
            return r, time.perf_counter() - t0
        finally:
            ropesolve.rope_forms = hinted

    print(f"{'nodes':>6} {'muscles':>7} {'draw':>4} | {'slack start: it':>15} {'s':>6} | {'equality first: it':>18} "
          f"{'s':>6} | {'slack':>5} {'|dE|/E':>8}")
    tot = {"new": [0, 0.0], "old": [0, 0.0]}
    for size in ("1k", "3k"):
        ny = SIZES[size]
        mesh = Mesh.rectangle(4.0, 1.0, 4 * ny, ny)
        for m in (1, 2, 4, 8):
            mus = muscles_for(4 * ny, ny, m)
            solve_internal(mesh, mat, mus, np.full(m, 0.05))  # the solver's build, outside the timing
            for draw in range(3):
                a = np.random.default_rng(draw + 10 * m).uniform(0.05, 0.25, size=m)
                out = {}
                for rep in range(2):
                    for key, forms in (("new", hinted), ("old", equality_first))[::1 if rep == 0 else -1]:
                        r, dt = solve(forms, mesh, mus, a)
                        if not r.success:
                            print(f"  {key}: FAILED {r.status}")
                        out.setdefault(key, []).append((r.iterations, dt, r.energy, int(r.slack.sum())))
                row = {k: (v[0][0], float(np.median([d for _, d, _, _ in v])), v[0][2], v[0][3]) for k, v in out.items()}
                for k in tot:
                    tot[k][0] += row[k][0]
                    tot[k][1] += row[k][1]
                de = abs(row["new"][2] - row["old"][2]) / abs(row["old"][2])
                print(f"{mesh.n_nodes:>6} {m:>7} {draw:>4} | {row['new'][0]:>15} {row['new'][1]:>6.3f} | "
                      f"{row['old'][0]:>18} {row['old'][1]:>6.3f} | {row['new'][3]:>5} {de:>8.1e}", flush=True)
    print(f"total: slack start {tot['new'][0]} iterations, {tot['new'][1]:.2f} s; equality first {tot['old'][0]} "
          f"iterations, {tot['old'][1]:.2f} s (medians of 2 alternating solves per case)")
    # random layouts: 2-4 ropes along rows of a 32 x 8 strip, contractions in [0.02, 0.4] (seed 7)
    mesh = Mesh.rectangle(4.0, 1.0, 32, 8)
    P = mesh.points
    rng = np.random.default_rng(7)
    res = {"new": [0, 0, 0.0], "old": [0, 0, 0.0]}
    refused = 0
    for _ in range(30):
        m = int(rng.integers(2, 5))
        mus = []
        for _j in range(m):
            y, x0, x1 = rng.choice([0.0, 0.125, 0.25, 0.5, 0.75, 1.0]), rng.choice([0.0, 0.5, 1.0]), \
                rng.choice([3.0, 3.5, 4.0])
            sel = [int(i) for i in np.argsort(P[:, 0], kind="stable") if abs(P[i, 1] - y) < 1e-9 and x0 <= P[i, 0] <= x1]
            mus.append(Muscle(sel))
        a = rng.uniform(0.02, 0.4, size=m)
        if len({mu.edges for mu in mus}) < m:  # two ropes on one path: refused at the door (ValueError)
            refused += 1
            continue
        for key, forms in (("new", hinted), ("old", equality_first)):
            r, dt = solve(forms, mesh, mus, a)
            res[key][2] += dt
            res[key][0] += r.iterations
            res[key][1] += bool(r.success)
    print(f"30 random layouts of 2-4 ropes (32 x 8 strip), {refused} with two ropes on one path refused: slack "
          f"start {res['new'][0]} iterations, {res['new'][1]} solved, {res['new'][2]:.1f} s; equality first "
          f"{res['old'][0]} iterations, {res['old'][1]} solved, {res['old'][2]:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
