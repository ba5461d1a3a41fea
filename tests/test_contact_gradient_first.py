"""Designs with contact and no method named (:mod:`mdsr_opt.synthesis.contactdesign`): a gradient design without
the contacts, kept when a forward solve with them touches nothing; derivative-free with them otherwise.

Before, every such design ran the derivative-free search with the contacts (each evaluation a contact solve),
even when nothing was ever touched: a T in mm over a floor 20 mm below it took 63 contact solves where the nested
design without the floor takes 14 forward solves, and a star mounted over a floor stopped at Nelder-Mead's
evaluation cap (3,200 contact solves), failed."""

import numpy as np
import pytest
from shapely.geometry import Point, Polygon

from mdsr_opt import (
    Disk,
    HalfPlane,
    Mesh,
    Muscle,
    NeoHookean,
    design_contractions,
    design_pipeline,
    nodes_in_box,
    solve_external,
)

MAT = NeoHookean(1.0, 0.3)


def _strip(L):
    """A 4L x L strip bent by its right end (left end held), two edge muscles, a floor 3 L below: never touched."""
    mesh = Mesh.rectangle(4.0 * L, 1.0 * L, 12, 3)
    P = mesh.points
    left = np.flatnonzero(P[:, 0] < 1e-9 * L)
    right = np.flatnonzero(P[:, 0] > 4.0 * L * (1 - 1e-9))
    c, s = np.cos(0.5), np.sin(0.5)
    R, pivot = np.array([[c, -s], [s, c]]), np.array([2.0, 0.5]) * L
    target = solve_external(mesh, MAT, left, {int(i): pivot + (P[i] - pivot) @ R.T for i in right}).x
    top = sorted(np.flatnonzero(np.abs(P[:, 1] - L) < 1e-9 * L), key=lambda i: P[i, 0])
    bot = sorted(np.flatnonzero(np.abs(P[:, 1]) < 1e-9 * L), key=lambda i: P[i, 0])
    return mesh, [Muscle(top), Muscle(bot)], target, HalfPlane([0.0, -3.0 * L], [0.0, 1.0])


def _finger():
    """A 4 x 0.8 finger clamped at its base, a rope along its top, its tip dragged by (-1, 2)."""
    mesh = Mesh.rectangle(4.0, 0.8, 20, 4)
    P = mesh.points
    base = np.flatnonzero(P[:, 0] == 0.0)
    row = [int(i) for i in np.argsort(P[:, 0]) if abs(P[i, 1] - 0.8) < 1e-9 and 0.2 <= P[i, 0] <= 3.8]
    drags = {int(i): P[i] + [-1.0, 2.0] for i in nodes_in_box(mesh, xmin=4.0)}
    return mesh, base, [Muscle(row)], drags


def test_free_body_over_an_untouched_floor_is_designed_flattened_with_the_strokes_without_the_floor():
    mesh, mus, target, floor = _strip(1e3)  # a 4 m strip in mm
    free = design_contractions(mesh, MAT, mus, target)
    res = design_contractions(mesh, MAT, mus, target, obstacles=[floor])
    assert res.method == "flattened" and res.success and res.verification.passed, res.status
    assert res.contact_route.startswith("by method 'flattened' without the obstacles, then checked with them: "
                                        "untouched"), res.contact_route
    assert res.contact_route in res.status and "verified with them" in res.contact_route
    # the same design as without the floor: strokes to 1e-9 of their size, the same difference
    np.testing.assert_allclose(res.stroke, free.stroke, rtol=1e-9, atol=1e-9 * mesh.size)
    assert res.difference == pytest.approx(free.difference, rel=1e-9)
    # verified with the floor: no contact, the state in the obstacles' frame (the gauge the contact solve holds)
    assert res.verification.contact is not None and res.verification.contact["pairs"] == []
    assert res.verification.gap <= 1e-5 * mesh.size
    np.testing.assert_allclose(res.x @ res.rotation.T + res.translation,
                               free.x @ free.rotation.T + free.translation, atol=1e-6 * mesh.size)
    assert floor.gap(res.x).min() > 2e3  # 3 m below the strip at rest: never near it
    # named, the derivative-free search takes the floor from the start, as before
    named = design_contractions(mesh, MAT, mus, target, obstacles=[floor], method="derivative-free")
    assert named.method == "derivative-free" and named.contact_route == ""


def test_self_contact_that_never_activates_is_designed_flattened():
    mesh, mus, target, _ = _strip(1e-3)
    free = design_contractions(mesh, MAT, mus, target)
    res = design_contractions(mesh, MAT, mus, target, contact=True)
    assert res.method == "flattened" and res.success, res.status
    assert "without self-contact, then checked with them: untouched" in res.contact_route
    np.testing.assert_allclose(res.contractions, free.contractions, atol=1e-12)


def test_mounted_body_over_an_untouched_floor_is_designed_nested_by_the_pipeline():
    mesh, base, mus, drags = _finger()
    floor = HalfPlane([0.0, -2.0], [0.0, 1.0])
    held = design_pipeline(mesh, MAT, base, drags, muscles=mus, held=base)  # no floor: nested, clamped
    over = design_pipeline(mesh, MAT, base, drags, muscles=mus, obstacles=[floor])
    d = over.design
    assert d.method == "nested" and over.success and d.verification.passed, d.status
    assert d.held == tuple(int(i) for i in base)
    assert "by method 'nested' without the obstacles, then checked with them: untouched" in d.contact_route
    # the same design as without the floor, to the targets' agreement (with the floor the target is solved by
    # IPOPT with contact rows, without it by Newton, both to 1e-8: strokes agree to 4e-8)
    np.testing.assert_allclose(d.stroke, held.design.stroke, rtol=1e-6)
    np.testing.assert_allclose(d.x, held.design.x, atol=1e-6 * mesh.size)
    assert d.contact["pairs"] == [] and d.contact["total_force"] == 0.0


def test_target_pressed_on_a_disk_is_designed_derivative_free_from_the_start_as_when_named():
    mesh, base, mus, drags = _finger()
    disk = Disk((1.7, 1.9), 0.5)
    target = solve_external(mesh, MAT, base, drags, obstacles=[disk])
    assert target.contact["pairs"]  # the target presses on the disk
    res = design_contractions(mesh, MAT, mus, target.x, held=base, obstacles=[disk])
    named = design_contractions(mesh, MAT, mus, target.x, held=base, obstacles=[disk], method="derivative-free")
    assert res.method == "derivative-free" and res.success and res.verification.passed, res.status
    assert res.contact_route.startswith("by method 'derivative-free' with the obstacles: its target touches "
                                        "obstacles[0]"), res.contact_route
    np.testing.assert_array_equal(res.contractions, named.contractions)  # today's search, untouched
    np.testing.assert_array_equal(res.initial_contractions, named.initial_contractions)
    assert len(res.contact["pairs"]) > 0 and res.contact["total_force"] > 0


def test_gradient_design_that_enters_a_disk_falls_back_to_derivative_free_from_its_contractions():
    # the target (tip dragged by (-1, 2)) passes 0.26 from the disk; the nested design without it curls the
    # finger more, through the disk (0.19 deep): the search with the disk starts from its contractions
    mesh, base, mus, drags = _finger()
    target = solve_external(mesh, MAT, base, drags).x
    disk = Disk((2.6, 1.35), 0.25)
    assert disk.gap(target).min() > 0.2 and disk.gap(mesh.points).min() > 0.2
    grad = design_contractions(mesh, MAT, mus, target, held=base)
    assert grad.method == "nested" and disk.gap(grad.x).min() < -0.1
    res = design_contractions(mesh, MAT, mus, target, held=base, obstacles=[disk])
    assert res.method == "derivative-free" and res.success and res.verification.passed, res.status
    np.testing.assert_allclose(res.initial_contractions, grad.contractions, rtol=1e-12)
    assert res.contact_route.startswith("by method 'derivative-free' with the obstacles, started from the "
                                        "contractions of the nested design without them, which touches the "
                                        "obstacles"), res.contact_route
    assert res.n_forward > grad.n_forward  # the counters cover both designs
    # the designed state presses on the disk and respects it (shapely, independently)
    assert len(res.contact["pairs"]) > 0 and res.contact["total_force"] > 0
    assert disk.gap(res.x).min() >= 0.0
    outline = Polygon(res.x[mesh.boundary_loops[0]])
    assert outline.intersection(Point(disk.center).buffer(disk.radius, 256)).area < 1e-3 * np.pi * disk.radius ** 2
    # the answer of the search with the disk named from its own start (0.0617): 0.16302 (measured)
    assert res.contractions[0] == pytest.approx(0.16302, abs=1e-4)


def test_contact_design_without_a_method_checks_the_searchs_options_at_the_door():
    mesh, mus, target, floor = _strip(1.0)
    with pytest.raises(ValueError, match="bogus"):
        design_contractions(mesh, MAT, mus, target, obstacles=[floor], options={"bogus": 1})
    with pytest.raises(ValueError, match="outer"):
        design_contractions(mesh, MAT, mus, target, obstacles=[floor], outer="simplex")
    with pytest.raises(ValueError, match="derivative-free"):
        design_contractions(mesh, MAT, mus, target, obstacles=[floor], method="nested")
