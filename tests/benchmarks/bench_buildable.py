"""Benchmark of issue 32 items 1-2: eight user-like bodies designed with ``design_pipeline``'s defaults.

Each body (a plate with a window, an L, a T, a C, a five-arm star, a thick ring, a tentacle with holes, a
finger with two windows) has a clamped region and a dragged region and is meshed to about ``--nodes``
nodes. Per body the table gives: success, the shape difference over the body's size, the number of
muscles, the smallest distance of a rope node from the outline and the holes over the body's diameter
(measured with shapely on the polygon the body was meshed from), the fixture radius used and the
resolutions the routing recorded (``routing.notes``); an error is printed in place of the figures.

Run:  python tests/benchmarks/bench_buildable.py [--nodes 700] [--bodies plate L] [--set issue|extra|all]
      python tests/benchmarks/bench_buildable.py --tree /tmp/old   # an older tree (git archive REV mdsr_opt)
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]


def _circle(cx, cy, r, n=24, phase=0.0):
    t = phase + 2 * np.pi * np.arange(n) / n
    return np.column_stack([cx + r * np.cos(t), cy + r * np.sin(t)])


def _rigid(P, centre, angle, shift):
    c, s = math.cos(angle), math.sin(angle)
    R = np.array([[c, -s], [s, c]])
    return (P - centre) @ R.T + centre + np.asarray(shift, float)


def bodies() -> dict:
    """name -> (outline, holes, clamp(points) -> mask, drag(points, mask) -> positions of the dragged nodes,
    dragged(points) -> mask). Sizes vary from 4 to 200 units on purpose (the defaults scale with the body)."""
    B = {}
    # a plate with a window (100 x 60): clamp the left edge, drag the right edge up and in
    B["plate"] = ([(0, 0), (100, 0), (100, 60), (0, 60)], [[(35, 20), (65, 20), (65, 40), (35, 40)]],
                  lambda P: P[:, 0] < 6, lambda P: P[:, 0] > 94, (0.25, (-12.0, 18.0)))
    # an L (arm 4 units): clamp the foot of the upright, drag the tip of the arm up
    B["L"] = ([(0, 0), (4, 0), (4, 1), (1, 1), (1, 4), (0, 4)], [],
              lambda P: P[:, 1] > 3.7, lambda P: P[:, 0] > 3.7, (0.5, (-0.8, 1.2)))
    # a T (bar 120 wide): clamp the stem's foot, drag the bar's right end down
    B["T"] = ([(45, 0), (75, 0), (75, 80), (120, 80), (120, 110), (0, 110), (0, 80), (45, 80)], [],
              lambda P: P[:, 1] < 6, lambda P: P[:, 0] > 112, (-0.4, (-15.0, -25.0)))
    # a C (50 across): clamp the lower tip, drag the upper tip down towards it
    C = np.vstack([_circle(0, 0, 25, 20)[[i for i in range(20) if not (i <= 2 or i >= 18)]],
                   _circle(0, 0, 13, 20)[[i for i in range(20) if not (i <= 2 or i >= 18)]][::-1]])
    B["C"] = (C, [], lambda P: (P[:, 0] > 8) & (P[:, 1] < -5), lambda P: (P[:, 0] > 8) & (P[:, 1] > 5),
              (-0.3, (2.0, -8.0)))
    # a five-arm star (radius 60): clamp one arm's tip, drag the next arm's tip round
    t = np.pi / 2 + np.pi * np.arange(10) / 5
    r = np.where(np.arange(10) % 2 == 0, 60.0, 30.0)
    star = np.column_stack([r * np.cos(t), r * np.sin(t)])
    B["star"] = (star, [], lambda P: P[:, 1] > 50, lambda P: (P[:, 0] < -45) & (P[:, 1] > 5), (0.5, (15.0, 25.0)))
    # a thick ring (outer radius 50, inner 28): clamp the left, drag the right side up
    B["ring"] = (_circle(0, 0, 50, 40), [_circle(0, 0, 28, 28)], lambda P: P[:, 0] < -44,
                 lambda P: P[:, 0] > 44, (0.3, (-10.0, 12.0)))
    # a tentacle with holes (200 long, 40 tapering to 16): clamp the base, curl the tip
    tent = [(0, 0), (200, 12), (200, 28), (0, 40)]
    holes = [_circle(40, 20, 7, 16), _circle(95, 20, 5.5, 16), _circle(145, 20, 4, 16)]
    B["tentacle"] = (tent, holes, lambda P: P[:, 0] < 8, lambda P: P[:, 0] > 192, (1.2, (-70.0, 60.0)))
    # a finger (30 x 120) with two windows: clamp the base, bend the tip sideways
    fing = [(0, 0), (30, 0), (30, 120), (0, 120)]
    wins = [[(10, 20), (20, 20), (20, 45), (10, 45)], [(10, 65), (20, 65), (20, 90), (10, 90)]]
    B["finger"] = (fing, wins, lambda P: P[:, 1] < 5, lambda P: P[:, 1] > 115, (0.7, (-40.0, -15.0)))
    return B


def _star(n_arms, r_out, r_in):
    t = np.pi / 2 + np.pi * np.arange(2 * n_arms) / n_arms
    r = np.where(np.arange(2 * n_arms) % 2 == 0, r_out, r_in)
    return np.column_stack([r * np.cos(t), r * np.sin(t)])


def extra_bodies() -> dict:
    """More bodies of the same kind (``--set extra``), for checks beyond the eight above: a six- and a seven-arm
    star, a plate with three windows, a thin ring, a C opened, a wide T with a hole, an L with a window."""
    B = {}
    s6 = _star(6, 50.0, 22.0)  # arm tips at 90 + 60 k degrees
    B["star6"] = (s6, [], lambda P: P[:, 1] > 42, lambda P: (P[:, 1] < -35) & (P[:, 0] > 0) | (P[:, 1] < -42),
                  (0.4, (12.0, 10.0)))
    s7 = _star(7, 80.0, 40.0)
    B["star7"] = (s7, [], lambda P: P[:, 1] > 70, lambda P: (P[:, 0] > 55) & (P[:, 1] > 0),
                  (0.5, (-15.0, 20.0)))
    wins = [[(x, 15), (x + 20, 15), (x + 20, 35), (x, 35)] for x in (15, 50, 85)]
    B["plate3"] = ([(0, 0), (120, 0), (120, 50), (0, 50)], wins, lambda P: P[:, 0] < 6,
                   lambda P: P[:, 0] > 114, (0.35, (-15.0, 25.0)))
    B["ring_thin"] = (_circle(0, 0, 30, 40), [_circle(0, 0, 21, 36)], lambda P: P[:, 1] < -25,
                      lambda P: P[:, 1] > 25, (-0.3, (8.0, -6.0)))
    C = np.vstack([_circle(0, 0, 40, 24)[[i for i in range(24) if not (i <= 2 or i >= 22)]],
                   _circle(0, 0, 28, 24)[[i for i in range(24) if not (i <= 2 or i >= 22)]][::-1]])
    B["C_open"] = (C, [], lambda P: (P[:, 0] > 20) & (P[:, 1] < -8), lambda P: (P[:, 0] > 20) & (P[:, 1] > 8),
                   (0.3, (6.0, 10.0)))
    B["T_hole"] = ([(30, 0), (50, 0), (50, 60), (80, 60), (80, 80), (0, 80), (0, 60), (30, 60)],
                   [_circle(40, 30, 4, 16)], lambda P: P[:, 1] < 4, lambda P: P[:, 0] < 5, (0.4, (10.0, 12.0)))
    B["L_window"] = ([(0, 0), (90, 0), (90, 25), (25, 25), (25, 90), (0, 90)], [[(8, 8), (17, 8), (17, 17), (8, 17)]],
                     lambda P: P[:, 1] > 85, lambda P: P[:, 0] > 85, (0.5, (-15.0, 25.0)))
    return B


def make_body(name: str, nodes: int = 700):
    """(mesh, anchors, drags, outline polygon (shapely), diameter) of body ``name`` (of :func:`bodies` or
    :func:`extra_bodies`) at about ``nodes`` nodes."""
    from shapely.geometry import Polygon

    from mdsr_opt import Mesh

    outline, holes, clamp, drag, (angle, shift) = {**bodies(), **extra_bodies()}[name]
    poly = Polygon(np.asarray(outline, float), [np.asarray(h, float) for h in holes])
    mesh = Mesh.from_polygon(np.asarray(outline, float), max_area=poly.area / (1.15 * nodes),
                             holes=[np.asarray(h, float) for h in holes] or None)
    P = mesh.points
    anchors = np.flatnonzero(clamp(P))
    dm = np.flatnonzero(drag(P))
    centre = P[dm].mean(axis=0)
    goal = _rigid(P[dm], centre, angle, shift)
    drags = {int(i): tuple(q) for i, q in zip(dm, goal)}
    hull = np.asarray(poly.convex_hull.exterior.coords)
    diameter = float(np.max(np.linalg.norm(hull[:, None] - hull[None], axis=-1)))
    return mesh, anchors, drags, poly, diameter


def buildable_figures(out, poly, diameter) -> dict:
    """Independent figures of a pipeline result (shapely on the body's own polygon): the smallest rope-node
    distance from the boundary, the smallest room of a fixture disk (radius r_f + wall) inside the body, the
    shortest rope over two fixture diameters."""
    import shapely

    boundary = poly.boundary
    P = out.mesh.points
    nodes = sorted({i for m in out.muscles for i in m.nodes})
    d = shapely.distance(shapely.points(P[nodes]), boundary)
    inside = shapely.contains_xy(poly, P[nodes, 0], P[nodes, 1])
    fab = getattr(out.routing, "fabrication", None) if out.routing is not None else None
    r_f = out.design.anchor_radius if getattr(out.design, "anchor_radius", None) is not None else float("nan")
    wall = fab.wall if fab is not None else 0.0
    ends = np.array([P[m.nodes[k]] for m in out.muscles for k in (0, -1)])
    room = shapely.distance(shapely.points(ends), boundary) - (r_f + wall)
    short = min(m.rest_length(out.mesh) for m in out.muscles) / (4 * r_f) if r_f > 0 else float("inf")
    return {"min_dist": float(np.where(inside, d, -d).min()) / diameter, "fixture_room": float(room.min()) / diameter,
            "shortest_over_2_fixtures": short, "radius": r_f / diameter}


def run(names, nodes):
    import warnings

    from mdsr_opt import NeoHookean, design_pipeline

    rows = []
    for name in names:
        mesh, anchors, drags, poly, D = make_body(name, nodes)
        t0 = time.perf_counter()
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                out = design_pipeline(mesh, NeoHookean(1.0, 0.45), anchors, drags)
            fig = buildable_figures(out, poly, D)
            rows.append((name, mesh.n_nodes, out.success, out.design.difference / D, len(out.muscles), fig,
                         tuple(getattr(out.routing, "notes", ())), time.perf_counter() - t0, None))
        except Exception as exc:  # the benchmark reports every failure in its row
            rows.append((name, mesh.n_nodes, False, float("nan"), 0, None, (), time.perf_counter() - t0,
                         f"{type(exc).__name__}: {exc}"))
    print(f"{'body':<9} {'nodes':>5} {'ok':>3} {'diff/D':>7} {'mus':>3} {'min d/D':>8} {'fix room/D':>10} "
          f"{'r_f/D':>6} {'short':>6} {'s':>5}  notes / error")
    for name, n, ok, diff, m, fig, notes, secs, err in rows:
        if err is not None:
            print(f"{name:<9} {n:>5} {'-':>3} {'':>7} {'':>3} {'':>8} {'':>10} {'':>6} {'':>6} {secs:5.1f}  {err[:160]}")
            continue
        print(f"{name:<9} {n:>5} {('yes' if ok else 'no'):>3} {diff:7.4f} {m:>3d} {fig['min_dist']:8.4f} "
              f"{fig['fixture_room']:10.4f} {fig['radius']:6.3f} {fig['shortest_over_2_fixtures']:6.2f} {secs:5.1f}  "
              + "; ".join(notes)[:300])
    good = [r for r in rows if r[8] is None and r[2] and r[3] <= 0.05]
    print(f"{len(good)}/{len(rows)} succeed within 5 % of the size")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--nodes", type=int, default=700, help="nodes each body is meshed with (default 700)")
    ap.add_argument("--bodies", nargs="*", default=None, help="names of the bodies to run (default: the set's)")
    ap.add_argument("--set", choices=("issue", "extra", "all"), default="issue",
                    help="issue: the eight bodies (default); extra: seven more of the kind; all: both")
    ap.add_argument("--tree", default=None, help="import mdsr_opt from this folder instead of the checkout")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(Path(args.tree).resolve()) if args.tree else str(ROOT))
    sets = {"issue": list(bodies()), "extra": list(extra_bodies()), "all": list(bodies()) + list(extra_bodies())}
    run(args.bodies or sets[args.set], args.nodes)


if __name__ == "__main__":
    main()
