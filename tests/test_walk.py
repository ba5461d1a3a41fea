"""Walking on a table with Coulomb friction (mdsr_opt.synthesis.walk): the friction potential's derivatives,
a frictionless cycle that goes nowhere, stick and slip against the elastic forces, an inchworm that walks and
its refinement study."""

import json

import numpy as np
import pytest

from mdsr_opt import Mesh, Muscle, NeoHookean
from mdsr_opt.mechanics.model import get_model
from mdsr_opt.mechanics.units import Units
from mdsr_opt.synthesis.walk import EPS, GroundFriction, node_loads, place_rigidly, rigid_motion, walk
from conftest import load_script

MAT = NeoHookean(1.0, 0.3)
STROKE = 0.3


def _strip(nx, ny, length=4.0):
    mesh = Mesh.rectangle(length, 1.0, nx, ny)
    return mesh, mesh.points


def _bender(nx=16, ny=4):
    """A 4 x 1 strip with a rope along its top and one along its bottom edge."""
    mesh, P = _strip(nx, ny)
    top = Muscle([int(i) for i in np.argsort(P[:, 0]) if P[i, 1] == 1.0])
    bot = Muscle([int(i) for i in np.argsort(P[:, 0]) if P[i, 1] == 0.0])
    return mesh, [top, bot]


def _inchworm(nx=16, ny=4):
    """A 4 x 1 strip with a rope along its middle line between two feet, the ends x < 0.5 and x > 3.5."""
    mesh, P = _strip(nx, ny)
    tol = 1e-9
    mid = Muscle([int(i) for i in np.argsort(P[:, 0]) if abs(P[i, 1] - 0.5) < tol
                  and 0.5 - tol <= P[i, 0] <= 3.5 + tol])
    feet = {"rear": np.flatnonzero(P[:, 0] < 0.5 + tol), "front": np.flatnonzero(P[:, 0] > 3.5 - tol)}
    return mesh, [mid], feet


# rear foot down while the rope is released, front foot down while it pulls: the two-anchor inchworm
INCH_S = np.array([[0.0], [STROKE], [STROKE]])
INCH_T = np.array([[True, False], [False, True], [True, False]])


def test_friction_derivatives_match_finite_differences():
    rng = np.random.default_rng(3)
    n = 6
    x0 = rng.normal(size=2 * n)
    muN = rng.uniform(0.1, 2.0, n)
    eps = 1e-2
    gf = GroundFriction(x0, muN, eps)
    # points in stick (|u| ~ eps), across it and in slip (|u| >> eps)
    for scale in (0.3 * eps, 3 * eps, 1.0):
        x = x0 + scale * rng.normal(size=2 * n)
        h = 1e-6 * max(scale, eps)
        g_fd = np.array([(gf.energy(x + h * e) - gf.energy(x - h * e)) / (2 * h) for e in np.eye(2 * n)])
        H_fd = np.array([(gf.gradient(x + h * e) - gf.gradient(x - h * e)) / (2 * h) for e in np.eye(2 * n)])
        assert np.allclose(gf.gradient(x), g_fd, rtol=1e-6, atol=1e-8 * muN.max())
        H = gf.hessian(x).toarray()
        assert np.allclose(H, H_fd, rtol=1e-5, atol=1e-6 * np.abs(H).max())
        assert np.allclose(H, H.T)
    # the force never exceeds mu N, and reaches it in slip
    x = x0 + rng.normal(size=2 * n)
    f = np.hypot(*gf.forces(x).T)
    assert np.all(f <= muN) and np.all(f >= muN * 0.999)
    # the CasADi expression the solver uses is the same function
    import casadi as ca
    X, X0, M, E = ca.SX.sym("x", 2 * n), ca.SX.sym("x0", 2 * n), ca.SX.sym("m", n), ca.SX.sym("e")
    fn = ca.Function("D", [X, X0, M, E], [GroundFriction.expr(X, X0, M, E)])
    assert float(fn(x, x0, muN, eps)) == pytest.approx(gf.energy(x), rel=1e-12)


def test_node_loads_share_the_weight_by_area():
    mesh, P = _strip(8, 2)
    N = node_loads(mesh, 3.0)
    assert N.sum() == pytest.approx(3.0)
    corner, middle = int(np.argmin(P.sum(1))), int(np.argmin(np.hypot(P[:, 0] - 2.0, P[:, 1] - 0.5)))
    assert N[middle] > N[corner] > 0
    feet = np.flatnonzero(P[:, 0] < 0.6)
    Nf = node_loads(mesh, 3.0, feet)
    assert Nf.sum() == pytest.approx(3.0) and np.all(Nf[np.setdiff1d(np.arange(mesh.n_nodes), feet)] == 0)


def test_feet_loads_do_not_depend_on_the_mesh():
    """A foot's weight is a uniform pressure on the area its nodes cover (the triangles with three feet
    corners): on a refinement that keeps the feet nodes and adds the midpoints between them (everywhere, or
    near a point only) each foot carries the same share and its centre of pressure is the same point, the
    centroid of that area (exact for the consistent load); nodes of no covered triangle carry nothing; a foot
    of nodes that cover no triangle is refused."""
    from mdsr_opt.synthesis.walkstudy import refine_walker

    mesh, mus, _ = _inchworm(16, 4)
    P = mesh.points
    feet = {"rear": np.flatnonzero(np.hypot(P[:, 0] - 0.5, P[:, 1] - 0.5) < 0.4),
            "front": np.flatnonzero(P[:, 0] > 3.6)}
    every = np.concatenate(list(feet.values()))

    def figures(m, sets):
        N = node_loads(m, 2.0, np.concatenate(list(sets.values())))
        return [(N[v].sum(), N[v] @ m.points[v] / N[v].sum()) for v in sets.values()]

    inside = np.zeros(mesh.n_nodes, bool)
    inside[feet["rear"]] = True
    cov = inside[mesh.triangles].all(1)
    centroid = (mesh.areas[cov] @ P[mesh.triangles[cov]].mean(1)) / mesh.areas[cov].sum()
    base = figures(mesh, feet)
    assert base[0][1] == pytest.approx(centroid, abs=1e-12)
    share = mesh.areas[cov].sum() / (mesh.areas[cov].sum() + 0.25 * 1.0)  # the front foot covers x >= 3.75
    assert base[0][0] == pytest.approx(2.0 * share, rel=1e-12)
    m, ms, sets = mesh, mus, feet
    for near in (None, P[mus[0].nodes[0]][None]):
        m, ms, sets, _ = refine_walker(m, ms, sets, near=near, distance=None if near is None else 0.5)
        for (w0, c0), (w1, c1) in zip(base, figures(m, sets)):
            assert w1 == pytest.approx(w0, rel=1e-12) and np.allclose(c1, c0, atol=1e-12)
    lumped = np.zeros(mesh.n_nodes)  # the nodes' lumped areas would move the rear foot's share with the mesh
    np.add.at(lumped, mesh.triangles.reshape(-1), np.repeat(mesh.areas / 3, 3))
    assert abs(lumped[feet["rear"]].sum() / lumped[every].sum() - share) > 0.01
    lone = int(np.argmin(np.hypot(P[:, 0] - 2.0, P[:, 1] - 0.5)))  # a foot of one node: no triangle, no weight
    with pytest.raises(ValueError, match=r"feet: foot \d \(1 node\(s\) near \[2\.0, 0\.5\]\) covers no triangle"):
        node_loads(mesh, 1.0, np.append(every, lone))
    with pytest.raises(ValueError, match="feet cover no triangle"):
        node_loads(mesh, 1.0, [0, 20])


def test_rigid_motion_recovers_a_rigid_motion():
    rng = np.random.default_rng(0)
    X = rng.normal(size=(20, 2))
    a = 0.3
    R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    d, r = rigid_motion(X, X @ R.T + [1.0, -2.0])
    assert r == pytest.approx(a)
    assert np.allclose(d, X.mean(0) @ R.T + [1.0, -2.0] - X.mean(0))


def test_frictionless_symmetric_cycle_goes_nowhere():
    mesh, mus = _bender()
    S = np.array([[0.0, 0.0], [0.4, 0.0], [0.0, 0.0], [0.0, 0.4]])  # bend one way, straight, the other way
    r = walk(mesh, MAT, mus, S, mu=0.0, cycles=2)
    assert r.success
    assert np.all(r.distance < 1e-6 * mesh.size)
    assert np.all(np.abs(r.rotation) < 1e-6)
    # a body on ice: its centre of area stays where it was in every frame, bent or not
    w = node_loads(mesh, 1.0)
    c = np.einsum("n,fnk->fk", w, r.states)
    assert np.abs(c - c[0]).max() < 1e-6 * mesh.size
    # the shape did change (a cycle that moves nothing would pass vacuously)
    assert np.abs(r.states[2] - r.states[0]).max() > 0.05


def test_place_rigidly_is_the_weighted_least_squares_rigid_placement():
    """Against the objective itself: the placed state is a rigid motion of the given one (distances kept), and
    no small rotation or shift of it moves it less from the reference, with weights."""
    rng = np.random.default_rng(5)
    X0 = rng.normal(size=(15, 2))
    a = 0.7
    R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    Y = (X0 + 0.1 * rng.normal(size=X0.shape)) @ R.T + [3.0, -1.0]
    w = rng.uniform(0.1, 2.0, len(X0))
    Z = place_rigidly(Y.reshape(-1), X0.reshape(-1), w).reshape(-1, 2)
    dist = lambda P: np.hypot(*(P[:, None] - P[None]).transpose(2, 0, 1))
    assert np.allclose(dist(Z), dist(Y), atol=1e-12)
    cost = lambda P: float((w * ((P - X0) ** 2).sum(1)).sum())
    c = (w @ Z) / w.sum()
    for t in (1e-4, -1e-4):
        Rt = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
        assert cost((Z - c) @ Rt.T + c) > cost(Z)
        for e in np.eye(2):
            assert cost(Z + t * e) > cost(Z)
    d, r = rigid_motion(X0, Z, w)
    assert np.abs(d).max() < 1e-12 and abs(r) < 1e-12


def _walker_on_legs():
    """A 4 x 1.4 body on four legs, ropes on the front and back halves of its top edge (trial8's walker)."""
    from mdsr_opt import edge_path, nodes_in_box

    body = [[0, 0.6], [0.3, 0.6], [0.3, 0], [0.6, 0], [0.6, 0.6], [1.4, 0.6], [1.4, 0], [1.7, 0], [1.7, 0.6],
            [2.3, 0.6], [2.3, 0], [2.6, 0], [2.6, 0.6], [3.4, 0.6], [3.4, 0], [3.7, 0], [3.7, 0.6], [4, 0.6],
            [4, 1.4], [0, 1.4]]
    mesh = Mesh.from_polygon(body, max_area=0.02)
    mus = [edge_path(mesh, [(2.3, 1.4), (3.9, 1.4)]), edge_path(mesh, [(0.1, 1.4), (1.7, 1.4)])]
    return mesh, mus, np.array([[0.0, 0.0], [0.1, 0.05]]), dict(feet=nodes_in_box(mesh, ymax=0.35))


def _l_body():
    """An L (3 x 2.5, arms 1 wide), ropes along its bottom edge and its left edge, out in two frames and back."""
    from mdsr_opt import edge_path

    mesh = Mesh.from_polygon([[0, 0], [3, 0], [3, 1], [1, 1], [1, 2.5], [0, 2.5]], max_area=0.03)
    mus = [edge_path(mesh, [(0.2, 0.0), (2.8, 0.0)]), edge_path(mesh, [(0.0, 2.3), (0.0, 0.3)])]
    return mesh, mus, np.array([[0.0, 0.0], [0.15, 0.05], [0.3, 0.1], [0.15, 0.05]]), {}


@pytest.mark.parametrize("body", [_walker_on_legs, _l_body])
def test_frictionless_reciprocal_cycle_returns_the_body_at_the_default_tol(body):
    """Out and back with mu = 0 at the default tol: the body returns to where it was (before: the drag of
    1e-6 fixed its rigid motion only to the solve's tolerance, and the walker turned by 5.1e-4 rad, the L by
    9.4e-3 rad in every cycle, the same each time). The rigid placement in every frame is the least weighted
    motion: the centre of the drag's weights stays put to round-off."""
    mesh, mus, S, kw = body()
    r = walk(mesh, MAT, mus, S, mu=0.0, cycles=3, **kw)
    assert r.success
    assert np.abs(r.rotation).max() < 1e-7
    assert r.distance.max() < 1e-7 * mesh.size
    w = node_loads(mesh, 1.0, kw.get("feet"))
    c = np.einsum("n,fnk->fk", w, r.states)
    assert np.abs(c - c[0]).max() < 1e-12 * mesh.size
    # each frame's placement: no rotation about that centre against the previous frame (weighted best fit)
    assert max(abs(rigid_motion(r.states[k - 1], r.states[k], w)[1]) for k in range(1, len(r.states))) < 1e-12
    assert np.abs(r.states[2] - r.states[1]).max() > 0.01 * mesh.size  # the shape did change


def test_stick_nodes_do_not_move_and_slip_is_at_the_limit():
    """Against the elastic forces (computed from the body's energy, not from the friction): nodes under a
    tangential force below 0.9 mu N creep by at most the stated 2.07 eps; nodes that moved by more than 10 eps
    feel mu N."""
    mesh, mus, feet = _inchworm(16, 4)
    un = Units(mesh, MAT)
    weight = 0.2 * un.force
    mu = 0.5
    # both feet down while the rope pulls: the whole strip is loaded, stick and slip regions side by side
    r = walk(mesh, MAT, mus, np.array([[0.0], [STROKE]]), mu=mu, cycles=1, weight=weight, anchor_radius=0)
    assert r.success
    d = json.loads(json.dumps(r.to_dict(), allow_nan=False))  # every field, strict JSON
    assert np.array(d["states"]).shape == r.states.shape and d["mu"] == mu and repr(r).startswith("WalkResult(")
    model = get_model(un.unit_mesh, un.unit_material)
    p = model.params(un.unit_material)
    rope = np.zeros(mesh.n_nodes, dtype=bool)
    rope[list(mus[0].nodes)] = True
    eps = EPS * mesh.size
    n_stick = n_slip = 0
    for k in range(1, len(r.states)):
        x = r.states[k]
        F = np.hypot(*(model.gradient((x / un.length).reshape(-1), p).reshape(-1, 2) * un.force).T)
        u = np.hypot(*(x - r.states[k - 1]).T)
        cap = mu * r.loads[k]
        free = ~rope & (cap > 0)
        stick = free & (F < 0.9 * cap)
        assert np.all(u[stick] <= 2.07 * eps * 1.05 + 1e-9 * mesh.size)
        slip = free & (u > 10 * eps)
        assert np.allclose(F[slip], cap[slip], rtol=0.02)
        n_stick += stick.sum()
        n_slip += slip.sum()
    assert n_stick > 5 and n_slip > 5  # both regimes were checked


def test_heavier_foot_holds_lighter_foot_slides():
    mesh, P = _strip(16, 4)
    tol = 1e-9
    mid = Muscle([int(i) for i in np.argsort(P[:, 0]) if abs(P[i, 1] - 0.5) < tol and 1.0 - tol <= P[i, 0] <= 3.5 + tol])
    feet = {"rear": np.flatnonzero(P[:, 0] < 1.0 + tol), "front": np.flatnonzero(P[:, 0] > 3.5 - tol)}
    r = walk(mesh, MAT, [mid], np.array([[0.0], [STROKE]]), mu=0.5, cycles=1, feet_groups=feet,
             touching=np.ones((2, 2), bool))
    assert r.success
    k = 2  # the frame in which the rope pulls
    move = {n: np.hypot(*(r.states[k][v] - r.states[k - 1][v]).mean(0)) for n, v in feet.items()}
    # the heavy foot deforms where the rope pulls it (partial slip) but does not slide: its mean moves little
    assert move["rear"] < 0.03 * STROKE and move["front"] > 0.5 * STROKE
    assert r.feet_slipping["front"][k] and not r.feet_slipping["rear"][k]


def test_inchworm_walks_forward_and_back():
    mesh, mus, feet = _inchworm(16, 4)
    fwd = walk(mesh, MAT, mus, INCH_S, mu=0.5, cycles=3, feet_groups=feet, touching=INCH_T)
    assert fwd.success
    d = fwd.displacement
    assert np.all(d[:, 0] > 0.3 * STROKE) and np.all(d[:, 0] < STROKE)  # forward, less than the stroke
    assert np.abs(d[:, 0] - d[0, 0]).max() < 1e-3 * d[0, 0]  # the same step every cycle
    assert np.abs(d[:, 1]).max() < 1e-6 and np.abs(fwd.rotation).max() < 1e-6  # the strip is symmetric
    # the planted foot never slides as a whole
    assert not any(v.any() for v in fwd.feet_slipping.values())
    import json
    summary = json.loads(json.dumps(fwd.summary()))
    assert summary["distance"] == pytest.approx(fwd.distance.tolist()) and summary["failed_frames"] == []
    assert set(summary["feet_slipping"]) == {"rear", "front"}
    # the other foot down first: the same gait backwards
    back = walk(mesh, MAT, mus, INCH_S, mu=0.5, cycles=1, feet_groups=feet, touching=~INCH_T)
    assert back.displacement[0, 0] == pytest.approx(-d[0, 0], rel=0.05)
    # while friction is weak against the body's stiffness (mu W << E t size) it only decides who holds: the
    # distance hardly depends on mu or the weight (here mu W is 16 times larger: 0.2 % longer)
    other = walk(mesh, MAT, mus, INCH_S, mu=0.8, cycles=1, weight=0.01 * Units(mesh, MAT).force,
                 feet_groups=feet, touching=INCH_T)
    assert other.displacement[0, 0] == pytest.approx(d[0, 0], rel=0.01)


def test_inchworm_step_converges_under_refinement():
    steps = []
    for nx, ny in ((16, 4), (32, 8), (64, 16)):
        mesh, mus, feet = _inchworm(nx, ny)
        r = walk(mesh, MAT, mus, INCH_S, mu=0.5, cycles=1, feet_groups=feet, touching=INCH_T)
        assert r.success
        steps.append(float(r.displacement[0, 0]))
    d1, d2 = abs(steps[1] - steps[0]), abs(steps[2] - steps[1])
    assert d2 < 0.5 * d1
    assert d2 < 0.05 * steps[2]


@pytest.mark.parametrize("kw, msg", [
    ({"strokes": np.zeros((3, 2))}, "strokes must be an"),
    ({"mu": -0.1}, "mu must be a number"),
    ({"touching": np.ones((2, 2), bool)}, "touching must be an"),
    ({"touching": np.array([[True, False], [False, False], [True, False]])}, "with no foot"),
    ({"feet": [10 ** 6]}, "feet must be node indices"),
    ({"cycles": 0}, "cycles"),
])
def test_bad_input_is_refused_at_the_door(kw, msg):
    mesh, mus, feet = _inchworm(8, 2)
    args = dict(strokes=INCH_S, mu=0.5, cycles=1, feet_groups=feet)
    args.update(kw)
    S = args.pop("strokes")
    with pytest.raises(ValueError, match=msg):
        walk(mesh, MAT, mus, S, **args)


def test_touching_takes_a_gaits_schedule_rows_with_its_closing_frame():
    """walk_gait (and walk_scene_refinement, through schedule_cycle) drop a cyclic schedule's closing frame (it
    repeats the first): ``touching`` may have a row per frame of the cycle, or a row per frame of the schedule
    whose last repeats its first (before: refused, "must be an (2, 2) bool array", though the schedule has 3
    rows). Both walk the same; a closing row that differs from the first is refused, saying why; a wrong count
    says what the rows are."""
    from mdsr_opt import solve_internal
    from mdsr_opt.synthesis.gait import gait_schedule
    from mdsr_opt.synthesis.poses import design_poses
    from mdsr_opt.synthesis.walk import schedule_cycle, walk_gait

    mesh, mus, feet = _inchworm(8, 2)
    x = solve_internal(mesh, MAT, mus, [STROKE / mus[0].rest_length(mesh)]).x
    lay = design_poses(mesh, MAT, {"pull": x}, separate={"pull": (mus, None)}, compare=False)
    sch = gait_schedule(mesh, MAT, lay, ["rest", "pull"], frames_per_step=1)
    assert len(sch.strokes) == 3 and np.allclose(sch.strokes[0], sch.strokes[-1])
    cycle = INCH_T[:2]
    args = dict(mu=0.5, cycles=2, feet_groups=feet)
    a = walk_gait(mesh, MAT, sch, lay.muscles, touching=cycle, **args)
    b = walk_gait(mesh, MAT, sch, lay.muscles, touching=np.vstack([cycle, cycle[:1]]), **args)
    assert a.cycle_frames == 2 and a.success
    assert np.array_equal(a.states, b.states) and np.array_equal(a.loads, b.loads)
    assert a.distance.min() > 0.01 * mesh.size  # it walks: the rows did lift feet in turn
    S, T = schedule_cycle(sch, np.vstack([cycle, cycle[:1]]))  # as walk_scene_refinement takes them too
    assert np.array_equal(S, sch.strokes[:2]) and np.array_equal(T, cycle)
    assert schedule_cycle(sch, cycle)[1] is cycle and schedule_cycle(sch)[1] is None
    with pytest.raises(ValueError, match=r"touching has 3 rows.*its last row must repeat its first.*2 rows of one "
                                         r"cycle.*cycle_frames"):
        walk_gait(mesh, MAT, sch, lay.muscles, touching=np.vstack([cycle, cycle[1:]]), **args)
    with pytest.raises(ValueError, match=r"touching must be an \(2, 2\) bool array: a row per frame of the cycle "
                                         r"\(the 2 rows of strokes, WalkResult.cycle_frames; a gait schedule's closing"):
        walk_gait(mesh, MAT, sch, lay.muscles, touching=np.ones((4, 2), bool), **args)


def test_walk_chart_draws_the_displacement_per_cycle(tmp_path):
    import matplotlib
    matplotlib.use("Agg")
    from mdsr_opt.plot.common import save_figure
    from mdsr_opt.plot.walk import plot_walk

    mesh, mus, feet = _inchworm(8, 2)
    r = walk(mesh, MAT, mus, INCH_S, mu=0.5, cycles=2, feet_groups=feet, touching=INCH_T, units="mm")
    fig = plot_walk(r)
    ax = fig.axes[0]
    dist = [ln for ln in ax.lines if ln.get_label() == "centroid distance"][0]
    assert np.allclose(dist.get_xdata(), [0, 1, 2])
    assert np.allclose(dist.get_ydata(), np.concatenate([[0.0], np.cumsum(r.distance)]), rtol=1e-9, atol=1e-12)
    assert "displacement (mm)" == ax.get_ylabel()
    path = save_figure(fig, tmp_path / "walk.png", close=True)
    assert (tmp_path / "walk.png").stat().st_size > 1000 and path.endswith("walk.png")


def test_foot_groups_are_the_connected_pieces():
    from mdsr_opt.synthesis.walk import foot_groups

    mesh, P = _strip(16, 4)
    left, right = np.flatnonzero(P[:, 0] < 0.3), np.flatnonzero(P[:, 0] > 3.7)
    g = foot_groups(mesh, np.concatenate([right, left]))
    assert list(g) == ["foot 1", "foot 2"]
    assert set(g["foot 1"]) == set(left) and set(g["foot 2"]) == set(right)
    with pytest.raises(ValueError, match="feet must be node indices"):
        foot_groups(mesh, [])


def test_library_gecko_reciprocal_gait_goes_nowhere_on_all_nodes():
    """The gecko's gait (bend left, straight, bend right, straight) with its weight on every node in every frame:
    each bend is undone on the way back, so the body stays where it is (to 1e-3 of its size per cycle)."""

    from mdsr_opt.scenes.runner import run_case
    from mdsr_opt.synthesis.poses import design_poses
    from mdsr_opt.synthesis.walk import walk_scene

    gecko = load_script("problems/gecko.py")
    sc = gecko.build("coarse")
    targets = {c: run_case(sc, c, photo=False).setup.target for c in sc.gait.poses}
    lay = design_poses(sc.mesh, sc.material, targets, max_muscles=sc.gait.max_muscles,
                       routing_options=sc.routing_options, design_options=sc.design_options, compare=False)
    sch, flat = walk_scene(sc, lay, feet="all", mu=0.5, cycles=2)
    assert flat.success and flat.units == sc.units
    assert flat.distance[-1] < 1e-3 * sc.mesh.size
    # the body did bend: the feet moved by a good part of the size within the cycle
    assert np.abs(flat.states - flat.states[1]).max() > 0.05 * sc.mesh.size


def _gecko_on_diagonal_feet():
    """The coarse gecko, its gait's shared layout, and the touching pattern of diagonal feet (front left and
    hind right down for the first half of the cycle, the other pair for the second)."""
    from mdsr_opt.scenes.runner import run_case
    from mdsr_opt.synthesis.poses import design_poses

    gecko = load_script("problems/gecko.py")
    sc = gecko.build("coarse")
    targets = {c: run_case(sc, c, photo=False).setup.target for c in sc.gait.poses}
    lay = design_poses(sc.mesh, sc.material, targets, max_muscles=sc.gait.max_muscles,
                       routing_options=sc.routing_options, design_options=sc.design_options, compare=False)
    F = len(sc.gait.sequence) * sc.gait.frames_per_step
    T = np.zeros((F, 4), dtype=bool)
    T[: F // 2, [0, 3]] = True
    T[F // 2:, [1, 2]] = True
    return sc, lay, T


@pytest.mark.slow
def test_library_gecko_walks_on_diagonal_feet_every_frame_solved():
    """The gecko's gait with its weight on two diagonal feet at a time (front left and hind right down for the
    first half of the cycle, the other pair for the second): every frame solves (the coarse mesh failed 6-16
    of its frames before the epigraph form), and the body walks the same distance in each cycle (to 2 %; it
    turns by about 2 degrees a cycle, so the step's direction turns with it)."""
    from mdsr_opt.synthesis.walk import walk_scene

    sc, lay, T = _gecko_on_diagonal_feet()
    _, w = walk_scene(sc, lay, feet="region", mu=0.5, cycles=3, touching=T)
    assert w.success, [w.status[k] for k in np.flatnonzero(~w.frame_success)]
    dist = w.distance[1:]  # the first cycle starts from the pose solved off the table
    assert dist.min() > 0.05 * sc.mesh.size
    assert dist.max() - dist.min() <= 0.02 * dist.max()


@pytest.mark.slow
def test_library_gecko_walks_on_a_mesh_that_resolves_its_rope_ends():
    """The gecko's layout on its coarse mesh (146 nodes) refined twice near the ropes' ends (each end patch of
    radius 0.19 cm then holds 10-18 nodes, one node on the coarse mesh): the gait on diagonal feet solves every
    frame, the nodes in stick stay put (a planted foot may slide as a whole where friction runs out: foot 4, in
    one frame), and it walks about 1.15 cm in its first cycle where the
    coarse mesh's point-like ends walk 0.93 (the refinement study: tests/benchmarks/bench_walk.py); with mu = 0
    the same cycle goes nowhere (a body on ice, to 1e-5 of its size). (The layout is routed as the pipeline
    routes since design_poses does: 477 nodes and 1.159 cm, where the plain routing gave 411 and 1.141.)"""
    from mdsr_opt.synthesis.walkstudy import walk_scene_refinement

    sc, lay, T = _gecko_on_diagonal_feet()
    out = {}
    for mu in (0.5, 0.0):
        _, [(mesh, r)] = walk_scene_refinement(sc, lay, levels=1, local=(0.4, 0.2), mu=mu, cycles=1, touching=T)
        assert r.success, [r.status[k] for k in np.flatnonzero(~r.frame_success)]
        out[mu] = r
    assert mesh.n_nodes > 2.5 * sc.mesh.n_nodes  # refined near every rope end
    walked = out[0.5]
    assert walked.distance[0] == pytest.approx(1.15, abs=0.03)
    # nodes that touch the table in two frames and do not slip between them stay where they are (stick)
    X, load, slip = walked.states, walked.loads, walked.slipping
    stick = (load[1:] > 0) & (load[:-1] > 0) & ~slip[1:]
    assert stick.any()
    moved = max(np.abs(X[k + 1][stick[k]] - X[k][stick[k]]).max(initial=0.0) for k in range(len(stick)))
    assert moved < 1e-8 * sc.mesh.size
    assert out[0.0].distance[0] < 1e-5 * sc.mesh.size
    assert np.abs(out[0.0].states - out[0.0].states[1]).max() > 0.05 * sc.mesh.size  # it did bend


def test_refine_walker_keeps_ropes_feet_and_state():
    """One split level: the ropes run through the same rest polyline (same rest length, every new node on it),
    every segment a mesh edge; a foot keeps its nodes and gains only midpoints of its own edges; a state that is
    an affine map of the rest shape is carried over exactly; a rope off the mesh's edges is refused."""
    from mdsr_opt.synthesis.walkstudy import refine_walker

    mesh, mus = _bender(8, 2)
    P = mesh.points
    foot = np.flatnonzero(P[:, 0] < 1.0 + 1e-9)
    A = np.array([[1.1, 0.2], [-0.3, 0.9]])
    fine, fm, sets, x = refine_walker(mesh, mus, {"rear": foot}, P @ A.T + [0.5, -1.0])
    assert fine.n_nodes == mesh.n_nodes + len(mesh.edges) and len(fine.triangles) == 4 * len(mesh.triangles)
    for m, f in zip(mus, fm):
        f.check_on(fine)
        assert f.rest_length(fine) == pytest.approx(m.rest_length(mesh), rel=1e-12)
        assert f.nodes[0::2] == m.nodes and f.name == m.name
        y = fine.points[list(f.nodes)]  # the top rope stays on y = 1, the bottom one on y = 0
        assert np.allclose(y[:, 1], P[m.nodes[0], 1])
    rear = sets["rear"]
    assert set(foot) <= set(rear.tolist()) and np.all(fine.points[rear, 0] <= 1.0 + 1e-9)
    assert len(rear) == np.sum(fine.points[:, 0] <= 1.0 + 1e-9)  # the same piece of the body, all of it
    assert np.allclose(x, fine.points @ A.T + [0.5, -1.0], atol=1e-12)
    with pytest.raises(ValueError, match="not a mesh edge"):
        refine_walker(mesh, [Muscle([0, int(np.argmax(P[:, 0]))])])


def test_inchworm_walk_refinement_with_one_layout_converges():
    """The inchworm's rope, feet and strokes carried unchanged to two nested refinements (85, 297, 1105 nodes):
    every frame solves, the step's change falls by more than half from one refinement to the next and the
    last change is within 5 % of the step."""
    from mdsr_opt.synthesis.walkstudy import walk_refinement

    mesh, mus, feet = _inchworm(16, 4)
    runs = walk_refinement(mesh, MAT, mus, INCH_S, levels=3, mu=0.5, cycles=1, feet_groups=feet, touching=INCH_T)
    assert [m.n_nodes for m, _ in runs] == [85, 297, 1105]
    assert all(r.success for _, r in runs)
    steps = np.array([r.displacement[0, 0] for _, r in runs])
    d = np.abs(np.diff(steps))
    assert np.all(steps > 0.3 * STROKE) and d[1] < 0.5 * d[0] and d[1] < 0.05 * steps[-1]
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mdsr_opt.plot.walk import plot_walk_refinement

    from mdsr_opt.synthesis.walkstudy import richardson

    est = richardson([r.distance[-1] for _, r in runs])
    fig = plot_walk_refinement([(m.n_nodes, r) for m, r in runs], estimate=est)  # distance against nodes
    line = [ln for ln in fig.axes[0].lines if ln.get_label() == "last cycle"][0]
    assert np.allclose(line.get_xdata(), [85, 297, 1105])
    assert np.allclose(line.get_ydata(), [r.distance[-1] for _, r in runs], rtol=1e-12)
    limit = [ln for ln in fig.axes[0].lines if ln.get_label().startswith("limit")][0]
    assert np.allclose(limit.get_ydata(), est["extrapolated"]) and "Richardson" in limit.get_label()
    plt.close(fig)


def test_refine_walker_near_points_splits_only_there_and_stays_conforming():
    """Local refinement near a rope's end: the triangles with a corner within the distance split into four and
    no far triangle changes; the mesh stays conforming (the same area and boundary, no hanging node: every
    interior edge has two triangles), its smallest angle at least a quarter of the base's; the rope keeps its rest
    polyline and length on mesh edges; a foot gains only midpoints of its own split edges; an affine state is
    carried exactly; the end's patch, one node before, holds several after two rounds."""
    from mdsr_opt.mechanics.anchors import anchor_patches
    from mdsr_opt.synthesis.walkstudy import refine_walker

    mesh, mus, feet = _inchworm(16, 4)
    P = mesh.points
    end = P[mus[0].nodes[0]]
    A = np.array([[1.1, 0.2], [-0.3, 0.9]])
    radius = 0.15
    assert [len(p) for p in anchor_patches(mesh, mus, radius)[0]] == [1, 1]
    m, ms, sets, x = mesh, mus, feet, P @ A.T
    for d in (0.4, 0.2):
        m, ms, sets, x = refine_walker(m, ms, sets, x, near=end[None], distance=d)
    assert mesh.n_nodes < m.n_nodes < 297  # one uniform split gives 297
    assert m.area == pytest.approx(mesh.area, rel=1e-12) and np.all(m.areas > 0)
    bl = lambda q: np.linalg.norm(np.diff(q.points[q.boundary_edges], axis=1), axis=2).sum()
    assert bl(m) == pytest.approx(bl(mesh), rel=1e-12) and len(m.boundary_loops) == 1
    assert m.quality()["min_angle_deg"] >= 0.25 * mesh.quality()["min_angle_deg"]  # a halved one halved again at most
    far = np.hypot(*(P[mesh.triangles].mean(1) - end).T) > 1.5  # triangles far away: unchanged
    kept = {tuple(sorted(t)) for t in m.triangles.tolist()}
    assert all(tuple(sorted(t)) in kept for t in mesh.triangles[far].tolist())
    near = np.hypot(*(m.points[m.triangles].mean(1) - end).T) < 0.2
    assert m.areas[near].max() <= 1.01 * mesh.areas.max() / 16  # twice split into four there
    f = ms[0]
    f.check_on(m)
    assert f.rest_length(m) == pytest.approx(mus[0].rest_length(mesh), rel=1e-12)
    assert np.allclose(m.points[list(f.nodes), 1], 0.5) and len(f.nodes) > len(mus[0].nodes)
    for k, v in feet.items():  # the same piece of the body: its nodes and midpoints between them
        assert set(v) <= set(sets[k].tolist())
        lo, hi = P[v, 0].min(), P[v, 0].max()
        assert np.all((m.points[sets[k], 0] >= lo - 1e-12) & (m.points[sets[k], 0] <= hi + 1e-12))
    assert np.allclose(x, m.points @ A.T, atol=1e-12)
    start, _ = anchor_patches(m, ms, radius)[0]
    assert len(start) >= 5
    with pytest.raises(ValueError, match="distance a length > 0"):
        refine_walker(mesh, mus, near=end[None], distance=0.0)


def test_richardson_estimates_the_limit_of_a_refinement_study():
    from mdsr_opt.synthesis.walkstudy import richardson

    e = richardson([1.4, 1.1, 1.025])  # 1 + 0.4 h^2 for h = 1, 1/2, 1/4: second order, limit 1
    assert e["ratios"] == pytest.approx([0.25]) and e["order"] == pytest.approx(2.0)
    assert e["extrapolated"] == pytest.approx(1.0) and e["error"] == pytest.approx(0.025)
    a = richardson([0.26, 0.273, 0.2728])  # changes of alternating sign, shrinking: the last value +- last change
    assert a["order"] is None and a["extrapolated"] == 0.2728 and a["error"] == pytest.approx(0.0002)
    g = richardson([0.932, 0.941, 1.124])  # growing changes: no estimate
    assert g["ratios"][0] > 1 and g["extrapolated"] is None and g["error"] is None
    with pytest.raises(TypeError, match="real number"):
        richardson(["1.0", 2.0])
    with pytest.raises(ValueError, match="two finite numbers"):
        richardson([1.0])


@pytest.mark.parametrize("local, err, msg", [([0.0], ValueError, "local must be distances > 0"),
                                             ([np.inf], ValueError, "local contains NaN or inf"),
                                             (["0.4"], TypeError, "real number")])
def test_walk_refinement_refuses_bad_local_distances_at_the_door(local, err, msg):
    from mdsr_opt.synthesis.walkstudy import walk_refinement

    mesh, mus, feet = _inchworm(8, 2)
    with pytest.raises(err, match=msg):
        walk_refinement(mesh, MAT, mus, INCH_S, levels=1, local=local, feet_groups=feet, touching=INCH_T)


def test_walking_a_schedule_with_a_pose_never_reached_is_no_success():
    """recheck10: the walk of a gait whose pose the layout never reached said "11/11 frames solved" and its
    per-frame success was all True; success is now one bool (frames solved and every pose reached)."""
    from mdsr_opt.synthesis.gait import gait_schedule
    from mdsr_opt.synthesis.poses import design_poses
    from mdsr_opt.synthesis.walk import walk_gait

    mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    X = mesh.points
    R, s = 3.0, 1.0

    def bend(sign):
        phi = (X[:, 0] - 2.0) / R
        r = R - sign * s * (X[:, 1] - 0.5)
        return np.column_stack([r * np.sin(phi), sign * s * (R - r * np.cos(phi))])

    lay = design_poses(mesh, MAT, {"up": bend(1), "down": bend(-1)}, max_muscles=1, compare=False)
    sch = gait_schedule(mesh, MAT, lay, ["up", "down"], frames_per_step=2)
    assert sch.unreached == ("down",)
    w = walk_gait(mesh, MAT, sch, lay.muscles, mu=0.5, cycles=1)
    assert w.frame_success.all() and w.success is False and w.unreached == ("down",)
    assert "NOT reached" in repr(w) and w.summary()["success"] is False and w.summary()["unreached"] == ["down"]
