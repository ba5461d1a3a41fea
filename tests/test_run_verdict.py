"""The design column of mdsr run's table states the cause of a failure first (the trial found
'FAILED (not mouldable as laid out)' for a design too far from its target, and 'FAILED (saturated M2)' for one
rejected by verification), the secondary flags after it."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from mdsr_opt.cli.main import main
from mdsr_opt.scenes.runner import CaseReport
from mdsr_opt.scenes.scenereport import SceneReport
from mdsr_opt.scenes.verdict import design_verdict

ROOT = Path(__file__).resolve().parents[1]
FINGER = ROOT / "tests" / "data" / "finger.toml"
OUTLINE = ["muscle upper: its channel runs on the outline"]


@pytest.mark.parametrize("message, extra, cell", [
    ("design too far from the target: difference 0.142 body units is 3.45 % of the size 4.12 body units, more "
     "than max_difference 1 %", {"fabrication": OUTLINE},
     "FAILED (too far from the target: 3.45 % of size, more than max_difference 1 %; not mouldable as laid out)"),
    ("design too far from the target: the design removes 4 % of the rest shape's difference 0.3 mm to the target "
     "(difference 0.29 mm), less than min_progress 10 %: the muscles barely move the body", {},
     "FAILED (too far from the target: removes 4 % of the rest shape's difference, less than 10 %)"),
    ("design failed: Solve_Succeeded; every muscle is idle (contractions 0.001, 0.002 below idle_contraction "
     "0.005): the design does not move the body", {"fabrication": OUTLINE},
     "FAILED (every muscle is idle: the design does not move the body; not mouldable as laid out)"),
    ("design not verified: Solve_Succeeded; rejected by verification: the boundary crosses itself (segments 3 "
     "and 17)", {"saturated": ["M2"]},
     "FAILED (the body would touch itself; saturated M2)"),
    ("design failed: Maximum_Iterations_Exceeded (warm-started from rest, the design failed too: x)",
     {"dropped": [{"name": "M3"}]}, "FAILED (the optimiser ran out of iterations; dropped M3)"),
    ("target solve failed: Infeasible_Problem_Detected", {}, "FAILED (target solve failed: Infeasible_Problem_Detected)"),
    ("", {"saturated": ["M1"], "fabrication": OUTLINE, "success": True}, "ok (saturated M1; not mouldable as laid out)"),
])
def test_the_design_cell_names_the_cause_first(message, extra, cell):
    success = extra.pop("success", False)
    c = CaseReport(scene="s", case="c", kind="external", n_nodes=10, success=success, message=message, **extra)
    assert design_verdict(c) == cell
    table = SceneReport(scene="s", title="", n_nodes=10, cases=[c]).table()
    assert f"| {cell} |" in table and table.splitlines()[-1].count("|") == table.splitlines()[0].count("|") == 16


def test_mdsr_run_too_far_says_so_in_the_table(tmp_path, capsys):
    code = main(["run", str(FINGER), "--out", str(tmp_path / "o"), "--max-difference", "0.01", "--case", "bend",
                 "--serial", "--no-photos", "--no-figures", "--no-animations", "--no-prototype"])
    assert code == 1
    row = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| finger | bend |")]
    assert len(row) == 1
    assert re.search(r"\| FAILED \(too far from the target: \d+\.\d+ % of size, more than max_difference 1 %\) \|",
                     row[0]), row[0]


@pytest.mark.parametrize("design, cell", [
    ({"table": 4, "success": False, "status": "load step 0.9961 -> 1 failed"}, "FAILED (validation.md)"),
    ({"table": 4, "success": True, "mean_px": 3.256, "ratio": 0.0154}, "3.26"),
    (None, "-"),  # no prototype run (--no-prototype, or no design)
])
def test_the_prototype_column_says_when_the_prototype_failed(design, cell):
    # trial7: a design whose virtual prototype failed showed "-" in summary.md, as if none had been run
    photo = {"prototype": {"design": design}} if design is not None else {}
    c = CaseReport(scene="s", case="c", kind="external", n_nodes=10, success=True, photo=photo)
    lines = SceneReport(scene="s", title="", n_nodes=10, cases=[c]).table().splitlines()
    head, row = ([v.strip() for v in ln.split("|")] for ln in (lines[0], lines[-1]))
    assert row[head.index("prototype d over every loop (px)")] == cell, row
