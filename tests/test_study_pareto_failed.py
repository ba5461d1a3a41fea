"""quick_pareto.png draws every failed run: one without an error (a time-out) is a cross on the top edge at its
time, and the panel's title counts them (new-user trial defect 11: it was not drawn at all)."""

from __future__ import annotations

import math

import matplotlib

matplotlib.use("Agg")
import numpy as np  # noqa: E402

from mdsr_opt.plot.studies import plot_study_pareto  # noqa: E402


def row(method, error, success, build=0.001, solve=0.01, wall=0.02):
    return {"kind": "equilibrium", "method": method, "error": error, "success": success, "build_time": build,
            "solve_time": solve, "wall_time": wall}


def test_a_timed_out_run_is_a_cross_on_the_top_edge_at_its_wall_time():
    rows = [row("ipopt", 1e-3, True), row("ipopt", 1e-4, True, solve=0.1),
            row("ipopt-lbfgs", 2e-3, True), row("ipopt-lbfgs", math.nan, False, solve=0.0, wall=30.0)]
    fig = plot_study_pareto(rows)
    ax = fig.axes[0]
    assert "1 with no result: x on the top edge" in ax.get_title()
    top = [c for c in ax.collections if c.get_offset_transform() == ax.get_xaxis_transform()]
    assert len(top) == 1
    np.testing.assert_allclose(top[0].get_offsets(), [[30.0, 1.0]])   # its wall time, the axes' top
    lo, hi = ax.get_xlim()
    assert lo < 0.011 and hi > 30.0                                   # inside the time axis
    assert "ipopt-lbfgs (no result: 1)" in [t.get_text() for t in ax.get_legend().get_texts()]


def test_a_panel_whose_runs_all_failed_without_an_error_still_shows_them():
    rows = [row("flattened", math.nan, False, wall=5.0), row("nested", math.nan, False, wall=7.0)]
    rows = [dict(r, kind="design") for r in rows]
    ax = plot_study_pareto(rows).axes[0]
    assert "2 with no result" in ax.get_title()
    offsets = np.vstack([c.get_offsets() for c in ax.collections])
    np.testing.assert_allclose(sorted(offsets[:, 0]), [5.0, 7.0])
    assert ax.get_xlim()[0] < 5.0 and ax.get_xlim()[1] > 7.0
