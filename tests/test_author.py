"""mdsr author without a browser: outlines, session checks and solves, scene export, the command line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from mdsr_opt import get_problem, load_scene, solve_external
from mdsr_opt.author import _is_loopback, body_spec
from mdsr_opt.author.export import download, save_scene
from mdsr_opt.author.outline import parse_outline
from mdsr_opt.author.server import _parse, load_body
from mdsr_opt.author.session import Session

SQUARE_WITH_HOLE = """<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 100 100">
  <path d="M 0 0 H 80 V 40 h -80 Z"/>
  <rect x="30" y="10" width="20" height="20"/>
</svg>"""


# ------------------------------------------------------------------------------------------ outlines
def test_svg_outline_with_hole_is_read_upright():
    outline, holes = parse_outline("body.svg", SQUARE_WITH_HOLE)
    assert len(holes) == 1
    assert np.isclose(abs(_area(outline)), 80 * 40) and np.isclose(abs(_area(holes[0])), 400)
    assert outline[:, 1].max() == 0.0 and outline[:, 1].min() == -40.0  # y flipped (SVG y points down)
    assert _area(outline) > 0  # counter-clockwise


def _area(p):
    x, y = p[:, 0], p[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def test_relative_path_commands():
    outline, _ = parse_outline("a.svg", '<svg><path d="m 1 1 l 2 0 l 0 2 l -2 0 z"/></svg>')
    assert sorted(map(tuple, outline.tolist())) == [(1, -3), (1, -1), (3, -3), (3, -1)]


@pytest.mark.parametrize("name, text, words", [
    ("a.svg", '<svg><path d="M0 0 C 1 1 2 2 3 0 Z"/></svg>', "not supported"),
    ("a.svg", '<svg><polygon points="0,0 1,0 1,1" transform="scale(2)"/></svg>', "transform"),
    ("a.svg", "<svg><polygon points='0,0 1,0", "not valid XML"),
    ("a.svg", '<svg><polygon points="0,0 2,2 2,0 0,2"/></svg>', "self-intersecting"),
    ("a.json", '{"outline": [[0, 0], [2, 2], [2, 0], [0, 2]]}', "self-intersecting"),
    ("a.json", '{"outline": [[0, 0], [1, 0]]}', "at least 3"),
    ("a.json", '{"outlines": []}', "unknown field"),
    ("a.json", '{"outline": [[0, 0], [1, "x"], [0, 1]]}', "not a number"),
    ("a.txt", "0 0 1 0 1 1", "ends in .json or .svg"),
    ("a.svg", '<!DOCTYPE x [<!ENTITY a "b">]><svg/>', "DOCTYPE"),
])
def test_bad_outline_files_are_named(name, text, words):
    with pytest.raises(ValueError, match=words):
        parse_outline(name, text)


# ------------------------------------------------------------------------------------------ sessions
@pytest.fixture(scope="module")
def tentacle():
    return get_problem("tentacle", resolution="coarse")


def test_session_starts_from_the_first_external_case(tentacle):
    s = Session.from_scene(tentacle)
    case = tentacle.cases[0]
    assert np.array_equal(s.anchors, case.anchors) and np.array_equal(s.drag_positions, case.drag_positions)
    st = s.settle()
    ref = solve_external(tentacle.mesh, tentacle.material, case.anchors, case.drags)
    assert st.success and not st.live and np.array_equal(st.x, ref.x)
    assert np.array_equal(s.target, ref.x)


def test_live_drag_is_warm_and_agrees_with_a_cold_solve(tentacle):
    s = Session.from_scene(tentacle)
    s.settle()
    shift = 0.02 * tentacle.mesh.size * np.array([1.0, -0.5])
    s.set_fixed(s.anchors, s.drag_nodes, s.drag_positions + shift)
    st = s.drag()
    assert st.live and st.success and not st.warm_failed
    # every later drag reuses the model and the solvers built so far: nothing new is built
    from mdsr_opt.mechanics.model import get_model
    from mdsr_opt.mechanics.units import Units

    unit = Units(tentacle.mesh, tentacle.material)  # the solves build on the body's unit copy
    model = get_model(unit.unit_mesh, unit.unit_material)
    built = dict(model._solvers)
    s.set_fixed(s.anchors, s.drag_nodes, s.drag_positions + 0.5 * shift)
    st = s.drag()
    assert st.live and st.success and get_model(unit.unit_mesh, unit.unit_material) is model
    assert model._solvers.keys() == built.keys() and all(model._solvers[k] is built[k] for k in built)
    assert s.target is None  # a live state is not a target until it is settled
    ref = solve_external(tentacle.mesh, tentacle.material, s.anchors, (s.drag_nodes, s.drag_positions))
    size = tentacle.mesh.size
    assert np.abs(st.x - ref.x).max() < 1e-3 * size  # a preview: close to the equilibrium
    settled = s.settle()  # the release: exactly solve_external's equilibrium, as mdsr run solves it
    assert settled.success and not settled.live
    assert np.array_equal(settled.x, ref.x) and np.array_equal(s.target, ref.x)


def test_a_drag_that_cannot_be_reached_is_reported_not_hidden(tentacle):
    s = Session.from_scene(tentacle)
    s.settle()
    far = s.mesh.points[s.anchors].mean(0)  # drag the tip onto the anchored base: folds the body
    s.set_fixed(s.anchors, s.drag_nodes, s.drag_positions - s.drag_positions.mean(0) + far)
    st = s.drag()
    assert not st.success and st.status
    assert s.target is None


@pytest.mark.parametrize("anchors, dn, dp, err, words", [
    ([0, 99999], [], [], ValueError, "out of range"),
    ([0, 1.5], [], [], TypeError, "not an integer"),
    ([0, 0], [], [], ValueError, "repeated"),
    ([0], [1], [[np.nan, 0.0]], ValueError, "finite"),
    ([0], [1], [[1e9, 0.0]], ValueError, "too large"),
    ([0], [1, 2], [[0.0, 0.0]], ValueError, "1 for 2 drag nodes"),
    ([0, 1], [1], [[0.0, 0.0]], ValueError, "both anchored and dragged"),
])
def test_fixed_nodes_are_checked_at_the_door(tentacle, anchors, dn, dp, err, words):
    s = Session.from_scene(tentacle)
    with pytest.raises(err, match=words):
        s.set_fixed(anchors, dn, dp)


def test_route_and_design_need_a_settled_target(tentacle):
    s = Session.from_scene(tentacle)
    with pytest.raises(ValueError, match="no settled target"):
        s.route(10.0, 4.0, None)
    s.settle()
    with pytest.raises(ValueError, match="route muscles first"):
        s.run_design()


def test_outline_session_and_resolution_limit():
    s = Session.from_outline([[0, 0], [4, 0], [4, 1], [0, 1]], resolution=120)
    assert 90 < s.n_nodes < 150 and s.source == "outline"
    with pytest.raises(ValueError, match="above the page's limit of 20000 nodes"):
        Session.from_outline([[0, 0], [4, 0], [4, 1], [0, 1]], resolution=50_000)
    with pytest.raises(ValueError, match="resolution must be at most 200000 nodes"):
        Session.from_outline([[0, 0], [4, 0], [4, 1], [0, 1]], resolution=10 ** 6)


# ------------------------------------------------------------------------------------------ export
@pytest.mark.parametrize("width", [1e-5, 1e-7])
def test_a_thin_outline_from_the_page_is_refused_before_meshing(width, monkeypatch):
    # the page's meshing is bounded by its node limit, not by the library's 2 M triangles: a sliver that
    # would keep the server busy for seconds is refused before the mesher runs, with its width and place
    import triangle

    mesher = triangle.triangulate

    def no_meshing(*a, **k):
        raise AssertionError("the mesher ran")

    monkeypatch.setattr(triangle, "triangulate", no_meshing)
    with pytest.raises(ValueError, match=r"only about 1e-0[57] wide"):
        Session.from_outline([[0, 0], [1, 0], [1, width], [0, width]], resolution=600)
    monkeypatch.setattr(triangle, "triangulate", mesher)
    assert Session.from_outline([[0, 0], [4, 0], [4, 1], [0, 1]], resolution=300).n_nodes > 200  # still usable


def test_saved_scene_reads_back_with_the_same_mesh_case_and_muscles(tentacle, tmp_path):
    s = Session.from_scene(tentacle)
    s.settle()
    s.route(10.0, 4.0, 2)
    files = save_scene(s, tmp_path, "x1")
    back = load_scene(files[0])
    assert np.array_equal(back.mesh.points, tentacle.mesh.points)
    c = back.case("curl")  # the case edited on the page keeps its name
    assert np.array_equal(c.drag_positions, s.drag_positions)  # exact floats, not rounded
    assert [m.nodes for m in c.muscles] == [m.nodes for m in s.muscles] and back.muscles is None  # curl's alone
    assert c.anchor_radius == s.fixture_radius and back.case("s_curve").muscles is None
    data = json.loads(Path(files[0]).read_text())
    assert data["routing"] == tentacle.routing_options  # the knobs s_curve routes with (not the page's K_a=10)


def test_saving_needs_fixed_nodes_and_a_valid_name(tentacle, tmp_path):
    s = Session.from_scene(tentacle)
    with pytest.raises(ValueError, match="may hold only"):
        save_scene(s, tmp_path, "bad name!")
    s.set_fixed([], [], [])
    with pytest.raises(ValueError, match="nothing to save"):
        save_scene(s, tmp_path, "ok")
    assert list(tmp_path.iterdir()) == []  # nothing partly written


def test_downloads_say_what_is_missing(tentacle, tmp_path):
    s = Session.from_scene(tentacle)
    with pytest.raises(ValueError, match="no settled target"):
        download(s, "target.vtu", tmp_path)
    s.settle()
    import matplotlib.pyplot as plt

    open_before = set(plt.get_fignums())
    data, media = download(s, "target.png", tmp_path)
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and media == "image/png"
    assert set(plt.get_fignums()) == open_before  # the server keeps no figure of a download open
    with pytest.raises(ValueError, match="no design yet"):
        download(s, "design.png", tmp_path)
    with pytest.raises(ValueError, match="unknown download"):
        download(s, "../etc/passwd", tmp_path)


# ------------------------------------------------------------------------------------------ server pieces
@pytest.mark.parametrize("raw, words", [
    ({"bytes": b"\x00"}, "binary"),
    ({"text": "{"}, "not JSON"),
    ({"text": "[1, 2]"}, "string 'type'"),
    ({"text": '{"type": 3}'}, "string 'type'"),
])
def test_malformed_frames(raw, words):
    with pytest.raises(ValueError, match=words):
        _parse(raw)


def test_load_body_errors():
    with pytest.raises(ValueError, match="library name"):
        load_body({"kind": "problem", "name": "../etc"})
    with pytest.raises(ValueError, match="unknown body kind"):
        load_body({"kind": "pdf"})
    with pytest.raises(ValueError, match="limit of 20000 nodes"):
        load_body({"kind": "problem", "name": "tentacle", "resolution": 50_000})
    with pytest.raises(FileNotFoundError, match="no such file"):
        body_spec("missing/scene.toml")


def test_json_outline_file_on_the_command_line(tmp_path):
    p = tmp_path / "plate.json"
    p.write_text(json.dumps({"outline": [[0, 0], [3, 0], [3, 1], [0, 1]],
                             "holes": [[[1, 0.3], [2, 0.3], [2, 0.7], [1, 0.7]]]}))
    spec = body_spec(str(p), resolution="200")
    s = load_body(spec)
    assert s.name == "plate" and len(s.mesh.boundary_loops) == 2


def test_loopback_detection():
    assert _is_loopback("127.0.0.1") and _is_loopback("::1") and _is_loopback("localhost")
    assert not _is_loopback("0.0.0.0") and not _is_loopback("192.168.1.5")


def test_allowed_hosts_are_the_loopback_names_with_the_port():
    from mdsr_opt.author.guard import allowed_hosts

    assert allowed_hosts("127.0.0.1", 8123) == {"127.0.0.1:8123", "localhost:8123", "[::1]:8123"}
    assert "[::1]:9" in allowed_hosts("::1", 9) and "localhost" in allowed_hosts("localhost", 80)
    assert "10.0.0.5:9" in allowed_hosts("10.0.0.5", 9) and "evil.example:9" not in allowed_hosts("10.0.0.5", 9)
    assert allowed_hosts("0.0.0.0", 9) is None  # a wildcard bind: the token is the only check (and a warning)


def test_non_loopback_host_warns(capsys, monkeypatch):
    import mdsr_opt.author as author

    class Stop(Exception):
        pass

    def no_bind(host, port):
        raise Stop

    monkeypatch.setattr(author, "_bind", no_bind)
    with pytest.raises(Stop):
        author.serve(None, host="0.0.0.0", open_browser=False)
    assert "WARNING" in capsys.readouterr().err


def test_cli_registers_author():
    from mdsr_opt.cli.main import main

    with pytest.raises(SystemExit) as e:
        main(["author", "--help"])
    assert e.value.code == 0
    assert main(["author", "no_such_robot", "--no-browser"]) == 2


def test_drags_that_arrive_while_the_server_solves_are_dropped_but_the_latest():
    """The page sends drags faster than the server solves: queued drags are replaced by the newest (counted
    in ``dropped``), and the state the page gets answers the last drag it sent, not a stale one."""
    import asyncio

    from mdsr_opt.author.server import Page

    sent = []

    class FakeSocket:
        async def send_text(self, text):
            sent.append(json.loads(text))

    async def scenario():
        page = Page(FakeSocket(), {"out": "unused", "folders": (), "written": set()})
        page.enqueue({"type": "load", "body": {"kind": "problem", "name": "tentacle", "resolution": "coarse"}})
        worker = asyncio.create_task(page.worker())
        while not any(m["type"] == "state" for m in sent):  # the body is loaded and settled
            await asyncio.sleep(0.01)
        start = next(m for m in sent if m["type"] == "state")
        base = np.array(start["drag_positions"])
        for k in range(1, 21):  # 20 drags in one burst, before the worker can take any of them
            page.enqueue({"type": "drag", "seq": k, "anchors": start["anchors"], "drag_nodes": start["drag_nodes"],
                          "drag_positions": (base + 0.002 * k).tolist()})
        while not any(m["type"] == "state" and m.get("seq") == 20 for m in sent):
            await asyncio.sleep(0.01)
        worker.cancel()
        page.tmp.cleanup()
        return page, base

    page, base = asyncio.run(asyncio.wait_for(scenario(), timeout=120))
    states = [m for m in sent if m["type"] == "state" and m.get("seq") is not None]
    assert [m["seq"] for m in states] == [20]  # 19 stale drags never solved
    assert page.dropped == 19 and states[-1]["dropped"] == 19
    assert np.allclose(states[-1]["drag_positions"], base + 0.04) and states[-1]["success"]
    assert not [m for m in sent if m["type"] == "error"]


def test_serve_says_where_files_go(capsys, monkeypatch, tmp_path):
    import mdsr_opt.author as author

    class NoServer:
        def run(self, sockets):
            for s in sockets:
                s.close()

    monkeypatch.setattr(author, "_server", lambda app, sock, access_log=False: NoServer())
    assert author.serve(None, port=0, open_browser=False, out=str(tmp_path / "saved")) == 0
    out = capsys.readouterr().out
    assert f"Save writes scene files to {(tmp_path / 'saved').resolve()} (--out)" in out
    assert "downloads: your browser's download folder" in out and "token=" in out


def test_downloaded_figures_name_the_scenes_unit(tentacle, monkeypatch, tmp_path):
    """The page's figure downloads label their axes in the scene's unit (a drawn outline: body units)."""
    import mdsr_opt.plot.common as common
    from mdsr_opt.author.export import download

    s = Session.from_scene(tentacle)
    assert s.units == tentacle.units
    s.settle()
    labels = []
    monkeypatch.setattr(common, "save_figure", lambda fig, path, **kw: (labels.append(fig.axes[0].get_xlabel()),
                                                                       Path(path).write_bytes(b"png")))
    _, media = download(s, "graph.png", tmp_path)
    assert labels == [f"x ({tentacle.units or 'body units'})"] and media == "image/png"


# ------------------------------------------------------------------------------------------ fabrication and deletion
def test_the_page_shows_the_bodys_fabrication_defaults(tentacle):
    from mdsr_opt.author.server import body_message
    from mdsr_opt.mechanics.anchors import body_size
    from mdsr_opt.synthesis.fabrication import Fabrication

    s = Session.from_scene(tentacle)
    shown = body_message(s)["fabrication"]
    assert shown == Fabrication().for_body(tentacle.mesh).to_dict()  # the class's defaults, read
    D = body_size(tentacle.mesh)
    assert np.isclose(shown["channel_diameter"], 0.01 * D) and np.isclose(shown["fixture_radius"], 0.04 * D)
    assert body_message(s)["units"] is None  # the library's tentacle states no unit: body units, none invented
    # a scene's own [fabrication] is what the page shows (the fields it leaves open: the body's defaults)
    s2 = Session.from_scene(tentacle)
    s2.routing_options["fabrication"] = {"channel_diameter": 0.2, "wall": 0.05}
    shown2 = body_message(s2)["fabrication"]
    assert shown2["channel_diameter"] == 0.2 and shown2["wall"] == 0.05
    assert shown2["fixture_radius"] == shown["fixture_radius"]


def test_route_uses_the_pages_channel_and_reports_its_notes(tentacle):
    from mdsr_opt.synthesis.fabrication import boundary_distance

    s = Session.from_scene(tentacle)
    s.settle()
    d = boundary_distance(tentacle.mesh)
    counts, notes = [], []
    for channel, wall in ((0.1, 0.05), (0.3, 0.08)):
        out = s.route(10.0, 4.0, None, {"channel_diameter": channel, "wall": wall})
        assert out["fabrication"]["channel_diameter"] == channel and out["fabrication"]["wall"] == wall
        assert out["notes"] == list(s.routing.notes)  # what made the ropes buildable, shown on the page
        notes += out["notes"]
        assert min(d[list(m.nodes)].min() for m in s.muscles) >= channel / 2 + wall - 1e-12
        assert out["fixture_radius"] <= out["fabrication"]["fixture_radius"]
        counts.append(len(out["muscles"]))
    assert 1 <= counts[1] < counts[0]  # a wider channel leaves room for fewer ropes
    assert any("fixtures shrunk" in t for t in notes)


@pytest.mark.parametrize("fab, err, words", [
    ({"channel_diameter": -1.0}, ValueError, "channel_diameter must be a finite length >= 0"),
    ({"wall": "abc"}, TypeError, "wall must be a length"),
    ({"wall": True}, TypeError, "wall must be a length"),
    ({"channel": 1.0}, ValueError, "unknown field"),
    ({"fixture_radius": 0.05, "min_fixture_radius": 0.1}, ValueError, "larger than fixture_radius"),
    ({"fixture_radius": 100.0}, ValueError, "half the body"),
    ({"channel_diameter": 5.0}, ValueError, "largest channel_diameter this body admits"),
    ("0.1", TypeError, "object of lengths"),
])
def test_bad_fabrication_fields_are_named_before_routing(tentacle, fab, err, words):
    s = Session.from_scene(tentacle)
    s.settle()
    with pytest.raises(err, match=words):
        s.route(10.0, 4.0, None, fab)
    assert s.routing is None


def test_the_page_colours_each_muscle_as_the_figures_do(tentacle):
    from mdsr_opt.plot.style import muscle_color_of

    s = Session.from_scene(tentacle)
    s.settle()
    out = s.route(10.0, 4.0, None, {"channel_diameter": 0.1})
    assert len(out["muscles"]) >= 2
    for i, (m, shown) in enumerate(zip(s.muscles, out["muscles"])):
        assert shown["name"] == m.name and shown["color"] == muscle_color_of(m, i)
    first = out["muscles"][0]
    after = s.delete_muscle(first["name"])  # the others keep their names, so their colours
    assert {m["name"]: m["color"] for m in after["muscles"]} == {m["name"]: m["color"] for m in out["muscles"][1:]}


def test_deleting_a_muscle_drops_the_design_and_keeps_the_fixtures(tentacle):
    s = Session.from_scene(tentacle)
    s.settle()
    out = s.route(10.0, 4.0, None, {"channel_diameter": 0.1})
    names = [m["name"] for m in out["muscles"]]
    assert len(names) >= 2
    s.run_design()
    out = s.delete_muscle(names[1])
    assert [m["name"] for m in out["muscles"]] == names[:1] + names[2:] and out["deleted"] == [names[1]]
    assert [st["name"] for st in out["stats"]] == names[:1] + names[2:]
    assert s.design is None  # designed again before it is shown or saved
    with pytest.raises(ValueError, match="no muscle 'nope'"):
        s.delete_muscle("nope")
    d = s.run_design()
    assert d["params"]["anchor_radius"] == s.routing.fixture_radius  # the fixtures the ropes were fitted to
    assert d["held"] is False  # a free body's design is shown aligned onto the target
    assert [m["name"] for m in d["layout"]] == names[:1] + names[2:]


def test_saved_fabrication_and_deletion_are_reproduced_by_run_case(tentacle, tmp_path):
    """The scene the page saves after a channel size and a deletion: `mdsr run`'s case runner designs the same
    muscles to the same contractions."""
    from mdsr_opt.scenes.runner import run_case

    s = Session.from_scene(tentacle)
    s.settle()
    fab = {"channel_diameter": 0.1, "wall": 0.07}
    names = [m["name"] for m in s.route(10.0, 4.0, None, fab)["muscles"]]
    s.delete_muscle(names[-1])  # the weakest (routed ropes come strongest first)
    page = s.run_design()
    files = save_scene(s, tmp_path, "fab_deleted")
    data = json.loads(Path(files[0]).read_text())
    assert data["fabrication"] == fab and "fabrication" not in data.get("routing", {})
    assert data["cases"][0]["anchor_radius"] == s.routing.fixture_radius  # curl's own ropes' fixtures
    back = load_scene(files[0])
    assert back.routing_options["fabrication"] == fab
    curl = back.case("curl").muscles
    assert [m.nodes for m in curl] == [m.nodes for m in s.muscles] and len(curl) == len(names) - 1
    run = run_case(back, "curl", photo=False)
    assert run.report.success, run.report.message
    np.testing.assert_allclose(run.report.contractions, page["contractions"], rtol=0, atol=1e-9)
    assert abs(run.report.difference - page["difference"]) <= 1e-9
    assert page["acceptance"] == "" and run.report.success  # the page says what mdsr run will say
    assert back.units == tentacle.units and back.acceptance == s.acceptance  # the scene's unit and [acceptance] kept
    # a stricter [acceptance]: the page names the failure mdsr run reports for the saved scene
    s.acceptance = dict(s.acceptance, max_difference=1e-4)
    strict = s.run_design()
    assert "more than max_difference 0.01 %" in strict["acceptance"]
    run = run_case(load_scene(save_scene(s, tmp_path, "strict")[0]), "curl", photo=False)
    assert not run.report.success and strict["acceptance"] in run.report.message
    # the saved scene loads on the page again with its channel and routes without a conflict of radii
    s2 = Session.from_scene_file(files[0])
    assert s2.fabrication_shown()["channel_diameter"] == 0.1
    s2.settle()
    assert s2.route(10.0, 4.0, None)["fabrication"]["wall"] == 0.07


def test_bad_route_and_delete_messages_get_error_replies_and_the_page_stays_served():
    import asyncio

    from mdsr_opt.author.server import Page

    sent = []

    class FakeSocket:
        async def send_text(self, text):
            sent.append(json.loads(text))

    bad = [{"type": "route", "K_a": 10, "K_b": 4, "fabrication": {"channel_diameter": -0.5}},
           {"type": "route", "K_a": 10, "K_b": 4, "fabrication": {"channel_diameter": "wide"}},
           {"type": "route", "K_a": 10, "K_b": 4, "fabrication": [1, 2]},
           {"type": "delete_muscle", "name": "M9"},
           {"type": "delete_muscle", "name": 3}]

    async def scenario():
        page = Page(FakeSocket(), {"out": "unused", "folders": (), "written": set()})
        page.enqueue({"type": "load", "body": {"kind": "problem", "name": "tentacle", "resolution": "coarse"}})
        worker = asyncio.create_task(page.worker())
        page.enqueue({"type": "route", "K_a": 10, "K_b": 4, "fabrication": {"channel_diameter": 0.1}})
        for m in bad:
            page.enqueue(m)
        page.enqueue({"type": "ping"})
        while not any(m["type"] == "pong" for m in sent):
            await asyncio.sleep(0.01)
        worker.cancel()
        page.tmp.cleanup()

    asyncio.run(asyncio.wait_for(scenario(), timeout=120))
    errors = [m["message"] for m in sent if m["type"] == "error"]
    assert len(errors) == len(bad), errors
    for text, words in zip(errors, ["channel_diameter must be a finite length >= 0", "channel_diameter must be a length",
                                    "object of lengths", "no muscle 'M9'", "muscle name must be a string"]):
        assert words in text
    routed = [m for m in sent if m["type"] == "routing"]
    assert len(routed) == 1 and routed[0]["fabrication"]["channel_diameter"] == 0.1


def _curl(s, turns):
    """Drag the right end of a 10 x 1 strip (left end anchored) through pure bending, ``turns`` (radians)
    at a time; returns the states and the number of solve_external calls they took."""
    import mdsr_opt.author.session as session_module

    P = s.mesh.points
    anc, dn = np.flatnonzero(P[:, 0] < 0.01), np.flatnonzero(P[:, 0] > 9.99)
    E = P[dn] - P[dn].mean(0)
    states, calls = [], 0
    real = {name: getattr(session_module, name) for name in ("solve_external", "target_solve")}
    for th in turns:
        R = 10.0 / th
        rot = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
        s.set_fixed(anc, dn, E @ rot.T + [R * np.sin(th), R - R * np.cos(th)])

        def counting(fn):
            def counted(*a, **k):
                nonlocal calls
                calls += 1
                return fn(*a, **k)
            return counted

        for name, fn in real.items():  # the warm solve and the exact one (a drag that falls back to it)
            setattr(session_module, name, counting(fn))
        try:
            states.append(s.drag())
        finally:
            for name, fn in real.items():
                setattr(session_module, name, fn)
    return states, calls


def test_a_live_drag_into_a_crossing_is_shown_at_once_and_the_drag_goes_on():
    """A preview that converges to a state whose boundary crosses itself is shown as the failed state it is
    (crossing named, no solve_external call), and the next drags go on from it, back to success."""
    s = Session.from_outline([[0, 0], [10, 0], [10, 1], [0, 1]], resolution=150)
    P = s.mesh.points
    s.set_fixed(np.flatnonzero(P[:, 0] < 0.01), np.flatnonzero(P[:, 0] > 9.99), P[P[:, 0] > 9.99])
    assert s.settle().success
    up, _ = _curl(s, np.radians(np.arange(7, 343, 7)))  # curled almost into a ring: no crossing yet
    assert all(st.success and st.live for st in up)
    over, calls = _curl(s, np.radians(np.arange(350, 400, 7)))  # the free end passes over the anchored one
    crossing = [st for st in over if st.crossing]
    assert crossing and calls == 0
    assert all(st.live and not st.success and not st.warm_failed and "crosses itself" in st.status
               for st in crossing)
    back, calls = _curl(s, np.radians(np.arange(393, 40, -7)))  # and back out of the crossing
    assert back[-1].success and back[-1].live and not back[-1].crossing and calls == 0
    settled = s.settle()  # the release: solve_external's equilibrium, bit for bit
    ref = solve_external(s.mesh, s.material, s.anchors, (s.drag_nodes, s.drag_positions))
    assert settled.success and np.array_equal(settled.x, ref.x)


def test_a_paused_drag_is_solved_exactly_before_its_release(monkeypatch):
    """While a drag waits for the next move, the server solves its exact equilibrium; the release then
    answers with that result (no new solve), bit for bit solve_external's. A move during that solve stops
    it, and the next release is exact too."""
    import asyncio

    import mdsr_opt.author.session as session_module
    from mdsr_opt.author.server import SPECULATE_AFTER, Page

    sent, solved = [], []
    real = session_module.solve_external
    exact = session_module.target_solve

    def counted(session):  # the exact solve (the live fallback calls solve_external with an initial guess)
        out = exact(session)
        solved.append(np.asarray(session.drag_positions).copy())
        return out

    monkeypatch.setattr(session_module, "target_solve", counted)

    class FakeSocket:
        async def send_text(self, text):
            sent.append(json.loads(text))

    async def reply(seq):
        while not any(m["type"] == "state" and m.get("seq") == seq for m in sent):
            await asyncio.sleep(0.005)
        return next(m for m in sent if m["type"] == "state" and m.get("seq") == seq)

    async def scenario():
        page = Page(FakeSocket(), {"out": "unused", "folders": (), "written": set()})
        page.enqueue({"type": "load", "body": {"kind": "problem", "name": "tentacle", "resolution": "coarse"}})
        worker = asyncio.create_task(page.worker())
        start = await reply(None)
        base = np.array(start["drag_positions"])
        fixed = {"anchors": start["anchors"], "drag_nodes": start["drag_nodes"]}
        out = {}
        p1 = (base + [0.3, -0.2]).tolist()
        page.enqueue(dict(fixed, type="drag", seq=1, drag_positions=p1))
        out["drag"] = await reply(1)
        for _ in range(2000):  # the pause: the exact solve of p1 runs and ends
            if any(np.array_equal(d, p1) for d in solved):
                break
            await asyncio.sleep(0.01)
        out["paused_solve"] = any(np.array_equal(d, p1) for d in solved)
        n = len(solved)
        page.enqueue(dict(fixed, type="fixed", seq=2, drag_positions=p1))
        out["release"], out["new_solves"] = await reply(2), len(solved) - n
        # a move stops the exact solve of the paused drag: the next drag and release are answered
        p3, p4 = (base + [0.5, -0.3]).tolist(), (base + [0.6, -0.2]).tolist()
        page.enqueue(dict(fixed, type="drag", seq=3, drag_positions=p3))
        await reply(3)
        await asyncio.sleep(SPECULATE_AFTER + 0.01)
        page.enqueue(dict(fixed, type="drag", seq=4, drag_positions=p4))
        out["moved"] = await reply(4)
        page.enqueue(dict(fixed, type="fixed", seq=5, drag_positions=p4))
        out["release2"] = await reply(5)
        worker.cancel()
        page.tmp.cleanup()
        return out

    out = asyncio.run(asyncio.wait_for(scenario(), timeout=300))
    assert out["drag"]["live"] and out["drag"]["success"]
    assert out["paused_solve"]  # the pause solved p1 exactly (the count sees the exact solves)
    assert out["new_solves"] == 0 and out["release"]["success"] and not out["release"]["live"]
    tent = get_problem("tentacle", resolution="coarse")
    for key, seq in (("release", 2), ("release2", 5)):
        st = out[key]
        ref = real(tent.mesh, tent.material, st["anchors"], (st["drag_nodes"], st["drag_positions"]))
        assert np.array_equal(np.asarray(st["x"]), ref.x), key  # exactly mdsr run's equilibrium
        assert st["settled"] and st["seq"] == seq
    assert out["moved"]["live"] and out["moved"]["success"]
    assert not [m for m in sent if m["type"] == "error"]


@pytest.mark.parametrize("source", ["library", "scene file", "mesh file"])
def test_saved_scenes_and_bundles_hold_no_machine_paths(tmp_path, source):
    """The scene file, its mesh and the downloaded bundle name the source by its file name only: no folder of
    this machine (the source's, the output's, the package's) in any byte."""
    import io
    import zipfile

    import mdsr_opt
    from mdsr_opt import write_mesh

    src = tmp_path / "my_lab" / "bodies"
    src.mkdir(parents=True)
    if source == "library":
        s = Session.from_problem("tentacle", "coarse")
    else:
        body = {"outline": [[0, 0], [4, 0], [4, 1], [0, 1]], "resolution": 80}
        if source == "mesh file":
            write_mesh(src / "strip.vtu", Session.from_outline(body["outline"], resolution=80).mesh)
            body = {"mesh": "strip.vtu"}
        (src / "strip.json").write_text(json.dumps({"name": "strip", "body": body, "regions": {
            "base": {"box": [-1, -1, 0.1, 2]}, "tip": {"box": [3.9, -1, 5, 2]}}, "cases": [
            {"name": "up", "anchors": "base", "drags": [{"nodes": "tip", "by": [0, 0.5]}]}]}))
        s = Session.from_scene_file(src / "strip.json")
    assert s.settle().success
    out = tmp_path / "saved here"
    files = save_scene(s, out, "mine")
    data, _ = download(s, "scene.zip", tmp_path)
    bundle = zipfile.ZipFile(io.BytesIO(data))
    blobs = [Path(f).read_bytes() for f in files] + [bundle.read(n) for n in bundle.namelist()]
    folders = {str(tmp_path), str(Path(mdsr_opt.__file__).parent.parent), str(Path.home()), "my_lab"}
    assert not [f for f in folders for b in blobs if f.encode() in b]
    scene = json.loads(Path(files[0]).read_text())
    assert scene["body"] == {"mesh": "mine.mesh.vtu"}
    assert scene["description"].endswith(("tentacle.py.", "strip.json.")), scene["description"]


@pytest.mark.parametrize("suffix", [".json", ".toml"])
def test_a_scene_file_the_page_opens_is_read_once_by_the_scene_reader(tmp_path, monkeypatch, suffix):
    """Opening a scene file by path (the page's check of its mesh file included) reads it once, through the
    scene reader, whose size limit then holds for the page too."""
    import mdsr_opt.scenes.reader as reader

    scene = tmp_path / f"strip{suffix}"
    if suffix == ".json":
        scene.write_text(json.dumps({"name": "strip", "body": {"outline": [[0, 0], [4, 0], [4, 1], [0, 1]],
                                                               "resolution": 60},
                                     "cases": [{"name": "up", "anchors": [[0, 0], [0, 1]],
                                                "drags": [{"at": [4, 1], "by": [0, 0.5]}]}]}))
    else:
        scene.write_text('name = "strip"\n[body]\noutline = [[0, 0], [4, 0], [4, 1], [0, 1]]\nresolution = 60\n'
                         '[[cases]]\nname = "up"\nanchors = [[0, 0], [0, 1]]\ndrags = [{ at = [4, 1], by = [0, 0.5] }]\n')
    reads = []
    for method in ("read_bytes", "read_text"):
        real = getattr(Path, method)

        def counted(self, *a, _real=real, _name=method, **k):
            if self.name == scene.name:
                reads.append(_name)
            return _real(self, *a, **k)

        monkeypatch.setattr(Path, method, counted)
    s = load_body({"kind": "path", "path": str(scene)}, (tmp_path.resolve(),))
    assert s.name == "strip" and len(s.drag_nodes) == 1
    assert reads == ["read_bytes"]  # read_file's one read
    monkeypatch.setattr(reader, "MAX_BYTES", 100)
    with pytest.raises(ValueError, match=r"strip\.(json|toml): the scene file is 0\.0 MB, more than"):
        load_body({"kind": "path", "path": str(scene)}, (tmp_path.resolve(),))


def test_a_warm_solve_that_ends_crossing_is_shown_without_a_cold_solve(monkeypatch):
    """When the preview cannot follow a drag, the warm solve_external takes over; a state it converges to
    whose boundary crosses itself is shown (failed, crossing named) after that one solve, and the next drag
    starts from it: one solve per drag, never the cold fallback."""
    s = Session.from_outline([[0, 0], [10, 0], [10, 1], [0, 1]], resolution=150)
    P = s.mesh.points
    s.set_fixed(np.flatnonzero(P[:, 0] < 0.01), np.flatnonzero(P[:, 0] > 9.99), P[P[:, 0] > 9.99])
    assert s.settle().success
    _curl(s, np.radians(np.arange(7, 343, 7)))
    monkeypatch.setattr(Session, "_preview", lambda self, y, t0: None)  # the warm solve_external alone
    over, calls = _curl(s, np.radians(np.arange(350, 380, 7)))
    assert calls == len(over) and not any(st.warm_failed for st in over)
    assert over[-1].crossing and over[-1].live and not over[-1].success and "crosses itself" in over[-1].status


def test_route_with_the_shown_knobs_lays_what_mdsr_run_lays():
    # gecko bend_left: mdsr run routes with route_for_design, which routes deeper inside when ropes are lost to
    # their fixtures (2 ropes; a plain route_muscles lays 1); the page's Route with the knobs it shows does too
    from mdsr_opt.author.server import body_message
    from mdsr_opt.author.session import routing_defaults
    from mdsr_opt.scenes.cases import prepare_case

    scene = get_problem("gecko", resolution="coarse")
    s = Session.from_scene(scene, case="bend_left")
    knobs = body_message(s)["routing"]
    given = {k: scene.routing_options[k] for k in ("K_a", "K_b", "max_muscles") if k in scene.routing_options}
    assert knobs == dict(routing_defaults(), **given)  # the scene's knobs, else route_muscles' own defaults
    assert Session.from_outline([[0, 0], [4, 0], [4, 1], [0, 1]], resolution=200).routing_options == {}
    assert body_message(Session.from_outline([[0, 0], [4, 0], [4, 1], [0, 1]], resolution=200))["routing"] == \
        {"K_a": 4.0, "K_b": 4.0, "max_muscles": None} == routing_defaults()
    s.settle()
    out = s.route(knobs["K_a"], knobs["K_b"], knobs["max_muscles"])
    ran = prepare_case(scene, "bend_left").routing
    assert [m.nodes for m in s.muscles] == [m.nodes for m in ran.muscles] and len(ran.muscles) == 2
    assert out["fixture_radius"] == ran.fixture_radius
    # a knob the page changes is routed as given
    assert s.route(1.0, knobs["K_b"], None)["params"]["K_a"] == 1.0
