"""routing_bounds: proofs that a rest-length shortest path is longer than a length, and the routing unchanged by them."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.sparse.csgraph import dijkstra

from mdsr_opt import Mesh
from mdsr_opt.synthesis import routing_bounds as rb
from mdsr_opt.synthesis.routing_memo import rest_graph


def _jittered_strip(ny=12, seed=3):
    mesh = Mesh.rectangle(4.0, 1.0, 4 * ny, ny)
    p = mesh.points.copy()
    inside = (p[:, 0] > 1e-12) & (p[:, 0] < 4 - 1e-12) & (p[:, 1] > 1e-12) & (p[:, 1] < 1 - 1e-12)
    p[inside] += np.random.default_rng(seed).uniform(-0.2, 0.2, (int(inside.sum()), 2)) / ny
    return Mesh(p, mesh.triangles)


def _plate_with_window():
    return Mesh.from_polygon([[0, 0], [6, 0], [6, 3], [0, 3]], max_area=0.01,
                             holes=[[[2, 1], [4, 1], [4, 2], [2, 2]]])


@pytest.mark.parametrize("make", [_jittered_strip, _plate_with_window, lambda: Mesh.rectangle(3.0, 1.0, 12, 4)])
def test_farther_is_never_claimed_for_a_path_within_the_length(make):
    """For pairs of nodes at every distance, with the length asked just above, at and just below the path length
    computed by Dijkstra's search on the rest lengths (the routing's): 'farther' only when the path is longer,
    whatever searches were kept before; and it does prove most of the 'just below' ones (not a bound that never
    says anything). A window makes paths go round it (far longer than the straight line)."""
    mesh = make()
    G = rest_graph(mesh)[0]
    rng = np.random.default_rng(0)
    b = rb.LowerBounds(mesh)
    proved = asked = 0
    for s in rng.choice(mesh.n_nodes, 12, replace=False):
        d = dijkstra(G, directed=True, indices=int(s))
        for u in rng.choice(mesh.n_nodes, 25, replace=False):
            if u == s:
                continue
            du = float(d[u])
            for need in (du * (1 + 1e-12), du, np.nextafter(du, 0.0), du * (1 - 1e-3), du - mesh.edge_lengths.mean()):
                got = b.farther(int(s), int(u), float(need))
                assert not (got and du <= need), (s, u, du, need)
            asked += 1
            proved += b.farther(int(s), int(u), du * (1 - 1e-3))
    assert proved >= 0.9 * asked, (proved, asked)


def test_farther_across_a_gap_between_two_parts():
    """Two separate squares: a node of the other part is farther than any length."""
    a = Mesh.rectangle(1.0, 1.0, 4, 4)
    pts = np.vstack([a.points, a.points + [3.0, 0.0]])
    mesh = Mesh(pts, np.vstack([a.triangles, a.triangles + a.n_nodes]))
    b = rb.LowerBounds(mesh)
    assert b.farther(0, a.n_nodes, 100.0)
    assert not b.farther(0, a.n_nodes - 1, 2.0)  # the far corner of its own square: sqrt(2) by the diagonals or 2
    with pytest.raises(ValueError, match="need must be a finite length"):
        b.farther(0, 1, float("inf"))


def test_the_routing_is_the_same_without_the_bounds(monkeypatch):
    """route_for_design on a fine strip (the bench_fine_design target), a plate with a window and an L: every
    answer of the search's heuristic (Router._distance) equals that of a whole Dijkstra search from its end node
    (the length if at most the length asked, else inf), and the muscles, notes and dropped units are those of the
    routing with the bounds switched off; the bounds did prove answers."""
    import math

    from mdsr_opt import NeoHookean, RigidDrag, solve_external
    from mdsr_opt.synthesis import routing_search
    from mdsr_opt.synthesis.routing import route_for_design

    def cases():
        strip = _jittered_strip(20)
        left = np.flatnonzero(strip.points[:, 0] < 1e-9)
        right = np.flatnonzero(strip.points[:, 0] > 4 - 1e-9)
        yield strip, left, RigidDrag(right, 0.6, (4.0, 0.5), shift=(-0.6, 1.0))
        plate = _plate_with_window()
        P = plate.points
        yield plate, np.flatnonzero(P[:, 0] < 0.2), {int(i): (P[i, 0] - 0.3, P[i, 1] + 0.8)
                                                      for i in np.flatnonzero(P[:, 0] > 5.8)}
        L = Mesh.from_polygon([[0, 0], [4, 0], [4, 1], [1, 1], [1, 4], [0, 4]], max_area=0.01)
        P = L.points
        yield L, np.flatnonzero(P[:, 1] > 3.8), {int(i): (P[i, 0] - 0.5, P[i, 1] + 1.0)
                                                 for i in np.flatnonzero(P[:, 0] > 3.8)}

    def route(mesh, x):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rr = route_for_design(mesh, x)
        return [m.nodes for m in rr.muscles], rr.notes, [(d.nodes, d.reason) for d in rr.dropped]

    answers, proofs = [], []
    distance, farther = routing_search.Router._distance, rb.LowerBounds.farther

    def checked(self, node, u, need, straight):
        got = distance(self, node, u, need, straight)
        d = float(dijkstra(rest_graph(self.mesh)[0], directed=True, indices=node)[u])
        answers.append(got == (d if d <= need else math.inf))
        return got

    for mesh, anchors, drags in cases():
        x = solve_external(mesh, NeoHookean(1.0, 0.3), anchors, drags, backend="newton").x
        monkeypatch.setattr(routing_search.Router, "_distance", checked)
        monkeypatch.setattr(rb.LowerBounds, "farther",
                            lambda self, s, u, need: proofs.append(farther(self, s, u, need)) or proofs[-1])
        with_bounds = route(mesh, x)
        monkeypatch.setattr(routing_search.Router, "_distance", distance)
        monkeypatch.setattr(rb.LowerBounds, "farther", lambda self, s, u, need: False)
        assert with_bounds == route(mesh, x) and len(with_bounds[0]) >= 1
    assert all(answers) and len(answers) >= 100
    assert sum(proofs) >= 20


def test_the_kept_graphs_and_searches_stay_within_their_budgets(monkeypatch):
    """With room for one reduced graph and one search only, the answers are those with room for all (the kept
    work only saves time) and no more than one of each is kept."""
    mesh = _plate_with_window()
    rng = np.random.default_rng(1)
    pairs = [(int(s), int(u)) for s, u in rng.choice(mesh.n_nodes, (60, 2)) if s != u]
    G = rest_graph(mesh)[0]
    needs = [float(dijkstra(G, directed=True, indices=s)[u]) * f for (s, u), f in
             zip(pairs, np.tile([0.999, 1.0, 0.99], len(pairs)))]
    roomy = rb.LowerBounds(mesh)
    want = [roomy.farther(s, u, need) for (s, u), need in zip(pairs, needs)]
    assert len(roomy._graphs) > 1 and len(roomy._searched) > 1 and any(want)
    monkeypatch.setattr(rb, "GRAPH_FLOATS", 1)
    monkeypatch.setattr(rb, "BOUND_FLOATS", 1)
    tight = rb.LowerBounds(mesh)
    assert [tight.farther(s, u, need) for (s, u), need in zip(pairs, needs)] == want
    assert len(tight._graphs) == 1 and len(tight._searched) == 1
