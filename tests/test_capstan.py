"""A rope with capstan friction in its channel, ending on rigid fixtures (mdsr_opt.mechanics.capstan, fixtures,
quadsolve): mu = 0 is the exact cable, and the tension falls by exp(-mu theta) along a curved channel."""

from __future__ import annotations

import json

import numpy as np
import pytest

from mdsr_opt import Mesh, Muscle, NeoHookean, solve_internal
from mdsr_opt.mechanics.capstan import CapstanRope, quadratic_chain, turning_angles
from mdsr_opt.mechanics.fixtures import RigidReduction, fixture_groups
from mdsr_opt.mechanics.quadratic import QuadraticModel
from mdsr_opt.mechanics.quadsolve import solve_quadratic_internal

MAT = NeoHookean(1.0, 0.3)


@pytest.fixture(scope="module")
def strip():
    mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    bottom = [int(i) for i in np.argsort(mesh.points[:, 0]) if mesh.points[i, 1] == 0.0]
    return mesh, bottom


def _roped(strip):
    """The strip with one rope (friction 0.3) along its bottom on quadratic elements, fixtures of radius 0.3:
    ``(mesh, bottom, mid, groups, model, ropes)``."""
    mesh, bottom = strip
    mid = mesh.n_nodes + np.arange(len(mesh.edges))
    groups = fixture_groups(mesh, [Muscle(bottom)], 0.3, mid)
    return mesh, bottom, mid, groups, QuadraticModel(mesh, MAT), [CapstanRope(quadratic_chain(mesh, bottom, mid), 0.3)]


def test_frictionless_rope_is_the_exact_cable_of_solve_internal(strip):
    """mu = 0 on linear elements with the anchor patches of solve_internal as fixtures: the same state (both
    aligned to rest) and the same tension, to the solvers' tolerances."""
    mesh, bottom = strip
    muscle = Muscle(bottom)
    for radius, a in ((0.3, 0.3), (0.0, 0.2)):
        ref = solve_internal(mesh, MAT, [muscle], [a], anchor_radius=radius)
        groups = fixture_groups(mesh, [muscle], radius)
        assert (len(groups) == 2) == (radius > 0)
        res = solve_quadratic_internal(QuadraticModel(mesh, MAT, order=1), [CapstanRope(bottom, 0.0)], [a], groups)
        assert res.success and ref.success
        assert np.abs(res.x - ref.x).max() < 1e-6 * mesh.size
        assert res.tension[0] == pytest.approx(ref.tension[0], rel=1e-6)
        assert res.end_tension[0] == pytest.approx(res.tension[0], rel=1e-14)
        assert res.achieved[0] == pytest.approx(a, abs=1e-8)


@pytest.mark.parametrize("order", [1, 2])
def test_end_tension_falls_by_the_capstan_law_on_a_curved_channel(strip, order):
    """A rope along the bottom edge and up the right edge (a channel turning through about 90 degrees),
    pulled at its bottom-left end, mu = 0.4, point ends. The elastic forces holding its two ends are the
    rope's end tensions: their ratio is exp(-mu theta), theta the total turning of the deformed path measured
    here from its nodes."""
    mesh, bottom = strip
    P = mesh.points
    right = [int(i) for i in np.argsort(P[:, 1]) if P[i, 0] == 4.0][1:]
    nodes = bottom + right
    model = QuadraticModel(mesh, MAT, order=order)
    chain = quadratic_chain(mesh, nodes, mesh.n_nodes + np.arange(len(mesh.edges))) if order == 2 else nodes
    mu = 0.4
    res = solve_quadratic_internal(model, [CapstanRope(chain, mu)], [0.1])
    assert res.success, res.status
    # the result's manners, as every result's: one short line, a strict-JSON dict of every field
    text = repr(res)
    assert text.startswith("QuadraticResult(success=True") and "\n" not in text and len(text) <= 200
    d = json.loads(json.dumps(res.to_dict(), allow_nan=False))
    assert d["commanded"] == [0.1] and np.array(d["x"]).shape == res.x.shape
    x = res.x
    d = np.diff(x[chain], axis=0)
    u = d / np.linalg.norm(d, axis=1)[:, None]
    theta = float(np.sum(np.arccos(np.clip((u[:-1] * u[1:]).sum(1), -1.0, 1.0))))
    assert 1.2 < theta < 3.5 and res.turning[0] == pytest.approx(theta, rel=1e-9)
    g = model.energy_gradient(x)[1].reshape(-1, 2)
    pull, far = g[chain[0]], g[chain[-1]]
    np.testing.assert_allclose(pull, res.tension[0] * u[0], rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(far, -res.end_tension[0] * u[-1], rtol=1e-6, atol=1e-9)
    assert np.linalg.norm(far) / np.linalg.norm(pull) == pytest.approx(np.exp(-mu * theta), rel=1e-6)
    # against the frictionless rope at the same contraction: the far end is pulled less
    free = solve_quadratic_internal(model, [CapstanRope(chain, 0.0)], [0.1])
    assert free.success and res.end_tension[0] < 0.8 * free.end_tension[0]


def test_fixture_nodes_move_rigidly_with_their_end_node(strip):
    mesh, bottom = strip
    muscle = Muscle(bottom)
    model = QuadraticModel(mesh, MAT, order=2)
    mid = mesh.n_nodes + np.arange(len(mesh.edges))
    groups = fixture_groups(mesh, [muscle], 0.45, mid)
    assert len(groups) == 2 and all((g >= mesh.n_nodes).any() for g in groups)  # midpoints inside too
    res = solve_quadratic_internal(model, [CapstanRope(quadratic_chain(mesh, bottom, mid), 0.3)], [0.25], groups)
    assert res.success, res.status
    X, x = model.points, res.x
    for g in groups:
        D0 = np.linalg.norm(X[g][:, None] - X[g][None], axis=2)
        D = np.linalg.norm(x[g][:, None] - x[g][None], axis=2)
        assert np.abs(D - D0).max() < 1e-10
    # the body outside the fixtures deforms
    rest = np.setdiff1d(np.arange(model.n_nodes), np.concatenate(groups))
    assert np.abs(np.linalg.norm(x[rest] - x[rest].mean(0), axis=1)
                  - np.linalg.norm(X[rest] - X[rest].mean(0), axis=1)).max() > 0.05


def test_turning_angles_and_reduction_by_hand():
    x = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    np.testing.assert_allclose(turning_angles(x, [0, 1, 2, 3]), [0.0, np.pi / 2, np.pi])
    np.testing.assert_allclose(CapstanRope([0, 1, 2, 3], 0.5).weights(x), np.exp(-0.5 * np.array([0, 1, 2]) * np.pi / 2))
    red = RigidReduction(x, [np.array([1, 2, 3])])
    q = red.rest_q()
    q[-1] = 0.3
    P = red.jacobian(q).toarray()
    h = 1e-7
    for k in range(red.n_q):
        dq = np.zeros(red.n_q)
        dq[k] = h
        np.testing.assert_allclose((red.x_of(q + dq) - red.x_of(q - dq)).ravel() / (2 * h), P[:, k], atol=1e-7)
    np.testing.assert_allclose(red.q_of(red.x_of(q)), q, atol=1e-14)


def test_bad_input_is_refused(strip):
    mesh, bottom = strip
    model = QuadraticModel(mesh, MAT, order=1)
    with pytest.raises(ValueError, match="at least two distinct nodes"):
        CapstanRope([3, 3])
    with pytest.raises(ValueError, match="mu"):
        CapstanRope(bottom, -0.1)
    with pytest.raises(ValueError, match="at least one CapstanRope"):
        solve_quadratic_internal(model, [], [])
    with pytest.raises(ValueError, match="one value in \\[0, 1\\) per rope"):
        solve_quadratic_internal(model, [CapstanRope(bottom)], [1.2])
    with pytest.raises(ValueError, match="not joined by a mesh edge"):
        quadratic_chain(mesh, [0, 2], mesh.n_nodes + np.arange(len(mesh.edges)))
    with pytest.raises(ValueError, match="overlaps"):
        RigidReduction(mesh.points, [np.array([0, 1]), np.array([1, 2])])


def test_a_solve_started_from_an_earlier_result_reaches_the_same_state(strip):
    mesh, bottom, mid, groups, model, ropes = _roped(strip)
    first = solve_quadratic_internal(model, ropes, [0.1], groups)
    cold = solve_quadratic_internal(model, ropes, [0.2], groups)
    warm = solve_quadratic_internal(model, ropes, [0.2], groups, start=first)
    assert first.success and cold.success and warm.success
    assert np.abs(warm.x - cold.x).max() < 1e-7 and warm.tension[0] == pytest.approx(cold.tension[0], rel=1e-7)
    with pytest.raises(ValueError, match="start must be"):
        solve_quadratic_internal(model, ropes, [0.2], [], start=first)


def test_load_steps_to_a_loose_tolerance_and_a_reused_ordering_reach_the_strict_state(strip, monkeypatch):
    """Intermediate load steps to quadsolve.INTERMEDIATE_TOL and LU factorisations in an order found once per
    solve (sparselu.ReusedOrdering) give the state of every step solved to 1e-9 with a fresh order each time."""
    import scipy.sparse.linalg as spla

    from mdsr_opt.mechanics import quadsolve, sparselu

    mesh, bottom, mid, groups, model, ropes = _roped(strip)
    fast = solve_quadratic_internal(model, ropes, [0.25], groups)
    orders = []
    real = spla.splu
    monkeypatch.setattr(sparselu.spla, "splu", lambda A, permc_spec=None, **k: orders.append(permc_spec)
                        or real(A, permc_spec=permc_spec, **k))
    fast_again = solve_quadratic_internal(model, ropes, [0.25], groups)
    assert "NATURAL" in orders and orders.count("MMD_AT_PLUS_A") < len(orders) / 2  # the order is reused
    monkeypatch.setattr(quadsolve, "INTERMEDIATE_TOL", 1e-9)
    monkeypatch.setattr(sparselu.ReusedOrdering, "factor", lambda self, J: real(
        J.tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.1, options={"SymmetricMode": True}).solve)
    strict = solve_quadratic_internal(model, ropes, [0.25], groups)
    assert fast.success and strict.success and fast.residual <= 1e-9
    assert np.abs(fast.x - fast_again.x).max() == 0.0
    assert np.abs(fast.x - strict.x).max() < 1e-7 * mesh.size
    assert fast.tension[0] == pytest.approx(strict.tension[0], rel=1e-6)


def test_a_solve_from_a_coarser_models_state_reaches_the_load_stepped_state(strip):
    """guess=: the linear-element equilibrium carried to the quadratic nodes starts one Newton solve at the
    full load; it reaches the load-stepped equilibrium in fewer iterations. A folded guess falls back to
    load steps; a guess of the wrong shape is refused."""
    from mdsr_opt.mechanics.quadratic import transfer_state

    mesh, bottom, mid, groups, model, ropes = _roped(strip)
    coarse = solve_quadratic_internal(QuadraticModel(mesh, MAT, order=1), [CapstanRope(bottom, 0.3)], [0.3],
                                      fixture_groups(mesh, [Muscle(bottom)], 0.3))
    stepped = solve_quadratic_internal(model, ropes, [0.3], groups)
    guessed = solve_quadratic_internal(model, ropes, [0.3], groups,
                                       guess=transfer_state(mesh, coarse.x, model.points))
    assert stepped.success and guessed.success and "predicted" in guessed.status and guessed.steps == 1
    assert guessed.iterations < stepped.iterations
    assert np.abs(guessed.x - stepped.x).max() < 1e-7 * mesh.size
    assert guessed.tension[0] == pytest.approx(stepped.tension[0], rel=1e-6)
    folded = model.points.copy()
    folded[:, 1] *= -1.0  # a mirror image: every element inverted
    back = solve_quadratic_internal(model, ropes, [0.3], groups, guess=folded)
    assert back.success and "predicted" not in back.status and np.abs(back.x - stepped.x).max() < 1e-7 * mesh.size
    with pytest.raises(ValueError, match="guess must be"):
        solve_quadratic_internal(model, ropes, [0.3], groups, guess=coarse.x)


def test_a_guess_whose_fixtures_fold_when_made_rigid_is_carried_into_the_body(strip):
    """A predicted state whose fixtures are squeezed (as a coarser model's anchor patch may be): made rigid,
    the fixtures push through the elements at their rim; the solve carries the fixtures' move into the body
    elastically and still starts from the prediction, reaching the load-stepped state."""
    mesh, bottom, mid, groups, model, ropes = _roped(strip)
    stepped = solve_quadratic_internal(model, ropes, [0.3], groups)
    guess = stepped.x.copy()
    for g in groups:  # every node near a fixture pulled a fifth of the way to its end node
        c = guess[g[0]]
        r = np.linalg.norm(model.points - model.points[g[0]], axis=1)
        w = np.clip((0.6 - r) / 0.3, 0.0, 1.0)[:, None]
        guess = guess + 0.2 * w * (c - guess)
    red = RigidReduction(model.points, groups)
    assert model.upright(guess) and not model.upright(red.x_of(red.q_of(guess)))  # rigid, it folds
    guessed = solve_quadratic_internal(model, ropes, [0.3], groups, guess=guess)
    assert stepped.success and guessed.success and "predicted" in guessed.status, guessed.status
    assert np.abs(guessed.x - stepped.x).max() < 1e-7 * mesh.size
    assert guessed.tension[0] == pytest.approx(stepped.tension[0], rel=1e-6)


def test_a_start_at_nearly_the_same_contractions_is_one_newton_solve(strip):
    """start= a result at contractions within START_FULL_STEP: one Newton solve at the full load from its
    state, the load-stepped state to the tolerance; farther away, load steps from it."""
    from mdsr_opt.mechanics.quadsolve import START_FULL_STEP

    mesh, bottom, mid, groups, model, ropes = _roped(strip)
    first = solve_quadratic_internal(model, ropes, [0.25], groups)
    a = 0.25 + 0.5 * START_FULL_STEP
    cold = solve_quadratic_internal(model, ropes, [a], groups)
    near = solve_quadratic_internal(model, ropes, [a], groups, start=first)
    assert cold.success and near.success and "start state" in near.status and near.steps == 1
    assert near.iterations < cold.iterations
    assert np.abs(near.x - cold.x).max() < 1e-7 * mesh.size
    far = solve_quadratic_internal(model, ropes, [0.25 + 2 * START_FULL_STEP], groups, start=first)
    assert far.success and "start state" not in far.status


def test_the_reduced_gradient_without_forming_the_jacobian_is_p_transpose_g():
    """quadsolve._pull_back (a line search's residual) is P^T g of RigidReduction.jacobian, to rounding."""
    from mdsr_opt.mechanics.quadsolve import _pull_back

    rng = np.random.default_rng(1)
    red = RigidReduction(rng.random((40, 2)), [np.array([3, 5, 7, 9]), np.array([10, 11, 12])])
    q = red.rest_q() + 0.1 * rng.standard_normal(red.n_q)
    g = rng.standard_normal(80)
    assert np.abs(_pull_back(red, q, g) - red.jacobian(q).T @ g).max() < 1e-13
    free = RigidReduction(rng.random((5, 2)))  # no fixture
    assert np.abs(_pull_back(free, free.rest_q(), g[:10]) - g[:10]).max() == 0.0


def test_a_newton_solve_that_creeps_stops_as_stalled():
    """dampednewton.damped_newton on a residual whose Newton matrix is 100 times too stiff (each step 1 % of
    the way): it stops as not converged after STALL_ITERATIONS * 2 iterations instead of running to max_iter; with
    the right matrix it converges at once."""
    import scipy.sparse as sp

    from mdsr_opt.mechanics.dampednewton import STALL_ITERATIONS, damped_newton

    A = sp.csr_matrix(np.diag([2.0, 3.0, 4.0]))
    b = np.array([1.0, 1.0, 1.0])
    for scale, converged, iterations in ((100.0, False, 2 * STALL_ITERATIONS), (1.0, True, 1)):
        z, ok, it, res = damped_newton(lambda z, jac, s=scale: (A @ z - b, s * A if jac else None), np.zeros(3),
                                       lambda z: True, 1e-9, 30)
        assert (ok, it) == (converged, iterations)


def test_a_newton_solve_whose_steps_the_line_search_keeps_cutting_stops_as_stalled():
    """dampednewton.damped_newton on a residual whose Newton step overshoots far (a soft mode swung along its
    tangent: here the matrix is 50 times too soft, so every step is cut to 1/64): it stops as not converged after
    SHORT_STEPS such steps instead of creeping for 2 * STALL_ITERATIONS; with the right matrix, at once."""
    import scipy.sparse as sp

    from mdsr_opt.mechanics.dampednewton import SHORT_STEP, SHORT_STEPS, STALL_ITERATIONS, damped_newton

    A = sp.csr_matrix(np.diag([2.0, 3.0, 4.0]))
    b = np.array([1.0, 1.0, 1.0])
    assert SHORT_STEP >= 1.0 / 64  # the line search's cut to 1/64 below counts as short
    z, ok, it, res = damped_newton(lambda z, jac: (A @ z - b, A / 50 if jac else None), np.zeros(3),
                                   lambda z: True, 1e-9, 30)
    assert not ok and it == SHORT_STEPS < 2 * STALL_ITERATIONS and 0 < res < 1.0
    z, ok, it, res = damped_newton(lambda z, jac: (A @ z - b, A if jac else None), np.zeros(3), lambda z: True,
                                   1e-9, 30)
    assert ok and it == 1


def test_a_shifted_newton_solve_crosses_a_soft_mode_that_newtons_step_overshoots():
    """dampednewton.damped_newton with ``shifted``: a soft coordinate (stiffness 1e-6 at the start, cubic
    hardening) whose Newton step overshoots a thousandfold, so that no cut of it is accepted, is crossed by the damped
    steps of the pseudo-transient shift, which fades with the residual: the root of the unchanged equations,
    to the tolerance."""
    import scipy.sparse as sp

    from mdsr_opt.mechanics.dampednewton import damped_newton

    def system(z, jac):
        r = np.array([1e-6 * z[0] + z[0] ** 3 - 1e-3, z[1] - 1.0, z[2] - 2.0])
        return r, (sp.csr_matrix(np.diag([1e-6 + 3 * z[0] ** 2, 1.0, 1.0])) if jac else None)

    z, ok, it, res = damped_newton(system, np.zeros(3), lambda z: True, 1e-12, 40)
    assert not ok and it == 0  # every cut of the first step refused
    z, ok, it, res = damped_newton(system, np.zeros(3), lambda z: True, 1e-12, 40, None, 3)
    assert ok and res <= 1e-12 and it <= 15
    assert 1e-6 * z[0] + z[0] ** 3 == pytest.approx(1e-3, abs=1e-12) and z[1:].tolist() == [1.0, 2.0]


def test_chord_steps_near_the_root_reach_it_with_fewer_factorisations():
    """dampednewton.damped_newton: once a full Newton step cuts the residual to CHORD_RATIO of what it was, the
    next steps reuse that step's factorisation while each cuts the residual as much; the root is the one of
    Newton's steps alone (CHORD_RATIO 0: a factorisation per step), to the tolerance, in fewer factorisations.
    A chord step that falls too slowly is dropped for a Newton step."""
    import scipy.sparse as sp

    from mdsr_opt.mechanics import dampednewton
    from mdsr_opt.mechanics.sparselu import ReusedOrdering

    class Counted(ReusedOrdering):
        def __init__(self):
            super().__init__()
            self.factored = 0

        def factor(self, J):
            self.factored += 1
            return super().factor(J)

    def system(z, jac):  # z_i**3 + z_i = c_i, coupled weakly: a root near (1.2, 1.5, 1.7)
        r = z ** 3 + z + 0.1 * np.roll(z, 1) - np.array([3.0, 5.0, 7.0])
        J = sp.csr_matrix(np.diag(3 * z ** 2 + 1) + 0.1 * np.roll(np.eye(3), 1, axis=1)) if jac else None
        return r, J

    runs = {}
    for ratio in (dampednewton.CHORD_RATIO, 0.0):
        order = Counted()
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(dampednewton, "CHORD_RATIO", ratio)
            z, ok, it, res = dampednewton.damped_newton(system, np.ones(3), lambda z: True, 1e-12, 40, order)
        assert ok and res <= 1e-12 and np.abs(system(z, False)[0]).max() <= 1e-12
        runs[ratio] = (z, it, order.factored)
    (zc, itc, fc), (zn, itn, fn) = runs[dampednewton.CHORD_RATIO], runs[0.0]
    assert np.abs(zc - zn).max() < 1e-11
    assert fn == itn and fc < itc and fc < fn  # Newton alone: one factorisation a step; chord steps: fewer


def test_a_quadratic_solve_with_chord_steps_reaches_the_state_of_newton_steps_alone(strip, monkeypatch):
    """solve_quadratic_internal with chord steps (dampednewton.CHORD_RATIO) and without them (0): the same
    equilibrium to the solver's tolerance, with fewer factorisations."""
    from mdsr_opt.mechanics import dampednewton, sparselu

    mesh, bottom, mid, groups, model, ropes = _roped(strip)
    counts = []
    real = sparselu.ReusedOrdering.factor

    def counted(self, J):
        counts[-1] += 1
        return real(self, J)

    monkeypatch.setattr(sparselu.ReusedOrdering, "factor", counted)
    out = {}
    for ratio in (dampednewton.CHORD_RATIO, 0.0):
        monkeypatch.setattr(dampednewton, "CHORD_RATIO", ratio)
        counts.append(0)
        out[ratio] = solve_quadratic_internal(model, ropes, [0.25], groups)
    chord, newton = out[dampednewton.CHORD_RATIO], out[0.0]
    assert chord.success and newton.success and chord.residual <= 1e-9 and newton.residual <= 1e-9
    assert np.abs(chord.x - newton.x).max() < 1e-7 * mesh.size
    assert chord.tension[0] == pytest.approx(newton.tension[0], rel=1e-6)
    assert counts[0] < counts[1]


@pytest.mark.parametrize("fmt", ["coo", "csr", "csc"])
def test_an_lu_solve_in_a_reused_order_gathers_the_same_matrix(fmt):
    """sparselu.ReusedOrdering: the second and later matrices of one pattern are reordered by a gather of their
    values (found once); the solutions equal those of a fresh factorisation, and a matrix of another pattern
    (an entry gone, one added) is still solved right."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    from mdsr_opt.mechanics.sparselu import ReusedOrdering

    rng = np.random.default_rng(3)
    n = 60
    base = sp.random(n, n, density=0.08, random_state=4, format="coo") + sp.eye(n) * 5.0
    base = sp.coo_matrix(base)
    order = ReusedOrdering()
    rhs = rng.standard_normal(n)
    for k in range(4):
        data = base.data * (1.0 + 0.1 * rng.standard_normal(base.nnz))
        J = sp.coo_matrix((data, (base.row, base.col)), shape=(n, n))
        if k == 3:  # another pattern: one entry dropped
            J = sp.coo_matrix((data[1:], (base.row[1:], base.col[1:])), shape=(n, n))
        J = J.asformat(fmt)
        x = order.solve(J, rhs)
        assert np.abs(x - spla.spsolve(sp.csc_matrix(J), rhs)).max() < 1e-10
        assert order.plan is None if k == 0 else order.plan is not None


def test_a_restriction_gathers_k_free_free_of_every_matrix_of_its_pattern_and_refuses_another():
    import scipy.sparse as sp

    from mdsr_opt.mechanics.sparselu import PatternRestriction

    model = QuadraticModel(Mesh.rectangle(2.0, 1.0, 3, 2), MAT)
    rng = np.random.default_rng(2)
    x = model.points + 0.01 * rng.standard_normal(model.points.shape)
    K0, K = model.evaluate(model.points)[2], model.evaluate(x)[2]
    free = np.sort(rng.choice(2 * model.n_nodes, 20, replace=False))
    cols = np.setdiff1d(np.arange(2 * model.n_nodes), free)
    for c in (free, cols):
        R = PatternRestriction(K0, free, c)
        assert abs(R(K) - K[free][:, c]).max() == 0.0
    with pytest.raises(ValueError, match="another pattern"):
        R(sp.csr_matrix(np.eye(2 * model.n_nodes)))
