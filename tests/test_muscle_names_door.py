"""Two muscles with one label are refused at every Python entry (trial 7 defect 7 closed for scene files
only): design_pipeline(muscles=...), design_contractions, solve_internal, design_poses(separate=...) and
export_fabrication(muscles=...) each raise a ValueError naming the label and both places, before any work.
An unnamed muscle is called by its place (M1, M2 ...), so a muscle named "M2" clashes with an unnamed second."""

from __future__ import annotations

import re

import numpy as np
import pytest

from mdsr_opt import Mesh, Muscle, NeoHookean, design_contractions, design_pipeline, solve_internal
from mdsr_opt.body.muscles import check_muscle_names, muscle_name_clash
from mdsr_opt.synthesis.export import export_fabrication
from mdsr_opt.synthesis.poses import design_poses

MESH = Mesh.rectangle(4.0, 1.0, 16, 4)
MAT = NeoHookean(1.0, 0.3)
A = Muscle(tuple(range(0, 10)), name="m")
B = Muscle(tuple(range(17, 27)), name="m")


def _said(label, i, j, what="muscles"):
    return re.escape(f"muscle name {label!r} is used twice ({what}[{i}] and {what}[{j}])")


def test_the_label_clash_is_found_by_label():
    assert muscle_name_clash([A, B]) == ("m", 0, 1)
    assert muscle_name_clash([Muscle(A.nodes, name="M2"), B.nodes]) == ("M2", 0, 1)  # a node list is M2 there
    assert muscle_name_clash([Muscle(A.nodes), Muscle(B.nodes, name="M1")]) == ("M1", 0, 1)
    assert muscle_name_clash([A, Muscle(B.nodes)]) is None and muscle_name_clash([A.nodes, B.nodes]) is None
    with pytest.raises(ValueError, match=_said("m", 0, 1, "ropes")):
        check_muscle_names([A, B], "ropes")


@pytest.mark.parametrize("muscles, label, i, j", [
    ((A, B), "m", 0, 1),
    ((Muscle(A.nodes, name="M3"), Muscle(tuple(range(34, 44))), Muscle(B.nodes)), "M3", 0, 2),
])
def test_every_python_entry_refuses_two_muscles_with_one_label(tmp_path, muscles, label, i, j):
    target = MESH.points.copy()
    target[:, 1] *= 0.95  # a shape of the body; the refusal comes before any solve
    said = _said(label, i, j)
    with pytest.raises(ValueError, match=said):
        solve_internal(MESH, MAT, muscles, [0.1] * len(muscles))
    with pytest.raises(ValueError, match=said):
        design_contractions(MESH, MAT, muscles, target)
    with pytest.raises(ValueError, match=said):
        design_pipeline(MESH, MAT, [0, 17], {16: [3.8, 1.0]}, muscles=muscles)
    with pytest.raises(ValueError, match=_said(label, i, j, "separate['p'] muscles")):
        design_poses(MESH, MAT, {"p": target}, separate={"p": (muscles, None)})
    with pytest.raises(ValueError, match=said):
        export_fabrication(MESH, None, tmp_path, muscles=muscles)
    assert not any(tmp_path.iterdir())  # nothing written


def test_distinct_labels_pass_every_door():
    res = solve_internal(MESH, MAT, (A, Muscle(B.nodes)), [0.05, 0.05])
    assert res.success


def test_design_poses_of_a_layout_no_pose_engages_returns_its_result():
    """With distinct labels the separate layout of the test above goes through; its muscles run along rows
    that the squashed target does not shorten, so no pose is designed (before: StopIteration)."""
    target = MESH.points.copy()
    target[:, 1] *= 0.95
    res = design_poses(MESH, MAT, {"p": target}, separate={"p": ((A, Muscle(B.nodes)), None)})
    assert not res.pose_success[0] and "left at rest" in res.status[0] and res.muscle_model == "cable"
    assert np.array_equal(res.states[0], MESH.points)
