"""The paper's routing results (issue 14): Figure 6 layouts at two K_a, the tortuosity rule over the whole
problem library, the routing-quality table, and the ``figure6`` script."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest

from mdsr_opt.scenes.library import figure_scripts, get_problem, list_problems
from mdsr_opt.scenes.cases import prepare_case
from problems import figure6


@pytest.fixture(scope="module")
def fig6_layouts():
    return figure6.route_targets("medium")


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
        scene = get_problem(name, resolution="coarse")
        for case in scene.cases:
            setup = prepare_case(scene, case)
            assert setup.target_result.success, f"{name}/{case.name}"
            rr = setup.routing
            limit = rr.params["max_turn"]
            for m in rr:
                d = np.diff(scene.mesh.points[list(m.nodes)], axis=0)
                a = np.arctan2(d[:, 1], d[:, 0])
                turn = np.degrees(np.abs((np.diff(a) + np.pi) % (2 * np.pi) - np.pi))
                assert turn.max(initial=0.0) <= limit + 1e-6, f"{name}/{case.name}: {turn.max():.1f} deg"
                checked += 1
    assert checked >= 20


def test_figure_scripts_are_not_scenes():
    assert "figure6" in figure_scripts()
    assert "figure6" not in list_problems()
    with pytest.raises(KeyError, match="unknown problem 'figure6'"):
        get_problem("figure6")


def test_read_ipopt_log_keeps_the_last_table(tmp_path):
    log = tmp_path / "ipopt.log"
    log.write_text(
        "iter    objective    inf_pr   inf_du lg(mu)  ||d||  lg(rg) alpha_du alpha_pr  ls\n"
        "   0  4.0000000e-01 1.00e-10 2.2e-02  -1.0 0.00e+00    -  0.00e+00 0.00e+00   0\n"
        "   1  3.0000000e-01 5.80e-02 1.9e+00  -1.7 3.09e-01    -  6.03e-01 1.00e+00f  1\n"
        "iter    objective    inf_pr   inf_du lg(mu)  ||d||  lg(rg) alpha_du alpha_pr  ls\n"
        "   0  2.0000000e-01 1.00e-10 2.2e-02  -1.0 0.00e+00    -  0.00e+00 0.00e+00   0\n"
        "   1r 1.0000000e-01 2.00e-03 1.9e+00  -1.7 3.09e-01    -  6.03e-01 1.00e+00f  1\n"
        "   2  5.0000000e-02 1.00e-14 1.9e-13 -11.0 3.09e-09    -  1.00e+00 1.00e+00h  1\n"
        "\nNumber of Iterations....: 2\n")
    its, f, inf = figure6.read_ipopt_log(log)
    assert its.tolist() == [0, 1, 2]
    assert f == pytest.approx([0.2, 0.1, 0.05])
    assert inf == pytest.approx([1e-10, 2e-3, 1e-14])


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
    scene = get_problem("gripper", resolution="coarse")
    setup = prepare_case(scene, "close")
    assert r.edge_muscles == len(edge_muscles(scene.mesh, setup.target)) > r.muscles
    paths = write_quality_table(rows, tmp_path / "q.csv", tmp_path / "q.md")
    assert len(paths) == 2
    with open(tmp_path / "q.csv") as fh:
        got = list(csv.DictReader(fh))
    assert got[0]["scene"] == "gripper" and float(got[0]["difference"]) == pytest.approx(r.difference)
    md = (tmp_path / "q.md").read_text()
    assert "| gripper | close |" in md and "edge_bound" in md


def test_routing_quality_rejects_bad_cases_before_any_work():
    from mdsr_opt.studies.routing_quality import routing_quality, write_quality_table

    with pytest.raises(TypeError, match="scene, case"):
        routing_quality(["gripper"])
    with pytest.raises(KeyError, match="no case 'open'"):
        routing_quality([("gripper", "close"), ("gripper", "open")])
    with pytest.raises(ValueError, match="at least one row"):
        write_quality_table([], "never.csv")


@pytest.mark.slow
def test_mdsr_run_figure6_writes_panels_table_and_chart(tmp_path):
    from mdsr_opt.cli.main import main

    code = main(["run", "figure6", "--out", str(tmp_path), "--resolution", "coarse", "--quiet"])
    assert code == 0
    for f in ("figure6a.png", "figure6b.png", "figure6c.png", "table1.csv", "table1.md", "figure6.json"):
        assert (tmp_path / f).stat().st_size > 500, f
    with open(tmp_path / "table1.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 10 and {r["layout"] for r in rows} == {"C", "D"}
    for r in rows:
        assert r["success"] == "True" and int(r["iterations"]) >= 1
        n = int(r["muscles"])
        for i in range(1, n + 1):  # stroke = contraction x rest length, within [0, a_max]
            assert 0.0 <= float(r[f"a{i}"]) <= 0.6 + 1e-9
            assert float(r[f"stroke{i}"]) >= 0.0
    from mdsr_opt.body.io import read_json

    data = read_json(tmp_path / "figure6.json")
    for lay, row in zip(data["layouts"], data["rows"]):
        tr = lay["trace"]
        assert len(tr["iterations"]) == row["iterations"] + 1
        assert tr["difference"][-1] == pytest.approx(row["difference"], rel=1e-12)
        assert math.isclose(tr["difference"][0], row["initial_difference"], rel_tol=1e-3)


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
