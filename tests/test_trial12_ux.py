"""New-user trial 12's UX defects: a design the acceptance rule rejects exports as a failed one (marked FAILED,
refused unless asked for), a failed result's repr says why, the routing error of design_pipeline is the one
``mdsr run`` shows, and clearer messages at the door (a Muscle of a Muscle, node ids for waypoints, a
finer-mesh hint only when finer, a frictionless grip, a single anchor node)."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest

from mdsr_opt import NeoHookean, design_pipeline, export_fabrication, mesh_polygon, nodes_in_box
from mdsr_opt.synthesis.pipeline import PipelineResult

MAT = NeoHookean(E=1.0, nu=0.3)


@pytest.fixture(scope="module")
def far():
    """trial12 t18: a 40 x 10 strip whose clamped tip is moved up by 10 (an S-bend its muscles cannot make):
    a verified design that removes a few % of the rest shape's difference, which mdsr run fails."""
    mesh = mesh_polygon([[0, 0], [40, 0], [40, 10], [0, 10]], resolution="coarse")
    X = mesh.points
    base, tip = nodes_in_box(mesh, xmax=0), nodes_in_box(mesh, xmin=40)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        p = design_pipeline(mesh, MAT, base, {int(i): X[i] + [0, 10] for i in tip})
    assert p.success and "the muscles barely move the body" in p.far_from_target
    return mesh, p


def _texts(files) -> dict:
    return {k: open(f, encoding="utf-8").read() for k, f in files.items()}


def test_a_design_the_acceptance_rule_rejects_is_refused_then_marked_with_its_reason(far, tmp_path):
    mesh, p = far
    with pytest.raises(ValueError, match=r"export_fabrication \(robot\): too far from the target \(the design "
                                         r"removes \d+ % of the rest shape's difference.*allow_failed=True"):
        export_fabrication(mesh, p, tmp_path / "no")
    assert not (tmp_path / "no").exists()  # refused before anything is written
    with pytest.warns(UserWarning, match="FAILED DESIGN: too far from the target"):
        files = export_fabrication(mesh, p, tmp_path / "yes", allow_failed=True)
    text = _texts(files)
    mark = "FAILED DESIGN: too far from the target (the design removes"
    assert mark in text["svg"] and mark in text["dxf"] and text["csv"].startswith("# " + mark)
    assert "the muscles barely move the body), do not build" in text["csv"].splitlines()[0]
    # saved and read back, the result keeps its verdict, and so does its export
    p.save(tmp_path / "saved")
    back = PipelineResult.load(tmp_path / "saved")
    with pytest.raises(ValueError, match="too far from the target"):
        export_fabrication(mesh, back, tmp_path / "no2")


def test_an_accepted_design_exports_unmarked(far, tmp_path):
    mesh, p = far
    ok = dataclasses.replace(p, far_from_target="")
    files = export_fabrication(mesh, ok, tmp_path / "ok")
    text = _texts(files)
    assert not any("FAILED" in t.upper() or "DO NOT BUILD" in t.upper() for t in text.values())


def test_a_failed_results_repr_says_why(far):
    _, p = far
    # a success far from the target says so
    text = repr(p)
    assert text.startswith("PipelineResult(success=True, far_from_target=\"the design removes ")
    assert len(text) <= 200 and "\n" not in text  # one line, as every result's repr
    ver = dataclasses.replace(p.design.verification, passed=False,
                              message="gap 10 between the design's state and the forward re-solve exceeds 0.00117")
    bad = dataclasses.replace(p.design, success=False, status="Maximum_Iterations_Exceeded", verification=ver)
    failed = dataclasses.replace(p, design=bad)
    want = "why=\"Maximum_Iterations_Exceeded; verification: gap 10 between the design's state and the"
    assert want in repr(failed) and want in repr(bad) and len(repr(failed)) <= 200
    assert failed.reason.startswith("Maximum_Iterations_Exceeded; verification: gap 10") and p.reason == p.far_from_target
    # a success's repr is as before: no why
    assert "why=" not in repr(p.design) and p.design.reason == ""


def test_a_failed_layouts_and_cases_repr_says_why():
    from mdsr_opt import Mesh
    from mdsr_opt.scenes.runner import CaseReport, CaseRun
    from mdsr_opt.synthesis.poses import design_poses

    mesh = Mesh.rectangle(4.0, 1.0, 8, 4)
    X = mesh.points
    phi, r = (X[:, 0] - 2.0) / 3.0, 3.0 - (X[:, 1] - 0.5)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = design_poses(mesh, MAT, {"left": np.column_stack([r * np.sin(phi), 3.0 - r * np.cos(phi)])},
                           compare=False)
    assert res.success and "why=" not in repr(res) and res.reason == ""
    bad = dataclasses.replace(res, pose_success=np.array([False]), status=("Restoration_Failed",))
    text = repr(bad)
    assert "success=False, why='pose left: Restoration_Failed')" in text and len(text) <= 200
    long = dataclasses.replace(bad, status=("Restoration_Failed " + "and more " * 40,), problems=("ropes cross",))
    assert len(repr(long)) <= 200 and "why='pose left: Restoration_Failed and more" in repr(long)
    assert long.reason.endswith("; ropes cross")
    rep = CaseReport(scene="s", case="c", kind="external", n_nodes=10, success=False,
                     message="routing found no muscle on the target (no edge contracts)")
    for text in (repr(rep), repr(CaseRun(report=rep))):
        assert "success=False, why='routing found no muscle on the target (no edge contracts)'" in text, text
    assert "why=" not in repr(dataclasses.replace(rep, success=True, message=""))


def test_the_python_writers_say_they_replace_files_of_the_same_name():
    """The CLI refuses to replace files without --overwrite; the Python writers replace them: documented."""
    from mdsr_opt.synthesis.poses_result import PosesResult
    from mdsr_opt.synthesis.results import DesignResult

    for f in (export_fabrication, PipelineResult.save, DesignResult.save, PosesResult.save):
        doc = " ".join(f.__doc__.split())
        assert "replaced" in doc and "without a warning" in doc and "--overwrite" in doc, f.__qualname__


def test_design_pipeline_raises_the_no_muscle_message_mdsr_run_fails_the_case_with(tmp_path):
    import json

    from mdsr_opt.scenes.runner import run_case
    from mdsr_opt.scenes.scenefile import load_scene

    # a strip pulled by its end without lateral contraction: every edge stretches, a cable cannot push
    d = {"name": "strip", "body": {"outline": [[0, 0], [4, 0], [4, 1], [0, 1]], "resolution": 100},
         "material": {"nu": 0.0}, "regions": {"base": {"box": [-1, -1, 0, 2]}, "end": {"box": [4, -1, 5, 2]}},
         "cases": [{"name": "stretch", "anchors": "base", "drags": [{"nodes": "end", "by": [0.5, 0]}]}]}
    (tmp_path / "strip.json").write_text(json.dumps(d))
    scene = load_scene(tmp_path / "strip.json")
    case = scene.case("stretch")
    run = run_case(scene, "stretch", photo=False)
    assert not run.report.success
    assert run.report.message.startswith("routing found no muscle on the target (no edge contracts")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(ValueError) as err:
            design_pipeline(scene.mesh, scene.material, case.anchors, case.drags)
    assert str(err.value) == run.report.message + "; pass muscles=... or relax routing_options"
    doc = " ".join(design_pipeline.__doc__.split())
    assert "routing found no muscle on the target (<the routing's reasons" in doc  # documented under Raises


def test_a_muscle_of_a_muscle_and_node_ids_for_points_are_named():
    from mdsr_opt import Mesh, Muscle, boundary_path, edge_path

    mesh = Mesh.rectangle(4.0, 1.0, nx=16, ny=4)
    m = edge_path(mesh, [[0.25, 0.5], [3.75, 0.5]])
    with pytest.raises(TypeError, match=r"Muscle\(\) takes a path of node indices, got a Muscle .*return a Muscle "
                                        r"already: use it as it is, or Muscle\(m.nodes, name=...\)"):
        Muscle(m)
    for bad, shown in ((5, "int 5"), (None, "NoneType None"), ("abc", "str 'abc'")):
        with pytest.raises(TypeError, match=rf"Muscle\(\) takes a path of node indices .*got {shown}"):
            Muscle(bad)
    assert Muscle(m.nodes, name="copy").nodes == m.nodes
    with pytest.raises(ValueError, match=r"waypoints are points \(x, y\) on the body, one row each, shape \(k, 2\); "
                                         r"got 3 \(and name=12\): node ids\? give their positions"):
        edge_path(mesh, 3, 12)
    with pytest.raises(ValueError, match=r"got \[3, 12\]: node ids\?"):
        edge_path(mesh, [3, 12])
    with pytest.raises(ValueError, match=r"got \[0.5, 0.5\]: give at least two points"):
        edge_path(mesh, [0.5, 0.5])
    with pytest.raises(ValueError, match=r"boundary_path: start is a point \(x, y\) near the boundary, got 3: a node "
                                         r"id\? give its position \(mesh.points\[3\]\)"):
        boundary_path(mesh, 3, 12)
    # every array checked at the door says what it was given beside its shape
    from mdsr_opt.core.checks import as_float_array

    with pytest.raises(ValueError, match=r"x must have shape \(k, 2\), got \(\) \(a single value, 3.0\)"):
        as_float_array(3, "x", shape=(None, 2))


def _t_on_disks(max_area):
    """trial12 t40/t19: a T whose arms are pressed down onto two fixed disks."""
    from mdsr_opt import Disk, Mesh, solve_external

    mesh = Mesh.from_polygon([[-0.5, 0], [0.5, 0], [0.5, 3], [2, 3], [2, 4], [-2, 4], [-2, 3], [-0.5, 3]],
                             max_area=max_area)
    X = mesh.points
    drags = {int(i): X[i] + [0, -0.9] for i in np.r_[nodes_in_box(mesh, xmin=1.99), nodes_in_box(mesh, xmax=-1.99)]}
    disks = [Disk([1.3, 2.3], 0.5), Disk([-1.3, 2.3], 0.5)]
    r = solve_external(mesh, MAT, nodes_in_box(mesh, ymax=0.0), drags, obstacles=disks)
    assert r.success
    return mesh, r, disks


def _t_routing_message(max_area):
    """The T on its disks: routing finds no seed (the compression filter)."""
    from mdsr_opt import route_muscles

    mesh, r, _ = _t_on_disks(max_area)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert len(route_muscles(mesh, r.x)) == 0
    (msg,) = [str(w.message) for w in caught if "no muscle unit could be seeded" in str(w.message)]
    return mesh, msg


def test_the_finer_mesh_hint_is_given_only_for_a_mesh_coarser_than_it_asks():
    mesh, msg = _t_routing_message(0.03)  # mean edge 0.2177, the band asks at most 0.265: already finer
    h = float(mesh.edge_lengths.mean())
    assert h == pytest.approx(0.2177, abs=1e-4)
    assert "a finer mesh (mean edge length at most" not in msg
    assert ("96 of those reach within an edge of the band, on a mesh already finer than the band asks (mean edge "
            "length 0.2177, at most 0.265): each has a node on the outline or a hole, where no rope lies at any mesh "
            "or inset") in msg
    assert "try compression_ratio=0.9 or lower" in msg  # the hint that works (0.5 routes 3 muscles)
    coarse, msg = _t_routing_message(0.06)  # mean edge 0.3112 > 0.265: a finer mesh is finer than now
    assert float(coarse.edge_lengths.mean()) > 0.265
    assert "a finer mesh (mean edge length at most 0.265, now 0.3112; the body is 0.6248 deep)" in msg


def test_a_frictionless_grip_reports_finite_figures_and_names_its_contacts():
    from mdsr_opt import grip_report

    mesh, r, disks = _t_on_disks(0.12)
    g0 = grip_report(r.x, r.contact, disks[0], 0.0)  # pushed from one side, no friction: not held
    assert not g0["held"] and g0["holding_force"] is None
    assert np.isfinite(g0["resisted"]).all() and min(g0["resisted"]) >= 0.0  # NaN before
    # at mu = 0 a load is held only where it cancels the push exactly: no positive load along any of 16 directions
    assert max(g0["resisted"]) <= 1e-3 * sum(g0["normal_forces"])
    k = len(g0["normal_forces"])
    assert k >= 1 and len(g0["contact_nodes"]) == len(g0["contact_segments"]) == k
    for node, seg in zip(g0["contact_nodes"], g0["contact_segments"]):  # a node, or a segment: never -1
        assert (node is None) != (seg is None)
        assert seg is None or (len(seg) == 2 and all(0 <= v < mesh.n_nodes for v in seg))
        assert node is None or 0 <= node < mesh.n_nodes
    # friction holds nothing more here (one side pushed), and the figures stay finite
    g5 = grip_report(r.x, r.contact, disks[0], 0.5)
    assert np.isfinite(g5["resisted"]).all() and (g5["holding_force"] is None) == (not g5["held"])
    # a disk nothing touches is not held (recheck12: held True, holding_force 0.0), whatever the friction
    untouched = dict(r.contact, pairs=[p for p in r.contact["pairs"] if p.get("obstacle") != 0])
    for mu in (0.0, 0.5):
        gu = grip_report(r.x, untouched, disks[0], mu)
        assert gu["held"] is False and gu["holding_force"] is None and gu["normal_forces"] == []
        assert gu["resisted"] == [0.0] * len(gu["directions"])


STAR5 = """name = "star5"
units = "mm"

[body]
outline = [[0.0, 50.0], [-11.756, 16.18], [-47.553, 15.451], [-19.021, -6.18], [-29.389, -40.451], [-0.0, -20.0],
           [29.389, -40.451], [19.021, -6.18], [47.553, 15.451], [11.756, 16.18]]
holes = [[[-5, -5], [5, -5], [5, 5], [-5, 5]]]
resolution = "coarse"

[material]
E = 0.5
nu = 0.45
stress_unit = "MPa"

[regions]
centre = { near = [0, 8], radius = 4 }
arm0 = { near = [0.0, 50.0], radius = 6 }

[fabrication]
channel_diameter = 1.0
wall = 1.0
fixture_radius = 2.5
min_fixture_radius = 1.5

[[cases]]
name = "curl_up"
anchors = "centre"
drags = [{ nodes = "arm0", rotate = 40, about = [0, 20] }]
"""


def test_a_single_anchor_node_is_named_as_the_reason_a_design_barely_moves_the_body(tmp_path):
    from mdsr_opt.scenes.runner import run_case
    from mdsr_opt.scenes.scenefile import load_scene
    from mdsr_opt.synthesis.acceptance import difference_failure

    (tmp_path / "star5.toml").write_text(STAR5)
    scene = load_scene(tmp_path / "star5.toml")
    case = scene.case("curl_up")
    assert len(case.anchors) == 1  # the region "centre", radius 4 mm, holds one node
    run = run_case(scene, "curl_up", photo=False)
    msg = run.report.message
    assert not run.report.success and "less than min_progress 10 %: the anchors are a single node" in msg, msg
    assert "the target differs from the rest shape by 0.41 % of the size 95.1 mm after alignment" in msg
    assert "anchor a region of several nodes" in msg and "barely move" not in msg
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        p = design_pipeline(scene.mesh, scene.material, case.anchors, case.drags, units="mm",
                            routing_options=dict(scene.routing_options))  # the scene's fabrication, as mdsr run
    assert "the anchors are a single node, about which the body turns freely" in p.far_from_target
    # without the anchors' count (a layout's poses): the numbers still say the target is nearly rigid
    plain = difference_failure(0.378, 95.1, units="mm", rest_difference=0.393)
    assert plain.endswith("the muscles barely move the body, and the target is nearly a rigid motion of the rest "
                          "shape (it differs by 0.41 % of the size 95.1 mm after alignment): do the anchors hold the "
                          "body?")
    # a target far from rigid: as before
    assert difference_failure(0.95, 50.0, rest_difference=1.0, n_anchors=1).endswith(
        "the muscles barely move the body (the anchors are a single node, about which it turns freely)")
    assert difference_failure(0.95, 50.0, rest_difference=1.0).endswith("less than min_progress 10 %: the muscles "
                                                                        "barely move the body")


def _panel_boxes(fig):
    """Each axes' drawn box (after its equal aspect is applied), in inches: (x0, x1, width, height)."""
    fig.canvas.draw()
    W, H = fig.get_size_inches()
    out = []
    for ax in fig.axes:
        ax.apply_aspect()
        p = ax.get_position()
        out.append((p.x0 * W, p.x1 * W, p.width * W, p.height * H))
    return out


@pytest.mark.parametrize("size", [(1.0, 4.0), (4.0, 1.0), (1.0, 1.0)])
def test_muscles_figure_panels_sit_a_label_apart_for_tall_and_wide_bodies(size):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from mdsr_opt import Mesh, Muscle
    from mdsr_opt.plot.design import plot_routing

    w, h = size
    mesh = Mesh.rectangle(w, h, 4 * int(w), 4 * int(h))
    fig = plot_routing(mesh, mesh.points * [0.9, 1.0], [Muscle([0, 1, 2])], ticks=False, units="cm")
    try:
        (_, a1, aw, ah), (b0, _, bw, bh) = _panel_boxes(fig)
        gap = b0 - a1
        # before: an 11 x 4 in figure; a body 1 x 4 drawn 0.8 in wide in each half, 4.5 in of blank between them
        assert 0.5 < gap <= 1.05, gap
        assert aw / ah == pytest.approx(w / h, rel=0.1) and bw / bh == pytest.approx(0.9 * w / h, rel=0.1)
        assert fig.get_size_inches()[0] <= 2 * 5.0 + 2.0  # never wider than two 5 in panels and their labels
    finally:
        plt.close(fig)


def test_a_scene_reports_repr_names_its_failed_cases():
    from mdsr_opt.scenes.runner import CaseReport
    from mdsr_opt.scenes.scenereport import SceneReport

    ok = CaseReport(scene="s", case="a", kind="external", n_nodes=10, success=True)
    bad = CaseReport(scene="s", case="b", kind="external", n_nodes=10, success=False, message="target solve failed: x")
    rep = SceneReport(scene="s", title="", n_nodes=10, cases=[ok, bad],
                      animations={"wave": {"success": False, "message": "frames [3] failed"}})
    text = repr(rep)
    assert "success=False, why='b: target solve failed: x; wave: frames [3] failed'" in text and len(text) <= 200
    assert "why=" not in repr(SceneReport(scene="s", title="", n_nodes=10, cases=[ok]))
