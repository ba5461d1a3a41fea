"""Driving-quantity design (mdsr_opt.synthesis.contractions): recovery, bounds, reachability, numbering, verification, I/O."""

from __future__ import annotations

import copy
import json
import math
import time

import numpy as np
import pytest

from mdsr_opt import LinearElastic, Mesh, Muscle, NeoHookean, solve_internal
from mdsr_opt.mechanics.align import align, node_weights
from mdsr_opt.synthesis.results import METHODS, DesignResult
from mdsr_opt.synthesis.pipeline import PipelineResult, design_pipeline
from mdsr_opt.synthesis.problem import ForwardSolver, DesignProblem
from mdsr_opt.synthesis.rivals import _Outer
from mdsr_opt.synthesis.verify import check_minimum, verify_design
from mdsr_opt.synthesis.contractions import design_contractions

MAT = NeoHookean(E=1.0, nu=0.3)
NX, NY = 16, 4


def rotation_matrix(theta):
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s], [s, c]])


def _row(j, i0, i1):
    """Grid-line muscle along row j of the rectangle mesh, columns i0..i1."""
    return Muscle([j * (NX + 1) + i for i in range(i0, i1 + 1)])


@pytest.fixture(scope="module")
def mesh():
    return Mesh.rectangle(4.0, 1.0, NX, NY)


@pytest.fixture(scope="module")
def muscles():
    return [_row(0, 1, 8), _row(NY, 8, 15)]  # bottom-left and top-right: an S-bend


A_TRUE = np.array([0.2, 0.12])
THETA, SHIFT = 0.5, np.array([0.3, -1.0])


@pytest.fixture(scope="module")
def target(mesh, muscles):
    fwd = solve_internal(mesh, MAT, muscles, A_TRUE, muscle_model="cable")
    assert fwd.success
    return fwd.x @ rotation_matrix(THETA).T + SHIFT  # rotated and shifted: only the shape may matter


A_START = [0.05, 0.3]  # the cable's geometric guess is already the answer: start elsewhere


@pytest.mark.parametrize("method", METHODS)
def test_recovers_known_contractions_and_rigid_motion(mesh, muscles, target, method):
    res = design_contractions(mesh, MAT, muscles, target, method=method, initial_guess=A_START)
    assert res.success, res.status
    assert res.method == method and res.muscle_model == "cable"  # the default
    assert np.abs(res.contractions - A_TRUE).max() < (1e-6 if method == "flattened" else 1e-5)
    assert res.angle == pytest.approx(THETA, abs=1e-5)
    assert res.translation == pytest.approx(SHIFT, abs=1e-5)
    assert res.difference < 1e-5 * mesh.size
    assert np.abs(res.x_aligned - target).max() < 1e-4
    assert res.verification.passed and res.verification.gap < res.verification.gap_tol
    assert res.verification.positive_definite and np.isnan(res.verification.min_eigenvalue)  # not estimated by default
    assert res.n_forward >= 1 and res.time >= res.solve_time >= 0
    assert res.initial_difference > 1e3 * res.difference  # it did move from the initial guess


def test_cable_design_reports_commanded_achieved_stroke_and_tension(mesh, muscles, target):
    res = design_contractions(mesh, MAT, muscles, target, initial_guess=A_START)
    fwd = solve_internal(mesh, MAT, muscles, A_TRUE, muscle_model="cable")
    L0 = np.array([m.rest_length(mesh) for m in muscles])
    assert res.rest_lengths == pytest.approx(L0, rel=1e-14)
    assert np.array_equal(res.commanded, res.contractions)
    # the exact cable reaches what it is commanded, measured along the node chain of the returned state
    assert res.achieved == pytest.approx([1 - m.length(res.x) / m.rest_length(mesh) for m in muscles], abs=1e-14)
    assert np.abs(res.achieved - res.contractions).max() < 1e-8
    assert res.stroke == pytest.approx(res.achieved * L0, rel=1e-12)
    # the NLP's tension multipliers are the forward solve's rope tensions
    assert np.all(res.tension > 0) and not res.slack.any()
    assert res.tension == pytest.approx(fwd.tension, rel=1e-5)
    assert res.anchor_radius == pytest.approx(fwd.anchor_radius)
    s = res.summary()
    assert s["achieved"] == pytest.approx(list(res.achieved)) and s["stroke"] == pytest.approx(list(res.stroke))
    assert s["tension"] == pytest.approx(list(res.tension)) and s["slack"] == [False, False]
    assert "achieved" in res.muscle_table() and len(res.muscle_table().splitlines()) == 3


def test_springs_design_recovers_and_reports_the_lower_achieved_contraction(mesh, muscles):
    fwd = solve_internal(mesh, MAT, muscles, A_TRUE, muscle_model="springs")
    assert fwd.success
    y = fwd.x @ rotation_matrix(0.2).T + [1.0, 2.0]
    for method in ("flattened", "nested"):
        res = design_contractions(mesh, MAT, muscles, y, muscle_model="springs", method=method, initial_guess=A_START)
        assert res.success, res.status
        assert np.abs(res.contractions - A_TRUE).max() < 1e-5
        # springs stretch: the achieved contraction is less than the commanded one, as solve_internal says
        assert np.all(res.achieved < res.contractions - 1e-4)
        assert res.achieved == pytest.approx(fwd.achieved, abs=1e-6)
        assert res.tension == pytest.approx(fwd.tension, rel=1e-5)


def test_a_slack_rope_is_reported_at_zero_tension(mesh):
    # A along the bottom-left, B along the bottom from the same start to the right end; the target is
    # A's contraction alone, so B must stay slack: zero tension, contracted only as far as A bends it
    A, B = Muscle(range(1, 9)), Muscle(range(1, 16))
    fwd = solve_internal(mesh, MAT, [A], [0.2])
    y = fwd.x @ rotation_matrix(0.4).T
    b_len = 1 - B.length(fwd.x) / B.rest_length(mesh)
    for method in ("flattened", "nested"):
        res = design_contractions(mesh, MAT, [A, B], y, method=method, initial_guess=[0.1, 0.1])
        assert res.success, res.status
        assert res.contractions == pytest.approx([0.2, b_len], abs=1e-6)
        assert res.achieved == pytest.approx(res.contractions, abs=1e-9)
        assert list(res.slack) == [False, True]
        assert res.tension[0] == pytest.approx(fwd.tension[0], rel=1e-5) and abs(res.tension[1]) < 1e-8
    # the rest shape as target: nothing pulls
    res = design_contractions(mesh, MAT, [A, B], mesh.points, initial_guess=[0.2, 0.1])
    assert res.success and res.contractions == pytest.approx([0, 0], abs=1e-9) and res.slack.all()


@pytest.mark.parametrize("method", ["nested", pytest.param("derivative-free", marks=pytest.mark.slow)])  # 10 s
def test_every_method_reports_a_slack_rope_at_the_contraction_its_path_reached(mesh, method):
    # any contraction of B up to the one A's bend gives it leaves B slack with the same shape: the outer
    # searches stopped anywhere on that flat side (0.02, 0.05, 0.088 from different starts); one answer
    A, B = Muscle(range(1, 9)), Muscle(range(1, 16))
    fwd = solve_internal(mesh, MAT, [A], [0.2])
    b_len = 1 - B.length(fwd.x) / B.rest_length(mesh)
    res = design_contractions(mesh, MAT, [A, B], fwd.x, method=method, initial_guess=[0.15, 0.02])
    assert res.success, res.status
    assert list(res.slack) == [False, True]
    assert res.contractions[1] == pytest.approx(b_len, abs=1e-6)
    assert res.contractions[1] == pytest.approx(res.achieved[1], abs=1e-12)


def test_flattened_recovers_with_the_cable_model_and_from_rest(mesh, muscles):
    fwd = solve_internal(mesh, MAT, muscles, A_TRUE, muscle_model="cable")
    y = fwd.x @ rotation_matrix(-1.0).T + [5.0, 5.0]
    res = design_contractions(mesh, MAT, muscles, y, muscle_model="cable", warm_start=False, initial_guess=A_START)
    assert res.success, res.status
    assert np.abs(res.contractions - A_TRUE).max() < 1e-6
    assert res.angle == pytest.approx(-1.0, abs=1e-6)
    assert res.n_forward == 0  # no warm start: the NLP started from the rest shape


def test_flattened_gauss_newton_hessian_recovers(mesh, muscles, target):
    res = design_contractions(mesh, MAT, muscles, target, hessian="gauss-newton", initial_guess=A_START)
    assert res.success, res.status
    assert np.abs(res.contractions - A_TRUE).max() < 1e-6


@pytest.mark.parametrize("model_kind", ["cable", "springs"])
def test_nested_gradient_matches_finite_differences(mesh, muscles, target, model_kind):
    # the cable: the adjoint of the KKT system (ropes and anchor patches as constraints)
    prob = DesignProblem(mesh, MAT, muscles, target, node_weights(mesh), model_kind, 10.0, 0.6, anchor_radius=0.3)
    assert prob.block.n_rigid > 0 and prob.block.n_rope == (2 if model_kind == "cable" else 0)
    outer = _Outer(prob, ForwardSolver(prob, 1e-11, 200), clock=lambda: 0.0)
    a = np.array([0.1, 0.15])
    _J, g = outer.value_and_grad(a)
    eps = 1e-5
    fd = [(outer.value(a + eps * e) - outer.value(a - eps * e)) / (2 * eps) for e in np.eye(2)]
    assert np.abs(g).max() > 1e-3
    assert g == pytest.approx(fd, rel=1e-4, abs=1e-9)


@pytest.mark.parametrize("method", ["flattened", "nested", "derivative-free"])
def test_unreachable_target_is_success_with_positive_difference(mesh, muscles, method):
    stretched = mesh.points * [1.15, 1.0]  # muscles only contract: no contraction stretches the body
    res = design_contractions(mesh, MAT, muscles, stretched, method=method)
    assert res.success, res.status
    assert res.difference > 0.05
    assert np.all(res.contractions >= 0) and np.all(res.contractions <= res.a_max)
    # the reported difference is the difference of the reported state
    w = node_weights(mesh)
    assert res.difference == pytest.approx(align(res.x, stretched, w).difference, rel=1e-9)
    assert res.verification.passed


def test_bounds_hold_and_become_active(mesh, muscles):
    fwd = solve_internal(mesh, MAT, muscles, [0.35, 0.05], muscle_model="cable")
    for method in ("flattened", "nested"):
        res = design_contractions(mesh, MAT, muscles, fwd.x, method=method, a_max=0.25)
        assert res.success, res.status
        assert np.all(res.contractions >= 0.0) and np.all(res.contractions <= 0.25)
        assert res.contractions[0] == pytest.approx(0.25, abs=1e-6)  # wants 0.35, held at the bound
        assert res.difference > 1e-3


def test_results_do_not_depend_on_node_numbering(mesh, muscles, target):
    perm = np.random.default_rng(3).permutation(mesh.n_nodes)
    mesh2 = mesh.relabel(perm)
    muscles2 = [Muscle([int(perm[v]) for v in m.nodes]) for m in muscles]
    target2 = np.empty_like(target)
    target2[perm] = target
    for method in ("flattened", "nested"):
        r1 = design_contractions(mesh, MAT, muscles, target * [1.0, 1.05], method=method)  # not reachable exactly
        r2 = design_contractions(mesh2, MAT, muscles2, target2 * [1.0, 1.05], method=method)
        assert r1.success and r2.success
        assert r2.contractions == pytest.approx(r1.contractions, abs=1e-6)
        assert r2.difference == pytest.approx(r1.difference, rel=1e-6)
        assert np.abs(r2.x_aligned[perm] - r1.x_aligned).max() < 1e-6


def test_bad_input_gives_clear_errors(mesh, muscles, target):
    with pytest.raises(ValueError, match=r"target must have shape \(85, 2\)"):
        design_contractions(mesh, MAT, muscles, target[:-1])
    with pytest.raises(ValueError, match=r"target must have shape \(85, 2\)"):
        design_contractions(mesh, MAT, muscles, target.T)
    with pytest.raises(ValueError, match="NaN or inf"):
        design_contractions(mesh, MAT, muscles, np.full_like(target, np.nan))
    with pytest.raises(ValueError, match="leaves the mesh"):
        design_contractions(mesh, MAT, [Muscle([0, 2])], target)  # skips node 1
    with pytest.raises(ValueError, match="out of range"):
        design_contractions(mesh, MAT, [Muscle([84, 85])], target)
    for a_max in (1.0, 1.5, 0.0):
        with pytest.raises(ValueError, match=r"a_max must lie in \(0, 1\)"):
            design_contractions(mesh, MAT, muscles, target, a_max=a_max)
    with pytest.raises(ValueError, match="muscle list is empty"):
        design_contractions(mesh, MAT, [], target)
    with pytest.raises(ValueError, match="method must be one of"):
        design_contractions(mesh, MAT, muscles, target, method="newton")
    with pytest.raises(ValueError, match=r"initial contractions must lie in \[0, a_max"):
        design_contractions(mesh, MAT, muscles, target, initial_guess=[0.7, 0.1])
    with pytest.raises(ValueError, match=r"initial must have shape \(2\)"):
        design_contractions(mesh, MAT, muscles, target, initial_guess=[0.1])
    with pytest.raises(TypeError, match="mesh must be a mdsr_opt.Mesh"):
        design_contractions(mesh.points, MAT, muscles, target)
    with pytest.raises(TypeError, match="a_max must be a real number"):
        design_contractions(mesh, MAT, muscles, target, a_max="0.5")
    with pytest.raises(ValueError, match="anchor_radius"):
        design_contractions(mesh, MAT, muscles, target, anchor_radius=-0.1)
    with pytest.raises(ValueError, match="muscle_model must be 'springs' or 'cable'"):
        design_contractions(mesh, MAT, muscles, target, muscle_model="rope")
    with pytest.raises(ValueError, match="anchor_radius"):  # one muscle's two anchors joined
        design_contractions(mesh, MAT, muscles, target, anchor_radius=3.0)


def test_check_minimum_detects_a_saddle(mesh, muscles):
    small = Mesh.rectangle(2.0, 1.0, 4, 2)
    mus = [Muscle([0, 1, 2])]
    fwd = solve_internal(small, MAT, mus, [0.3], muscle_model="springs")
    pd, lam, res = check_minimum(small, MAT, mus, [0.3], fwd.x, muscle_model="springs")
    assert pd and lam > 0 and res < 1e-8
    squeezed = small.points * [0.5, 1.0]  # compressed across: the Neo-Hookean Hessian is indefinite
    pd, lam, _res = check_minimum(small, MAT, mus, [0.0], squeezed, muscle_model="springs")
    assert not pd
    # the smallest eigenvalue of the free-coordinate Hessian, checked densely
    from mdsr_opt.mechanics.equilibrium import gauge_coordinates
    from mdsr_opt.mechanics.model import get_model
    from mdsr_opt.mechanics.constraints import segment_spring_parameters

    model = get_model(small, MAT)
    p = model.params(MAT, springs=segment_spring_parameters(small, MAT, mus, [0.0], 10.0))
    free = np.ones(2 * small.n_nodes, dtype=bool)
    free[list(gauge_coordinates(small))] = False
    H = model.hessian(squeezed.reshape(-1), p).toarray()[np.ix_(free, free)]
    assert lam == pytest.approx(np.linalg.eigvalsh(H)[0], rel=1e-8)
    assert lam < 0


def test_verification_rejects_wrong_states(mesh, muscles, target):
    res = design_contractions(mesh, MAT, muscles, target, verify=False)
    assert res.verification is None and res.success
    good = verify_design(mesh, MAT, muscles, res, target)
    assert good.passed and good.message == "" and np.isnan(good.min_eigenvalue)  # inertia only by default
    est = verify_design(mesh, MAT, muscles, res, target, lowest=True)  # the eigenvalue estimate on request
    _pd, lam, _r = check_minimum(mesh, MAT, muscles, res.contractions, res.x)
    assert est.passed and est.min_eigenvalue > 0 and est.min_eigenvalue == pytest.approx(lam, rel=1e-6)
    pd2, lam2, _r2 = check_minimum(mesh, MAT, muscles, res.contractions, res.x, lowest=False)
    assert pd2 and np.isnan(lam2)
    shifted = DesignResult.from_dict(res.to_dict())
    shifted.x = res.x + 1e-3 * np.sin(7 * res.x[:, ::-1])  # not the equilibrium at these contractions
    v = verify_design(mesh, MAT, muscles, shifted, target)
    assert not v.passed and v.gap > v.gap_tol
    assert "exceeds" in v.message
    saddle = DesignResult.from_dict(res.to_dict())
    saddle.x = mesh.points * [0.5, 1.0]
    v = verify_design(mesh, MAT, muscles, saddle, target)
    assert not v.passed and not v.positive_definite and v.min_eigenvalue < 0
    assert "not a minimum" in v.message


def test_the_verification_from_rest_takes_the_predictor_when_the_rest_shape_fails(monkeypatch, mesh, muscles,
                                                                                 target):
    from mdsr_opt.synthesis import verify

    res = design_contractions(mesh, MAT, muscles, target, verify=False)
    starts, real = [], verify.solve_internal

    def rest_fails(*a, **kw):  # as if the solve from the rest shape had failed
        starts.append(kw["initial_guess"])
        out = real(*a, **kw)
        if kw["initial_guess"] == "rest":
            out.success, out.status = False, "load stepping stalled (test)"
        return out

    monkeypatch.setattr(verify, "solve_internal", rest_fails)
    v = verify_design(mesh, MAT, muscles, res, target)
    assert starts == ["rest", "predictor"] and v.passed and v.forward_start == "rest, predictor"
    alone = real(mesh, MAT, muscles, res.contractions, muscle_model=res.muscle_model, tol=1e-10,
                 anchor_radius=res.anchor_radius)
    assert v.forward_iterations > alone.iterations  # both solves counted
    saved = DesignResult.from_dict(json.loads(json.dumps(dict(res.to_dict(), verification=v.to_dict()))))
    assert saved.verification.forward_start == "rest, predictor"
    assert saved.verification.forward_iterations == v.forward_iterations


def test_verification_from_the_design_checks_a_converged_state_where_it_stands(mesh, muscles, target):
    """A design state within tol is what the forward solve from it returns: verified there (residual, the
    reduced Hessian's inertia, the boundary) with no solver iteration; a state that is not an equilibrium
    still goes through the forward solve, which moves away from it (a gap) and fails the check."""
    res = design_contractions(mesh, MAT, muscles, target, verify=False)
    v = verify_design(mesh, MAT, muscles, res, target, start="design")
    assert v.passed and v.forward_success and v.positive_definite
    assert v.forward_iterations == 0 and "stops there" in v.forward_status
    assert v.gap < 1e-12 * mesh.size and v.residual <= 1e-10
    pd, _lam, r = check_minimum(mesh, MAT, muscles, res.contractions, res.x, tol=1e-10, lowest=False)
    assert pd is True and r == pytest.approx(v.residual, abs=1e-12)  # the independent check agrees
    # the same design with its state moved off the equilibrium (1e-4 of the size): the solver path
    bent = copy.deepcopy(res)
    rng = np.random.default_rng(3)
    bent.x = res.x + 1e-4 * mesh.size * rng.uniform(-1.0, 1.0, res.x.shape)
    vb = verify_design(mesh, MAT, muscles, bent, target, start="design")
    assert not vb.passed and vb.forward_iterations > 0 and "stops there" not in vb.forward_status
    assert vb.gap > vb.gap_tol and "gap" in vb.message and "not an equilibrium" in vb.message


def test_verification_starts_from_the_design_or_from_rest(mesh, muscles, target):
    from mdsr_opt.mechanics.equilibrium import gauge_coordinates
    from mdsr_opt.mechanics.equilibrium import in_gauge_frame

    res = design_contractions(mesh, MAT, muscles, target, verify=False)
    v_design = verify_design(mesh, MAT, muscles, res, target, start="design")
    v_rest = verify_design(mesh, MAT, muscles, res, target)  # the default: contracted from rest
    assert v_design.passed and v_rest.passed
    assert v_design.gap < 1e-9 * mesh.size and v_rest.gap < 1e-7 * mesh.size
    assert v_design.forward_difference == pytest.approx(v_rest.forward_difference, abs=1e-8 * mesh.size)
    assert (v_design.forward_start, v_rest.forward_start) == ("design", "rest")
    assert 0 <= v_design.forward_iterations < v_rest.forward_iterations
    with pytest.raises(ValueError, match="start must be"):
        verify_design(mesh, MAT, muscles, res, target, start="target")
    # the design's state in any pose is moved rigidly into the solver's gauge frame
    moved = res.x @ rotation_matrix(2.5).T + [4.0, -3.0]
    g = in_gauge_frame(mesh, moved)
    gauge = list(gauge_coordinates(mesh))
    assert np.abs(g.reshape(-1)[gauge] - mesh.points.reshape(-1)[gauge]).max() < 1e-12
    assert align(g, moved).difference < 1e-12  # congruent
    assert in_gauge_frame(mesh, mesh.points * [-1.0, 1.0]) is None  # a reflection inverts every element
    for bad in (np.vstack([moved, moved[:1]]), moved.reshape(-1)):  # one node too many; flattened
        with pytest.raises(ValueError, match=r"x must have shape"):
            in_gauge_frame(mesh, bad)
    # a state that cannot start a solve is verified from rest: a saddle guess still fails, from rest
    folded = DesignResult.from_dict(res.to_dict())
    folded.x = res.x.copy()
    k = NY // 2 * (NX + 1) + NX // 2  # an interior node pushed through its neighbours
    folded.x[k] += [0.0, 0.6]
    assert mesh.jacobians(folded.x).min() < 0 and in_gauge_frame(mesh, folded.x) is None
    v = verify_design(mesh, MAT, muscles, folded, target, start="design")
    assert v.forward_success and not v.passed and v.gap > v.gap_tol and not v.positive_definite
    assert "inverts an element" in v.message


def test_failed_optimiser_is_not_success(mesh, muscles, target):
    res = design_contractions(mesh, MAT, muscles, target, method="derivative-free", max_iter=5)
    assert not res.success
    assert "Maximum number" in res.status
    res = design_contractions(mesh, MAT, muscles, target, max_iter=1, initial_guess=A_START)
    assert not res.success
    assert "Maximum_Iterations_Exceeded" in res.status
    # (from the geometric guess, here the answer, one iteration suffices: the start is the solution)
    assert design_contractions(mesh, MAT, muscles, target, max_iter=1).success


def test_result_round_trips_through_json(mesh, muscles, target):
    res = design_contractions(mesh, MAT, muscles, target, method="nested", initial_guess=A_START)
    res.initial_difference = float("nan")  # JSON has no NaN: written as null
    text = json.dumps(res.to_dict(), allow_nan=False)
    back = DesignResult.from_dict(json.loads(text))
    assert np.array_equal(back.contractions, res.contractions)
    assert np.array_equal(back.x, res.x) and np.array_equal(back.rotation, res.rotation)
    assert back.verification == res.verification
    assert math.isnan(back.initial_difference)
    assert back.summary()["contractions"] == res.summary()["contractions"]
    for k in ("achieved", "stroke", "tension", "rest_lengths"):
        assert np.array_equal(getattr(back, k), getattr(res, k)) and len(getattr(res, k)) == 2
    assert np.array_equal(back.slack, res.slack) and back.slack.dtype == bool
    assert back.anchor_radius == res.anchor_radius and back.muscle_model == "cable"


def test_pipeline_designs_saves_and_reloads(tmp_path):
    mesh = Mesh.rectangle(4.0, 1.0, NX, NY)
    left = [i for i, (x, y) in enumerate(mesh.points) if x == 0.0]
    right = {i: (x - 0.3, y - 0.5) for i, (x, y) in enumerate(mesh.points) if x == 4.0}
    out = design_pipeline(mesh, MAT, left, right, routing_options={"max_muscles": 2})
    assert out.success, out.design.status
    assert out.design.muscle_model == "cable"  # the pipeline's default too
    assert 1 <= len(out.muscles) <= 2 and out.routing is not None
    assert out.design.difference < 0.05 * mesh.size
    assert out.design.verification.passed
    assert set(out.times) == {"external", "routing", "design", "total"}
    path = out.save(tmp_path / "result")
    assert (tmp_path / "result" / "target.vtu").exists() and (tmp_path / "result" / "driven.vtu").exists()
    back = PipelineResult.load(tmp_path / "result")
    assert np.allclose(back.target, out.target, atol=1e-12)
    assert np.array_equal(back.contractions, out.contractions)
    assert back.muscles == out.muscles
    assert back.material == MAT
    assert np.array_equal(back.anchors, np.asarray(left))
    assert back.design.difference == out.design.difference
    # the reloaded pieces are consistent: the stored state and alignment reproduce the stored difference
    w = node_weights(back.mesh)
    assert align(back.design.x, back.target, w).difference == pytest.approx(back.design.difference, rel=1e-9)
    assert json.load(open(path))["format"] == "mdsr_opt.design/1"
    with pytest.raises(FileNotFoundError, match="no design.json"):
        PipelineResult.load(tmp_path)


def test_pipeline_target_by_newton_agrees_with_ipopt():
    """Without a backend the pipeline solves its target with Newton: the same stable equilibrium as IPOPT's
    to the tolerance contract; a backend given in external_options is used as given."""
    from mdsr_opt import solve_external
    mesh = Mesh.rectangle(4.0, 1.0, NX, NY)
    left = [i for i, (x, y) in enumerate(mesh.points) if x == 0.0]
    right = {i: (x - 0.3, y - 0.5) for i, (x, y) in enumerate(mesh.points) if x == 4.0}
    mus = [_row(0, 1, 8), _row(NY, 8, 15)]
    out = design_pipeline(mesh, MAT, left, right, muscles=mus, verify=False)
    ref = solve_external(mesh, MAT, left, right)  # solve_external's default: IPOPT
    assert out.external.backend == "newton" and ref.backend == "ipopt"
    assert out.external.success and out.external.stable and out.external.residual <= 1e-8
    assert np.abs(out.target - ref.x).max() < 1e-6 * mesh.size
    given = design_pipeline(mesh, MAT, left, right, muscles=mus, verify=False, external_options={"backend": "ipopt"})
    assert given.external.backend == "ipopt"
    assert np.abs(given.design.contractions - out.design.contractions).max() < 1e-5


def test_pipeline_rejects_a_target_without_contraction():
    mesh = Mesh.rectangle(4.0, 1.0, 8, 2)
    left = [i for i, (x, y) in enumerate(mesh.points) if x == 0.0]
    pull = {i: (x + 0.4, y) for i, (x, y) in enumerate(mesh.points) if x == 4.0}  # stretches only
    with pytest.warns(UserWarning), pytest.raises(ValueError, match="routing found no muscle"):
        design_pipeline(mesh, MAT, left, pull)


# ---------------------------------------------------------------------------------------------- assembled derivatives
# (model, anchor radius): radius 0 has point ends and overlapping muscles (rows of B with two nonzeros for the
# springs); radius 0.5 has rigid end patches, two of them merged across muscles
CASES = [("springs", 0.0), ("cable", 0.0), ("springs", 0.5), ("cable", 0.5)]


def _nlp_point(model_kind, radius, seed=1, material=MAT):
    """A small flattened NLP (both derivative paths) and a random point, parameters and multipliers (with
    the linear elastic material, the pinned pose's rotation and translation too)."""
    from mdsr_opt.synthesis import nlp as D

    mesh = Mesh.rectangle(4.0, 1.0, 8, 2)
    if radius == 0:  # the second muscle shares edges 2-3 and 3-4 with the first
        mus = [Muscle([0, 1, 2, 3, 4]), Muscle([2, 3, 4, 5, 6]), Muscle([2 * 9 + i for i in range(3, 8)])]
    else:
        mus = [Muscle([0, 1, 2, 3]), Muscle([5, 6, 7, 8]), Muscle([2 * 9 + i for i in range(4, 8)])]
    rng = np.random.default_rng(seed)
    y = mesh.points @ rotation_matrix(0.3).T + 0.05 * rng.standard_normal(mesh.points.shape)
    prob = DesignProblem(mesh, material, mus, y, node_weights(mesh), model_kind, 10.0, 0.6, anchor_radius=radius)
    blk = prob.block
    assert blk.n_rope == (3 if model_kind == "cable" else 0) and (blk.n_rigid > 0) == (radius > 0)
    assert prob.free_pose == (material.kind == "neo-hookean") and prob.nv == (0 if prob.free_pose else 3)
    n = mesh.n_nodes
    z = np.concatenate([mesh.points.reshape(-1) + 0.03 * rng.standard_normal(2 * n), [0.1, 0.2, 0.15],
                        [0.3, 0.1, -0.2][:prob.nv], rng.standard_normal(blk.nc)])
    par = np.concatenate([y.reshape(-1), node_weights(mesh), prob.p0, [0.7, 1.3]])
    lam = rng.standard_normal(int(prob.free.sum()) + blk.nc)
    return D, prob, z, par, lam


@pytest.mark.parametrize("material", [MAT, LinearElastic(1.0, 0.3)], ids=["free-pose", "pinned-pose"])
@pytest.mark.parametrize("model_kind,radius", CASES)
@pytest.mark.parametrize("hessian", ["exact", "gauss-newton"])
def test_assembled_derivatives_match_casadi(model_kind, radius, hessian, material):
    import casadi as ca

    D, prob, z, par, lam = _nlp_point(model_kind, radius, material=material)
    nlp, fa = D._assembled_nlp(prob, hessian)
    snlp, extra = D._symbolic_nlp(prob, hessian)
    zs, ps = snlp["x"], snlp["p"]
    lf, ls = ca.SX.sym("lam_f"), ca.SX.sym("lam_g", len(lam))
    ref = ca.Function("ref", [zs, ps], [snlp["f"], ca.gradient(snlp["f"], zs), snlp["g"], ca.jacobian(snlp["g"], zs)])
    f_s, gf_s, g_s, J_s = (np.array(ca.DM(v)) for v in ref(z, par))
    if hessian == "exact":
        lag = lf * snlp["f"] + ca.dot(ls, snlp["g"])
        H_s = np.array(ca.DM(ca.Function("H", [zs, ps, lf, ls], [ca.hessian(lag, zs)[0]])(z, par, 0.8, lam)))
    else:  # the SX path's own Gauss-Newton Hessian (upper triangle)
        H_s = np.array(ca.DM(extra["hess_lag"](z, par, 0.8, lam)))
        H_s = np.triu(H_s) + np.triu(H_s, 1).T
    f_a, gf_a = (np.array(ca.DM(v)) for v in fa["grad_f"](z, par))
    g_a, J_a = (np.array(ca.DM(v)) for v in fa["jac_g"](z, par))
    g_nlp = np.array(ca.DM(ca.Function("g", [nlp["x"], nlp["p"]], [nlp["g"]])(z, par)))
    H = fa["hess_lag"](z, par, 0.8, lam)
    Hu = np.array(ca.DM(H))
    assert np.all(np.tril(Hu, -1) == 0)  # the upper triangle only
    H_a = np.triu(Hu) + np.triu(Hu, 1).T

    def rel(u, v):
        return np.abs(u - v).max() / np.abs(v).max()

    assert rel(f_a, f_s) < 1e-13 and rel(gf_a, gf_s) < 1e-13
    assert rel(g_a, g_s) < 1e-13 and rel(g_nlp, g_s) < 1e-13
    assert rel(J_a, J_s) < 1e-13
    n2 = 2 * prob.mesh.n_nodes
    nf = int(prob.free.sum())
    assert (np.abs(J_s[:, n2:n2 + 3]).max(axis=0) >= 1.0).all()  # every a-column is exercised
    if model_kind == "cable":  # a enters the rope rows only, with coefficient 1
        assert np.abs(J_s[:nf, n2:n2 + 3]).max() == 0 and np.all(J_s[nf:nf + 3, n2:n2 + 3] == np.eye(3))
    nc = prob.block.nc
    if nc:  # every multiplier column of the stationarity rows is exercised
        ik = n2 + 3 + prob.nv
        assert (np.abs(J_s[:nf, ik:]).max(axis=0) > 0).all() and J_s.shape[1] == ik + nc
    assert rel(H_a, H_s) < 1e-13
    if hessian == "exact":
        if model_kind == "springs":
            assert (np.abs(H_s[:n2, n2:n2 + 3]).max(axis=0) > 1e-2).all()  # every x-a column is exercised
        if nc:  # x-kappa: the ropes' and the nonlinear (scale) rigid rows' curvature
            cols = np.abs(H_s[:n2, n2 + 3 + prob.nv:]).max(axis=0) > 0
            assert cols[:prob.block.n_rope].all() and cols.sum() >= prob.block.n_rope + len(prob.constraints.groups)
    assert np.all(H_a[n2:n2 + 3, n2:n2 + 3] == 0)  # constraints affine in a
    assert np.all(H_a[n2 + 3 + prob.nv:, n2 + 3 + prob.nv:] == 0)  # and in the multipliers


@pytest.mark.parametrize("material", [MAT, LinearElastic(1.0, 0.3)], ids=["free-pose", "pinned-pose"])
@pytest.mark.parametrize("model_kind,radius", CASES)
@pytest.mark.parametrize("hessian", ["exact", "gauss-newton"])
def test_numeric_nlp_matches_casadi(model_kind, radius, hessian, material):
    """The numpy callbacks of the NLP against CasADi's own derivatives of the SX NLP, at a random point with
    random multipliers (end patches and point ends; springs shared by two muscles; the free pose of the
    Neo-Hookean body and the pinned pose, with rotation and translation, of the linear elastic one)."""
    import casadi as ca
    from mdsr_opt.synthesis.nlp_numeric import numeric_nlp, supports

    D, prob, z, par, lam = _nlp_point(model_kind, radius, material=material)
    assert supports(prob)
    nlp, fn, _keep = numeric_nlp(prob, hessian)
    snlp, extra = D._symbolic_nlp(prob, hessian)
    zs, ps = snlp["x"], snlp["p"]
    ref = ca.Function("ref", [zs, ps], [snlp["f"], ca.gradient(snlp["f"], zs), snlp["g"], ca.jacobian(snlp["g"], zs)])
    f_s, gf_s, g_s, J_s = (np.array(ca.DM(v)) for v in ref(z, par))
    lf, ls = ca.SX.sym("lam_f"), ca.SX.sym("lam_g", len(lam))
    if hessian == "exact":
        lag = lf * snlp["f"] + ca.dot(ls, snlp["g"])
        H_s = np.array(ca.DM(ca.Function("H", [zs, ps, lf, ls], [ca.hessian(lag, zs)[0]])(z, par, 0.8, lam)))
    else:
        H_s = np.array(ca.DM(extra["hess_lag"](z, par, 0.8, lam)))
        H_s = np.triu(H_s) + np.triu(H_s, 1).T
    f_n, gf_n = (np.array(ca.DM(v)) for v in fn["grad_f"](z, par))
    g_n, J_n = (np.array(ca.DM(v)) for v in fn["jac_g"](z, par))
    f_nlp, g_nlp = (np.array(ca.DM(ca.Function("fg", [nlp["x"], nlp["p"]], [nlp[k]])(z, par))) for k in "fg")
    Hu = np.array(ca.DM(fn["hess_lag"](z, par, 0.8, lam)))
    assert np.all(np.tril(Hu, -1) == 0)  # the upper triangle only
    H_n = np.triu(Hu) + np.triu(Hu, 1).T

    def rel(u, v):
        return np.abs(u - v).max() / np.abs(v).max()

    assert rel(f_n, f_s) < 1e-13 and rel(f_nlp, f_s) < 1e-13 and rel(gf_n, gf_s) < 1e-13
    assert rel(g_n, g_s) < 1e-13 and rel(g_nlp, g_s) < 1e-13
    assert rel(J_n, J_s) < 1e-13
    assert rel(H_n, H_s) < 1e-12
    n2, nc, ik = 2 * prob.mesh.n_nodes, prob.block.nc, 2 * prob.mesh.n_nodes + 3 + prob.nv
    if hessian == "exact":  # the x-kappa block: every rope's and every group's scale row's curvature
        curved = np.abs(H_n[:n2, ik:]).max(axis=0) > 0
        assert curved.sum() == prob.block.n_rope + (len(prob.constraints.groups) if radius else 0)
        if model_kind == "springs":  # and the springs' x-a block
            assert (np.abs(H_n[:n2, n2:n2 + 3]).max(axis=0) > 1e-2).all()
    if not prob.free_pose:  # the rotation couples to every node
        assert (np.abs(H_n[:n2:2, n2 + 3]) > 0).all()
    assert J_n.shape == (int(prob.free.sum()) + nc, ik + nc)


def _two_rows(nx=16, ny=4):
    mesh = Mesh.rectangle(4.0, 1.0, nx, ny)
    h = nx // 2
    return mesh, [Muscle([j * (nx + 1) + i for i in range(i0, i1 + 1)]) for j, i0, i1 in ((0, 1, h), (ny, h, nx - 1))]


@pytest.mark.parametrize("derivatives", ["numeric", "casadi"])
def test_linear_elastic_design_recovers_its_contractions(derivatives):
    """The linear elastic energy changes under rotation, so its NLP pins the pose and aligns with an explicit
    rotation (a free pose found a state in another pose, off equilibrium: a = [0.183, 0.131] here)."""
    mesh, mus = _two_rows()
    mat = LinearElastic(1.0, 0.3)
    fwd = solve_internal(mesh, mat, mus, [0.2, 0.12])
    target = fwd.x @ rotation_matrix(2.0).T + [5.0, 3.0]
    for verify in (False, True):
        res = design_contractions(mesh, mat, mus, target, initial_guess=[0.05, 0.3], derivatives=derivatives,
                                  verify=verify)
        assert res.success, res.status
        assert res.contractions == pytest.approx([0.2, 0.12], abs=1e-6)
        assert res.difference < 1e-6


@pytest.mark.parametrize("model_kind", ["cable", "springs"])
def test_free_pose_design_at_the_gauges_degenerate_pose(model_kind):
    """A target turned so that the gauge nodes' line is perpendicular to node j's gauge coordinate: had the
    state followed the target there, the NLP's left-out rows would not follow from the others (a false
    equilibrium held by forces on the gauge nodes passed as a success with a = [0.2042, 0.1192])."""
    from mdsr_opt.mechanics.equilibrium import gauge_coordinates

    mesh, mus = _two_rows()
    a_true = [0.2, 0.12]
    fwd = solve_internal(mesh, MAT, mus, a_true, muscle_model=model_kind)
    gi, _gi1, gj = gauge_coordinates(mesh)
    d = fwd.x[gj // 2] - fwd.x[gi // 2]
    comp = gj % 2  # node j's gauge coordinate; the degenerate pose turns i-j perpendicular to it
    phi = (np.pi / 2 if comp == 1 else 0.0) - np.arctan2(d[1], d[0])
    for off in np.radians([-0.3, 0.0, 1.0]):
        target = fwd.x @ rotation_matrix(phi + off).T + [0.3, -1.0]
        res = design_contractions(mesh, MAT, mus, target, initial_guess=[0.05, 0.3], muscle_model=model_kind,
                                  verify=False)
        assert res.success, res.status
        assert res.contractions == pytest.approx(a_true, abs=1e-5 if model_kind == "springs" else 1e-7)


def test_design_solvers_are_evicted_safely():
    """More option sets than the per-mesh solver cache keeps: the oldest solvers and their callbacks go, and
    a design with the first options again (rebuilt) gives the same answer as the first time."""
    from mdsr_opt.synthesis.nlp import DESIGN_SOLVERS_KEPT

    mesh, mus = _two_rows(8, 2)
    target = solve_internal(mesh, MAT, mus, [0.2, 0.1]).x
    first = design_contractions(mesh, MAT, mus, target, verify=False, options={"max_iter": 100})
    for k in range(DESIGN_SOLVERS_KEPT + 2):
        r = design_contractions(mesh, MAT, mus, target, verify=False, options={"max_iter": 101 + k})
        assert r.success and r.contractions == pytest.approx(first.contractions, abs=1e-12)
    again = design_contractions(mesh, MAT, mus, target, verify=False, options={"max_iter": 100})
    assert again.success and np.array_equal(again.contractions, first.contractions)
    assert again.build_time > 0  # rebuilt: the first solver was evicted


def test_the_numeric_jacobian_kept_from_the_last_call_is_that_of_the_point_asked():
    """The numeric NLP keeps its last Jacobian (IPOPT asks twice at its start): a call at another point, or
    with other parameters, is evaluated anew, and a call at the same point returns the same values."""
    import casadi as ca

    from mdsr_opt.synthesis.nlp_numeric import numeric_nlp

    D, prob, z, par, _lam = _nlp_point("cable", CASES[0][1])
    _nlp, fn, _keep = numeric_nlp(prob, "exact")
    snlp, _extra = D._symbolic_nlp(prob, "exact")
    ref = ca.Function("J", [snlp["x"], snlp["p"]], [ca.jacobian(snlp["g"], snlp["x"])])

    def jac(zz, pp):
        return np.array(ca.DM(fn["jac_g"](zz, pp)[1]))

    z2 = z + 1e-3 * np.cos(np.arange(len(z)))
    par2 = par.copy()
    par2[-1] *= 1.5  # the constraints' scale
    for zz, pp in ((z, par), (z, par), (z2, par), (z2, par2), (z, par)):
        J_ref = np.array(ca.DM(ref(zz, pp)))
        assert np.abs(jac(zz, pp) - J_ref).max() <= 1e-13 * np.abs(J_ref).max()


def test_numeric_nlp_refuses_a_symbolic_energy():
    from mdsr_opt.mechanics.model import get_model
    from mdsr_opt.synthesis.nlp_numeric import numeric_nlp, supports

    _D, prob, _z, _par, _lam = _nlp_point("cable", 0.5)
    prob.model = get_model(prob.mesh, MAT, cables=[[0, 1, 2]])  # a sliding cable: no numpy energy
    assert not supports(prob)
    with pytest.raises(ValueError, match="needs a numeric energy"):
        numeric_nlp(prob, "exact")


@pytest.mark.parametrize("model_kind,radius", CASES)
def test_assembled_derivatives_match_finite_differences(model_kind, radius):
    import casadi as ca

    D, prob, z, par, lam = _nlp_point(model_kind, radius, seed=4)
    nlp, fa = D._assembled_nlp(prob, "exact")
    lf, h = 0.8, 1e-6

    def f_and_g(zz):
        f, gf = fa["grad_f"](zz, par)
        g, J = fa["jac_g"](zz, par)
        return float(f), np.array(gf).ravel(), np.array(g).ravel(), np.array(ca.DM(J))

    _f, gf, _g, J = f_and_g(z)
    Hu = np.array(ca.DM(fa["hess_lag"](z, par, lf, lam)))
    H = np.triu(Hu) + np.triu(Hu, 1).T
    E = np.eye(len(z))
    fd_gf, fd_J, fd_H = [], [], []
    for e in E:
        fp, gfp, gp, Jp = f_and_g(z + h * e)
        fm, gfm, gm, Jm = f_and_g(z - h * e)
        fd_gf.append((fp - fm) / (2 * h))
        fd_J.append((gp - gm) / (2 * h))
        fd_H.append((lf * (gfp - gfm) + (Jp - Jm).T @ lam) / (2 * h))  # d/dz of grad_z L
    fd_gf, fd_J, fd_H = np.array(fd_gf), np.array(fd_J).T, np.array(fd_H).T
    assert np.abs(gf - fd_gf).max() < 1e-7 * np.abs(gf).max()
    assert np.abs(J - fd_J).max() < 1e-7 * np.abs(J).max()
    assert np.abs(H - fd_H).max() < 1e-6 * np.abs(H).max()
    assert np.abs(H - H.T).max() == 0


@pytest.mark.parametrize("model_kind", ["cable", "springs"])
def test_all_derivative_paths_give_the_same_design(mesh, muscles, target, model_kind):
    kw = {"muscle_model": model_kind, "initial_guess": A_START, "anchor_radius": 0.3, "verify": False}  # end patches
    rn = design_contractions(mesh, MAT, muscles, target, derivatives="numeric", **kw)
    ra = design_contractions(mesh, MAT, muscles, target, derivatives="assembled", **kw)
    rc = design_contractions(mesh, MAT, muscles, target, derivatives="casadi", **kw)
    assert rn.success and ra.success and rc.success, (rn.status, ra.status, rc.status)
    assert ra.difference < 0.05
    for r in (rn, ra):
        assert r.contractions == pytest.approx(rc.contractions, abs=1e-9)
        assert r.iterations == rc.iterations
    with pytest.raises(ValueError, match="derivatives must be 'numeric', 'assembled' or 'casadi'"):
        design_contractions(mesh, MAT, muscles, target, derivatives="symbolic")


# ---------------------------------------------------------------------------------------------- refinement
def _bend_stroke(ny: int) -> float:
    """Stroke of one cable along the top of a 4 x 1 strip (``4 ny x ny`` cells) designed for a 90-degree arc."""
    from conftest import arc_map

    nx = 4 * ny
    mesh = Mesh.rectangle(4.0, 1.0, nx, ny)
    top = Muscle([ny * (nx + 1) + i for i in range(nx + 1)])
    assert np.allclose(mesh.points[list(top.nodes), 1], 1.0)
    res = design_contractions(mesh, MAT, [top], arc_map(mesh.points), verify=False)  # default anchor size
    assert res.success, res.status
    assert res.stroke[0] == pytest.approx(res.contractions[0] * 4.0, rel=1e-7)  # the cable reaches its command
    return float(res.stroke[0])


def _assert_converging(strokes):
    changes = np.abs(np.diff(strokes))
    assert np.all(changes[1:] < changes[:-1]), strokes  # each refinement changes the stroke less
    assert abs(strokes[-1] - strokes[-2]) < 0.03 * strokes[-1], strokes  # the two finest agree to 3 %


def test_design_strokes_converge_under_refinement_coarse():
    # 85, 297 and 1105 nodes (measured: 1.459, 1.350, 1.375)
    _assert_converging([_bend_stroke(ny) for ny in (4, 8, 16)])


@pytest.mark.slow
def test_design_strokes_converge_under_refinement():
    # 297, 1105 and 4257 nodes, the meshes (measured: 1.350, 1.375, 1.352); with point ends the
    # strokes grew without bound (0.920, 0.975, 1.035, 1.080 with the old springs)
    _assert_converging([_bend_stroke(ny) for ny in (8, 16, 32)])


def test_scene_table_prints_achieved_contractions_and_strokes():
    from mdsr_opt.scenes.runner import CaseReport
    from mdsr_opt.scenes.scenereport import SceneReport

    c = CaseReport(scene="s", case="c", kind="internal", n_nodes=10, n_muscles=2, success=True,
                   contractions=[0.3, 0.2], achieved=[0.25, 0.2], stroke=[0.5, 0.125], difference=0.01,
                   relative_difference=0.001)
    table = SceneReport(scene="s", title="t", n_nodes=10, cases=[c]).table()
    head, _sep, row = table.splitlines()
    assert "achieved contractions" in head and "strokes" in head
    assert "0.250, 0.200" in row and "0.5, 0.125" in row and "0.300" not in row  # achieved, not commanded
    # lengths carry their unit in every cell: the scene's, else body units (as the figures say)
    assert "| 0.5, 0.125 body units |" in row and "| 0.01 body units |" in row
    row = SceneReport(scene="s", title="t", n_nodes=10, cases=[c], units="cm").table().splitlines()[2]
    assert "| 0.5, 0.125 cm |" in row and "| 0.01 cm |" in row


def test_design_figure_title_states_the_contractions_reached():
    """design.png never claims a contraction that was not reached: with the penalty springs the muscle
    reaches less than commanded, and the title shows the commanded value beside the reached one."""
    import matplotlib

    matplotlib.use("Agg")
    from mdsr_opt.plot.design import plot_design

    mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    mus = [Muscle(range(1, 16))]
    target = solve_internal(mesh, MAT, mus, [0.2]).x
    res = design_contractions(mesh, MAT, mus, target, muscle_model="springs", verify=False)
    assert abs(res.achieved[0] - res.contractions[0]) > 5e-4  # springs: reached differs from commanded
    title = plot_design(mesh, res, target, mus).axes[0].get_title()
    assert f"commanded \u2192 achieved: M1 {res.contractions[0]:.3f} \u2192 {res.achieved[0]:.3f}" in title
    assert f"difference D = {res.difference:.3g} body units" in title


# ------------------------------------------------------------------------------ warm start from the target
def test_the_warm_start_from_the_target_reaches_the_design_of_the_rest_start(mesh, muscles, target):
    from_target = design_contractions(mesh, MAT, muscles, target)
    from_rest = design_contractions(mesh, MAT, muscles, target, warm_start="rest")
    assert from_target.success and from_rest.success
    np.testing.assert_allclose(from_target.contractions, from_rest.contractions, atol=1e-9)
    assert from_target.verification.passed and from_target.verification.gap < 1e-8
    # a reachable target is the equilibrium at the geometric guess: one solve of a few iterations from it,
    # against load steps from rest
    assert from_target.inner_iterations < from_rest.inner_iterations
    with pytest.raises(ValueError, match="warm_start must be"):
        design_contractions(mesh, MAT, muscles, target, warm_start="target-ish")


def test_the_forward_solver_starts_from_rest_when_the_given_shape_cannot_start_it(mesh, muscles, target):
    prob = DesignProblem(mesh, MAT, muscles, target, node_weights(mesh), "cable", 10.0, 0.6)
    fwd = ForwardSolver(prob, 1e-10, 200)
    folded = target.copy()
    folded[[0, 1]] = folded[[1, 0]]  # two corner nodes swapped: an inverted element
    x, ok, _ = fwd.solve(A_TRUE, start=folded)
    assert ok and fwd.started_from == "rest"
    ref = solve_internal(mesh, MAT, muscles, A_TRUE, align_to_rest=False, tol=1e-10)
    assert np.abs(x - ref.x.reshape(-1)).max() < 1e-8
    fwd2 = ForwardSolver(prob, 1e-10, 200)
    x2, ok2, _ = fwd2.solve(A_TRUE, start=target)
    assert ok2 and fwd2.started_from == "target"
    assert np.abs(align(x2.reshape(-1, 2), ref.x).apply(x2.reshape(-1, 2)) - ref.x).max() < 1e-8


def test_a_design_warm_started_from_the_target_that_fails_is_repeated_from_rest(monkeypatch, mesh, muscles, target):
    from mdsr_opt.synthesis import contractions
    from mdsr_opt.synthesis.results import Verification

    calls, verify = [], contractions.verify_design

    def first_fails(*args, **kw):  # as if the forward re-solve from rest had reached another state
        v = verify(*args, **kw)
        calls.append(v)
        if len(calls) == 1:
            v = Verification(**{**v.__dict__, "passed": False, "message": "gap 0.3 between ..."})
        return v

    monkeypatch.setattr(contractions, "verify_design", first_fails)
    designs, design = [], contractions._design

    def counted(*a, **k):  # each design's counters as it returned them
        out = design(*a, **k)
        designs.append((out[0].iterations, out[0].n_forward, out[0].inner_iterations, out[0].time))
        return out

    monkeypatch.setattr(contractions, "_design", counted)
    t0 = time.perf_counter()
    res = design_contractions(mesh, MAT, muscles, target)
    wall = time.perf_counter() - t0
    assert len(calls) == 2 and res.success and res.verification.passed
    assert "warm-started from rest after the design warm-started from the target failed" in res.status
    np.testing.assert_allclose(res.contractions, A_TRUE, atol=1e-7)
    # the counters and the clock cover both designs
    first, second = designs
    assert (res.iterations, res.n_forward, res.inner_iterations) == tuple(np.add(first[:3], second[:3]))
    assert first[3] < res.time <= wall
    # an optimiser that stops short (no verification failure) is not repeated from rest (named: the default's
    # failure would be made again by the nested method, synthesis.fallback)
    designs.clear()
    short = design_contractions(mesh, MAT, muscles, target, max_iter=1, initial_guess=A_START, method="flattened")
    assert not short.success and len(designs) == 1


def test_warm_start_takes_numpy_booleans_and_refuses_numbers(mesh, muscles, target):
    assert design_contractions(mesh, MAT, muscles, target, warm_start=np.True_, verify=False).success
    with pytest.raises(ValueError, match="warm_start must be True, False, 'target', 'rest' or an \\(n, 2\\) array of "
                                         "node positions, got 1"):
        design_contractions(mesh, MAT, muscles, target, warm_start=1)


def test_a_design_warm_started_from_a_given_shape_is_the_design_from_the_target(mesh, muscles, target):
    target = target * [1.05, 0.97]  # out of reach: the warm start's solve from the target has work to do
    ref = design_contractions(mesh, MAT, muscles, target)
    # an earlier design's state (in another pose: only the shape counts) starts the forward solve there
    moved = ref.x @ np.array([[0.0, -1.0], [1.0, 0.0]]).T + [3.0, -2.0]
    again = design_contractions(mesh, MAT, muscles, target, warm_start=moved, initial_guess=ref.contractions)
    assert again.success and again.verification.passed
    np.testing.assert_allclose(again.contractions, ref.contractions, atol=1e-7)
    assert abs(again.difference - ref.difference) < 1e-9 * mesh.size and ref.difference > 1e-3 * mesh.size
    # started at the equilibrium itself: the warm start's solve has (next to) nothing to do
    assert again.inner_iterations <= 2 < ref.inner_iterations
    with pytest.raises(ValueError, match=rf"warm_start must have shape \({mesh.n_nodes}, 2\)"):
        design_contractions(mesh, MAT, muscles, target, warm_start=ref.x[:-1])
    with pytest.raises(ValueError, match="warm_start"):
        design_contractions(mesh, MAT, muscles, target, warm_start=np.full_like(ref.x, np.nan))


def test_the_verification_takes_the_forward_check_only_for_the_same_state(monkeypatch, mesh, muscles, target):
    from mdsr_opt.synthesis import verify as verify_mod

    res = design_contractions(mesh, MAT, muscles, target, verify=False)
    checks, stability = [], verify_mod._stability
    monkeypatch.setattr(verify_mod, "_stability", lambda *a, **k: checks.append(1) or stability(*a, **k))
    v = verify_design(mesh, MAT, muscles, res, target)
    # the forward re-solve lands on the design's state: its own check answers, the residual is the state's
    assert v.passed and v.gap <= verify_mod.SAME_STATE_RTOL * mesh.size and not checks
    pd, _lam, residual = check_minimum(mesh, MAT, muscles, res.contractions, res.x)
    assert v.positive_definite == pd and v.residual == pytest.approx(residual, rel=1e-6, abs=1e-15)
    # a state off by more than that is checked itself
    off = DesignResult(**{**res.__dict__, "x": res.x + 1e-6 * mesh.size * np.sin(np.arange(res.x.size)).reshape(-1, 2)})
    v2 = verify_design(mesh, MAT, muscles, off, target)
    assert checks and v2.gap > verify_mod.SAME_STATE_RTOL * mesh.size and v2.residual > 10 * v.residual


def test_a_long_outer_loop_design_says_how_far_it_got(mesh, muscles, target, monkeypatch, caplog):
    """A derivative-free design (the only one that takes contact, each forward solve seconds long) printed
    nothing for minutes; it now logs its forward solves and best difference every PROGRESS_SECONDS."""
    import logging

    import mdsr_opt.synthesis.rivals as rivals

    monkeypatch.setattr(rivals, "PROGRESS_SECONDS", 0.0)
    with caplog.at_level(logging.INFO, logger="mdsr_opt.synthesis.rivals"):
        res = design_contractions(mesh, MAT, muscles, target, method="derivative-free", max_iter=5)
    said = [r.getMessage() for r in caplog.records if r.name == "mdsr_opt.synthesis.rivals"]
    assert len(said) >= 5 and all(m.startswith("design: ") and "forward solve(s)" in m for m in said)
    assert said[-1].startswith(f"design: {len(said)} forward solve(s)")
    assert float(said[-1].split("best difference so far ")[1].split()[0]) >= res.difference - 1e-12
