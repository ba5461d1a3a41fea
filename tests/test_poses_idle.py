"""design_poses drops a muscle that no pose uses, as design_pipeline drops an idle one (new-user trial 11,
defect 4: on a star bent left and right, M3 carried no tension in either pose and went into the SVG, DXF and
CSV to be moulded, with no word); a shared-layout design's warnings name their pose."""

from __future__ import annotations

import csv
import json
import warnings

import numpy as np
import pytest

from mdsr_opt import Mesh, NeoHookean, nodes_near, solve_external
from mdsr_opt.synthesis.export import export_fabrication
from mdsr_opt.synthesis.poses import design_poses
from mdsr_opt.synthesis.poses_result import PosesResult
from mdsr_opt.synthesis.results import MuscleWarning

MAT = NeoHookean(1.0, 0.3)


@pytest.fixture(scope="module")
def star():
    """A five-point star (112 nodes, mm), its top point turned 35 degrees left and right about (0, 15)."""
    k = np.arange(10)
    r, th = np.where(k % 2 == 0, 50.0, 22.0), np.pi / 2 + k * np.pi / 5
    mesh = Mesh.from_polygon(np.c_[r * np.cos(th), r * np.sin(th)], max_area=30)
    P, centre, tip = mesh.points, nodes_near(mesh, [0, 0], 8), nodes_near(mesh, [0, 50], 6)

    def pose(deg):
        c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
        turned = (P[tip] - [0.0, 15.0]) @ np.array([[c, -s], [s, c]]).T + [0.0, 15.0]
        res = solve_external(mesh, MAT, centre, dict(zip(map(int, tip), turned)))
        assert res.success
        return res.x

    return mesh, {"left": pose(35), "right": pose(-35)}


def designed(mesh, poses, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return design_poses(mesh, MAT, poses, max_muscles=4, units="mm", **kw)


def test_a_muscle_no_pose_uses_is_dropped_said_saved_and_not_exported(star, tmp_path):
    mesh, poses = star
    before = designed(mesh, poses, idle_contraction=0)  # every muscle kept: the layout as it was
    res = designed(mesh, poses)
    names = [m.name for m in before.muscles]
    assert names == ["M1", "M2", "M3", "M4"]
    j = names.index("M3")
    # M3 pulls in no pose: slack where it is engaged (left), released where its path lengthens (right)
    assert before.engaged[:, j].tolist() == [True, False] and np.nanmax(before.tensions[:, j]) == 0.0
    assert [m.name for m in res.muscles] == ["M1", "M2", "M4"]  # the others keep their names
    assert [d.name for d in res.dropped] == ["M3"] and res.dropped[0].nodes == tuple(before.muscles[j].nodes)
    assert (np.nanmax(res.tensions, axis=0) > 0).all()  # every muscle kept pulls in some pose
    assert res.sources == tuple(s for i, s in enumerate(before.sources) if i != j)
    np.testing.assert_allclose(res.differences, before.differences, rtol=1e-6)  # a slack rope changed nothing
    assert res.success and res.pose_success.all()
    said = [n for n in res.notes if n.startswith("idle muscle M3 dropped from the shared layout: no pose uses it")]
    assert len(said) == 1 and "left: slack (contraction" in said[0] and "right: released" in said[0]
    assert "pose(s) left designed again without it" in said[0]
    assert not any("idle" in n for n in before.notes)
    assert res.table().splitlines()[-1] == "dropped, no pose uses it: M3" and "dropped" not in before.table()
    back = PosesResult.load(res.save(tmp_path / "layout.json"))
    assert back.dropped == res.dropped and back.notes == res.notes
    files = export_fabrication(mesh, res, tmp_path / "parts", name="star")
    rows = list(csv.DictReader(open(files["csv"])))
    assert [r["muscle"] for r in rows] == ["M1", "M2", "M4"]


def test_an_idle_muscle_is_kept_with_a_warning_when_a_pose_fails_without_it(star, monkeypatch):
    """A pose designed again without the idle muscle that fails (here a stand-in failure) keeps the layout
    as it was, as design_active keeps an idle muscle: a MuscleWarning and a note name it."""
    import mdsr_opt.synthesis.contractions as contractions

    real = contractions.design_contractions

    def fails_again(*a, **kw):
        d = real(*a, **kw)
        if "initial_guess" in kw:  # the design made again without the idle muscle, started from the one with it
            d.success, d.verification, d.status = False, None, "stand-in: the optimiser stopped short"
        return d

    monkeypatch.setattr(contractions, "design_contractions", fails_again)
    mesh, poses = star
    with pytest.warns(MuscleWarning, match=r"design_poses: idle muscle\(s\) M3 kept in the shared layout "
                                           r"\(no pose uses them: M3: left: slack"):
        res = design_poses(mesh, MAT, poses, max_muscles=4, units="mm", compare=False)
    assert [m.name for m in res.muscles] == ["M1", "M2", "M3", "M4"] and res.dropped == ()
    said = [n for n in res.notes if n.startswith("idle muscle(s) M3 kept")]
    assert len(said) == 1 and "the design without them failed (left: stand-in: the optimiser stopped short" in said[0]
    assert res.success  # the design with it stands


def test_the_shared_layouts_warnings_name_their_pose(star):
    mesh, poses = star
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        design_poses(mesh, MAT, poses, max_muscles=4, units="mm", design_options={"a_max": 0.1}, compare=False)
    said = [str(x.message) for x in w if issubclass(x.category, MuscleWarning) and "saturated" in str(x.message)]
    assert len(said) == 2
    assert said[0].startswith("design_poses: pose 'left' on the shared layout: muscle(s) M1 (a = 0.1) saturated")
    assert said[1].startswith("design_poses: pose 'right' on the shared layout: muscle(s) ")


@pytest.mark.parametrize("value, error, words", [
    (0.7, ValueError, "idle_contraction (0.7) must lie below a_max (0.6)"),
    (-0.1, ValueError, "idle_contraction"),
    ("0.01", TypeError, "idle_contraction"),
])
def test_idle_contraction_is_checked_at_the_door(value, error, words):
    mesh = Mesh.rectangle(4.0, 1.0, 8, 2)
    with pytest.raises(error) as err:
        design_poses(mesh, MAT, {"up": mesh.points * [1.0, 1.1]}, idle_contraction=value)
    assert words in str(err.value)


def test_mdsr_run_drops_a_given_rope_no_pose_of_its_gait_uses(tmp_path):
    """Two poses of a strip bent by its upper rope (internal cases keep the lower rope at contraction 0): the
    gait's layout drops the lower rope, released in both, and the run's summary says so."""
    from mdsr_opt.scenes.runscene import run_scene
    from mdsr_opt.scenes.scenefile import load_scene

    spec = {"name": "strip", "units": "mm",
            "body": {"outline": [[0, 0], [100, 0], [100, 30], [0, 30]], "resolution": "coarse"},
            "material": {"E": 1.0, "nu": 0.4},
            "fabrication": {"channel_diameter": 1.0, "wall": 1.0, "fixture_radius": 2.0},
            "muscles": [{"name": "upper", "path": [[15, 24], [50, 24], [85, 24]]},
                        {"name": "lower", "path": [[15, 6], [50, 6], [85, 6]]}],
            "cases": [{"name": "up", "contractions": [0.1, 0.0]}, {"name": "higher", "contractions": [0.15, 0.0]}],
            "gait": {"name": "wave", "poses": ["up", "rest", "higher"]}}
    path = tmp_path / "strip.json"
    path.write_text(json.dumps(spec))
    out, said = tmp_path / "out", []
    run_scene(load_scene(path), out, photos=False, figures=False, animations=False, prototype=False,
              log=said.append, background=False)
    layout = json.loads((out / "wave" / "layout.json").read_text())
    gait = json.loads((out / "wave" / "wave.json").read_text())
    assert [m["name"] for m in layout["muscles"]] == ["upper"] == gait["muscles"]
    assert [d["name"] for d in gait["dropped"]] == ["lower"] and gait["success"]
    rows = list(csv.DictReader((out / "wave" / "strip_muscles.csv").read_text().splitlines()))
    assert [r["muscle"] for r in rows] == ["upper"]
    md = (out / "summary.md").read_text()
    assert "- **gait wave**\n  - idle muscle lower dropped from the shared layout: no pose uses it (up: released" in md
    assert "[strip] gait wave: idle lower dropped from the shared layout (no pose uses it)" in said
