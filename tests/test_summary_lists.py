"""summary.json's per-muscle lists line up (trial 7, defect 5): a case's ``muscles`` names exactly the muscles
whose contractions, achieved contractions, strokes, tensions and stroke bands it gives (the designed layout);
a muscle the design dropped is named in ``dropped`` only."""

from __future__ import annotations

import json

import numpy as np
import pytest

from mdsr_opt import load_scene

SCENE = """name = "drop"
[body]
outline = [[0, 0], [4, 0], [4, 1], [0, 1]]
resolution = "coarse"
[[muscles]]
name = "low"
path = [[0.3, 0.3], [3.3, 0.3]]
[[muscles]]
name = "high"
path = [[0.3, 0.7], [3.3, 0.7]]
[[muscles]]
path = [[0.3, 0.5], [3.3, 0.5]]
[[cases]]
name = "up"
anchors = [[0, 0], [0, 1], [0, 0.5]]
drags = [{ at = [4, 1], by = [-0.5, 1.0] }]
[acceptance]
bands = true
"""


def test_a_dropped_muscle_is_named_only_in_dropped_and_the_lists_pair_names_with_values(tmp_path):
    from mdsr_opt.scenes.runscene import run_scene

    (tmp_path / "drop.toml").write_text(SCENE)
    scene = load_scene(tmp_path / "drop.toml")
    run_scene(scene, tmp_path / "o", photos=False, prototype=False, figures=False, animations=False, log=None,
              background=False)
    case = json.loads((tmp_path / "o" / "summary.json").read_text())["cases"][0]
    dropped = [d["name"] for d in case["dropped"]]
    assert "low" in dropped  # the lower rope is slack when the tip is lifted (the middle one may be too)
    names = [m["name"] for m in case["muscles"]]
    assert names == [n for n in ("low", "high", "M3") if n not in dropped] and case["n_muscles"] == len(names) >= 1
    for key in ("contractions", "achieved", "stroke", "tension", "stroke_band"):
        assert len(case[key]) == len(names), (key, case[key])
    # each name's nodes belong with its values: its stroke is its achieved contraction times its rest length
    P = scene.mesh.points
    for m, a, s in zip(case["muscles"], case["achieved"], case["stroke"]):
        L0 = float(np.linalg.norm(np.diff(P[m["nodes"]], axis=0), axis=1).sum())
        assert s == pytest.approx(a * L0, rel=1e-9), m["name"]
        given = next(g for g in scene.muscles if g.label(scene.muscles.index(g)) == m["name"])
        assert list(given.nodes) == m["nodes"]
    for (lo, hi), s in zip(case["stroke_band"], case["stroke"]):
        assert lo <= s <= hi
    row = next(line for line in (tmp_path / "o" / "summary.md").read_text().splitlines() if "| up |" in line)
    assert f"| {len(names)} |" in row and f"dropped {', '.join(dropped)}" in row


def test_an_unnamed_muscle_is_named_by_its_place_with_or_without_a_drop(tmp_path):
    """trial 7 (fixa): summary.json wrote an unnamed muscle as ``name: null`` in a case with no drop and as
    "M3" in a case with one; now always by its label, as every table, figure and file names it."""
    from mdsr_opt.scenes.runscene import run_scene

    text = SCENE.replace("[acceptance]\nbands = true\n", '[[cases]]\nname = "c"\ncontractions = [0.05, 0.05, 0.05]\n')
    (tmp_path / "drop.toml").write_text(text)
    run_scene(load_scene(tmp_path / "drop.toml"), tmp_path / "o", photos=False, prototype=False, figures=False,
              animations=False, log=None, background=False)
    cases = {c["case"]: c for c in json.loads((tmp_path / "o" / "summary.json").read_text())["cases"]}
    dropped = [d["name"] for d in cases["up"]["dropped"]]
    assert "low" in dropped
    assert sorted([m["name"] for m in cases["up"]["muscles"]] + dropped) == ["M3", "high", "low"]  # never None
    assert not cases["c"].get("dropped") and cases["c"]["success"], cases["c"].get("message")
    assert [m["name"] for m in cases["c"]["muscles"]] == ["low", "high", "M3"]  # before: ["low", "high", None]
