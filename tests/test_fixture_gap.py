"""A rope's two end fixtures never meet in a designed state (trial7 defect 1: a plate's design succeeded with a
rope at a_max = 0.6 whose fixtures, radius 0.0949, ended 0.187 apart; the virtual prototype then failed).

Each fixture is a disk of ``anchor_radius`` r centred on a rope's end node; the two slide towards each other
along the rope's channel and need ``2 r + wall`` of rope between their centres (as ``rope_conflicts`` asks of
the fixtures of two ropes). The design caps each contraction so that a taut rope keeps that length, designs
again with a lower cap when the state still leaves less, and refuses a design whose state does."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pytest

from mdsr_opt import Mesh, Muscle, NeoHookean, design_contractions, solve_internal
from mdsr_opt.synthesis import contractions, problem
from mdsr_opt.synthesis.problem import fixture_caps, fixture_overlaps

R, WALL = 0.1, 0.04
NEED = 2 * R + WALL


@pytest.fixture(scope="module")
def strip():
    """A 4 x 1 strip, a rope 0.5 long on its bottom edge and a target the rope makes at a = 0.58 (0.21 of rope
    between its ends: less than two fixtures of radius 0.1 with a wall 0.04 between them need, 0.24)."""
    mesh = Mesh.rectangle(4.0, 1.0, 32, 8)
    mat = NeoHookean(1.0, 0.3)
    rope = Muscle(range(0, 5))
    t = solve_internal(mesh, mat, [rope], [0.58], anchor_radius=R)
    assert t.success
    x = t.x.reshape(-1, 2)
    assert rope.length(x) < NEED - 0.02  # the target itself brings the fixtures together
    return mesh, mat, rope, t.x


def _ends(x, rope) -> float:  # the rope left between the fixtures' centres, along its path
    return rope.length(np.asarray(x).reshape(-1, 2))


def _design(strip):
    mesh, mat, rope, target = strip
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the rope ends at its cap: the MuscleWarning is not the point here
        return design_contractions(mesh, mat, [rope], target, anchor_radius=R, fixture_wall=WALL)


def test_a_design_keeps_the_fixtures_of_a_short_strongly_contracted_rope_apart(strip):
    mesh, _mat, rope, _target = strip
    res = _design(strip)
    # before: success with a = 0.58 and 0.21 of rope between the fixtures
    assert res.success, res.status
    assert _ends(res.x, rope) >= NEED - 1e-9
    cap = 1.0 - NEED / rope.length(mesh.points)
    assert res.contractions[0] == pytest.approx(cap, abs=1e-6)  # as far as the fixtures allow, not given up
    assert "at the most their ropes can shorten" in res.status


def test_a_design_whose_fixtures_still_meet_is_no_success(strip, monkeypatch):
    # the prevention switched off: the check of the designed state alone
    monkeypatch.setattr(problem, "fixture_caps", lambda points, muscles, radius, wall: np.ones(len(muscles)))
    monkeypatch.setattr(contractions, "FIXTURE_REDESIGNS", 0)
    res = _design(strip)
    d = _ends(res.x, strip[2])
    assert d < NEED
    assert not res.success
    m = re.search(r"rejected: end fixtures meet in the designed state: rope M1 at a = (\S+) leaves (\S+) of rope "
                  r"between its end fixtures' centres \(0.5 at rest\), less than two fixtures of radius 0.1 with a "
                  r"wall 0.04 need \(0.24\)", res.status)
    assert m, res.status
    assert float(m.group(1)) == pytest.approx(res.contractions[0], abs=1e-3)
    assert float(m.group(2)) == pytest.approx(d, rel=1e-3)


def test_fixture_caps_and_overlaps_by_hand():
    P = np.array([[0.0, 0.0], [0.3, 0.4], [0.6, 0.0], [1.0, 0.0]])
    mus = [Muscle([0, 1, 2]), Muscle([0, 1, 2, 3])]  # 1.0 and 1.4 long along their paths (ends 0.6, 1.0 apart)
    assert fixture_caps(P, mus, 0.1, 0.05).tolist() == pytest.approx([1 - 0.25 / 1.0, 1 - 0.25 / 1.4])
    assert fixture_caps(P, mus, 0.0, 0.05).tolist() == [1.0, 1.0]  # no fixtures, nothing to meet
    # the first rope is shorter than its fixtures at rest: no contraction helps (its layout's to fix), uncapped
    assert fixture_caps(P, mus, 0.55, 0.05).tolist() == pytest.approx([1.0, 1 - 1.15 / 1.4])
    assert [(c, round(l0, 6)) for c, l0, _ in problem.short_ropes(P, mus, 0.55, 0.05)] == [(0, 1.0)]
    assert fixture_overlaps(P, mus, 0.1, 0.05) == []
    hit = fixture_overlaps(P, mus, 0.5, 0.05)  # need 1.05: the first rope is 1.0 long
    assert [(c, round(d, 6), round(n, 6)) for c, d, n in hit] == [(0, 1.0, 1.05)]
    assert fixture_overlaps(P, mus, 0.5, 0.05, rest=P) == []  # too short already at rest: not the design's doing


SCENE = """
name = "gap"
[body]
outline = [[0, 0], [4, 0], [4, 1], [0, 1]]
resolution = "coarse"
[material]
model = "neo-hookean"
E = 1.0
nu = 0.3
[[muscles]]
name = "short"
path = [[1.5, 0.5], [2.1, 0.5]]
[design]
anchor_radius = 0.12
[fabrication]
wall = 0.05
[[cases]]
name = "squeeze"
contractions = [0.58]
"""


def test_mdsr_run_fails_a_case_whose_fixtures_meet(tmp_path, monkeypatch, capsys):
    from mdsr_opt.cli.main import main

    # the prevention switched off: the check of the designed state alone must fail the case
    monkeypatch.setattr(problem, "fixture_caps", lambda points, muscles, radius, wall: np.ones(len(muscles)))
    monkeypatch.setattr(contractions, "FIXTURE_REDESIGNS", 0)
    path = tmp_path / "gap.toml"
    path.write_text(SCENE)
    code = main(["run", str(path), "--out", str(tmp_path / "o"), "--serial", "--no-photos", "--no-figures",
                 "--no-animations", "--no-prototype"])
    out = capsys.readouterr().out
    assert code == 1, out
    row = [line for line in out.splitlines() if line.startswith("| gap | squeeze |")]
    assert len(row) == 1 and "FAILED (the end fixtures of rope short would meet" in row[0], out
    assert re.search(r"FAILED gap/squeeze: design \w+: the end fixtures of rope short would meet: at a = 0.58 \S+ "
                     r"of rope is left between their centres, 0.29 needed", out), out


def test_mdsr_run_designs_the_short_rope_buildable(tmp_path, capsys):
    from mdsr_opt.cli.main import main
    from mdsr_opt.scenes.scenefile import load_scene

    path = tmp_path / "gap.toml"
    path.write_text(SCENE)
    main(["run", str(path), "--out", str(tmp_path / "o"), "--serial", "--no-photos", "--no-figures",
          "--no-animations", "--no-prototype"])
    import json

    case = json.loads((tmp_path / "o" / "summary.json").read_text())["cases"][0]
    scene = load_scene(path)
    mus = scene.muscles
    p = scene.mesh.points
    l0 = mus[0].length(p)
    assert case["contractions"][0] <= 1 - 0.29 / l0 + 1e-6  # capped below the known 0.58
    assert case["contractions"][0] < 0.58 - 0.01  # the known contraction would bring the fixtures together
    assert "end fixtures" in case["design_status"]
    assert Path(tmp_path / "o").is_dir()


PLATE = """
name = "plate2win"
[body]
outline = [[0,0],[6,0],[6,2],[0,2]]
holes = [[[1,0.6],[2.5,0.6],[2.5,1.4],[1,1.4]], [[3.5,0.6],[5,0.6],[5,1.4],[3.5,1.4]]]
resolution = 400
[regions]
base = { box = [-1, -1, 0, 3] }
tip = { box = [6, -1, 7, 3] }
[[cases]]
name = "lift"
anchors = "base"
drags = [{ nodes = "tip", by = [-0.8, 1.8] }]
"""


@pytest.mark.slow
def test_the_trial7_plate_designs_ropes_whose_fixtures_stay_apart(tmp_path):
    # trial7's reproducer: routed rope M8 designed to a = 0.6 with its ends 0.187 apart (fixtures of radius
    # 0.0949: 2 r = 0.190), the design a success and its virtual prototype failed
    from mdsr_opt.scenes.casefab import fixture_wall
    from mdsr_opt.scenes.runner import run_case
    from mdsr_opt.scenes.scenefile import load_scene

    path = tmp_path / "plate.toml"
    path.write_text(PLATE)
    scene = load_scene(path)
    run = run_case(scene, "lift")
    assert run.report.success, run.report.message
    res, mus = run.design, run.setup.muscles
    need = 2 * res.anchor_radius + fixture_wall(scene)
    assert res.anchor_radius == pytest.approx(0.09487, rel=1e-3) and need == pytest.approx(0.2530, rel=1e-3)
    for m in mus:
        assert _ends(res.x, m) >= need - 1e-9, (m.name, _ends(res.x, m), need)
        x = np.asarray(res.x).reshape(-1, 2)  # and the two disks do not overlap in the plane (M8: 0.187 < 0.190)
        assert np.linalg.norm(x[m.nodes[-1]] - x[m.nodes[0]]) >= 2 * res.anchor_radius, m.name
