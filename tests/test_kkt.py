"""KKT factorisations in the mesh's order (mechanics/kkt.py): solutions and inertia against dense algebra."""

import numpy as np
import pytest
import scipy.linalg as sla
import scipy.sparse as sp

from mdsr_opt import Mesh, Muscle, NeoHookean, solve_internal
from mdsr_opt.mechanics.constrained import ConstrainedModel
from mdsr_opt.mechanics.constraints import muscle_constraints
from mdsr_opt.mechanics.equilibrium import gauge_coordinates
from mdsr_opt.mechanics.kkt import kkt_factor, kkt_inertia, kkt_order
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
