"""Contact: rigid obstacles and self-contact of the boundary (issue 35), each result checked independently
(shapely for crossings and gaps, the energy gradient for force balance, finite differences for the gap
rows' derivatives)."""

import copy

import numpy as np
import pytest
import shapely
from shapely.geometry import LineString, Point, Polygon

from mdsr_opt import Disk, HalfPlane, Mesh, NeoHookean, Obstacle, solve_external
from mdsr_opt.mechanics.contact import ContactRows
from mdsr_opt.mechanics.quadratic import transfer_state
from mdsr_opt.mechanics.model import get_model
from conftest import assert_matches_central_differences

MAT = NeoHookean(1.0, 0.3)


def _outline(mesh, x):
    return Polygon(np.asarray(x)[mesh.boundary_loops[0]])


def _min_gap(mesh, x):
    """The smallest distance between a boundary node and a boundary segment with no end within two boundary
    edges of it (shapely); a crease (the boundary folded at one node) is held by its angle row instead, which keeps
    the gap along the edges' rest lengths."""
    x = np.asarray(x)
    seg = mesh.boundary_edges
    best = np.inf
    lines = [LineString(x[s]) for s in seg]
    tree = shapely.STRtree(lines)
    near = {}
    for loop in mesh.boundary_loops:
        m = len(loop)
        for k, q in enumerate(loop):
            near[int(q)] = {int(loop[(k + d) % m]) for d in range(-2, 3)}
    for q in mesh.boundary_nodes:
        pt = Point(x[q])
        for j in tree.query(pt.buffer(0.2)):
            if set(seg[j].tolist()) & near[int(q)]:
                continue
            best = min(best, pt.distance(lines[j]))
    return best


def _drag_reaction(mesh, x, nodes):
    """The total force the drags exert on the body: the energy gradient summed over the dragged nodes."""
    model = get_model(mesh, MAT)
    g = model.gradient(np.asarray(x).reshape(-1), model.params(MAT)).reshape(-1, 2)
    return g[nodes].sum(0)


def _push(mesh, frac):
    P = mesh.points
    left, right = np.flatnonzero(P[:, 0] == 0.0), np.flatnonzero(P[:, 0] == P[:, 0].max())
    return left, {int(i): (P[i, 0] - frac * 4.0, P[i, 1]) for i in right}, right


def test_gap_rows_derivatives_match_finite_differences():
    rng = np.random.default_rng(3)
    x = rng.uniform(0, 1, (5, 2))
    rows = ContactRows(np.array([[0, 1, 2], [3, 5, 6], [4, 7, 8]]), 5,
                       consts=np.array([[0.2, -0.5], [1.3, -0.4], [0.5, 2.0], [9.0, 9.0]]),
                       w=np.array([[0.0, 0.0], [2.0, 0.0], [1.0, 0.7]]))
    x = x.reshape(-1)
    J = rows.jacobian(x).toarray()
    lam = np.array([0.7, -1.3, 2.1])
    H = rows.hessian(x, lam).toarray()
    h = 1e-6
    for k in range(len(x)):
        e = np.zeros(len(x))
        e[k] = h
        fd = (rows.values(x + e) - rows.values(x - e)) / (2 * h)
        assert np.allclose(J[:, k], fd, atol=1e-7)
        fdh = ((rows.jacobian(x + e).T @ lam) - (rows.jacobian(x - e).T @ lam)) / (2 * h)
        assert np.allclose(H[:, k], fdh, atol=1e-6)
    # the node-segment gap is the signed distance from the segment's line (outside: right of a -> b)
    p, a, b = x.reshape(-1, 2)[[0, 1, 2]]
    d = b - a
    assert rows.values(x)[0] == pytest.approx((d[1] * (p - a)[0] - d[0] * (p - a)[1]) / np.hypot(*d))


def test_a_point_that_slid_past_its_segment_is_handed_to_the_segment_it_slid_to():
    """handoff_rows: a point pressed on a bottom segment of a strip that slid 2.5 segment lengths past its end
    goes to the segment under it (the walk along the boundary), not only to the next one; without the state,
    to the next one."""
    from mdsr_opt.mechanics.contact import handoff_rows

    mesh = Mesh.rectangle(4.0, 1.0, 8, 2)  # bottom segments (k, k + 1), k = 0..7, 0.5 long
    x = mesh.points.copy()
    p = int(np.flatnonzero((x[:, 1] == 1.0) & (x[:, 0] == 2.0))[0])
    rows = ContactRows([[p, 1, 2]], mesh.n_nodes, w=np.zeros((1, 2)))
    x[p] = (2.0 + 0.25 + 0.01, 0.01)  # over segment (4, 5): 2.5 lengths past node 2
    t = rows.projections(x)
    assert t[0] == pytest.approx(3.52)
    assert handoff_rows(mesh, rows, [0], t, x).pts.tolist() == [[p, 4, 5]]
    assert handoff_rows(mesh, rows, [0], t).pts.tolist() == [[p, 2, 3]]
    back = ContactRows([[p, 6, 7]], mesh.n_nodes)  # slid the other way past node 6: (4, 5) again
    assert handoff_rows(mesh, back, [0], back.projections(x), x).pts.tolist() == [[p, 4, 5]]


def test_strip_pressed_onto_ground_rests_on_it_and_reactions_balance():
    mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    P = mesh.points
    top = np.flatnonzero(P[:, 1] == 1.0)
    drags = {int(i): (P[i, 0], P[i, 1] - 0.3) for i in top}
    level = -0.05
    res = solve_external(mesh, MAT, None, drags, obstacles=[HalfPlane((0.0, level), (0.0, 1.0))])
    assert res.success and res.stable, res.status
    assert res.residual <= 1e-8
    gap = res.contact["gap"]
    assert gap == pytest.approx(1e-4 * mesh.size)
    y = res.x[:, 1]
    assert y.min() >= level + gap * (1 - 1e-6)  # no node below the ground (nor inside the gap)
    bottom = np.flatnonzero(P[:, 1] == 0.0)
    assert np.allclose(y[bottom], level + gap, atol=1e-9)  # the whole bottom rests on it
    assert len(res.contact["pairs"]) == len(bottom)
    assert all(p["force"] > 0 for p in res.contact["pairs"])
    # the force on the ground equals the load the drags apply, and the contact forces on the nodes sum to it
    load = _drag_reaction(mesh, res.x, top)
    assert np.allclose(res.contact["obstacle_forces"][0], load, rtol=1e-6, atol=1e-9)
    assert np.allclose(-np.sum(res.contact["node_forces"], axis=0), load, rtol=1e-6, atol=1e-9)
    assert load[1] < -0.5 and abs(load[0]) < 1e-6


def test_contact_off_by_default_and_on_changes_nothing_when_nothing_touches():
    mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    left, drags, _ = _push(mesh, 0.05)
    plain = solve_external(mesh, MAT, left, drags)
    assert plain.contact is None
    on = solve_external(mesh, MAT, left, drags, contact=True, obstacles=[Disk((2.0, -3.0), 1.0)])
    assert on.success and plain.success
    assert on.contact["pairs"] == [] and on.contact["total_force"] == 0.0
    assert np.abs(on.x - plain.x).max() < 1e-6  # the same equilibrium, both within tol 1e-8
    assert on.energy == pytest.approx(plain.energy, rel=1e-8)


def _check_push(mesh, frac):
    left, drags, right = _push(mesh, frac)
    res = solve_external(mesh, MAT, left, drags, contact=True)
    assert res.success, res.status
    assert res.stable and res.residual <= 1e-8
    poly = _outline(mesh, res.x)
    assert poly.is_valid  # shapely: the outline does not cross itself
    assert not mesh.boundary_crosses(res.x)
    assert _min_gap(mesh, res.x) >= res.contact["gap"] - 1e-8 * mesh.size  # the gap, to the tolerance
    return res, right


def test_strip_clamped_at_both_ends_pushed_30_percent_folds_without_crossing():
    mesh = Mesh.rectangle(4.0, 1.0, 40, 10)
    left, drags, _ = _push(mesh, 0.3)
    plain = solve_external(mesh, MAT, left, drags)
    assert not plain.success and "crosses itself" in plain.status
    res, _ = _check_push(mesh, 0.3)
    assert len(res.contact["pairs"]) > 0 and res.contact["total_force"] > 0
    assert all(p["kind"] in ("self", "fold", "inner") for p in res.contact["pairs"])


@pytest.mark.slow
def test_strip_pushed_10_to_50_percent_energy_continuous():
    mesh = Mesh.rectangle(4.0, 1.0, 40, 10)
    pushes = np.round(np.arange(0.10, 0.501, 0.05), 2)
    energies, forces = [], []
    for frac in pushes:
        res, right = _check_push(mesh, frac)
        energies.append(res.energy)
        forces.append(_drag_reaction(mesh, res.x, right)[0])
    energies, forces = np.array(energies), np.array(forces)
    assert np.all(np.diff(energies) > 0)
    # continuous in the push: each rise is the work of the end's force (trapezoid rule, dx = -0.2 per 0.05)
    work = -0.5 * (forces[1:] + forces[:-1]) * 0.05 * 4.0
    assert np.allclose(np.diff(energies), work, rtol=0.25)


def test_disk_obstacle_holds_a_strip_bent_over_it():
    mesh = Mesh.rectangle(4.0, 0.5, 32, 4)
    P = mesh.points
    ends = np.flatnonzero((P[:, 0] == 0.0) | (P[:, 0] == 4.0))
    drags = {int(i): (P[i, 0], P[i, 1] - 0.6) for i in ends}
    disk = Disk((2.0, -0.55), 0.5)
    res = solve_external(mesh, MAT, None, drags, obstacles=[disk])
    assert res.success and res.stable, res.status
    poly = _outline(mesh, res.x)
    # shapely: the body and the disk overlap by nothing more than the chords between nodes cut off
    h = 4.0 / 32
    assert poly.intersection(Point(2.0, -0.55).buffer(0.5, 256)).area < 0.5 * h ** 3
    assert np.linalg.norm(res.x - [2.0, -0.55], axis=1).min() >= 0.5 + res.contact["gap"] * (1 - 1e-6)
    load = _drag_reaction(mesh, res.x, ends)
    assert np.allclose(res.contact["obstacle_forces"][0], load, rtol=1e-6, atol=1e-9)
    assert load[1] < 0


def test_contact_inputs_refused_at_the_door():
    mesh = Mesh.rectangle(4.0, 1.0, 8, 2)
    P = mesh.points
    left, drags, _ = _push(mesh, 0.1)
    with pytest.raises(ValueError, match="holds node"):
        solve_external(mesh, MAT, left, drags, obstacles=[Disk((2.0, 0.5), 0.2)])
    with pytest.raises(ValueError, match="convex"):
        Obstacle([(0, 0), (2, 0), (1, 0.2), (2, 1), (0, 1)])
    with pytest.raises(TypeError, match="obstacles"):
        solve_external(mesh, MAT, left, drags, obstacles=[(0.0, 0.0)])
    with pytest.raises(TypeError, match="contact must be True or False"):
        solve_external(mesh, MAT, left, drags, contact="yes")
    with pytest.raises(ValueError, match="ipopt"):
        solve_external(mesh, MAT, left, drags, contact=True, backend="newton")
    with pytest.raises(ValueError, match="contact_gap"):
        solve_external(mesh, MAT, left, drags, contact=True, contact_gap=-1.0)
    with pytest.raises(ValueError, match="radius"):
        Disk((0, 0), 0.0)
    with pytest.raises(ValueError, match="normal"):
        HalfPlane((0, 0), (0, 0))
    assert P.shape[1] == 2


def _gripper():
    """The library's gripper body (coarse) with two muscles along its inner rim: contracted, they close it."""
    from pathlib import Path

    from mdsr_opt.scenes.library import load_problem_module
    from mdsr_opt.scenes.select import boundary_path

    g = load_problem_module(Path(__file__).resolve().parents[1] / "problems" / "gripper.py")
    mesh, mat = g.body("coarse")
    ri, half = g.R0 - g.WIDTH / 2, g.OPENING / 2

    def rim(a0, a1):
        return ri * np.array([np.cos(a0), np.sin(a0)]), ri * np.array([np.cos(a1), np.sin(a1)])

    upper = boundary_path(mesh, *rim(half + 0.08, np.pi - 0.12), via=ri * np.array([0.0, 1.0]), name="upper")
    lower = boundary_path(mesh, *rim(np.pi + 0.12, 2 * np.pi - half - 0.08), via=ri * np.array([0.0, -1.0]),
                          name="lower")
    return mesh, mat, [upper, lower]


def test_gripper_jaws_meet_with_self_contact_in_internal_driving():
    from mdsr_opt import solve_internal

    mesh, mat, muscles = _gripper()
    plain = solve_internal(mesh, mat, muscles, [0.3, 0.3])
    assert not plain.success and "crosses itself" in plain.status
    res = solve_internal(mesh, mat, muscles, [0.3, 0.3], contact=True)
    assert res.success and res.stable and res.residual <= 1e-8, res.status
    assert _outline(mesh, res.x).is_valid and not mesh.boundary_crosses(res.x)
    assert _min_gap(mesh, res.x) >= res.contact["gap"] - 1e-8 * mesh.size
    assert any(p["kind"] == "self" and p["force"] > 0 for p in res.contact["pairs"])
    assert np.allclose(res.achieved, 0.3, atol=1e-7) and np.all(res.tension > 0)
    # the contact forces are internal: they sum to zero
    assert np.abs(np.sum(res.contact["node_forces"], axis=0)).max() < 1e-9


def test_gripper_holds_a_disk_with_friction():
    from mdsr_opt import free_disk, grip_report, solve_internal  # top-level names, as the README calls them

    mesh, mat, muscles = _gripper()
    # (radius 1.2: a disk of 1.1 is pushed out into the opening, to where it would hold a jaw's node at rest)
    res, disk, info = free_disk(lambda d: solve_internal(mesh, mat, muscles, [0.3, 0.3], obstacles=[d]),
                                Disk((0.0, 0.0), 1.2))
    assert info["converged"], info
    assert res.success and res.stable, res.status
    N = np.array([p["force"] for p in res.contact["pairs"] if p["kind"] in ("obstacle", "obstacle segment")])
    assert len(N) >= 2 and N.min() > 0
    # a free disk: the contacts' net force on it vanishes and the body's mount (gauge) holds nothing
    assert np.linalg.norm(res.contact["obstacle_forces"][0]) <= 1e-3 * N.max()
    assert np.linalg.norm(res.contact["gauge_force"]) <= 1e-3 * N.max()
    # no body node inside the disk, and no boundary segment cuts into it (shapely, a 1024-gon inside the disk)
    assert np.linalg.norm(res.x - disk.center, axis=1).min() >= disk.radius
    assert _outline(mesh, res.x).intersection(Point(*disk.center).buffer(disk.radius, 256)).area == 0.0
    g3, g1 = grip_report(res.x, res.contact, disk, 0.3), grip_report(res.x, res.contact, disk, 1.0)
    g0 = grip_report(res.x, res.contact, disk, 0.0)
    assert g0["holding_force"] == 0.0 and max(g0["resisted"]) <= 1e-3 * N.sum()
    # no load beyond mu times the normal forces is held
    assert max(g3["resisted"]) <= 0.3 * N.sum() * (1 + 1e-9) and max(g1["resisted"]) <= N.sum() * (1 + 1e-9)
    # the jaws' two faces squeeze the disk from opposite sides (their contact points on a line through its
    # centre): friction holds a load across that line up to mu times both normal forces (closed form), and along
    # it nothing (the normal forces are kept as the load comes on)
    assert len(N) == 2
    p0, p1 = np.array(g3["contact_points"])
    u = (p1 - p0) / np.linalg.norm(p1 - p0)
    v = disk.center - p0
    assert abs(u[0] * v[1] - u[1] * v[0]) <= 1e-2 * disk.radius
    across = np.array([-u[1], u[0]])
    w = 0.3 * 2 * N.min()
    for sgn in (1.0, -1.0):
        assert grip_report(res.x, res.contact, disk, 0.3, load=0.95 * w * sgn * across)["held"]
        assert not grip_report(res.x, res.contact, disk, 0.3, load=1.1 * 0.3 * N.sum() * sgn * across)["held"]
        assert not grip_report(res.x, res.contact, disk, 0.0, load=0.1 * w * sgn * across)["held"]
        assert not grip_report(res.x, res.contact, disk, 0.3, load=0.1 * w * sgn * u)["held"]


def test_friction_term_derivatives_match_finite_differences():
    from mdsr_opt.mechanics.friction import FrictionTerm

    rng = np.random.default_rng(5)
    t = rng.normal(size=(3, 2))
    t /= np.linalg.norm(t, axis=1)[:, None]
    ft = FrictionTerm(np.array([0, 2, 3]), t, rng.normal(size=8), np.array([0.5, 1.0, 2.0]), 0.4, 0.05)
    x = rng.normal(size=8)
    assert_matches_central_differences(ft.energy, ft.gradient, lambda y: ft.hessian(y).toarray(), x)
    assert np.all(np.abs(ft.forces(x)) < 0.4 * ft.N)  # never beyond mu N


@pytest.mark.parametrize("mu", [0.0, 0.2, 1.0])
def test_strip_pressed_and_sheared_on_ground_with_coulomb_friction(mu):
    mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    P = mesh.points
    top, bottom = np.flatnonzero(P[:, 1] == 1.0), np.flatnonzero(P[:, 1] == 0.0)
    drags = {int(i): (P[i, 0] + 0.3, P[i, 1] - 0.3) for i in top}
    res = solve_external(mesh, MAT, None, drags, obstacles=[HalfPlane((0.0, -0.05), (0.0, 1.0))], friction=mu)
    assert res.success and res.stable and res.residual <= 1e-8, res.status
    fr = res.contact["friction"]
    load = _drag_reaction(mesh, res.x, top)
    # the ground takes the whole load, normal and tangential (friction included)
    assert np.allclose(res.contact["obstacle_forces"][0], load, rtol=1e-6, atol=1e-8)
    assert res.x[:, 1].min() >= -0.05
    dx = res.x[bottom, 0] - P[bottom, 0]
    if mu == 0.0:
        assert abs(load[0]) < 1e-8 and fr is None
        assert dx.min() > 0.05  # frictionless: the bottom slides with the top
        return
    F, N, slip = np.array(fr["tangential"]), np.array(fr["normal"]), np.array(fr["slipping"])
    assert np.all(np.abs(F) <= mu * N * (1 + 1e-9) + 1e-12)  # inside the friction cone
    assert load[0] > 0.01  # the shear reaches the ground through friction
    stick = ~slip & (N > 0)
    assert stick.sum() >= 3
    # sticking nodes do not slide in the (last) load step: a creep of order eps
    assert np.abs(np.array(fr["step_slide"])[stick]).max() < 10 * fr["eps"]
    assert np.abs(np.array(fr["step_slide"])[slip]).min() > 10 * fr["eps"] if slip.any() else True
    if mu == 0.2:
        assert slip.sum() > 0  # at mu 0.2 part of the bottom slides


#: the turns solved from rest in this module, by (nx, ny, sign): each is solved and checked once per session
_TURNS: dict = {}


def _turn(nx, ny, sign, seed=None):
    """The 4 x 1 strip (nx x ny cells), left end clamped, right end turned by ``sign`` x 90 degrees about its
    centre and moved by (-2, 2) (issue 35): the inner side wrinkles into creases that fold onto themselves.
    ``seed``: a solved ``(mesh, result)`` of the turn on a coarser mesh, whose state carried to this mesh's
    nodes starts one load step at full load. A turn from rest asked again (the same mesh and sign in another
    test) is the first one's, checked then, as a copy: no test sees another's changes."""
    if seed is None:
        key = (nx, ny, sign)
        if key not in _TURNS:
            _TURNS[key] = _solve_turn(nx, ny, sign, None)
        return copy.deepcopy(_TURNS[key])
    return _solve_turn(nx, ny, sign, seed)


def _solve_turn(nx, ny, sign, seed):
    mesh = Mesh.rectangle(4.0, 1.0, nx, ny)
    P = mesh.points
    left, right = np.flatnonzero(P[:, 0] == 0.0), np.flatnonzero(P[:, 0] == 4.0)
    c, th = np.array([4.0, 0.5]), np.radians(sign * 90.0)
    R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    drags = {int(i): tuple(c + R @ (P[i] - c) + np.array([-2.0, 2.0])) for i in right}
    kw = {} if seed is None else {"initial_guess": transfer_state(seed[0], seed[1].x, P), "min_step": 1.0}
    res = solve_external(mesh, MAT, left, drags, contact=True, **kw)
    assert res.success, res.status
    assert res.stable and res.residual <= 1e-8
    assert _outline(mesh, res.x).is_valid and not mesh.boundary_crosses(res.x)  # shapely, and the mesh's test
    assert _min_gap(mesh, res.x) >= res.contact["gap"] - 1e-8 * mesh.size
    assert np.allclose(res.x[right], [drags[int(i)] for i in right], atol=1e-9)
    return mesh, res


@pytest.mark.parametrize("sign", [-1.0, 1.0])
def test_strip_end_turned_90_degrees_solves_with_contact_either_way(sign):
    _, res = _turn(20, 5, sign)
    if sign < 0:  # turned clockwise the inner side creases: its faces press on each other
        assert len(res.contact["pairs"]) > 0 and res.contact["total_force"] > 0
        assert all(p["force"] > 0 for p in res.contact["pairs"])
    else:  # turned the other way nothing touches
        assert res.contact["pairs"] == []


def test_strip_end_turned_90_degrees_energy_converges_under_refinement():
    """At 85, 175 and 297 nodes (16 x 4, 24 x 6, 32 x 8 cells) the strip's energy falls (a displacement model is
    too stiff on a coarse mesh) and its change at least halves from one refinement to the next, the last
    within 4 % of the energy."""
    E = np.array([_turn(4 * k, k, -1.0)[1].energy for k in (4, 6, 8)])
    d = np.abs(np.diff(E))
    assert E[0] > E[1] > E[2]
    assert d[1] <= 0.5 * d[0]
    assert d[1] <= 0.04 * E[2]


def _inner_contact(mesh, res):
    """The rest x of the nodes of the inner (bottom) side in pushing pairs, sorted."""
    P = mesh.points
    touch = sorted({q for pr in res.contact["pairs"] for q in pr["nodes"] if q >= 0 and P[q, 1] == 0.0})
    return np.sort(P[touch, 0])


@pytest.mark.slow
def test_strip_end_turned_90_degrees_contact_region_converges():
    """The turn's contact region at 175, 297 and 451 nodes (24 x 6, 32 x 8, 40 x 10 cells): the inner side
    touches itself along one unbroken stretch (every boundary node in it in a pushing pair) from about x = 2.7
    to the last node before the turned end; the stretch's start moves by less than half as much from the second
    refinement to the third as from the first to the second (2.833, 2.625, 2.7). The sum of the contact forces
    (0.067, 0.091, 0.099) is not checked: the creases the stretch folds into are an element wide."""
    starts = []
    for k in (6, 8, 10):
        mesh, res = _turn(4 * k, k, -1.0)
        xs = _inner_contact(mesh, res)
        h = 4.0 / (4 * k)
        assert len(xs) >= 5 and np.allclose(np.diff(xs), h)  # one stretch, no node in it left out
        assert xs[-1] == pytest.approx(4.0 - h)
        starts.append(xs[0])
    ds = np.abs(np.diff(starts))
    assert 2.5 < starts[-1] < 2.9
    assert ds[1] < 0.5 * ds[0]


@pytest.mark.slow
def test_strip_end_turned_90_degrees_contact_region_at_1701_nodes():
    """The turn at 451 nodes by load steps and at 1,701 nodes (80 x 20 cells) in one load step at full load from
    the 451-node state carried to its nodes (a fine mesh's own load path folds its inner side into creases an
    element wide, one short load step at a time): each a stable state without crossing (``_turn``); the inner
    side touches itself along one unbroken stretch from x = 2.70 to 3.90 at both (3.90: the last node before the
    turned end at 451 nodes, the last but one at 1,701); the energy falls (0.24528, 0.23728). The finer state is a minimum of its own mesh, not the coarse state: its
    nodes move by more than a fifth of a coarse element from where they started (0.049). The total contact force
    (0.0986, 0.1476) is reported, not checked: at 1,701 nodes the nodes of both faces push (26 pairs on 25
    nodes), at 451 nodes 8 pairs on 13."""
    coarse = _turn(40, 10, -1.0)
    mesh, res = _turn(80, 20, -1.0, seed=coarse)
    start = transfer_state(coarse[0], coarse[1].x, mesh.points)
    assert np.abs(res.x - start).max() > 0.2 * 0.1
    starts = []
    for m, r in (coarse, (mesh, res)):
        xs = _inner_contact(m, r)
        h = 4.0 / (len(np.unique(m.points[:, 0])) - 1)
        assert len(xs) >= 5 and np.allclose(np.diff(xs), h)  # one stretch, no node in it left out
        assert 3.9 - 1e-9 <= xs[-1] <= 4.0 - h + 1e-9  # to within a coarse element of the turned end
        starts.append(xs[0])
    assert abs(starts[1] - starts[0]) <= 0.1 + 1e-9  # within one coarse element
    assert 2.5 < starts[1] < 2.9
    assert res.energy < coarse[1].energy


@pytest.mark.parametrize("cells", [(40, 4), pytest.param((60, 6), marks=pytest.mark.slow)])
def test_a_contact_solve_continues_from_a_state_solved_for_nearby_drags(cells):
    """initial_guess = the state solved for a slightly smaller push: the drags move from where that state has
    them to their targets, a short continuation; they had moved from rest, back through states far from the
    guess (trial9, the 60 x 6 strip: 4,730 IPOPT iterations against 1,612 from rest). Same energy as from rest,
    the continued branch, no crossing. The default run folds the strip on 40 x 4 cells (205 nodes: 28
    iterations continued against 1,425 from rest, where 30 x 3 cells take 97 against 398), the trial's 427-node
    strip is slow (66 against 1,409)."""
    mesh = Mesh.rectangle(5.0, 0.5, *cells)
    P = mesh.points
    left, right = np.flatnonzero(P[:, 0] <= 1e-9), np.flatnonzero(P[:, 0] >= 5.0 - 1e-9)

    def pushed(f):
        return {int(i): P[i] + [-5.0 * f, 0.0] for i in right}

    near = solve_external(mesh, MAT, left, pushed(0.8), contact=True)
    fresh = solve_external(mesh, MAT, left, pushed(0.81), contact=True)
    cont = solve_external(mesh, MAT, left, pushed(0.81), contact=True, initial_guess=near.x)
    assert near.success and fresh.success and cont.success and cont.stable
    assert len(cont.steps) <= 2 and cont.iterations < fresh.iterations / 5, (cont.steps, cont.iterations)
    assert cont.energy == pytest.approx(fresh.energy, rel=1e-6)
    assert np.abs(cont.x - near.x).max() < 0.2           # the guess's own fold, pushed a little further
    assert _outline(mesh, cont.x).is_valid and _min_gap(mesh, cont.x) > 0.0


def test_polish_falls_back_to_independent_rows_where_the_held_rows_are_dependent():
    """Where the held contact rows are dependent (a point past a segment's end held by both segments' rows at a
    flat fold; here every pushing row of the turned strip twice, which makes the KKT matrix singular), the polishing
    Newton step holds an independent subset of them and meets the tolerance as with each row once."""
    from mdsr_opt.mechanics.contactsolve import ContactProblem, ContactSpec, contact_residual, polish
    from mdsr_opt.mechanics.kkt import kkt_factor

    mesh, res = _turn(20, 5, -1.0)
    P = mesh.points
    left, right = np.flatnonzero(P[:, 0] == 0.0), np.flatnonzero(P[:, 0] == 4.0)
    model = get_model(mesh, MAT)
    p = model.params(MAT)
    gap = res.contact["gap"]
    prob = ContactProblem(mesh, model, ContactSpec([], True, gap))
    fixed = np.zeros((mesh.n_nodes, 2), dtype=bool)
    fixed[np.r_[left, right]] = True
    fixed = fixed.reshape(-1)
    x = res.x.reshape(-1)
    once = prob.rows_for(x, [x])
    pushing = np.flatnonzero(once.values(x) - gap < 1e-6 * mesh.size)
    assert len(pushing) >= 2
    twice = ContactRows(np.vstack([once.pts[pushing]] * 2), mesh.n_nodes, None, np.vstack([once.w[pushing]] * 2),
                        np.vstack([once.labels[pushing]] * 2))
    rng = np.random.default_rng(0)
    y = x + np.where(fixed, 0.0, rng.normal(scale=1e-5 * mesh.size, size=x.shape))  # off the solution
    F = MAT.E * MAT.thickness * mesh.size
    for rows in (once, twice):
        r0, _ = contact_residual(prob, rows, y, p, fixed, 1e-8, F)
        assert r0.value > 1e-6
        x2, r2, fc = polish(prob, rows, y, p, fixed, 1e-8, F, steps=4)
        assert r2.value <= 1e-8, r2.value
        assert np.abs(x2 - x).max() < 1e-7 * mesh.size  # the solved state again
    H = model.hessian(y, p).tocsr()[~fixed][:, ~fixed]
    assert kkt_factor(H, twice.jacobian(y)[:, ~fixed]) is None  # all rows held: no step
