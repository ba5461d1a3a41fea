"""The muscle constraints' closed forms (numpy) against their CasADi functions, and the shared cache."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from mdsr_opt import Mesh, Muscle
from mdsr_opt.mechanics.constraints import MuscleConstraints, muscle_constraints


def _muscles(mesh):
    P = mesh.points
    bottom = [int(i) for i in np.argsort(P[:, 0]) if P[i, 1] == 0.0]
    side = [int(i) for i in np.argsort(P[:, 1]) if P[i, 0] == P[:, 0].max()][1:]
    top = [int(i) for i in np.argsort(P[:, 0]) if P[i, 1] == P[:, 1].max()][2:7]
    return [Muscle(bottom + side), Muscle(top)]


@pytest.mark.parametrize("radius", [0.0, 0.3])
def test_numeric_rows_jacobian_hessian_equal_the_casadi_functions(radius):
    mesh = Mesh.rectangle(2.0, 1.0, 8, 4)
    mc = MuscleConstraints(mesh, _muscles(mesh), radius=radius)
    assert (mc.n_rigid > 0) == (radius > 0)
    assert mc.linear_rows.sum() == mc.n_rigid - len(mc.groups)  # one scale row per group is nonlinear
    rng = np.random.default_rng(3)
    x = (mesh.points + 0.05 * rng.standard_normal(mesh.points.shape)).reshape(-1)
    lam = rng.standard_normal(mc.n_constraints)
    xs, ls = ca.SX.sym("x", len(x)), ca.SX.sym("lam", mc.n_constraints)
    f = ca.Function("f", [xs, ls], [mc.constraints_expr(xs), mc.jacobian_expr(xs), mc.hessian_expr(xs, ls)])
    g, J, Hu = (np.array(ca.DM(v)) for v in f(x, lam))
    H = np.triu(Hu) + np.triu(Hu, 1).T
    assert np.abs(mc.values(x) - g.ravel()).max() < 1e-14
    assert np.abs(mc.jacobian(x).toarray() - J).max() < 1e-14
    assert np.abs(mc.hessian(x, lam).toarray() - H).max() < 1e-12
    assert np.abs(H).max() > 0.1  # the ropes' curvature is exercised
    # the rows split as P nl(xl) + Lin xl, the linear rows exactly linear
    nl, Pm, Lin = mc.symbolic_parts()
    xl = x[mc.dofs]
    assert np.abs(Pm @ np.array(ca.DM(nl(xl))).ravel() + Lin @ xl - mc.values(x)).max() < 1e-14
    assert Lin[~mc.linear_rows].nnz == 0
    xl2 = xl + rng.standard_normal(len(xl))
    lin = mc.linear_rows
    assert lin.any() == (radius > 0)  # patches of more than two nodes have linear rows
    if lin.any():
        assert np.abs(mc.local_values(xl2)[lin] - Lin[lin] @ xl2).max() < 1e-13
    # MX arguments give the same rows (the equilibrium NLP builds them in MX)
    xm = ca.MX.sym("x", len(x))
    gm = ca.Function("gm", [xm], [mc.constraints_expr(xm)])(x)
    assert np.abs(np.array(gm).ravel() - mc.values(x)).max() < 1e-14
    with pytest.raises(ValueError, match="lam must have"):
        mc.hessian(x, lam[:-1])


@pytest.mark.parametrize("radius", [0.0, 0.3])
def test_third_derivative_and_hessian_products_of_the_rows(radius):
    """``local_third_entries`` against central differences of ``local_hessian`` along ``v`` (error O(h^2));
    ``local_hessian_product_entries`` against each row's Hessian times ``v``."""
    import scipy.sparse as sp

    mesh = Mesh.rectangle(2.0, 1.0, 8, 4)
    mc = MuscleConstraints(mesh, _muscles(mesh), radius=radius)
    rng = np.random.default_rng(5)
    nl, nr = mc.n_local, mc.n_constraints
    xl = (mesh.points + 0.05 * rng.standard_normal(mesh.points.shape)).reshape(-1)[mc.dofs]
    lam, v = rng.standard_normal(nr), rng.standard_normal(nl)
    r, c, t = mc.local_third_entries(xl, lam, v)
    T = sp.csr_matrix((t, (r, c)), shape=(nl, nl)).toarray()
    h = 1e-5
    fd = (mc.local_hessian(xl + h * v, lam) - mc.local_hessian(xl - h * v, lam)).toarray() / (2 * h)
    assert np.abs(T - fd).max() < 1e-7 * np.abs(T).max() and np.abs(T - T.T).max() < 1e-14
    assert np.abs(T).max() > 1.0  # the ropes' third derivative is exercised
    r2, c2, _ = mc.local_third_entries(xl + 1.0, 2 * lam, -v)  # rows and columns do not depend on the values
    assert np.array_equal(r, r2) and np.array_equal(c, c2)
    r, c, pv = mc.local_hessian_product_entries(xl, v)
    M = sp.csr_matrix((pv, (r, c)), shape=(nl, nr)).toarray()
    ref = np.column_stack([mc.local_hessian(xl, np.eye(nr)[i]) @ v for i in range(nr)])
    assert np.abs(M - ref).max() < 1e-13 * np.abs(ref).max()
    assert (np.abs(ref).max(axis=0) > 0).sum() == mc.n_muscles + (len(mc.groups) if radius else 0)


def test_muscle_constraints_are_cached_per_mesh_muscles_and_radius():
    mesh = Mesh.rectangle(2.0, 1.0, 8, 4)
    mus = _muscles(mesh)
    a = muscle_constraints(mesh, mus, 0.12)
    assert muscle_constraints(mesh, [Muscle(m.nodes) for m in mus], 0.12) is a  # same chains: same object
    assert muscle_constraints(mesh, mus, 0.3) is not a
    assert muscle_constraints(mesh, mus[:1], 0.12).n_muscles == 1
    other = Mesh.rectangle(2.0, 1.0, 8, 4)
    assert muscle_constraints(other, mus, 0.12) is not a
    np.testing.assert_array_equal(muscle_constraints(other, mus, 0.12).dofs, a.dofs)
