"""Only stable equilibria are successes: a compressed clamped strip buckles instead of staying straight."""

from __future__ import annotations

import numpy as np
import pytest

from mdsr_opt import Mesh, NeoHookean, get_model, solve_external


@pytest.fixture(scope="module")
def clamped_strip():
    mesh = Mesh.rectangle(10.0, 1.0, 40, 4)
    P = mesh.points
    left = np.flatnonzero(P[:, 0] == 0.0)
    right = np.flatnonzero(P[:, 0] == 10.0)
    free = np.ones(2 * mesh.n_nodes, bool)
    nodes = np.r_[left, right]
    free[2 * nodes] = free[2 * nodes + 1] = False
    return mesh, left, right, free


def _push(mesh, right, by):
    P = mesh.points
    return {int(i): (P[i, 0] - by, P[i, 1]) for i in right}


def _min_eig(mesh, mat, x, free):
    model = get_model(mesh, mat)
    H = model.hessian(x.reshape(-1), model.params(mat))
    return float(np.linalg.eigvalsh(H[free][:, free].toarray())[0])


def test_issue_example_returns_the_buckled_state(clamped_strip):
    """Right end pushed left by 2: the straight state (energy 0.2519) is a saddle; the buckled one has 0.0782."""
    mesh, left, right, free = clamped_strip
    mat = NeoHookean(1.0, 0.3)
    res = solve_external(mesh, mat, left, _push(mesh, right, 2.0))
    assert res.success and res.stable is True
    assert res.energy == pytest.approx(0.0782, abs=5e-4)
    assert "left a saddle" in res.status
    assert res.stability["n_negative"] == 0 and res.stability["method"] == "ldl-inertia"
    assert np.abs(res.x[:, 1] - mesh.points[:, 1]).max() > 1.0  # visibly buckled
    assert _min_eig(mesh, mat, res.x, free) > 0


@pytest.mark.parametrize("compression", [0.05, 0.15, 0.30, 0.50])
def test_compressed_strip_buckles_into_a_minimum(clamped_strip, compression):
    mesh, left, right, free = clamped_strip
    mat = NeoHookean(1.0, 0.3)
    res = solve_external(mesh, mat, left, _push(mesh, right, 10.0 * compression))
    assert res.success and res.stable
    assert _min_eig(mesh, mat, res.x, free) > 0  # dense check of the returned state
    assert not mesh.boundary_crosses(res.x)
    # the straight state at this compression has more energy: the solver did leave it
    straight = mesh.points.copy()
    straight[:, 0] *= 1.0 - compression
    model = get_model(mesh, mat)
    assert res.energy < model.energy(straight.reshape(-1), model.params(mat))


def test_saddle_without_escape_is_a_failure_with_the_reason(clamped_strip, monkeypatch):
    """With no re-solves allowed, the straight saddle must be reported as a failure, never as a success."""
    import mdsr_opt.mechanics.loadsteps as eq

    mesh, left, right, free = clamped_strip
    mat = NeoHookean(1.0, 0.3)
    monkeypatch.setattr(eq, "_RESTARTS", 0)
    res = solve_external(mesh, mat, left, _push(mesh, right, 2.0))
    assert not res.success and res.stable is False
    assert "not a stable equilibrium" in res.status and "negative curvature" in res.status
    assert res.stability["n_negative"] >= 1
    assert res.energy == pytest.approx(0.2519, abs=5e-4)  # the straight state, reported as what it is
    assert _min_eig(mesh, mat, res.x, free) < 0
    with pytest.raises(Exception, match="not a stable equilibrium"):
        res.raise_on_failure()


def test_stretched_strip_is_stable_without_restarts(clamped_strip):
    mesh, left, right, free = clamped_strip
    res = solve_external(mesh, NeoHookean(1.0, 0.3), left, _push(mesh, right, -1.0))
    assert res.success and res.stable and "saddle" not in res.status
    assert res.summary()["stable"] is True


@pytest.mark.parametrize("bad", [0, 0.0, -0.1, float("nan"), 1.5, float("inf")])
def test_min_step_out_of_range_is_refused_at_the_door(clamped_strip, bad):
    mesh, left, right, free = clamped_strip
    with pytest.raises(ValueError, match=r"min_step must be in \(0, 1\]"):
        solve_external(mesh, NeoHookean(1.0, 0.3), left, _push(mesh, right, 1.0), min_step=bad)


def test_min_step_wrong_type():
    mesh = Mesh.rectangle(4.0, 1.0, 8, 2)
    with pytest.raises(TypeError, match="min_step must be a number"):
        solve_external(mesh, NeoHookean(1.0, 0.3), [0, 9], {8: (4.5, 0.0)}, min_step="small")


def test_external_stability_of_a_target(clamped_strip, monkeypatch):
    import mdsr_opt.mechanics.loadsteps as eq
    from mdsr_opt import external_stability

    mesh, left, right, free = clamped_strip
    mat = NeoHookean(1.0, 0.3)
    drags = _push(mesh, right, 2.0)
    buckled = solve_external(mesh, mat, left, drags)
    monkeypatch.setattr(eq, "_RESTARTS", 0)
    straight = solve_external(mesh, mat, left, drags)
    chk, res = external_stability(mesh, mat, left, drags, buckled.x, lowest=True)
    assert chk.stable and res < 1e-8
    assert chk.curvature == pytest.approx(_min_eig(mesh, mat, buckled.x, free), rel=1e-4)
    chk, res = external_stability(mesh, mat, left, drags, straight.x)
    assert not chk.stable and chk.n_negative >= 1 and res < 1e-8


@pytest.mark.filterwarnings("ignore")
def test_verify_design_checks_the_targets_stability(clamped_strip, monkeypatch):
    import mdsr_opt.mechanics.loadsteps as eq
    from mdsr_opt import Muscle, design_contractions, verify_design

    mesh, left, right, free = clamped_strip
    mat = NeoHookean(1.0, 0.3)
    drags = _push(mesh, right, 2.0)
    buckled = solve_external(mesh, mat, left, drags)
    monkeypatch.setattr(eq, "_RESTARTS", 0)
    straight = solve_external(mesh, mat, left, drags)
    bottom = sorted(np.flatnonzero(mesh.points[:, 1] == 0.0), key=lambda i: mesh.points[i, 0])
    mus = [Muscle(bottom[2:-2])]
    for target, stable in ((straight.x, False), (buckled.x, True)):
        res = design_contractions(mesh, mat, mus, target, verify=False, max_iter=50)
        v = verify_design(mesh, mat, mus, res, target, anchors=left, drags=drags)
        assert v.target_stable is stable
        assert ("target is not a stable equilibrium" in v.message) is (not stable)
        if not stable:
            assert not v.passed
        assert verify_design(mesh, mat, mus, res, target).target_stable is None  # not asked
