"""With self-contact, prescribed nodes that push the prescribed parts of the body through each other are
refused at the door (the trial's C gripper with both jaws dragged into one band ran load stepping for 30 s
and stalled at fraction 0.78 without naming the cause), as drags into a rigid obstacle are."""

from __future__ import annotations


import numpy as np
import pytest

from mdsr_opt import Mesh, NeoHookean, mesh_polygon, nodes_in_box, nodes_near, solve_external
from mdsr_opt.mechanics.selfprescribed import check_prescribed_self

# the trial's thick C (outer radius 40, inner 22, opening on the right)
C = [[40.0, 0.0], [30.64, 25.71], [20.0, 34.64], [6.95, 39.39], [-6.95, 39.39], [-20.0, 34.64], [-30.64, 25.71],
     [-37.59, 13.68], [-40.0, 0.0], [-37.59, -13.68], [-30.64, -25.71], [-20.0, -34.64], [-6.95, -39.39],
     [6.95, -39.39], [20.0, -34.64], [30.64, -25.71], [16.85, -14.14], [11.0, -19.05], [3.82, -21.66],
     [-3.82, -21.66], [-11.0, -19.05], [-16.85, -14.14], [-20.67, -7.52], [-22.0, 0.0], [-20.67, 7.52],
     [-16.85, 14.14], [-11.0, 19.05], [-3.82, 21.66], [3.82, 21.66], [11.0, 19.05], [16.85, 14.14]]


@pytest.fixture(scope="module")
def gripper():
    mesh = mesh_polygon(C, resolution=300)
    back = nodes_in_box(mesh, -41, -8, -35, 8)
    up, lo = nodes_near(mesh, (23.7, 20), 7), nodes_near(mesh, (23.7, -20), 7)
    return mesh, back, up, lo


def _jaws(mesh, up, lo, dy):
    P = mesh.points
    return {**{int(i): P[i] + [0, -dy] for i in up}, **{int(i): P[i] + [0, dy] for i in lo}}


def test_jaws_dragged_into_each_other_are_refused_at_once(gripper, monkeypatch):
    import mdsr_opt.mechanics.equilibrium as equilibrium

    def no_solve(*a, **k):
        raise AssertionError("the energy model was built: the refusal came after the solve began")

    mesh, back, up, lo = gripper
    monkeypatch.setattr(equilibrium, "get_model", no_solve)  # refused before any solve (the stalled one took minutes)
    with pytest.raises(ValueError, match=r"with contact, the prescribed nodes would overlap at their targets: "
                                         r"node \d+ \(dragged to .*prescribed nodes around \(2\d\.\d+, -?\d") as e:
        solve_external(mesh, NeoHookean(1.0, 0.4), back, _jaws(mesh, up, lo, 20.0), contact=True)
    assert "move the drags' targets" in str(e.value)


def test_jaws_passing_through_each_other_on_the_way_are_refused(gripper):
    mesh, back, up, lo = gripper
    drags = _jaws(mesh, up, lo, 40.0)  # swapped at the end: apart at the target, through each other midway
    nodes = np.concatenate([back, list(drags)])
    final = np.vstack([mesh.points[back], list(drags.values())])
    rest = mesh.points[nodes]
    with pytest.raises(ValueError, match=r"would overlap \d+% of the way along the drags"):
        check_prescribed_self(mesh, nodes, lambda s: rest + s * (final - rest), 1e-3, anchored=len(back))


@pytest.mark.parametrize("dy", [0.0, 8.0, 12.0])
def test_drags_that_keep_the_jaws_apart_pass(gripper, dy):
    mesh, back, up, lo = gripper
    drags = _jaws(mesh, up, lo, dy)  # the trial scene's own case closes them by 8 each
    nodes = np.concatenate([back, list(drags)])
    final = np.vstack([mesh.points[back], list(drags.values())])
    rest = mesh.points[nodes]
    check_prescribed_self(mesh, nodes, lambda s: rest + s * (final - rest), 1e-3, anchored=len(back))


def test_a_rigid_turn_of_a_strip_end_passes_and_the_gap_is_kept():
    mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    P = mesh.points
    left, right = np.flatnonzero(P[:, 0] == 0.0), np.flatnonzero(P[:, 0] == 4.0)
    nodes = np.concatenate([left, right])
    for dx, gap, refused in ((-3.9, 1e-3, False), (-3.9995, 1e-3, True), (-3.9995, 1e-4, False)):
        x = np.vstack([P[left], P[right] + [dx, 0.0]])  # the right end brought beside the left one
        rest = P[nodes]
        if refused:
            with pytest.raises(ValueError, match=r"closer than the contact gap 0\.001 to the boundary edge"):
                check_prescribed_self(mesh, nodes, lambda s: rest + s * (x - rest), gap, anchored=len(left))
        else:
            check_prescribed_self(mesh, nodes, lambda s: rest + s * (x - rest), gap, anchored=len(left))
