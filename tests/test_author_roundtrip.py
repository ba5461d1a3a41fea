"""mdsr author's Save scene keeps every part of the scene opened that the page does not edit (trial 5,
defect 4): a scene file's gait, regions, other cases and case names, material, title; a problem script's
too, with every case's own muscles; the muscles routed on the page are the edited case's alone."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from mdsr_opt import get_problem, load_scene
from mdsr_opt.author.export import save_scene
from mdsr_opt.author.roundtrip import kept_lines
from mdsr_opt.author.server import body_message
from mdsr_opt.author.session import Session

# the trial's C gripper (cgrip.toml), coarser, with a second case and an animation
GRIPPER = """name = "cgrip"
title = "thick C gripper, silicone, mm"
units = "mm"
[body]
outline = [[40.0, 0.0], [30.64, 25.71], [20.0, 34.64], [6.95, 39.39], [-6.95, 39.39], [-20.0, 34.64],
           [-30.64, 25.71], [-37.59, 13.68], [-40.0, 0.0], [-37.59, -13.68], [-30.64, -25.71], [-20.0, -34.64],
           [-6.95, -39.39], [6.95, -39.39], [20.0, -34.64], [30.64, -25.71], [16.85, -14.14], [11.0, -19.05],
           [3.82, -21.66], [-3.82, -21.66], [-11.0, -19.05], [-16.85, -14.14], [-20.67, -7.52], [-22.0, 0.0],
           [-20.67, 7.52], [-16.85, 14.14], [-11.0, 19.05], [-3.82, 21.66], [3.82, 21.66], [11.0, 19.05],
           [16.85, 14.14]]
resolution = 200
[material]
silicone = "dragon-skin-30"
thickness = 5.0
[fabrication]
channel_diameter = 2.0
wall = 1.5
[regions]
back = { box = [-41, -8, -35, 8] }
upper_jaw = { near = [23.7, 20.0], radius = 6 }
lower_jaw = { near = [23.7, -20.0], radius = 6 }
[[cases]]
name = "close"
description = "both jaws closed"
anchors = "back"
drags = [{ nodes = "upper_jaw", by = [0, -8] }, { nodes = "lower_jaw", by = [0, 8] }]
[[cases]]
name = "open"
anchors = "back"
drags = [{ nodes = "upper_jaw", by = [0, 4] }, { nodes = "lower_jaw", by = [0, -4] }]
[[animations]]
name = "snap"
keyframes = [["rest", 0], ["close", 1]]
[gait]
name = "grip"
poses = ["rest", "close", "open"]
"""


@pytest.fixture
def gripper(tmp_path):
    path = tmp_path / "cgrip.toml"
    path.write_text(GRIPPER)
    return path


def _saved(session, out, name):
    notes = []
    files = save_scene(session, out, name, notes=notes)
    return json.loads(Path(files[0]).read_text()), load_scene(files[0]), notes


def test_a_scene_file_saved_unedited_keeps_its_own_tables(gripper, tmp_path):
    """The trial's save: gait, regions, the case "close", the material preset, the title all come back as the
    scene file wrote them, and the saved scene reads back as the scene opened."""
    import tomllib

    src = tomllib.loads(GRIPPER)
    s = Session.from_scene_file(gripper)
    assert s.settle().success
    data, back, notes = _saved(s, tmp_path / "out", "resaved")
    assert notes == []
    for key in ("regions", "gait", "animations", "material", "title", "units", "fabrication"):
        assert data[key] == src[key], key
    assert data["cases"] == src["cases"]  # names, descriptions, region names and `by` drags as written
    scene = load_scene(gripper)
    assert back.gait == scene.gait and [c.name for c in back.cases] == ["close", "open"]
    for a, b in zip(back.cases, scene.cases):
        assert np.array_equal(a.anchors, b.anchors) and np.array_equal(a.drag_positions, b.drag_positions)
    assert {k: v.tolist() for k, v in back.regions.items()} == {k: v.tolist() for k, v in scene.regions.items()}


def test_an_edited_case_keeps_its_name_and_the_rest_stays(gripper, tmp_path):
    s = Session.from_scene_file(gripper)
    moved = s.drag_positions + [0.0, 1.0]
    s.set_fixed(s.anchors[1:], s.drag_nodes, moved)
    assert s.settle().success
    data, back, notes = _saved(s, tmp_path, "edited")
    assert [c["name"] for c in data["cases"]] == ["close", "open"] and notes == []
    close = back.case("close")
    assert close.description == "both jaws closed"
    assert np.array_equal(close.anchors, np.sort(s.anchors)) and np.array_equal(close.drag_positions, moved)
    assert data["cases"][1]["drags"][0] == {"nodes": "upper_jaw", "by": [0, 4]}  # "open" as written
    assert data["gait"]["poses"] == ["rest", "close", "open"] and "back" in data["regions"]


def test_the_page_lists_what_a_save_keeps(gripper):
    kept = body_message(Session.from_scene_file(gripper))["kept"]
    assert "gait 'grip' (poses rest, close, open): kept as loaded" in kept
    assert "case 'close': anchors and drags as set here; cases open: kept as loaded" in kept
    assert "regions back, upper_jaw, lower_jaw: kept as loaded" in kept
    assert "muscles routed here: case 'close''s alone; cases open: their muscles (or routing) as loaded" in kept
    assert body_message(Session.from_outline([[0, 0], [4, 0], [4, 1], [0, 1]], resolution=80))["kept"] == []


@pytest.mark.parametrize("problem", ["gecko", "starfish"])
def test_a_problem_scripts_gait_cases_and_regions_are_saved(problem, tmp_path):
    """A library problem has no scene file: its gait, cases, regions and animations are written out (node ids,
    exact positions) and read back equal."""
    scene = get_problem(problem, resolution="coarse")
    s = Session.from_scene(scene)
    _, back, notes = _saved(s, tmp_path, "mine")
    assert notes == []
    assert back.gait == scene.gait and back.gait is not None
    assert [c.name for c in back.cases] == [c.name for c in scene.cases]
    for a, b in zip(back.cases, scene.cases):
        assert np.array_equal(np.sort(a.anchors), np.sort(b.anchors))
        order_a, order_b = np.argsort(a.drag_nodes), np.argsort(b.drag_nodes)
        assert np.array_equal(a.drag_positions[order_a], b.drag_positions[order_b])  # bit for bit
    assert {k: sorted(v.tolist()) for k, v in back.regions.items()} == \
        {k: sorted(v.tolist()) for k, v in scene.regions.items()}
    assert back.animations == scene.animations and back.expected == scene.expected


def test_routing_on_a_scene_with_given_muscles_keeps_them_for_its_internal_cases(tmp_path):
    """two_muscles' internal cases give two contractions for the scene's two muscles; the page routes one muscle
    for a new case. The saved scene keeps the two [[muscles]] (its internal cases still load and run) and lays
    the routed one on the new case alone."""
    s = Session.from_problem("two_muscles", "coarse")
    P = s.mesh.points
    span = np.ptp(P, axis=0)
    left = np.flatnonzero(P[:, 0] < P[:, 0].min() + 0.05 * span[0])
    right = np.flatnonzero(P[:, 0] > P[:, 0].max() - 0.05 * span[0])
    s.set_fixed(left, right, P[right] + [0.0, 0.2 * span[1]])
    assert s.settle().success
    assert len(s.route(10.0, 4.0, 1)["muscles"]) == 1
    data, back, notes = _saved(s, tmp_path, "routed")
    assert notes == [] and [c["name"] for c in data["cases"]] == ["a20", "a30", "a40", "a50", "authored"]
    assert data["cases"][0]["contractions"] == [0.2, 0.2]
    assert [m.nodes for m in back.muscles] == [m.nodes for m in s.origin.scene.muscles]
    assert [m.nodes for m in back.case("authored").muscles] == [m.nodes for m in s.muscles]
    assert back.case("a20").muscles is None


def _same_run(a, b):
    """Two runs of one case designed the same muscles to the same contractions, both succeeding."""
    ra, rb = a.report, b.report
    assert ra.success and rb.success, (ra.message, rb.message)
    assert ra.muscles == rb.muscles
    np.testing.assert_allclose(ra.contractions, rb.contractions, rtol=0, atol=1e-9)


@pytest.mark.parametrize("problem, edited, kept", [("tentacle", "curl", "s_curve"),
                                                   ("gecko", "bend_left", "bend_right")])
def test_muscles_routed_for_one_case_leave_the_kept_cases_as_they_ran(problem, edited, kept, tmp_path):
    """Issue 32 item 6: the saved scene runs with the same result. The layout routed on the page is the edited
    case's own muscles: mdsr run designs that case with it as the page did, and the kept case routes its own
    layout as it did before the save (with the page's layout it failed, every muscle idle)."""
    from mdsr_opt.scenes.runner import run_case

    scene = get_problem(problem, resolution="coarse")
    s = Session.from_scene(scene)
    assert s.settle().success
    s.route(10.0, 4.0, 2)
    page = s.run_design()
    data, back, notes = _saved(s, tmp_path, "mine")
    assert notes == [] and "muscles" not in data  # no scene-wide layout: each case's is its own
    assert data["routing"] == {k: v for k, v in scene.routing_options.items()}  # the kept cases' knobs
    assert "anchor_radius" not in data["design"]
    assert any(line.startswith("material, routing knobs") for line in kept_lines(s))  # the page says it too
    assert data["cases"][[c.name for c in scene.cases].index(edited)]["anchor_radius"] == s.fixture_radius
    assert [c.get("muscles") for c in data["cases"]] == [
        [{"name": m.name, "nodes": list(m.nodes)} for m in s.muscles] if c["name"] == edited else None
        for c in data["cases"]]
    mine = run_case(back, edited, photo=False)
    assert mine.report.success and [m["nodes"] for m in mine.report.muscles] == [list(m.nodes) for m in s.muscles]
    np.testing.assert_allclose(mine.report.contractions, page["contractions"], rtol=0, atol=1e-9)
    _same_run(run_case(back, kept, photo=False), run_case(scene, kept, photo=False))


def test_design_and_fabrication_set_on_the_page_are_said_to_drive_the_kept_cases(tmp_path):
    s = Session.from_scene(get_problem("tentacle", resolution="coarse"))
    s.settle()
    s.route(10.0, 4.0, 2)
    s.run_design(a_max=0.5)
    data, back, notes = _saved(s, tmp_path, "t")
    assert notes == ["the design settings set here (a_max 0.5, was 0.6) are the scene's [design]: mdsr run designs "
                     "every case with them, also s_curve"]
    assert back.design_options["a_max"] == 0.5 and data["description"].endswith(notes[0] + ".")
    s.route(10.0, 4.0, 2, {"channel_diameter": 0.1})  # a channel size too: the [fabrication] every case routes with
    s.run_design()
    _, back, notes = _saved(s, tmp_path, "t2")
    assert notes == ["the channel, wall and fixture sizes set here (channel_diameter 0.1, was 0.06279) are the "
                     "scene's [fabrication]: mdsr run routes and checks every case's ropes with them, also s_curve"]
    assert back.routing_options["fabrication"]["channel_diameter"] == 0.1


def test_a_bad_save_name_is_called_a_scene_name(gripper, tmp_path):
    s = Session.from_scene_file(gripper)
    with pytest.raises(ValueError, match=r"^scene name 'my scene/v2' may hold only letters"):
        save_scene(s, tmp_path / "out", "my scene/v2")
    assert not (tmp_path / "out").exists()  # nothing written, not even the folder


def test_a_problem_scripts_per_case_muscles_are_saved(tmp_path):
    """face's cases lay their own muscles (a problem script's Case.muscles): the saved file holds them as each
    case's ``muscles``, and each reads back as the case's own."""
    scene = get_problem("face", resolution="coarse")
    s = Session.from_scene(scene)
    data, back, notes = _saved(s, tmp_path, "face2")
    assert notes == [] and "Saved with notes" not in data["description"]
    assert [c.name for c in back.cases] == ["smile", "frown", "wink", "pucker"] and back.muscles is None
    for c in scene.cases:
        assert [m.nodes for m in back.case(c.name).muscles] == [m.nodes for m in c.muscles], c.name
        assert [m.name for m in back.case(c.name).muscles] == [m.name for m in c.muscles], c.name


def test_a_save_that_would_not_load_leaves_no_file_and_names_the_cause(tmp_path):
    """An edit the scene file refuses (here: drags through the anchored base of a contact scene) is reported
    as the user's ValueError, not a bug, and neither file is left in the folder."""
    text = (Path(__file__).parent / "data" / "finger.toml").read_text()
    assert "[design]\n" in text
    (tmp_path / "fc.toml").write_text(text.replace("[design]\n", "[design]\ncontact = true\n", 1))
    s = Session.from_scene_file(tmp_path / "fc.toml")
    s.set_fixed(s.anchors, s.drag_nodes, s.mesh.points[s.drag_nodes] - [3.85, 0.0])
    out = tmp_path / "saved"
    with pytest.raises(ValueError, match=r"not saved: as edited, fc_edit would not load: .*prescribed nodes would"):
        save_scene(s, out, "fc_edit")
    assert sorted(p.name for p in out.iterdir()) == []
    s.set_fixed(s.anchors, s.drag_nodes, s.mesh.points[s.drag_nodes] + [0.0, 0.5])  # a drag it accepts
    assert [Path(p).name for p in save_scene(s, out, "fc_edit")] == ["fc_edit.json", "fc_edit.mesh.vtu"]
    assert sorted(p.name for p in out.iterdir()) == ["fc_edit.json", "fc_edit.mesh.vtu"]


def test_saving_a_saved_scene_again_keeps_one_authored_sentence(gripper, tmp_path):
    src = tmp_path / "mine.toml"
    src.write_text(Path(gripper).read_text().replace('units = "mm"', 'units = "mm"\ndescription = "my gripper"', 1))
    for k in range(3):
        src = save_scene(Session.from_scene_file(src), tmp_path / f"out{k}", f"s{k}")[0]
    text = json.loads(Path(src).read_text())["description"]
    assert text == "my gripper Authored on the mdsr author page from s1.json."


def test_the_page_solves_a_contact_scene_with_contact_as_mdsr_run_does(tmp_path, monkeypatch):
    """A scene with contact = true under [design]: the page's settled and live solves pass contact=True (the
    target mdsr run solves), and a live drag skips the preview, which models no contact."""
    import mdsr_opt.author.session as session_module

    text = (Path(__file__).parent / "data" / "finger.toml").read_text()
    (tmp_path / "fc.toml").write_text(text.replace("[design]\n", "[design]\ncontact = true\n", 1))
    seen, solve = [], session_module.solve_external

    def spy(*a, **k):
        seen.append(k.get("contact"))
        return solve(*a, **k)

    monkeypatch.setattr(session_module, "solve_external", spy)
    monkeypatch.setattr(Session, "_preview", lambda *a: pytest.fail("the contact-free preview was used"))
    s = Session.from_scene_file(tmp_path / "fc.toml")
    assert s.settle().success
    s.set_fixed(s.anchors, s.drag_nodes, s.drag_positions + [0.0, 0.05])
    assert s.drag().success
    assert seen and all(c is True for c in seen), seen
