"""One name per muscle everywhere a user reads it (issue 36): tables, reprs, warnings, dropped muscles and
the run's summary call muscle ``i`` by its own name, else ``M<i+1>`` (mdsr_opt.plot.style.muscle_label), as
the figures, the routing table and the fabrication files do."""

from __future__ import annotations

import warnings

import pytest

from mdsr_opt import Mesh, Muscle, NeoHookean, solve_internal
from mdsr_opt.synthesis.acceptance import design_active
from mdsr_opt.synthesis.contractions import design_contractions
from mdsr_opt.synthesis.pipeline import design_pipeline
from mdsr_opt.synthesis.results import DesignResult, MuscleWarning

MAT = NeoHookean(1.0, 0.3)


def strip():
    return Mesh.rectangle(4.0, 1.0, 16, 4)


def unnamed(mesh):
    """The bottom row's muscle and the top row's, without names."""
    return Muscle(range(1, 16)), Muscle(range(69, 84))


def test_unnamed_muscles_are_m1_m2_in_tables_reprs_and_warnings():
    mesh = strip()
    lower, upper = unnamed(mesh)
    target = solve_internal(mesh, MAT, [lower, upper], [0.15, 0.02]).x
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = design_contractions(mesh, MAT, [lower, upper], target, a_max=0.1)
    sat = [str(w.message) for w in caught if issubclass(w.category, MuscleWarning)]
    assert len(sat) == 1 and sat[0].startswith("muscle(s) M1 (a = ")
    assert res.names == ("M1", "M2") and res.saturated_names == ["M1"]
    assert "saturated=['M1']" in repr(res) and res.summary()["muscles"] == ["M1", "M2"]
    rows = res.table().splitlines()
    assert [r.split()[0] for r in rows[1:]] == ["M1", "M2"]
    assert DesignResult.from_dict(res.to_dict()).names == ("M1", "M2")


def test_own_names_are_kept_and_a_dropped_muscle_keeps_its_place_name():
    mesh = strip()
    lower, upper = unnamed(mesh)
    target = solve_internal(mesh, MAT, [lower], [0.15]).x  # the upper muscle is idle
    res, kept, dropped = design_active(mesh, MAT, [lower, upper], target)
    assert [d.name for d in dropped] == ["M2"] and res.names == ("M1",) and [m.name for m in kept] == ["M1"]
    # dropping the first muscle: the second keeps its name M2 in the design made again
    res, kept, dropped = design_active(mesh, MAT, [upper, lower], target)
    assert [d.name for d in dropped] == ["M1"] and res.names == ("M2",)
    named = design_contractions(mesh, MAT, [Muscle(lower.nodes, name="belly")], target)
    assert named.names == ("belly",) and named.table().splitlines()[1].split()[0] == "belly"


def test_the_pipeline_repr_and_table_use_the_names():
    mesh = strip()
    lower, upper = unnamed(mesh)
    left = [i for i, (x, y) in enumerate(mesh.points) if x == 0.0]
    bent = solve_internal(mesh, MAT, [lower, upper], [0.15, 0.12]).x
    right = {i: tuple(bent[i]) for i, (x, y) in enumerate(mesh.points) if x == 4.0}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MuscleWarning)
        out = design_pipeline(mesh, MAT, left, right, muscles=[lower, upper], a_max=0.05)
    assert out.design.saturated.tolist() == [True, False] and "saturated=['M1']" in repr(out)
    assert [r.split()[0] for r in out.table().splitlines()[1:3]] == ["M1", "M2"]


def test_a_union_of_layouts_names_every_muscle_once():
    from mdsr_opt.scenes.animate import union_of_layouts

    a, b, c = Muscle(range(1, 16)), Muscle(range(69, 84)), Muscle(range(18, 33))
    union, slots = union_of_layouts({"left": [a, b], "right": [Muscle(b.nodes, name="other"), c]})
    # b is the same path in both cases: one muscle, named as the first case names it (M2); names collide
    # (left's M2 and right's M2 = c), so every muscle of one case only carries its case
    assert [m.name for m in union] == ["left:M1", "M2", "right:M2"] and slots == {"left": [0, 1], "right": [1, 2]}
    union, _ = union_of_layouts({"left": [Muscle(a.nodes, name="belly")], "right": [c]})
    assert [m.name for m in union] == ["belly", "M1"]  # no collision: the names as they are
    union, _ = union_of_layouts({"left": [a, b], "right": [c]})  # gecko: left M1, M2 and right M1
    assert [m.name for m in union] == ["left:M1", "left:M2", "right:M1"]


def test_a_gait_and_an_animation_may_not_share_a_name():
    from mdsr_opt.scenes.names import check_output_names
    from mdsr_opt.scenes.reader import SceneFileError

    check_output_names(["bend"], ["gait"], gait_names=["walk"])
    with pytest.raises(SceneFileError, match="the gait 'Walk' has the name of the animation 'walk'"):
        check_output_names(["bend"], ["walk"], gait_names=["Walk"])



def test_long_animation_titles_wrap_at_a_comma():
    from mdsr_opt.plot.scenes import wrap_title

    t = "gait 6/21: bend_left:M1 0.54 → 0.54, bend_right:M1 0.00 → 0.01, bend_right:M2 0.00 → 0.01"
    lines = wrap_title(t, 76).split("\n")
    assert len(lines) == 2 and all(len(s) <= 76 for s in lines) and lines[0].endswith("0.01,")
    assert "".join(s if s.endswith(",") is False else s + " " for s in lines) == t
    assert wrap_title("frame 1/3", 76) == "frame 1/3"


def test_mechanics_errors_name_the_muscle_as_figures_do():
    from mdsr_opt.core.errors import LayoutError

    mesh = strip()
    lower, upper = unnamed(mesh)
    with pytest.raises(LayoutError, match=r"^muscle M1: its anchor patches cover"):
        solve_internal(mesh, MAT, [lower, upper], [0.5, 0.5], anchor_radius=1.9)
    with pytest.raises(LayoutError, match=r"^muscle belly: its anchor patches cover"):
        solve_internal(mesh, MAT, [Muscle(lower.nodes, name="belly")], [0.5], anchor_radius=1.9)
