"""A scene's gait designs its poses with the fixtures the cases used and keeps the scene's muscle names, so
the gait's files agree with the case results for the same muscle and target (new-user trial defect 5: 0.233
and 10.26 mm in the gait against 0.200 and 8.79 mm in the case, fixtures of radius 1.5 against 4, the
muscle renamed M1); a gait whose fixtures must differ says so."""

from __future__ import annotations

import csv
import json

import numpy as np

from mdsr_opt import Muscle
from mdsr_opt.scenes.runscene import run_scene
from mdsr_opt.scenes.scenefile import load_scene
from mdsr_opt.scenes.gaitrun import _radius_note
from mdsr_opt.synthesis.layouts import shared_layout


def ring(r: float, n: int = 48) -> list:
    t = 2 * np.pi * np.arange(n) / n
    return np.round(np.c_[r * np.cos(t), r * np.sin(t)], 3).tolist()


def test_the_gait_of_a_scene_with_its_own_muscle_agrees_with_its_cases(tmp_path):
    spec = {"name": "thick_ring", "units": "mm",
            "body": {"outline": ring(50.0), "holes": [ring(28.0)], "resolution": "coarse"},
            "material": {"E": 1.0, "nu": 0.4},
            "regions": {"bottom": {"near": [0, -50], "radius": 8, "boundary": True},
                        "top": {"near": [0, 50], "radius": 8, "boundary": True}},
            "muscles": [{"name": "inner_left", "boundary": {"from": [-28, 0], "to": [0, 28]}}],
            "cases": [{"name": "squash", "anchors": "bottom", "drags": [{"nodes": "top", "by": [0, -20]}]},
                      {"name": "pull", "contractions": [0.2]}],
            "gait": {"poses": ["squash", "rest", "pull"], "max_muscles": 4}}
    path = tmp_path / "thick_ring.json"
    path.write_text(json.dumps(spec))
    out = tmp_path / "out"
    run_scene(load_scene(path), out, photos=False, figures=False, animations=True, prototype=False, log=None,
              background=False)
    summary = json.loads((out / "summary.json").read_text())
    case = {c["case"]: c for c in summary["cases"]}
    layout = json.loads((out / "gait" / "layout.json").read_text())
    gait = json.loads((out / "gait" / "gait.json").read_text())
    assert [m["name"] for m in layout["muscles"]] == ["inner_left"] == gait["muscles"]
    lines = (out / "gait" / "thick_ring_muscles.csv").read_text().splitlines()
    # one muscle cannot squash the ring: the gait failed, and its fabrication table says so first
    assert not gait["success"] and lines[0].startswith("# FAILED DESIGN: the layout's design failed (pose squash")
    rows = list(csv.DictReader(line for line in lines if not line.startswith("#")))  # after FAILED, NOT MOULDABLE
    assert [r["muscle"] for r in rows] == ["inner_left"]
    k = layout["names"].index("pull")
    np.testing.assert_allclose(layout["contractions"][k][0], 0.2, atol=1e-6)        # the known contraction
    np.testing.assert_allclose(float(rows[0]["contraction pull [1]"]), 0.2, atol=1e-6)
    np.testing.assert_allclose(layout["differences"][k], case["pull"]["difference"], atol=1e-6)
    np.testing.assert_allclose(layout["strokes"][k], case["pull"]["stroke"], rtol=1e-6)   # 8.79 mm both
    np.testing.assert_allclose(float(rows[0]["stroke pull [mm]"]), case["pull"]["stroke"][0], rtol=1e-6)
    np.testing.assert_allclose(layout["anchor_radius"], 0.04 * 100.0, rtol=1e-3)   # the scene's: 0.04 x size
    assert "notes" not in gait


def test_a_gait_with_other_fixtures_than_its_cases_says_so():
    note = _radius_note(1.5, {"squash": 4.0, "pull": 4.0}, "mm")
    assert note.startswith("the gait's end fixtures have radius 1.5 mm, the cases' designs squash 4, pull 4 mm")
    assert "differ from the cases'" in note
    assert _radius_note(4.0, {"squash": 4.0, "pull": 4.0}, "mm") == ""


def test_the_shared_layout_keeps_given_names_and_numbers_routed_ones():
    from mdsr_opt import Mesh

    mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    a, b = Muscle(range(0, 8), name="bottom_left"), Muscle(range(8, 16), name="M1")
    mus, _ = shared_layout(mesh, {"p": [a], "q": [b]})
    # names no other muscle takes are kept (a routed M1 stays M1: one name per rope in every figure)
    assert [m.name for m in mus] == ["bottom_left", "M1"]
    mus, _ = shared_layout(mesh, {"p": [Muscle(range(0, 8), name="M1")], "q": [Muscle(range(8, 16), name="M1")]})
    assert [m.name for m in mus] == ["M1", "M2"]                       # two poses' own M1: by place
    mus, _ = shared_layout(mesh, {"p": [Muscle(range(0, 8), name="x")], "q": [Muscle(range(8, 16), name="x")]})
    assert [m.name for m in mus] == ["M1", "M2"]                       # one name twice: by place


def test_an_external_case_of_a_scene_with_muscles_says_it_is_not_routed():
    """README (d): the scene's [[muscles]] are used for an external case, and the case's messages say so."""
    from mdsr_opt.scenes.runner import run_case

    spec = {"name": "s", "body": {"outline": [[0, 0], [4, 0], [4, 1], [0, 1]], "resolution": 60},
            "regions": {"base": {"box": [-1, -1, 0, 2]}, "end": {"box": [4, -1, 5, 2]}},
            "muscles": [{"name": "lower", "path": [[0.3, 0.0], [3.7, 0.0]]}],
            "cases": [{"name": "bend", "anchors": "base", "drags": [{"nodes": "end", "by": [-0.3, 0.6]}]}]}
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "s.json"
        path.write_text(json.dumps(spec))
        scene = load_scene(path)
    lines: list[str] = []
    run = run_case(scene, "bend", photo=False, log=lines.append)
    said = [s for s in lines if "not routed" in s]
    assert len(said) == 1 and "the scene's 1 muscle(s) (lower) are designed for this target" in said[0], lines
    assert run.setup.routing is None and [m.name for m in run.setup.muscles] == ["lower"]
