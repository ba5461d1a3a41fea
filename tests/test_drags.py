"""Drags along a path (RigidDrag) and the accepted drag forms."""

from __future__ import annotations

import numpy as np
import pytest

from mdsr_opt import Mesh, NeoHookean, RigidDrag, solve_external
from mdsr_opt.mechanics.drags import drag_path

L = 10.0


@pytest.fixture(scope="module")
def strip():
    mesh = Mesh.rectangle(L, 1.0, 40, 4)
    P = mesh.points
    return mesh, np.flatnonzero(P[:, 0] == 0.0), np.flatnonzero(P[:, 0] == L)


def _half_turn(right):
    """The right end turned through 180 degrees about its middle and moved over the anchored end: a U."""
    R = L / np.pi
    return RigidDrag(right, np.pi, (L, 0.5), shift=(-L, 2 * R))


def test_rigid_drag_positions_along_the_path(strip):
    mesh, left, right = strip
    d = _half_turn(right)
    path = drag_path(d, mesh)
    X = mesh.points[right]
    np.testing.assert_allclose(path.positions(0.0), X, atol=1e-12)
    # at every load the end keeps its shape (a rigid motion): pairwise distances preserved
    for s in (0.25, 0.5, 1.0):
        Y = path.positions(s)
        np.testing.assert_allclose(np.linalg.norm(Y - Y[0], axis=1), np.linalg.norm(X - X[0], axis=1), atol=1e-12)
    # halfway: turned by 90 degrees (the end's direction (0, 1) now points along -x)
    Y = path.positions(0.5)
    v = (Y[-1] - Y[0]) / np.linalg.norm(Y[-1] - Y[0])
    np.testing.assert_allclose(v, [-1.0, 0.0], atol=1e-12)
    # at full load: turned by 180 degrees, the middle of the end at (0, 0.5 + 2 L / pi)
    np.testing.assert_allclose(path.final.mean(0), [0.0, 0.5 + 2 * L / np.pi], atol=1e-12)


def test_strip_curls_through_180_degrees(strip):
    mesh, left, right = strip
    res = solve_external(mesh, NeoHookean(1.0, 0.3), left, _half_turn(right))
    assert res.success and res.stable, res.status
    assert not mesh.boundary_crosses(res.x)
    np.testing.assert_allclose(res.x[right], drag_path(_half_turn(right), mesh).final, atol=1e-12)
    # the end is upside down: its top node is now below its bottom node
    top, bottom = right[np.argmax(mesh.points[right, 1])], right[np.argmin(mesh.points[right, 1])]
    assert res.x[top, 1] < res.x[bottom, 1]
    assert res.min_J > 0


def test_straight_interpolation_to_the_same_half_turn_fails(strip):
    """The same end positions as straight moves pass the end through itself: load stepping stalls."""
    mesh, left, right = strip
    final = drag_path(_half_turn(right), mesh).final
    res = solve_external(mesh, NeoHookean(1.0, 0.3), left, {int(i): tuple(p) for i, p in zip(right, final)})
    assert not res.success and "stalled" in res.status


def test_mixed_list_of_rigid_and_straight_drags(strip):
    mesh, left, right = strip
    mid = int(np.flatnonzero((mesh.points[:, 0] == L / 2) & (mesh.points[:, 1] == 0.0))[0])
    d = RigidDrag(right, np.pi / 6, (L, 0.0), shift=(-0.5, 0.0))
    res = solve_external(mesh, NeoHookean(1.0, 0.3), left, [d, {mid: (L / 2, 0.2)}])
    assert res.success, res.status
    np.testing.assert_allclose(res.x[mid], [L / 2, 0.2], atol=1e-12)
    np.testing.assert_allclose(res.x[right], d.positions(mesh.points[right], 1.0), atol=1e-12)


def test_list_of_pairs_gets_a_clear_type_error(strip):
    mesh, left, right = strip
    pairs = [(int(i), (mesh.points[i, 0] + 1.0, mesh.points[i, 1])) for i in right]
    with pytest.raises(TypeError, match=r"list of \(node, position\) pairs.*dict\(") as e:
        solve_external(mesh, NeoHookean(1.0, 0.3), left, pairs)
    assert "RigidDrag" in str(e.value) and "dict {node: (x, y)}" in str(e.value)
    with pytest.raises(TypeError, match="single \\(node, position\\) pair"):
        solve_external(mesh, NeoHookean(1.0, 0.3), left, (int(right[0]), (11.0, 0.0)))
    with pytest.raises(TypeError, match="drags must be a dict"):
        solve_external(mesh, NeoHookean(1.0, 0.3), left, "right")


def test_pair_form_still_accepted(strip):
    mesh, left, right = strip
    pos = mesh.points[right] + [1.0, 0.0]
    res = solve_external(mesh, NeoHookean(1.0, 0.3), left, (right, pos))
    assert res.success
    np.testing.assert_allclose(res.x[right], pos, atol=1e-12)


def test_bad_rigid_drags(strip):
    mesh, left, right = strip
    with pytest.raises(ValueError, match="angle must be a finite number"):
        RigidDrag(right, float("nan"), (0.0, 0.0))
    with pytest.raises(ValueError, match="center"):
        RigidDrag(right, 1.0, (0.0, 0.0, 1.0))
    with pytest.raises(ValueError, match="at least one node"):
        RigidDrag([], 1.0, (0.0, 0.0))
    with pytest.raises(ValueError, match="more than once"):
        solve_external(mesh, NeoHookean(1.0, 0.3), left, [RigidDrag(right, 1.0, (L, 0.0)),
                                                          {int(right[0]): (L, 0.0)}])
    with pytest.raises(ValueError, match="both anchored and dragged"):
        solve_external(mesh, NeoHookean(1.0, 0.3), left, RigidDrag(left, 1.0, (0.0, 0.0)))
    with pytest.raises(ValueError, match="RigidDrag nodes"):
        solve_external(mesh, NeoHookean(1.0, 0.3), left, RigidDrag([mesh.n_nodes], 1.0, (0.0, 0.0)))


def test_rigid_drag_is_frozen_and_hashable(strip):
    d = RigidDrag([3, 4], 0.5, (1, 2))
    assert d.nodes == (3, 4) and d.center == (1.0, 2.0) and d.shift == (0.0, 0.0)
    with pytest.raises(Exception):
        d.angle = 1.0
    assert hash(d) == hash(RigidDrag((3, 4), 0.5, (1.0, 2.0)))
