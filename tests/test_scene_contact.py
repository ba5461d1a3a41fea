"""A scene file turns self-contact on with ``contact = true`` under ``[design]`` (the trial found no way to):
checked at the door (did-you-mean for a misspelling, the design method, contact_gap without contact) and used
by the case's target solve as well as the design."""

from __future__ import annotations

import pytest

import mdsr_opt.mechanics.equilibrium as equilibrium
from mdsr_opt.scenes.cases import prepare_case
from mdsr_opt.scenes.reader import SceneFileError, contact_options
from mdsr_opt.scenes.scenefile import load_scene

SCENE = """name = "strip"
[body]
outline = [[0, 0], [4, 0], [4, 1], [0, 1]]
resolution = 60
[design]
{design}
[[cases]]
name = "lift"
anchors = [[0, 0], [0, 1]]
drags = [{{ at = [4, 1], by = [0, 0.5] }}]
"""


def _scene(tmp_path, design: str):
    p = tmp_path / "strip.toml"
    p.write_text(SCENE.format(design=design))
    return load_scene(p)


def test_contact_true_reaches_the_target_solve(tmp_path, monkeypatch):
    scene = _scene(tmp_path, "contact = true\ncontact_gap = 0.01")
    assert scene.design_options["contact"] is True
    assert contact_options(scene.design_options) == {"contact": True, "contact_gap": 0.01}
    seen = {}
    real = equilibrium.solve_external

    def spy(*args, **kw):
        seen.update(kw)
        return real(*args, **kw)

    monkeypatch.setattr(equilibrium, "solve_external", spy)
    setup = prepare_case(scene, "lift", route_internal=False)
    assert seen.get("contact") is True and seen.get("contact_gap") == 0.01
    assert setup.target_result.success


def test_without_contact_nothing_changes(tmp_path):
    assert contact_options(_scene(tmp_path, "a_max = 0.5").design_options) == {}


@pytest.mark.parametrize("design, error", [
    ("contac = true", "design.contac: unknown field (did you mean 'contact'?)"),
    ("contact = 1", "design.contact: expected true or false"),
    ('contact = true\nmethod = "flattened"', "design.method: contact = true is designed by method = "
                                             '"derivative-free", or with no method'),
    ("contact_gap = 0.01", "design.contact_gap: is the gap of self-contact: set contact = true too"),
    ("contact = true\ncontact_gap = -1", "design.contact_gap: must be > 0"),
    ("contact = true\ncontact_gap = 1", "contact_gap 1 is 24% of the body's size 4.123: it is the small clearance"),
])
def test_contact_is_checked_at_the_door(tmp_path, design, error):
    with pytest.raises((SceneFileError, TypeError), match=error.replace("(", r"\(").replace(")", r"\)")
                       .replace("?", r"\?")):
        _scene(tmp_path, design)


FOLD = """name = "strip"
[body]
outline = [[0, 0], [4, 0], [4, 1], [0, 1]]
resolution = 60
[design]
{design}
[regions]
start = {{ box = [-1, -1, 0.1, 2] }}
end = {{ box = [3.9, -1, 5, 2] }}
[[cases]]
name = "fold"
anchors = "start"
drags = [{{ nodes = "end", by = [-4, 0] }}]
"""


def test_drags_through_the_body_itself_are_refused_when_the_scene_loads(tmp_path):
    p = tmp_path / "fold.toml"
    p.write_text(FOLD.format(design="contact = true"))  # the right end dragged onto the anchored left end
    with pytest.raises(SceneFileError, match=r"fold\.toml: scene 'strip', case 'fold': with contact, the "
                                             r"prescribed nodes would overlap at their targets: .*node \d+ "
                                             r"\(anchored; .*node \d+ \(dragged to"):
        load_scene(p)
    p.write_text(FOLD.format(design="a_max = 0.5"))  # without contact the file loads (the solve rejects it)
    assert load_scene(p).case("fold").drag_nodes.size > 0


def test_a_contact_gap_is_a_small_clearance_in_python_too():
    from mdsr_opt import Mesh, NeoHookean, solve_external

    mesh = Mesh.rectangle(4.0, 1.0, 8, 2)
    left = [i for i, p in enumerate(mesh.points) if p[0] == 0.0]
    with pytest.raises(ValueError, match=r"contact_gap 0.5 is 12% of the body's size 4.123.*less than 0.1 of"):
        solve_external(mesh, NeoHookean(E=1.0, nu=0.3), left, {int(mesh.n_nodes - 1): (4.0, 1.5)}, contact=True,
                       contact_gap=0.5)
