"""The derivative-free design's stopping test (trial 11, defect 1): it means the same for a body in mm or in m
and for two or four muscles, so a design with an obstacle it never touches (or self-contact that never
activates) stops on its own, a success, instead of sitting at its answer until the evaluation cap.

Before the fix (``fatol = tol ** 2`` on the objective, below the noise of its warm-started forward solves)
every design below ran to the cap (400 evaluations per muscle) and came back ``success=False``. The designs name
the method: without it a design whose contacts are never touched is made by a gradient method and checked with
them (test_contact_gradient_first.py)."""

import numpy as np
import pytest

from mdsr_opt import HalfPlane, Mesh, Muscle, NeoHookean, design_contractions, solve_external

MAT = NeoHookean(1.0, 0.3)


def _strip(L, split=False):
    """A 4L x L strip bent 29 deg by its right end (its left end held): a target two (or four) edge muscles
    along its long sides approach but cannot reach, and a floor 3 L below it that no state touches."""
    mesh = Mesh.rectangle(4.0 * L, 1.0 * L, 12, 3)
    P = mesh.points
    left = np.flatnonzero(P[:, 0] < 1e-9 * L)
    right = np.flatnonzero(P[:, 0] > 4.0 * L * (1 - 1e-9))
    c, s = np.cos(0.5), np.sin(0.5)
    R, pivot = np.array([[c, -s], [s, c]]), np.array([2.0, 0.5]) * L
    target = solve_external(mesh, MAT, left, {int(i): pivot + (P[i] - pivot) @ R.T for i in right}).x
    top = sorted(np.flatnonzero(np.abs(P[:, 1] - L) < 1e-9 * L), key=lambda i: P[i, 0])
    bot = sorted(np.flatnonzero(np.abs(P[:, 1]) < 1e-9 * L), key=lambda i: P[i, 0])
    paths = [top[:7], top[6:], bot[:7], bot[6:]] if split else [top, bot]
    return mesh, [Muscle(p) for p in paths], target, HalfPlane([0.0, -3.0 * L], [0.0, 1.0])


@pytest.mark.parametrize("outer", ["nelder-mead", "powell"])
def test_design_with_a_far_obstacle_stops_converged_the_same_in_mm_and_m(outer):
    found = {}
    for L in (1e3, 1e-3):  # a 4 m strip in mm, a 4 mm strip in m
        mesh, mus, target, floor = _strip(L)
        res = design_contractions(mesh, MAT, mus, target, obstacles=[floor], outer=outer, method="derivative-free")
        assert res.method == "derivative-free"
        assert res.success and res.verification.passed, res.status
        assert "terminated successfully" in res.status, res.status
        assert res.n_forward < 400, res.n_forward  # the cap is 800: stopped on the test, well before it
        assert np.all(res.x[:, 1] > -3.0 * L + 0.5 * L)  # the floor is never touched
        found[L] = (res.contractions, res.difference / L)
    (a_mm, d_mm), (a_m, d_m) = found[1e3], found[1e-3]
    np.testing.assert_allclose(a_mm, a_m, atol=1e-6)
    assert d_mm == pytest.approx(d_m, rel=1e-6)
    assert a_mm[0] == pytest.approx(0.1161, abs=2e-4) and a_mm[1] == pytest.approx(0.0, abs=1e-6)
    assert d_mm == pytest.approx(0.04236, rel=1e-3)


def test_self_contact_that_never_activates_stops_converged():
    mesh, mus, target, _ = _strip(1e-3)
    res = design_contractions(mesh, MAT, mus, target, contact=True, method="derivative-free")
    assert res.method == "derivative-free"
    assert res.success and res.verification.passed, res.status
    assert "terminated successfully" in res.status, res.status
    assert res.contractions[0] == pytest.approx(0.1161, abs=2e-4)


@pytest.mark.slow  # about 20 s: four muscles (adaptive Nelder-Mead)
def test_four_muscles_with_a_far_obstacle_stop_converged_the_same_in_mm_and_m():
    found = []
    for L in (1e3, 1e-3):
        mesh, mus, target, floor = _strip(L, split=True)
        res = design_contractions(mesh, MAT, mus, target, obstacles=[floor], method="derivative-free")
        assert res.success and "terminated successfully" in res.status, res.status
        assert res.n_forward < 1600, res.n_forward  # the cap
        found.append((res.contractions, res.difference / L))
    np.testing.assert_allclose(found[0][0], found[1][0], atol=1e-6)
    assert found[0][1] == pytest.approx(found[1][1], rel=1e-6)


def test_search_stopped_by_the_cap_fails_and_says_how_far_apart_its_last_points_were():
    mesh, mus, target, floor = _strip(1e3)
    res = design_contractions(mesh, MAT, mus, target, obstacles=[floor], max_iter=12, method="derivative-free")
    assert not res.success
    assert "Maximum number of function evaluations" in res.status
    assert "its last simplex: contractions" in res.status and "xatol 1e-07" in res.status, res.status


def test_search_stopped_by_the_cap_whose_last_simplex_meets_the_test_succeeds():
    # the cap is hit right after the first simplex, whose points lie within the loose xatol and fatol given
    mesh, mus, target, floor = _strip(1e-3)
    res = design_contractions(mesh, MAT, mus, target, obstacles=[floor], max_iter=3,
                              options={"xatol": 0.5, "fatol": 1.0}, method="derivative-free")
    assert "its last simplex met the test" in res.status, res.status
    assert res.success, res.status


def _tee(L):
    """A T (bar 100 x 25, stem 24 x 65, in mm at L = 1, in m at L = 1e-3) whose stem is bent 35 deg about its
    root: the nested search's first full step folds the outline through itself."""
    outline = np.array([[0, 0], [100, 0], [100, 25], [62, 25], [62, 90], [38, 90], [38, 25], [0, 25]]) * L
    mesh = Mesh.from_polygon(outline, max_area=20 * L * L)
    P = mesh.points
    bar, stem = np.flatnonzero(P[:, 1] < 1e-9 * L), np.flatnonzero(P[:, 1] > 90 * L * (1 - 1e-9))
    c, s = np.cos(np.deg2rad(35)), np.sin(np.deg2rad(35))
    R, pivot = np.array([[c, -s], [s, c]]), np.array([50, 25]) * L
    return mesh, solve_external(mesh, MAT, bar, {int(i): pivot + (P[i] - pivot) @ R.T for i in stem}).x


def test_nested_design_backs_off_a_step_whose_outline_crosses_itself_the_same_in_mm_and_m():
    from mdsr_opt import route_for_design
    mesh, target = _tee(1.0)
    routing = route_for_design(mesh, target)  # routed once in mm: the same ropes (node paths) in m
    mus, radius = list(routing), routing.fixture_radius
    assert len(mus) == 4
    found = []
    for L in (1.0, 1e-3):
        mesh, target = _tee(L)
        res = design_contractions(mesh, MAT, mus, target, method="nested", anchor_radius=radius * L)
        # before: "forward solve failed: ... the boundary crosses itself" at the first guess, difference 7.30
        assert res.success and res.verification.passed, res.status
        assert "trial step(s) backed off" in res.status and "crosses itself" in res.status, res.status
        found.append((res.contractions, res.difference / L))
    flat = design_contractions(mesh, MAT, mus, target, method="flattened", anchor_radius=radius * 1e-3)
    for a, d in found:  # the flattened design's answer (it never solves a crossed state)
        np.testing.assert_allclose(a, flat.contractions, atol=2e-3)
        assert d == pytest.approx(flat.difference / 1e-3, rel=1e-3)
        assert d == pytest.approx(2.385, abs=2e-3)
