"""The vectorised projected Newton backend (mdsr_opt.mechanics.newton): exact derivatives, projection, energies."""

from __future__ import annotations

import numpy as np
import pytest

from mdsr_opt import LinearElastic, Mesh, MooneyRivlin, Muscle, NeoHookean, Yeoh, solve_external
from mdsr_opt.mechanics.model import get_model, spring_parameters
from mdsr_opt.mechanics.newton import NewtonEnergy, _pd4, _psd4


@pytest.mark.parametrize("mat", [NeoHookean(2.0, 0.3, thickness=0.7), LinearElastic(1.0, 0.25),
                                 NeoHookean(2.0, 0.45, 0.7, plane="stress"), Yeoh(0.5, 0.1, -0.004),
                                 MooneyRivlin(0.4, 0.1)], ids=lambda m: m.kind[:24])
def test_energy_gradient_hessian_match_the_casadi_model(mat):
    mesh = Mesh.rectangle(4.0, 1.0, 12, 3)
    x = (mesh.points + 0.03 * np.random.default_rng(0).standard_normal(mesh.points.shape)).ravel()
    model = get_model(mesh, mat)
    p = model.params(mat, spring_parameters(mesh, [Muscle(range(0, 12))], [0.2], 10.0))
    en = NewtonEnergy(model, p)
    assert len(en.k) == 11  # only the muscle's springs are evaluated
    # against the symbolic CasADi model (model.energy/gradient/hessian are this numpy code themselves)
    f, g = model.grad_fn(x, p)
    up = np.asarray(model.hess_fn(x, p).full())
    H = np.triu(up) + np.triu(up, 1).T
    assert en.energy(x) == pytest.approx(float(f), rel=1e-13)
    assert np.abs(en.gradient(x) - np.asarray(g).ravel()).max() < 1e-12
    assert np.abs(en.hessian(x).toarray() - H).max() < 1e-12 * np.abs(H).max()
    # projected per term: positive semi-definite globally
    assert np.linalg.eigvalsh(en.hessian(x, project=True).toarray())[0] > -1e-12


# (the incompressible laws have fourth derivatives too large for this step's 1e-7: see test_materials)
@pytest.mark.parametrize("mat", [NeoHookean(2.0, 0.3, thickness=0.7), LinearElastic(1.0, 0.25),
                                 NeoHookean(2.0, 0.45, 0.7, plane="stress")], ids=lambda m: m.kind[:24])
def test_third_derivative_matches_differences_of_the_hessian(mat):
    """``third_data`` (elements and muscle springs) against central differences of the exact Hessian along a
    random direction: error O(h^2), symmetric; zero for the linear material without springs."""
    mesh = Mesh.rectangle(4.0, 1.0, 12, 3)
    rng = np.random.default_rng(2)
    x = (mesh.points + 0.03 * rng.standard_normal(mesh.points.shape)).ravel()
    v = rng.standard_normal(x.shape)
    model = get_model(mesh, mat)
    for p in (model.params(mat), model.params(mat, spring_parameters(mesh, [Muscle(range(0, 12))], [0.2], 10.0))):
        T = model.hessian_pattern.matrix(model.third_data(x, p, v)).toarray()
        h = 1e-5
        fd = (model.hessian(x + h * v, p) - model.hessian(x - h * v, p)).toarray() / (2 * h)
        scale = max(np.abs(fd).max(), 1.0)
        assert np.abs(T - fd).max() < 1e-7 * scale
        assert np.abs(T - T.T).max() < 1e-12 * scale
    if mat.kind == "linear":
        assert np.abs(model.third_data(x, model.params(mat), v)).max() == 0.0
    else:
        assert np.abs(T).max() > 1.0


def test_energy_is_infinite_for_an_inverted_triangle():
    mesh = Mesh.rectangle(1.0, 1.0, 1, 1)
    mat = NeoHookean(1.0, 0.3)
    en = NewtonEnergy(get_model(mesh, mat), get_model(mesh, mat).params(mat))
    assert en.energy((mesh.points * [1.0, -1.0]).ravel()) == np.inf


def test_block_projection_clamps_only_negative_eigenvalues():
    rng = np.random.default_rng(1)
    A = rng.standard_normal((50, 4, 4))
    A = A + np.swapaxes(A, 1, 2)
    A[:10] = A[:10] @ np.swapaxes(A[:10], 1, 2) + 0.1 * np.eye(4)  # positive definite ones
    w = np.linalg.eigvalsh(A)
    assert np.array_equal(_pd4(A), w[:, 0] > 0)
    P = _psd4(A)
    wp = np.linalg.eigvalsh(P)
    assert wp.min() > -1e-12
    assert np.allclose(np.sort(wp, axis=1), np.sort(np.maximum(w, 0), axis=1), atol=1e-12)
    assert np.array_equal(P[:10], A[:10])


@pytest.mark.parametrize("mat", [NeoHookean(2.0, 0.3, thickness=0.7), NeoHookean(2.0, 0.45, 0.7, plane="stress"),
                                 Yeoh(0.5, 0.1, -0.004), MooneyRivlin(0.4, 0.1)], ids=lambda m: m.kind[:24])
def test_isotropic_tangents_are_projected_in_closed_form_as_eigh_projects_them(mat):
    """The closed form of _psd_isotropic (the SVD basis of F: two scalings, twist, flip) against eigh's clamp on
    material tangents at stretched, compressed, sheared and turned F, with equal or nearly equal singular
    values, a pure rotation and the identity: every block split by the basis, the same projection."""
    from mdsr_opt.mechanics.newton import _psd_isotropic

    rng = np.random.default_rng(3)
    F = np.eye(2)[None] + 0.6 * rng.standard_normal((3000, 2, 2))
    F[:, 0] *= 0.5  # compressed rows: many tangents indefinite
    F = F[np.linalg.det(F) > 0.05]
    c, s = np.cos(0.7), np.sin(0.7)
    F = np.concatenate([F, [np.eye(2), 0.7 * np.eye(2), 0.9 * np.array([[c, -s], [s, c]]),
                            np.diag([0.5, 0.5 + 1e-13]), np.diag([1.3, 0.6]) @ np.array([[c, -s], [s, c]])]])
    mesh = Mesh.rectangle(1.0, 1.0, 1, 1)
    model = get_model(mesh, mat)
    en = NewtonEnergy(model, model.params(mat))
    _P, A = en._stress_tangent(np.ascontiguousarray(np.moveaxis(F, 0, -1)), True)
    A = np.ascontiguousarray(np.moveaxis(A.reshape(4, 4, -1), -1, 0))
    proj, split = _psd_isotropic(A, F)
    assert split.all()
    w, V = np.linalg.eigh(A)
    ref = (V * np.maximum(w, 0.0)[:, None, :]) @ np.swapaxes(V, 1, 2)
    scale = np.abs(A).max(axis=(1, 2))[:, None, None]
    assert np.abs(proj - ref).max() < 1e-12 * scale.max() and (np.abs(proj - ref) < 1e-12 * scale).all()
    assert (~_pd4(A)).sum() > len(A) // 3  # many indefinite tangents were projected
    assert np.abs(_psd4(A, F) - _psd4(A)).max() < 1e-12 * scale.max()  # through _psd4: its eigh path
    assert np.array_equal(_psd4(A, F)[_pd4(A)], A[_pd4(A)])  # definite blocks untouched


def test_a_tangent_the_isotropic_basis_does_not_split_is_projected_by_eigh():
    from mdsr_opt.mechanics.newton import _psd_isotropic

    rng = np.random.default_rng(4)
    A = rng.standard_normal((40, 4, 4))
    A = A + np.swapaxes(A, 1, 2)  # no isotropic energy's: its scalings and rotations couple
    F = np.eye(2)[None] + 0.3 * rng.standard_normal((40, 2, 2))
    _proj, split = _psd_isotropic(A, F)
    assert not split.any()
    w, V = np.linalg.eigh(A)
    ref = (V * np.maximum(w, 0.0)[:, None, :]) @ np.swapaxes(V, 1, 2)
    bad = ~_pd4(A)
    assert np.abs(_psd4(A, F)[bad] - ref[bad]).max() < 1e-12 * np.abs(A).max()


@pytest.mark.parametrize("bend", [False, True])
def test_energies_match_ipopt(bend):
    mesh = Mesh.from_polygon([[0, 0], [4, 0], [4, 1], [0, 1]], max_area=0.012)
    P = mesh.points
    left, right = np.flatnonzero(P[:, 0] < 1e-9), np.flatnonzero(P[:, 0] > 4 - 1e-9)
    if bend:  # through 90 degrees: compressed elements, where the exact Hessian is used once it is definite
        R, th = 8 / np.pi, P[right, 0] / 4 * np.pi / 2
        target = np.column_stack([(R - P[right, 1]) * np.sin(th), R - (R - P[right, 1]) * np.cos(th)])
    else:
        target = P[right] + [1.0, 0.0]
    mat = NeoHookean(1.0, 0.3)
    a = solve_external(mesh, mat, left, (right, target), backend="newton", tol=1e-10)
    b = solve_external(mesh, mat, left, (right, target), tol=1e-10)
    assert a.success and b.success, (a.status, b.status)
    assert a.energy == pytest.approx(b.energy, rel=1e-10)
    assert np.abs(a.x - b.x).max() < 1e-6


def test_sliding_cables_are_refused():
    mesh = Mesh.rectangle(2.0, 1.0, 4, 2)
    mat = NeoHookean(1.0, 0.3)
    model = get_model(mesh, mat, cables=[(0, 1, 2)])
    with pytest.raises(ValueError, match="does not support sliding cables"):
        NewtonEnergy(model, np.zeros(model.n_params))


def test_step_seconds_times_one_assembly_and_factorisation():
    from mdsr_opt.mechanics.newton import step_seconds

    mesh = Mesh.rectangle(2.0, 1.0, 8, 4)
    mat = NeoHookean(1.0, 0.3)
    model = get_model(mesh, mat)
    fixed = np.zeros(2 * mesh.n_nodes, bool)
    fixed[:2] = fixed[2 * 8:2 * 8 + 2] = True
    t = step_seconds(model, model.params(mat), mesh.points.ravel(), fixed, repeat=3)
    assert 0.0 < t < 5.0
    assert len(model.__dict__.get("_newton_patterns", {})) == 0  # timing leaves the solver's cache alone
