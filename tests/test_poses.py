"""One muscle layout for several poses (mdsr_opt.synthesis.poses) and the gait schedule (mdsr_opt.synthesis.gait)."""

from __future__ import annotations

import csv
import json
import time
from pathlib import Path

import numpy as np
import pytest

from mdsr_opt import Mesh, NeoHookean
from mdsr_opt.plot.design import plot_schedule
from mdsr_opt.synthesis.gait import Gait, gait_schedule
from mdsr_opt.synthesis.layouts import shared_layout
from mdsr_opt.synthesis.poses import Pose, design_poses
from mdsr_opt.synthesis.poses_result import PosesResult

MAT = NeoHookean(1.0, 0.3)


def strip(scale=1.0):
    return Mesh.rectangle(4.0 * scale, 1.0 * scale, 16, 4)


def bend(mesh, s, scale=1.0):
    """The strip bent about its centre line: s = +1 up (left), -1 down (right)."""
    X = mesh.points / scale
    R = 3.0
    phi = (X[:, 0] - 2.0) / R
    r = R - s * (X[:, 1] - 0.5)
    return scale * np.column_stack([r * np.sin(phi), s * (R - r * np.cos(phi))])


@pytest.fixture(scope="module")
def lr():
    mesh = strip()
    res = design_poses(mesh, MAT, {"left": bend(mesh, 1), "right": bend(mesh, -1)})
    return mesh, res


def test_shared_layout_reproduces_each_pose_with_no_more_muscles(lr):
    mesh, res = lr
    assert res.success
    assert res.n_muscles <= int(res.separate_n_muscles.sum())
    assert np.all(np.isfinite(res.separate_differences))
    assert np.all(res.differences <= 1.10 * res.separate_differences)
    # each bend pulls with the muscle on its concave side, the other rope is slack: its channel lies between
    # the centre line and the convex side (a wall's width inside the outline), and the one-rope bend also
    # shortens the strip, so its path shortens a little (0.11 of the engaged rope's 0.65) at zero tension
    for k, name in enumerate(res.names):
        assert res.engaged[k].sum() == 1
        i = int(np.flatnonzero(res.engaged[k])[0])
        assert res.strokes[k, i] > 0.5                       # ~0.65 of a 3.5-long muscle
        assert np.all(res.strokes[k, ~res.engaged[k]] < 0.25 * res.strokes[k, i])
        assert np.all(res.tensions[k, ~res.engaged[k]] == 0)
    assert "2 shared muscles" in repr(res) and len(repr(res)) < 300


def test_a_pose_that_engages_exactly_its_own_layout_reuses_its_separate_design(lr):
    """Each bend engages one muscle of the shared layout, its own routing's: given that design as
    ``separate``, the pose's shared-layout design is that very result (no second NLP); a design recorded with
    other options is not taken."""
    from mdsr_opt import design_contractions

    mesh, res = lr
    targets = {"left": bend(mesh, 1), "right": bend(mesh, -1)}
    own = {name: [res.muscles[int(i)] for i in np.flatnonzero(res.engaged[k])] for k, name in enumerate(res.names)}
    sep = {name: (own[name], design_contractions(mesh, MAT, own[name], targets[name])) for name in res.names}
    again = design_poses(mesh, MAT, targets, separate=sep)
    for k, name in enumerate(again.names):
        on = [again.muscles[int(i)].nodes for i in np.flatnonzero(again.engaged[k])]
        assert on == [m.nodes for m in own[name]]
        assert again.designs[name] is sep[name][1]
        assert again.differences[k] == pytest.approx(res.differences[k], rel=1e-6)
    other = {name: (own[name], design_contractions(mesh, MAT, own[name], targets[name], a_max=0.5))
             for name in res.names}
    fresh = design_poses(mesh, MAT, targets, separate=other)
    assert all(fresh.designs[name] is not other[name][1] for name in res.names)
    assert np.allclose(fresh.contractions, again.contractions, atol=1e-6)
    # verified from its own state only (verify="design"): not taken where a re-solve from rest is asked,
    # taken where verify="design" is
    quick = {name: (own[name], design_contractions(mesh, MAT, own[name], targets[name], verify="design"))
             for name in res.names}
    redone = design_poses(mesh, MAT, targets, separate=quick)
    assert all(redone.designs[name] is not quick[name][1] for name in res.names)
    kept = design_poses(mesh, MAT, targets, separate=quick, design_options={"verify": "design"})
    assert all(kept.designs[name] is quick[name][1] for name in res.names)


def test_result_round_trips_through_json(lr, tmp_path):
    _, res = lr
    p = res.save(tmp_path / "layout.json")
    back = PosesResult.load(p)
    assert back.names == res.names and [m.nodes for m in back.muscles] == [m.nodes for m in res.muscles]
    for f in ("strokes", "contractions", "differences", "separate_differences", "states", "engaged"):
        np.testing.assert_array_equal(getattr(back, f), getattr(res, f))
    assert json.loads(Path(p).read_text())["names"] == ["left", "right"]
    lines = res.table().splitlines()
    assert [r.split()[0] for r in lines[2:4]] == ["left", "right"] and "length units" in lines[-1]


@pytest.mark.parametrize("cyclic", [True, False])
def test_schedule_first_and_last_frames_are_the_designed_strokes(lr, cyclic):
    mesh, res = lr
    sch = gait_schedule(mesh, MAT, res, ["left", "right"], frames_per_step=3, cyclic=cyclic)
    assert sch.n_frames == (2 if cyclic else 1) * 3 + 1
    np.testing.assert_array_equal(sch.strokes[0], res.strokes[0])
    np.testing.assert_array_equal(sch.strokes[-1], res.strokes[0 if cyclic else 1])
    assert sch.frame_success.all() and sch.success, sch.status
    # the forward solves reach the designed strokes at the keyframes
    for k, name in zip(sch.keyframes, sch.sequence):
        np.testing.assert_allclose(sch.achieved[k], res.strokes[res.index(name)], atol=1e-5)
    np.testing.assert_allclose(sch.times[-1], 2.0 if cyclic else 1.0)


def test_schedule_csv_and_chart(lr, tmp_path):
    mesh, res = lr
    sch = gait_schedule(mesh, MAT, res, ["rest", "left"], frames_per_step=2, units="cm")
    rows = list(csv.reader(open(sch.write_csv(tmp_path / "s.csv"))))
    assert rows[0][:4] == ["frame", "time [s]", "pose", "M1 stroke [cm]"]
    assert len(rows) == 1 + 5
    assert [float(v) for v in rows[1][3:5]] == [0.0, 0.0]          # rest
    np.testing.assert_allclose([float(v) for v in rows[3][3:5]], res.strokes[0], rtol=1e-8)
    fig = plot_schedule(sch)
    assert fig.axes[0].get_ylabel().startswith("stroke (cm")  # quantity (unit), as every figure
    assert np.all(sch.states[0] == mesh.points)


def _held_top_layout(top_stroke):
    """A strip curled by its bottom edge's muscle (contraction 0.15) while its top edge's muscle holds the top at
    its rest length (contraction 0, in tension): one pose, its top stroke given."""
    from mdsr_opt import Muscle, solve_internal
    from mdsr_opt.body.fingerprint import mesh_fingerprint

    mesh = strip()
    P = mesh.points

    def edge(y, name):
        idx = np.flatnonzero(np.isclose(P[:, 1], y))
        return Muscle(idx[np.argsort(P[idx, 0])], name=name)

    mus = (edge(0.0, "bottom"), edge(1.0, "top"))
    L0 = np.array([m.rest_length(mesh) for m in mus])
    eq = solve_internal(mesh, MAT, list(mus), [0.15, 0.0])
    assert eq.success and eq.tension[1] > 0  # the top rope pulls at zero stroke
    res = PosesResult(names=("curl",), muscles=mus, rest_lengths=L0, sources=(("curl",), ("curl",)),
                      contractions=np.array([[0.15, top_stroke / L0[1]]]),
                      strokes=np.array([[0.15 * L0[0], top_stroke]]), tensions=np.full((1, 2), np.nan),
                      differences=np.array([0.0]), pose_success=np.array([True]), status=("ok",),
                      states=np.array([eq.x]), separate_differences=np.array([np.nan]),
                      separate_n_muscles=np.array([2]), engaged=np.array([[True, True]]),
                      rest_mesh=mesh_fingerprint(mesh))
    return mesh, res, eq


def test_a_pulled_muscle_left_at_zero_stroke_is_held_not_released():
    """A pose's zero stroke stored as -5e-16 (round-off) is a rope held at its rest length: every frame
    solves it at contraction 0 and the keyframe is the pose's state; a real pay-out (1e-3 of the length,
    far beyond ZERO_STROKE) is still a released rope, and the body's path along it makes it taut."""
    from mdsr_opt.synthesis.gait import ZERO_STROKE

    mesh, res, eq = _held_top_layout(-5e-16)
    assert 5e-16 < ZERO_STROKE * res.rest_lengths[1]
    sch = gait_schedule(mesh, MAT, res, ["rest", "curl"], frames_per_step=2, cyclic=False)
    assert sch.frame_success.all() and sch.success, sch.status
    assert sch.strokes[-1, 1] == 0.0  # said as zero, not -5e-16
    np.testing.assert_allclose(sch.states[-1], eq.x, atol=1e-6)
    np.testing.assert_allclose(sch.achieved[1:, 1], 0.0, atol=1e-6 * res.rest_lengths[1])
    assert (sch.tensions[1:, 1] > 0).all()  # held, and pulling

    mesh, res, _ = _held_top_layout(-1e-3 * res.rest_lengths[1])
    sch = gait_schedule(mesh, MAT, res, ["rest", "curl"], frames_per_step=2, cyclic=False)
    assert not sch.frame_success[-1] and not sch.success and "released muscle top would be taut" in sch.status[-1]


def test_budget_of_one_keeps_the_strongest_muscle():
    mesh = strip()
    m_left = [m for m in _route(mesh, bend(mesh, 1))]
    m_right = [m for m in _route(mesh, bend(mesh, -1))]
    mus, src = shared_layout(mesh, {"left": m_left, "right": m_right}, max_muscles=1)
    assert len(mus) == 1 and src == (("left",),)
    both, src2 = shared_layout(mesh, {"left": m_left, "again": m_left})   # duplicates merged
    assert len(both) == len(m_left) and src2[0] == ("left", "again")


def _route(mesh, y):
    from mdsr_opt.synthesis.routing import route_muscles

    return route_muscles(mesh, y)


def test_units_propagate_body_in_millimetres():
    """The same strip in cm (4 x 1) and in mm (40 x 10): contractions agree, strokes are 10x, headers say mm."""
    out = []
    for scale in (1.0, 10.0):
        mesh = strip(scale)
        out.append(design_poses(mesh, MAT, {"left": bend(mesh, 1, scale)}, compare=False))
    np.testing.assert_allclose(out[1].contractions, out[0].contractions, rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(out[1].strokes, 10.0 * out[0].strokes, rtol=1e-5, atol=1e-6)
    # 40 mm less a node at each end: the ends moved inward so that the fixtures fit inside the strip
    np.testing.assert_allclose(out[1].rest_lengths, [35.0])
    sch = gait_schedule(strip(10.0), MAT, out[1], ["rest", "left"], frames_per_step=1, cyclic=False, units="mm")
    assert sch.units == "mm" and "mm" in repr(sch)
    np.testing.assert_allclose(sch.strokes[-1], out[1].strokes[0])


@pytest.mark.parametrize("make, kind, words", [
    (lambda m: {}, ValueError, "poses is empty"),
    (lambda m: [Pose("a", m.points), Pose("b", Mesh.rectangle(4, 1, 8, 2).points)], ValueError, "same mesh"),
    (lambda m: [Pose("a", m.points, mesh=Mesh.rectangle(4.0, 1.0, 16, 4).with_points(m.points * 2))], ValueError,
     "different mesh"),
    (lambda m: {"a": m.points, "rest": m.points}, ValueError, "'rest'"),
    (lambda m: "left", TypeError, "poses must be"),
])
def test_bad_poses_are_refused(make, kind, words):
    mesh = strip()
    with pytest.raises(kind, match=words):
        design_poses(mesh, MAT, make(mesh))


@pytest.mark.parametrize("budget, kind", [(0, ValueError), (-2, ValueError), (1.5, TypeError), (True, TypeError)])
def test_budget_below_one_is_refused(budget, kind):
    mesh = strip()
    with pytest.raises(kind, match="max_muscles"):
        design_poses(mesh, MAT, {"left": bend(mesh, 1)}, max_muscles=budget)


@pytest.mark.parametrize("kw, kind, words", [
    (dict(frames_per_step=0), ValueError, "frames_per_step must be a positive integer"),
    (dict(frames_per_step=-3), ValueError, "frames_per_step"),
    (dict(frames_per_step=2.0), TypeError, "frames_per_step"),
    (dict(units="furlong"), ValueError, "unknown units 'furlong'"),
    (dict(sequence=[]), ValueError, "sequence is empty"),
    (dict(sequence=["left", "up"]), ValueError, "unknown pose 'up'"),
])
def test_bad_schedule_input_is_refused(lr, kw, kind, words):
    mesh, res = lr
    kw = dict(kw)
    seq = kw.pop("sequence", ["left", "right"])
    with pytest.raises(kind, match=words):
        gait_schedule(mesh, MAT, res, seq, **kw)


def test_gait_block_checks():
    with pytest.raises(ValueError, match="frames_per_step"):
        Gait("g", ("a", "b"), frames_per_step=0)
    with pytest.raises(ValueError, match="empty"):
        Gait("g", ())
    with pytest.raises(ValueError, match="max_muscles"):
        Gait("g", ("a",), max_muscles=0)
    assert Gait("g", ("rest", "a", "rest", "b")).poses == ("a", "b")


def test_scene_file_units_and_gait(tmp_path):
    from test_scenes import finger_dict, write_json

    from mdsr_opt.scenes.reader import SceneFileError
    from mdsr_opt.scenes.scenefile import load_scene

    d = finger_dict()
    d["units"] = "cm"
    d["gait"] = {"name": "wave", "poses": ["rest", "bend"], "frames_per_step": 3, "max_muscles": 2}
    scene = load_scene(write_json(tmp_path, d))
    assert scene.units == "cm" and scene.gait.poses == ("bend",) and scene.gait.frames_per_step == 3
    for key, value, words in (("units", "furlong", "unknown units 'furlong'"),
                              ("gait", {"poses": ["bnd"]}, r"gait\.poses\[0\]: unknown case 'bnd'"),
                              ("gait", {"poses": ["bend"], "frames_per_step": 0}, "gait.frames_per_step"),
                              ("gait", {"poses": ["bend"], "max_muscles": 0}, "gait.max_muscles")):
        bad = finger_dict()
        bad[key] = value
        with pytest.raises(SceneFileError, match=words):
            load_scene(write_json(tmp_path, bad, name=f"bad_{key}.json"))


def test_run_scene_writes_the_gait_folder(tmp_path):
    """The runner's hook: a scene file with units and a gait block gives layout, schedule, chart, GIF and
    fabrication files in out/<gait>/, every length in the scene's unit."""
    from test_scenes import finger_dict, write_json

    from mdsr_opt.scenes.scenefile import load_scene
    from mdsr_opt.scenes.runscene import run_scene

    d = finger_dict()
    d["units"] = "cm"
    d["gait"] = {"name": "wave", "poses": ["rest", "bend"], "frames_per_step": 2}
    scene = load_scene(write_json(tmp_path, d))
    rep = run_scene(scene, tmp_path / "out", cases=["bend"], photos=False, log=None)
    info = rep.animations["wave"]
    assert info["success"], info.get("message")
    folder = tmp_path / "out" / "wave"
    names = {"layout.json", "schedule.csv", "schedule.png", "wave.gif", "wave.json", f"{scene.name}.svg",
             f"{scene.name}.dxf", f"{scene.name}_muscles.csv"}
    assert names <= {p.name for p in folder.iterdir()}
    assert info["frames"] == 5 and info["n_muscles"] <= info["separate_n_muscles"]
    head = open(folder / "schedule.csv").readline()
    assert "stroke [cm]" in head and "[mm]" not in head
    lay = PosesResult.load(folder / "layout.json")
    rows = list(csv.DictReader(open(folder / f"{scene.name}_muscles.csv")))
    np.testing.assert_allclose([float(r["stroke bend [cm]"]) for r in rows], lay.strokes[0], rtol=1e-8)


def _slow_broken_gif(*args, **kwargs):
    time.sleep(1.5)  # the other gait jobs (chart, fabrication files) report first
    raise ValueError("the DXF writer broke")


def _broken_export(*args, **kwargs):  # a module's function: a worker process finds it by name
    raise ValueError("the DXF writer broke")


# each failing job in the pool and serially; the default run keeps one of each (the slow GIF failing in a worker
# after the other jobs reported, the export failing in this process), the other two pairs are slow
@pytest.mark.parametrize("job, background", [
    ("gif", True), ("export", False),
    pytest.param("export", True, marks=pytest.mark.slow), pytest.param("gif", False, marks=pytest.mark.slow)])
def test_a_failed_gait_job_leaves_no_gait_json_listing_its_files(tmp_path, monkeypatch, background, job):
    """The gait's chart, GIF and fabrication files are background jobs: wave.json (<gait>.json), which lists their files,
    is written only once every one of them has reported; one that fails fails the run (in a worker or
    here) and leaves no wave.json, even when the others finished before it."""
    from test_scenes import finger_dict, write_json

    import mdsr_opt.synthesis.export as export
    import mdsr_opt.scenes.gaitrun as gaitrun
    from mdsr_opt.scenes.scenefile import load_scene
    from mdsr_opt.scenes.runscene import run_scene

    if job == "export":
        monkeypatch.setattr(export, "export_fabrication", _broken_export)
    else:
        monkeypatch.setattr(gaitrun, "save_gait_animation", _slow_broken_gif)
    d = finger_dict()
    d["gait"] = {"name": "wave", "poses": ["rest", "bend"], "frames_per_step": 2}
    scene = load_scene(write_json(tmp_path, d))
    with pytest.raises(ValueError, match="the DXF writer broke"):
        run_scene(scene, tmp_path / "out", cases=["bend"], photos=False, log=None, background=background)
    folder = tmp_path / "out" / "wave"
    assert (folder / "layout.json").exists() and not (folder / "wave.json").exists()


@pytest.mark.slow
@pytest.mark.parametrize("name, gait, resolution",
                         [("gecko", "walk", "coarse"), ("starfish", "swim_cycle", "medium")])
def test_library_scenes_have_one_layout_for_their_gait(tmp_path, name, gait, resolution):
    """The scene's gait on one buildable layout. The starfish runs at its default resolution (569 nodes): on
    its coarse mesh (145 nodes) the arms are too narrow for ropes in channels inside the body, and the
    pinwheel case itself removes only 6 % of the rest shape's difference (test_problems.py's coarse runs
    route on the whole graph for that reason)."""
    from mdsr_opt.scenes.library import get_problem
    from mdsr_opt.scenes.runscene import run_scene

    scene = get_problem(name, resolution=resolution)
    assert scene.gait.name == gait and scene.units == "cm"
    rep = run_scene(scene, tmp_path, photos=False, log=None)
    info = rep.animations[gait]
    assert info["success"], info.get("message")
    assert info["n_muscles"] <= info["separate_n_muscles"]
    for pose, dd in info["differences"].items():
        assert dd <= 1.10 * info["separate_differences"][pose] + 1e-9, pose
    assert (tmp_path / gait / f"{name}.dxf").exists()
