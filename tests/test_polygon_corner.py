"""A node that goes round a convex polygon's corner is not held against the first edge's extension.

A cantilever turned by 80 degrees past a square's corner (recheck12 N1): the contact pair of a node against
the square's bottom edge stayed in place after the node had passed the corner, a wall on the edge's
extension. The solve then returned a "success" with a force on a node 1.4 mm clear of the square and an energy
of 3.61 against the touching equilibrium's 1.247. The rows of a polygon are now refreshed as the node goes
round (``contactsteps._stale_polygon_rows``)."""

from __future__ import annotations

import numpy as np
import pytest
from shapely.geometry import Point, Polygon

from mdsr_opt import Mesh, NeoHookean, Obstacle, nodes_in_box, solve_external

SQUARE = [[1.3478751161711275, 33.67851887809984], [1.3988202407110149, 27.678735165807737],
          [7.378604673962145, 27.72951047326582], [7.327659549422257, 33.729294185557926]]


@pytest.fixture(scope="module")
def turned():
    mesh = Mesh.from_polygon([[0, 0], [60, 0], [60, 6], [0, 6]], max_area=1.5)
    mat = NeoHookean(E=0.5, nu=0.45)
    X = mesh.points
    base, tip = nodes_in_box(mesh, xmax=0.0), nodes_in_box(mesh, xmin=60.0)
    th = np.radians(80)
    R = np.array([[np.cos(th), np.sin(th)], [-np.sin(th), np.cos(th)]])
    C = np.array([0.0, 3.0])
    drags = {int(i): p for i, p in zip(tip, (X[tip] - C) @ R + C)}
    plain = solve_external(mesh, mat, base, drags)
    held = solve_external(mesh, mat, base, drags, obstacles=[Obstacle(SQUARE)])
    return mesh, plain, held


def test_a_node_round_a_polygon_corner_is_not_held_by_the_edge_extension(turned):
    mesh, plain, held = turned
    Q = Polygon(SQUARE)
    assert Polygon(plain.x[mesh.boundary_loops[0]]).intersection(Q).area > 0  # the plain state enters it
    assert held.success and held.stable, held.status
    body = Polygon(held.x[mesh.boundary_loops[0]])
    assert body.intersection(Q).area == pytest.approx(0.0, abs=1e-9)
    # pressed by its corner only: the energy is the plain state's within 0.1 % (3.61 with the phantom wall)
    assert held.energy == pytest.approx(plain.energy, rel=1e-3)
    gap = held.contact["gap"] if "gap" in held.contact else 0.0
    for pair in held.contact["pairs"]:  # every force acts where the body touches the square
        pts = [held.x[n] for n in pair["nodes"] if n >= 0]
        d = min(Q.distance(Point(p)) for p in pts) if pair["kind"] == "obstacle" else body.distance(Q)
        assert d <= 2 * max(gap, pair["gap"]) + 1e-9, pair
