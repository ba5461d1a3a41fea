"""A prescribed node driven into a rigid obstacle can never get there: refused at the door with the node, the
obstacle and the depth (the trial's clamp dragged 0.8 into HalfPlane([0, -0.3], [0, 1]) load-stepped for 244 s
and ended 'load stepping stalled at fraction 0.3711')."""

from __future__ import annotations

import numpy as np
import pytest

from mdsr_opt import Disk, HalfPlane, Mesh, NeoHookean, Obstacle, design_pipeline, solve_external
from mdsr_opt.mechanics.drags import RigidDrag
from mdsr_opt.mechanics.obstacles import check_prescribed


class Reached(Exception):
    pass


@pytest.fixture
def strip(monkeypatch):
    """A 4 x 1 strip, its left end for anchors and its right end for drags; the contact solver replaced by
    a stop, so that a test sees whether the door let a drag through."""
    def stop(*a, **k):
        raise Reached

    monkeypatch.setattr("mdsr_opt.mechanics.equilibrium.solve_with_contact", stop)
    m = Mesh.rectangle(4.0, 1.0, 16, 4)
    P = m.points
    return m, np.flatnonzero(P[:, 0] < 1e-9), np.flatnonzero(P[:, 0] > 4 - 1e-9)


def test_the_trials_drag_below_the_ground_is_refused(strip):
    m, left, right = strip
    drags = {int(i): m.points[i] + [0.0, -0.8] for i in right}
    low = int(right[np.argmin(m.points[right, 1])])
    with pytest.raises(ValueError) as e:
        solve_external(m, NeoHookean(1, 0.3), left, drags, obstacles=[HalfPlane([0, -0.3], [0, 1])])
    msg = str(e.value)
    assert f"node {low} is dragged to (4, -0.8), 0.5 deep inside obstacles[0] (HalfPlane(point=[0.0, -0.3]" in msg
    assert "at its target" in msg


@pytest.mark.parametrize("obstacle, depth", [(Disk((5.0, 0.5), 0.6), 0.6), (Obstacle([(4.5, -1), (6, -1), (6, 2), (4.5, 2)]), 0.5)])
def test_every_kind_of_obstacle_is_checked(strip, obstacle, depth):
    m, left, right = strip
    drags = {int(i): m.points[i] + [1.0, 0.0] for i in right}  # the end pushed 1.0 to the right, to x = 5
    with pytest.raises(ValueError, match=rf"{depth:.3g} deep inside obstacles\[1\]"):
        solve_external(m, NeoHookean(1, 0.3), left, drags, obstacles=[HalfPlane([0, -5], [0, 1]), obstacle])


def test_a_path_through_an_obstacle_is_refused_and_a_target_on_its_surface_is_not(strip):
    m, left, right = strip
    drags = {int(i): m.points[i] + [3.0, 0.0] for i in right}  # through the disk at x = 5, out at x = 7
    with pytest.raises(ValueError, match=r"of the way along its drag \(target \(7, "):
        solve_external(m, NeoHookean(1, 0.3), left, drags, obstacles=[Disk((5.0, 0.5), 0.3)])
    touch = {int(i): m.points[i] + [0.0, -0.3] for i in right}  # the lowest node just onto the ground
    with pytest.raises(Reached):
        solve_external(m, NeoHookean(1, 0.3), left, touch, obstacles=[HalfPlane([0, -0.3], [0, 1])])
    # a rigid drag that swings the end down through the ground
    swing = [RigidDrag(right, -np.pi / 2, (2.0, 0.5))]
    with pytest.raises(ValueError, match=r"deep inside obstacles\[0\]"):
        solve_external(m, NeoHookean(1, 0.3), left, swing, obstacles=[HalfPlane([0, -0.3], [0, 1])])


def test_design_pipeline_refuses_it_before_any_solve(strip):
    m, left, right = strip
    drags = {int(i): m.points[i] + [0.0, -0.8] for i in right}
    with pytest.raises(ValueError, match=r"deep inside obstacles\[0\]"):
        design_pipeline(m, NeoHookean(1, 0.3), left, drags, obstacles=[HalfPlane([0, -0.3], [0, 1])])


def test_check_prescribed_tolerance_and_fixed_positions():
    ground = [HalfPlane([0, 0], [0, 1])]
    check_prescribed(ground, [3], np.array([[1.0, -1e-4]]), tolerance=2e-4)  # within the gap: allowed
    with pytest.raises(ValueError, match=r"node 3 is anchored to \(1, -0.001\), 0.001 deep inside obstacles\[0\]"):
        check_prescribed(ground, [3], np.array([[1.0, -1e-3]]), tolerance=2e-4, what="anchored")
