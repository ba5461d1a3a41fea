"""Quadratic (6-node) triangles of the virtual prototype (mdsr_opt.mechanics.quadratic, quadsolve): derivatives,
the patch test, and convergence at the expected order on a bending case."""

from __future__ import annotations

import numpy as np
import pytest

from mdsr_opt import Mesh, NeoHookean
from mdsr_opt.body.material import LinearElastic
from mdsr_opt.mechanics.quadratic import QuadraticModel, extend_prescribed, split_mesh
from mdsr_opt.mechanics.quadsolve import solve_quadratic_external

MAT = NeoHookean(1.0, 0.3, thickness=0.7)


@pytest.fixture(scope="module")
def patch_mesh():
    """An unstructured mesh of a 2 x 1 rectangle (straight edges for the traction check)."""
    return Mesh.from_polygon([[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0]], max_area=0.05)


@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize("material", [MAT, LinearElastic(2.0, 0.4, thickness=0.5),
                                      NeoHookean(1.5, 0.49, thickness=0.3, plane="stress")])  # the prototype's
def test_derivatives_agree_with_casadi_and_finite_differences(order, material):
    mesh = Mesh.rectangle(2.0, 1.0, 3, 2)
    fast, ref = QuadraticModel(mesh, material, order), QuadraticModel(mesh, material, order, numeric=False)
    assert fast.numeric and not ref.numeric
    rng = np.random.default_rng(order)
    x = fast.points + 0.05 * rng.standard_normal(fast.points.shape)
    e, g, K = fast.evaluate(x)
    e2, g2, K2 = ref.evaluate(x)
    assert e == pytest.approx(e2, rel=1e-12) and np.abs(g - g2).max() < 1e-12 and abs(K - K2).max() < 1e-10
    d, h = rng.standard_normal(x.size), 1e-6
    ep, gp = fast.energy_gradient(x.ravel() + h * d)
    em, gm = fast.energy_gradient(x.ravel() - h * d)
    assert (ep - em) / (2 * h) == pytest.approx(g @ d, rel=1e-7)
    assert np.abs((gp - gm) / (2 * h) - K @ d).max() < 1e-7 * np.abs(K @ d).max()


@pytest.mark.parametrize("numeric", [True, False])
def test_gradient_without_the_energy_is_the_same_gradient_and_hessian(numeric):
    model = QuadraticModel(Mesh.rectangle(2.0, 1.0, 3, 2), NeoHookean(1.5, 0.49, thickness=0.3, plane="stress"),
                           numeric=numeric)
    x = model.points + 0.05 * np.random.default_rng(3).standard_normal(model.points.shape)
    e, g, K = model.evaluate(x)
    e2, g2, K2 = model.evaluate(x, energy=False)
    assert e2 is None and np.isfinite(e) and e > 0
    assert np.array_equal(g, g2) and np.array_equal(K.toarray(), K2.toarray())
    assert np.array_equal(model.gradient(x), model.energy_gradient(x)[1]) and np.array_equal(model.gradient(x), g)


def test_split_mesh_and_quadratic_nodes_are_the_same_nodes():
    mesh = Mesh.rectangle(2.0, 1.0, 3, 2)
    model, fine = QuadraticModel(mesh, MAT, 2), split_mesh(mesh)
    assert fine.n_nodes == model.n_nodes == mesh.n_nodes + len(mesh.edges)
    assert fine.n_triangles == 4 * mesh.n_triangles and fine.area == pytest.approx(mesh.area, rel=1e-14)
    np.testing.assert_array_equal(fine.points, model.points)
    np.testing.assert_array_equal(fine.points[:mesh.n_nodes], mesh.points)
    # every element's midpoint nodes sit at the middle of its edges
    P, T = model.points, model.elements
    for k, (a, b) in enumerate([(0, 1), (1, 2), (2, 0)]):
        np.testing.assert_allclose(P[T[:, 3 + k]], 0.5 * (P[T[:, a]] + P[T[:, b]]), atol=1e-15)
    # prescribed nodes carried over: midpoints between anchors anchored, between drags dragged halfway
    anc, dn, dp = extend_prescribed(mesh, [0, 1], [3, 7], [[9.0, 0.0], [9.0, 2.0]])
    mid01 = mesh.n_nodes + mesh.edge_rows(0, 1)
    assert mid01 in anc and len(anc) == 3
    mid37 = mesh.n_nodes + mesh.edge_rows(3, 7)
    assert mid37 in dn and np.allclose(dp[list(dn).index(mid37)], [9.0, 1.0])


@pytest.mark.parametrize("order", [1, 2])
def test_patch_test_reproduces_an_affine_state_with_zero_residual(patch_mesh, order):
    """Boundary nodes moved by an affine map: the interior nodes follow it exactly, the residual at the
    affine state vanishes on the free nodes, and the boundary reactions are the consistent loads of the
    homogeneous stress P: on the right edge they sum to P N times its length, and a midpoint node of a
    quadratic edge carries 2/3 of its edge's load (the vertices 1/6 each)."""
    model = QuadraticModel(patch_mesh, MAT, order)
    A, b = np.array([[1.2, 0.15], [-0.1, 0.9]]), np.array([0.3, -0.2])
    P0 = model.points
    bnd = model.display_mesh.boundary_nodes
    inner = np.setdiff1d(np.arange(model.n_nodes), bnd)
    assert len(inner) > 10
    res = solve_quadratic_external(model, [], bnd, P0[bnd] @ A.T + b, tol=1e-12)
    assert res.success, res.status
    np.testing.assert_allclose(res.x, P0 @ A.T + b, atol=1e-11)
    _e, g, _K = model.evaluate(P0 @ A.T + b)
    g = g.reshape(-1, 2)
    assert np.abs(g[inner]).max() < 1e-12
    Pk = MAT.stress_tangent(A[:, :, None], *MAT.params, tangent=False)[0][:, :, 0]  # per unit rest area x t
    right = bnd[P0[bnd, 0] > 2.0 - 1e-12]
    np.testing.assert_allclose(g[right].sum(0), Pk @ [1.0, 0.0] * 1.0, rtol=1e-12)
    if order == 2:
        mid_right = right[right >= patch_mesh.n_nodes]
        E = patch_mesh.edges[mid_right - patch_mesh.n_nodes]
        length = np.linalg.norm(P0[E[:, 1]] - P0[E[:, 0]], axis=1)
        np.testing.assert_allclose(g[mid_right], (2.0 / 3.0) * length[:, None] * (Pk @ [1.0, 0.0]), rtol=1e-10)


def _bend(P, k=0.25, W=4.0, H=1.0):
    """A bending map of the strip [0, W] x [0, H], quadratic in the coordinates."""
    X, Y = P[:, 0] - W / 2, P[:, 1] - H / 2
    return P + k * np.column_stack([-X * Y, X ** 2 / 2])


def test_convergence_order_on_a_bending_strip():
    """A 4 x 1 Neo-Hookean strip bent by its whole outline (a displacement quadratic in the coordinates,
    which both elements interpolate on the boundary up to O(h^2) for P1, exactly for P2). Measured against
    a quadratic-element reference on 64 x 16 cells, on meshes of 8 x 2, 16 x 4 and 32 x 8 cells (each a
    split of the one before): the energy error |E_h - E_ref| and the largest displacement error at the
    nodes of the 8 x 2 mesh. Expected rates in h: energy 2p (P1: 2, P2: 4), nodal displacement p + 1
    (P1: 2, P2: 3); asserted loosely (the reference one level finer than the last mesh caps the measured
    P2 energy rate near 3.3)."""
    meshes = [Mesh.rectangle(4.0, 1.0, 8, 2)]
    for _ in range(3):
        meshes.append(split_mesh(meshes[-1]))

    def solve(mesh, order):
        model = QuadraticModel(mesh, MAT, order)
        bnd = model.display_mesh.boundary_nodes
        res = solve_quadratic_external(model, [], bnd, _bend(model.points[bnd]))
        assert res.success, res.status
        return model.energy(res.x), res.x

    e_ref, x_ref = solve(meshes[3], 2)
    n1 = meshes[0].n_nodes
    rates, errors = {}, {}
    for order in (1, 2):
        err = []
        for mesh in meshes[:3]:
            e, x = solve(mesh, order)
            err.append((abs(e - e_ref), np.abs(x[:n1] - x_ref[:n1]).max()))
        err = np.array(err)
        errors[order] = err
        rates[order] = np.log2(err[:-1] / err[1:])
    assert (rates[1][:, 0] > 1.6).all() and rates[1][-1, 1] > 1.4      # P1: energy -> h^2, displacement -> h^2
    assert (rates[2][:, 0] > 3.0).all() and (rates[2][:, 1] > 2.5).all()  # P2: energy ~h^4, displacement ~h^3
    assert (errors[2] < 0.1 * errors[1]).all()                          # far smaller at every mesh


def test_bad_input_is_refused():
    mesh = Mesh.rectangle(2.0, 1.0, 2, 1)
    with pytest.raises(ValueError, match="order must be 1"):
        QuadraticModel(mesh, MAT, order=3)
    with pytest.raises(TypeError, match="psi_expr"):
        QuadraticModel(mesh, object())
    with pytest.raises(TypeError, match="must be a Mesh"):
        split_mesh(mesh.points)
    model = QuadraticModel(mesh, MAT)
    with pytest.raises(ValueError, match="at least two fixed nodes"):
        solve_quadratic_external(model, [0], [], np.zeros((0, 2)))
    with pytest.raises(ValueError, match="out of range|must lie in"):
        solve_quadratic_external(model, [0, 99], [], np.zeros((0, 2)))
    with pytest.raises(ValueError, match="shape"):
        model.energy(np.zeros((3, 2)))


def test_hessian_assembled_into_its_precomputed_pattern_equals_the_summed_element_blocks():
    """QuadraticModel.evaluate sums the element Hessians into a CSR pattern computed once per mesh: the same
    matrix as summing the blocks entry by entry (COO), sorted, with no duplicate entries."""
    import scipy.sparse as sp

    mesh = Mesh.rectangle(2.0, 1.0, 5, 3)
    model = QuadraticModel(mesh, MAT)
    x = model.points + 0.05 * np.sin(3.0 * model.points[:, ::-1])
    _e, _g, K = model.evaluate(x)
    H = model._evaluate(x)[2]
    dofs = np.stack([2 * model.elements, 2 * model.elements + 1], axis=2).reshape(len(model.elements), -1)
    k = dofs.shape[1]
    ref = sp.coo_matrix((H.ravel(), (np.repeat(dofs, k, axis=1).ravel(), np.tile(dofs, (1, k)).ravel())),
                        shape=K.shape).tocsr()
    assert K.has_canonical_format and K.nnz == ref.nnz
    assert abs(K - ref).max() <= 1e-14 * abs(ref).max()


def test_transfer_state_carries_an_affine_state_exactly_inside_and_outside_the_mesh():
    """transfer_state interpolates the displacement linearly: an affine state of one mesh arrives exactly at
    the nodes of another mesh of the body and at points just outside it (a boundary meshed differently)."""
    from mdsr_opt.mechanics.quadratic import transfer_state

    coarse = Mesh.rectangle(2.0, 1.0, 4, 2)
    A, b = np.array([[1.1, 0.3], [-0.2, 0.9]]), np.array([0.5, -0.25])
    pts = np.vstack([QuadraticModel(Mesh.rectangle(2.0, 1.0, 7, 5), MAT).points, [[2.02, 0.5], [-0.01, -0.01]]])
    out = transfer_state(coarse, coarse.points @ A.T + b, pts)
    assert np.abs(out - (pts @ A.T + b)).max() < 1e-12
    with pytest.raises(ValueError, match="x must be"):
        transfer_state(coarse, pts, pts)
    with pytest.raises(ValueError, match="points must be"):
        transfer_state(coarse, coarse.points, pts[:, :1])


def test_vertex_jacobians_see_a_curved_edge_fold_the_quadrature_points_miss():
    mesh = Mesh.rectangle(1.0, 1.0, 2, 2)
    model = QuadraticModel(mesh, MAT, 2)
    x = model.points.copy()
    e = 0
    a, b = model.elements[e][:2]
    mid = model.elements[e][3:]
    # the midpoint node of edge (a, b) slid along it by 0.3 of its length: x(t) along the edge has
    # slope 1 + 4 (0.3) (1 - 2t), negative at b (t = 1), positive at the quadrature points
    k = [m for m in mid if np.allclose(model.points[m], 0.5 * (model.points[a] + model.points[b]))][0]
    x[k] = model.points[k] + 0.3 * (model.points[b] - model.points[a])
    jv, jq = model.vertex_jacobians(x)[e], model.jacobians(x)[e]
    assert jq.min() > 0.1 and jv.min() == pytest.approx(-0.2, abs=1e-9)  # folded at a vertex only
    assert not model.upright(x)
    np.testing.assert_allclose(model.vertex_jacobians(model.points), 1.0, rtol=1e-12)
    lin = QuadraticModel(mesh, MAT, 1)
    np.testing.assert_allclose(lin.vertex_jacobians(lin.points), lin.jacobians(lin.points)[:, :1].repeat(3, 1))


def test_a_solve_refused_by_an_inverting_step_says_which_element_and_where():
    mesh = Mesh.rectangle(1.0, 1.0, 3, 3)
    model = QuadraticModel(mesh, MAT, 2)
    n0 = mesh.n_nodes
    left = np.flatnonzero(model.points[:n0, 0] < 1e-9)
    far = int(np.flatnonzero((model.points[:n0, 0] > 1 - 1e-9) & (model.points[:n0, 1] > 1 - 1e-9))[0])
    # the top right corner dragged through the body to beyond the left side: it cannot stay upright
    res = solve_quadratic_external(model, left, [far], [[-0.5, -0.5]], min_step=1.0 / 16)
    assert not res.success
    assert "the last trial step inverted element" in res.status
    assert ("at a vertex" in res.status) or ("at a quadrature point" in res.status)


def test_an_external_solve_from_a_coarser_models_state_reaches_the_load_stepped_state():
    """guess=: the linear-element equilibrium of the same driving carried to the quadratic nodes starts one
    Newton solve at the full load (no load steps, no predictors); the same equilibrium to the tolerance in
    fewer Newton iterations. A guess that inverts an element falls back to load steps; one of the wrong
    shape is refused."""
    from mdsr_opt.mechanics.quadratic import transfer_state

    mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    coarse, model = QuadraticModel(mesh, MAT, 1), QuadraticModel(mesh, MAT, 2)
    left = np.flatnonzero(np.isclose(model.points[:, 0], 0.0))
    right = np.flatnonzero(np.isclose(model.points[:, 0], 4.0))
    turn = _bend(model.points[right], k=0.4)
    stepped = solve_quadratic_external(model, left, right, turn)
    lin = solve_quadratic_external(coarse, left[left < mesh.n_nodes], right[right < mesh.n_nodes],
                                   turn[right < mesh.n_nodes])
    guessed = solve_quadratic_external(model, left, right, turn, guess=transfer_state(mesh, lin.x, model.points))
    assert stepped.success and lin.success and guessed.success and stepped.steps > 1
    assert "predicted" in guessed.status and guessed.steps == 1 and guessed.iterations < stepped.iterations
    assert np.abs(guessed.x - stepped.x).max() < 1e-7 * mesh.size
    folded = model.points.copy()
    folded[[0, 1]] = folded[[1, 0]]
    back = solve_quadratic_external(model, left, right, turn, guess=folded)
    assert back.success and "predicted" not in back.status and np.abs(back.x - stepped.x).max() < 1e-7 * mesh.size
    with pytest.raises(ValueError, match="guess must be"):
        solve_quadratic_external(model, left, right, turn, guess=lin.x[:5])
