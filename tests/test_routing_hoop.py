"""route_muscles' ``compression_ratio``: a hole drawn shut is ringed by a rope inside the body.

Around a hole whose rim is pulled inward the material contracts along the rim (hoop) about as much as it
stretches across it (radially), so no edge inside the body is compression-dominated and the default routing
lays nothing there; ``compression_ratio`` below 1 admits the hoop contraction a ring-shaped rope makes.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from mdsr_opt import NeoHookean
from mdsr_opt.mechanics.equilibrium import solve_external
from mdsr_opt.scenes.scene import mesh_polygon
from mdsr_opt.synthesis.routing import RoutingWarning, route_muscles


def _ring(n_out: int, centre, ax) -> np.ndarray:
    t = np.linspace(0, 2 * np.pi, n_out, endpoint=False)
    return np.column_stack([centre[0] + ax[0] * np.cos(t), centre[1] + ax[1] * np.sin(t)])


@pytest.fixture(scope="module", params=[((4.0, 3.0), (0.7, 0.35)), ((3.0, 3.0), (0.5, 0.5))],
                ids=["plate-slot", "disk-hole"])
def squeezed(request):
    """A plate (an ellipse) with a hole in its middle, the hole's rim drawn to 60 % x 40 % of its size,
    nothing else held: the wink of a face, on bodies other than the face."""
    outer, hole = request.param
    mesh = mesh_polygon(_ring(48, (0.0, 0.0), outer), [_ring(20, (0.0, 0.0), hole)], resolution=900)
    P = mesh.points
    rim = np.asarray(mesh.boundary_loops[1])
    target = P[rim] * (0.6, 0.4)
    res = solve_external(mesh, NeoHookean(E=1.0, nu=0.4), np.zeros(0, dtype=np.int64), (rim, target))
    assert res.success
    return mesh, res.x, hole


def test_a_hole_drawn_shut_routes_nothing_by_default_and_a_ring_with_compression_ratio(squeezed):
    mesh, x, hole = squeezed
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RoutingWarning)
        plain = route_muscles(mesh, x, K_a=1.0, min_length=0.2)
        ring = route_muscles(mesh, x, K_a=1.0, min_length=0.2, compression_ratio=0.4)
    assert len(plain) == 0
    assert len(ring) >= 1 and ring.params["compression_ratio"] == 0.4
    P = mesh.points
    spans = []
    for m in ring:  # the ropes curl round the hole, and each shortens in the target
        q = P[list(m.nodes)]
        ang = np.unwrap(np.arctan2(q[:, 1] / hole[1], q[:, 0] / hole[0]))
        spans.append(abs(ang[-1] - ang[0]))
        assert m.length(x) < m.rest_length(mesh)
    assert max(spans) > np.pi / 2, spans


@pytest.mark.parametrize("bad", [0.0, -0.5, 1.5])
def test_compression_ratio_out_of_range_is_refused(squeezed, bad):
    mesh, x, _ = squeezed
    with pytest.raises(ValueError, match="compression_ratio"):
        route_muscles(mesh, x, compression_ratio=bad)


def _winding(P, nodes, centre) -> float:
    q = P[list(nodes)] - centre
    return float(np.unwrap(np.arctan2(q[:, 1], q[:, 0]))[-1] - np.unwrap(np.arctan2(q[:, 1], q[:, 0]))[0])


def test_a_hole_drawn_shut_is_ringed_by_one_rope_within_the_turn_limit():
    """The plate's slot drawn shut: one rope rings it nearly all the way round (not arcs that stop at the
    slot's sharp ends), every turn within max_turn, its two ends a short gap apart, and it shortens. Fixtures
    of radius 0.05 (the face's), which the ring's ends keep room for."""
    from mdsr_opt.synthesis.fabrication import check_fabrication
    from mdsr_opt.synthesis.routing_result import largest_turn

    mesh = mesh_polygon(_ring(48, (0.0, 0.0), (4.0, 3.0)), [_ring(20, (0.0, 0.0), (0.7, 0.35))], resolution=900)
    P = mesh.points
    rim = np.asarray(mesh.boundary_loops[1])
    res = solve_external(mesh, NeoHookean(E=1.0, nu=0.4), np.zeros(0, dtype=np.int64), (rim, P[rim] * (0.6, 0.4)))
    assert res.success
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RoutingWarning)
        rr = route_muscles(mesh, res.x, K_a=1.0, min_length=0.2, compression_ratio=0.4,
                          fabrication=check_fabrication(None, 0.05))
    wind = [abs(_winding(P, m.nodes, (0.0, 0.0))) for m in rr]
    ring = rr[int(np.argmax(wind))]
    assert max(wind) > 1.6 * np.pi, wind
    assert np.degrees(largest_turn(P, ring.nodes)) <= 45.0 + 1e-6
    assert ring.length(res.x) < ring.rest_length(mesh)
    gap = np.linalg.norm(P[ring.nodes[0]] - P[ring.nodes[-1]])
    assert gap < 4.0 * ring.rest_length(mesh) / (len(ring.nodes) - 1)  # a few edges apart


def test_no_ring_round_a_hole_whose_rim_stretches_somewhere():
    """A hole pulled into a slit (its rim lengthens at the ends) is not a squeezed hole: no ring rope."""
    from mdsr_opt.synthesis.routing_rings import hole_rings

    mesh = mesh_polygon(_ring(48, (0.0, 0.0), (4.0, 3.0)), [_ring(20, (0.0, 0.0), (0.7, 0.35))], resolution=900)
    P = mesh.points
    rim = np.asarray(mesh.boundary_loops[1])
    res = solve_external(mesh, NeoHookean(E=1.0, nu=0.4), np.zeros(0, dtype=np.int64), (rim, P[rim] * (1.3, 0.3)))
    assert res.success
    E = mesh.edges
    w = 1.0 - np.linalg.norm(res.x[E[:, 1]] - res.x[E[:, 0]], axis=1) / mesh.edge_lengths
    wq = np.rint(w / 1e-9).astype(np.int64)
    lim = 1.0 - np.cos(np.radians(45.0))
    assert (w[mesh.edge_rows(rim, np.roll(rim, -1))] < 0).any()
    assert hole_rings(mesh, wq > 10**6, wq, lim, 10**6) == []
    # the squeezed rim of the same plate is ringed
    res = solve_external(mesh, NeoHookean(E=1.0, nu=0.4), np.zeros(0, dtype=np.int64), (rim, P[rim] * (0.6, 0.4)))
    w = 1.0 - np.linalg.norm(res.x[E[:, 1]] - res.x[E[:, 0]], axis=1) / mesh.edge_lengths
    wq = np.rint(w / 1e-9).astype(np.int64)
    (cycle,) = hole_rings(mesh, wq > 10**6, wq, lim, 10**6)
    assert abs(_winding(P, cycle + cycle[:1], (0.0, 0.0))) == pytest.approx(2 * np.pi, abs=1e-9)
