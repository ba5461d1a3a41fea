"""Load stepping past a limit point of the branch from rest (mdsr_opt.mechanics.quadsolve's continuation with
a pseudo-transient solve, mdsr_opt.mechanics.pseudotransient)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from mdsr_opt.mechanics.dampednewton import damped_newton
from mdsr_opt.mechanics.pseudotransient import DIVERGED, pseudo_transient
from mdsr_opt.mechanics.quadsolve import _continue


def _snapping_spring(s):
    """A cubic spring ``h(z) = z^3 - 3 z`` (limit points at ``z = +-1``, ``h = -+2``) tied to a stiff spring
    ``w`` and loaded by ``c(s) = -1.5 + 4 s``: ``r = (h(z) + c + 10 (z - w), 10 (w - z) + (w - z)^3)``. From the
    upper branch at rest (``z`` = 1.94) the branch ends at ``s = 0.875`` (``c = 2``); at ``s = 1`` the one root
    is ``z = w`` = the real root of ``z^3 - 3 z + 2.5``."""
    c = -1.5 + 4.0 * s

    def system(v, jac):
        z, w = v
        r = np.array([z ** 3 - 3 * z + c + 10 * (z - w), 10 * (w - z) + (w - z) ** 3])
        if not jac:
            return r, None
        return r, sp.csr_matrix([[3 * z ** 2 + 7.0, -10.0], [-10.0 - 3 * (w - z) ** 2, 10.0 + 3 * (w - z) ** 2]])
    return system


def _solve_at(t, z0, final, s, transient=False):
    if transient:
        return pseudo_transient(_snapping_spring(t), z0, lambda v: True, 1e-12, 400, 2)
    return damped_newton(_snapping_spring(t), z0, lambda v: True, 1e-12, 30)


def test_the_load_steps_pass_a_limit_point_of_the_branch_from_rest_by_a_pseudo_transient_solve():
    """Without a snap the stepping stops at the limit point s = 0.875 (the step past it fails however small);
    with it the stepping reaches s = 1 at the other branch's root (z = w = the cubic's real root), to the
    tolerance, and the status names the load where the branch from rest was left."""
    z0, ok, _it, _res = damped_newton(_snapping_spring(0.0), np.array([2.0, 2.0]), lambda v: True, 1e-12, 30)
    assert ok and z0[0] == pytest.approx(1.9422, abs=1e-4)
    z, s, conv, _iters, _steps, _res, status = _continue(_solve_at, z0, 1.0 / 256)
    assert not conv and s == pytest.approx(0.875, abs=1.0 / 256) and "failed" in status
    assert z[0] == pytest.approx(1.0, abs=1e-3)  # at the limit point
    snap = lambda t, zs, final, s_from: _solve_at(t, zs, final, s_from, transient=True)
    z, s, conv, _iters, _steps, res, status = _continue(_solve_at, z0, 1.0 / 256, snap=snap)
    roots = np.roots([1.0, 0.0, -3.0, 2.5])
    root = float(np.real(roots[np.abs(np.imag(roots)) < 1e-12][0]))
    assert conv and s == 1.0 and res <= 1e-12
    assert z == pytest.approx([root, root], abs=1e-10)
    assert "stalled at load 0.875" in status and "pseudo-transient" in status


def test_a_snap_that_does_not_converge_is_a_failure_that_says_so():
    """A pseudo-transient solve given too few steps to cross from the limit point to the other branch: the
    stepping fails, its status names both failures, and the state is the last equilibrium (at the limit point)."""
    z0 = damped_newton(_snapping_spring(0.0), np.array([2.0, 2.0]), lambda v: True, 1e-12, 30)[0]
    snap = lambda t, zs, final, s_from: pseudo_transient(_snapping_spring(t), zs, lambda v: True, 1e-12, 5, 2)
    z, s, conv, _iters, _steps, _res, status = _continue(_solve_at, z0, 1.0 / 256, snap=snap)
    assert not conv and s == pytest.approx(0.875, abs=1.0 / 256)
    assert "failed" in status and "pseudo-transient solve from there did not converge either" in status
    assert z[0] == pytest.approx(1.0, abs=1e-3)


def test_pseudo_transient_refuses_bad_input_and_reports_failures():
    """A bad ``shifted`` is a ValueError; a start the caller refuses, a residual that grows past DIVERGED times
    the start's, and a step refused at every cut are failures, not results."""
    system = _snapping_spring(1.0)
    for bad in (0, 3, True, 1.5):
        with pytest.raises(ValueError, match="shifted"):
            pseudo_transient(system, np.zeros(2), lambda v: True, 1e-9, 10, bad)
    z, ok, it, res = pseudo_transient(system, np.zeros(2), lambda v: False, 1e-9, 10, 2)
    assert (ok, it, res) == (False, 0, float("inf"))

    def growing(v, jac):  # r = v - 1, its Jacobian of the wrong sign: shifted, the second step moves away
        return v - 1.0, (sp.csr_matrix(np.diag([-1.0, -3.0])) if jac else None)
    z, ok, it, res = pseudo_transient(growing, np.zeros(2), lambda v: True, 1e-9, 10 ** 6, 2)
    assert not ok and DIVERGED < res < 4 * DIVERGED and it < 20
    z, ok, it, res = pseudo_transient(system, np.array([2.0, 2.0]), lambda v: bool(v[0] >= 2.0 - 1e-9), 1e-9, 10, 2)
    assert not ok and z.tolist() == [2.0, 2.0]


PADDLE = """name = "paddle"
units = "mm"
[body]
outline = [[0, 0], [70, 0], [76, 2], [79.5, 8], [80, 15], [79.5, 22], [76, 28], [70, 30], [0, 30]]
holes = [[[15, 10], [30, 10], [30, 20], [15, 20]], [[42, 11], [55, 11], [55, 19], [42, 19]]]
resolution = 700
[material]
E = 1.0
nu = 0.3
[regions]
base = { box = [-1, -1, 3, 31] }
tip = { near = [80, 15], radius = 6 }
[fabrication]
channel_diameter = 1.5
wall = 1.5
fixture_radius = 3.0
min_fixture_radius = 1.5
[[cases]]
name = "curl"
anchors = "base"
drags = [{ nodes = "tip", by = [-12, 28] }]
"""


@pytest.mark.slow
def test_a_prototype_whose_load_steps_from_rest_stall_reaches_the_equilibrium_continued_from_less_load(tmp_path):
    """A new user's paddle (two windows) curled by three ropes, one contracted 60 %: the strip between that rope
    and the edge wrinkles, and the branch of equilibria the load steps follow from rest ends at a limit point
    just short of the full contractions (before the pseudo-transient solve, the prototype failed: "load step
    0.9961 -> 1 failed"). Now it succeeds, and its state is the one reached by another path: the contractions
    solved at 98 % from rest and then continued to 99.5, 99.8 and 100 % (each a Newton solve from the last),
    to within 1e-6 of the body's size."""
    from mdsr_opt.scenes.prototype import VirtualPrototype
    from mdsr_opt.scenes.runner import run_case
    from mdsr_opt.scenes.scenefile import load_scene

    path = tmp_path / "paddle.toml"
    path.write_text(PADDLE)
    scene = load_scene(path)
    run = run_case(scene, "curl", photo=False)
    design = run.design
    a = np.asarray(design.contractions)
    assert a.max() == pytest.approx(0.6)
    proto = VirtualPrototype.for_scene(scene, seed=0)
    shot = proto.internal(run.setup.muscles, a, photo=False, fixture_radius=design.anchor_radius, guess=design.x)
    assert shot.success, shot.status
    assert "stalled at load" in shot.status and "pseudo-transient" in shot.status
    other = VirtualPrototype.for_scene(scene, seed=0)
    for f in (0.98, 0.995, 0.998, 1.0):
        via = other.internal(run.setup.muscles, f * a, photo=False, fixture_radius=design.anchor_radius)
        assert via.success, (f, via.status)
    assert "pseudo-transient" not in via.status and "from the start state" in via.status
    assert np.abs(shot.x - via.x).max() <= 1e-6 * scene.mesh.size
