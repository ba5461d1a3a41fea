"""A rigid disk keeps the body's boundary segments out, not only its nodes (a disk has no corners): the
disk-segment rows of :mod:`mdsr_opt.mechanics.contact`, checked against shapely, finite differences and the
reactions' balance."""

import numpy as np
import pytest
from shapely.geometry import LineString, Point, Polygon
from shapely.ops import unary_union

from mdsr_opt import Disk, Mesh, NeoHookean, nodes_in_box, solve_external
from mdsr_opt.mechanics.contact import ContactRows
from mdsr_opt.mechanics.model import get_model
from conftest import assert_matches_central_differences

MAT = NeoHookean(1.0, 0.3)


def _overlap(mesh, x, disk):
    """The area the body (its triangles' union, shapely) shares with the disk (a 1024-gon inscribed in it)."""
    body = unary_union([Polygon(x[t]) for t in mesh.triangles])
    return body.intersection(Point(*disk.center).buffer(disk.radius, 256)).area


def _edge_gap(mesh, x, disk):
    """The smallest distance from the disk's centre to a boundary segment, less the radius (shapely)."""
    c = Point(*disk.center)
    return min(c.distance(LineString(x[e])) for e in mesh.boundary_edges) - disk.radius


def _reaction(mesh, x, nodes):
    model = get_model(mesh, MAT)
    return model.gradient(np.asarray(x).reshape(-1), model.params(MAT)).reshape(-1, 2)[nodes].sum(0)


def test_disk_segment_rows_match_the_distance_and_finite_differences():
    rng = np.random.default_rng(7)
    x = np.array([[0, 0], [1, 0], [2, 0.3], [3, 0.1]], float) + rng.normal(scale=0.05, size=(4, 2))
    C = np.array([[0.5, 0.7], [2.6, 0.9], [-0.4, 0.5], [3.6, 0.6]])  # the centres: inside, beyond the ends
    pts = [(4 + j, a, b) for j in range(len(C)) for a, b in ((1, 0), (2, 1), (3, 2))]
    w = [(4.0, 0.3 + 0.05 * (p[0] - 4)) for p in pts]
    rows = ContactRows(np.array(pts), 4, consts=C, w=np.array(w))
    X, xf = x.copy(), x.reshape(-1)
    g = rows.values(xf)
    seen = {"in": 0, "out": 0}
    for i, (c, a, b) in enumerate(pts):
        cc, r = C[c - 4], w[i][1]
        d = X[b] - X[a]
        t = float((cc - X[a]) @ d / (d @ d))
        dist = Point(*cc).distance(LineString([X[a], X[b]])) - r
        side = d[1] * (cc - X[a])[0] - d[0] * (cc - X[a])[1]
        if 0 <= t <= 1 and side > 0:  # the centre projects onto it: the distance to the segment
            seen["in"] += 1
            assert g[i] == pytest.approx(dist, abs=1e-12)
        elif not 0 <= t <= 1:  # beyond an end: looser than the end node's row, which is the distance there
            seen["out"] += 1
            end = X[b] if t > 1 else X[a]
            assert g[i] > np.hypot(*(cc - end)) - r == pytest.approx(dist, abs=1e-12)
    assert seen["in"] >= 2 and seen["out"] >= 3
    J = rows.jacobian(xf).toarray()
    lam = rng.normal(size=rows.n_rows)
    H = rows.hessian(xf, lam).toarray()
    h = 1e-6
    for k in range(len(xf)):
        e = np.zeros(len(xf))
        e[k] = h
        assert np.allclose(J[:, k], (rows.values(xf + e) - rows.values(xf - e)) / (2 * h), atol=1e-7)
        fdh = (rows.jacobian(xf + e).T @ lam - rows.jacobian(xf - e).T @ lam) / (2 * h)
        assert np.allclose(H[:, k], fdh, atol=1e-6)


@pytest.mark.parametrize("d", [0.05, 0.3])
def test_a_disk_smaller_than_an_edge_stays_out_of_the_body(d):
    """A block (edges 0.25) pushed up against a disk of radius 0.05 above the middle of a top edge: before the
    disk-segment rows it went 37 % into the body with success (d 0.05) or the solve stalled (d 0.3)."""
    mesh = Mesh.rectangle(2.0, 1.0, 8, 4)
    P = mesh.points
    bot = nodes_in_box(mesh, ymax=0.0)
    disk = Disk((1.125, 1.06), 0.05)
    res = solve_external(mesh, MAT, None, {int(i): P[i] + [0, d] for i in bot}, obstacles=[disk])
    assert res.success and res.stable and res.residual <= 1e-8, res.status
    assert _overlap(mesh, res.x, disk) == 0.0
    assert _edge_gap(mesh, res.x, disk) >= res.contact["gap"] * (1 - 1e-6) - 1e-9
    assert any(p["kind"] == "obstacle segment" and p["force"] > 0 for p in res.contact["pairs"])
    # the disk takes the whole load the drags put in
    load = _reaction(mesh, res.x, bot)
    assert np.allclose(res.contact["obstacle_forces"][0], load, rtol=1e-6, atol=1e-8)
    assert np.allclose(np.sum(res.contact["node_forces"], axis=0), -load, rtol=1e-6, atol=1e-8)


def _jaws_on_disk():
    """A C (edges about 0.25), its back anchored, its jaws dragged shut by 0.5 each on a disk of radius 0.4:
    ``(mesh, anchors, drags, disk)``."""
    C = [[0, 0], [3, 0], [3, 0.8], [1, 0.8], [1, 2.2], [3, 2.2], [3, 3], [0, 3]]
    mesh = Mesh.from_polygon(C, max_area=0.03)
    P = mesh.points
    back = nodes_in_box(mesh, xmax=0.0)
    lo, hi = nodes_in_box(mesh, xmin=2.8, ymax=0.8), nodes_in_box(mesh, xmin=2.8, ymin=2.2)
    drags = {**{int(i): P[i] + [0, 0.5] for i in lo}, **{int(i): P[i] + [0, -0.5] for i in hi}}
    return mesh, back, drags, Disk((2.2, 1.5), 0.4)


def test_coarse_jaws_closed_on_a_disk_keep_their_edges_out():
    """A C whose jaws (coarse, edges about 0.25) are dragged shut by 0.5 on a disk of radius 0.4: before, its
    edges cut 0.026 into the disk (shapely overlap 6.8e-3)."""
    mesh, back, drags, disk = _jaws_on_disk()
    res = solve_external(mesh, MAT, back, drags, obstacles=[disk])
    assert res.success and res.stable, res.status
    assert _overlap(mesh, res.x, disk) == 0.0
    assert _edge_gap(mesh, res.x, disk) >= res.contact["gap"] * (1 - 1e-6) - 1e-9
    # the forces on the disk: what the drags and the clamp put in
    load = _reaction(mesh, res.x, np.r_[list(drags), back])
    assert np.allclose(res.contact["obstacle_forces"][0], load, rtol=1e-5, atol=1e-8)


def test_strip_bent_over_a_small_disk_wraps_it_without_cutting_in():
    """A 4 x 0.2 strip (edges 0.2) clamped at both ends and pushed down in the middle over a disk of radius 0.1:
    the bent strip rests on the disk with its segments, not cutting through it between its nodes."""
    mesh = Mesh.rectangle(4.0, 0.2, 20, 1)
    P = mesh.points
    ends = np.flatnonzero((P[:, 0] == 0.0) | (P[:, 0] == 4.0))
    disk = Disk((2.1, -0.15), 0.1)
    drags = {int(i): (P[i, 0], P[i, 1] - 0.6) for i in ends}
    res = solve_external(mesh, MAT, None, drags, obstacles=[disk])
    assert res.success and res.stable, res.status
    assert _overlap(mesh, res.x, disk) == 0.0
    assert _edge_gap(mesh, res.x, disk) >= res.contact["gap"] * (1 - 1e-6) - 1e-9
    assert res.contact["total_force"] > 0
    load = _reaction(mesh, res.x, ends)
    assert np.allclose(res.contact["obstacle_forces"][0], load, rtol=1e-5, atol=1e-8)


def test_friction_at_a_point_on_a_segment_matches_finite_differences():
    from mdsr_opt.mechanics.friction import FrictionTerm

    rng = np.random.default_rng(11)
    t = rng.normal(size=(3, 2))
    t /= np.linalg.norm(t, axis=1)[:, None]
    w = np.array([[1.0, 0.0], [0.3, 0.7], [0.55, 0.45]])  # a node, then two points on segments
    ft = FrictionTerm(np.array([[0, 0], [1, 2], [3, 1]]), t, rng.normal(size=8), np.array([0.5, 1.0, 2.0]), 0.4,
                      0.05, w)
    assert ft.nodes.tolist() == [0, -1, -1]
    x = rng.normal(size=8)
    assert_matches_central_differences(ft.energy, ft.gradient, lambda y: ft.hessian(y).toarray(), x)
    g = ft.gradient(x)
    # a point's friction force is shared by its segment's nodes by their weights, and sums to it
    f = ft.forces(x)
    G = g.reshape(-1, 2)
    assert np.allclose(G[2], 0.7 * f[1] * t[1])
    assert np.allclose(G.sum(0), (f[:, None] * t).sum(0))


def test_coarse_jaws_close_on_a_disk_with_friction_in_seconds():
    """The C's jaws shut on the disk with Coulomb friction mu 0.3: before, IPOPT's steps cycled across the
    friction potential's kink until each solve's iteration cap (57,454 iterations in all, 156 s) and the load
    stepping stalled at 0.85."""
    mesh, back, drags, disk = _jaws_on_disk()
    res = solve_external(mesh, MAT, back, drags, obstacles=[disk], friction=0.3)
    assert res.success and res.stable, res.status
    assert res.iterations < 5000
    assert _overlap(mesh, res.x, disk) == 0.0
    fr = res.contact["friction"]
    F, N = np.array(fr["tangential"]), np.array(fr["normal"])
    assert N.max() > 0 and np.all(np.abs(F) <= 0.3 * N * (1 + 1e-9) + 1e-12)  # inside the friction cone
    load = _reaction(mesh, res.x, np.r_[list(drags), back])
    assert np.allclose(res.contact["obstacle_forces"][0], load, rtol=1e-5, atol=1e-7)


@pytest.mark.slow
def test_a_failed_contact_solve_reports_the_contacts_of_the_state_it_returns():
    """A ring (R 2, hole 1) squeezed by 1.2 with self-contact is rejected (its residual 0.0185 stays above tol);
    its report listed no pair and a total force of 0, for a state squeezed further than the solved d = 1.1
    (38 pairs, 0.448). The forces reported now are those fitted on its touching rows."""
    th = np.linspace(0, 2 * np.pi, 48, endpoint=False)
    outer, inner = np.c_[2 * np.cos(th), 2 * np.sin(th)], np.c_[np.cos(th), np.sin(th)]
    mesh = Mesh.from_polygon(outer, holes=[inner[::-1]], max_area=0.03)
    P = mesh.points
    top, bot = nodes_in_box(mesh, ymin=1.6), nodes_in_box(mesh, ymax=-1.6)

    def squeeze(d):
        return solve_external(mesh, MAT, None, {**{int(i): P[i] + [0, -d] for i in top},
                                                **{int(i): P[i] + [0, d] for i in bot}}, contact=True)

    ok, bad = squeeze(1.1), squeeze(1.2)
    assert ok.success  # (should the squeeze by 1.2 come to solve, its report is checked the same way)
    c = bad.contact
    assert c["forces_known"] and c["load_fraction"] == 1.0
    assert len(c["pairs"]) >= len(ok.contact["pairs"]) and c["total_force"] > ok.contact["total_force"]
    assert all(p["force"] > 0 and p["gap"] <= c["gap"] + 1e-4 * mesh.size for p in c["pairs"])
    assert np.allclose(np.sum(c["node_forces"], axis=0), 0.0, atol=1e-9)  # self-contact: action and reaction
