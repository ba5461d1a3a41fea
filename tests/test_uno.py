"""The ``uno`` backend runs Uno's interior-point preset (trial 12, defect 4: its default filtersqp solved the QP
subproblems with BQPD on a dense reduced Hessian, printed BQPD's Fortran workspace message and took two orders
of magnitude longer than the other backends on a few hundred nodes)."""

import numpy as np
import pytest

from mdsr_opt import Mesh, Muscle, NeoHookean, solve_external, solve_internal
from mdsr_opt.mechanics.backends import BACKENDS, UNO_PRESET, available_backends

MAT = NeoHookean(1.0, 0.3)

pytestmark = pytest.mark.skipif("uno" not in available_backends(), reason="uno is not in this CasADi build")


def test_uno_agrees_with_ipopt_quietly_in_few_iterations(capfd):
    mesh = Mesh.rectangle(4.0, 1.0, 32, 8)  # 297 nodes: BQPD's workspace message and ~30 s with filtersqp
    P = mesh.points
    bottom = Muscle([int(i) for i in np.argsort(P[:, 0]) if P[i, 1] == 0.0])
    left, right = np.flatnonzero(P[:, 0] == 0.0), np.flatnonzero(P[:, 0] == 4.0)
    drags = {int(i): (P[i, 0] - 0.3, P[i, 1] + 0.8) for i in right}
    capfd.readouterr()
    for solve in (lambda b: solve_internal(mesh, MAT, [bottom], [0.3], backend=b),
                  lambda b: solve_external(mesh, MAT, left, drags, backend=b)):
        ref, res = solve("ipopt"), solve("uno")
        assert res.success and res.stable, res.status
        assert res.energy == pytest.approx(ref.energy, rel=1e-9)
        assert np.abs(res.x - ref.x).max() < 1e-7 * mesh.size
        assert res.iterations <= 3 * ref.iterations + 10
    out, err = capfd.readouterr()
    assert "workspace" not in out + err and "mxws" not in out + err


def test_uno_description_names_its_preset():
    assert UNO_PRESET == "ipopt" and "interior-point" in BACKENDS["uno"]
