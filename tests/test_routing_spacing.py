"""The seed spacing is a length that holds on every mesh (issue 32 item 4: routing on fine meshes gave more,
shorter muscles): contracted regions closer than it are one region, and no kept rope runs beside a stronger
one within it. Checked independently (scipy and shapely distances) on the fine-design strip at several
resolutions and turns of its end."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import shapely
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra
from shapely.geometry import LineString

from mdsr_opt import solve_external
from mdsr_opt.mechanics.anchors import body_size
from mdsr_opt.synthesis import routing_search
from mdsr_opt.synthesis.fabrication import Fabrication
from mdsr_opt.synthesis.routing import SEED_SPACING, route_for_design, route_muscles
from conftest import load_script

_B = load_script("tests/benchmarks/bench_fine_design.py")
DRAGS = [(0.6, (-0.6, 1.0)), (-0.5, (-0.5, -0.8)), (1.0, (-1.0, 1.2))]


def _target(ny, angle=0.6, shift=(-0.6, 1.0)):
    mesh = _B.strip(ny)
    anchors, drags = _B.driving(mesh, angle, shift)
    return mesh, solve_external(mesh, _B.MAT, anchors, drags, backend="newton").x


@pytest.mark.parametrize("ny", [24, 32])
def test_seeded_regions_lie_farther_apart_than_the_seed_spacing(ny, monkeypatch):
    # the deep band search of route_for_design: on a jittered mesh its strong edges broke into islands a few
    # edges big beside the compressed side (1, 2, 3 regions at 1.1k, 2.4k, 4.3k nodes), each seeded
    mesh, x = _target(ny)
    seen = []
    regions = routing_search.Router.regions
    monkeypatch.setattr(routing_search.Router, "regions", lambda self, *a, **k: seen.append(regions(self, *a, **k))
                        or seen[-1])
    f = Fabrication().for_body(mesh)
    rr = route_muscles(mesh, x, inset=f.min_fixture_radius + f.wall,
                       fabrication=Fabrication(f.channel_diameter, f.wall, f.min_fixture_radius, f.min_fixture_radius))
    assert len(rr) >= 1 and len(seen) == 1
    spacing = SEED_SPACING * body_size(mesh)
    E = mesh.edges
    L = np.linalg.norm(mesh.points[E[:, 0]] - mesh.points[E[:, 1]], axis=1)
    graph = csr_matrix((np.r_[L, L], (np.r_[E[:, 0], E[:, 1]], np.r_[E[:, 1], E[:, 0]])), shape=(mesh.n_nodes,) * 2)
    nodes = [np.unique(E[r]) for r in seen[0]]
    for i in range(len(nodes)):  # through the body, along mesh edges
        d = dijkstra(graph, indices=nodes[i], min_only=True)
        for j in range(len(nodes)):
            if j != i:
                assert d[nodes[j]].min() >= spacing, (i, j, d[nodes[j]].min(), spacing)


def _beside(P, paths, spacing):
    """Per rope after the first: the share of its length within ``spacing`` of the ropes before it."""
    out = []
    for k in range(1, len(paths)):
        line = LineString(P[list(paths[k])])
        strip = shapely.union_all([LineString(P[list(q)]).buffer(spacing, 16) for q in paths[:k]])
        out.append(line.intersection(strip).length / line.length)
    return out


@pytest.mark.parametrize("angle, shift", DRAGS)
def test_no_routed_rope_runs_beside_a_stronger_one(angle, shift):
    mesh, x = _target(32, angle, shift)  # 4.3k nodes
    spacing = SEED_SPACING * body_size(mesh)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        routings = [route_for_design(mesh, x), route_muscles(mesh, x, fabrication=False),
                    route_muscles(mesh, x, band="offset+long")]
    for rr in routings:
        # ranked strongest first; each lies beside the stronger ones over less than half its length
        paths = [m.nodes for m in rr.muscles]
        assert all(s < 0.5 for s in _beside(mesh.points, paths, spacing)), _beside(mesh.points, paths, spacing)
    assert all("parallel twin" in d.reason for rr in routings for d in rr.dropped if "of stronger ropes" in d.reason)
    assert 1 <= len(routings[0]) <= 4


def _shortening(mesh, x, rr):
    """How much the ropes of a routing shorten in the target, summed (independent of the routing's stats)."""
    P = mesh.points
    return sum(np.linalg.norm(np.diff(P[list(m.nodes)], axis=0), axis=1).sum()
               - np.linalg.norm(np.diff(x[list(m.nodes)], axis=0), axis=1).sum() for m in rr.muscles)


def test_the_pipeline_routing_shortens_at_least_as_much_as_its_first_and_deep_routings():
    # route_for_design keeps the deeper routing when it keeps more ropes or ropes that shorten clearly more:
    # here one weak rope at the clearance (shortening 0.079) and one strong rope deeper inside (0.285)
    mesh, x = _target(24, -0.7, (-0.7, -1.0))
    f = Fabrication().for_body(mesh)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        first = route_muscles(mesh, x)
        deep = route_muscles(mesh, x, inset=f.min_fixture_radius + f.wall,
                             fabrication=Fabrication(f.channel_diameter, f.wall, f.min_fixture_radius,
                                                     f.min_fixture_radius))
        rr = route_for_design(mesh, x)
    got = _shortening(mesh, x, rr)
    assert got >= max(_shortening(mesh, x, first), _shortening(mesh, x, deep)) * (1 - 1e-9)


def test_ropes_on_either_side_of_a_slot_are_no_twins():
    """Beside means through the body: two ropes about 0.4 apart across a slot (a hole) are two muscles, while the
    same two ropes on a plate without the slot are one rope and its twin."""
    from mdsr_opt import mesh_polygon
    from mdsr_opt.scenes.select import edge_path
    from mdsr_opt.synthesis.routing_spacing import parallel_twins

    outline = [[0, 0], [4, 0], [4, 2], [0, 2]]
    slot = [[0.5, 0.95], [3.5, 0.95], [3.5, 1.05], [0.5, 1.05]]
    for holes, twins in (([slot], []), ([], [1])):
        mesh = mesh_polygon(outline, holes=holes, resolution=1500)
        low, high = (edge_path(mesh, [(0.8, y), (3.2, y)]) for y in (0.8, 1.2))
        P = mesh.points
        # on either side of the slot, closer than the spacing in a straight line (across the slot)
        assert P[list(low.nodes), 1].max() <= 0.95 + 1e-9 and P[list(high.nodes), 1].min() >= 1.05 - 1e-9
        assert LineString(P[list(low.nodes)]).hausdorff_distance(LineString(P[list(high.nodes)])) < 0.7
        assert list(parallel_twins(mesh, [low.nodes, high.nodes], 0.7)) == twins
