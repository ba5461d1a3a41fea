"""Every *_options dict of design_pipeline and design_poses (and the pipeline's other keywords, its design
options) is checked at the door, before the target is solved, with the nearest key suggested."""

from __future__ import annotations

import functools

import pytest

import mdsr_opt.mechanics.equilibrium as equilibrium
from mdsr_opt import Mesh, NeoHookean
from mdsr_opt.synthesis.pipeline import design_pipeline
from mdsr_opt.synthesis.poses import design_poses

MAT = NeoHookean(1.0, 0.3)


@pytest.fixture
def no_solve(monkeypatch):
    """The pipeline's target solve refuses to run (patched where the pipeline calls it, so no module imported
    meanwhile keeps the patched function)."""
    import mdsr_opt.synthesis.pipeline as pipeline

    def refuse(*a, **k):
        raise AssertionError("the target was solved before the options were checked")
    monkeypatch.setattr(pipeline, "_target", refuse)


@pytest.mark.parametrize("kwargs, err, words", [
    ({"routing_options": {"max_muscle": 2}}, ValueError, r"routing_options: unknown key 'max_muscle' \(did you mean 'max_muscles'\?\)"),
    ({"external_options": {"backnd": "ipopt"}}, ValueError, r"external_options: unknown key 'backnd' \(did you mean 'backend'\?\)"),
    ({"band_options": {"nu_tl": 0.1}}, ValueError, r"band_options: unknown key 'nu_tl' \(did you mean 'nu_tol'\?\)"),
    ({"a_mx": 0.3}, ValueError, r"design options .*unknown key 'a_mx' \(did you mean 'a_max'\?\)"),
    ({"routing_options": {"zzzz": 1}}, ValueError, r"unknown key 'zzzz' \(allowed: .*max_muscles"),
    ({"routing_options": ["max_muscles"]}, TypeError, "routing_options must be a dict, got list"),
    ({"routing_options": {3: 1}}, TypeError, "keys must be strings, got int 3"),
])
def test_design_pipeline_checks_its_option_dicts_before_any_solve(no_solve, kwargs, err, words):
    mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    left = [i for i, (x, y) in enumerate(mesh.points) if x == 0.0]
    drags = {i: (x - 0.3, y - 0.4) for i, (x, y) in enumerate(mesh.points) if x == 4.0}
    with pytest.raises(err, match=words):
        design_pipeline(mesh, MAT, left, drags, **kwargs)


@pytest.mark.parametrize("kwargs, words", [
    ({"routing_options": {"max_muscle": 2}}, r"routing_options: unknown key 'max_muscle' \(did you mean 'max_muscles'\?\)"),
    ({"design_options": {"a_mx": 0.3}}, r"design_options: unknown key 'a_mx' \(did you mean 'a_max'\?\)"),
])
def test_design_poses_checks_its_option_dicts_before_any_routing(monkeypatch, kwargs, words):
    import mdsr_opt.synthesis.poses as poses

    def refuse(*a, **k):
        raise AssertionError("routed before the options were checked")
    monkeypatch.setattr(poses, "route_poses", refuse)
    mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    with pytest.raises(ValueError, match=words):
        design_poses(mesh, MAT, {"squeeze": mesh.points * [0.8, 1.0]}, **kwargs)


def test_gait_schedule_checks_its_solve_options_before_any_frame(monkeypatch):
    from mdsr_opt import Muscle
    from mdsr_opt.synthesis.gait import gait_schedule

    mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    target = equilibrium.solve_internal(mesh, MAT, [Muscle(range(1, 9))], [0.1]).x
    layout = design_poses(mesh, MAT, {"pull": target},
                          compare=False)
    import mdsr_opt.synthesis.export  # noqa: F401 - imported before the patch: no module keeps it

    @functools.wraps(equilibrium.solve_internal)
    def refuse(*a, **k):
        raise AssertionError("a frame was solved before the options were checked")
    monkeypatch.setattr(equilibrium, "solve_internal", refuse)
    with pytest.raises(ValueError, match=r"solve_options: unknown key 'max_iters' \(did you mean 'max_iter'\?\)"):
        gait_schedule(mesh, MAT, layout, ["rest", "pull"], solve_options={"max_iters": 50})
    with pytest.raises(ValueError, match="solve_options: unknown key 'anchor_radius'"):  # the layout's own
        gait_schedule(mesh, MAT, layout, ["rest", "pull"], solve_options={"anchor_radius": 0.1})
