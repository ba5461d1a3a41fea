"""The routing in a design's result names the muscles the result has, fresh and loaded (the fourth new-user
trial: the README's first design dropped an idle muscle, the fresh routing still listed it and the loaded one
paired five names with six figures)."""

from __future__ import annotations

import json
import re
import warnings

import numpy as np
import pytest

from mdsr_opt import Mesh, NeoHookean, PipelineResult, design_pipeline, nodes_in_box


@pytest.fixture(scope="module")
def first_design():
    """The README's first design: a strip clamped at x = 0, its tip dragged up and back."""
    mesh = Mesh.from_polygon([[0, 0], [4, 0], [4, 1], [0, 1]], max_area=0.03)
    base, tip = nodes_in_box(mesh, xmax=0.0), nodes_in_box(mesh, xmin=4.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = design_pipeline(mesh, NeoHookean(1.0, 0.3), base, {i: mesh.points[i] + [-0.6, 1.4] for i in tip})
    assert res.dropped, "the README's first design no longer drops an idle muscle: pick another witness"
    return res


def _consistent(res):
    rr = res.routing
    names = [m.name for m in res.muscles]
    assert [m.name for m in rr.muscles] == names and [tuple(m.nodes) for m in rr] == [tuple(m.nodes) for m in res.muscles]
    assert [s.name for s in rr.stats] == names
    shown = re.search(r"muscle\(s\) (\[.*?\]), edges (\[.*?\]), contractions (\[.*?\])", repr(rr))
    assert shown and len(eval(shown.group(1))) == len(eval(shown.group(2))) == len(eval(shown.group(3))) == len(names)
    rows = [line.split()[0] for line in rr.table().splitlines()[1:]]
    assert rows == names
    out = [d for d in rr.dropped if d.reason.startswith("dropped after the design: ")]
    assert [d.nodes for d in out] == [tuple(d.nodes) for d in res.dropped]
    assert [d.reason for d in out] == [f"dropped after the design: {d.reason}" for d in res.dropped]


def test_the_routing_of_a_result_names_its_muscles_fresh_and_loaded(first_design, tmp_path):
    res = first_design
    _consistent(res)
    back = PipelineResult.load(res.save(tmp_path / "r").rsplit("/", 1)[0])
    _consistent(back)
    assert repr(back.routing) == repr(res.routing) and back.routing.table() == res.routing.table()
    assert [d.to_dict() for d in back.routing.dropped] == [d.to_dict() for d in res.routing.dropped]


def test_a_result_saved_with_the_dropped_muscles_figures_loads_consistent(first_design, tmp_path):
    """A design.json written before: the routing's figures of a muscle the design dropped are still there."""
    res = first_design
    path = res.save(tmp_path / "old")
    data = json.loads(open(path).read())
    d = res.dropped[0]
    data["routing"]["stats"].append(dict(data["routing"]["stats"][0], name=d.name))
    data["routing"]["dropped"] = [u for u in data["routing"]["dropped"]
                                  if not u["reason"].startswith("dropped after the design")]
    open(path, "w").write(json.dumps(data))
    back = PipelineResult.load(tmp_path / "old")
    assert [s.name for s in back.routing.stats] == [m.name for m in back.muscles]
    assert d.name not in back.routing.table() and len(back.routing.stats) == len(back.muscles)
    assert np.isfinite([s.contraction for s in back.routing.stats]).all()


def test_a_scene_run_keeps_its_routing_to_the_muscles_kept_and_says_its_notes(tmp_path):
    """The same design as a scene file through run_case (as ``mdsr run``): the routing, its figures in the
    report and the summary name the muscles kept, and the summary says every routing note once."""
    from mdsr_opt import load_scene, run_case

    (tmp_path / "strip.toml").write_text(
        'name = "strip"\n[body]\noutline = [[0, 0], [4, 0], [4, 1], [0, 1]]\nmax_area = 0.03\n'
        '[material]\nmodel = "neo-hookean"\nE = 1.0\nnu = 0.3\n'
        '[regions]\nbase = { box = [-1, -1, 0, 2] }\ntip = { box = [4, -1, 5, 2] }\n'
        '[[cases]]\nname = "first"\nanchors = "base"\ndrags = [{ nodes = "tip", by = [-0.6, 1.4] }]\n')
    lines: list = []
    run = run_case(load_scene(tmp_path / "strip.toml"), "first", photo=False, log=lines.append)
    rep, rr = run.report, run.setup.routing
    assert rep.dropped, "the strip no longer drops an idle muscle: pick another witness"
    assert [tuple(m.nodes) for m in rr] == [tuple(m.nodes) for m in run.setup.muscles]
    assert len(rr.stats) == len(rr.muscles) == rep.n_muscles == len(rep.routing["muscles"])
    assert [s.n_edges for s in rr.stats] == [m["n_edges"] for m in rep.routing["muscles"]]
    assert any(d.reason.startswith("dropped after the design: idle") for d in rr.dropped)
    said = [ln[len("routing: "):] for ln in lines if ln.startswith("routing: ") and "muscle(s) from" not in ln]
    assert rr.notes and said == list(rr.notes) and len(set(said)) == len(said)


def test_route_for_design_gives_the_pipelines_layout_and_fixtures(first_design):
    """What route_muscles' docstring and the README promise: route_for_design on the pipeline's target routes
    the pipeline's ropes (those kept and those the design dropped) with the fixture radius it designed with."""
    from mdsr_opt import route_for_design

    res = first_design
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rr = route_for_design(res.mesh, res.target)
    routed = sorted([tuple(m.nodes) for m in res.routing] + [d.nodes for d in res.routing.dropped
                                                             if d.reason.startswith("dropped after the design")])
    assert sorted(tuple(m.nodes) for m in rr) == routed
    assert rr.fixture_radius == pytest.approx(res.design.anchor_radius, rel=1e-12) and rr.notes == res.routing.notes
