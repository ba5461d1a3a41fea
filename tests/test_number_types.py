"""Numbers of the wrong type (strings, booleans, None, complex, object arrays) are refused at every public entry
that takes numeric arrays, by the one checker (core/checks.as_float_array), with a TypeError naming the argument,
the bad element and its type: never converted ("0.2" solved as 0.2, True as 1.0)."""

from __future__ import annotations

import numpy as np
import pytest

from mdsr_opt import Mesh, Muscle, NeoHookean, design_contractions, solve_external, solve_internal
from mdsr_opt.core.checks import as_float_array
from mdsr_opt.scenes.scene import Case

MAT = NeoHookean(1.0, 0.3)
BAD = [(["0.2"], r"\[0\] must be a real number, got str '0.2'"),
       ([True], r"\[0\] must be a real number, got bool True"),
       ([0.1, True], r"\[1\] must be a real number, got bool True"),
       ([None], r"\[0\] must be a real number, got NoneType None"),
       ([0.2 + 0j], r"\[0\] must be a real number, got complex"),
       (np.array([0.2, "x"], dtype=object), r"\[1\] must be a real number, got str 'x'"),
       (np.array([0.2], dtype=object), "must be an array of real numbers, got dtype object"),
       (np.array([True]), "must be an array of real numbers, got booleans"),
       (np.array([0.2 + 1j]), "must be real, got complex")]


@pytest.fixture(scope="module")
def strip():
    mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    mus = [Muscle(range(1, 9))]
    return mesh, mus, solve_internal(mesh, MAT, mus, [0.2]).x


@pytest.mark.parametrize("bad, words", BAD)
def test_the_checker_refuses_every_non_real_element(bad, words):
    with pytest.raises(TypeError, match=words):
        as_float_array(bad, "contractions")
    assert as_float_array([0.2, np.float32(0.5), 1], "c").tolist() == [0.2, 0.5, 1.0]


@pytest.mark.parametrize("bad, words", BAD)
def test_solve_internal_refuses_contractions_of_the_wrong_type(strip, bad, words):
    mesh, mus, _ = strip
    with pytest.raises(TypeError, match="contractions" + ("" if words[0] == "\\" else " ") + words):
        solve_internal(mesh, MAT, mus, bad)


def test_targets_drags_strokes_cases_poses_and_gaits_refuse_the_same(strip):
    mesh, mus, target = strip
    t = target.tolist()
    t[3][0] = True
    with pytest.raises(TypeError, match=r"target\[3\]\[0\] must be a real number, got bool True"):
        design_contractions(mesh, MAT, mus, t)
    with pytest.raises(TypeError, match=r"weights\[0\] must be a real number, got bool"):
        design_contractions(mesh, MAT, mus, target, weights=[True] * mesh.n_nodes)
    with pytest.raises(TypeError, match=r"\[0\]\[0\] must be a real number, got str '1'"):
        solve_external(mesh, MAT, [0], {16: ["1", 0.0]})
    with pytest.raises(TypeError, match=r"\[0\]\[0\] must be a real number, got bool True"):
        solve_external(mesh, MAT, [0], {16: [True, 0.0]})
    with pytest.raises(TypeError, match=r"drag_positions\[0\]\[1\] must be a real number, got NoneType"):
        Case("c", anchors=[0], drag_nodes=[16], drag_positions=[[4.0, None]])
    from mdsr_opt.synthesis.walk import walk
    with pytest.raises(TypeError, match=r"strokes\[0\]\[0\] must be a real number, got str"):
        walk(mesh, MAT, mus, [["0.1"]])
    from mdsr_opt.synthesis.poses import Pose, design_poses
    t = target.astype(object)
    t[2, 1] = "0.5"
    with pytest.raises(TypeError, match=r"pose 'p': target\[2\]\[1\] must be a real number, got str"):
        design_poses(mesh, MAT, [Pose("p", t)])
    from mdsr_opt.synthesis.gait import Gait
    with pytest.raises(TypeError, match="step_time must be a real number, got str"):
        Gait("g", ["p", "rest"], step_time="0.5")


def test_animation_keyframe_fractions_are_numbers_not_text_or_booleans():
    from mdsr_opt.scenes.scene import Animation

    with pytest.raises(TypeError, match="keyframe fraction for 'a' must be a real number, got str"):
        Animation("x", (("a", "0.5"), ("b", 1.0)))
    with pytest.raises(TypeError, match="keyframe fraction for 'a' must be a real number, got bool"):
        Animation("x", (("a", True), ("b", 1.0)))
    assert Animation("x", (("a", 0), ("b", 1))).keyframes == (("a", 0.0), ("b", 1.0))
