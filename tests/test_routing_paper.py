"""The paper's routing results (issue 14): Figure 6 layouts at two K_a, the tortuosity rule over the whole
problem library, the routing-quality table, and the ``figure6`` script."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest

from mdsr_opt.scenes.library import figure_scripts, get_problem, list_problems
from mdsr_opt.scenes.cases import prepare_case
from mdsr_opt.scenes.casefab import fixture_wall
from mdsr_opt.synthesis.contractions import design_contractions
from mdsr_opt.synthesis.routing_band import SNAP_TURN
from problems import figure6


@pytest.fixture(scope="module")
def fig6_layouts():
    return figure6.route_targets("medium")


#: the library's scenes at their coarse resolution, by name, and their cases prepared as mdsr run does, by
#: (scene name, case name): the tortuosity test prepares every case, the tests below read some of them again
#: (none changes what it reads)
_SCENES: dict = {}
_PREPARED: dict = {}


def _prepared(name, case):
    """The coarse library scene ``name`` and its case ``case`` prepared (:func:`prepare_case`), once a module."""
    if name not in _SCENES:
        _SCENES[name] = get_problem(name, resolution="coarse")
    if (name, case) not in _PREPARED:
        _PREPARED[name, case] = prepare_case(_SCENES[name], case)
    return _SCENES[name], _PREPARED[name, case]


def _prepared_names(name):
    if name not in _SCENES:
        _SCENES[name] = get_problem(name, resolution="coarse")
    return _SCENES[name].case_names


def _layout(result):
    return {min(m.nodes, m.nodes[::-1]) for m in result}


def test_K_a_changes_the_layout_of_at_least_3_of_the_5_figure6_targets(fig6_layouts):
    assert [(r["scene"].name, r["case"].name) for r in fig6_layouts] == [(s, c) for s, c, _ in figure6.TARGETS]
    changed, fewer = 0, 0
    for r in fig6_layouts:
        lo, hi = r["layouts"]
        assert r["K_a"][0] < r["K_a"][1]
        assert len(lo) >= 1 and len(hi) >= 1
        name = f"{r['scene'].name}/{r['case'].name}"
        # the paper's trade-off: the smaller K_a gives no more muscles, and longer ones on average
        assert len(lo) <= len(hi), name
        mean_lo = np.mean([s.rest_length for s in lo.stats])
        mean_hi = np.mean([s.rest_length for s in hi.stats])
        assert mean_lo >= mean_hi * (1 - 1e-9), name
        changed += _layout(lo) != _layout(hi)
        fewer += len(lo) < len(hi)
    assert changed >= 3 and fewer >= 3


def test_no_muscle_in_the_library_turns_more_than_the_tortuosity_limit():
    checked = 0
    for name in list_problems():
        for case in _prepared_names(name):
            scene, setup = _prepared(name, case)
            assert setup.target_result.success, f"{name}/{case}"
            rr = setup.routing
            # ropes snapped into the buildable band (band != "edges") may zigzag along its jagged edge up to
            # SNAP_TURN; the search's own ropes keep max_turn
            snapped = rr.params.get("band", "edges") != "edges"
            limit = max(rr.params["max_turn"], SNAP_TURN) if snapped else rr.params["max_turn"]
            for m in rr:
                d = np.diff(scene.mesh.points[list(m.nodes)], axis=0)
                a = np.arctan2(d[:, 1], d[:, 0])
                turn = np.degrees(np.abs((np.diff(a) + np.pi) % (2 * np.pi) - np.pi))
                assert turn.max(initial=0.0) <= limit + 1e-6, f"{name}/{case}: {turn.max():.1f} deg"
                checked += 1
    assert checked >= 20


def test_figure_scripts_are_not_scenes():
    assert "figure6" in figure_scripts()
    assert "figure6" not in list_problems()
    with pytest.raises(KeyError, match="unknown problem 'figure6'"):
        get_problem("figure6")


ROOT = Path(__file__).resolve().parents[1]
#: Table 1 of the default (medium) `mdsr run figure6`, whose findings the README states
STORED_TABLE = ROOT / "tests" / "data" / "figure6_table1.csv"
MARK = "`findings.txt`: the next three sentences, computed from its default run's table."


def _readme_figure6_sentences() -> str:
    """The README's sentences about Figure 6's results: after MARK, up to the next topic."""
    text = " ".join((ROOT / "README.md").read_text().split())
    start = text.index(MARK) + len(MARK)
    return text[start:text.index("`routing_quality()`", start)].strip()


def test_readme_figure6_sentences_are_the_findings_of_the_stored_run():
    with open(STORED_TABLE) as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 10
    assert _readme_figure6_sentences() == " ".join(figure6.findings(rows))


def test_figure6c_charts_equilibria_at_every_iterate():
    """Every point of a Figure 6c trace is the difference of an equilibrium: iteration 0 at the design's start,
    the last at its result; the contractions in between are the IPOPT iterates (the design stopped there)."""
    from mdsr_opt.synthesis.routing import route_muscles

    scene, setup = _prepared("tentacle", "curl")
    target = setup.target
    muscles = route_muscles(scene.mesh, target, K_a=1.0, **figure6.ROUTING).muscles
    res, tr = figure6.design_layout(scene, target, muscles)
    assert res.success and all(tr["solved"])
    assert tr["iterations"][0] == 0 and tr["iterations"][-1] == res.iterations
    assert np.all(np.diff(tr["iterations"]) > 0)
    assert tr["difference"][0] == pytest.approx(res.initial_difference, rel=1e-3)
    assert tr["difference"][-1] == pytest.approx(res.difference, rel=1e-6)
    A = np.array(tr["contractions"])
    assert A.shape == (len(tr["iterations"]), len(muscles))
    assert np.allclose(A[0], res.initial_contractions) and np.allclose(A[-1], res.contractions)
    assert np.abs(np.diff(A, axis=0)).max() > 1e-6  # the iterates move: not the end point repeated


def test_findings_count_what_the_table_says():
    def row(t, lay, m, it, d, up):
        return {"target": t, "layout": lay, "muscles": m, "iterations": it, "difference": d, "equilibrium_rises": up}

    rows = [row("a", "C", 1, 5, 0.2, 0), row("a", "D", 2, 7, 0.1, 1),   # fewer: fewer iterations, larger D
            row("b", "C", 2, 6, 0.1, 0), row("b", "D", 2, 6, 0.1, 0),   # same count
            row("c", "C", 3, 4, 0.05, 2), row("c", "D", 1, 4, 0.06, 0)]  # smaller K_a gives MORE: ties
    s = figure6.findings(rows)
    assert s[0] == "The smaller `K_a` gives fewer muscles for 1 of 3 targets and as many for 1 (more for 1)."
    assert "fewer IPOPT iterations for 1 of 2, in as many for 1 and in more for 0" in s[1]
    assert "smaller difference for 0 of 2" in s[1]
    assert s[2].endswith("rises after an iteration in 2 of 6 designs.")
    assert figure6.rises([0.3, 0.2, 0.25, 0.25, np.nan, 0.1]) == 1


def test_routing_quality_rows_and_tables(tmp_path):
    from mdsr_opt.studies.routing_quality import edge_muscles, routing_quality, write_quality_table

    rows = routing_quality([("gripper", "close")], resolution="coarse")
    (r,) = rows
    assert r.success and r.status == "ok"
    assert r.muscles >= 1 and r.total_length > 0
    assert r.largest_turn <= 45.0 + 1e-6
    assert 0.0 <= r.nonuniformity < 1.0
    # every contracted edge its own spring muscle relaxes the routed layout: it can only do better
    assert r.edge_bound <= r.difference * (1 + 1e-6)
    assert r.ratio == pytest.approx(r.difference / r.edge_bound)
    scene, setup = _prepared("gripper", "close")
    assert r.edge_muscles == len(edge_muscles(scene.mesh, setup.target)) > r.muscles
    paths = write_quality_table(rows, tmp_path / "q.csv", tmp_path / "q.md")
    assert len(paths) == 2
    with open(tmp_path / "q.csv") as fh:
        got = list(csv.DictReader(fh))
    assert got[0]["scene"] == "gripper" and float(got[0]["difference"]) == pytest.approx(r.difference)
    md = (tmp_path / "q.md").read_text()
    assert "| gripper | close |" in md and "edge_bound" in md


def test_routing_quality_routes_and_designs_as_mdsr_run():
    from mdsr_opt.studies.routing_quality import routing_quality

    # gecko bend_left: route_for_design lays 2 ropes deeper inside (a plain route_muscles lays 1), fitted to
    # a fixture radius smaller than the default; the study's row is that layout, designed with that radius
    (r,) = routing_quality([("gecko", "bend_left")], resolution="coarse", bound=False)
    scene, setup = _prepared("gecko", "bend_left")
    assert r.muscles == len(setup.routing.muscles) == 2
    assert r.total_length == pytest.approx(sum(s.rest_length for s in setup.routing.stats), rel=1e-12)
    res = design_contractions(scene.mesh, scene.material, setup.routing.muscles, setup.target,
                              **scene.design_options, anchor_radius=setup.anchor_radius,
                              fixture_wall=fixture_wall(scene))
    assert setup.anchor_radius == setup.routing.fixture_radius
    assert r.success and r.difference == pytest.approx(res.difference, rel=1e-9)


def test_routing_quality_rejects_bad_cases_before_any_work():
    from mdsr_opt.studies.routing_quality import routing_quality, write_quality_table

    with pytest.raises(TypeError, match="scene, case"):
        routing_quality(["gripper"])
    with pytest.raises(KeyError, match="no case 'open'"):
        routing_quality([("gripper", "close"), ("gripper", "open")])
    with pytest.raises(ValueError, match="at least one row"):
        write_quality_table([], "never.csv")


@pytest.mark.slow
def test_mdsr_run_figure6_writes_panels_table_chart_and_the_readme_findings(tmp_path):
    from mdsr_opt.cli.main import main

    code = main(["run", "figure6", "--out", str(tmp_path), "--quiet"])  # the default resolution: the README's
    assert code == 0
    for f in figure6.OUTPUTS:
        assert (tmp_path / f).stat().st_size > 100, f
    with open(tmp_path / "table1.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 10 and {r["layout"] for r in rows} == {"C", "D"}
    for r in rows:
        assert r["success"] == "True" and int(r["iterations"]) >= 1
        n = int(r["muscles"])
        for i in range(1, n + 1):  # stroke = contraction x rest length, within [0, a_max]
            assert 0.0 <= float(r[f"a{i}"]) <= 0.6 + 1e-9
            assert float(r[f"stroke{i}"]) >= 0.0
    found = (tmp_path / "findings.txt").read_text().split("\n")[:-1]
    assert found == figure6.findings(rows)
    assert " ".join(found) == _readme_figure6_sentences()  # the README states this run's numbers
    from mdsr_opt.body.io import read_json

    data = read_json(tmp_path / "figure6.json")
    for lay, row in zip(data["layouts"], data["rows"]):
        tr = lay["trace"]
        assert all(tr["solved"]) and tr["iterations"][0] == 0
        assert tr["iterations"][-1] == row["iterations"]
        # every point is an equilibrium's difference: the first at the start, the last at the design
        assert tr["difference"][-1] == pytest.approx(row["difference"], rel=1e-6)
        # the design starts from an equilibrium solved from the target to the warm start's residual
        # (nlp.WARM_START_TOL, 1e-4), the trace's first point from the predictor to the solver's tolerance: on
        # the soft one-rope tentacle/curl (layout D) they differ by 0.23 % in D, elsewhere by 0.09 % at most
        assert math.isclose(tr["difference"][0], row["initial_difference"], rel_tol=5e-3)
        assert figure6.rises(tr["difference"]) == row["equilibrium_rises"]


def test_layout_legends_sit_beside_the_rows_never_over_a_drawing():
    """plot_layout_grid gives each layout row one legend, beside its last panel: it covers no drawing (the
    body, wherever its empty corner is) and names the muscles as every figure does (issue 36)."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.colors import to_hex

    from mdsr_opt import Mesh, Muscle
    from mdsr_opt.plot.routing import plot_layout_grid

    mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    X = mesh.points.copy()
    right = X[:, 0] > 2.0  # an L: the strip's right half turned up into a column
    X[right] = np.column_stack([2.0 + (X[right, 1]), (X[right, 0] - 2.0) * 1.0])
    bottom = [int(i) for i in np.argsort(mesh.points[:, 0]) if mesh.points[i, 1] == 0.0 and mesh.points[i, 0] <= 2.0]
    top = [int(i) for i in np.argsort(mesh.points[:, 0]) if mesh.points[i, 1] == 1.0 and mesh.points[i, 0] <= 2.0]
    col = {"title": "L", "mesh": mesh, "target": X, "layouts": [[Muscle(bottom)], [Muscle(bottom), Muscle(top)]],
           "row_labels": ["C", "D"]}
    fig = plot_layout_grid([col, dict(col, title="L2")])
    fig.canvas.draw()
    axes = np.array(fig.axes).reshape(4, 2)
    legends = [(ax, ax.get_legend()) for ax in fig.axes if ax.get_legend() is not None]
    assert [ax for ax, _ in legends] == [axes[2, 1], axes[3, 1]]  # one per layout row, on its last panel
    for ax, leg in legends:
        box = leg.get_window_extent()
        assert box.x0 >= ax.get_window_extent().x1  # beside the panel, over no drawing
    d = legends[1][1]
    assert [t.get_text() for t in d.get_texts()] == ["M1", "M2"]
    assert [to_hex(h.get_color()) for h in d.legend_handles] == ["#d62728", "#1f77b4"]
