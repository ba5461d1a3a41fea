"""KKT factorisations in the mesh's order (mechanics/kkt.py): solutions and inertia against dense algebra."""

import numpy as np
import pytest
import scipy.linalg as sla
import scipy.sparse as sp

from mdsr_opt import Mesh, Muscle, NeoHookean, solve_internal
from mdsr_opt.mechanics.constrained import ConstrainedModel
from mdsr_opt.mechanics.constraints import muscle_constraints
from mdsr_opt.mechanics.equilibrium import gauge_coordinates
from mdsr_opt.mechanics.kkt import kkt_factor, kkt_inertia, kkt_order, least_squares_multipliers
from mdsr_opt.mechanics.model import get_model
from mdsr_opt.mechanics.stability import check_stability

MAT = NeoHookean(E=1.0, nu=0.3)


def _strip(nx=24, ny=6, a=(0.3, 0.1)):
    """A strip with two cable muscles solved at contractions ``a``: (mesh, model, H, free, J) at the solution,
    H the Lagrangian's Hessian, J the active constraints' Jacobian."""
    mesh = Mesh.rectangle(4.0, 1.0, nx, ny)
    P = mesh.points
    rows = [sorted(np.flatnonzero(np.isclose(P[:, 1], y)), key=lambda i: P[i, 0])[1:-1] for y in (0.0, 0.5)]
    mus = [Muscle(r) for r in rows]
    res = solve_internal(mesh, MAT, mus, list(a))
    assert res.success, res.status
    cm = ConstrainedModel(get_model(mesh, MAT), muscle_constraints(mesh, mus, None), ropes=True)
    L0 = np.array([m.rest_length(mesh) for m in mus])
    fixed = np.zeros(2 * mesh.n_nodes, dtype=bool)
    fixed[list(gauge_coordinates(mesh))] = True
    x = res.x.reshape(-1)
    p = cm.params(cm.model.params(MAT), (1 - np.asarray(a)) * L0)
    lam, taut = cm.multipliers(x, p, fixed)
    H = cm.hessian(x, cm.params(cm.model.params(MAT), (1 - np.asarray(a)) * L0, lam))
    active = np.ones(cm.n_rows, dtype=bool)
    active[:cm.n_targets] = taut
    J = cm.jacobian(x)[active]
    return mesh, cm, sp.csc_matrix(H), ~fixed, sp.csr_matrix(J)


def _reduced_eigenvalues(Hf, Jf):
    Z = sla.null_space(Jf.toarray())
    return np.linalg.eigvalsh(Z.T @ Hf.toarray() @ Z)


def test_kkt_order_puts_each_row_after_its_last_unknown():
    rng = np.random.default_rng(1)
    J = sp.random(5, 30, density=0.15, random_state=2, format="csr")
    order = rng.permutation(30)
    perm = kkt_order(J, order)
    assert sorted(perm.tolist()) == list(range(35))
    where = np.empty(35, dtype=int)
    where[perm] = np.arange(35)
    for r in range(5):
        cols = J.indices[J.indptr[r]:J.indptr[r + 1]]
        if len(cols):
            assert where[30 + r] > where[cols].max()
    assert [int(i) for i in perm if i < 30] == order.tolist()  # the unknowns keep the given order


def test_kkt_factor_solves_like_a_dense_solve():
    mesh, cm, H, free, J = _strip()
    Hf, Jf = H[free][:, free], J[:, free]
    order = cm.model.free_ordering(free)
    fac = kkt_factor(Hf, Jf, order)
    K = sp.bmat([[Hf, Jf.T], [Jf, None]]).toarray()
    b = np.random.default_rng(0).standard_normal(K.shape[0])
    ref = np.linalg.solve(K, b)
    assert np.abs(fac.solve(b) - ref).max() <= 1e-9 * np.abs(ref).max()
    # without an order (SuperLU's COLAMD) the same solution
    assert np.abs(kkt_factor(Hf, Jf).solve(b) - ref).max() <= 1e-9 * np.abs(ref).max()


def test_least_squares_multipliers_match_a_dense_least_squares_fit():
    mesh = Mesh.rectangle(4.0, 1.0, 24, 6)
    P = mesh.points
    mus = [Muscle(sorted(np.flatnonzero(np.isclose(P[:, 1], y)), key=lambda i: P[i, 0])[1:-1]) for y in (0.0, 0.5)]
    mc = muscle_constraints(mesh, mus, 0.4)
    assert mc.n_rigid > 20  # anchor patches: rows sharing their reference nodes
    rng = np.random.default_rng(3)
    x = (P + 0.01 * rng.standard_normal(P.shape)).reshape(-1)
    free = np.ones(2 * mesh.n_nodes, dtype=bool)
    free[list(gauge_coordinates(mesh))] = False
    Jf = sp.csr_matrix(mc.jacobian(x))[:, free]
    for g in (rng.standard_normal(Jf.shape[1]), np.zeros(Jf.shape[1])):
        ref = np.linalg.lstsq(Jf.T.toarray(), -g, rcond=None)[0]
        lam = least_squares_multipliers(Jf, g)
        assert lam is not None and np.abs(lam - ref).max() <= 1e-10 * max(np.abs(ref).max(), 1.0)
    # columns all shared by several rows (no row can be paired with a column of its own): still the fit
    D = sp.csr_matrix(rng.standard_normal((4, 6)))
    g = rng.standard_normal(6)
    lam = least_squares_multipliers(D, g)
    assert np.allclose(lam, np.linalg.lstsq(D.T.toarray(), -g, rcond=None)[0], atol=1e-10)
    # a dependent row: None (the caller's normal equations then), or a least-squares solution all the same
    Dd = sp.vstack([D, D[0] + D[1]]).tocsr()
    lam = least_squares_multipliers(Dd, g)
    assert lam is None or np.abs(Dd @ (g + Dd.T @ lam)).max() <= 1e-8 * np.abs(g).max()


@pytest.mark.parametrize("shift", [0.0, -1.0, -3.0])
def test_kkt_inertia_counts_the_negative_eigenvalues_on_the_constraints_null_space(shift):
    mesh, cm, H, free, J = _strip()
    Hf, Jf = H[free][:, free], J[:, free]
    Hs = (Hf + shift * float(abs(Hf.diagonal()).mean()) * 1e-2 * sp.identity(Hf.shape[0])).tocsc()
    w = _reduced_eigenvalues(Hs, Jf)
    got = kkt_inertia(Hs, Jf, cm.model.free_ordering(free))
    assert got is not None
    assert got == (int((w < 0).sum()), 0)
    if shift == 0.0:
        assert got == (0, 0) and w.min() > 0  # the solved state is a strict minimum
    else:
        assert got[0] > 0


def test_the_constrained_stability_check_gives_the_same_verdict_with_and_without_the_order():
    mesh, cm, H, free, J = _strip(a=(0.4, 0.05))
    order = cm.model.free_ordering(free)
    for shift in (0.0, -0.02, -0.1):
        Hs = (H + shift * float(abs(H.diagonal()).mean()) * sp.identity(H.shape[0])).tocsc()
        fast = check_stability(Hs, free, J, order=order)
        slow = check_stability(Hs, free, J)
        assert fast.stable == slow.stable, (shift, fast, slow)
        if fast.stable:
            assert fast.method == "kkt-inertia"
        else:
            assert fast.n_negative == slow.n_negative and fast.direction is not None


def test_a_bad_order_is_refused():
    mesh, cm, H, free, J = _strip(nx=8, ny=2)
    with pytest.raises(ValueError, match="permutation"):
        check_stability(H, free, J, order=np.zeros(int(free.sum()), dtype=int))
