"""check_stability: inertia of a sparse symmetric factorisation against dense eigenvalues."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sl
import scipy.sparse as sp

from mdsr_opt import Mesh, NeoHookean, get_model
from mdsr_opt.mechanics.stability import StabilityCheck, check_stability


def _random_case(rng, n, n_neg, sparse_band=None):
    Q = np.linalg.qr(rng.standard_normal((n, n)))[0]
    lam = rng.uniform(0.1, 3.0, n)
    lam[:n_neg] *= -1
    return Q @ np.diag(lam) @ Q.T


def test_unconstrained_random_matches_dense_eigenvalues():
    rng = np.random.default_rng(1)
    for _ in range(60):
        n = int(rng.integers(2, 40))
        H = _random_case(rng, n, int(rng.integers(0, 4)))
        free = rng.random(n) > 0.25
        if not free.any():
            continue
        ev = np.linalg.eigvalsh(H[np.ix_(free, free)])
        if np.abs(ev).min() < 1e-6:
            continue
        c = check_stability(sp.csc_matrix(H), free)
        assert isinstance(c, StabilityCheck)
        assert c.n_negative == int((ev < 0).sum())
        assert c.stable == bool(ev.min() > 0)
        if c.stable:
            assert c.direction is None
        else:
            d = c.direction
            assert d.shape == (n,) and np.allclose(d[~free], 0.0)
            assert abs(np.linalg.norm(d) - 1) < 1e-12
            assert d @ H @ d < 0 and abs(d @ H @ d - c.curvature) < 1e-10


def test_direction_is_close_to_the_lowest_mode():
    rng = np.random.default_rng(2)
    for _ in range(20):
        n = int(rng.integers(5, 40))
        H = _random_case(rng, n, int(rng.integers(1, 4)))
        c = check_stability(sp.csc_matrix(H), np.ones(n, bool))
        lmin = np.linalg.eigvalsh(H)[0]
        assert c.curvature <= 0.9 * lmin  # within 10 % of the most negative curvature


def test_constrained_random_matches_dense_reduced_hessian():
    rng = np.random.default_rng(3)
    checked = 0
    for _ in range(120):
        n = int(rng.integers(4, 30))
        H = _random_case(rng, n, int(rng.integers(0, 4)))
        free = rng.random(n) > 0.2
        m = int(rng.integers(1, 4))
        A = rng.standard_normal((m, n))
        Af = A[:, free]
        if Af.shape[1] <= m or np.linalg.matrix_rank(Af) < m:
            continue
        Z = sl.null_space(Af)
        ev = np.linalg.eigvalsh(Z.T @ H[np.ix_(free, free)] @ Z)
        if np.abs(ev).min() < 1e-6:
            continue
        c = check_stability(sp.csc_matrix(H), free, sp.csr_matrix(A))
        assert c.method == "ldl-inertia+finsler"
        assert c.n_negative == int((ev < 0).sum())
        assert c.stable == bool(ev.min() > 0)
        if not c.stable:
            d = c.direction
            assert np.abs(A @ d).max() < 1e-8  # tangent to the constraints
            assert d @ H @ d < 0
        checked += 1
    assert checked > 50


def test_constraint_makes_an_indefinite_hessian_stable():
    # H = diag(1, -1): a saddle; constraining the second coordinate to move with... nothing free (A = e2)
    H = sp.csc_matrix(np.diag([1.0, -1.0, 2.0]))
    free = np.ones(3, bool)
    assert not check_stability(H, free).stable
    A = sp.csr_matrix(np.array([[0.0, 1.0, 0.0]]))
    c = check_stability(H, free, A)
    assert c.stable and c.n_negative == 0
    # a constraint not removing the negative direction keeps it a saddle
    c2 = check_stability(H, free, sp.csr_matrix(np.array([[1.0, 0.0, 0.0]])))
    assert not c2.stable and c2.n_negative == 1 and abs(c2.direction[1]) == pytest.approx(1.0)


def test_singular_reports_zero_pivots():
    H = sp.csc_matrix(np.diag([1.0, 0.0, 2.0]))
    c = check_stability(H, np.ones(3, bool))
    assert not c.stable and c.n_negative == 0 and c.n_zero == 1
    assert c.method.startswith("shifted")
    assert abs(c.direction[1]) == pytest.approx(1.0)


def test_no_free_coordinate_is_stable():
    c = check_stability(sp.identity(4, format="csc"), np.zeros(4, bool))
    assert c.stable and c.n_negative == 0


def _clamped_strip():
    """A 10 x 1 strip (40 x 4 cells) with both ends clamped: mesh, material, rest points, free mask, model."""
    mesh = Mesh.rectangle(10.0, 1.0, 40, 4)
    mat = NeoHookean(1.0, 0.3)
    P = mesh.points
    fixed_nodes = np.flatnonzero((P[:, 0] == 0.0) | (P[:, 0] == 10.0))
    free = np.ones(2 * mesh.n_nodes, bool)
    free[2 * fixed_nodes] = free[2 * fixed_nodes + 1] = False
    return mesh, mat, P, free, get_model(mesh, mat)


def test_real_mesh_compressed_strip_inertia_matches_dense():
    """The straight strip compressed by 20 % (a saddle) and the strip at rest (a minimum)."""
    mesh, mat, P, free, model = _clamped_strip()
    p = model.params(mat)
    # homogeneous compression x -> 0.8 x: the straight state (an equilibrium up to the Poisson bulge)
    x = P.copy()
    x[:, 0] *= 0.8
    for state in (P, x):
        H = model.hessian(state.reshape(-1), p)
        ev = np.linalg.eigvalsh(H[free][:, free].toarray())
        c = check_stability(H, free)
        assert c.n_negative == int((ev < 0).sum())
        assert c.stable == bool(ev[0] > 0)
    assert not c.stable and c.n_negative >= 1
    assert c.curvature == pytest.approx(ev[0], rel=0.05)  # the lowest (buckling) mode


@pytest.mark.parametrize("bad, exc, words", [
    (dict(H="x"), TypeError, "H must be a scipy sparse"),
    (dict(free=np.ones(3)), ValueError, "free must be a boolean mask"),
    (dict(A=sp.csr_matrix(np.ones((1, 2)))), ValueError, "A must have 3 columns"),
    (dict(rtol=-1.0), ValueError, "rtol must be"),
])
def test_bad_input(bad, exc, words):
    kw = dict(H=sp.identity(3, format="csc"), free=np.ones(3, bool), A=None, rtol=1e-10)
    kw.update(bad)
    with pytest.raises(exc, match=words):
        check_stability(kw["H"], kw["free"], kw["A"], rtol=kw["rtol"])


def test_lowest_eigenvalue_estimate_when_stable():
    rng = np.random.default_rng(5)
    for m in (0, 2):  # small (dense path)
        H = _random_case(rng, 30, 0)
        A = sp.csr_matrix(rng.standard_normal((m, 30))) if m else None
        c = check_stability(sp.csc_matrix(H), np.ones(30, bool), A, lowest=True)
        R = H if not m else sl.null_space(A.toarray()).T @ H @ sl.null_space(A.toarray())
        assert c.stable and c.curvature == pytest.approx(np.linalg.eigvalsh(R)[0], rel=1e-8)


def test_lowest_eigenvalue_estimate_on_a_mesh():
    """LOBPCG preconditioned by the factor, on a real stiffness matrix (with and without constraints)."""
    mesh = Mesh.rectangle(4.0, 1.0, 24, 6)
    mat = NeoHookean(1.0, 0.3)
    model = get_model(mesh, mat)
    H = model.hessian(mesh.points.reshape(-1), model.params(mat))
    free = np.ones(2 * mesh.n_nodes, bool)
    left = np.flatnonzero(mesh.points[:, 0] == 0.0)
    free[2 * left] = free[2 * left + 1] = False
    Hff = H[free][:, free].toarray()
    A = sp.random(3, H.shape[0], density=0.05, random_state=1, format="csr")
    Z = sl.null_space(A.toarray()[:, free])
    for AA, R in ((None, Hff), (A, Z.T @ Hff @ Z)):
        c = check_stability(H, free, AA, lowest=True)
        lmin = np.linalg.eigvalsh(R)[0]
        assert c.stable and c.curvature == pytest.approx(lmin, rel=1e-3)


def test_dependent_constraint_rows_are_reduced():
    rng = np.random.default_rng(7)
    H = _random_case(rng, 20, 2)
    A = rng.standard_normal((4, 20))
    A[3] = A[0] - 2 * A[1]  # dependent
    Z = sl.null_space(A)
    ev = np.linalg.eigvalsh(Z.T @ H @ Z)
    c = check_stability(sp.csc_matrix(H), np.ones(20, bool), sp.csr_matrix(A))
    assert c.n_negative == int((ev < 0).sum())
    if not c.stable:
        assert np.abs(A @ c.direction).max() < 1e-8


@pytest.mark.parametrize("m", [0, 2])
def test_lowest_when_unstable_is_the_lowest_eigenpair(m):
    """On a real (indefinite) mesh Hessian: the compressed strip, large enough for the LOBPCG path."""
    mesh, mat, P, free, model = _clamped_strip()
    x = P.copy()
    x[:, 0] *= 0.8
    H = model.hessian(x.reshape(-1), model.params(mat))
    A = sp.random(m, H.shape[0], density=0.05, random_state=3, format="csr") if m else None
    Z = np.eye(free.sum()) if not m else sl.null_space(A.toarray()[:, free])
    lmin = np.linalg.eigvalsh(Z.T @ H[free][:, free].toarray() @ Z)[0]
    c = check_stability(H, free, A, lowest=True)
    assert not c.stable and lmin < 0
    assert c.curvature == pytest.approx(lmin, rel=1e-4)
    d = c.direction
    assert d @ H @ d == pytest.approx(c.curvature, rel=1e-10)
    if m:
        assert np.abs(A @ d).max() < 1e-8


def test_finsler_penalty_below_threshold_is_not_mistaken_for_a_saddle():
    """H = [[eps, 1], [1, 0]] with the second coordinate constrained: Z'HZ = eps > 0, but H + rho A'A is
    indefinite until rho > 1/eps; the first rho (1e4 * max diag / |A|^2 = 10) is too small, the third
    (1e5) is enough."""
    eps = 1e-3
    H = sp.csc_matrix(np.array([[eps, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, eps]]))
    A = sp.csr_matrix(np.array([[0.0, 1.0, 0.0]]))
    c = check_stability(H, np.ones(3, bool), A)
    assert c.stable and c.n_negative == 0 and "uncertified" not in c.method
    # and a real saddle on the tangent space is certified as one
    H2 = sp.csc_matrix(np.array([[-eps, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, eps]]))
    c2 = check_stability(H2, np.ones(3, bool), A)
    assert not c2.stable and c2.n_negative == 1 and c2.curvature == pytest.approx(-eps)
    assert abs(c2.direction[1]) < 1e-12


def test_given_ordering_gives_the_same_answer_and_direction():
    # the mesh's fill-reducing ordering (EnergyModel.free_ordering) replaces SuperLU's own: the same inertia;
    # the direction (mapped back to the original coordinates) is refined from other pivots, so it is close
    # to, not equal to, the one without the ordering: both near the lowest mode
    mesh, mat, P, free, model = _clamped_strip()
    order = model.free_ordering(free)
    assert np.array_equal(np.sort(order), np.arange(free.sum())) and not np.array_equal(order, np.sort(order))
    x = P.copy()
    x[:, 0] *= 0.8  # a saddle
    H = model.hessian(x.reshape(-1), model.params(mat))
    a, b = check_stability(H, free), check_stability(H, free, order=order)
    assert (a.stable, a.n_negative, a.n_zero) == (b.stable, b.n_negative, b.n_zero) == (False, a.n_negative, 0)
    ev = np.linalg.eigvalsh(H[free][:, free].toarray())
    assert b.curvature == pytest.approx(ev[0], rel=0.05) and a.curvature == pytest.approx(ev[0], rel=0.05)
    v = b.direction
    assert float(v @ (H @ v)) == pytest.approx(b.curvature, rel=1e-9) and b.curvature < 0
    assert np.all(b.direction[~free] == 0.0)
    with pytest.raises(ValueError, match="order must be a permutation"):
        check_stability(H, free, order=order[:-1])
