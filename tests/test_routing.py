"""Tests of the contraction graph and the muscle routing (issue 3)."""

from __future__ import annotations

import networkx as nx
import numpy as np
import pytest

from conftest import arc_map, rotation
from mdsr_opt import Mesh, Muscle
from mdsr_opt.synthesis.routing import RoutingWarning, contraction_graph, edge_weights, route_muscles
from mdsr_opt.synthesis.routing_result import MuscleStats, RoutingResult


# ------------------------------------------------------------------------------------------ targets
def bend(X: np.ndarray, kappa, length: float, y_axis: float) -> np.ndarray:
    """Map a strip along x onto a curve of curvature ``kappa(s)`` (fibres at ``y_axis`` keep their length).

    Positive curvature bends toward +y, so the side ``y > y_axis`` is the concave (contracted) one.
    """
    s = np.linspace(0.0, length, 4001)
    k = kappa(s)
    th = np.concatenate([[0.0], np.cumsum(0.5 * (k[1:] + k[:-1]) * np.diff(s))])
    cx = np.concatenate([[0.0], np.cumsum(0.5 * (np.cos(th[1:]) + np.cos(th[:-1])) * np.diff(s))])
    cy = np.concatenate([[0.0], np.cumsum(0.5 * (np.sin(th[1:]) + np.sin(th[:-1])) * np.diff(s))])
    T = np.interp(X[:, 0], s, th)
    x0, y0 = np.interp(X[:, 0], s, cx), np.interp(X[:, 0], s, cy)
    y = X[:, 1] - y_axis
    return np.column_stack([x0 - y * np.sin(T), y0 + y * np.cos(T)])


def arc(X: np.ndarray, radius: float, y_axis: float) -> np.ndarray:
    """Bend a strip onto a circular arc of signed radius ``radius``; the fibre at ``y_axis`` keeps its
    length (conftest's ``arc_map`` with the neutral fibre moved from y = 0 to ``y_axis``)."""
    return arc_map(X - [0.0, y_axis], length=4.0, angle=4.0 / radius)


def shorten(X: np.ndarray, angle: float, amount: float = 0.2) -> np.ndarray:
    """Uniform shortening by ``amount`` along the direction at ``angle`` (radians)."""
    d = np.array([np.cos(angle), np.sin(angle)])
    return X @ (np.eye(2) - amount * np.outer(d, d)).T


@pytest.fixture(scope="module")
def grid_strip():
    """A structured 4 x 1 strip (16 x 4 cells): many equal weights, so ties matter."""
    return Mesh.rectangle(4.0, 1.0, nx=16, ny=4)


@pytest.fixture(scope="module")
def body():
    """An unstructured mesh (Triangle) of a 4 x 2 rectangle."""
    return Mesh.from_polygon([[0, 0], [4, 0], [4, 2], [0, 2]], max_area=0.01)


def family(body):
    """Targets with curved, oblique or uneven contraction, for the K_a / K_b trade-off."""
    X = body.points
    out = {f"shorten {a} deg": shorten(X, np.radians(a)) for a in (20, 35, 50, 70)}
    out["bend, curvature x1..2"] = bend(X, lambda s: 0.15 * (1 + s / 4), 4.0, 1.0)
    out["bend, curvature x1..4"] = bend(X, lambda s: 0.15 * (1 + 3 * s / 4), 4.0, 1.0)
    return out


def edge_weight_map(mesh, target):
    _, _, w = edge_weights(mesh, target)
    return {tuple(e): wk for e, wk in zip(mesh.edges.tolist(), w)}


def path_weights(muscle, wmap):
    return np.array([wmap[(min(a, b), max(a, b))] for a, b in zip(muscle.nodes[:-1], muscle.nodes[1:])])


# ------------------------------------------------------------------------------------------ contraction graph
def test_edge_weights_cannot_corrupt_the_mesh(grid_strip):
    t = arc(grid_strip.points, 3.0, 0.5)
    ref = [m.nodes for m in route_muscles(grid_strip, t)]
    l0, l, w = edge_weights(grid_strip, t)
    with pytest.raises(ValueError, match="read-only"):
        l0[0] = 123.0
    l[:] = 0.0  # l and w are the caller's own arrays
    w[:] = -1.0
    l0_again, _, w_again = edge_weights(grid_strip, t)
    assert np.all(l0_again == grid_strip.edge_lengths) and l0_again.max() < 1.0
    assert w_again.max() > 0.1
    assert [m.nodes for m in route_muscles(grid_strip, t)] == ref


def test_contraction_graph_weights_follow_the_definition(grid_strip):
    X = grid_strip.points
    G = contraction_graph(grid_strip, X * [0.9, 1.2])
    assert G.number_of_nodes() == grid_strip.n_nodes and G.number_of_edges() == len(grid_strip.edges)
    dx, dy = 0.25, 0.25
    diag = 1.0 - np.hypot(0.9 * dx, 1.2 * dy) / np.hypot(dx, dy)
    for a, b, d in G.edges(data=True):
        v = X[b] - X[a]
        expected = 0.1 if v[1] == 0 else (-0.2 if v[0] == 0 else diag)
        assert d["weight"] == pytest.approx(expected, abs=1e-12)
        assert d["rest_length"] == pytest.approx(np.linalg.norm(v), abs=1e-14)
        assert d["weight"] == pytest.approx((d["rest_length"] - d["target_length"]) / d["rest_length"])
    assert G.graph["w_max"] == pytest.approx(0.1) and G.graph["w_min"] == pytest.approx(-0.2)
    assert G.nodes[5]["rest"] == tuple(X[5])
    assert G.nodes[5]["target"] == pytest.approx(tuple(X[5] * [0.9, 1.2]))


def test_contraction_graph_is_invariant_to_rigid_motion(body):
    t = bend(body.points, lambda s: 0.3 + 0 * s, 4.0, 1.0)
    G1 = contraction_graph(body, t)
    G2 = contraction_graph(body, t @ rotation(2.0).T + [5.0, -3.0])
    w1 = np.array([d["weight"] for _, _, d in G1.edges(data=True)])
    w2 = np.array([G2.edges[a, b]["weight"] for a, b in G1.edges()])
    assert np.max(np.abs(w1 - w2)) < 1e-12 and np.max(np.abs(w1)) > 0.1


# ------------------------------------------------------------------------------------------ routing: shape
def test_bent_strip_muscle_on_the_concave_side_analytic(grid_strip):
    X = grid_strip.points
    for sign in (+1, -1):  # bend up (top side concave), then down (bottom side concave)
        res = route_muscles(grid_strip, arc(X, sign * 3.0, 0.5), fabrication=False)
        assert len(res) >= 1
        for m in res:
            side = sign * (X[list(m.nodes), 1] - 0.5)
            assert np.all(side > 0), f"muscle {m.nodes} crosses to the convex side"
        # the strongest muscle runs along the whole inner side
        span = np.ptp(X[list(res[0].nodes), 0])
        assert span == pytest.approx(4.0)
        assert res.stats[0].mean_weight == pytest.approx(0.5 / 3.0, rel=0.01)


def test_bent_strip_by_external_driving_routes_on_the_concave_side(grid_strip):
    from mdsr_opt import NeoHookean
    from mdsr_opt.mechanics.equilibrium import solve_external

    X = grid_strip.points
    left = np.flatnonzero(X[:, 0] < 1e-9)
    right = np.flatnonzero(X[:, 0] > 4.0 - 1e-9)
    goal = arc(X, 3.0, 0.5)  # drag the right end around an arc of radius 3 (centre line)
    sol = solve_external(grid_strip, NeoHookean(E=1.0, nu=0.3), left, {int(i): goal[i] for i in right})
    assert sol.success
    res = route_muscles(grid_strip, sol.x)
    assert len(res) >= 1
    top = X[:, 1] > 0.5
    for m in res:
        assert top[list(m.nodes)].all()
    assert np.ptp(X[list(res[0].nodes), 0]) >= 3.0  # runs along most of the inner side
    assert res.stats[0].contraction > 0.1


def test_uniform_shortening_gives_straight_muscles_along_the_axis():
    for pattern in ("right", "alternating"):
        mesh = Mesh.rectangle(3.0, 2.0, nx=12, ny=8, pattern=pattern)
        X = mesh.points
        for axis in (0, 1):
            scale = np.ones(2)
            scale[axis] = 0.8
            res = route_muscles(mesh, X * scale, fabrication=False)
            assert len(res) >= 1
            for m, s in zip(res, res.stats):
                assert s.turning_angle == 0.0 and s.turning_angle_target == 0.0
                seg = np.diff(X[list(m.nodes)], axis=0)
                assert np.all(seg[:, 1 - axis] == 0.0)  # every segment along the axis
                assert s.mean_weight == pytest.approx(0.2) and s.nonuniformity < 1e-20
                assert np.ptp(X[list(m.nodes), axis]) == pytest.approx(np.ptp(X[:, axis]))


def test_muscles_are_disjoint_simple_paths_on_contracted_edges(body):
    for name, t in family(body).items():
        res = route_muscles(body, t, K_a=1.0, K_b=1.0, min_length=0.0)
        wmap = edge_weight_map(body, t)
        seen: set[int] = set()
        assert len(res) >= 1, name
        for m in res:
            m.check_on(body)  # raises if a segment is not a mesh edge
            assert len(set(m.nodes)) == len(m.nodes)
            assert seen.isdisjoint(m.nodes), f"{name}: muscles share a node"
            seen.update(m.nodes)
            assert path_weights(m, wmap).min() > 1e-3, f"{name}: a muscle uses an edge that does not contract"


def test_a_cable_cannot_push_elongated_regions_get_no_muscle(grid_strip):
    X = grid_strip.points
    # stretch the strip 10 % along x, then bend it: only a band along the inner side still shortens
    t = arc(X * [1.1, 1.0], 3.0, 0.5)
    wmap = edge_weight_map(grid_strip, t)
    contracted = np.array([w > 1e-3 for w in wmap.values()])
    assert 0 < contracted.sum() < len(contracted) / 2
    res = route_muscles(grid_strip, t, K_a=0.0, K_b=0.0, min_length=0.0)  # most permissive growth
    for m in res:
        assert path_weights(m, wmap).min() > 1e-3
    # a target that only stretches: nothing to route, and the user is told why
    with pytest.warns(RoutingWarning, match="cable cannot push"):
        empty = route_muscles(grid_strip, X * 1.2)
    assert len(empty) == 0 and list(empty) == [] and empty.stats == ()
    # raising the floor above every contraction gives the same empty answer
    with pytest.warns(RoutingWarning, match="min_contraction=0.5"):
        assert len(route_muscles(grid_strip, X * [0.8, 1.0], min_contraction=0.5)) == 0


def test_splicing_joins_separate_seed_units():
    mesh = Mesh.rectangle(6.0, 1.0, nx=24, ny=4)
    X = mesh.points
    peaks = lambda s: 0.2 + 0.1 * np.exp(-((s - 1.5) / 0.3) ** 2) + 0.1 * np.exp(-((s - 4.5) / 0.3) ** 2)
    t = bend(X, peaks, 6.0, 0.5)
    res = route_muscles(mesh, t, K_a=4.0, seed_threshold=0.9, fabrication=False)
    assert res.n_regions == 2  # two contracted regions, each seeded ...
    assert len(res) == 1 and res.n_units == 1  # ... spliced into one muscle
    assert np.ptp(X[list(res[0].nodes), 0]) == pytest.approx(6.0)
    # a designer who wants uniform muscles (large K_a) keeps them apart: one muscle on each peak
    strict = route_muscles(mesh, t, K_a=100.0, seed_threshold=0.9, min_length=0.0, fabrication=False)
    assert len(strict) >= 2 and all(np.ptp(X[list(m.nodes), 0]) < 3.0 for m in strict)
    for peak in (1.5, 4.5):  # each peak has a muscle of its own
        assert any(np.ptp(X[list(m.nodes), 0]) < 3.0 and X[list(m.nodes), 0].min() <= peak <= X[list(m.nodes), 0].max()
                   for m in strict)


def test_smaller_K_a_splices_more_and_the_mismatch_gate_holds():
    """K_a is a weight of order one: g_a is the squared relative mismatch of a joined part, so the number
    of muscles falls as K_a falls over 1 .. 100 (the paper's trade-off), never rises."""
    mesh = Mesh.rectangle(6.0, 1.0, nx=24, ny=4)
    X = mesh.points
    peaks = lambda s: 0.2 + 0.1 * np.exp(-((s - 1.5) / 0.3) ** 2) + 0.1 * np.exp(-((s - 4.5) / 0.3) ** 2)
    t = bend(X, peaks, 6.0, 0.5)
    counts = [len(route_muscles(mesh, t, K_a=K, seed_threshold=0.9, min_length=0.0)) for K in (1, 4, 30, 100)]
    assert counts == sorted(counts) and counts[0] < counts[-1]


# -------------------------------------------------------------------------------- routing: invariance
@pytest.mark.parametrize("seed, name", [(0, "shorten 20 deg"), (1, "shorten 50 deg"),
                                        (2, "bend, curvature x1..4")])
def test_relabelling_and_rigid_motion_change_nothing(body, seed, name):
    rng = np.random.default_rng(seed)
    t = family(body)[name]
    ref = route_muscles(body, t, K_a=1.0, K_b=1.0, n_seeds=10)
    perm = rng.permutation(body.n_nodes)
    relabelled = body.relabel(perm)
    t2 = np.empty_like(t)
    t2[perm] = t
    moved = t2 @ rotation(rng.uniform(0, 2 * np.pi)).T + rng.normal(scale=10.0, size=2)
    out = route_muscles(relabelled, moved, K_a=1.0, K_b=1.0, n_seeds=10)
    assert sum(len(m.nodes) for m in ref) >= 10  # ropes to compare (inside the body: fewer nodes than on the outline)
    assert [tuple(perm[list(m.nodes)]) for m in ref] == [m.nodes for m in out]
    assert {tuple(sorted(perm[list(e)])) for e in ref.seeds} == {tuple(sorted(e)) for e in out.seeds}
    for a, b in zip(ref.stats, out.stats):
        assert a.rest_length == pytest.approx(b.rest_length, rel=1e-12)
        assert a.mean_weight == pytest.approx(b.mean_weight, rel=1e-9)
        assert a.turning_angle == pytest.approx(b.turning_angle, abs=1e-9)


@pytest.mark.parametrize("kind", ["shorten", "arc"])
def test_ties_are_broken_by_geometry_not_by_node_numbers(grid_strip, kind):
    """Structured meshes give many equal weights: the routing must not fall back on node order."""
    X = grid_strip.points
    t = X * [0.8, 1.0] if kind == "shorten" else arc(X, 3.0, 0.5)
    ref = route_muscles(grid_strip, t, n_seeds=4)
    rng = np.random.default_rng(7)
    for _ in range(3):
        perm = rng.permutation(grid_strip.n_nodes)
        t2 = np.empty_like(t)
        t2[perm] = t
        out = route_muscles(grid_strip.relabel(perm), t2 @ rotation(1.0).T, n_seeds=4)
        assert [tuple(perm[list(m.nodes)]) for m in ref] == [m.nodes for m in out]
        assert [set(perm[list(e)]) for e in ref.seeds] == [set(e) for e in out.seeds]


def canonical(result):
    """The muscles as node paths, each read from its smaller end node (the frame decides which end a
    path starts at; rotating the frame may reverse it)."""
    return [min(m.nodes, m.nodes[::-1]) for m in result]


@pytest.mark.parametrize("name", ["shorten 35 deg", "shorten 70 deg", "bend, curvature x1..4"])
def test_rotating_mesh_and_target_together_changes_nothing(body, name):
    """The growth heuristic is a length along mesh edges, so it does not depend on the x and y axes
    (a Manhattan distance would)."""
    t = family(body)[name]
    for kw in ({"K_a": 1.0, "K_b": 1.0, "n_seeds": 10}, {}):
        ref = route_muscles(body, t, **kw, fabrication=False)
        assert sum(len(m.nodes) for m in ref) >= 10  # ropes to compare (inside the body: fewer nodes than on the outline)
        for deg in (10.0, 30.0, 45.0, 90.0, 137.0, 200.0):
            R = rotation(np.radians(deg))
            out = route_muscles(Mesh(body.points @ R.T, body.triangles), t @ R.T, **kw, fabrication=False)
            assert canonical(out) == canonical(ref), f"{name}, {kw}, rotated by {deg} degrees"
            assert {frozenset(e) for e in out.seeds} == {frozenset(e) for e in ref.seeds}


def _router(mesh, t, w, K_a, K_b, K_h, n_seeds=10):
    """A router with its first units, as ``route_muscles`` builds it (no symmetry)."""
    import math

    from mdsr_opt.synthesis import routing
    from mdsr_opt.synthesis.routing_search import Router
    from mdsr_opt.synthesis.routing_why import compression_dominated

    ell = float(mesh.edge_lengths.mean())
    wq = np.rint(w / routing._QUANTUM).astype(np.int64)
    router = Router(mesh, wq, K_a, K_b, K_h, int(round(1e-3 / routing._QUANTUM)), ell,
                             1.0 - math.cos(math.radians(45.0)) + 1e-12)
    router.seed_units(router.regions(int(0.5 * wq.max()), compression_dominated(mesh, t, w)), n_seeds)
    return router


def test_heuristic_is_the_path_length_along_mesh_edges_to_another_unit(body):
    """h of every candidate step = shortest path over all mesh edges (rest lengths) from the new end node
    to the nearest end node of another unit, in mean edge lengths (checked against networkx)."""

    t = family(body)["shorten 35 deg"]
    _, _, w = edge_weights(body, t)
    ell = float(body.edge_lengths.mean())
    router = _router(body, t, w, 1.0, 1.0, 0.1)
    G = nx.Graph()
    G.add_weighted_edges_from((int(a), int(b), float(l)) for (a, b), l in zip(body.edges, body.edge_lengths))
    for _ in range(5):  # a few growth steps, so that endpoints have moved since the first fields
        cands = router._candidates()
        alive = [U for U in router.units if U.alive]
        assert len(alive) >= 2 and cands
        h = router._heuristic(cands)
        ends = {V.path[i] for V in alive for i in (0, -1)}
        dist = {e: nx.single_source_dijkstra_path_length(G, e) for e in ends}
        for c, hc in zip(cands, h):
            U, u = c[3], c[5]
            others = [V.path[i] for V in alive if V is not U for i in (0, -1)]
            assert hc == pytest.approx(min(dist[e][u] for e in others) / ell, rel=1e-12)
            # never shorter than the straight line
            straight = min(np.linalg.norm(body.points[u] - body.points[e]) for e in others) / ell
            assert hc >= straight * (1 - 1e-12)
        router._apply_orbit(cands[router._choose(cands)])


@pytest.mark.parametrize("K_h", [0.1, 1.0])
def test_pruned_choice_equals_the_full_heuristic(body, K_h):
    """The growth step computes h only where a straight-line bound says it can matter; every step it
    takes must be the one the full computation of h picks."""

    steps = 0
    for name in ("shorten 35 deg", "shorten 70 deg", "bend, curvature x1..4"):
        _, _, w = edge_weights(body, family(body)[name])
        router = _router(body, family(body)[name], w, 1.0, 1.0, K_h)
        while cands := router._candidates():
            h = router._heuristic(cands)
            full = min(range(len(cands)), key=lambda i: (cands[i][0] + K_h * float(h[i]), cands[i][1],
                                                         cands[i][2]))
            assert router._choose(cands) == full, f"{name}, step {steps}"
            router._apply_orbit(cands[full])
            steps += 1
    assert steps >= 50


# ------------------------------------------------------------------------------------------ routing: knobs
def _mean_stat(res, attr):
    return float(np.mean([getattr(s, attr) for s in res.stats]))


def test_raising_K_a_lowers_nonuniformity_and_K_b_lowers_turning(body):
    nu_lo, nu_hi, tu_lo, tu_hi, len_lo, len_hi = [], [], [], [], [], []
    for name, t in family(body).items():
        lax_a = route_muscles(body, t, K_a=1.0, min_length=0.0)
        strict_a = route_muscles(body, t, K_a=100.0, min_length=0.0)
        lax_b = route_muscles(body, t, K_b=1.0, min_length=0.0)
        strict_b = route_muscles(body, t, K_b=16.0, min_length=0.0)
        assert min(len(lax_a), len(strict_a), len(lax_b), len(strict_b)) >= 1, name
        nu_lo.append(_mean_stat(lax_a, "nonuniformity"))
        nu_hi.append(_mean_stat(strict_a, "nonuniformity"))
        tu_lo.append(_mean_stat(lax_b, "turning_angle"))
        tu_hi.append(_mean_stat(strict_b, "turning_angle"))
        len_lo.append(_mean_stat(lax_a, "rest_length"))
        len_hi.append(_mean_stat(strict_a, "rest_length"))
        assert nu_hi[-1] <= nu_lo[-1] * (1 + 1e-9), name
        assert tu_hi[-1] <= tu_lo[-1] + 1e-9, name
    assert np.mean(nu_hi) < 0.5 * np.mean(nu_lo)
    assert np.mean(tu_hi) < 0.5 * np.mean(tu_lo)
    # the paper's trade-off: a small K_a gives fewer, longer muscles
    assert np.mean(len_lo) > 1.5 * np.mean(len_hi)


def test_nonuniformity_is_the_largest_relative_mismatch_of_a_joined_part():
    from mdsr_opt.synthesis.routing_search import mismatch as _mismatch

    # a unit of 3 edges with mean 10 joined by an edge of weight 5: joined mean 35/4
    mu = 35 / 4
    assert _mismatch(((3, 30), (1, 5))) == pytest.approx(((5 - mu) / mu) ** 2, rel=1e-15)
    # splicing two units through an edge: the part furthest from the joined mean decides
    mu = (20 + 8 + 60) / 9
    assert _mismatch(((2, 20), (1, 8), (6, 60))) == pytest.approx(((8 - mu) / mu) ** 2, rel=1e-15)
    assert _mismatch(((4, 40), (1, 10))) == 0.0  # a perfectly uniform unit costs nothing
    # scale-free: doubling every weight changes nothing
    assert _mismatch(((3, 60), (1, 10))) == pytest.approx(_mismatch(((3, 30), (1, 5))), rel=1e-15)


def test_seeds_are_the_most_contracted_edges(body):
    t = family(body)["bend, curvature x1..4"]
    wmap = edge_weight_map(body, t)
    for n in (1, 5, 10):
        res = route_muscles(body, t, n_seeds=n, fabrication=False)
        assert len(res.seeds) == n
        ws = [wmap[e] for e in res.seeds]
        others = [w for e, w in wmap.items() if e not in set(res.seeds)]
        assert min(ws) >= max(others) - 1e-9
        assert ws == sorted(ws, reverse=True)


def test_max_muscles_keeps_the_strongest_and_min_length_drops_short_ones(body):
    t = family(body)["shorten 50 deg"]
    wmap = edge_weight_map(body, t)
    full = route_muscles(body, t, n_seeds=10, min_length=0.0, fabrication=False)
    assert len(full) >= 4
    strength = [float(np.sum(path_weights(m, wmap) * np.diff(np.cumsum(np.r_[0, np.linalg.norm(
        np.diff(body.points[list(m.nodes)], axis=0), axis=1)])))) for m in full]
    assert strength == sorted(strength, reverse=True)
    top2 = route_muscles(body, t, n_seeds=10, min_length=0.0, max_muscles=2, fabrication=False)
    assert [m.nodes for m in top2] == [m.nodes for m in full][:2]
    twins = [d.nodes for d in full.dropped if "parallel twin" in d.reason]  # beside stronger ropes (routing_spacing)
    assert [d.nodes for d in top2.dropped if "parallel twin" in d.reason] == twins
    assert len(top2.dropped) - len(twins) == len(full) - 2 and all(
        "max_muscles=2" in d.reason for d in top2.dropped if d.nodes not in twins)
    cut = float(np.median([s.rest_length for s in full.stats]))
    long_only = route_muscles(body, t, n_seeds=10, min_length=cut, fabrication=False)
    assert all(s.rest_length >= cut for s in long_only.stats)
    # every fragment shorter than min_length is recorded, spliced or dropped, with the reason
    frags = [d for d in long_only.dropped if "parallel twin" not in d.reason]
    assert frags and all(d.rest_length < cut for d in frags)
    assert all(d.reason.startswith(("spliced", "dropped")) and "min_length" in d.reason for d in frags)
    kept = {v for m in long_only for v in m.nodes}
    for d in long_only.dropped:
        if d.reason.startswith("spliced"):
            assert set(d.nodes) <= kept      # a spliced fragment lives on inside a muscle
        else:
            assert not set(d.nodes) & kept   # a dropped one is in no muscle
    with pytest.warns(RoutingWarning, match="shorter than min_length"):
        assert len(route_muscles(body, t, min_length=100.0)) == 0


def test_stats_agree_with_the_muscles(body):
    t = family(body)["shorten 20 deg"]
    res = route_muscles(body, t)
    wmap = edge_weight_map(body, t)
    assert isinstance(res, RoutingResult) and all(isinstance(s, MuscleStats) for s in res.stats)
    assert len(res.stats) == len(res) and res[0] is res.muscles[0]
    for m, s in zip(res, res.stats):
        assert isinstance(m, Muscle) and m.name == s.name
        w = path_weights(m, wmap)
        assert s.n_edges == len(w)
        assert s.mean_weight == pytest.approx(w.mean(), rel=1e-12)
        assert s.nonuniformity == pytest.approx(w.var(), rel=1e-9, abs=1e-18)
        assert s.rest_length == pytest.approx(m.rest_length(body), rel=1e-12)
        assert s.target_length == pytest.approx(m.length(t), rel=1e-12)
        assert s.contraction == pytest.approx(1 - s.target_length / s.rest_length, rel=1e-12)
        assert s.turning_angle == pytest.approx(m.turning_angle(body.points), abs=1e-12)
        assert X_first_is_smaller(body, m)
    lines = res.table().splitlines()
    assert len(lines) == len(res) + 1 and lines[1].startswith(res.stats[0].name)
    assert not any(set(line) <= {"-"} for line in lines)  # no dashed rule: laid out as the other tables
    assert {len(line) for line in lines} == {len(lines[0])}  # header and rows in the same columns
    # a result holds a graph and a dict: == is identity and hashing works (eq=False)
    again = route_muscles(body, t)
    assert res == res and res != again and hash(res) != hash(again)


def test_the_graph_is_built_on_first_access_and_kept(grid_strip):
    t = grid_strip.points * [0.8, 1.0]
    res = route_muscles(grid_strip, t)
    G = res.graph
    assert G is res.graph and G.number_of_edges() == len(grid_strip.edges)
    ref = contraction_graph(grid_strip, t)
    assert all(G.edges[e]["weight"] == pytest.approx(ref.edges[e]["weight"], abs=1e-15) for e in ref.edges)
    calls = []
    lazy = res.replaced(graph=lambda: calls.append(1) or ref, notes=("x",))
    assert calls == [] and lazy.notes == ("x",) and lazy.muscles == res.muscles
    kept = lazy.replaced(notes=("y",))  # a copy keeps the builder unbuilt
    assert calls == [] and kept.graph is ref and kept.graph is ref and calls == [1]
    with pytest.raises(TypeError, match="graph must be a networkx.Graph or a function"):
        res.replaced(graph=3)
    import pickle  # a run's jobs send results to worker processes: an unbuilt graph pickles too

    back = pickle.loads(pickle.dumps(route_muscles(grid_strip, t)))
    assert back.muscles == res.muscles and back.graph.number_of_edges() == G.number_of_edges()


def X_first_is_smaller(mesh, m) -> bool:
    return tuple(mesh.points[m.nodes[0]]) < tuple(mesh.points[m.nodes[-1]])


# ------------------------------------------------------------------------------------------ bad input
def test_target_of_the_wrong_shape_or_type(grid_strip):
    X = grid_strip.points
    n = grid_strip.n_nodes
    with pytest.raises(ValueError, match=rf"target must have shape \({n}, 2\), got \({n - 1}, 2\)"):
        route_muscles(grid_strip, X[:-1])
    with pytest.raises(ValueError, match=r"target must have shape"):
        contraction_graph(grid_strip, X.T)
    with pytest.raises(TypeError, match=r"target\[0\]\[0\] must be a real number, got str .a."):
        route_muscles(grid_strip, [["a", "b"]] * grid_strip.n_nodes)
    for fn in (route_muscles, contraction_graph, edge_weights):
        with pytest.raises(TypeError, match="mesh must be a mdsr_opt.Mesh, got ndarray"):
            fn(X, X)


def test_target_with_nan(grid_strip):
    t = grid_strip.points * [0.8, 1.0]
    t[7, 1] = np.nan
    with pytest.raises(ValueError, match=r"target contains NaN or inf \(first at index \(7, 1\)\)"):
        route_muscles(grid_strip, t)


def test_target_with_inverted_elements(grid_strip):
    t = grid_strip.points * [0.8, 1.0]
    t[20] = t[20] + [0.0, -0.6]  # pull an interior node through its lower neighbours
    J = grid_strip.jacobians(t)
    assert (J <= 0).any()
    with pytest.raises(ValueError, match=r"target has \d+ inverted triangle\(s\) \(det F <= 0\), first"):
        route_muscles(grid_strip, t)
    with pytest.raises(ValueError, match="inverts every triangle"):
        contraction_graph(grid_strip, grid_strip.points * [-1.0, 1.0])  # a mirror image


def test_rest_shape_gives_an_empty_result_with_a_warning(grid_strip):
    X = grid_strip.points
    # the rest shape, moved rigidly, and within 1e-10 of it (round-off of an upstream solver)
    for t in (X, X @ rotation(0.8).T + [2.0, 1.0], X * (1 + 1e-10), X * [1 - 1e-10, 1.0]):
        with pytest.warns(RoutingWarning, match="target equals the rest shape within tolerance") as rec:
            res = route_muscles(grid_strip, t)
        assert len(res) == 0 and res.seeds == () and res.graph.number_of_edges() == len(grid_strip.edges)
        assert not any("stretches" in str(r.message) for r in rec)


def test_weak_contraction_is_not_called_stretching(grid_strip):
    X = grid_strip.points
    with pytest.warns(RoutingWarning) as rec:  # contracts, but by less than the default floor 1e-3
        assert len(route_muscles(grid_strip, X * [0.9999, 1.0])) == 0
    (msg,) = [str(r.message) for r in rec]
    assert "min_contraction=0.001" in msg and "largest contraction 0.0001" in msg
    assert "only stretches" not in msg and "rest shape" not in msg
    assert len(route_muscles(grid_strip, X * [0.9999, 1.0], min_contraction=1e-5)) >= 1


@pytest.mark.parametrize("kw, exc, msg", [
    ({"K_a": -1.0}, ValueError, "K_a must be >= 0"),
    ({"K_b": float("nan")}, ValueError, "K_b must be finite"),
    ({"K_h": "1"}, TypeError, "K_h must be a real number"),
    ({"n_seeds": 0}, ValueError, "n_seeds must be an integer >= 1"),
    ({"n_seeds": 2.5}, TypeError, "n_seeds must be an integer"),
    ({"max_muscles": 0}, ValueError, "max_muscles must be an integer >= 1"),
    ({"min_length": -0.1}, ValueError, "min_length must be >= 0"),
    ({"min_contraction": 1.0}, ValueError, "min_contraction must be < 1"),
])
def test_bad_knobs(grid_strip, kw, exc, msg):
    with pytest.raises(exc, match=msg):
        route_muscles(grid_strip, grid_strip.points * [0.8, 1.0], **kw)


# ------------------------------------------------------------------------------------------ figures
def test_figures(grid_strip, tmp_path):
    from matplotlib.collections import LineCollection

    from mdsr_opt.plot.design import plot_contraction_graph, plot_routing
    from mdsr_opt.plot.common import save_figure

    t = arc(grid_strip.points, 3.0, 0.5)
    res = route_muscles(grid_strip, t)
    fig = plot_contraction_graph(grid_strip, t, res.graph, seeds=res.seeds)
    ax = fig.axes[0]
    lcs = [c for c in ax.collections if isinstance(c, LineCollection)]
    colored = [c for c in lcs if c.get_array() is not None]
    assert len(colored) == 1 and len(colored[0].get_segments()) == len(grid_strip.edges)
    _, _, w = edge_weights(grid_strip, t)
    assert np.allclose(colored[0].get_array(), w)
    assert colored[0].get_clim() == pytest.approx((-np.abs(w).max(), np.abs(w).max()))
    black = [c for c in lcs if c.get_array() is None]  # the seed edges, and the title says what they are
    assert len(black) == 1 and len(black[0].get_segments()) == len(res.seeds)
    assert "black: seed edges" in ax.get_title()
    assert "black" not in plot_contraction_graph(grid_strip, t, res.graph).axes[0].get_title()
    assert save_figure(fig, tmp_path / "graph.png") and (tmp_path / "graph.png").stat().st_size > 1000

    fig = plot_routing(grid_strip, t, res)
    assert len(fig.axes) == 2
    for ax, pos in zip(fig.axes, (grid_strip.points, t)):
        line = [ln for ln in ax.get_lines() if ln.get_label() == "M1"][0]  # plot.style.muscle_name(0)
        assert np.allclose(line.get_xydata(), pos[list(res[0].nodes)])
    save_figure(fig, tmp_path / "routing.png")
    assert (tmp_path / "routing.png").stat().st_size > 1000


# ------------------------------------------------------------------------------ seeds per region, symmetry
def test_each_contracted_region_gets_seeds_not_only_the_strongest():
    """An S-bend contracts the top of the first half strongly and the bottom of the second half weakly:
    a global top-n would put every seed in the first half; seeds per region give the weak side a muscle."""
    mesh = Mesh.from_polygon([[0, 0], [6, 0], [6, 1], [0, 1]], max_area=0.01)
    X = mesh.points
    t = bend(X, lambda s: np.where(s < 3.0, 0.4, -0.28), 6.0, 0.5)
    wmap = edge_weight_map(mesh, t)
    res = route_muscles(mesh, t, n_seeds=5, seed_threshold=0.5)
    assert res.n_regions >= 2
    top_global = sorted(wmap, key=wmap.get, reverse=True)[:5]
    assert all(X[list(e), 0].mean() < 3.0 for e in top_global)       # the global top 5: all strong side
    seed_x = [X[list(e), 0].mean() for e in res.seeds]
    assert min(seed_x) < 3.0 < max(seed_x)                            # seeds on both sides
    sides = {(bool(X[list(m.nodes), 0].mean() < 3.0), bool(X[list(m.nodes), 1].mean() > 0.5)) for m in res}
    assert {(True, True), (False, False)} <= sides                    # concave side of each half


def test_every_turn_obeys_the_tortuosity_rule_seeds_included(body):
    for name, t in family(body).items():
        for max_turn in (20.0, 45.0):
            res = route_muscles(body, t, max_turn=max_turn, K_b=0.0, n_seeds=10, min_length=0.0)
            assert len(res) >= 1
            for m in res:
                d = np.diff(body.points[list(m.nodes)], axis=0)
                a = np.arctan2(d[:, 1], d[:, 0])
                turn = np.abs((np.diff(a) + np.pi) % (2 * np.pi) - np.pi)
                assert np.degrees(turn.max(initial=0.0)) <= max_turn + 1e-6, (name, max_turn)
                # the seed edges of a muscle are part of its path, not exempt
            assert max(np.degrees(s.max_turn) for s in res.stats) <= max_turn + 1e-6


def _two_dimples(X, a=0.12):
    """Exactly mirror-symmetric about x = 2: the top edges near x = 1 and x = 3 shorten (a tanh step)."""
    u = X[:, 0] - 2.0
    h = np.sign(u) * 0.5 * (1.0 + np.tanh((np.abs(u) - 1.0) / 0.2))
    return np.column_stack([X[:, 0] - a * X[:, 1] * h, X[:, 1]])


def mirrored_mesh(max_area=0.01):
    """An unstructured mesh of the 4 x 1 plate, exactly mirror-symmetric about x = 2: Triangle meshes the
    left half, the right half is its mirror image (nodes on the axis shared)."""
    L = Mesh.from_polygon([[0, 0], [2, 0], [2, 1], [0, 1]], max_area=max_area)
    P, T = L.points, L.triangles
    on = np.flatnonzero(np.abs(P[:, 0] - 2.0) < 1e-12)
    off = np.setdiff1d(np.arange(len(P)), on)
    idx = np.arange(len(P))
    idx[off] = len(P) + np.arange(len(off))
    return Mesh(np.vstack([P, np.column_stack([4.0 - P[off, 0], P[off, 1]])]), np.vstack([T, idx[T][:, ::-1]]))


def symmetric_bend(X, c=0.3, R=3.0):
    """Bend about x = 2 with curvature (1 + 3 c u^2) / R, u = x - 2: exactly mirror-symmetric."""
    u = X[:, 0] - 2.0
    phi = (u + c * u ** 3) / R
    r = R - (X[:, 1] - 0.5)
    return np.column_stack([2.0 + r * np.sin(phi), R - r * np.cos(phi)])


def _mirror_closed(mesh, result):
    """True when the mirror image (about x = 2) of every muscle is a muscle, node positions to 1e-12."""
    paths = [mesh.points[list(m.nodes)] for m in result]
    ok = []
    for P in paths:
        Q = np.column_stack([4.0 - P[:, 0], P[:, 1]])
        ok.append(any(len(R) == len(Q) and (np.allclose(R, Q, atol=1e-12) or np.allclose(R, Q[::-1], atol=1e-12))
                      for R in paths))
    return all(ok)


@pytest.mark.parametrize("K_a", [1.0, 4.0, 30.0])
def test_a_symmetric_target_gets_mirror_symmetric_muscles(K_a, monkeypatch):
    mesh = mirrored_mesh()
    t = symmetric_bend(mesh.points)
    res = route_muscles(mesh, t, K_a=K_a, min_length=0.0)
    assert res.reflection is not None and len(res) >= 1
    assert _mirror_closed(mesh, res)
    # without the symmetric treatment, and seeds allowed a cell apart (no SEED_SPACING), the same target
    # gets a muscle whose mirror image is not one
    import mdsr_opt.synthesis.routing as routing_module
    with monkeypatch.context() as mp:
        mp.setattr(routing_module, "SEED_SPACING", 0.0)
        plain = route_muscles(mesh, t, K_a=K_a, min_length=0.0, symmetry=False)
    assert plain.reflection is None and not _mirror_closed(mesh, plain)
    # the symmetric layout does not depend on node numbers
    perm = np.random.default_rng(3).permutation(mesh.n_nodes)
    t2 = np.empty_like(t)
    t2[perm] = t
    out = route_muscles(mesh.relabel(perm), t2, K_a=K_a, min_length=0.0)
    assert sorted(canonical(out)) == sorted(min(tuple(perm[list(m.nodes)]), tuple(perm[list(m.nodes)])[::-1])
                                           for m in res)


def test_structured_symmetric_target_gives_mirror_pairs(grid_strip):
    res = route_muscles(grid_strip, _two_dimples(grid_strip.points), K_a=4.0, min_length=0.0)
    assert res.reflection is not None and len(res) >= 2 and _mirror_closed(grid_strip, res)


def test_symmetry_true_requires_a_symmetric_target(grid_strip):
    X = grid_strip.points
    lopsided = X.copy()
    lopsided[:, 0] -= 0.1 * X[:, 1] * np.clip(X[:, 0] - 2.5, 0.0, None)
    with pytest.raises(ValueError, match="not mirror-symmetric"):
        route_muscles(grid_strip, lopsided, symmetry=True)
    assert route_muscles(grid_strip, lopsided).reflection is None
    assert route_muscles(grid_strip, _two_dimples(X), symmetry=False, min_length=0.0).reflection is None


def test_find_reflection_maps_nodes_and_edges():
    from mdsr_opt.synthesis.routing_symmetry import find_reflections

    mesh = Mesh.rectangle(4.0, 1.0, nx=16, ny=4)
    refl = find_reflections(mesh)
    assert len(refl) == 2  # about x = 2 and about y = 0.5
    for r in refl:
        assert np.allclose(r.apply(mesh.points), mesh.points[r.node_map], atol=1e-12)
        assert np.array_equal(r.node_map[r.node_map], np.arange(mesh.n_nodes))
        E = mesh.edges
        assert np.array_equal(np.sort(r.node_map[E], axis=1), E[r.edge_map])
    assert find_reflections(Mesh.rectangle(4.0, 1.0, nx=16, ny=4, pattern="right")) == []


def _brute_nearest_within(X, Y, tol):
    d = np.hypot(Y[:, None, 0] - X[None, :, 0], Y[:, None, 1] - X[None, :, 1])
    j = np.argmin(d, axis=1)  # the first of equally near points, as nearest_within's ties
    dj = d[np.arange(len(Y)), j]
    return np.where(dj <= tol, dj, np.inf), np.where(dj <= tol, j, -1)


@pytest.mark.parametrize("seed", range(6))
def test_nearest_within_matches_brute_force(seed):
    from mdsr_opt.synthesis.routing_symmetry import nearest_within

    rng = np.random.default_rng(seed)
    X = rng.normal(size=(300, 2)) * 10.0 ** rng.uniform(-3, 3)
    if seed % 2:
        X = np.round(X / X.std()) * X.std()  # lattice points: many share a cell when tol is large, and ties
        X = np.unique(X, axis=0)
    for tol in np.array([1e-12, 1e-6, 1e-2, 0.3]) * np.ptp(X):
        near = X[rng.integers(0, len(X), 200)] + rng.normal(size=(200, 2)) * tol
        Y = np.vstack([near, rng.normal(size=(20, 2)) * 1e3 * np.ptp(X), [[1e300, -1e300]]])
        d, i = nearest_within(X, Y, tol)
        db, ib = _brute_nearest_within(X, Y, tol)
        assert np.array_equal(np.isfinite(d), np.isfinite(db))
        assert np.allclose(d[np.isfinite(d)], db[np.isfinite(db)], rtol=0, atol=1e-15 * np.ptp(X))
        assert np.array_equal(i, ib)
    d, i = nearest_within(X, np.array([[np.nan, 0.0], [np.inf, 1.0]]), 1.0)
    assert np.isinf(d).all() and (i == -1).all()
    d, i = nearest_within(X, X[::-1], 0.0)  # tol 0: exact matches only
    assert (d == 0).all() and np.array_equal(X[i], X[::-1])


def test_nearest_within_ties_scales_and_bad_input():
    from mdsr_opt.synthesis.routing_symmetry import nearest_within

    g = np.arange(5.0)
    X = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)[::-1].copy()  # a lattice, numbered backwards
    Y = np.vstack([(X[:-1] + X[1:]) / 2, X[:5] + [0.5, 0.5]])  # midpoints: two or four nodes equally near
    for scale in (1e-200, 1.0, 1e200, 1e305):
        d, i = nearest_within(X * scale, Y * scale, 0.75 * scale)
        db, ib = _brute_nearest_within(X * scale, Y * scale, 0.75 * scale)
        assert np.array_equal(i, ib) and (i >= 0).all()  # ties go to the lower index
        assert np.allclose(d, db, rtol=1e-12)
    # points of very different sizes beside a huge one: the distances are the points' own
    X = np.array([[1e300, 0.0], [0.0, 0.0], [1e-30, 0.0]])
    d, i = nearest_within(X, np.array([[1e-30, 0.0], [2e-30, 0.0], [1.0, 0.0]]), 1e-40)
    assert i.tolist() == [2, -1, -1] and d[0] == 0.0
    d, i = nearest_within(X, np.array([[1e-30, 0.0]]), 1.0)
    assert i.tolist() == [2] and d[0] == 0.0
    X = np.array([[0.0, 0.0], [1.0, 0.0], [1e305, 0.0]])
    for bad, words in (((X, Y, -1.0), "tol must be >= 0"), ((np.c_[X, X[:, :1]], Y, 1.0), r"X must have shape \(n, 2\)"),
                       ((X, Y[:, :1], 1.0), r"Y must have shape"), ((np.vstack([X, [np.nan, 0]]), Y, 1.0), "finite")):
        with pytest.raises(ValueError, match=words):
            nearest_within(*bad)


def test_find_reflections_of_a_body_built_turned_and_shifted():
    """The node matching of a mirror axis works at any position, angle and scale of the body."""
    from mdsr_opt.synthesis.routing_symmetry import find_reflections

    base = Mesh.rectangle(4.0, 1.0, nx=16, ny=4)
    for scale, angle, shift in ((1e-3, 0.3, (5e-3, -2e-3)), (1e3, -1.1, (4e4, 7e3)), (1.0, 0.0, (0.0, 0.0))):
        c, s = np.cos(angle), np.sin(angle)
        mesh = base.with_points(scale * base.points @ np.array([[c, -s], [s, c]]).T + shift)
        refl = find_reflections(mesh)
        assert len(refl) == 2
        for r in refl:
            assert np.allclose(r.apply(mesh.points), mesh.points[r.node_map], atol=1e-9 * mesh.size)
            assert np.array_equal(np.sort(r.node_map[mesh.edges], axis=1), mesh.edges[r.edge_map])
    assert len(find_reflections(Mesh.rectangle(4.0, 2.0, 8, 4), rtol=0.0)) == 2  # exact mirror images
