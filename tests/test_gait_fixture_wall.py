"""Every design a scene runs keeps a rope's two end fixtures the scene's [fabrication] wall apart: the case
designs did, the gait's (``design_poses``) took the default wall (1 % of the diameter) whatever the scene said.
``design_poses`` now takes its fabrication's wall, as ``design_pipeline`` does, and the gait passes the scene's."""

from __future__ import annotations

import functools
import warnings

import numpy as np
import pytest

from mdsr_opt import Mesh, Muscle, NeoHookean, load_scene, solve_internal
from mdsr_opt.mechanics.anchors import body_size
from mdsr_opt.synthesis import contractions
from mdsr_opt.synthesis.fabrication import WALL_FRACTION, Fabrication
from mdsr_opt.synthesis.poses import design_poses

R, WALL = 0.1, 0.1


@pytest.fixture(scope="module")
def strip():
    """A 4 x 1 strip, a rope 0.5 long inside it and a target the rope makes at a = 0.5 (its ends about 0.25
    apart: closer than two fixtures of radius 0.1 with a wall 0.1 between them, 0.3)."""
    mesh = Mesh.rectangle(4.0, 1.0, 32, 8)
    rope = Muscle(range(2 * 33, 2 * 33 + 5), name="r")  # on the line y = 0.25
    t = solve_internal(mesh, NeoHookean(1.0, 0.3), [rope], [0.5], anchor_radius=R)
    assert t.success
    return mesh, rope, t.x.reshape(-1, 2)


def _ends(x, rope) -> float:  # the rope left between its fixtures' centres, along its path
    return rope.length(np.asarray(x).reshape(-1, 2))


def test_design_poses_keeps_the_fabrication_wall_between_a_rope_s_fixtures(strip, monkeypatch):
    mesh, rope, target = strip
    seen = []
    design = contractions.design_contractions

    @functools.wraps(design)  # its keywords, which design_poses checks its options against
    def spy(*args, **kwargs):
        seen.append(kwargs.get("fixture_wall"))
        return design(*args, **kwargs)

    monkeypatch.setattr(contractions, "design_contractions", spy)
    assert _ends(target, rope) < 2 * R + WALL - 0.03  # the target itself brings the fixtures together
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the rope at its cap: the MuscleWarning is not the point here
        res = design_poses(mesh, NeoHookean(1.0, 0.3), {"p": target}, separate={"p": ((rope,), None)},
                           design_options={"anchor_radius": R}, fabrication=Fabrication(fixture_radius=R, wall=WALL))
    assert seen and all(w == WALL for w in seen), seen  # before: None (the default wall 0.041) every time
    assert res.anchor_radius == pytest.approx(R, abs=0)
    assert _ends(res.states[0], rope) >= 2 * R + WALL - 1e-9  # before: about 0.25
    # without a fabrication: the default wall, the pipeline's
    seen.clear()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        design_poses(mesh, NeoHookean(1.0, 0.3), {"p": target}, separate={"p": ((rope,), None)},
                     design_options={"anchor_radius": R}, compare=False)
    assert seen == [pytest.approx(WALL_FRACTION * body_size(mesh), rel=1e-12)]


SCENE = """name = "gw"
[body]
outline = [[0, 0], [4, 0], [4, 1], [0, 1]]
resolution = "coarse"
[fabrication]
fixture_radius = 0.1
wall = 0.08
[[cases]]
name = "up"
anchors = [[0, 0], [0, 1]]
drags = [{ at = [4, 1], by = [-0.5, 1.0] }]
muscles = [{ name = "upper", path = [[0.3, 0.7], [3.3, 0.7]] }]
[gait]
poses = ["rest", "up"]
"""


def test_a_gait_designs_with_the_scene_s_fabrication_wall(tmp_path, monkeypatch):
    from mdsr_opt.scenes.runscene import run_scene
    from mdsr_opt.synthesis import poses

    asked = []
    inner = poses.design_poses

    def spy(*args, **kwargs):
        asked.append(dict(kwargs.get("design_options") or {}))
        return inner(*args, **kwargs)

    monkeypatch.setattr(poses, "design_poses", spy)
    p = tmp_path / "gw.toml"
    p.write_text(SCENE)
    run_scene(load_scene(p), tmp_path / "run", photos=False, prototype=False, figures=False, log=None,
              background=False)
    assert len(asked) == 1 and asked[0].get("fixture_wall") == pytest.approx(0.08, abs=0), asked  # before: absent


def test_a_separate_design_is_reused_only_with_the_same_fixture_wall(strip, monkeypatch):
    """design_poses takes a pose's separate design as its shared-layout design only when it was made with
    the options asked; the wall between a rope's fixtures is one (before: reused whatever its wall)."""
    mesh, rope, target = strip
    mat = NeoHookean(1.0, 0.3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        made = contractions.design_contractions(mesh, mat, [rope], target, anchor_radius=R, fixture_wall=WALL)
    assert made.fixture_wall == WALL and made.to_dict()["fixture_wall"] == WALL
    calls = []
    design = contractions.design_contractions

    @functools.wraps(design)
    def spy(*args, **kwargs):
        calls.append(kwargs.get("fixture_wall"))
        return design(*args, **kwargs)

    monkeypatch.setattr(contractions, "design_contractions", spy)
    for wall, designed in ((WALL, []), (0.02, [0.02])):
        calls.clear()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = design_poses(mesh, mat, {"p": target}, separate={"p": ((rope,), made)},
                               design_options={"anchor_radius": R, "fixture_wall": wall})
        assert calls == designed, (wall, calls)  # before: [] for both (the design with the wall 0.1 reused)
        assert (res.designs["p"] is made) == (wall == WALL)


def test_the_authoring_page_designs_with_its_fabrication_wall_and_saves_it_once(tmp_path):
    """The page's design keeps the ropes' end fixtures its fabrication's wall apart, as mdsr run designs the
    scene it saves (before: the default wall); the wall is saved in [fabrication], never in [design]."""
    import json
    from pathlib import Path

    from mdsr_opt import get_problem
    from mdsr_opt.author.export import save_scene
    from mdsr_opt.author.session import Session

    s = Session.from_scene(get_problem("tentacle", resolution="coarse"))
    s.settle()
    s.route(10.0, 4.0, None, {"channel_diameter": 0.1, "wall": 0.07})
    page = s.run_design()
    assert page["params"]["fixture_wall"] == 0.07 and s.design.fixture_wall == 0.07  # before: absent (the default wall)
    data = json.loads(Path(save_scene(s, tmp_path, "walled")[0]).read_text())
    assert data["fabrication"]["wall"] == 0.07 and "fixture_wall" not in data.get("design", {})
    assert load_scene(Path(save_scene(s, tmp_path, "walled2")[0])).routing_options["fabrication"]["wall"] == 0.07
