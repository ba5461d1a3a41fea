"""design.check_minimum: the sparse inertia check against dense eigenvalues of the (reduced) Hessian."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sl

from mdsr_opt import Mesh, Muscle, NeoHookean, check_minimum, solve_internal
from mdsr_opt.synthesis.problem import DesignProblem
from mdsr_opt.mechanics.equilibrium import gauge_coordinates

MAT = NeoHookean(1.0, 0.3)


@pytest.fixture(scope="module")
def small():
    mesh = Mesh.rectangle(2.0, 1.0, 8, 4)
    top = sorted(np.flatnonzero(mesh.points[:, 1] == 1.0), key=lambda i: mesh.points[i, 0])
    return mesh, [Muscle(top[1:-1])]


def test_springs_without_patches_match_dense(small):
    mesh, mus = small
    fwd = solve_internal(mesh, MAT, mus, [0.2], muscle_model="springs", anchor_radius=0.0)
    assert fwd.success and fwd.stable
    squeezed = mesh.points * [0.5, 1.0]  # compressed across: the Neo-Hookean Hessian is indefinite there
    free = np.ones(2 * mesh.n_nodes, bool)
    free[list(gauge_coordinates(mesh))] = False
    prob = DesignProblem(mesh, MAT, mus, mesh.points, np.ones(mesh.n_nodes), "springs", 10.0, 0.99, anchor_radius=0.0)
    for x, a in ((fwd.x, [0.2]), (squeezed, [0.0])):
        pd, lam, res = check_minimum(mesh, MAT, mus, a, x, muscle_model="springs", anchor_radius=0.0)
        H = prob.model.hessian(x.reshape(-1), prob.params(np.array(a))).toarray()[np.ix_(free, free)] / MAT.E
        ev = np.linalg.eigvalsh(H)
        assert pd == bool(ev[0] > 0)
        assert lam == pytest.approx(ev[0], rel=1e-6)
    assert not pd and lam < 0


def test_cable_reduced_hessian_matches_dense(small):
    mesh, mus = small
    fwd = solve_internal(mesh, MAT, mus, [0.2])  # the exact cable with anchor patches (defaults)
    assert fwd.success and fwd.stable
    pd, lam, res = check_minimum(mesh, MAT, mus, [0.2], fwd.x)
    assert pd and lam > 0 and res < 1e-7
    prob = DesignProblem(mesh, MAT, mus, mesh.points, np.ones(mesh.n_nodes), "cable", 10.0, 0.99)
    H, free, A, kap, _ = prob.kkt_data(np.array([0.2]), fwd.x.reshape(-1))
    assert kap[0] > 0  # the rope is taut
    Z = sl.null_space(A.toarray()[:, free])
    ev = np.linalg.eigvalsh(Z.T @ H.toarray()[np.ix_(free, free)] @ Z)
    assert lam == pytest.approx(ev[0] * prob.h, rel=1e-6)
    # a squeezed state with the rope: not a minimum
    pd, lam, _ = check_minimum(mesh, MAT, mus, [0.0], mesh.points * [0.5, 1.0])
    assert not pd and lam < 0


def test_check_minimum_bad_model(small):
    mesh, mus = small
    with pytest.raises(ValueError, match="muscle_model must be 'springs' or 'cable'"):
        check_minimum(mesh, MAT, mus, [0.1], mesh.points, muscle_model="rope")
