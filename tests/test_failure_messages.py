"""Failure lines say the cause first, once, in the user's words, with what helps; the table's cell is cut
cleanly (the trial's FAILED line was 598 characters, said 'the boundary crosses itself' twice, used internal
names and never mentioned contact=True; its cell ended inside an open bracket with 'Solve_Succeeded' in it)."""

from __future__ import annotations

import pytest

from mdsr_opt.scenes.runner import CaseReport
from mdsr_opt.scenes.verdict import design_verdict, failure_cause, plain_failure

#: the trial's design status (windows.toml, a design rejected for crossing itself, then again from rest)
TRIAL = ("Solve_Succeeded; at the free-length cap (their end patches hold most of the rope, contraction_caps): M3 "
         "a = 0.4965; rejected by verification: forward re-solve failed (Solve_Succeeded; rejected: the boundary "
         "crosses itself (self-contact is not modelled)) (warm-started from rest, the design failed too: "
         "Solve_Succeeded; at the free-length cap (their end patches hold most of the rope, contraction_caps): M3 a "
         "= 0.4965; rejected by verification: forward re-solve failed (Solve_Succeeded; rejected: the boundary "
         "crosses itself (self-contact is not modelled)))")


def _balanced(text: str) -> bool:
    depth = 0
    for ch in text:
        depth += {"(": 1, ")": -1}.get(ch, 0)
        if depth < 0:
            return False
    return depth == 0


@pytest.mark.parametrize("status, cause, helps", [
    (TRIAL, "the body would touch itself", "contact=True"),
    ("Solve_Succeeded; rejected by verification: the design's state inverts an element (det F <= 0)",
     "the shape would turn elements inside out", "finer mesh"),
    ("Solve_Succeeded; rejected by verification: gap 0.31 between the design's state and the forward re-solve "
     "exceeds 0.001", "reach another shape", "warm_start"),
    ("Maximum_Iterations_Exceeded (again from rest: Maximum_Iterations_Exceeded)", "ran out of iterations",
     "max_iter"),
    ("load stepping stalled at fraction 0.7812 (Error_In_Step_Computation)", "past a fraction 0.7812",
     "smaller deformation"),
    # with contact on, a crossing means the contact solve lost the fold: not "turn contact on"
    ("load stepping stalled at fraction 0.7812; rejected: the boundary crosses itself and no new contact pair to "
     "prevent it", "could not follow the body as it folds onto itself", "finer mesh"),
])
def test_a_failure_line_says_the_cause_once_and_what_helps(status, cause, helps):
    line = plain_failure(status)
    assert line.startswith(cause) or line.split(":")[0].endswith(cause.split()[-1]) or cause in line, line
    assert line.count(cause) == 1 and helps in line, line
    for internal in ("Solve_Succeeded", "contraction_caps", "free-length", "warm-started", "not modelled"):
        assert internal not in line, line
    assert len(line) < 200 and _balanced(line), line


def test_the_trial_case_fails_with_a_short_line_and_a_clean_cell():
    msg = f"design rejected: {plain_failure(TRIAL)}"
    c = CaseReport(scene="windows", case="lift", kind="external", n_nodes=468, success=False, message=msg)
    assert design_verdict(c) == "FAILED (the body would touch itself)"
    assert "contact = true under [design]" in msg and len(msg) < 200


@pytest.mark.parametrize("message", [
    "design failed: Solve_Succeeded; " + "x" * 50 + " (an unknown reason that goes on (and on) and on for a long "
    "while, much longer than the cell)",
    "design failed: Solved_To_Acceptable_Level; a very long reason without a known cause " + "y" * 120,
    "target solve failed: Solve_Succeeded; rejected: residual 0.1 (tol 1e-08), min J 0.5 " + "(z " * 40,
])
def test_a_cell_is_cut_cleanly(message):
    cell = failure_cause(message)
    assert len(cell) <= 90 and _balanced(cell), cell
    assert "Solve_Succeeded" not in cell and "Solved_To_Acceptable_Level" not in cell, cell


def test_a_forward_re_solve_rejected_says_why_not_its_solver_status():
    from types import SimpleNamespace

    from mdsr_opt.synthesis.verify import _forward_messages

    fwd = SimpleNamespace(success=False, status="Solve_Succeeded; rejected: the boundary crosses itself (contact is "
                                                "off: contact=True models it)")
    msgs = _forward_messages(fwd, "forward re-solve", 0.0, 1.0, False)
    assert msgs == ["forward re-solve failed (the boundary crosses itself (contact is off: contact=True models it))"]
    stalled = SimpleNamespace(success=False, status="load stepping stalled at fraction 0.5 (Restoration_Failed)")
    assert _forward_messages(stalled, "forward re-solve", 0.0, 1.0, False) == [
        "forward re-solve failed (load stepping stalled at fraction 0.5 (Restoration_Failed))"]
