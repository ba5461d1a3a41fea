"""Every result object has the same manners: a short one-line ``repr`` naming the class and its key fields,
a ``to_dict()`` that :func:`json.dumps` accepts, and, where it holds states, ``save(path)`` /
``load(path)`` that round-trip exactly and refuse a damaged or foreign file with a ValueError naming it."""

from __future__ import annotations

import dataclasses
import json
import re

import numpy as np
import pytest

from mdsr_opt import Mesh, Muscle, NeoHookean, design_contractions, solve_internal

MAT = NeoHookean(1.0, 0.3)
MAX_REPR = 200


def check_repr(obj, *names):
    text = repr(obj)
    assert "\n" not in text and len(text) <= MAX_REPR, text
    assert text.startswith(type(obj).__name__ + "("), text
    for name in names:
        assert name in text, (name, text)
    return text


def check_dict(obj):
    d = obj.to_dict()
    back = json.loads(json.dumps(d, allow_nan=False))  # strict JSON: no NaN, no arrays
    assert back == d
    return d


def same(a, b, path=""):
    """Exact equality of two results field by field (arrays: dtype and every bit; NaN equals NaN)."""
    if dataclasses.is_dataclass(a):
        assert type(a) is type(b), path
        for f in dataclasses.fields(a):
            same(getattr(a, f.name), getattr(b, f.name), f"{path}.{f.name}")
    elif isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray) and a.dtype == b.dtype and a.shape == b.shape, path
        assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), path
    elif isinstance(a, (list, tuple)):
        assert type(a) is type(b) and len(a) == len(b), (path, a, b)
        for k, (u, v) in enumerate(zip(a, b)):
            same(u, v, f"{path}[{k}]")
    elif isinstance(a, dict):
        assert a.keys() == b.keys(), path
        for k in a:
            same(a[k], b[k], f"{path}[{k}]")
    elif isinstance(a, float) and np.isnan(a):
        assert isinstance(b, float) and np.isnan(b), path
    else:
        assert a == b and type(a) is type(b), (path, a, b)


def check_damaged(cls, path, tmp_path, *args):
    """A truncated copy, a copy with flipped bytes, a text file and a missing file are all refused."""
    data = path.read_bytes()
    cases = {"truncated": data[: len(data) // 2], "flipped": data[:200] + bytes(b ^ 0xFF for b in data[200:260])
             + data[260:], "text": b"this is not a result\n"}
    for name, content in cases.items():
        bad = tmp_path / f"{name}{path.suffix}"
        bad.write_bytes(content)
        with pytest.raises(ValueError, match=str(bad.name)):
            cls.load(bad, *args)
    with pytest.raises(FileNotFoundError):
        cls.load(tmp_path / f"nowhere{path.suffix}", *args)


# ---------------------------------------------------------------------------------------------- mechanics
@pytest.fixture(scope="module")
def strip():
    mesh = Mesh.rectangle(4.0, 1.0, 8, 2)
    return mesh, [Muscle(range(0, 9), name="bottom")]


@pytest.fixture(scope="module")
def equilibrium(strip):
    mesh, mus = strip
    return solve_internal(mesh, MAT, mus, [0.2])


def test_equilibrium_result(equilibrium, tmp_path):
    from mdsr_opt.mechanics.result import EquilibriumResult

    res = equilibrium
    check_repr(res, "mode='internal'", "success=True", "x=array((27, 2), float64)", "residual=")
    d = check_dict(res)
    assert d["x"] == res.x.tolist() and d["achieved"] == pytest.approx(res.achieved.tolist())
    path = tmp_path / "eq.npz"
    assert res.save(path) == str(path)
    back = EquilibriumResult.load(path)
    same(res, back)
    assert back.x.tobytes() == res.x.tobytes() and back.steps == res.steps
    check_damaged(EquilibriumResult, path, tmp_path)
    # a 30k-node state still prints one short line
    big = dataclasses.replace(res, x=np.zeros((30000, 2)), status="x" * 500)
    check_repr(big, "x=array((30000, 2), float64)")
    with pytest.raises(ValueError, match=r"saved as one \.npz file: give a file name ending in \.npz, e\.g\. "
                                         r"'.*eq\.npz' \(got '.*eq\.json'"):
        res.save(tmp_path / "eq.json")


def test_stability_check_and_alignment(strip, equilibrium):
    from mdsr_opt.mechanics.align import align
    from mdsr_opt.mechanics.stability import check_stability
    import scipy.sparse as sp

    H = sp.diags([2.0, -1.0, 3.0, 1.0]).tocsr()
    chk = check_stability(H, np.array([True, True, True, False]))
    check_repr(chk, "stable=False", "n_negative=1")
    d = check_dict(chk)
    assert d["stable"] is False and d["n_negative"] == 1 and len(d["direction"]) == 4
    assert {k: d[k] for k in chk.summary()} == chk.summary()
    mesh, _ = strip
    th = 0.3
    R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    al = align(mesh.points, mesh.points @ R.T + [1.0, 2.0])
    check_repr(al, "angle=", "difference=")
    d = check_dict(al)
    assert d["angle"] == pytest.approx(th, abs=1e-12) and d["t"] == pytest.approx([1.0, 2.0], abs=1e-12)
    np.testing.assert_allclose(d["R"], R, atol=1e-12)


def test_minimize_outcome(strip, tmp_path):
    from mdsr_opt.mechanics.backends import minimize
    from mdsr_opt.mechanics.result import MinimizeOutcome
    from mdsr_opt.mechanics.model import get_model

    mesh, _ = strip
    model = get_model(mesh, MAT)
    x0 = mesh.points.reshape(-1).copy()
    fixed = np.zeros(len(x0), dtype=bool)
    left, right = np.flatnonzero(mesh.points[:, 0] == 0.0), np.flatnonzero(mesh.points[:, 0] == 4.0)
    for i in np.r_[left, right]:
        fixed[2 * i:2 * i + 2] = True
    target = mesh.points.copy()
    target[right, 0] += 0.4
    out = minimize(model, model.params(MAT), x0, fixed, target.reshape(-1)[fixed], backend="newton")
    assert out.success
    check_repr(out, "success=True", "x=array((54,), float64)", "iterations=")
    assert check_dict(out)["lam_g"] is None
    path = tmp_path / "min.npz"
    out.save(path)
    same(out, MinimizeOutcome.load(path))
    check_damaged(MinimizeOutcome, path, tmp_path)


# ---------------------------------------------------------------------------------------------- synthesis
@pytest.fixture(scope="module")
def designed(strip, equilibrium):
    mesh, mus = strip
    return design_contractions(mesh, MAT, mus, equilibrium.x)


def test_design_result_and_verification(designed, tmp_path):
    from mdsr_opt.synthesis.results import DesignResult

    res = designed
    assert res.success
    check_repr(res, "method='flattened'", "success=True", "difference=", "contractions=[0.2")
    check_repr(res.verification, "passed=True", "gap=")
    d = check_dict(res)
    assert d["contractions"] == pytest.approx([0.2], abs=1e-6)
    json.dumps(res.verification.to_dict(), allow_nan=False)
    path = tmp_path / "design.npz"
    res.save(path)
    back = DesignResult.load(path)
    same(res, back)
    assert isinstance(back.verification, type(res.verification)) and isinstance(back.history[0], tuple)
    check_damaged(DesignResult, path, tmp_path)
    # a folder (PipelineResult.save's argument) is refused at once with the file name to give instead
    for folder in (tmp_path, tmp_path / "new"):
        with pytest.raises(ValueError, match=r"give a file name ending in \.npz, e\.g\. '" +
                           re.escape(str(folder / "design.npz")) + "'.*PipelineResult"):
            res.save(folder)
    assert not (tmp_path / "new").exists()
    with pytest.raises(ValueError, match="is a folder, not a design result file: give the .npz file that save"):
        DesignResult.load(tmp_path)
    # a file of another kind of result is refused by name, not misread
    other = tmp_path / "eq.npz"
    solve_internal(Mesh.rectangle(1.0, 1.0, 2, 2), MAT, [Muscle([0, 1, 2])], [0.1]).save(other)
    with pytest.raises(ValueError, match=r"eq\.npz is not a mdsr_opt design result \(format "
                                         r"'mdsr_opt.equilibrium/1'\)"):
        DesignResult.load(other)


def test_pipeline_result(tmp_path):
    from mdsr_opt import design_pipeline
    from mdsr_opt.synthesis.pipeline import PipelineResult

    mesh = Mesh.rectangle(4.0, 1.0, 8, 2)
    left = np.flatnonzero(mesh.points[:, 0] == 0.0)
    drags = {int(i): (x - 0.3, y - 0.4) for i, (x, y) in enumerate(mesh.points) if x == 4.0}
    res = design_pipeline(mesh, MAT, left, drags, muscles=[Muscle(range(1, 8))])
    check_repr(res, "success=", "n_nodes=27", "n_muscles=1", "difference=")
    d = check_dict(res)
    assert d["format"] == "mdsr_opt.design/1" and len(d["target"]) == mesh.n_nodes
    back = PipelineResult.load(res.save(tmp_path / "run").rsplit("/", 1)[0])
    same(res.design, back.design)
    assert np.array_equal(back.anchors, res.anchors) and back.muscles == res.muscles
    assert np.allclose(back.target, res.target, atol=1e-12)  # through the .vtu mesh file


@pytest.fixture(scope="module")
def poses():
    from mdsr_opt.synthesis.poses import design_poses

    mesh = Mesh.rectangle(4.0, 1.0, 8, 4)  # rows inside off the centre line: the ropes' channels need them
    X = mesh.points

    def bend(s):
        phi, r = (X[:, 0] - 2.0) / 3.0, 3.0 - s * (X[:, 1] - 0.5)
        return np.column_stack([r * np.sin(phi), s * (3.0 - r * np.cos(phi))])

    return mesh, design_poses(mesh, MAT, {"left": bend(1), "right": bend(-1)})


def test_poses_result(poses, tmp_path):
    from mdsr_opt.synthesis.poses_result import PosesResult

    mesh, res = poses
    check_repr(res, "2 poses", "shared muscles", "success=")
    check_dict(res)
    path = tmp_path / "layout.json"
    res.save(path)
    back = PosesResult.load(path)
    for f in ("rest_lengths", "contractions", "strokes", "states", "differences", "pose_success", "engaged"):
        a, b = getattr(res, f), getattr(back, f)
        assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), f
    assert back.names == res.names and back.muscles == res.muscles and back.designs == {}
    check_damaged(PosesResult, path, tmp_path)
    foreign = tmp_path / "foreign.json"
    foreign.write_text(json.dumps({"format": "mdsr_opt.design/1", "names": []}))
    with pytest.raises(ValueError, match=r"foreign\.json is not a mdsr_opt poses result"):
        PosesResult.load(foreign)
    # many poses: still one short line
    many = dataclasses.replace(res, names=tuple(f"pose_{k}" for k in range(40)), differences=np.linspace(0, 1, 40),
                               separate_differences=np.linspace(0, 1, 40))
    check_repr(many, "40 poses")


def test_gait_and_schedule(poses, tmp_path):
    from mdsr_opt.synthesis.gait import Gait, GaitSchedule, gait_schedule

    mesh, layout = poses
    gait = Gait("wave", ("left", "rest", "right"), frames_per_step=2)
    check_repr(gait, "name='wave'", "frames_per_step=2")
    assert check_dict(gait)["sequence"] == ["left", "rest", "right"]
    sch = gait_schedule(mesh, MAT, layout, gait.sequence, frames_per_step=2)
    text = repr(sch)
    assert text.startswith("GaitSchedule(") and len(text) <= MAX_REPR and "frames" in text
    d = check_dict(sch)
    assert np.asarray(d["states"]).shape == sch.states.shape
    path = tmp_path / "schedule.npz"
    sch.save(path)
    same(sch, GaitSchedule.load(path))
    check_damaged(GaitSchedule, path, tmp_path)
    # a file written before the per-frame verdicts were named frame_success (its 'success' that array)
    from mdsr_opt.core.results import load_npz, save_npz

    arrays, meta = load_npz(path, "gait_schedule")
    arrays["success"] = arrays.pop("frame_success")
    older = tmp_path / "older.npz"
    save_npz(older, "gait_schedule", arrays, meta)
    same(sch, GaitSchedule.load(older))
    arrays["success"] = np.zeros_like(arrays["success"])  # its frames failed: read so, not as solved
    save_npz(older, "gait_schedule", arrays, meta)
    assert not GaitSchedule.load(older).success and not GaitSchedule.load(older).frame_success.any()


def test_fabrication_data(poses):
    from mdsr_opt.synthesis.export import fabrication_data

    mesh, layout = poses
    fd = fabrication_data(mesh, layout, units="cm")
    check_repr(fd, "units='cm'", "pose_names=('left', 'right')", "n_muscles=")
    d = check_dict(fd)
    assert d["units"] == "cm" and np.asarray(d["strokes"]).shape == fd.strokes.shape


# ---------------------------------------------------------------------------------------------- scenes
@pytest.fixture(scope="module")
def one_muscle():
    from mdsr_opt import get_problem

    return get_problem("one_muscle", resolution="coarse")


def test_case_setup(one_muscle, tmp_path):
    from mdsr_opt.scenes.cases import CaseSetup, prepare_case

    setup = prepare_case(one_muscle, "a30")
    check_repr(setup, "scene='one_muscle'", "case='a30'", "kind='internal'", "n_muscles=1")
    d = check_dict(setup)
    assert d["known_contractions"] == [0.3] and d["target_result"]["success"] is True
    path = tmp_path / "setup.npz"
    setup.save(path)
    back = CaseSetup.load(path, one_muscle)
    for f in ("target", "known_contractions", "muscles", "times", "warnings", "target_result"):
        same(getattr(setup, f), getattr(back, f), f)
    assert back.case is one_muscle.case("a30") and back.routing is None
    check_damaged(CaseSetup, path, tmp_path, one_muscle)
    from mdsr_opt import get_problem

    other = get_problem("one_muscle", resolution=60)
    with pytest.raises(ValueError, match=r"setup\.npz: .* not of 'one_muscle' \("):
        CaseSetup.load(path, other)


def test_case_run_case_report_and_scene_report(one_muscle, tmp_path):
    from mdsr_opt.scenes.runner import run_case
    from mdsr_opt.scenes.runscene import run_scene

    run = run_case(one_muscle, "a30", photo_size=(300, 300))
    assert run.report.success
    check_repr(run, "scene='one_muscle'", "case='a30'", "success=True", "photo=True")
    d = check_dict(run)
    assert d["report"]["photo"]["image_size"] == [300, 300] and d["photo"]["synthetic"] is True
    check_repr(run.report, "case='a30'", "kind='internal'", "success=True")
    check_dict(run.report)
    rep = run_scene(one_muscle, tmp_path / "out", cases=["a20"], photos=False, figures=False, animations=False,
                    log=None)
    check_repr(rep, "scene='one_muscle'", "success=True", "cases='1/1 ok'")
    assert check_dict(rep)["cases"][0]["case"] == "a20"


def test_animation_result(one_muscle, tmp_path):
    from mdsr_opt.scenes.animate import AnimationResult, animate

    res = animate(one_muscle, "sweep", {"a50": (one_muscle.muscles, np.array([0.5]))})
    assert res.success and len(res.states) == 13
    check_repr(res, "name='sweep'", "success=True", "n_frames=13")
    assert check_dict(res)["n_frames"] == 13
    path = tmp_path / "sweep.npz"
    res.save(path)
    same(res, AnimationResult.load(path))
    check_damaged(AnimationResult, path, tmp_path)
    empty = AnimationResult("none", message="case 'x' has no design in this run")
    empty.save(tmp_path / "empty.npz")
    same(empty, AnimationResult.load(tmp_path / "empty.npz"))


# ---------------------------------------------------------------------------------------------- photos
def test_case_result_and_contour_comparison(tmp_path):
    from mdsr_opt import render_photo, write_mesh
    from mdsr_opt.photos.folder import evaluate_folder

    mesh = Mesh.rectangle(2.0, 1.0, 8, 4)
    x = mesh.points * [1.0, 0.8]
    write_mesh(tmp_path / "states" / "bent.vtu", mesh, x=x)
    render_photo(mesh, x, image_size=(300, 200)).save(tmp_path / "img" / "bent.png")
    (row,) = evaluate_folder(tmp_path / "img", tmp_path / "states")
    check_repr(row, "case='bent'", "synthetic=True", "mean_px=")
    check_repr(row.comparison, "mean_px=", "registration=")
    assert check_dict(row)["comparison"]["n_nodes"] == row.comparison.n_nodes


def test_routing_result():
    from mdsr_opt.synthesis.routing import route_muscles

    mesh = Mesh.rectangle(2.0, 1.0, 8, 4)
    res = route_muscles(mesh, mesh.points * [0.8, 1.0])
    check_repr(res, "muscle(s)", "n_units=")
    assert len(check_dict(res)["muscles"]) == len(res)
