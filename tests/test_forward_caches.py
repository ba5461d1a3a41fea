"""What the forward (internal-driving) solves keep between calls, and that a kept answer answers only its
own question (the rest state's linearisation and KKT factorisation, the last multipliers); the constraint
Jacobian handed to IPOPT."""

import numpy as np
import pytest

from mdsr_opt import Mesh, Muscle, NeoHookean, solve_internal
from mdsr_opt.mechanics import constrained as constrained_mod
from mdsr_opt.mechanics.constrained import ConstrainedModel
from mdsr_opt.mechanics.constraints import muscle_constraints
from mdsr_opt.mechanics.equilibrium import gauge_coordinates
from mdsr_opt.mechanics.model import get_model

MAT = NeoHookean(E=1.0, nu=0.3)


def bottom_and_top(mesh):
    P = mesh.points
    rows = []
    for y in (0.0, 1.0):
        rows.append(Muscle([int(i) for i in np.argsort(P[:, 0], kind="stable") if abs(P[i, 1] - y) < 1e-9]))
    return rows


@pytest.fixture
def setup(monkeypatch):
    mesh = Mesh.rectangle(4.0, 1.0, 24, 6)
    mus = bottom_and_top(mesh)
    cm = ConstrainedModel(get_model(mesh, MAT), muscle_constraints(mesh, mus, None), ropes=True)
    fixed = np.zeros(2 * mesh.n_nodes, dtype=bool)
    fixed[list(gauge_coordinates(mesh))] = True
    calls = []
    real = constrained_mod.kkt_factor

    def counting(H, J, order=None, *args, **kw):
        calls.append(H.shape)
        return real(H, J, order, *args, **kw)

    monkeypatch.setattr(constrained_mod, "kkt_factor", counting)
    return mesh, mus, cm, fixed, calls


def targets(cm, a):
    return (1.0 - np.asarray(a)) * cm.constraints.rest_lengths


def test_predictions_from_rest_share_one_factorisation_and_equal_fresh_ones(setup):
    mesh, mus, cm, fixed, calls = setup
    pe = cm.model.params(MAT)
    X = mesh.points.reshape(-1).copy()
    a1, a2 = [0.1, 0.05], [0.07, 0.12]
    y1 = cm.predict(cm.params(pe, targets(cm, a1)), X, fixed, X[fixed])
    # a prediction from another state replaces the last linearisation; the rest one stays
    y_mid = cm.predict(cm.params(pe, targets(cm, a1)), y1, fixed, X[fixed])
    n_before = len(calls)
    y2 = cm.predict(cm.params(pe, targets(cm, a2)), X.copy(), fixed, X[fixed])
    assert len(calls) == n_before  # the rest factorisation answered
    assert y_mid is not None and not np.array_equal(y_mid, y1)
    fresh = ConstrainedModel(cm.model, cm.constraints, ropes=True)
    for a, y in ((a1, y1), (a2, y2)):
        assert np.array_equal(fresh.predict(fresh.params(pe, targets(fresh, a)), X, fixed, X[fixed]), y)


def test_the_rest_factorisation_is_not_used_for_another_state_parameters_or_fixed_set(setup):
    mesh, mus, cm, fixed, calls = setup
    pe = cm.model.params(MAT)
    X = mesh.points.reshape(-1).copy()
    p = cm.params(pe, targets(cm, [0.1, 0.05]))
    cm.predict(p, X, fixed, X[fixed])
    assert len(calls) == 1
    # a state a rounding error away from rest is another state
    Y = X.copy()
    Y[7] += 1e-12
    cm.predict(p, Y, fixed, Y[fixed])
    assert len(calls) == 2
    # other energy parameters (a stiffer material) at rest: another linearisation
    pe2 = cm.model.params(NeoHookean(E=2.0, nu=0.3))
    y_stiff = cm.predict(cm.params(pe2, targets(cm, [0.1, 0.05])), X, fixed, X[fixed])
    assert len(calls) == 3
    # the first one is still there, answering for its own key only
    y = cm.predict(p, X, fixed, X[fixed])
    assert len(calls) == 3
    # other fixed coordinates at rest: another linearisation
    fixed2 = fixed.copy()
    fixed2[np.flatnonzero(~fixed)[5]] = True
    cm.predict(p, X, fixed2, X[fixed2])
    assert len(calls) == 4
    fresh = ConstrainedModel(cm.model, cm.constraints, ropes=True)
    assert np.array_equal(fresh.predict(p, X, fixed, X[fixed]), y)
    assert np.array_equal(fresh.predict(cm.params(pe2, targets(cm, [0.1, 0.05])), X, fixed, X[fixed]), y_stiff)


def test_a_second_solve_from_rest_factors_the_rest_state_once_and_finds_the_same_state(setup):
    mesh, mus, cm, fixed, calls = setup
    first = solve_internal(mesh, MAT, mus, [0.2, 0.1])
    n_first = len(calls)
    again = solve_internal(mesh, MAT, mus, [0.15, 0.12])
    n_again = len(calls) - n_first
    assert first.success and again.success
    # the second solve's first prediction is at rest: one factorisation fewer than the first solve
    # needed for the same number of load steps
    assert len(again.steps) == len(first.steps)
    assert n_again == n_first - 1
    other = Mesh.rectangle(4.0, 1.0, 24, 6)  # nothing cached on it
    ref = solve_internal(other, MAT, bottom_and_top(other), [0.15, 0.12])
    assert np.array_equal(ref.x, again.x) and ref.energy == again.energy


def test_the_kept_multipliers_answer_only_their_own_state_targets_and_fixed_set(setup):
    mesh, mus, cm, fixed, calls = setup
    res = solve_internal(mesh, MAT, mus, [0.2, 0.1], align_to_rest=False)
    x = res.x.reshape(-1)
    pe = cm.model.params(MAT)
    cases = [(x, targets(cm, [0.2, 0.1]), fixed), (x, targets(cm, [0.2, 0.1]), fixed),  # asked twice
             (x, targets(cm, [0.1, 0.1]), fixed),  # other targets: the bottom rope is then slack
             (x + 1e-4 * np.sin(np.arange(x.size)), targets(cm, [0.2, 0.1]), fixed),  # another state
             (x, targets(cm, [0.2, 0.1]), np.roll(fixed, 4))]  # another fixed set
    for xi, t, fx in cases:
        lam, taut = cm.multipliers(xi, cm.params(pe, t), fx)
        ref_lam, ref_taut = ConstrainedModel(cm.model, cm.constraints, ropes=True).multipliers(xi, cm.params(pe, t), fx)
        assert np.array_equal(lam, ref_lam) and np.array_equal(taut, ref_taut)
        lam[:] = 1e9  # the caller's copy: the kept answer is unchanged
        taut[:] = False
    lam, taut = cm.multipliers(x, cm.params(pe, targets(cm, [0.2, 0.1])), fixed)
    assert np.all(taut) and np.all(lam[:2] > 0) and np.all(np.abs(lam) < 1e9)


@pytest.mark.parametrize("ropes", [True, False])
def test_the_nlp_jacobian_given_to_ipopt_is_that_of_the_nlp_constraints(ropes):
    import casadi as ca

    mesh = Mesh.rectangle(4.0, 1.0, 24, 6)
    # patches of a few nodes at each muscle end: rigid rows besides the ropes
    cm = ConstrainedModel(get_model(mesh, MAT), muscle_constraints(mesh, bottom_and_top(mesh), 0.35), ropes=ropes)
    assert cm.n_targets == (2 if ropes else 0) and cm.n_rows > cm.n_targets
    x = ca.MX.sym("x", cm.n_dof)
    mine = ca.Function("mine", [x], [cm.nlp_jacobian_expr(x)])
    ad = ca.Function("ad", [x], [ca.jacobian(cm.nlp_constraints_expr(x), x)])
    rng = np.random.default_rng(3)
    X = mesh.points.reshape(-1)
    for y in (X, X + 0.05 * rng.standard_normal(X.size)):
        J1, J2 = mine(y), ad(y)
        assert J1.shape == (cm.n_rows, cm.n_dof) == J2.shape
        assert np.abs(np.asarray(J1.full()) - np.asarray(J2.full())).max() <= 1e-14
        # and the numeric Jacobian, scaled as the NLP sees the rows
        ref = (cm.jacobian(y).toarray() * cm.row_scale[:, None])
        assert np.abs(np.asarray(J1.full()) - ref).max() <= 1e-12 * np.abs(ref).max()
