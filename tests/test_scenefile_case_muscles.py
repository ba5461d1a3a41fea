"""A scene file's case may lay its own muscles (``muscles = [...]``, with ``anchor_radius``), as a Python
Case can: the scene's [[muscles]] (or a routing) drive the other cases."""

from __future__ import annotations

import json

import numpy as np
import pytest

from mdsr_opt import Case, load_scene
from mdsr_opt.body.muscles import Muscle
from mdsr_opt.scenes.cases import prepare_case
from mdsr_opt.synthesis.fabrication import FabricationWarning
from conftest import STRIP_HEAD

STRIP = STRIP_HEAD + """[[muscles]]
name = "lower"
boundary = { from = [0, 0], to = [4, 0] }
[[cases]]
name = "squeeze"
contractions = [0.2]
[[cases]]
name = "up"
anchors = "left"
drags = [{ nodes = "right", by = [0, 0.5] }]
anchor_radius = 0.1
[[cases.muscles]]
name = "top"
boundary = { from = [4, 1], to = [0, 1] }
[[cases]]
name = "down"
anchors = "left"
drags = [{ nodes = "right", by = [0, -0.5] }]
"""


def _load(tmp_path, text=STRIP, suffix=".toml"):
    path = tmp_path / f"strip{suffix}"
    path.write_text(text)
    return load_scene(path)


def test_a_cases_own_muscles_drive_it_alone(tmp_path):
    scene = _load(tmp_path)
    up, down = scene.case("up"), scene.case("down")
    top = [m.nodes for m in up.muscles]
    assert [m.name for m in up.muscles] == ["top"] and up.anchor_radius == 0.1
    assert down.muscles is None and down.anchor_radius is None and scene.case("squeeze").muscles is None
    P = scene.mesh.points
    assert np.allclose(P[list(top[0]), 1], 1.0)  # along the upper side, not the scene's lower muscle
    # the given ropes lie on the outline: the check names each case's fixtures, up's at its own radius
    with pytest.warns(FabricationWarning, match=r"case 'up'.* a fixture of radius 0\.1 with"):
        assert [m.nodes for m in prepare_case(scene, "up").muscles] == top
    with pytest.warns(FabricationWarning, match=r"case 'down'.* a fixture of radius 0\.1649 with"):
        assert [m.nodes for m in prepare_case(scene, "down").muscles] == [m.nodes for m in scene.muscles]


def test_a_cases_own_muscles_read_back_from_json_as_node_ids(tmp_path):
    """The round trip the authoring page makes: own muscles written as node ids read back the same."""
    scene = _load(tmp_path)
    data = {"name": "strip2", "body": {"outline": [[0, 0], [4, 0], [4, 1], [0, 1]], "resolution": 80},
            "muscles": [{"name": "lower", "nodes": list(scene.muscles[0].nodes)}],
            "cases": [{"name": "squeeze", "contractions": [0.2]},
                      {"name": "up", "anchors": scene.case("up").anchors.tolist(),
                       "drags": [{"nodes": [int(i)], "to": p.tolist()} for i, p in
                                 zip(scene.case("up").drag_nodes, scene.case("up").drag_positions)],
                       "muscles": [{"name": m.name, "nodes": list(m.nodes)} for m in scene.case("up").muscles],
                       "anchor_radius": 0.1}]}
    back = _load(tmp_path, json.dumps(data), ".json")
    assert [m.nodes for m in back.case("up").muscles] == [m.nodes for m in scene.case("up").muscles]
    assert back.case("up").anchor_radius == 0.1 and back.case("squeeze").contractions.tolist() == [0.2]


@pytest.mark.parametrize("old, new, message", [
    ("[[cases.muscles]]\nname = \"top\"", "[[cases.muscles]]\nnme = \"top\"",
     r"cases\[1\]\.muscles\[0\]\.nme: unknown field \(did you mean 'name'\?\)"),
    ("anchor_radius = 0.1\n", "anchor_radus = 0.1\n",
     r"cases\[1\]\.anchor_radus: unknown field \(did you mean 'anchor_radius'\?\)"),
    ("contractions = [0.2]", "contractions = [0.2]\nanchors = [0, 1]",
     r"cases\[0\]\.anchors: an internal case \(with contractions\) has no anchors or drags: it drives the "
     r"scene's \[\[muscles\]\] \(or its own muscles\), one contraction each"),
    ("anchor_radius = 0.1\n[[cases.muscles]]\nname = \"top\"\nboundary = { from = [4, 1], to = [0, 1] }\n",
     "anchor_radius = 0.1\n", r"cases\[1\]\.anchor_radius: is the end-fixture radius of the case's own muscles"),
    ("anchor_radius = 0.1\n[[cases.muscles]]\nname = \"top\"\nboundary = { from = [4, 1], to = [0, 1] }\n",
     "muscles = []\n", r"cases\[1\]\.muscles: is empty: give at least one muscle, or leave the key out"),
    ("anchor_radius = 0.1\n", "anchor_radius = -0.1\n", r"cases\[1\]\.anchor_radius: must be >= 0, got -0\.1"),
    ("anchor_radius = 0.1\n", "anchor_radius = 3.0\n", r"case 'up': anchor_radius 3 is at least half the body"),
    ("boundary = { from = [4, 1], to = [0, 1] }\n[[cases]]", "nodes = [0, 999]\n[[cases]]",
     r"cases\[1\]\.muscles\[0\]\.nodes: .*999"),
])
def test_bad_case_muscles_are_named_at_the_door(tmp_path, old, new, message):
    assert STRIP.count(old) == 1
    with pytest.raises(ValueError, match=message):
        _load(tmp_path, STRIP.replace(old, new))


def test_a_python_case_takes_anchor_radius_only_with_its_own_muscles():
    with pytest.raises(ValueError, match=r"case 'up': anchor_radius is the end-fixture radius of the case's own"):
        Case("up", anchors=[0, 1], anchor_radius=0.1)
    with pytest.raises(ValueError, match=r"case 'up': anchor_radius"):
        Case("up", anchors=[0, 1], muscles=(Muscle((0, 1)),), anchor_radius=-1.0)
    assert Case("up", anchors=[0, 1], muscles=(Muscle((0, 1)),), anchor_radius=0.2).anchor_radius == 0.2


def test_mdsr_run_designs_a_case_with_its_own_muscles_and_fixture_radius(tmp_path):
    from mdsr_opt.scenes.runner import run_case

    scene = _load(tmp_path)
    lines: list[str] = []
    run = run_case(scene, "up", photo=False, log=lines.append)
    said = [s for s in lines if "not routed" in s]
    assert said == ["not routed: the case's own 1 muscle(s) (top) are designed for this target"], lines
    assert run.design is not None and run.design.anchor_radius == 0.1  # the case's, not the default 0.1649
    assert [m["name"] for m in run.report.muscles] == ["top"]
    assert "a fixture of radius 0.1 with" in run.report.fabrication[0]  # reported, as for the scene's muscles


def test_an_animation_solves_with_the_fixtures_of_the_cases_own_muscles(tmp_path, monkeypatch):
    """The scene's [design] anchor_radius is 0.1, the animated case's own muscles have fixtures of 0.25: the
    animation's frames are solved with 0.25, as the case was designed (not the scene's 0.1)."""
    from pathlib import Path

    import mdsr_opt.mechanics.equilibrium as equilibrium
    from mdsr_opt.scenes.runscene import run_scene

    text = (Path(__file__).parent / "data" / "finger.toml").read_text()
    text = text.replace("[design]\n", "[design]\nanchor_radius = 0.1\n", 1)
    text = text.replace('drags = [{ nodes = "tip", rotate = 60, about = [0, 0.5] }]\n',
                        'drags = [{ nodes = "tip", rotate = 60, about = [0, 0.5] }]\n'
                        'muscles = [{ name = "own", path = [[0.3, 0.7], [3.3, 0.7]] }]\nanchor_radius = 0.25\n', 1)
    text = text.replace('keyframes = [["rest", 0], ["contract", 1], ["rest", 0]]',
                        'keyframes = [["rest", 0], ["bend", 1]]')
    assert text.count("anchor_radius") == 2 and '["bend", 1]' in text
    (tmp_path / "fr.toml").write_text(text)
    seen, solve = [], equilibrium.solve_internal

    def spy(*a, **k):
        seen.append(k.get("anchor_radius"))
        return solve(*a, **k)

    monkeypatch.setattr(equilibrium, "solve_internal", spy)  # the design's checks and the animation's frames
    scene = load_scene(tmp_path / "fr.toml")
    run_scene(scene, tmp_path / "run", cases=["bend"], photos=False, prototype=False, log=None, background=False)
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert [c["case"] for c in summary["cases"]] == ["bend"] and summary["cases"][0]["success"]
    assert (tmp_path / "run" / f"{scene.animations[0].name}.gif").is_file()  # the animation ran, here
    assert seen and set(seen) == {0.25}, seen
