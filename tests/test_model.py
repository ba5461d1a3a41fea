"""Material and symbolic model: derivatives against finite differences, invariances, parameter checks."""

import casadi as ca
import numpy as np
import pytest

from mdsr_opt import LinearElastic, Mesh, MooneyRivlin, Muscle, NeoHookean, Yeoh
from mdsr_opt.mechanics.model import get_model, spring_parameters

from conftest import rotation


def _perturbed(mesh, scale=0.03, seed=0):
    x = mesh.points + scale * np.random.default_rng(seed).standard_normal(mesh.points.shape)
    assert mesh.jacobians(x).min() > 0.2
    return x


@pytest.fixture(scope="module")
def small():
    return Mesh.from_polygon([[0, 0], [2, 0], [2, 1], [0, 1]], max_area=0.08)


def test_psi_zero_at_rest_and_rotation_invariant():
    mat = NeoHookean(E=2.0, nu=0.35)
    assert mat.psi(np.eye(2)) == 0.0
    F = np.array([[1.3, 0.2], [-0.1, 0.8]])
    R = rotation(0.7)
    assert mat.psi(R @ F) == pytest.approx(mat.psi(F), rel=1e-13)
    assert mat.psi(np.diag([1.0, -1.0])) == np.inf  # inverted


def test_psi_numpy_matches_casadi():
    mat = NeoHookean(E=3.0, nu=0.2, thickness=0.5)
    F = np.array([[1.1, 0.3], [0.05, 0.95]])
    Fs = ca.SX.sym("F", 2, 2)
    f = ca.Function("psi", [Fs], [mat.psi(Fs)])
    assert float(f(F)) == pytest.approx(mat.psi(F), rel=1e-13)


def test_lame_parameters():
    mat = NeoHookean(E=10.0, nu=0.25)
    assert mat.mu == pytest.approx(4.0)
    assert mat.lam == pytest.approx(4.0)


@pytest.mark.parametrize("kwargs, err, match", [
    (dict(E=0.0, nu=0.3), ValueError, "E"),
    (dict(E=-1.0, nu=0.3), ValueError, "E"),
    (dict(E=1.0, nu=0.5), ValueError, "nu"),
    (dict(E=1.0, nu=-1.0), ValueError, "nu"),
    (dict(E=float("nan"), nu=0.3), ValueError, "finite"),
    (dict(E=1.0, nu=float("nan")), ValueError, "nu"),
    (dict(E=1.0, nu=0.3, thickness=0.0), ValueError, "thickness"),
    (dict(E="1", nu=0.3), TypeError, "E"),
])
def test_material_parameters_validated(kwargs, err, match):
    with pytest.raises(err, match=match):
        NeoHookean(**kwargs)


def test_energy_matches_numpy_sum(small):
    mat = NeoHookean(E=3.0, nu=0.3, thickness=2.0)
    model = get_model(small, mat)
    x = _perturbed(small)
    expected = float((small.areas * mat.psi(small.deformation_gradients(x))).sum())
    assert model.energy(x, model.params(mat)) == pytest.approx(expected, rel=1e-12)


def _fd_check(model, x, p, h=1e-6):
    xf = x.reshape(-1)
    E = np.eye(len(xf))
    g = model.gradient(xf, p)
    H = model.hessian(xf, p).toarray()
    g_fd = np.array([(model.energy(xf + h * e, p) - model.energy(xf - h * e, p)) / (2 * h) for e in E])
    H_fd = np.array([(model.gradient(xf + h * e, p) - model.gradient(xf - h * e, p)) / (2 * h) for e in E])
    return np.abs(g - g_fd).max() / np.abs(g).max(), np.abs(H - H_fd).max() / np.abs(H).max(), H


@pytest.mark.parametrize("kind", ["neo-hookean", "linear"])
def test_gradient_and_hessian_against_finite_differences(small, kind):
    mat = NeoHookean(1.5, 0.3) if kind == "neo-hookean" else LinearElastic(1.5, 0.3)
    # path along mesh edges for a spring muscle and a cable
    path = [0, int(small.neighbors[0][0])]
    path.append(int([v for v in small.neighbors[path[-1]] if v not in path][0]))
    model = get_model(small, mat, cables=[path])
    k, r = spring_parameters(small, [Muscle(path)], [0.2], 5.0)
    p = model.params(mat, springs=(k, r), cables=(np.array([3.0]), np.array([0.4])))
    eg, eh, H = _fd_check(model, _perturbed(small), p)
    assert eg < 1e-7
    assert eh < 1e-6
    assert np.allclose(H, H.T)


def test_linear_elastic_is_small_strain_limit(small):
    """At rest both materials have the same Hessian (the linear-elastic stiffness)."""
    nh, le = NeoHookean(2.0, 0.3), LinearElastic(2.0, 0.3)
    m1, m2 = get_model(small, nh), get_model(small, le)
    H1 = m1.hessian(small.points, m1.params(nh)).toarray()
    H2 = m2.hessian(small.points, m2.params(le)).toarray()
    assert np.abs(H1 - H2).max() <= 1e-10 * np.abs(H1).max()


def test_hessian_at_rest_has_exactly_three_rigid_modes(small):
    mat = NeoHookean(1.0, 0.3)
    m = get_model(small, mat)
    w = np.linalg.eigvalsh(m.hessian(small.points, m.params(mat)).toarray())
    assert np.sum(np.abs(w) < 1e-9 * w.max()) == 3
    assert w.min() > -1e-9 * w.max()


def test_model_is_cached_per_mesh_and_kind(small):
    a = get_model(small, NeoHookean(1.0, 0.3))
    b = get_model(small, NeoHookean(5.0, 0.1))
    c = get_model(small, LinearElastic(1.0, 0.3))
    assert a is b and a is not c
    with pytest.raises(ValueError, match="built for a neo-hookean"):
        a.params(LinearElastic(1.0, 0.3))


def test_spring_parameters_combine_shared_edges(small):
    e = small.edges[0]
    m1, m2 = Muscle(list(e)), Muscle(list(e[::-1]))
    k, r = spring_parameters(small, [m1, m2], [0.2, 0.4], 3.0)
    i = small.edge_index[tuple(int(v) for v in e)]
    assert k[i] == pytest.approx(6.0)
    assert r[i] == pytest.approx(1.0 - 0.3)
    assert np.count_nonzero(k) == 1 and np.all(r[np.arange(len(r)) != i] == 1.0)


def test_term_families_reproduce_energy_gradient_and_hessian(small):
    """Summing each family's term function over its instances, with inputs read from p, gives the model."""
    mat = NeoHookean(1.5, 0.3)
    path = [0, int(small.neighbors[0][0])]
    path.append(int([v for v in small.neighbors[path[-1]] if v not in path][0]))
    model = get_model(small, mat, cables=[path])
    k, r = spring_parameters(small, [Muscle(path)], [0.2], 5.0)
    p = model.params(mat, springs=(k, r), cables=(np.array([3.0]), np.array([0.4])))
    x = _perturbed(small).reshape(-1)
    fams = model.term_families()
    assert [f.name for f in fams] == ["elem", "spring", "cable0"]
    W, g, H = 0.0, np.zeros(model.n_dof), np.zeros((model.n_dof, model.n_dof))
    for fam in fams:
        N, d = fam.dofs.shape
        xl = ca.SX.sym("xl", d)
        ins = [ca.SX.sym(f"d{i}", fam.W.size1_in(1 + i)) for i in range(fam.W.n_in() - 1)]
        w = fam.W(xl, *ins)
        F = ca.Function("F", [xl, *ins], [w, ca.gradient(w, xl), ca.hessian(w, xl)[0]])
        vals = fam.inputs(ca.DM(p))
        for e in range(N):
            args = [x[fam.dofs[e]]] + [v[:, e] for v in vals[:-1]] + [vals[-1]]
            we, ge, he = (np.array(ca.DM(u)) for u in F(*args))
            W += we.item()
            g[fam.dofs[e]] += ge.ravel()
            H[np.ix_(fam.dofs[e], fam.dofs[e])] += he
        # a subset of instances reads the same columns
        if N > 1:
            sub = [N - 1, 0]
            full = [np.array(ca.DM(v)) for v in vals[:-1]]
            for v_sub, v_full in zip(fam.inputs(ca.DM(p), sub)[:-1], full):
                assert np.array_equal(np.array(ca.DM(v_sub)), v_full[:, sub])
    assert W == pytest.approx(model.energy(x, p), rel=1e-12)
    assert np.abs(g - model.gradient(x, p)).max() < 1e-12 * np.abs(g).max()
    assert np.abs(H - model.hessian(x, p).toarray()).max() < 1e-12 * np.abs(H).max()
    # the spring datum read from p is (k, r) on every edge; the cable's is (K, R)
    assert np.array_equal(np.asarray(fams[1].data_index[1]).ravel(), 2 + np.arange(model.n_edges))
    assert [float(v) for v in fams[2].inputs(ca.DM(p))[:2]] == [3.0, 0.4]


@pytest.mark.parametrize("mat", [NeoHookean(E=2.0, nu=0.3, thickness=0.7), LinearElastic(E=1.5, nu=0.25)])
def test_numeric_evaluation_matches_the_symbolic_model(small, mat):
    # energy, gradient and Hessian come from vectorised numpy (model.is_numeric); the CasADi graph, built
    # on first use of grad_fn / hess_fn, must give the same numbers, springs included
    from mdsr_opt.mechanics.model import EnergyModel

    model = EnergyModel(small, mat)
    assert model.is_numeric and "_graph_fns" not in model.__dict__
    x = _perturbed(small, seed=3).reshape(-1)
    k = np.where(np.arange(model.n_edges) % 3 == 0, 2.5, 0.0)
    r = np.linspace(0.8, 1.1, model.n_edges)
    p = model.params(mat, springs=(k, r))
    E_num, g_num, H_num = model.energy(x, p), model.gradient(x, p), model.hessian(x, p)
    assert "_graph_fns" not in model.__dict__  # nothing symbolic built so far
    f, g = model.grad_fn(x, p)
    Hs = model.hess_fn(x, p)
    assert E_num == pytest.approx(float(f), rel=1e-13)
    np.testing.assert_allclose(g_num, np.asarray(g).ravel(), rtol=0, atol=1e-13 * np.abs(g_num).max())
    up = np.asarray(ca.DM(Hs).full())
    full = np.triu(up) + np.triu(up, 1).T
    np.testing.assert_allclose(H_num.toarray(), full, rtol=0, atol=1e-12 * np.abs(full).max())
    # the upper-triangle pattern IPOPT is given is the symbolic model's
    assert model.hessian_pattern.sparsity_upper() == model.hess_sparsity


def test_numeric_energy_at_rest_is_round_off_squared(small):
    model = get_model(small, NeoHookean(E=1.0, nu=0.3))
    p = model.params(NeoHookean(E=1.0, nu=0.3))
    assert abs(model.energy(small.points + 1e-17, p)) < 1e-28
    x = small.points.copy()
    x[0] = x[1]  # a collapsed triangle: no finite energy
    assert not np.isfinite(model.energy(x, p))


@pytest.mark.parametrize("mat", [NeoHookean(E=2.0, nu=0.3, thickness=0.7), LinearElastic(E=1.5, nu=0.25),
                                 NeoHookean(2.0, 0.45, 0.7, plane="stress"), NeoHookean(2.0, 0.5, plane="stress"),
                                 Yeoh(0.5, 0.1, -0.004, 0.7), MooneyRivlin(0.4, 0.1),
                                 LinearElastic(1.5, 0.5, plane="stress")], ids=lambda m: m.kind[:24])
def test_closed_forms_of_every_material_match_casadis_derivatives_of_its_density(mat):
    """A material's law is stated once (``density``); the numpy ``psi``, the symbolic ``psi_expr`` and the
    closed-form stress, tangent and tangent derivative the numeric models use must agree with CasADi's
    derivatives of ``psi_expr`` at random deformation gradients, and the stress with central differences."""
    from mdsr_opt.body.material import numeric_law

    assert numeric_law(mat)
    rng = np.random.default_rng(5)
    F = np.eye(2)[:, :, None] + 0.35 * rng.standard_normal((2, 2, 200))
    F = F[:, :, F[0, 0] * F[1, 1] - F[0, 1] * F[1, 0] > 0.2][:, :, :40]  # (2, 2, m), elements last
    dF = rng.standard_normal(F.shape)
    mu, lam = mat.params
    f, df = ca.SX.sym("f", 4), ca.SX.sym("df", 4)  # vec(F), column-major: F00, F10, F01, F11
    psi = mat.psi_expr(ca.reshape(f, 2, 2), ca.DM(mat.params))
    P = ca.gradient(psi, f)
    A = ca.jacobian(P, f)
    dA = ca.jacobian(ca.mtimes(A, df), f)  # D A [dF] (A is symmetric)
    ad = ca.Function("ad", [f, df], [psi, P, A, dA])
    P_cf, A_cf = mat.stress_tangent(F, mu, lam)
    dA_cf = None if mat.tangent_derivative is None else mat.tangent_derivative(F, dF, mu, lam)
    Fm = np.moveaxis(F, -1, 0)  # (m, 2, 2)
    # the one density through its three doors: numpy psi, CasADi psi_expr, and the Newton energy's call
    np.testing.assert_allclose(mat.psi(Fm), [float(ad(Fe.T.ravel(), 0)[0]) for Fe in Fm], rtol=1e-13, atol=1e-15)
    h = 1e-6
    for e in range(F.shape[-1]):
        v, dv = F[:, :, e].T.ravel(), dF[:, :, e].T.ravel()  # column-major vec
        psi_e, P_e, A_e, dA_e = (np.asarray(ca.DM(u)) for u in ad(v, dv))
        scale = max(1.0, np.abs(A_e).max())
        # P_ij at vec index i + 2 j; A[i, j, k, l] at (i + 2 j, k + 2 l)
        assert np.abs(P_cf[:, :, e] - P_e.reshape(2, 2, order="F")).max() < 1e-12 * scale
        Ae = A_cf[..., min(e, A_cf.shape[-1] - 1)]
        assert np.abs(Ae.transpose(1, 0, 3, 2).reshape(4, 4) - A_e).max() < 1e-12 * scale
        dAe = np.zeros((2, 2, 2, 2)) if dA_cf is None else dA_cf[..., e]
        assert np.abs(dAe.transpose(1, 0, 3, 2).reshape(4, 4) - dA_e).max() < 1e-11 * scale
        fd = np.array([(mat.psi(F[:, :, e] + h * E) - mat.psi(F[:, :, e] - h * E)) / (2 * h)
                       for E in np.eye(4).reshape(4, 2, 2)]).reshape(2, 2)
        assert np.abs(fd - P_cf[:, :, e]).max() < 1e-7 * scale
    if dA_cf is None:  # a constant tangent: CasADi finds no third derivative either
        assert np.abs(np.asarray(ca.DM(ad(F[:, :, 0].T.ravel(), dF[:, :, 0].T.ravel())[3]))).max() == 0.0
