"""The face makes faces with ONE muscle layout: every expression's design recovers at least 70 % of its target
motion on every node it moves noticeably (more than 10 % of its largest motion; holes' rims included).

The measure is problems.face.motion_recovered: 1 - ||driven - target|| / ||target - rest|| over those nodes
(problems.face.moving_nodes), the driven state rigidly aligned onto the target (the design's x_aligned).
"""

from __future__ import annotations

import numpy as np
import pytest

from mdsr_opt.synthesis.routing_symmetry import find_reflection
from mdsr_opt.scenes.library import get_problem, load_problem_module, problems_dir
from mdsr_opt.scenes.runner import run_case

face_module = load_problem_module(problems_dir() / "face.py")


@pytest.fixture(scope="module")
def scene():
    return get_problem("face", resolution="coarse")


@pytest.mark.parametrize("name", ["smile", "frown", "wink", "pucker"])
def test_each_expression_recovers_70_percent_on_its_moving_nodes_with_one_layout(scene, name):
    run = run_case(scene, name, photo=False)
    assert run.report.success, run.report.message
    moving = face_module.moving_nodes(scene.mesh, run.setup.target)
    rims = scene.mesh.boundary_loops[1:]
    assert len(moving) > len(run.setup.case.drag_nodes)  # far more than the dragged nodes
    assert any(np.isin(loop, moving).all() for loop in rims)  # a hole's whole rim is measured
    rec = face_module.motion_recovered(scene.mesh.points, run.setup.target, run.design.x_aligned, moving)
    assert rec >= 0.70, f"{name}: {rec:.3f}"
    # the case's muscles are muscles of the one layout, as its report names them
    layout = {m.name: tuple(m.nodes) for c in scene.cases for m in c.muscles}
    assert {m["name"]: tuple(m["nodes"]) for m in run.report.muscles}.items() <= layout.items()


def test_all_expressions_share_one_routed_layout(scene):
    chains = {}
    for c in scene.cases:
        assert c.muscles, c.name
        for m in c.muscles:  # one name, one node chain, whichever expression uses it
            assert chains.setdefault(m.name, tuple(m.nodes)) == tuple(m.nodes)
    assert len(chains) >= 4  # one layout, used in part by each expression
    assert max(face_module.turns(scene.mesh, v).max() for v in chains.values()) <= 45.0 + 1e-6


def test_the_face_mesh_is_mirror_symmetric(scene):
    r = find_reflection(scene.mesh)
    assert r is not None
    P = scene.mesh.points
    assert np.allclose(P[r.node_map] * (-1.0, 1.0), P, atol=1e-9)


def test_motion_recovered_measure():
    X = np.zeros((3, 2))
    T = X + (1.0, 0.0)
    assert face_module.motion_recovered(X, T, T, [0, 1]) == pytest.approx(1.0)
    assert face_module.motion_recovered(X, T, X, [0, 1]) == pytest.approx(0.0)
    assert face_module.motion_recovered(X, T, X + (0.25, 0.0), [0, 1, 2]) == pytest.approx(0.25)
    with pytest.raises(ValueError, match="does not move"):
        face_module.motion_recovered(X, X, X, [0])
    with pytest.raises(ValueError, match="nodes is empty"):
        face_module.motion_recovered(X, T, T, [])
    with pytest.raises(ValueError, match=r"\(n, 2\)"):
        face_module.motion_recovered(X, T[:2], T, [0])


def test_the_expressions_figure_lays_one_layout_with_design_poses(tmp_path, scene, monkeypatch):
    """problems/face_expressions.py: design_poses lays the face's one layout (the scene's cases' muscles), and
    all four expressions reach 70 % of their motion on it; its JSON names every muscle's node chain."""
    from mdsr_opt.body.io import read_json

    import mdsr_opt.plot.common as common

    titles, rows, save = [], [], common.save_figure

    def recording(figure, path, **kw):  # the drawn figure's panel titles and row names, then the real save
        titles.extend(ax.get_title() for ax in figure.axes)
        rows.extend(ax.get_ylabel() for ax in figure.axes if ax.get_ylabel())
        titles.append(figure.get_suptitle())
        return save(figure, path, **kw)

    monkeypatch.setattr(common, "save_figure", recording)
    fig = load_problem_module(problems_dir() / "face_expressions.py")
    assert fig.run_figure(tmp_path, resolution="coarse", log=lambda s: None, vector="svg") == 0
    assert "<svg" in (tmp_path / "expressions.svg").read_text()  # the vector copy beside the PNG
    driven = [t.replace(":\n", ": ") for t in titles if ": D = " in t.replace(":\n", ": ")]  # long: two lines
    from mdsr_opt.plot.style import unit_label

    u = unit_label(scene.units)  # the face gives no unit: "body units"
    assert len(driven) == 4 and all(t.split(": D = ")[1].split(" ", 1)[1] == u for t in driven), driven
    assert rows == ["target", "driven by its strokes"]  # no "layout C" of Figure 6 in the face's figure
    n = len(read_json(tmp_path / "layout.json")["muscles"])
    assert f"one layout of {n} muscles (M1..M{n})" in titles[-1], titles[-1]
    data = read_json(tmp_path / "expressions.json")
    chains = {m["name"]: tuple(m["nodes"]) for m in data["layout"]}
    assert chains == {m.name: tuple(m.nodes) for c in scene.cases for m in c.muscles}
    assert [e["expression"] for e in data["expressions"]] == ["smile", "frown", "wink", "pucker"]
    for e, case in zip(data["expressions"], scene.cases):
        assert e["success"] and e["motion_recovered"] >= 0.70, e
        assert e["muscles"] == [m.name for m in case.muscles]  # the case pulls the muscles its pose pulls
    assert (tmp_path / "expressions.png").stat().st_size > 20000


def test_the_one_layout_runs_inside_the_body(scene):
    """Issue 32: every rope node at least max(channel/2 + wall, 2 % of the diameter) inside the outline and the
    holes (shapely, on the mesh's own boundary), with the default fabrication; fixtures of the design's size."""
    from shapely.geometry import Point, Polygon

    from mdsr_opt.mechanics.anchors import body_size
    from mdsr_opt.synthesis.fabrication import MIN_INSET_FRACTION, Fabrication

    P, loops = scene.mesh.points, scene.mesh.boundary_loops
    poly = Polygon(P[loops[0]], [P[lp] for lp in loops[1:]])
    fab = Fabrication().for_body(scene.mesh)
    need = max(0.5 * fab.channel_diameter + fab.wall, MIN_INSET_FRACTION * body_size(scene.mesh))
    nodes = {i for c in scene.cases for m in c.muscles for i in m.nodes}
    inset = min(poly.boundary.distance(Point(P[i])) for i in nodes)
    assert all(poly.contains(Point(P[i])) for i in nodes) and inset >= need - 1e-9, (inset, need)
    # the wink's rope rings the left eye: it passes above and below the eye's centre
    wink = next(c for c in scene.cases if c.name == "wink")
    lx, ly = -face_module.EYE_C[0], face_module.EYE_C[1]
    near = [P[list(m.nodes)] for m in wink.muscles
            if np.linalg.norm((P[list(m.nodes)] - (lx, ly)) / (1.0, 0.6), axis=1).max() < 1.5]
    assert any((q[:, 1] > ly).any() and (q[:, 1] < ly).any() and (np.abs(q[:, 0] - lx) < 0.3).any() for q in near)


def test_the_wink_rings_the_eye_not_the_islands_inside_the_inset():
    """On 766 nodes the mesh's first ring of nodes round the eye clears the ropes' inset only above and below
    the eye's centre: two islands of a few strongly contracted edges, which were seeded first (strongest edge)
    and kept the ring just outside them from being seeded (3-node units, wink 0.61). Regions are seeded by the
    contraction they hold: the ring's arcs above and below the eye are routed (wink 0.68)."""
    import warnings

    from mdsr_opt.mechanics.equilibrium import solve_external
    from mdsr_opt.synthesis.fabrication import check_fabrication
    from mdsr_opt.synthesis.routing import route_muscles

    mesh = face_module.symmetric_mesh(800)
    assert mesh.n_nodes == 766
    P = mesh.points
    lx, ly = -face_module.EYE_C[0], face_module.EYE_C[1]
    b = mesh.boundary_nodes
    rim = b[np.linalg.norm(P[b] - (lx, ly), axis=1) < face_module.EYE_AX[0] + 0.05]  # as the scene's left_eye
    squeezed = np.column_stack([lx + 0.6 * (P[rim, 0] - lx), ly + 0.4 * (P[rim, 1] - ly)])
    res = solve_external(mesh, face_module.NeoHookean(E=1.0, nu=0.4), np.zeros(0, dtype=np.int64),
                         (rim, squeezed))
    assert res.success
    opts = {"K_a": 10.0, "K_b": 4.0, "max_muscles": 4, **face_module.EXPRESSION_ROUTING,
            "fabrication": check_fabrication(None, face_module.ANCHOR_RADIUS)}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rr = route_muscles(mesh, res.x, **opts)
    for side in (1.0, -1.0):  # an arc of at least 6 nodes wholly above (below) the eye, within its width
        arcs = [len(m.nodes) for m in rr if (side * (P[list(m.nodes), 1] - ly) > face_module.EYE_AX[1]).all()
                and (np.abs(P[list(m.nodes), 0] - lx) < face_module.EYE_AX[0] + 0.4).all()]
        assert max(arcs, default=0) >= 6, (side, [len(m.nodes) for m in rr])


def _wink_routing(n):
    """The wink's own target and routing (the face's routing options) on the face meshed at about ``n`` nodes."""
    import warnings

    from mdsr_opt.mechanics.equilibrium import solve_external
    from mdsr_opt.synthesis.fabrication import check_fabrication
    from mdsr_opt.synthesis.routing import route_muscles

    mesh = face_module.symmetric_mesh(n)
    P, b = mesh.points, mesh.boundary_nodes
    lx, ly = -face_module.EYE_C[0], face_module.EYE_C[1]
    rim = b[np.linalg.norm(P[b] - (lx, ly), axis=1) < face_module.EYE_AX[0] + 0.05]
    squeezed = np.column_stack([lx + 0.6 * (P[rim, 0] - lx), ly + 0.4 * (P[rim, 1] - ly)])
    res = solve_external(mesh, face_module.NeoHookean(E=1.0, nu=0.4), np.zeros(0, dtype=np.int64), (rim, squeezed))
    assert res.success
    opts = {"K_a": 10.0, "K_b": 4.0, "max_muscles": 4, **face_module.EXPRESSION_ROUTING,
            "fabrication": check_fabrication(None, face_module.ANCHOR_RADIUS)}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return mesh, res.x, route_muscles(mesh, res.x, **opts)


@pytest.mark.parametrize("n", [600, 1100, 2400])
def test_the_wink_is_made_by_one_rope_ringing_the_eye_on_meshes_of_every_size(n):
    """On 553, 1049 and 2310 nodes one rope rings the left eye (it winds more than 320 degrees round the eye's
    centre; growth laid arcs of at most 0.8 pi on 1049 nodes), every turn within 45 degrees, and it shortens."""
    mesh, x, rr = _wink_routing(n)
    P = mesh.points
    c = np.array([-face_module.EYE_C[0], face_module.EYE_C[1]])

    def winding(m):
        a = np.unwrap(np.arctan2(*(P[list(m.nodes)] - c).T[::-1]))
        return abs(a[-1] - a[0])

    ring = max(rr, key=winding)
    assert 1.78 * np.pi < winding(ring) < 2 * np.pi, [winding(m) / np.pi for m in rr]
    assert face_module.turns(mesh, ring.nodes).max() <= 45.0 + 1e-6
    assert ring.length(x) < ring.rest_length(mesh)


@pytest.mark.slow
@pytest.mark.parametrize("resolution", [1100, 1500, 2800])
def test_one_layout_makes_all_four_expressions_on_other_meshes(resolution):
    """The face's one layout on 1049, 1423 and 2697 nodes (the scene's own mesh, 845, is tested above): every
    expression recovers at least 70 % of its motion on its moving nodes. (Not on 2310 nodes, the ``fine``
    mesh: the pucker's lip arcs cross its corner ropes there, and cut back to be mouldable they give 60 %;
    problems/face.py lists the meshes where an expression falls short.)"""
    fig = load_problem_module(problems_dir() / "face_expressions.py")
    scene, face, targets, res = fig.design_expressions(resolution)
    rows = fig.expression_rows(scene, face, targets, res)
    assert [r["expression"] for r in rows] == ["smile", "frown", "wink", "pucker"]
    for r in rows:
        assert r["success"] and r["motion_recovered"] >= 0.70, (scene.mesh.n_nodes, r)
