"""Exact cable muscles, rigid anchor patches and mesh-independent dummy springs (issue 10)."""

import numpy as np
import pytest

from mdsr_opt import Mesh, Muscle, NeoHookean, solve_internal
from mdsr_opt.mechanics.anchors import anchor_patches, body_size, default_anchor_radius, rigid_groups
from mdsr_opt.mechanics.constraints import MuscleConstraints, segment_spring_parameters

MAT = NeoHookean(E=1.0, nu=0.3)


def row(mesh, y, x0=-np.inf, x1=np.inf):
    """The muscle along the mesh row at height ``y`` (between x0 and x1), left to right."""
    P = mesh.points
    sel = [int(i) for i in np.argsort(P[:, 0], kind="stable") if abs(P[i, 1] - y) < 1e-9 and x0 <= P[i, 0] <= x1]
    return Muscle(sel)


def pairwise(x, nodes):
    d = x[nodes][:, None, :] - x[nodes][None, :, :]
    return np.sqrt((d ** 2).sum(-1))


# ------------------------------------------------------------------------------ exact cable
@pytest.mark.parametrize("cells", [(20, 4), (60, 16), (128, 32)],  # ~2 s for the 4257 nodes
                         ids=["105-nodes", "1037-nodes", "4257-nodes"])
def test_exact_cable_reaches_the_commanded_contraction_on_every_mesh(cells):
    mesh = Mesh.rectangle(4.0, 1.0, *cells)
    mus = [row(mesh, 0.0), row(mesh, 0.5)]
    a = np.array([0.3, 0.1])
    res = solve_internal(mesh, MAT, mus, a)
    assert res.success, res.status
    assert res.muscle_model == "cable"  # the default
    L = np.array([m.length(res.x) for m in mus])
    L0 = np.array([m.rest_length(mesh) for m in mus])
    assert np.abs((1 - L / L0) - a).max() < 1e-6
    assert np.abs(res.achieved - a).max() < 1e-6
    assert np.allclose(res.commanded, a) and np.allclose(res.rest_lengths, L0)
    assert np.allclose(res.stroke, res.achieved * L0)
    assert np.all(res.tension > 0) and not res.slack.any()
    assert res.residual < 1e-6  # the Lagrangian gradient: a KKT point, not a penalised one


def test_tension_is_the_derivative_of_the_energy_with_respect_to_the_stroke():
    # envelope theorem: dE*/d(target length) = -tau, i.e. dE*/da = tau * L0 — an independent check of the
    # multiplier read off as the rope's tension
    mesh = Mesh.rectangle(4.0, 1.0, 32, 8)
    mus = [row(mesh, 0.0)]
    d = 1e-4
    e_lo, e_hi = (solve_internal(mesh, MAT, mus, [0.3 + s]).energy for s in (-d, d))
    res = solve_internal(mesh, MAT, mus, [0.3])
    assert (e_hi - e_lo) / (2 * d) == pytest.approx(res.tension[0] * res.rest_lengths[0], rel=1e-5)


def test_a_rope_that_would_have_to_push_goes_slack():
    mesh = Mesh.rectangle(4.0, 1.0, 32, 8)
    # the bottom rope bends the strip; the rope a quarter up is shortened by the bend more than its own 5 %
    res = solve_internal(mesh, MAT, [row(mesh, 0.0), row(mesh, 0.25)], [0.3, 0.05])
    assert res.success, res.status
    assert res.achieved[0] == pytest.approx(0.3, abs=1e-6) and res.tension[0] > 0
    assert list(res.slack) == [False, True]
    assert res.tension[1] == 0.0  # never compressive
    assert res.achieved[1] > 0.05 + 1e-3  # its path is shorter than the rope: it hangs loose
    assert res.residual < 1e-6


@pytest.mark.parametrize("ropes, a", [([(0.0,), (0.0, 1.0, 3.0)], [0.3, 0.05]),
                                      ([(0.0, 0.5, 4.0), (0.25, 0.0, 3.5)], [0.35, 0.15])],
                         ids=["along-the-first", "above-the-first"])
def test_a_rope_the_predictor_leaves_slack_skips_the_equality_solve(monkeypatch, ropes, a):
    from mdsr_opt.mechanics import ropesolve

    mesh = Mesh.rectangle(4.0, 1.0, 32, 8)
    # the second rope runs along the middle of the first (the predictor's step is taken) or a quarter up
    # (the step is not: it lengthens the first rope), contracted less: the first's pull leaves it slack
    mus = [row(mesh, *r) for r in ropes]
    res = solve_internal(mesh, MAT, mus, a)
    assert res.success and list(res.slack) == [False, True] and res.tension[1] == 0.0
    # the taut rope is never longer than its target in the inequality form (IPOPT's default bound
    # relaxation left it 7.7e-9 L0 too long here)
    assert 0.0 <= res.achieved[0] - a[0] < 1e-8
    # the predictor left the second rope slack: the inequality form, which decided it, was the only one solved
    forms, hinted = [], ropesolve.rope_forms
    monkeypatch.setattr(ropesolve, "rope_forms", lambda cm, p, x0: forms.append(hinted(cm, p, x0)) or (True, False))
    both = solve_internal(mesh, MAT, mus, a)  # the equality form first, as before
    assert both.success and forms == [(False, True)]
    np.testing.assert_allclose(res.x, both.x, atol=1e-9)  # the same start and form: the same equilibrium
    assert res.iterations < both.iterations
    # a warm start with the second rope released (shorter than its new target) is no prediction: equality first
    forms.clear()
    again = solve_internal(mesh, MAT, mus, [a[0], 0.02], initial_guess=res.x)
    assert again.success and forms == [(True, False)]


@pytest.mark.parametrize("a_next", [[0.35, 0.05, 0.0], [0.25, 0.05, 0.0]], ids=["further", "back"])
def test_a_warm_start_releases_the_ropes_slack_in_its_state_first(monkeypatch, a_next):
    """The next frame of an animation, started from the last one's state: the ropes slack there (a rope a
    quarter up and one an eighth up at contraction 0, both shortened by the bend) are released and the
    others held, one solve (the equality form first has a rope push, then the inequality form, together
    costlier than the default start): the same equilibrium as without the guess and as from the default
    start, in fewer IPOPT iterations than either."""
    from mdsr_opt.mechanics import ropesolve

    mesh = Mesh.rectangle(4.0, 1.0, 32, 8)
    mus = [row(mesh, 0.0), row(mesh, 0.25, 1.0, 3.0), row(mesh, 0.125, 0.5, 3.5)]
    first = solve_internal(mesh, MAT, mus, [0.3, 0.05, 0.0])
    assert first.success and list(first.slack) == [False, True, True]
    guessed = solve_internal(mesh, MAT, mus, a_next, initial_guess=first.x)
    cold = solve_internal(mesh, MAT, mus, a_next)
    monkeypatch.setattr(ropesolve, "_warm_active_set", lambda *args: None)
    forms = solve_internal(mesh, MAT, mus, a_next, initial_guess=first.x)
    for res in (guessed, cold, forms):
        assert res.success and list(res.slack) == [False, True, True] and res.tension[1:].tolist() == [0.0, 0.0]
    assert guessed.iterations < min(forms.iterations, cold.iterations) // 2
    assert np.abs(guessed.x - forms.x).max() < 1e-7 and np.abs(guessed.x - cold.x).max() < 1e-7


def test_a_warm_start_whose_released_rope_pulls_again_solves_the_forms():
    """A rope slack in the start's state but taut in the new frame (its target shortened past its path): the
    guess that releases it ends with it longer than its target and is not taken; the rope forms give the
    equilibrium the default start reaches."""
    mesh = Mesh.rectangle(4.0, 1.0, 32, 8)
    mus = [row(mesh, 0.0), row(mesh, 0.25, 1.0, 3.0)]
    first = solve_internal(mesh, MAT, mus, [0.3, 0.05])
    assert first.success and list(first.slack) == [False, True]
    res = solve_internal(mesh, MAT, mus, [0.3, 0.25], initial_guess=first.x)
    cold = solve_internal(mesh, MAT, mus, [0.3, 0.25])
    assert res.success and cold.success and not res.slack.any() and np.all(res.tension > 0)
    np.testing.assert_allclose(res.achieved, [0.3, 0.25], atol=1e-7)
    assert np.abs(res.x - cold.x).max() < 1e-7


def test_a_start_far_from_equilibrium_makes_no_guess_of_slack_ropes(monkeypatch):
    """Inside ``projected_energy_hessian`` (the design's warm start from its target shape, no equilibrium)
    the start's multipliers are no sign of slack ropes: no guess is solved, the rope forms are. Outside, the
    same start (an earlier equilibrium) has its slack ropes released first. Both reach the same state."""
    from mdsr_opt.mechanics import ropesolve
    from mdsr_opt.mechanics.ropesolve import projected_energy_hessian

    mesh = Mesh.rectangle(4.0, 1.0, 32, 8)
    mus = [row(mesh, 0.0), row(mesh, 0.25, 1.0, 3.0), row(mesh, 0.125, 0.5, 3.5)]
    first = solve_internal(mesh, MAT, mus, [0.3, 0.05, 0.0])
    guesses, original = [], ropesolve._warm_active_set
    monkeypatch.setattr(ropesolve, "_warm_active_set", lambda *args: guesses.append(original(*args)) or guesses[-1])
    kw = dict(initial_guess=first.x, min_step=1.0, check_stability=False, align_to_rest=False)
    plain = solve_internal(mesh, MAT, mus, [0.35, 0.05, 0.0], **kw)
    assert len(guesses) == 1 and guesses[0] is not None  # the guess was solved and taken
    guesses.clear()
    with projected_energy_hessian():
        far = solve_internal(mesh, MAT, mus, [0.35, 0.05, 0.0], **kw)
    assert len(guesses) == 1 and guesses[0] is None
    assert plain.success and far.success and list(far.slack) == [False, True, True]
    assert np.abs(np.asarray(far.x) - np.asarray(plain.x)).max() < 1e-6 * mesh.size


def test_a_rope_predicted_slack_that_ends_at_its_length_is_met_exactly(monkeypatch):
    from mdsr_opt.mechanics import ropesolve

    mesh = Mesh.rectangle(4.0, 1.0, 24, 6)
    P = mesh.points
    mus = [Muscle(sorted(np.flatnonzero(np.isclose(P[:, 1], y)), key=lambda i: P[i, 0])[1:-1]) for y in (0.0, 0.5)]
    from mdsr_opt.mechanics.constrained import ConstrainedModel

    forms, hinted = [], ropesolve.rope_forms
    monkeypatch.setattr(ropesolve, "rope_forms", lambda cm, p, x0: forms.append(hinted(cm, p, x0)) or forms[-1])
    calls, solver = [], ConstrainedModel.solver

    class Recording:  # each solve's start and answer
        def __init__(self, s):
            self.s = s

        def __call__(self, **kw):
            out = self.s(**kw)
            calls.append((np.asarray(kw["x0"], dtype=float).ravel(), np.asarray(out["x"]).ravel()))
            return out

        def stats(self):
            return self.s.stats()

    monkeypatch.setattr(ConstrainedModel, "solver", lambda self, b, o, f: (lambda r: (Recording(r[0]), r[1]))(solver(self, b, o, f)))
    res = solve_internal(mesh, MAT, mus, [0.4, 0.05])
    # the predictor took the second rope for slack, but it ends at its length with a small tension: the
    # inequality form left it 9e-7 L0 short (undecided); the equality form, started from that answer, meets it
    assert forms[0] == (False, True) and len(calls) == 2
    np.testing.assert_array_equal(calls[1][0], calls[0][1])
    assert res.success, res.status
    assert not res.slack.any() and 0.0 < res.tension[1] < 0.05 * res.tension[0]
    np.testing.assert_allclose(res.achieved, [0.4, 0.05], atol=1e-9)
    assert res.residual < 1e-8


def grid_ropes(nx, ny, m):
    """``m`` ropes along grid rows of a ``nx x ny`` rectangle: halves of the bottom and top rows, then of
    two inner rows (the layout of bench_design.py)."""
    def rope(j, i0, i1):
        return Muscle([j * (nx + 1) + i for i in range(i0, i1 + 1)])

    h, j1, j2 = nx // 2, ny // 3, (2 * ny) // 3
    return [rope(0, 1, h), rope(ny, h, nx - 1), rope(0, h, nx - 1), rope(ny, 1, h), rope(j1, 2, h - 1),
            rope(j2, h + 1, nx - 2), rope(j1, h + 1, nx - 2), rope(j2, 2, h - 1)][:m]


@pytest.mark.parametrize("ny, m, seed", [(4, 8, 1), (4, 8, 2), (4, 6, 5), (6, 6, 25)])
def test_ropes_an_inequality_answer_leaves_undecided_are_settled(monkeypatch, ny, m, seed):
    # several ropes on one strip, some slack: the inequality form stopped with one rope 1e-6 to 1e-4 L0
    # short and a spurious tension, and the state was rejected (Lagrangian residual 1e-4 to 1e-2); holding
    # every rope at its length (the old re-solve) made the clearly slack ones push
    from mdsr_opt.mechanics import ropesolve

    settled, decide = [], ropesolve._decide_ropes
    monkeypatch.setattr(ropesolve, "_decide_ropes", lambda *a: settled.append(decide(*a)) or settled[-1])
    mesh = Mesh.rectangle(4.0, 1.0, 4 * ny, ny)
    mus = grid_ropes(4 * ny, ny, m)
    a = np.random.default_rng(seed).uniform(0.05, 0.25, size=m)
    res = solve_internal(mesh, MAT, mus, a)
    assert res.success, res.status
    assert any(out is not None for out in settled)  # the undecided rope was settled, not left as it was
    assert res.residual < 1e-6 and res.slack.any()
    L0 = np.array([mu.rest_length(mesh) for mu in mus])
    short = (1.0 - a) - np.array([mu.length(res.x) for mu in mus]) / L0  # how much shorter than its target
    assert np.all(short > -1e-9)  # no rope longer than its target
    assert np.all(np.abs(short[~res.slack]) < 1e-8) and np.all(res.tension[~res.slack] > 0)
    assert np.all(short[res.slack] > 1e-7) and np.all(res.tension[res.slack] == 0.0)


class _Forced:
    """The constrained solver, with the outcome of one form's solves replaced (as IPOPT can report it)."""

    def __init__(self, solver, inequality: bool, status: str):
        self.solver, self.inequality, self.status, self.hit = solver, inequality, status, False

    def __call__(self, **kw):
        self.hit = bool(np.isinf(np.asarray(kw["lbg"])).any()) == self.inequality
        return self.solver(**kw)

    def stats(self):
        st = dict(self.solver.stats())
        if self.hit:
            st.update(success=False, return_status=self.status)
        return st


def _force(monkeypatch, inequality, status):
    from mdsr_opt.mechanics import ropesolve
    from mdsr_opt.mechanics.constrained import ConstrainedModel

    solver = ConstrainedModel.solver
    monkeypatch.setattr(ConstrainedModel, "solver",
                        lambda self, b, o, f: (lambda r: (_Forced(r[0], inequality, status), r[1]))(solver(self, b, o, f)))
    outcomes, solve = [], ropesolve.solve_constrained

    def spy(plugin, opts, cm, p, *args, **kw):
        out = solve(plugin, opts, cm, p, *args, **kw)
        outcomes.append((out, 1e-9 * cm.force_scale(p), cm.n_targets))
        return out

    monkeypatch.setattr(ropesolve, "solve_constrained", spy)
    return outcomes


def test_a_failed_inequality_form_is_never_replaced_by_a_pushing_rope(monkeypatch):
    # the predictor leaves the second rope slack, the inequality form (first) fails, the equality form
    # after it has the rope pushing: the step fails; no accepted step has a pushing rope
    outcomes = _force(monkeypatch, inequality=True, status="Restoration_Failed")
    mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    res = solve_internal(mesh, MAT, [row(mesh, 0.0), row(mesh, 0.25)], [0.3, 0.05])
    assert outcomes and not res.success
    for out, tol, nt in outcomes:
        assert not out.success or np.all(out.lam_g[:nt] >= -tol), (out.status, out.lam_g)


def test_an_undecided_inequality_answer_stands_when_the_equality_form_hits_its_cap(monkeypatch):
    outcomes = _force(monkeypatch, inequality=False, status="Maximum_Iterations_Exceeded")
    mesh = Mesh.rectangle(4.0, 1.0, 24, 6)
    P = mesh.points
    mus = [Muscle(sorted(np.flatnonzero(np.isclose(P[:, 1], y)), key=lambda i: P[i, 0])[1:-1]) for y in (0.0, 0.5)]
    res = solve_internal(mesh, MAT, mus, [0.4, 0.05])
    # the inequality form's answer (second rope 9e-7 L0 short) is kept, not the capped equality solve's
    assert outcomes[0][0].success and outcomes[0][0].status == "Solve_Succeeded"
    assert np.abs(res.achieved - [0.4, 0.05]).max() < 1e-5


def test_an_opposing_rope_holds_with_positive_tension():
    mesh = Mesh.rectangle(4.0, 1.0, 32, 8)
    # the top rope is not pulled in (a = 0) but may not lengthen: it holds against the bottom one
    res = solve_internal(mesh, MAT, [row(mesh, 0.0), row(mesh, 1.0)], [0.3, 0.0])
    assert res.success, res.status
    assert np.all(res.tension > 0) and not res.slack.any()
    assert np.abs(res.achieved - [0.3, 0.0]).max() < 1e-6
    free = solve_internal(mesh, MAT, [row(mesh, 0.0)], [0.3])
    # held at its length, the top cannot stretch as it does when free: the body bends less
    top = row(mesh, 1.0)
    assert top.length(free.x) > top.rest_length(mesh) + 0.05


def test_load_stepping_moves_the_rope_targets():
    mesh = Mesh.rectangle(4.0, 1.0, 32, 8)
    mus = [row(mesh, 0.0), row(mesh, 1.0)]
    a = np.array([0.6, 0.6])  # two opposing ropes: a hard axial squeeze
    # a tight iteration cap forces load steps; every rope target follows the load fraction s
    res = solve_internal(mesh, MAT, mus, a, max_iter=6, initial_guess="rest")
    assert res.success, res.status
    assert len(res.steps) >= 2 and res.steps[-1] == 1.0
    assert np.abs(res.achieved - a).max() < 1e-6
    assert res.min_J > 0
    # a cap too tight to finish: the failure is reported, and the last accepted state has its ropes at
    # s * a for the last accepted fraction s (solved to the intermediate steps' tolerance, whose rope rows
    # IPOPT meets to its constr_viol_tol, 1e-4 of a rope's rest length; a step of 1/16 is 0.0375 here)
    bad = solve_internal(mesh, MAT, mus, a, max_iter=2, min_step=1 / 16)
    assert not bad.success and "stalled" in bad.status
    s = bad.steps[-1]
    assert 0 < s < 1
    assert np.abs(bad.achieved - s * a).max() < 1e-4


def test_the_rope_predictor_never_starts_farther_from_the_ropes_targets():
    """From rest, the linearised (KKT) step of a strongly contracted rope bends the strip and lengthens the
    rope; the load step then starts from the current state instead. Away from rest, with a small load step,
    the step is kept (its rope residual is second order)."""
    from mdsr_opt.mechanics.constraints import muscle_constraints
    from mdsr_opt.mechanics.constrained import ConstrainedModel
    from mdsr_opt.mechanics.equilibrium import gauge_coordinates
    from mdsr_opt.mechanics.model import get_model

    mesh = Mesh.rectangle(4.0, 1.0, 32, 8)
    mus = [row(mesh, 0.0)]
    L0 = mus[0].rest_length(mesh)
    res = solve_internal(mesh, MAT, mus, [0.2])
    cm = ConstrainedModel(get_model(mesh, MAT), muscle_constraints(mesh, mus, None), ropes=True)
    pe = cm.model.params(MAT)
    fixed = np.zeros(2 * mesh.n_nodes, dtype=bool)
    fixed[list(gauge_coordinates(mesh))] = True
    X = mesh.points.reshape(-1)
    for x, a in ((X, 0.5), (X, 0.3), (res.x.reshape(-1), 0.22)):
        p = cm.params(pe, np.array([(1 - a) * L0]))
        y = cm.predict(p, x, fixed, x[fixed])
        r0, r1 = (abs(mus[0].length(z.reshape(-1, 2)) - (1 - a) * L0) / L0 for z in (x, y))
        assert r1 <= r0 + 1e-15, (a, r0, r1)
    assert r1 < 0.05 * r0  # the continuation step near a solution is a good prediction, and is kept


def test_a_strong_contraction_from_rest_takes_one_load_step_and_agrees_with_small_steps():
    mesh = Mesh.rectangle(4.0, 1.0, 32, 8)
    mus = [row(mesh, 0.0)]
    one = solve_internal(mesh, MAT, mus, [0.5])
    assert one.success and one.steps == [1.0], (one.status, one.steps)
    # a second path: an iteration cap that forces short load steps
    r = solve_internal(mesh, MAT, mus, [0.5], max_iter=8)
    assert r.success and len(r.steps) >= 2, (r.status, r.steps)
    assert one.energy == pytest.approx(r.energy, rel=1e-7)  # both solved to IPOPT tol 1e-8
    assert np.abs(one.achieved - 0.5).max() < 1e-6


@pytest.mark.parametrize("pose", ["as returned", "rotated and shifted"])
def test_an_earlier_result_in_any_pose_starts_a_solve(pose):
    """initial_guess=<an earlier state> is moved rigidly into the solver's gauge frame: setting the three
    gauge coordinates alone sheared the state (an inverted element, no solve) when it was not already there."""
    mesh = Mesh.rectangle(4.0, 1.0, 32, 8)
    mus = [row(mesh, 0.0), row(mesh, 1.0, 1.0, 3.0)]
    r0 = solve_internal(mesh, MAT, mus, [0.1, 0.1])
    x0 = r0.x
    if pose != "as returned":
        th = 0.7
        R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
        x0 = x0 @ R.T + [3.0, -2.0]
    warm = solve_internal(mesh, MAT, mus, [0.12, 0.12], initial_guess=x0)
    cold = solve_internal(mesh, MAT, mus, [0.12, 0.12])
    assert warm.success and cold.success, (warm.status, cold.status)
    assert warm.iterations < cold.iterations
    assert warm.energy == pytest.approx(cold.energy, rel=1e-7)
    assert np.abs(warm.x - cold.x).max() < 1e-5 * mesh.size  # both aligned to rest


@pytest.mark.parametrize("backend", ["sqpmethod", "uno"])
def test_other_constrained_backends_agree_with_ipopt(backend):
    from mdsr_opt.mechanics.backends import available_backends

    if backend not in available_backends():
        pytest.skip(f"{backend} is not in this CasADi build")
    mesh = Mesh.rectangle(4.0, 1.0, 12, 3)
    mus = [row(mesh, 0.0)]
    ref = solve_internal(mesh, MAT, mus, [0.2])
    res = solve_internal(mesh, MAT, mus, [0.2], backend=backend)
    assert res.success, res.status
    assert np.abs(res.x - ref.x).max() < 1e-5
    assert res.achieved[0] == pytest.approx(0.2, abs=1e-6)
    assert res.tension[0] == pytest.approx(ref.tension[0], rel=1e-5)


def test_backends_without_constraints_are_refused_at_the_door():
    mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    mus = [row(mesh, 0.0)]
    for backend in ("newton", "scipy"):
        with pytest.raises(ValueError, match=f"backend '{backend}' cannot take constraints.*exact cable"):
            solve_internal(mesh, MAT, mus, [0.2], backend=backend)
        with pytest.raises(ValueError, match="rigid anchor patches.*anchor_radius=0"):
            solve_internal(mesh, MAT, mus, [0.2], muscle_model="springs", backend=backend, anchor_radius=0.3)
    # without anchor patches the springs need no constraints: the Newton baseline still runs
    a = solve_internal(mesh, MAT, mus, [0.2], muscle_model="springs", backend="newton", anchor_radius=0)
    b = solve_internal(mesh, MAT, mus, [0.2], muscle_model="springs", anchor_radius=0)
    assert a.success and np.abs(a.x - b.x).max() < 1e-6


def test_bad_anchor_radius_is_refused():
    mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    with pytest.raises(ValueError, match="anchor_radius must be >= 0"):
        solve_internal(mesh, MAT, [row(mesh, 0.0)], [0.2], anchor_radius=-1.0)
    with pytest.raises(TypeError, match="anchor_radius must be a real number"):
        solve_internal(mesh, MAT, [row(mesh, 0.0)], [0.2], anchor_radius="big")
    # anchors covering half of a short muscle: the other half cannot take up a 60 % stroke
    for model in ("cable", "springs"):
        with pytest.raises(ValueError, match=r"shorten the rest by 1.2 >= 1; give a smaller anchor_radius"):
            solve_internal(mesh, MAT, [row(mesh, 0.0, 0.0, 1.0)], [0.6], muscle_model=model, anchor_radius=0.3)


# ------------------------------------------------------------------------------ anchor patches
def test_anchor_patches_are_physical_balls_around_the_ends():
    mesh = Mesh.rectangle(4.0, 1.0, 32, 8)
    P = mesh.points
    m = row(mesh, 0.0)
    r = default_anchor_radius(mesh)
    assert r == pytest.approx(0.04 * np.hypot(4.0, 1.0))
    (start, end), = anchor_patches(mesh, [m])
    assert start[0] == m.nodes[0] and end[0] == m.nodes[-1]
    for patch in (start, end):
        d = np.linalg.norm(P - P[patch[0]], axis=1)
        assert set(patch.tolist()) == set(np.nonzero(d <= r)[0].tolist())  # a convex body: the whole ball
    assert not set(start.tolist()) & set(end.tolist())
    # radius 0: the end nodes alone; a huge radius still never joins a muscle's two ends
    (s0, e0), = anchor_patches(mesh, [m], radius=0.0)
    assert s0.tolist() == [m.nodes[0]] and e0.tolist() == [m.nodes[-1]]
    (s9, e9), = anchor_patches(mesh, [m], radius=10.0)
    assert not set(s9.tolist()) & set(e9.tolist()) and len(s9) + len(e9) < mesh.n_nodes
    # the default is a size, not a count: scaling the body scales the radius and keeps the patches
    big = mesh.with_points(10.0 * P)
    assert default_anchor_radius(big) == pytest.approx(10 * r)
    (sb, eb), = anchor_patches(big, [m])
    assert sb.tolist() == start.tolist() and eb.tolist() == end.tolist()
    # finer meshes put more nodes in the same ball
    fine = Mesh.rectangle(4.0, 1.0, 64, 16)
    (sf, _), = anchor_patches(fine, [row(fine, 0.0)])
    assert len(sf) > len(start)


def test_body_size_is_rotation_invariant():
    mesh = Mesh.rectangle(4.0, 1.0, 8, 2)
    c, s = np.cos(0.7), np.sin(0.7)
    turned = mesh.with_points(mesh.points @ np.array([[c, -s], [s, c]]).T)
    assert body_size(turned) == pytest.approx(body_size(mesh), rel=1e-12)
    assert body_size(mesh) == pytest.approx(np.hypot(4.0, 1.0))


def test_body_size_is_the_largest_node_distance_of_any_body():
    """The diameter from the boundary nodes is the largest distance between any two nodes (brute force), for
    a body with a hole and a concave outline."""
    from mdsr_opt.scenes.scene import mesh_polygon

    outer = np.array([[0, 0], [6, 0], [6, 4], [4, 4], [3, 1.5], [2, 4], [0, 4]], float)  # a notch
    hole = np.array([[1, 1], [2, 1], [2, 2], [1, 2]], float)
    for mesh in (mesh_polygon(outer, holes=[hole], resolution=300), Mesh.rectangle(3.0, 2.0, 7, 5, pattern="right")):
        P = mesh.points
        brute = float(np.sqrt(((P[:, None, :] - P[None, :, :]) ** 2).sum(-1)).max())
        assert body_size(mesh) == pytest.approx(brute, rel=1e-14)


@pytest.mark.parametrize("seed", range(4))
def test_convex_hull_matches_qhull(seed):
    from scipy.spatial import ConvexHull

    from mdsr_opt.mechanics.anchors import convex_hull

    rng = np.random.default_rng(seed)
    for _ in range(25):
        P = rng.normal(size=(int(rng.integers(3, 400)), 2)) * 10.0 ** rng.uniform(-3, 3)
        if seed % 2:
            P = np.round(P / P.std()) * 2.0 ** rng.integers(-8, 8)  # a lattice (exact): points on hull edges
        mine = convex_hull(P)
        assert set(map(tuple, mine)) == set(map(tuple, P[ConvexHull(P).vertices]))
        e, f = np.roll(mine, -1, 0) - mine, np.roll(mine, -2, 0) - np.roll(mine, -1, 0)
        cross = e[:, 0] * f[:, 1] - e[:, 1] * f[:, 0]
        assert (cross > 0).all()  # counter-clockwise, every turn a left one
    assert convex_hull([[0, 0], [1, 1], [2, 2]]).tolist() == [[0, 0], [2, 2]]  # a line: its ends
    assert convex_hull([[1, 1], [1, 1]]).tolist() == [[1, 1]]
    tiny = convex_hull(np.array([[0, 0], [1, 0], [0.5, 3], [0.5, 1]]) * 1e-170)  # no underflow of the turns
    assert len(tiny) == 3
    for bad, words in (([[0, 0, 0]], r"shape \(m, 2\)"), ([[0, 0], [np.nan, 1]], "finite")):
        with pytest.raises(ValueError, match=words):
            convex_hull(bad)


def test_patches_of_different_muscles_that_touch_merge():
    mesh = Mesh.rectangle(4.0, 1.0, 32, 8)
    left, right = row(mesh, 0.0, 0.0, 2.0), row(mesh, 0.0, 2.0, 4.0)  # share the node at x = 2
    groups = rigid_groups(mesh, [left, right])
    assert len(groups) == 3  # the outer two ends, and one merged group in the middle
    mid = [g for g in groups if left.nodes[-1] in g.tolist()][0]
    assert right.nodes[0] in mid.tolist()


@pytest.mark.parametrize("muscle_model", ["cable", "springs"])
def test_rigid_patches_stay_rigid(muscle_model):
    mesh = Mesh.rectangle(4.0, 1.0, 48, 12)
    mus = [row(mesh, 0.0), row(mesh, 0.5)]
    res = solve_internal(mesh, MAT, mus, [0.3, 0.15], muscle_model=muscle_model)
    assert res.success, res.status
    groups = rigid_groups(mesh, mus, res.anchor_radius)
    assert len(groups) == 4 and all(len(g) >= 3 for g in groups)
    for g in groups:
        assert np.abs(pairwise(res.x, g) - pairwise(mesh.points, g)).max() < 1e-8
        # no reflection either: the signed area of the first three nodes keeps its sign
        def area(x):
            a, b, c = x[g[:3]]
            u, v = b - a, c - a
            return u[0] * v[1] - u[1] * v[0]
        assert area(res.x) == pytest.approx(area(mesh.points), abs=1e-8)


def _segment_strains(cells, radius):
    mesh = Mesh.rectangle(4.0, 1.0, *cells)
    m = row(mesh, 0.0)
    res = solve_internal(mesh, MAT, [m], [0.2], anchor_radius=radius)
    assert res.success and res.achieved[0] == pytest.approx(0.2, abs=1e-6)
    return 1 - m.segment_lengths(res.x) / m.segment_lengths(mesh.points)


def test_anchor_patches_keep_the_muscle_strain_from_drifting_under_refinement():
    # a rope pulling on single end nodes indents the body more with every refinement, so the same stroke
    # leaves less for the muscle's interior; over anchor patches of physical size the interior converges
    cells = [(16, 4), (32, 8), (64, 16)]
    point = [np.median(_segment_strains(c, 0.0)) for c in cells]
    patch = [np.median(_segment_strains(c, None)) for c in cells]
    assert point[0] - point[2] > 0.025  # measured 0.183 -> 0.150
    assert np.ptp(patch) < 0.01  # measured 0.183, 0.190, 0.186


@pytest.mark.slow
def test_end_segment_strain_converges_only_with_anchor_patches():
    cells = [(32, 8), (64, 16), (128, 32)]
    point = [_segment_strains(c, 0.0).max() for c in cells]  # measured 0.38, 0.54, 0.69: no limit
    patch = [_segment_strains(c, None).max() for c in cells]  # measured 0.31, 0.40, 0.43
    assert point[2] - point[1] > 0.1
    assert abs(patch[2] - patch[1]) < 0.5 * abs(patch[1] - patch[0])


# ------------------------------------------------------------------------------ constraint derivatives
def test_constraint_jacobian_and_hessian_match_finite_differences():
    mesh = Mesh.rectangle(2.0, 1.0, 8, 4)
    P = mesh.points
    # a bent muscle (along the bottom, then up the right side) and a straight one
    bottom = [int(i) for i in np.argsort(P[:, 0]) if P[i, 1] == 0.0]
    side = [int(i) for i in np.argsort(P[:, 1]) if P[i, 0] == 2.0][1:]
    mc = MuscleConstraints(mesh, [Muscle(bottom + side), row(mesh, 0.5)], radius=0.3)
    assert mc.n_rigid > 0
    rng = np.random.default_rng(1)
    x = (P + 0.05 * rng.standard_normal(P.shape)).reshape(-1)
    J = mc.jacobian(x).toarray()
    lam = rng.standard_normal(mc.n_constraints)
    H = mc.hessian(x, lam).toarray()
    h = 1e-6
    Jfd = np.zeros_like(J)
    Hfd = np.zeros_like(H)
    for k in range(len(x)):
        e = np.zeros_like(x)
        e[k] = h
        Jfd[:, k] = (mc.values(x + e) - mc.values(x - e)) / (2 * h)
        Hfd[:, k] = (mc.jacobian(x + e).T @ lam - mc.jacobian(x - e).T @ lam) / (2 * h)
    assert np.abs(J - Jfd).max() < 1e-8
    assert np.abs(H - Hfd).max() < 1e-6
    assert np.abs(H - H.T).max() == 0.0
    # rigid motions keep every rigid row at zero and every rope length; a reflection does not
    c, s = np.cos(0.8), np.sin(0.8)
    moved = P @ np.array([[c, -s], [s, c]]).T + [3.0, -1.0]
    assert np.abs(mc.rigid(moved)).max() < 1e-12
    assert mc.lengths(moved) == pytest.approx(mc.rest_lengths, rel=1e-12)
    assert np.abs(mc.rigid(P * [1.0, -1.0])).max() > 0.1
    assert mc.n_rigid == sum(2 * len(g) - 3 for g in mc.groups)


# ------------------------------------------------------------------------------ dummy springs
@pytest.mark.parametrize("stiffness", [1.0, 10.0])
def test_spring_contraction_does_not_depend_on_the_mesh(stiffness):
    def achieved(cells):
        mesh = Mesh.rectangle(4.0, 1.0, *cells)
        res = solve_internal(mesh, MAT, [row(mesh, 0.0)], [0.3], muscle_model="springs", stiffness=stiffness)
        assert res.success, res.status
        return res.achieved[0]

    coarse, fine = achieved((24, 6)), achieved((64, 16))  # 175 and 1105 nodes: 6x as many
    assert abs(fine - coarse) / fine < 0.03
    assert coarse < 0.3  # a penalty: the body resists


def test_spring_contraction_does_not_depend_on_the_mesh_600_to_4k_nodes():  # about 2 s
    def achieved(cells):
        mesh = Mesh.rectangle(4.0, 1.0, *cells)
        res = solve_internal(mesh, MAT, [row(mesh, 0.0), row(mesh, 0.5)], [0.3, 0.1], muscle_model="springs",
                             stiffness=1.0)
        assert res.success, res.status
        return res.achieved

    coarse, fine = achieved((48, 12)), achieved((128, 32))  # 637 and 4257 nodes
    assert np.abs(fine - coarse).max() / fine.max() < 0.03


def test_springs_stiffness_is_per_unit_rest_length():
    mesh = Mesh.rectangle(4.0, 1.0, 8, 2)
    m = row(mesh, 0.0)
    k, r = segment_spring_parameters(mesh, MAT, [m], [0.2], 3.0, anchor_radius=0)
    on = k > 0
    l0 = mesh.edge_lengths[on]
    K = 3.0 * MAT.E * MAT.thickness * np.hypot(4.0, 1.0)
    assert k[on] * l0 == pytest.approx(np.full(on.sum(), K))
    assert r[on] == pytest.approx(np.full(on.sum(), 0.8))
    # with anchors the segments inside a patch carry no spring and the rest shorten more, so that the chain
    # as a whole is commanded 20 %
    k2, r2 = segment_spring_parameters(mesh, MAT, [m], [0.2], 3.0, anchor_radius=0.6)
    on2 = k2 > 0
    assert on2.sum() == on.sum() - 2
    free = mesh.edge_lengths[on2].sum()
    assert (1 - r2[on2]) * free == pytest.approx(np.full(on2.sum(), 0.2 * 4.0))


def test_springs_of_muscles_with_different_segment_counts():
    mesh = Mesh.rectangle(4.0, 1.0, 8, 2)
    long, short = row(mesh, 0.0), row(mesh, 1.0, 0.0, 1.0)
    k, r = segment_spring_parameters(mesh, MAT, [long, short], [0.2, 0.1], 3.0, anchor_radius=0)
    assert (k > 0).sum() == len(long.segments) + len(short.segments)
    assert sorted(set(np.round(r[k > 0], 12))) == [0.8, 0.9]


# ------------------------------------------------------------------------------ stability of constrained states
def test_constrained_equilibrium_is_a_minimum_on_the_constraints_tangent_space():
    """The result's stability check agrees with a dense eigen-solve of the reduced Lagrangian Hessian,
    built here from the constraints' own Jacobian and Hessian with least-squares multipliers."""
    import scipy.linalg as sl

    from mdsr_opt.mechanics.equilibrium import gauge_coordinates
    from mdsr_opt.mechanics.model import get_model

    mesh = Mesh.rectangle(3.0, 1.0, 12, 4)
    mus = [row(mesh, 0.0), row(mesh, 1.0)]
    res = solve_internal(mesh, MAT, mus, [0.3, 0.0], align_to_rest=False)
    assert res.success and res.stable is True
    assert res.stability["method"] in ("kkt-inertia", "ldl-inertia+finsler", "ipopt-inertia") and \
        res.stability["n_negative"] == 0
    x = res.x.reshape(-1)
    fixed = np.zeros(len(x), dtype=bool)
    fixed[list(gauge_coordinates(mesh))] = True
    free = ~fixed
    mc = MuscleConstraints(mesh, mus, res.anchor_radius)
    model = get_model(mesh, MAT)
    g = model.gradient(x, model.params(MAT))
    J = mc.jacobian(x).toarray()  # both ropes are taut (the top one holds): every row is active
    lam = np.linalg.lstsq(J[:, free].T, -g[free], rcond=None)[0]
    assert np.abs(g[free] + J[:, free].T @ lam).max() < 1e-7  # a KKT point
    assert lam[:2] == pytest.approx(res.tension, rel=1e-6)
    H = model.hessian(x, model.params(MAT)).toarray() + mc.hessian(x, lam).toarray()
    Z = sl.null_space(J[:, free])
    ev = np.linalg.eigvalsh(Z.T @ H[np.ix_(free, free)] @ Z)
    assert ev[0] > 0


def test_a_constrained_state_the_check_calls_unstable_is_not_a_success(monkeypatch):
    """Wiring: internal driving with constraints goes through the stability check, and a failed check
    (here forced, with no escape direction) turns the solve into a reported failure."""
    import mdsr_opt.mechanics.loadsteps as eq
    from mdsr_opt.mechanics.stability import StabilityCheck

    seen = []

    def unstable(H, free, A=None, **kw):
        seen.append(A)
        return StabilityCheck(False, 1, 0, None, -1.0, "forced", 0.0)

    monkeypatch.setattr(eq, "check_stability", unstable)
    mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    res = solve_internal(mesh, MAT, [row(mesh, 0.0)], [0.2])
    assert not res.success and res.stable is False
    assert "not a stable equilibrium" in res.status
    assert seen and all(A is not None and A.shape[0] >= 1 for A in seen)  # active constraint rows were passed


def test_ropes_at_rest_length_leave_the_body_exactly_at_rest():
    # unloaded ropes have multipliers of round-off size: that must not send the solve into the barrier
    # (slack) mode, which would leave the body a little off rest
    mesh = Mesh.rectangle(4.0, 1.0, 24, 6)
    mus = [row(mesh, 0.0), row(mesh, 0.5), row(mesh, 1.0), row(mesh, 0.5, 1.0, 3.0)]
    res = solve_internal(mesh, MAT, mus, np.zeros(4))
    assert res.success and res.iterations <= 2
    assert np.abs(res.x - mesh.points).max() < 1e-9
    assert np.all(res.tension >= 0.0) and res.tension.max() < 1e-12 and not res.slack.any()
    assert np.abs(res.achieved).max() < 1e-12


@pytest.mark.parametrize("length, E", [(1e-2, 1e5), (1e3, 1e-3)])
def test_units_do_not_matter(length, E):
    # the same body in other units (and a material in matching units): the same shape, contraction and
    # (scaled) tension — constraint rows are dimensionless inside the NLP
    base = Mesh.rectangle(4.0, 1.0, 32, 8)
    mus = [row(base, 0.0), row(base, 0.25)]
    ref = solve_internal(base, MAT, mus, [0.3, 0.05])
    res = solve_internal(base.with_points(base.points * length), NeoHookean(E=E, nu=0.3), mus, [0.3, 0.05])
    assert res.success, res.status
    assert np.abs(res.x / length - ref.x).max() < 1e-6
    assert np.abs(res.achieved - ref.achieved).max() < 1e-7
    assert res.tension / (E * length) == pytest.approx(ref.tension, rel=1e-5, abs=1e-12)
    assert list(res.slack) == list(ref.slack) == [False, True]


def test_the_nlp_hessian_is_the_lagrangians():
    # the Hessian handed to IPOPT (energy + multipliers x constraint curvature, NLP-scaled multipliers)
    # against the numeric Lagrangian Hessian and a finite difference of the Lagrangian gradient
    import casadi as ca
    import scipy.sparse as sp

    from mdsr_opt.mechanics.constrained import ConstrainedModel
    from mdsr_opt.mechanics.model import get_model

    mesh = Mesh.rectangle(2.0, 1.0, 8, 4)
    mus = [row(mesh, 0.0), row(mesh, 0.5)]
    model = get_model(mesh, MAT)
    cm = ConstrainedModel(model, MuscleConstraints(mesh, mus, radius=0.3), ropes=True)
    rng = np.random.default_rng(4)
    x = mesh.points.reshape(-1) + 0.02 * rng.standard_normal(2 * mesh.n_nodes)
    lam_nlp = rng.standard_normal(cm.n_rows)
    lam = lam_nlp * cm.row_scale
    pe = model.params(MAT)
    lf, lg = ca.MX.sym("lf"), ca.MX.sym("lg", cm.n_rows)
    Hf = ca.Function("H", [model.x, model.p, lf, lg], [cm.hess_lag_upper(model.x, model.p, lf, lg)])
    H_nlp = np.array(ca.DM(Hf(x, pe, 1.0, lam_nlp)))
    p = cm.params(pe, cm.values(x)[:2], lam)
    H = cm.hessian(x, p)
    assert np.abs(H_nlp - sp.triu(H).toarray()).max() < 1e-10
    h = 1e-6
    for k in rng.choice(2 * mesh.n_nodes, 8, replace=False):
        e = np.zeros_like(x)
        e[k] = h
        col = (cm.gradient(x + e, p) - cm.gradient(x - e, p)) / (2 * h)
        assert np.abs(col - H[:, k].toarray().ravel()).max() < 1e-6


@pytest.mark.parametrize("ropes", [True, False])
def test_the_numeric_nlp_pieces_are_the_symbolic_ones(ropes):
    """ConstrainedModel.numeric_functions (what IPOPT evaluates) against the SX pieces (rows, Jacobian,
    Lagrangian Hessian, NLP-scaled) and against finite differences; with the rigid patches' scale rows,
    whose node pairs need not be mesh edges; the springs' model keeps only the anchor rows."""
    import casadi as ca

    from mdsr_opt.mechanics.constrained import ConstrainedModel
    from mdsr_opt.mechanics.model import get_model

    mesh = Mesh.rectangle(2.0, 1.0, 8, 4)
    mus = [row(mesh, 0.0), row(mesh, 0.5), row(mesh, 1.0, 0.0, 2.0)]
    model = get_model(mesh, MAT)
    cm = ConstrainedModel(model, MuscleConstraints(mesh, mus, radius=0.3), ropes=ropes)
    assert cm.n_rows == cm.constraints.n_constraints - (0 if ropes else len(mus))
    fns = cm.numeric_functions()
    rng = np.random.default_rng(7)
    x = mesh.points.reshape(-1) + 0.02 * rng.standard_normal(2 * mesh.n_nodes)
    pe, lam = model.params(MAT), rng.standard_normal(cm.n_rows)
    xs, lf, lg = model.x, ca.MX.sym("lf"), ca.MX.sym("lg", cm.n_rows)
    sym = ca.Function("s", [xs, model.p, lf, lg], [cm.nlp_constraints_expr(xs), cm.nlp_jacobian_expr(xs),
                                                   cm.hess_lag_upper(xs, model.p, lf, lg)])
    g_s, J_s, H_s = (np.array(ca.DM(v)) for v in sym(x, pe, 0.7, lam))
    g_n = np.array(ca.DM(fns["g"](x, pe))).ravel()
    g2, J_n = fns["jac_g"](x, pe)
    J_n, H_n = np.array(ca.DM(J_n)), np.array(ca.DM(fns["hess_lag"](x, pe, 0.7, lam)))
    np.testing.assert_allclose(g_n, g_s.ravel(), rtol=0, atol=1e-13)
    np.testing.assert_allclose(np.array(ca.DM(g2)).ravel(), g_n, rtol=0, atol=0)
    np.testing.assert_allclose(J_n, J_s, rtol=0, atol=1e-13)
    np.testing.assert_allclose(H_n, H_s, rtol=0, atol=1e-12)
    assert np.all(np.tril(H_n, -1) == 0)  # IPOPT takes the upper triangle
    # independent check: the Jacobian and the Lagrangian Hessian by central differences
    h = 1e-6
    H_full = H_n + np.triu(H_n, 1).T

    def lag_grad(z):
        return 0.7 * model.gradient(z, pe) + cm.jacobian(z).T @ (lam * cm.row_scale)

    for k in rng.choice(2 * mesh.n_nodes, 10, replace=False):
        e = np.zeros_like(x)
        e[k] = h
        dg = (np.array(ca.DM(fns["g"](x + e, pe))) - np.array(ca.DM(fns["g"](x - e, pe)))).ravel() / (2 * h)
        assert np.abs(dg - J_n[:, k]).max() < 1e-7
        assert np.abs((lag_grad(x + e) - lag_grad(x - e)) / (2 * h) - H_full[:, k]).max() < 1e-6


def test_the_numeric_nlp_pieces_without_rows_and_their_lifetime():
    """A model without rows (dummy springs, no anchor patches): the Hessian is the energy's alone and the
    solve the plain minimisation's; the callbacks do not keep their model alive."""
    import gc
    import weakref

    import casadi as ca

    from mdsr_opt.mechanics.constrained import ConstrainedModel
    from mdsr_opt.mechanics.model import get_model

    mesh = Mesh.rectangle(2.0, 1.0, 8, 4)
    model = get_model(mesh, MAT)
    cm = ConstrainedModel(model, MuscleConstraints(mesh, [row(mesh, 0.0)], radius=None), ropes=False)
    assert cm.n_rows == 0
    fns = cm.numeric_functions()
    x = mesh.points.reshape(-1) * 1.01
    pe = model.params(MAT)
    H = np.array(ca.DM(fns["hess_lag"](x, pe, 1.0, np.zeros(0))))
    np.testing.assert_allclose(H, np.triu(model.hessian(x, pe).toarray()), rtol=0, atol=1e-12)
    ref = weakref.ref(cm)
    del cm, fns
    gc.collect()
    assert ref() is None


def test_check_stability_false_skips_only_the_stability_check(monkeypatch):
    from mdsr_opt.mechanics import loadsteps

    mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    mus = [row(mesh, 0.0), row(mesh, 1.0, 0.0, 2.0)]
    checked = solve_internal(mesh, MAT, mus, [0.25, 0.1])
    calls, stability_at = [], loadsteps._stability_at
    monkeypatch.setattr(loadsteps, "_stability_at", lambda *a, **k: calls.append(1) or stability_at(*a, **k))
    unchecked = solve_internal(mesh, MAT, mus, [0.25, 0.1], check_stability=False)
    assert checked.success and checked.stable and unchecked.success and not calls
    assert unchecked.stable is None and unchecked.stability is None
    np.testing.assert_allclose(unchecked.x, checked.x, atol=1e-12)
    with pytest.raises(TypeError, match="check_stability must be True or False"):
        solve_internal(mesh, MAT, mus, [0.25, 0.1], check_stability="no")


@pytest.mark.parametrize("model", ["cable", "springs"])
def test_equality_rows_start_from_fitted_multipliers_with_the_same_answer(monkeypatch, model):
    # all rows equalities (taut ropes, anchor patches): IPOPT starts from the multipliers fitted at the start
    # instead of estimating them itself; the equilibrium is the same
    from mdsr_opt.mechanics import ropesolve

    mesh = Mesh.rectangle(4.0, 1.0, 32, 8)
    mus = [row(mesh, 0.0, 0.5, 3.5), row(mesh, 1.0, 0.5, 2.0)]
    fitted = solve_internal(mesh, MAT, mus, [0.3, 0.1], muscle_model=model)
    monkeypatch.setattr(ropesolve, "WARM_MULTIPLIERS", {})
    estimated = solve_internal(Mesh.rectangle(4.0, 1.0, 32, 8), MAT, mus, [0.3, 0.1], muscle_model=model)
    assert fitted.success and estimated.success
    np.testing.assert_allclose(fitted.x, estimated.x, atol=1e-9)
    assert abs(fitted.iterations - estimated.iterations) <= 1


def test_fitted_multipliers_from_an_earlier_state_cost_no_iterations(monkeypatch):
    # frames each started from the last: a rope shorter than its new target still pulls at the start (fitted
    # as slack, its zero tension cost 116 IPOPT iterations against 81 on 24 such frames)
    from mdsr_opt.mechanics import ropesolve

    mesh = Mesh.rectangle(4.0, 1.0, 32, 8)
    mus = [row(mesh, 0.0, 0.0, 2.0), row(mesh, 0.0, 2.0, 4.0), row(mesh, 1.0, 0.0, 2.0), row(mesh, 1.0, 2.0, 4.0)]
    phases = np.linspace(0.0, 2.0 * np.pi, 8)
    frames = [0.1 + 0.08 * np.array([np.sin(t), np.cos(t), -np.sin(t), -np.cos(t)]) for t in phases]

    def run():
        total, prev = 0, None
        for a in frames:
            r = solve_internal(mesh, MAT, mus, a, initial_guess="predictor" if prev is None else prev)
            assert r.success, r.status
            total, prev = total + r.iterations, r.x
        return total, prev

    fitted, x1 = run()
    monkeypatch.setattr(ropesolve, "WARM_MULTIPLIERS", {})
    estimated, x2 = run()
    np.testing.assert_allclose(x1, x2, atol=1e-8)
    assert fitted <= estimated + 2


def test_two_cable_ropes_along_one_path_are_refused_at_the_door():
    from mdsr_opt import design_contractions
    from mdsr_opt.synthesis.results import DesignResult
    from mdsr_opt.synthesis.verify import check_minimum, verify_design

    mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    rope = row(mesh, 0.0, 0.25, 2.75)
    for twin in (Muscle(rope.nodes), Muscle(rope.nodes[::-1])):  # the same path, either direction
        with pytest.raises(ValueError, match="muscles 0 and 1 run along the same path"):
            solve_internal(mesh, MAT, [rope, twin], [0.2, 0.1])
    # (it was a stall at load fraction 0 "predictor inverted an element", and a singular-factor traceback
    # from inside scipy in a design)
    single = solve_internal(mesh, MAT, [rope], [0.2])
    with pytest.raises(ValueError, match="run along the same path"):
        design_contractions(mesh, MAT, [rope, Muscle(rope.nodes)], single.x)
    with pytest.raises(ValueError, match="run along the same path"):
        check_minimum(mesh, MAT, [rope, Muscle(rope.nodes)], [0.2, 0.2], single.x)
    res = design_contractions(mesh, MAT, [rope], single.x)
    two = DesignResult(**{**res.__dict__, "contractions": np.array([0.2, 0.2])})
    with pytest.raises(ValueError, match="run along the same path"):
        verify_design(mesh, MAT, [rope, Muscle(rope.nodes)], two, single.x)
    # dummy springs along one path are springs in parallel: allowed; ropes sharing only part of a path too
    assert solve_internal(mesh, MAT, [rope, Muscle(rope.nodes)], [0.2, 0.1], muscle_model="springs").success
    part = Muscle(rope.nodes[:-2])
    assert solve_internal(mesh, MAT, [rope, part], [0.2, 0.1]).success
