"""A command line and API that say what they do (issue 36, a new-user trial): `mdsr study recommend --help`
is the study's own help, recommend takes scene files as `mdsr run` does, unknown names get a "did you mean",
empty drags are refused at the door, and a target no muscle can make says why."""

from __future__ import annotations

import csv
import warnings
from pathlib import Path

import pytest

from mdsr_opt import Mesh, NeoHookean, solve_external
from mdsr_opt.body.silicone import silicone
from mdsr_opt.cli.main import main
from mdsr_opt.scenes.library import get_problem
from mdsr_opt.studies.problems import get_study_problem
from mdsr_opt.studies.recommend import run_recommendation
from mdsr_opt.synthesis.pipeline import design_pipeline
from mdsr_opt.synthesis.routing import RoutingWarning, route_muscles

ROOT = Path(__file__).resolve().parents[1]
FINGER = ROOT / "tests" / "data" / "finger.toml"


def test_study_recommend_help_is_its_own(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["study", "recommend", "--help"])
    text = capsys.readouterr().out
    assert exc.value.code == 0 and text.startswith("usage: mdsr study recommend")
    assert "recommend.csv" in text and "--stroke-tol" in text and "--scenes" in text
    assert "--problems" not in text and "--materials" not in text and "--list" not in text  # not its options
    with pytest.raises(SystemExit):
        main(["study", "--help"])
    assert "--problems" in capsys.readouterr().out  # the generic help is still the generic one


def test_recommend_takes_a_scene_file(tmp_path):
    recs, res = run_recommendation(tmp_path / "r", scenes=[str(FINGER)], backends=["ipopt"], resolutions=[60],
                                   reference_resolution=150, figures=False, progress=False, workers=1)
    assert [r.scene for r in recs] == [str(FINGER)] and recs[0].cases == 2
    assert {r["problem"] for r in res.rows} == {f"{FINGER}/bend", f"{FINGER}/contract"}
    rows = list(csv.DictReader(open(tmp_path / "r" / "recommend.csv")))
    assert len(rows) == 1


@pytest.mark.parametrize("call, hint", [
    (lambda: get_problem("onemuscle"), "did you mean 'one_muscle'?"),
    (lambda: silicone("ecoflex-30"), "did you mean 'ecoflex-00-30'?"),
    (lambda: run_recommendation(None, scenes=["gripr"]), "did you mean 'gripper'?"),
    (lambda: get_study_problem("strip-bnd"), "did you mean 'strip-bend'?"),
])
def test_unknown_names_get_a_did_you_mean(call, hint):
    with pytest.raises(ValueError) as exc:
        call()
    assert hint in str(exc.value)


def test_design_pipeline_refuses_empty_drags_at_the_door(monkeypatch):
    import mdsr_opt.mechanics.equilibrium as eq

    mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    left = [i for i, (x, y) in enumerate(mesh.points) if x == 0.0]
    monkeypatch.setattr(eq, "solve_external", lambda *a, **k: pytest.fail("solved before refusing"))
    with pytest.raises(ValueError, match="drags is empty"):
        design_pipeline(mesh, NeoHookean(1.0, 0.3), left, {})


def test_a_stretching_target_says_no_edge_contracts():
    mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    left = [i for i, (x, y) in enumerate(mesh.points) if x == 0.0]
    right = {i: (x + 0.4, y) for i, (x, y) in enumerate(mesh.points) if x == 4.0}
    target = solve_external(mesh, NeoHookean(1.0, 0.3), left, right).x
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        rr = route_muscles(mesh, target)
    msgs = [str(w.message) for w in caught if issubclass(w.category, RoutingWarning)]
    assert rr.muscles == () and len(msgs) == 1
    # the Poisson narrowing contracts edges across the stretch: the compression filter is named as what removed them
    assert "no muscle unit could be seeded" in msgs[0] and "all 0 muscle unit" not in msgs[0]
    assert "the compression_ratio filter (1) removed all" in msgs[0]


def test_reprs_print_per_muscle_values_alike_for_any_count():
    import numpy as np

    from mdsr_opt.core.results import format_value

    for n in (2, 6, 7, 12):
        a = np.linspace(0.1, 0.3, n)
        assert format_value(a) == format_value(list(a)) == "[" + ", ".join(f"{v:.4g}" for v in a) + "]"
    assert format_value(np.zeros((54,))) == "array((54,), float64)"  # a flattened state: its shape
