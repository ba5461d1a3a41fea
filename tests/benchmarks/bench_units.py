"""Benchmark of issue 31 items 6 and 7: one tolerance contract, and solves that do not depend on units.

``--resolve`` (item 6): random small designs, 2-3 ropes along shortest edge paths between boundary nodes of
a 4 x 1 strip (232 nodes) and an L-shape (162 nodes), a third of the ropes not pulled, targets the forward
solution plus noise; every design that passes its verification is solved forward again with
``solve_internal``'s defaults. Prints how many re-solves fail, and how many forward successes (tol 1e-8)
have a scaled KKT residual above 1e-8.

``--scaled`` (item 7): random cable solves on the same bodies, each also in micrometres, in SI units
(a 4 mm body, E = 1 MPa, t = 1 mm), at E = 1e-9, 1e-3 and 1e9 and at a thickness of 1e-6: how many
succeed, and their largest node distance to the unit-scale solution over the body's size.

Run:  python tests/benchmarks/bench_units.py --resolve --seeds 3 4 --cases 80
      python tests/benchmarks/bench_units.py --scaled --seeds 7 --cases 15
      python tests/benchmarks/bench_units.py --scaled --tree /tmp/old   # an older tree (git archive REV mdsr_opt)
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

SCALES = {"unit": (1.0, 1.0, 1.0), "micrometres": (1e3, 1.0, 1e3), "SI": (1e-3, 1e6, 1e-3),
          "E=1e-9": (1.0, 1e-9, 1.0), "E=1e-3": (1.0, 1e-3, 1.0), "E=1e9": (1.0, 1e9, 1.0),
          "t=1e-6": (1.0, 1.0, 1e-6)}


def bodies():
    from mdsr_opt import Mesh

    return {"strip": Mesh.rectangle(4.0, 1.0, 28, 7),
            "L": Mesh.from_polygon([[0, 0], [3, 0], [3, 1], [1, 1], [1, 3], [0, 3]], max_area=0.03)}


def random_ropes(mesh, rng, m):
    """``m`` ropes along shortest edge paths between random boundary nodes at least 0.4 x size apart."""
    import networkx as nx
    import numpy as np
    from mdsr_opt import Muscle

    G = nx.Graph()
    for i, j in mesh.edges:
        G.add_edge(int(i), int(j), weight=float(np.linalg.norm(mesh.points[i] - mesh.points[j])))
    B = mesh.boundary_nodes
    mus, used = [], set()
    for _ in range(50):
        if len(mus) == m:
            break
        a, b = rng.choice(B, 2, replace=False)
        if np.linalg.norm(mesh.points[a] - mesh.points[b]) < 0.4 * mesh.size:
            continue
        path = nx.shortest_path(G, int(a), int(b), weight="weight")
        key = frozenset(zip(path[:-1], path[1:]))
        if key not in used:
            used.add(key)
            mus.append(Muscle(path))
    return mus


def contractions(rng, m, top=0.5):
    a = rng.uniform(0.05, top, size=m)
    a[rng.random(m) < 0.35] = 0.0
    if not a.any():
        a[0] = 0.1
    return a


def resolve(seeds, n_cases) -> int:
    import numpy as np
    from mdsr_opt import NeoHookean, solve_internal
    from mdsr_opt.synthesis.contractions import design_contractions

    mat = NeoHookean(1.0, 0.3)
    tot = {"forward successes": 0, "above tol": 0, "verified designs": 0, "re-solves failed": 0}
    worst = 0.0
    for seed in seeds:
        rng = np.random.default_rng(seed)
        for _k in range(n_cases):
            for name, mesh in bodies().items():
                mus = random_ropes(mesh, rng, int(rng.integers(2, 4)))
                a = contractions(rng, len(mus))
                try:
                    fwd = solve_internal(mesh, mat, mus, a)
                except ValueError:  # two ropes on one path
                    continue
                if not fwd.success:
                    continue
                tot["forward successes"] += 1
                tot["above tol"] += fwd.residual > 1e-8
                worst = max(worst, fwd.residual)
                target = fwd.x + rng.normal(0, rng.choice([0.003, 0.03, 0.1]), fwd.x.shape)
                try:
                    d = design_contractions(mesh, mat, mus, target)
                except ValueError:  # a target that inverts an element, refused at the door
                    continue
                if d.success:
                    tot["verified designs"] += 1
                    again = solve_internal(mesh, mat, mus, d.contractions)
                    if not again.success:
                        tot["re-solves failed"] += 1
                        print(f"  {name}: re-solve failed: {again.status}", flush=True)
    print(", ".join(f"{k} {v}" for k, v in tot.items()) + f"; worst forward residual {worst:.2g}")
    return 0


def scaled(seeds, n_cases) -> int:
    import numpy as np
    from mdsr_opt import Mesh, NeoHookean, solve_internal

    cases = []
    for seed in seeds:
        rng = np.random.default_rng(seed)
        for _k in range(n_cases):
            for mesh in bodies().values():
                mus = random_ropes(mesh, rng, int(rng.integers(2, 4)))
                cases.append((mesh, mus, contractions(rng, len(mus), 0.4)))
    ref = {}
    print(f"{'units':<12} {'solved':>8} {'fails where unit succeeded':>27} {'max |x - x_unit| / size':>24}")
    for label, (L, E, t) in SCALES.items():
        n, ok, bad, dev = 0, 0, 0, 0.0
        for i, (mesh, mus, a) in enumerate(cases):
            m2 = mesh if L == 1.0 else Mesh(mesh.points * L, mesh.triangles)
            try:
                r = solve_internal(m2, NeoHookean(E, 0.3, thickness=t), mus, a)
            except ValueError:
                continue
            n += 1
            if label == "unit":
                ref[i] = r
            good = ref.get(i) is not None and ref[i].success
            ok += r.success
            bad += good and not r.success
            if r.success and good:
                dev = max(dev, float(np.abs(r.x / m2.size - ref[i].x / mesh.size).max()))
        print(f"{label:<12} {ok:>4} / {n:<3} {bad:>27} {dev:>24.1e}", flush=True)
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolve", action="store_true", help="item 6: re-solves of verified designs (see above)")
    ap.add_argument("--scaled", action="store_true", help="item 7: scaled copies of cable solves (see above)")
    ap.add_argument("--seeds", nargs="+", type=int, default=[3], help="random seeds of the generated cases")
    ap.add_argument("--cases", type=int, default=20, help="random cases per body and seed")
    ap.add_argument("--tree", default=str(ROOT), help="source tree to measure (default: this script's)")
    a = ap.parse_args(argv)
    sys.path.insert(0, a.tree)
    import mdsr_opt

    print(f"mdsr_opt from {mdsr_opt.__file__}")
    if a.scaled:
        scaled(a.seeds, a.cases)
    if a.resolve or not a.scaled:
        resolve(a.seeds, a.cases)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
