"""design_poses routes every pose as the pipeline routes (synthesis.layouts.route_poses) and says the true
cause when a pose gets no rope (trial7 defect 6)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from mdsr_opt import NeoHookean, mesh_polygon, nodes_in_box, nodes_near, solve_external
from mdsr_opt.synthesis.layouts import route_poses
from mdsr_opt.synthesis.poses import design_poses
from mdsr_opt.synthesis.routing import route_for_design, route_muscles

MAT = NeoHookean(1.0, 0.3)


@pytest.fixture(scope="module")
def ell():
    """An L-shaped body standing on its foot, the arm's tip dragged up: the default routing keeps no rope
    inside the buildable band, the pipeline's fallbacks do."""
    mesh = mesh_polygon([[0, 0], [1, 0], [1, 3], [2.5, 3], [2.5, 4], [0, 4]], resolution=250)
    P = mesh.points
    foot = nodes_in_box(mesh, ymax=0.0)
    drags = {int(i): P[i] + [0.0, 1.0] for i in nodes_near(mesh, [2.5, 3.5], 0.35)}
    res = solve_external(mesh, MAT, foot, drags)
    assert res.success
    th = 0.3  # a rigid motion of the rest shape: no edge changes length
    still = P @ np.array([[np.cos(th), np.sin(th)], [-np.sin(th), np.cos(th)]]) + [1.0, 2.0]
    return mesh, res.x, still


def quiet(f, *a, **k):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return f(*a, **k)


def test_the_body_needs_the_pipelines_fallbacks(ell):
    """The premise of the tests below: plain routing keeps nothing, the pipeline's routing keeps ropes."""
    mesh, lift, _ = ell
    assert len(quiet(route_muscles, mesh, lift)) == 0
    assert len(quiet(route_for_design, mesh, lift)) >= 1


def test_a_pose_the_pipeline_can_route_gets_its_ropes(ell):
    mesh, lift, _ = ell
    # idle_contraction=0: every rope routed is kept (with the default, M2, designed to 0.00025 and slack, is
    # dropped as idle: tests/test_poses_idle.py)
    res = quiet(design_poses, mesh, MAT, {"lift": lift}, max_muscles=4, idle_contraction=0)
    want = quiet(route_for_design, mesh, lift)
    assert res.n_muscles == len(want)
    assert [tuple(m.nodes) for m in res.muscles] == [tuple(m.nodes) for m in want.muscles]
    assert res.engaged[0].any()
    assert res.differences[0] < 0.9 * res.rest_differences[0]  # the ropes move the body towards the pose


def test_route_poses_is_route_for_design_per_pose(ell):
    mesh, lift, still = ell
    layouts, reasons = route_poses(mesh, {"lift": lift, "still": still}, {})
    assert list(layouts) == ["lift", "still"]
    assert [tuple(m.nodes) for m in layouts["lift"]] == \
        [tuple(m.nodes) for m in quiet(route_for_design, mesh, lift).muscles]
    assert layouts["still"] == () and list(reasons) == ["still"]
    assert "equals the rest shape" in reasons["still"] and "no edge length changes" in reasons["still"]


def test_no_rope_for_any_pose_says_each_poses_reason(ell):
    mesh, lift, still = ell
    with pytest.raises(ValueError) as err:
        quiet(design_poses, mesh, MAT, {"still": still})
    msg = str(err.value)
    assert msg.startswith("no rope for any pose, nothing to design: pose 'still': ")
    assert "equals the rest shape" in msg and "contracts any edge" not in msg
    # ropes the routing finds but drops: said with the figure that dropped them
    with pytest.raises(ValueError) as err:
        quiet(design_poses, mesh, MAT, {"lift": lift}, routing_options={"compression_ratio": 0.5, "min_length": 50.0})
    msg = str(err.value)
    assert "pose 'lift'" in msg and "min_length=50" in msg and "contracts any edge" not in msg


def test_a_pose_without_ropes_says_why_in_its_status(ell):
    mesh, lift, still = ell
    res = quiet(design_poses, mesh, MAT, {"lift": lift, "still": still}, compare=False)
    assert res.n_muscles >= 1 and not res.engaged[1].any()
    assert "its own routing kept no rope" in res.status[1] and "equals the rest shape" in res.status[1]
    assert "own routing" not in res.status[0]


def test_a_list_of_bare_targets_is_named_by_place(ell):
    mesh, lift, still = ell
    res = quiet(design_poses, mesh, MAT, [lift, ("still", still)], compare=False)
    assert res.names == ("pose0", "still")
