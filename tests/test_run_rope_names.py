"""A rope keeps one name through a scene's run: the idle rope an earlier case dropped is named as it was
when a later case routes it again (it was numbered on, M5 of four ropes, after the earlier case dropped M2)."""

import textwrap

import pytest

#: a T in mm (stem 20 x 60, bar 88 x 18), the bar's right end turned 30 degrees: routing gives four ropes,
#: one of them idle in the design, which drops it
T_SCENE = """
name = "tnames"
units = "mm"
[body]
outline = [[-10, 0], [10, 0], [10, 60], [44, 60], [44, 78], [-44, 78], [-44, 60], [-10, 60]]
resolution = 500
[regions]
base = { box = [-11, -1, 11, 4] }
right = { box = [38, 59, 45, 79] }
[[cases]]
name = "first"
drags = [{ nodes = "base", by = [0, 0] }, { nodes = "right", rotate = -30, about = [10, 69] }]
[[cases]]
name = "again"
drags = [{ nodes = "base", by = [0, 0] }, { nodes = "right", rotate = -30, about = [10, 69] }]
"""


@pytest.fixture(scope="module")
def t_run(tmp_path_factory):
    from mdsr_opt.scenes.runscene import run_scene
    from mdsr_opt.scenes.scenefile import load_scene

    d = tmp_path_factory.mktemp("tnames")
    (d / "t.toml").write_text(textwrap.dedent(T_SCENE))
    scene = load_scene(d / "t.toml")
    rep = run_scene(scene, d / "out", photos=False, figures=False, animations=False, prototype=False,
                    background=False, log=None)
    return rep


def test_a_rope_dropped_as_idle_keeps_its_name_in_a_later_case(t_run):
    first, again = (next(c for c in t_run.cases if c.case == n) for n in ("first", "again"))
    assert first.success and again.success
    assert first.dropped, "the scene is meant to give an idle rope (the check needs one)"
    drop1 = {tuple(d["nodes"]): d["name"] for d in first.dropped}
    drop2 = {tuple(d["nodes"]): d["name"] for d in again.dropped}
    assert drop1 == drop2  # the same rope, dropped in both, under one name
    kept1 = {tuple(m["nodes"]): m["name"] for m in first.muscles}
    kept2 = {tuple(m["nodes"]): m["name"] for m in again.muscles}
    assert kept1 == kept2
    names = list(drop1.values()) + list(kept1.values())
    assert sorted(names) == [f"M{i + 1}" for i in range(len(names))]  # M1..Mk, no gap, no repeat
