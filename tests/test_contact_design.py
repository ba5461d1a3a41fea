"""Design with contact (issue 35 item 6): targets posed with contact are designed and verified with contact;
crossings checked independently with shapely; without contact the same verification rejects the design."""

import copy
import sys
from pathlib import Path

import numpy as np
import pytest
from shapely.geometry import Point, Polygon

from mdsr_opt import Disk, Mesh, Muscle, NeoHookean, design_contractions, solve_external, solve_internal
from mdsr_opt.synthesis.results import MuscleWarning
from mdsr_opt.synthesis.verify import verify_design

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_contact import _gripper  # noqa: E402  the library's gripper with two rim muscles

MAT = NeoHookean(1.0, 0.3)


def _valid_outline(mesh, x):
    x = np.asarray(x)
    return Polygon(x[mesh.boundary_loops[0]]).is_valid and not mesh.boundary_crosses(x)


def _strip_target(frac=0.3):
    mesh = Mesh.rectangle(4.0, 1.0, 24, 6)
    P = mesh.points
    left, right = np.flatnonzero(P[:, 0] == 0.0), np.flatnonzero(P[:, 0] == 4.0)
    drags = {int(i): (P[i, 0] - frac * 4.0, P[i, 1]) for i in right}
    plain = solve_external(mesh, MAT, left, drags)
    target = solve_external(mesh, MAT, left, drags, contact=True)
    return mesh, plain, target


@pytest.mark.slow  # 13-23 s: the default suite keeps the gripper's and the pipeline's contact designs
def test_strip_pushed_past_buckling_designed_and_verified_with_contact():
    mesh, plain, target = _strip_target()
    # the target needs contact: without it the buckled strip folds through itself
    assert not plain.success and "crosses itself" in plain.status
    assert target.success and any(p["force"] > 0 for p in target.contact["pairs"])
    assert _valid_outline(mesh, target.x)
    P = mesh.points
    top = [int(i) for i in np.argsort(P[:, 0]) if P[i, 1] == 1.0]
    bot = [int(i) for i in np.argsort(P[:, 0]) if P[i, 1] == 0.0]
    mus = [Muscle(top[:9]), Muscle(top[8:17]), Muscle(top[16:]), Muscle(bot[4:21])]
    with pytest.warns(MuscleWarning):  # the middle muscle ends at a_max: a free body only approaches the clamped fold
        res = design_contractions(mesh, MAT, mus, target.x, contact=True)
    assert res.method == "derivative-free"
    assert res.success and res.verification.passed, res.status
    assert res.contact is not None and res.verification.forward_success
    assert _valid_outline(mesh, res.x)
    # the shape: within 6 % of the body's size of the clamped, folded target (a free body has no clamps)
    assert res.difference < 0.06 * mesh.size
    assert res.verification.gap <= res.verification.gap_tol


#: the gripper (mesh, material, muscles) pressing Disk((0, 0), 1.1) at contractions [0.3, 0.25], and that
#: pressed state (solve_internal): solved once for the two tests that start from it, each given a copy
_PRESSED: list = []


def _gripper_pressing():
    if not _PRESSED:
        mesh, mat, mus = _gripper()
        disk = Disk((0.0, 0.0), 1.1)
        _PRESSED.append((mesh, mat, mus, disk, solve_internal(mesh, mat, mus, [0.3, 0.25], obstacles=[disk])))
    mesh, mat, mus, disk, target = _PRESSED[0]
    return mesh, mat, mus, disk, copy.deepcopy(target)


def _gripper_design():
    mesh, mat, mus, disk, target = _gripper_pressing()
    res = design_contractions(mesh, mat, mus, target.x, obstacles=[disk], initial_guess=[0.2, 0.2])
    return mesh, mat, mus, disk, target, res


def test_gripper_closed_on_a_disk_designed_and_verified_with_contact_and_not_without():
    mesh, mat, mus, disk, target, res = _gripper_design()
    assert target.success and target.stable
    assert res.success and res.verification.passed, res.status
    assert np.allclose(res.contractions, [0.3, 0.25], atol=1e-4)
    assert res.difference < 1e-4 * mesh.size
    # the verified state presses on the disk: positive normal forces, no node inside it, no self-crossing
    N = [p["force"] for p in res.contact["pairs"] if p["kind"] in ("obstacle", "obstacle segment")]
    assert len(N) >= 1 and min(N) > 0
    assert np.linalg.norm(res.x - disk.center, axis=1).min() >= disk.radius
    assert Polygon(res.x[mesh.boundary_loops[0]]).intersection(Point(0.0, 0.0).buffer(1.1, 256)).area < 1e-3
    assert _valid_outline(mesh, res.x)
    # the same verification without contact rejects it: the jaws close through the disk and each other
    v = verify_design(mesh, mat, mus, res, target.x)
    assert not v.passed and "crosses itself" in v.message and v.gap > 100 * v.gap_tol


def test_design_with_contact_refused_at_the_door():
    mesh = Mesh.rectangle(4.0, 1.0, 8, 2)
    mus = [Muscle(range(1, 8))]
    with pytest.raises(ValueError, match="derivative-free"):
        design_contractions(mesh, MAT, mus, mesh.points, contact=True, method="flattened")
    with pytest.raises(ValueError, match="derivative-free"):
        design_contractions(mesh, MAT, mus, mesh.points, obstacles=[Disk((2.0, -1.0), 0.5)], method="nested")
    with pytest.raises(TypeError, match="contact must be True or False"):
        design_contractions(mesh, MAT, mus, mesh.points, contact="yes")
    with pytest.raises(ValueError, match="holds node"):
        design_contractions(mesh, MAT, mus, mesh.points, obstacles=[Disk((2.0, 0.5), 0.2)])
    with pytest.raises(TypeError, match="obstacles"):
        design_contractions(mesh, MAT, mus, mesh.points, obstacles=[(0.0, 0.0)])


def test_check_minimum_with_contact_on_the_gripper_pressing_its_disk():
    from mdsr_opt.synthesis.verify import check_minimum

    mesh, mat, mus, disk, res = _gripper_pressing()
    ok, lam, r = check_minimum(mesh, mat, mus, [0.3, 0.25], res.x, obstacles=[disk])
    assert ok and r <= 1e-8 and np.isnan(lam)
    # without the disk the pressed state is no equilibrium (the contact forces are missing)
    ok0, _, r0 = check_minimum(mesh, mat, mus, [0.3, 0.25], res.x)
    assert r0 > 1e-6


def test_pipeline_with_contact_solves_the_target_and_verifies_with_contact():
    from mdsr_opt.synthesis.pipeline import design_pipeline

    mesh = Mesh.rectangle(4.0, 1.0, 24, 6)
    P = mesh.points
    left, right = np.flatnonzero(P[:, 0] == 0.0), np.flatnonzero(P[:, 0] == 4.0)
    drags = {int(i): (P[i, 0] - 1.2, P[i, 1]) for i in right}
    top = [int(i) for i in np.argsort(P[:, 0]) if P[i, 1] == 1.0]
    mus = [Muscle(top[:9]), Muscle(top[8:17]), Muscle(top[16:])]
    with pytest.raises(ValueError, match="derivative-free"):
        design_pipeline(mesh, MAT, left, drags, muscles=mus, contact=True, method="flattened")
    with pytest.warns(MuscleWarning):
        out = design_pipeline(mesh, MAT, left, drags, muscles=mus, contact=True, idle_contraction=0.0)
    assert out.external.success and out.external.contact["total_force"] > 0  # the target solved with contact
    assert _valid_outline(mesh, out.target)
    d = out.design
    assert d.method == "derivative-free" and d.success and d.verification.passed, d.status
    assert d.contact is not None and _valid_outline(mesh, d.x)
    assert d.difference < 0.06 * mesh.size


@pytest.mark.slow  # 13-23 s: the default suite keeps the gripper's and the pipeline's contact designs
def test_strip_curled_onto_itself_designed_with_self_contact_and_rejected_without():
    mesh = Mesh.rectangle(4.0, 0.5, 32, 4)
    P = mesh.points
    mus = [Muscle([int(i) for i in np.argsort(P[:, 0]) if P[i, 1] == 0.5])]
    target = solve_internal(mesh, MAT, mus, [0.65], contact=True)  # curled until its ends touch
    assert target.success and any(p["kind"] == "self" and p["force"] > 0 for p in target.contact["pairs"])
    res = design_contractions(mesh, MAT, mus, target.x, contact=True, initial_guess=[0.55], a_max=0.75)
    assert res.success and res.verification.passed, res.status
    assert abs(res.contractions[0] - 0.65) < 0.01 and res.difference < 0.002 * mesh.size
    # the verified state touches itself (positive normal forces) without crossing (shapely)
    assert any(p["kind"] == "self" and p["force"] > 0 for p in res.contact["pairs"])
    assert _valid_outline(mesh, res.x)
    # without contact the same verification is rejected: the forward solve curls through itself
    v = verify_design(mesh, MAT, mus, res, target.x)
    assert not v.passed and "crosses itself" in v.message
