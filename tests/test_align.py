"""Weighted Kabsch alignment and the difference index (mdsr_opt.align)."""

from __future__ import annotations

import numpy as np
import pytest

from mdsr_opt import Mesh
from mdsr_opt.mechanics.align import align, difference, node_weights


def rotation_matrix(theta):
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s], [s, c]])


def _brute_force(x, y, w):
    """min over a fine angle grid (refined twice) of sum w |R x + t - y|^2, with t optimal for each angle."""
    W = w.sum()
    cx, cy = (w[:, None] * x).sum(0) / W, (w[:, None] * y).sum(0) / W

    def D(th):
        R = rotation_matrix(th)
        r = (x - cx) @ R.T - (y - cy)
        return float((w * (r ** 2).sum(1)).sum())

    grid = np.linspace(-np.pi, np.pi, 3601)
    for _ in range(3):
        vals = np.array([D(t) for t in grid])
        k = int(np.argmin(vals))
        step = grid[1] - grid[0]
        grid = np.linspace(grid[k] - step, grid[k] + step, 401)
    vals = np.array([D(t) for t in grid])
    k = int(np.argmin(vals))
    return grid[k], vals[k]


@pytest.fixture
def cloud():
    rng = np.random.default_rng(7)
    x = rng.normal(size=(30, 2))
    y = x @ rotation_matrix(1.1).T + [0.4, -2.0] + 0.2 * rng.normal(size=(30, 2))  # rotated, shifted and noisy
    w = rng.uniform(0.3, 1.0, size=30)
    return x, y, w


def test_kabsch_matches_brute_force_angle_search(cloud):
    x, y, w = cloud
    al = align(x, y, w)
    th, Dmin = _brute_force(x, y, w)
    D = al.difference ** 2 * w.sum()
    assert D <= Dmin * (1 + 1e-9)  # never worse than the search
    assert D == pytest.approx(Dmin, rel=1e-6)
    assert al.angle == pytest.approx(th, abs=1e-5)
    assert np.linalg.det(al.R) == pytest.approx(1.0)
    # the optimal translation for that rotation maps weighted centroids onto each other
    W = w.sum()
    assert al.R @ ((w[:, None] * x).sum(0) / W) + al.t == pytest.approx((w[:, None] * y).sum(0) / W)


def test_exact_rigid_motion_is_recovered():
    rng = np.random.default_rng(1)
    x = rng.uniform(-1, 1, size=(12, 2))
    R, t = rotation_matrix(-2.5), np.array([3.0, 1.5])
    al = align(x, x @ R.T + t)
    assert np.allclose(al.R, R, atol=1e-12)
    assert np.allclose(al.t, t, atol=1e-12)
    assert al.difference < 1e-12
    assert np.allclose(al.apply(x), x @ R.T + t, atol=1e-12)


def test_invariances(cloud):
    x, y, w = cloud
    d = difference(x, y, w)
    assert d > 0.05
    Q, s = rotation_matrix(0.7), np.array([-5.0, 2.0])
    assert difference(x @ Q.T + s, y, w) == pytest.approx(d, rel=1e-10)  # moving x rigidly
    assert difference(x, y @ Q.T + s, w) == pytest.approx(d, rel=1e-10)  # moving y rigidly
    assert difference(y, x, w) == pytest.approx(d, rel=1e-10)  # symmetric
    assert difference(x, y, 3.0 * w) == pytest.approx(d, rel=1e-10)  # only relative weights matter
    perm = np.random.default_rng(2).permutation(len(x))
    assert difference(x[perm], y[perm], w[perm]) == pytest.approx(d, rel=1e-10)  # node order
    assert difference(2 * x, 2 * y, w) == pytest.approx(2 * d, rel=1e-10)  # a length


def test_reflection_is_not_a_rotation():
    x = np.array([[0.0, 0.0], [2.0, 0.0], [0.0, 1.0], [1.0, 3.0]])
    y = x * [-1.0, 1.0]  # mirror image
    al = align(x, y)
    assert np.linalg.det(al.R) == pytest.approx(1.0)
    assert al.difference > 0.1


def test_weights_steer_the_fit():
    x = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0]])
    y = x.copy()
    y[3] += [0.0, 1.0]  # one node off
    w_low = np.array([1.0, 1.0, 1.0, 1e-6])
    assert difference(x, y, w_low) < 1e-3 < difference(x, y)


def test_node_weights():
    mesh = Mesh.rectangle(2.0, 1.0, 4, 2)
    w = node_weights(mesh, interior=0.4)
    assert set(np.nonzero(w == 1.0)[0]) == set(mesh.boundary_nodes.tolist())
    interior = np.setdiff1d(np.arange(mesh.n_nodes), mesh.boundary_nodes)
    assert len(interior) == 3 and np.all(w[interior] == 0.4)
    assert np.all(node_weights(mesh)[interior] == 0.5)
    for bad in (0.2, 0.71):
        with pytest.raises(ValueError, match=r"interior weight must lie in \[0.3, 0.7\]"):
            node_weights(mesh, bad)


def test_bad_input():
    x = np.zeros((4, 2))
    with pytest.raises(ValueError, match=r"y must have shape \(4, 2\)"):
        align(x, np.zeros((3, 2)))
    with pytest.raises(ValueError, match=r"x must have shape \(k, 2\)"):
        align(np.zeros((4, 3)), np.zeros((4, 3)))
    with pytest.raises(ValueError, match="non-negative with a positive sum"):
        align(x, x, weights=[1.0, -1.0, 1.0, 1.0])
    with pytest.raises(ValueError, match=r"weights must have shape \(4\), got \(2,\)"):
        align(x, x, weights=[1.0, 1.0])
    with pytest.raises(ValueError, match="NaN or inf"):
        difference(x, np.full((4, 2), np.nan))
