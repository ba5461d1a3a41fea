"""External and internal driving: closed-form cases, large drags, invariances, backends, bad input."""

import numpy as np
import pytest

from mdsr_opt import LinearElastic, Mesh, Muscle, NeoHookean, solve_external, solve_internal
from mdsr_opt.mechanics.align import difference
from mdsr_opt.mechanics.backends import available_backends
from mdsr_opt.mechanics.result import SolverFailure
from mdsr_opt.mechanics.model import get_model
from mdsr_opt.mechanics.units import Units

from conftest import arc_map, ends, rotation


def stretch_drags(mesh, amount=1.0, length=4.0):
    _, right = ends(mesh, length)
    return {int(i): (mesh.points[i, 0] + amount, mesh.points[i, 1]) for i in right}


def test_patch_test_affine_boundary_gives_affine_interior(material):
    mesh = Mesh.from_polygon([[0, 0], [2, 0], [2, 1], [0, 1]], max_area=0.03)
    A = np.array([[1.3, 0.2], [-0.15, 0.85]])
    b = np.array([0.5, -0.2])
    bnd = mesh.boundary_nodes
    res = solve_external(mesh, material, anchors=None, drags=(bnd, mesh.points[bnd] @ A.T + b))
    assert res.success
    exact = mesh.points @ A.T + b
    assert np.abs(res.x - exact).max() < 1e-7
    # closed form: energy = area * psi(A)
    assert res.energy == pytest.approx(mesh.area * material.psi(A), rel=1e-9)


def test_stretch_by_own_width_converges(strip, material):
    left, _ = ends(strip)
    res = solve_external(strip, material, left, stretch_drags(strip, 1.0))
    assert res.success and res.min_J > 0
    assert res.residual < 1e-8
    # the strip necks: the middle gets narrower than at rest
    mid = np.abs(strip.points[:, 0] - 2.0) < 0.15
    assert np.ptp(res.x[mid, 1]) < 0.97


def test_bend_through_ninety_degrees_needs_and_survives_load_steps(strip, material):
    left, right = ends(strip)
    target = arc_map(strip.points[right])
    res = solve_external(strip, material, left, (right, target))
    assert res.success and res.min_J > 0
    assert len(res.steps) >= 2 and res.steps[-1] == 1.0  # the linear guess alone would invert elements
    assert np.abs(res.x[right] - target).max() < 1e-12  # drags honoured exactly
    # the inner (top) side is shortened, the outer (bottom) side lengthened
    P = strip.points
    top = sorted(np.nonzero(P[:, 1] > 1 - 1e-9)[0], key=lambda i: P[i, 0])
    bot = sorted(np.nonzero(P[:, 1] < 1e-9)[0], key=lambda i: P[i, 0])
    length = lambda idx: np.linalg.norm(np.diff(res.x[idx], axis=0), axis=1).sum()  # noqa: E731
    assert length(top) < 4.0 < length(bot)


def test_bend_past_ninety_degrees(strip, material):
    left, right = ends(strip)
    res = solve_external(strip, material, left, (right, arc_map(strip.points[right], angle=2.5)))
    assert res.success and res.min_J > 0


def test_energy_converges_under_refinement(material):
    """A smooth boundary motion (no corner singularity): energy differences shrink like h^2. Nested structured
    meshes (h halves exactly); unstructured ones of halving area are not nested, and their energy differences
    scatter around the rate (0.43 and 0.04 for three successive pairs)."""
    def phi(X):
        return np.column_stack([X[:, 0] + 0.15 * np.sin(np.pi * X[:, 1]), X[:, 1] + 0.2 * np.sin(np.pi * X[:, 0] / 2)])

    energies = []
    for k in (4, 8, 16):
        mesh = Mesh.rectangle(2.0, 1.0, 2 * k, k)
        bnd = mesh.boundary_nodes
        res = solve_external(mesh, material, None, (bnd, phi(mesh.points[bnd])))
        assert res.success
        energies.append(res.energy)
    d1, d2 = abs(energies[0] - energies[1]), abs(energies[1] - energies[2])
    assert d2 < 0.4 * d1  # h halves each time: second order would give 0.25
    assert d2 / energies[2] < 0.03  # and the finest two agree to a few per cent


@pytest.mark.parametrize("backend", available_backends())
def test_every_backend_reaches_the_same_energy(backend, material):
    mesh = Mesh.from_polygon([[0, 0], [4, 0], [4, 1], [0, 1]], max_area=0.06)
    left, _ = ends(mesh)
    drags = stretch_drags(mesh, 0.6)
    ref = solve_external(mesh, material, left, drags, backend="ipopt", tol=1e-10)
    res = solve_external(mesh, material, left, drags, backend=backend, tol=1e-10)
    assert res.success, res.status
    assert res.backend == backend
    assert res.energy == pytest.approx(ref.energy, rel=1e-7)
    assert np.abs(res.x - ref.x).max() < 1e-4


def test_model_and_solver_are_reused_across_drags(strip, material):
    left, _ = ends(strip)
    solve_external(strip, material, left, stretch_drags(strip, 0.2))
    unit = Units(strip, material)  # the solves build on the body's unit copy
    model = get_model(unit.unit_mesh, unit.unit_material)
    n_solvers = len(model._solvers)
    res = solve_external(strip, material, left, stretch_drags(strip, 0.4))
    assert get_model(Units(strip, material).unit_mesh, unit.unit_material) is model
    assert len(model._solvers) == n_solvers
    assert res.success
    # a cached solver reports no build time, so a build is counted once (one per tolerance: load steps
    # before the last have their own, loadsteps.INTERMEDIATE_TOL)
    keys = [k for k in model._solvers if k[0] == "ipopt"]
    assert 1 <= len(keys) <= 2
    assert all(model.solver("ipopt", dict(eval(k[1])), None)[1] == 0.0 for k in keys)


def test_solver_failure_is_reported_not_returned_as_success(strip, material):
    left, right = ends(strip)
    res = solve_external(strip, material, left, (right, arc_map(strip.points[right])), max_iter=1,
                         min_step=0.25)
    assert not res.success
    assert "stalled" in res.status
    with pytest.raises(SolverFailure, match="failed"):
        res.raise_on_failure()
    assert res.min_J > 0  # the last accepted state is still a valid body


def _bottom_muscle(mesh):
    P = mesh.points
    return Muscle(sorted((i for i in range(mesh.n_nodes) if P[i, 1] < 1e-9), key=lambda i: P[i, 0]))


@pytest.mark.parametrize("muscle_model", ["springs", "cable"])
def test_internal_contraction_bends_the_body(strip, material, muscle_model):
    mus = _bottom_muscle(strip)
    res = solve_internal(strip, material, [mus], [0.5], muscle_model=muscle_model)
    assert res.success and res.min_J > 0
    ratio = mus.length(res.x) / mus.rest_length(strip)
    if muscle_model == "cable":  # an inextensible rope: exactly the commanded length
        assert ratio == pytest.approx(0.5, abs=1e-7)
    else:  # penalty springs: the body resists a little
        assert 0.5 < ratio < 0.6
    assert res.achieved[0] == pytest.approx(1 - ratio, abs=1e-12)
    top = sorted((i for i in range(strip.n_nodes) if strip.points[i, 1] > 1 - 1e-9),
                 key=lambda i: strip.points[i, 0])
    top_len = np.linalg.norm(np.diff(res.x[top], axis=0), axis=1).sum()
    assert top_len > mus.length(res.x)  # bent towards the muscle


def test_internal_stiffer_springs_track_the_contraction_closer(strip, material):
    mus = _bottom_muscle(strip)
    soft = solve_internal(strip, material, [mus], [0.3], muscle_model="springs", stiffness=2.0)
    stiff = solve_internal(strip, material, [mus], [0.3], muscle_model="springs", stiffness=50.0)
    L0 = mus.rest_length(strip)
    assert abs(mus.length(stiff.x) / L0 - 0.7) < abs(mus.length(soft.x) / L0 - 0.7)


@pytest.mark.parametrize("muscle_model", ["cable", "springs"])
def test_internal_driving_invariant_under_rigid_motion_and_relabelling(material, muscle_model):
    mesh = Mesh.from_polygon([[0, 0], [3, 0], [3, 1], [0, 1]], max_area=0.04)
    mus = _bottom_muscle(mesh)
    base = solve_internal(mesh, material, [mus], [0.35], muscle_model=muscle_model)
    assert base.success
    # rigid motion of the rest mesh
    R, t = rotation(0.9), np.array([5.0, -2.0])
    moved = mesh.with_points(mesh.points @ R.T + t)
    res = solve_internal(moved, material, [mus], [0.35], muscle_model=muscle_model)
    assert difference(res.x, base.x) < 1e-6
    assert res.energy == pytest.approx(base.energy, rel=1e-8)
    assert res.tension == pytest.approx(base.tension, rel=1e-6)
    # relabelling of nodes
    perm = np.random.default_rng(3).permutation(mesh.n_nodes)
    relab = mesh.relabel(perm)
    res2 = solve_internal(relab, material, [Muscle(perm[list(mus.nodes)])], [0.35], muscle_model=muscle_model)
    assert np.abs(res2.x[perm] - base.x).max() < 1e-6


@pytest.mark.parametrize("muscle_model", ["cable", "springs"])
def test_no_contraction_leaves_the_body_at_rest(strip, material, muscle_model):
    res = solve_internal(strip, material, [_bottom_muscle(strip)], [0.0], muscle_model=muscle_model)
    assert res.success and res.energy < 1e-20
    assert np.abs(res.x - strip.points).max() < 1e-9
    assert abs(res.tension[0]) < 1e-9 and abs(res.achieved[0]) < 1e-9


# ------------------------------------------------------------------------------------ bad input
def test_external_bad_input(strip, material):
    left, right = ends(strip)
    drags = stretch_drags(strip)
    with pytest.raises(ValueError, match="both anchored and dragged"):
        solve_external(strip, material, left, {int(left[0]): (0.0, 0.0), **drags})
    with pytest.raises(ValueError, match="needs fixed nodes"):
        solve_external(strip, material, None, None)
    with pytest.raises(ValueError, match="at least two fixed nodes"):
        solve_external(strip, material, [int(left[0])], None)
    with pytest.raises(ValueError, match="out of range"):
        solve_external(strip, material, [10 ** 6], drags)
    with pytest.raises(ValueError, match="NaN"):
        solve_external(strip, material, left, {int(right[0]): (np.nan, 0.0)})
    with pytest.raises(ValueError, match="unknown backend 'knitro'; available: ipopt"):
        solve_external(strip, material, left, drags, backend="knitro")
    with pytest.raises(TypeError, match="drags must be"):
        solve_external(strip, material, left, [1, 2, 3])
    with pytest.raises(TypeError, match="mesh must be"):
        solve_external(strip.points, material, left, drags)
    with pytest.raises(TypeError, match="material"):
        solve_external(strip, 1.0, left, drags)
    with pytest.raises(TypeError, match="integer"):
        solve_external(strip, material, left.astype(float), drags)


def test_internal_bad_input(strip, material):
    mus = _bottom_muscle(strip)
    with pytest.raises(ValueError, match=r"outside \[0, 1\)"):
        solve_internal(strip, material, [mus], [1.0])
    with pytest.raises(ValueError, match=r"outside \[0, 1\)"):
        solve_internal(strip, material, [mus], [-0.1])
    with pytest.raises(ValueError, match="NaN"):
        solve_internal(strip, material, [mus], [np.nan])
    with pytest.raises(ValueError, match="one value per muscle"):
        solve_internal(strip, material, [mus], [0.1, 0.2])
    with pytest.raises(ValueError, match="at least one muscle"):
        solve_internal(strip, material, [], [])
    far = int(np.argmax(strip.points[:, 0]))
    with pytest.raises(ValueError, match="not a mesh edge"):
        solve_internal(strip, material, [Muscle([0, far])], [0.1])
    with pytest.raises(ValueError, match="repeats node"):
        Muscle([0, 1, 0])
    with pytest.raises(ValueError, match="model must be"):
        solve_internal(strip, material, [mus], [0.1], muscle_model="rope")
    with pytest.raises(ValueError, match="stiffness"):
        solve_internal(strip, material, [mus], [0.1], stiffness=0.0)


@pytest.mark.parametrize("material", [NeoHookean(1.0, 0.3), LinearElastic(1.0, 0.3)], ids=["neo-hookean", "linear"])
def test_numeric_evaluation_matches_the_symbolic_model(material):
    """The default IPOPT path evaluates energy, gradient and Hessian in numpy (also beside the exact cable's
    constraints); ``ipopt-symbolic`` takes them from the symbolic CasADi model. Same problem: same
    iterations, energies and states to round-off, same rope tension."""
    mesh = Mesh.rectangle(4.0, 1.0, 24, 6)
    P = mesh.points
    left, right = np.flatnonzero(P[:, 0] == 0), np.flatnonzero(P[:, 0] == 4)
    top = sorted(np.flatnonzero(P[:, 1] == 1), key=lambda i: P[i, 0])
    runs = {b: (solve_external(mesh, material, left, (right, P[right] + [0.5, 1.0]), backend=b, tol=1e-10),
                solve_internal(mesh, material, [Muscle(top[2:-2])], [0.2], muscle_model="springs", backend=b),
                solve_internal(mesh, material, [Muscle(top[2:-2])], [0.3], muscle_model="cable", backend=b))
            for b in ("ipopt", "ipopt-symbolic")}
    for num, sym in zip(runs["ipopt"], runs["ipopt-symbolic"]):
        assert num.success and sym.success and num.iterations == sym.iterations
        assert num.energy == pytest.approx(sym.energy, rel=1e-12)
        assert np.abs(num.x - sym.x).max() < 1e-8
    assert runs["ipopt"][2].tension[0] == pytest.approx(runs["ipopt-symbolic"][2].tension[0], rel=1e-8)
    assert get_model(mesh, material).is_numeric  # the default path really is the numeric one here


def _step_tolerances(monkeypatch) -> list:
    """The tolerance of every load step's solve, in order, as load stepping asks for it."""
    import mdsr_opt.mechanics.loadsteps as loadsteps

    tols = []
    real = loadsteps.minimize

    def spy(*args, **kw):
        tols.append(kw["tol"])
        return real(*args, **kw)

    monkeypatch.setattr(loadsteps, "minimize", spy)
    return tols


def test_load_steps_before_the_last_use_the_looser_tolerance_and_reach_the_same_state(monkeypatch):
    """A 32 x 8 strip with 4 grid-row ropes at 35 %: two load steps. The first is solved to
    loadsteps.INTERNAL_INTERMEDIATE_TOL, the last to the solve's own tolerance; the equilibrium is the one every
    step at the solve's tolerance reaches."""
    import mdsr_opt.mechanics.loadsteps as loadsteps

    nx, ny = 32, 8
    mesh = Mesh.rectangle(4.0, 1.0, nx, ny)
    h = nx // 2

    def row(j, i0, i1):
        return Muscle([j * (nx + 1) + i for i in range(i0, i1 + 1)])

    mus = [row(0, 1, h), row(ny, h, nx - 1), row(0, h, nx - 1), row(ny, 1, h)]
    tols = _step_tolerances(monkeypatch)
    res = solve_internal(mesh, NeoHookean(1.0, 0.3), mus, [0.35] * 4, tol=1e-10, align_to_rest=False)
    assert res.success and res.steps == [0.5, 1.0]
    assert tols == [loadsteps.INTERNAL_INTERMEDIATE_TOL, 1e-10] and loadsteps.INTERNAL_INTERMEDIATE_TOL > 1e-10
    monkeypatch.setattr(loadsteps, "INTERNAL_INTERMEDIATE_TOL", 0.0)  # every step at 1e-10
    ref = solve_internal(mesh, NeoHookean(1.0, 0.3), mus, [0.35] * 4, tol=1e-10, align_to_rest=False)
    assert ref.success and ref.steps == [0.5, 1.0]
    assert abs(res.energy - ref.energy) <= 1e-10 * abs(ref.energy)
    assert np.abs(res.x - ref.x).max() <= 1e-8 * mesh.size


def test_external_load_steps_before_the_last_keep_the_tighter_intermediate_tolerance(monkeypatch):
    """External driving solves its steps before the last to loadsteps.INTERMEDIATE_TOL (1e-6), not to the
    internal driving's looser one: a drag through a bifurcation passes its states on the unstable branch."""
    import mdsr_opt.mechanics.loadsteps as loadsteps

    mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    P = mesh.points
    left, right = np.flatnonzero(P[:, 0] < 1e-9), np.flatnonzero(P[:, 0] > 4 - 1e-9)
    tols = _step_tolerances(monkeypatch)
    drags = {int(i): (P[i, 0] + 12.0, P[i, 1]) for i in right}  # stretched to 4x: two load steps with 8 iterations
    res = solve_external(mesh, NeoHookean(1.0, 0.3), left, drags, tol=1e-10, max_iter=8)
    assert res.success and res.steps == [0.5, 1.0]
    assert tols == [loadsteps.INTERMEDIATE_TOL, 1e-10]
    assert loadsteps.INTERMEDIATE_TOL == 1e-6 and loadsteps.INTERNAL_INTERMEDIATE_TOL > loadsteps.INTERMEDIATE_TOL


def test_max_iter_caps_each_solve_not_the_call_as_documented():
    """trial7: solve_internal's docstring did not say what max_iter caps. It caps every solve (each load step
    tried, the stability re-solve); the result's iterations sum them, so a tiny cap shows in many short load
    steps, not in a failure."""
    mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    bottom = Muscle([int(i) for i in np.argsort(mesh.points[:, 0]) if mesh.points[i, 1] == 0.0])
    for solve in (solve_internal, solve_external):
        doc = " ".join(solve.__doc__.split())
        assert "max_iter : iteration cap of each solve" in doc and "not of the call" in doc
    free = solve_internal(mesh, NeoHookean(1.0, 0.3), [bottom], [0.3])
    capped = solve_internal(mesh, NeoHookean(1.0, 0.3), [bottom], [0.3], max_iter=1)
    assert free.success and capped.success and capped.stable
    assert list(free.steps) == [1.0] and len(capped.steps) > 4 and capped.steps[-1] == 1.0
    assert capped.iterations > len(capped.steps) - 1 > 1  # summed over the steps: above the cap of 1
    assert np.allclose(capped.achieved, [0.3], atol=1e-9)
    assert np.abs(capped.x - free.x).max() < 1e-6 * mesh.size  # the same state, reached in small steps
