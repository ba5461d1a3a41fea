"""An outer-loop design's progress line gives its best difference in the caller's lengths, with its share of
the body's size (it gave the unit body's: 0.136 for a 117 mm plate whose design ended 2.9 mm away)."""

from __future__ import annotations

import logging

import pytest

import mdsr_opt.synthesis.rivals as rivals
from mdsr_opt import Mesh, Muscle, NeoHookean, design_contractions, solve_internal


@pytest.mark.parametrize("scale", [1.0, 50.0])
def test_the_progress_line_is_in_the_callers_lengths(scale, monkeypatch, caplog):
    base = Mesh.rectangle(4.0, 1.0, 8, 2)
    mesh = Mesh(base.points * scale, base.triangles)
    mat, mus = NeoHookean(1.0, 0.3), [Muscle(range(1, 8))]
    target = solve_internal(mesh, mat, mus, [0.1]).x
    monkeypatch.setattr(rivals, "PROGRESS_SECONDS", 0.0)
    with caplog.at_level(logging.INFO, logger="mdsr_opt.synthesis.rivals"):
        res = design_contractions(mesh, mat, mus, target, method="derivative-free", max_iter=6,
                                  initial_guess=[0.05], verify=False)
    said = [r.getMessage() for r in caplog.records if r.name == "mdsr_opt.synthesis.rivals"]
    last = said[-1].split("best difference so far ")[1]
    d, share = float(last.split()[0]), float(last.split("(")[1].split()[0])
    assert d == pytest.approx(res.difference, rel=1e-3, abs=1e-9 * scale)  # the design's own figure, its units
    assert share == pytest.approx(100 * res.difference / mesh.size, rel=2e-3, abs=1e-6)
    assert "% of the body's size" in last


def test_the_pipeline_says_each_stage(caplog):
    from mdsr_opt import design_pipeline

    mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    left = [i for i, (x, y) in enumerate(mesh.points) if x == 0.0]
    top_right = {i: (x - 0.3, y - 0.4) for i, (x, y) in enumerate(mesh.points) if x == 4.0}
    with caplog.at_level(logging.INFO, logger="mdsr_opt.synthesis.pipeline"):
        out = design_pipeline(mesh, NeoHookean(1.0, 0.3), left, top_right)
    said = [r.getMessage() for r in caplog.records if r.name == "mdsr_opt.synthesis.pipeline"]
    assert said[0].startswith("design_pipeline: target solved in ") and said[0].endswith(" s")
    assert said[1] == f"design_pipeline: designing {len(out.routing.muscles) + len(out.dropped)} muscle(s) by flattened"


def test_dropping_an_idle_muscle_says_so_before_designing_again(caplog):
    from mdsr_opt.synthesis.acceptance import design_active

    mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    mat = NeoHookean(1.0, 0.3)
    lower, upper = Muscle(range(1, 16), name="lower"), Muscle(range(69, 84), name="upper")
    target = solve_internal(mesh, mat, [lower], [0.15]).x  # the upper muscle lengthens: idle
    with caplog.at_level(logging.INFO, logger="mdsr_opt.synthesis.acceptance"):
        _, kept, dropped = design_active(mesh, mat, [lower, upper], target)
    said = [r.getMessage() for r in caplog.records if r.name == "mdsr_opt.synthesis.acceptance"]
    assert [d.name for d in dropped] == ["upper"]
    assert said == ["design: idle muscle(s) upper left out; designing again with the 1 kept"]
