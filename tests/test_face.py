"""The face makes faces: every expression's design recovers at least 70 % of its drag motion.

The measure is problems.face.motion_recovered: 1 - ||driven - target|| / ||target - rest|| over the dragged
nodes, the driven state rigidly aligned onto the target (the design's x_aligned).
"""

from __future__ import annotations

import numpy as np
import pytest

from mdsr_opt.synthesis.routing_symmetry import find_reflection
from mdsr_opt.scenes.library import get_problem, load_problem_module, problems_dir
from mdsr_opt.scenes.runner import run_case

face_module = load_problem_module(problems_dir() / "face.py")


@pytest.fixture(scope="module")
def scene():
    return get_problem("face", resolution="coarse")


@pytest.mark.parametrize("name", ["smile", "frown", "wink", "pucker"])
def test_each_expression_recovers_at_least_70_percent(scene, name):
    run = run_case(scene, name, photo=False)
    assert run.report.success, run.report.message
    rec = face_module.motion_recovered(scene.mesh.points, run.setup.target, run.design.x_aligned,
                                       run.setup.case.drag_nodes)
    assert rec >= 0.70, f"{name}: {rec:.3f}"
    # symmetric expressions get symmetric contractions
    if name in ("smile", "frown"):
        a = np.sort(run.report.achieved)
        assert len(a) % 2 == 0 and np.allclose(a[0::2], a[1::2], atol=1e-6), a


@pytest.mark.parametrize("resolution", ["coarse", "medium"])
def test_laid_muscles_obey_the_tortuosity_limit(resolution):
    s = get_problem("face", resolution=resolution)
    laid = [m for c in s.cases for m in (c.muscles or ())]
    assert len(laid) == 6
    assert max(face_module.turns(s.mesh, m.nodes).max() for m in laid) <= face_module.MAX_TURN


def test_the_face_mesh_is_mirror_symmetric(scene):
    r = find_reflection(scene.mesh)
    assert r is not None
    P = scene.mesh.points
    assert np.allclose(P[r.node_map] * (-1.0, 1.0), P, atol=1e-9)


def test_motion_recovered_measure():
    X = np.zeros((3, 2))
    T = X + (1.0, 0.0)
    assert face_module.motion_recovered(X, T, T, [0, 1]) == pytest.approx(1.0)
    assert face_module.motion_recovered(X, T, X, [0, 1]) == pytest.approx(0.0)
    assert face_module.motion_recovered(X, T, X + (0.25, 0.0), [0, 1, 2]) == pytest.approx(0.25)
    with pytest.raises(ValueError, match="does not move"):
        face_module.motion_recovered(X, X, X, [0])
    with pytest.raises(ValueError, match="nodes is empty"):
        face_module.motion_recovered(X, T, T, [])
    with pytest.raises(ValueError, match=r"\(n, 2\)"):
        face_module.motion_recovered(X, T[:2], T, [0])
