"""What contact costs: solves with and without ``contact=True`` / ``obstacles`` on scenes that never touch and
on scenes that touch, side by side (best of ``--repeat`` runs each, after one warm-up).

Scenes that never touch (both settings reach the same state): a 4 x 1 strip clamped at its left end and
pulled 10 % (external), pushed 5 % (below buckling), and the same strip bent by a 30 % rope along its bottom
(internal), with a disk far away as an obstacle. Scenes that touch: the strip pressed onto the ground, the
strip clamped at both ends and pushed 30 % and 50 % (it buckles and folds onto itself; rejected without
contact), and the library gripper's jaws closing with inner-rim muscles at 30 %.

    python tests/benchmarks/bench_contact.py            # 40 x 10 strips (451 nodes)
    python tests/benchmarks/bench_contact.py --nx 80 --repeat 1

``--turn 40,80,160`` instead solves the 90-degree turn of issue 35 once per mesh (the 4 x 1 strip, nx x nx/4
cells, left end clamped, right end turned by -90 degrees about its centre and moved by (-2, 2), with
self-contact) and prints per mesh: nodes, time, load steps, whether the outline crosses itself (shapely),
stability, the start (rest x) of the inner side's touching stretch, the total contact force, the energy and
the force the clamp exerts on the body; then per touching region (a stretch of the boundary,
:func:`contact_regions`) its pairs and their summed force, beside half the summed magnitudes of the contact
forces on its nodes (equal for a flat fold: a pair pushing each way is not counted twice).

    python tests/benchmarks/bench_contact.py --turn 40,80,160

``--seed`` solves only the first mesh of ``--turn`` by load steps and each finer one in one load step at full
load from the state of the mesh before it carried to its nodes (``transfer_state``, ``initial_guess`` with
``min_step=1``): the load path of a fine mesh folds its inner side in creases an element wide, one load step
of 1/256 at a time.

    python tests/benchmarks/bench_contact.py --turn 40,80,160 --seed

``--method ipopt,barrier`` solves each mesh of ``--turn`` by both contact methods, one after the other
(``contact_method``: the gap constraints solved by IPOPT, or the barrier solved by Newton's method,
:mod:`mdsr_opt.mechanics.barriersolve`); times are CPU seconds of the solve, ``iters`` IPOPT or Newton
iterations summed over the load steps, ``energy`` the strain energy (the barrier's own is left out).

    python tests/benchmarks/bench_contact.py --turn 40,80,160 --method ipopt,barrier
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from mdsr_opt import Disk, HalfPlane, Mesh, Muscle, NeoHookean, solve_external, solve_internal

MAT = NeoHookean(1.0, 0.3)


def _best(fn, repeat):
    fn()  # warm-up: models and solvers built once per mesh
    times, res = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        res = fn()
        times.append(time.perf_counter() - t0)
    return min(times), res


def scenes(nx: int):
    mesh = Mesh.rectangle(4.0, 1.0, nx, nx // 4)
    P = mesh.points
    left, right = np.flatnonzero(P[:, 0] == 0.0), np.flatnonzero(P[:, 0] == 4.0)
    top = np.flatnonzero(P[:, 1] == 1.0)
    far = [Disk((2.0, -5.0), 1.0)]
    bottom = Muscle([int(i) for i in np.argsort(P[:, 0]) if P[i, 1] == 0.0])

    def ext(drags, anchors=left, **kw):
        return lambda: solve_external(mesh, MAT, anchors, drags, **kw)

    pull = {int(i): (P[i, 0] + 0.4, P[i, 1]) for i in right}
    push = {f: {int(i): (P[i, 0] - 4 * f, P[i, 1]) for i in right} for f in (0.05, 0.3, 0.5)}
    press = {int(i): (P[i, 0], P[i, 1] - 0.3) for i in top}
    ground = [HalfPlane((0.0, -0.05), (0.0, 1.0))]
    yield "no touch", "pull 10 %", ext(pull), ext(pull, contact=True, obstacles=far)
    yield "no touch", "push 5 %", ext(push[0.05]), ext(push[0.05], contact=True, obstacles=far)
    yield ("no touch", "rope 30 %", lambda: solve_internal(mesh, MAT, [bottom], [0.3]),
           lambda: solve_internal(mesh, MAT, [bottom], [0.3], contact=True))
    yield "touch", "press on ground", None, ext(press, anchors=None, obstacles=ground)
    yield "touch", "push 30 %", ext(push[0.3]), ext(push[0.3], contact=True)
    yield "touch", "push 50 %", ext(push[0.5]), ext(push[0.5], contact=True)


def gripper():
    import sys
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from test_contact import _gripper

    mesh, mat, muscles = _gripper()
    return ("touch", "gripper jaws 30 %", lambda: solve_internal(mesh, mat, muscles, [0.3, 0.3]),
            lambda: solve_internal(mesh, mat, muscles, [0.3, 0.3], contact=True))


def turn(nx: int, seed=None, method: str = "ipopt", verbose: bool = False):
    """The 90-degree turn on ``nx`` x ``nx/4`` cells: ``(mesh, result, seconds)``; ``seed``: a solved
    ``(mesh, result)`` of the turn on another mesh, whose state starts the one load step at full load;
    ``method``: the ``contact_method``."""
    mesh = Mesh.rectangle(4.0, 1.0, nx, nx // 4)
    P = mesh.points
    left, right = np.flatnonzero(P[:, 0] == 0.0), np.flatnonzero(P[:, 0] == 4.0)
    c, th = np.array([4.0, 0.5]), np.radians(-90.0)
    R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    drags = {int(i): tuple(c + R @ (P[i] - c) + np.array([-2.0, 2.0])) for i in right}
    kw = {}
    if seed is not None:
        from mdsr_opt.mechanics.quadratic import transfer_state

        kw = {"initial_guess": transfer_state(seed[0], seed[1].x, P), "min_step": 1.0}
    t0 = time.process_time()
    res = solve_external(mesh, MAT, left, drags, contact=True, contact_method=method, verbose=verbose, **kw)
    return mesh, res, time.process_time() - t0


def contact_regions(mesh, res) -> list[dict]:
    """The result's touching regions: its pushing pairs grouped by stretches of the boundary (the nodes of
    each pair, ``p, a, b``, by their places along the loop; places at most two boundary edges apart join).
    Per region: ``nodes`` (in it, sorted along the loop), ``pairs``, ``force`` (the sum of the pairs' normal
    forces) and ``half_abs`` (half the sum of the magnitudes of the contact forces on its nodes). Where every
    pair's normal is that of the region's interface (a flat fold), ``half_abs`` equals ``force`` whichever way
    the pairs point (node of one face against segment of the other, or back): the force is not counted twice
    where both faces' nodes push."""
    loop = np.asarray(mesh.boundary_loops[0])
    place = np.full(mesh.n_nodes, -1)
    place[loop] = np.arange(len(loop))
    pairs = [pr for pr in res.contact["pairs"] if all(q >= 0 and place[q] >= 0 for q in pr["nodes"])]
    used = np.unique([place[q] for pr in pairs for q in pr["nodes"]]).astype(int)
    if not len(used):
        return []
    gaps = np.diff(np.r_[used, used[0] + len(loop)])
    cut = np.flatnonzero(gaps > 2)  # a run ends after these
    runs = []
    starts = np.roll(cut + 1, 1) % len(used) if len(cut) else np.array([0])
    for s0, e0 in zip(starts, cut if len(cut) else np.array([len(used) - 1])):
        idx = used[s0:e0 + 1] if s0 <= e0 else np.r_[used[s0:], used[:e0 + 1]]
        runs.append(loop[idx])
    f = np.asarray(res.contact["node_forces"])
    out = []
    for nodes in runs:
        mine = set(nodes.tolist())
        prs = [pr for pr in pairs if pr["nodes"][0] in mine]
        out.append({"nodes": nodes, "pairs": len(prs), "force": float(sum(pr["force"] for pr in prs)),
                    "half_abs": 0.5 * float(np.linalg.norm(f[nodes], axis=1).sum())})
    return out


def clamp_reaction(mesh, x, anchors) -> np.ndarray:
    """The force the anchors exert on the body (2,): minus the energy gradient summed over them (the contact
    forces, internal to the body, add nothing to it)."""
    from mdsr_opt.mechanics.model import get_model

    model = get_model(mesh, MAT)
    g = model.gradient(np.asarray(x, dtype=float).reshape(-1), model.params(MAT)).reshape(-1, 2)
    return -g[np.asarray(anchors)].sum(0)


def turn_study(sizes, seed: bool = False, methods=("ipopt",)) -> None:
    """Print the turn's contact region per mesh (module docstring); ``seed``: each mesh after the first
    started from the one before; ``methods``: the contact methods, each mesh solved by each in turn."""
    from shapely.geometry import Polygon

    print(f"{'cells':>8s} {'method':>7s} {'nodes':>6s} {'CPU s':>8s} {'iters':>5s} {'steps':>5s} {'ok':>3s} "
          f"{'valid':>5s} {'stable':>6s} {'start x':>7s} {'force':>8s} {'energy':>8s} {'clamp Rx':>8s} "
          f"{'clamp Ry':>8s}  status")
    last = {}
    for nx, method in [(nx, m) for nx in sizes for m in methods]:
        mesh, res, t = turn(nx, last.get(method) if seed else None, method)
        last[method] = (mesh, res) if res.success else None
        P = mesh.points
        valid = Polygon(res.x[mesh.boundary_loops[0]]).is_valid  # shapely: the outline does not cross itself
        touch = sorted({q for pr in res.contact["pairs"] for q in pr["nodes"] if q >= 0 and P[q, 1] == 0.0})
        R = clamp_reaction(mesh, res.x, np.flatnonzero(P[:, 0] == 0.0))
        start = float(P[touch, 0].min()) if touch else float("nan")
        print(f"{nx:>4d}x{nx // 4:<3d} {method:>7s} {mesh.n_nodes:6d} {t:8.1f} {res.iterations:5d} {len(res.steps):5d} "
              f"{'yes' if res.success else 'no':>3s} {valid!s:>5s} {bool(res.stable)!s:>6s} {start:7.3f} "
              f"{res.contact['total_force']:8.5f} {res.energy:8.5f} {R[0]:8.5f} {R[1]:8.5f}  {res.status[:70]}",
              flush=True)
        for k, reg in enumerate(contact_regions(mesh, res)):  # where it touches, and how hard
            side = ["bottom" if P[q, 1] == 0.0 else "top" if P[q, 1] == 1.0 else "end" for q in reg["nodes"]]
            xs = P[reg["nodes"], 0]
            print(f"{'':8s} region {k}: {max(set(side), key=side.count):6s} x {xs.min():.3f}-{xs.max():.3f}, "
                  f"{reg['pairs']:3d} pairs, force {reg['force']:.5f} (half the sum of |node force| "
                  f"{reg['half_abs']:.5f})", flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--nx", type=int, default=40, help="cells along the strip (nx/4 across)")
    ap.add_argument("--repeat", type=int, default=3, help="runs per solve (the best is reported)")
    ap.add_argument("--turn", default=None, help="comma-separated nx: the 90-degree turn's refinement study")
    ap.add_argument("--seed", action="store_true", help="with --turn: each mesh after the first at full load from "
                    "the one before")
    ap.add_argument("--method", default="ipopt", help="with --turn: comma-separated contact methods (ipopt, barrier), "
                    "each mesh solved by each in turn")
    args = ap.parse_args(argv)
    if args.turn:
        turn_study([int(v) for v in args.turn.split(",")], args.seed, args.method.split(","))
        return 0
    print(f"{'scene':10s} {'case':20s} {'plain s':>9s} {'ok':>3s} {'contact s':>10s} {'ok':>3s} {'ratio':>6s} "
          f"{'pairs':>5s}  status (contact)")
    for kind, name, plain, contact in [*scenes(args.nx), gripper()]:
        tp, rp = _best(plain, args.repeat) if plain is not None else (float("nan"), None)
        tc, rc = _best(contact, args.repeat)
        ok_p = "-" if rp is None else ("yes" if rp.success else "no")
        print(f"{kind:10s} {name:20s} {tp:9.3f} {ok_p:>3s} {tc:10.3f} {'yes' if rc.success else 'no':>3s} "
              f"{tc / tp:6.2f} {len(rc.contact['pairs']):5d}  {rc.status[:60]}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
