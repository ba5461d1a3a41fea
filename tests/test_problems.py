"""The problem library: every scene's factory runs at coarse resolution through the whole pipeline.

Each case is solved (target), routed, designed and verified (``run_case``); the tests assert the key
figures: success, the number of muscles, the difference to the target, and for the paper's one-, two- and
four-muscle experiments the recovery of the contractions that made the target (a known answer).
"""

from __future__ import annotations

import numpy as np
import pytest

from mdsr_opt.mechanics.align import align
from mdsr_opt.scenes.scene import Scene
from mdsr_opt.scenes.animate import animate
from mdsr_opt.scenes.library import get_problem, list_problems
from mdsr_opt.scenes.runner import run_case

LIBRARY = ("face", "four_muscles", "gecko", "gripper", "humanoid", "one_muscle", "starfish", "tentacle",
           "two_muscles")
EXPERIMENTS = {"one_muscle": 1, "two_muscles": 2, "four_muscles": 4}

_cache: dict = {}


def runs(name):
    """Build ``name`` at coarse resolution and run every case once per test session (photo on the first).

    The routing is the paper's search on the whole contraction graph (``fabrication=False``): these tests
    reproduce the paper's experiments, whose muscles lie on the outline, on meshes (~150 nodes) too coarse
    for ropes in channels inside; buildable layouts of the library are checked at its default resolution in
    ``test_buildable.py``."""
    if name not in _cache:
        scene = get_problem(name, resolution="coarse")
        scene.routing_options["fabrication"] = False
        out = {}
        for i, case in enumerate(scene.cases):
            out[case.name] = run_case(scene, case, photo=(i == 0), photo_size=(300, 300))
        _cache[name] = (scene, out)
    return _cache[name]


def test_library_lists_every_scene_of_the_paper():
    assert set(LIBRARY) <= set(list_problems())


@pytest.mark.parametrize("name", LIBRARY)
def test_factory_builds_a_coarse_scene(name):
    scene = get_problem(name, resolution="coarse")
    assert isinstance(scene, Scene) and scene.name == name
    # coarse is about 150 nodes (the face asks for 900, where its one layout makes all four expressions)
    lo, hi = (780, 910) if name == "face" else (120, 180)
    assert lo <= scene.mesh.n_nodes <= hi
    assert scene.mesh.quality()["min_angle_deg"] >= 30.0 - 1e-6
    assert "drawn by the mdsr_opt authors" in open(scene.source).read()
    for case in scene.cases:
        if case.kind == "external":
            assert len(case.anchors) + len(case.drag_nodes) >= 2 and len(case.drag_nodes) >= 1  # face: drags alone


@pytest.mark.parametrize("name", sorted(set(LIBRARY) - set(EXPERIMENTS)))
def test_external_scene_designs_succeed(name):
    scene, out = runs(name)
    cap = scene.routing_options.get("max_muscles", 99)
    if name == "face":  # the cap is each expression's own routing's; a case pulls any muscle of their union
        cap = len({m.name for c in scene.cases for m in c.muscles})
    for cname, run in out.items():
        r = run.report
        assert r.target_success, f"{cname}: {r.target_status}"
        assert r.success, f"{cname}: {r.message}"
        assert r.verified and r.gap < 1e-5 * scene.mesh.size
        assert 1 <= r.n_muscles <= cap
        assert all(0.0 <= a <= scene.design_options["a_max"] + 1e-9 for a in r.contractions)
        # the design improves on its starting point and lands within 3 % of the body's size of the target
        assert r.difference <= r.initial_difference + 1e-12
        assert r.relative_difference < 0.03, f"{cname}: {r.relative_difference:.4f}"


@pytest.mark.parametrize("name", sorted(EXPERIMENTS))
def test_muscle_experiment_recovers_contractions(name):
    scene, out = runs(name)
    assert [c.name for c in scene.cases] == ["a20", "a30", "a40", "a50"]
    for level, (cname, run) in zip((0.2, 0.3, 0.4, 0.5), out.items()):
        r = run.report
        assert r.success, f"{cname}: {r.message}"
        assert r.n_muscles == EXPERIMENTS[name] == len(scene.muscles)
        assert r.known_contractions == pytest.approx([level] * EXPERIMENTS[name])
        assert r.contraction_error < 1e-6
        assert r.difference < 1e-6 * scene.mesh.size
        # the muscle really shortened its body: the target is not the rest shape (the geometric initial
        # guess is now (nearly) the answer, so the design's start says nothing about it)
        assert align(run.setup.target, scene.mesh.points).difference > 0.002 * scene.mesh.size
        # the report carries what was reached: never more than commanded (springs stretch), strokes > 0
        assert len(r.achieved) == len(r.stroke) == r.n_muscles and all(s > 0 for s in r.stroke)
        assert np.all(np.asarray(r.achieved) <= np.asarray(r.contractions) + 1e-7)
        assert np.asarray(r.achieved) == pytest.approx(r.contractions, abs=0.02)


def test_routing_recovers_boundary_muscles_of_the_experiments():
    for name in ("one_muscle", "two_muscles"):
        _, out = runs(name)
        assert all(run.report.routing["recovered"] == 1.0 for run in out.values()), name
    _, out = runs("four_muscles")
    assert all(run.report.routing["recovered"] >= 0.5 for run in out.values())


def test_stronger_contraction_bends_more():
    scene, out = runs("one_muscle")
    # the target's distance from the rest shape (the design's initial difference no longer measures it: the
    # geometric initial guess is about the answer)
    d0 = [align(out[c].setup.target, scene.mesh.points).difference for c in ("a20", "a30", "a40", "a50")]
    assert np.all(np.diff(d0) > 0)


def _muscle_centroid(run):
    P = run.setup.scene.mesh.points
    return np.vstack([P[list(m.nodes)] for m in run.setup.muscles]).mean(0)


def test_gecko_muscles_lie_on_the_concave_side():
    scene, out = runs("gecko")
    assert _muscle_centroid(out["bend_left"])[1] > 0.3      # bending left: muscles along the left (+y) flank
    assert _muscle_centroid(out["bend_right"])[1] < -0.3


def test_tentacle_and_humanoid_muscles_where_the_body_shortens():
    _, out = runs("tentacle")
    assert _muscle_centroid(out["curl"])[1] > 0.2           # the curl is to the left (+y): the top side
    _, out = runs("humanoid")
    assert _muscle_centroid(out["raise_arms"])[1] > 2.85    # above the arms' centre line


def test_symmetric_targets_give_symmetric_contractions():
    _, out = runs("gripper")
    a = out["close"].report.contractions
    assert len(a) == 2 and abs(a[0] - a[1]) < 0.01           # the ring is symmetric about its axis
    _, out = runs("starfish")
    a = np.array(out["pinwheel"].report.contractions)
    assert len(a) == 5 and np.ptp(a) < 0.25 * a.mean()       # five-fold symmetry, up to the mesh


@pytest.mark.parametrize("name", LIBRARY)
def test_synthetic_photograph_metrics(name):
    scene, out = runs(name)
    photo = next(iter(out.values())).report.photo
    assert photo["synthetic"] is True
    # the measuring chain's floor (driven outline on its own photograph) stays near a pixel at 300 px, and
    # every hole is found; a hole a few pixels thin (the face's smiling mouth at 300 px) is partly filled by
    # the segmentation's closing, so the floor over every loop is higher there (0.7 px at 500 px)
    assert photo["self"]["outer_mean_px"] < 2.5 and photo["self"]["n_unmatched"] == 0
    assert photo["self"]["mean_px"] < (5.0 if name == "face" else 2.5)
    assert photo["target"]["mean_px"] >= 0.0 and 0.0 <= photo["target"]["ratio"] < 0.1


def test_gecko_gait_alternates_left_and_right():
    scene, out = runs("gecko")
    designs = {c: (out[c].setup.muscles, out[c].design.contractions) for c in ("bend_left", "bend_right")}
    res = animate(scene, "gait", designs)
    assert res.success and len(res.states) == 4 * 5 + 1
    head = scene.regions["head"]
    rest_y = scene.mesh.points[head, 1].mean()
    assert res.states[5][head, 1].mean() > rest_y + 0.1      # keyframe 2: bent left
    assert res.states[15][head, 1].mean() < rest_y - 0.1     # keyframe 4: bent right
    assert np.abs(res.states[-1] - scene.mesh.points).max() < 1e-6   # back at rest
    assert res.contractions.shape == (21, len(res.muscles))
    names = [m.name for m in res.muscles]  # the two cases' separately routed M1, M2: unique in the union
    assert len(set(names)) == len(names) and "bend_left:M1" in names and "bend_right:M1" in names
