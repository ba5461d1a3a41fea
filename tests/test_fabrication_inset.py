"""A slender body and the ropes' least inset (trial 10, defects 1 and 2).

A tentacle 100 mm long, 4 mm thick at the base and 1 mm at the tip, with a 1 mm channel and a 0.5 mm wall, has
room for a rope (1 mm of material each side) but not for the 2 % of its diameter (2 mm) the routing kept as a
fixed floor: routing it was a ``ValueError`` that ``mdsr run`` called "a bug in mdsr_opt" and that aborted the
run, and the message blamed the mesh. Now the floor is ``Fabrication.min_inset_fraction`` (default 0.02), a
body or mesh that holds no rope is a :class:`~mdsr_opt.core.errors.LayoutError` (one failed case in ``mdsr
run``), and the message names the real cause with values that work. Insets are checked with shapely on the
polygon the body was meshed from, not with the library's own distances.
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
import shapely
from shapely.geometry import LineString, Point, Polygon

from mdsr_opt import Fabrication, Mesh, NeoHookean, load_scene, mesh_polygon, nodes_in_box, solve_external
from mdsr_opt.cli.main import main
from mdsr_opt.core.errors import LayoutError
from mdsr_opt.mechanics.anchors import body_size
from mdsr_opt.synthesis.fabrication import MIN_INSET_FRACTION
from mdsr_opt.synthesis.routing import RoutingWarning, route_for_design, route_muscles

OUTLINE = [[0.0, 0.0], [100.0, 1.5], [100.0, 2.5], [0.0, 4.0]]  # mm: 4 thick at the base, 1 at the tip
SIZES = {"channel_diameter": 1.0, "wall": 0.5, "fixture_radius": 1.0, "min_fixture_radius": 0.8}

SCENE = """name = "slender"
units = "mm"
[body]
outline = [[0, 0], [100, 1.5], [100, 2.5], [0, 4]]
resolution = 150
[regions]
base = { box = [-1, -1, 0, 5] }
tip = { box = [99.9, 0, 101, 3] }
[fabrication]
channel_diameter = 1.0
wall = 0.5
fixture_radius = 1.0
min_fixture_radius = 0.8
%s
[[cases]]
name = "curl"
anchors = "base"
drags = [{ nodes = "tip", rotate = 35, about = [100, 2], by = [-15, 30] }]
[[cases]]
name = "given"
anchors = "base"
drags = [{ nodes = "tip", by = [-5, 10] }]
muscles = [{ name = "m", path = [[5, 2.8], [60, 2.3]] }]
"""


def _tentacle(resolution: int):
    """The tentacle meshed at ``resolution``, and its tip turned by 0.6 rad about (100, 2) and moved by (-15, 30)
    (the trial's curl), solved with the base clamped."""
    mesh = mesh_polygon(OUTLINE, resolution=resolution)
    P = mesh.points
    c, s = np.cos(0.6), np.sin(0.6)
    tip = np.flatnonzero(P[:, 0] > 100 - 1e-9)
    d = P[tip] - [100.0, 2.0]
    drags = {int(i): [100 + c * x - s * y - 15, 2 + s * x + c * y + 30] for i, (x, y) in zip(tip, d)}
    res = solve_external(mesh, NeoHookean(E=1.0, nu=0.3), nodes_in_box(mesh, xmax=0.0), drags)
    assert res.success
    return mesh, res.x


@pytest.fixture(scope="module")
def tentacle():
    return _tentacle(600)


@pytest.mark.parametrize("serial", [True, False], ids=["serial", "pool"])
def test_mdsr_run_fails_the_routed_case_of_a_body_too_thin_and_runs_the_others(tmp_path, capsys, serial):
    scene = tmp_path / "slender.toml"
    scene.write_text(SCENE % "")
    out = tmp_path / "out"
    code = main(["run", str(scene), "--out", str(out), "--no-animations", "--no-prototype", "--no-photos",
                 *(["--serial"] if serial else [])])
    text = capsys.readouterr()
    assert code == 1, text.err
    assert "internal error" not in text.err and "bug in mdsr_opt" not in text.err
    summary = json.loads((out / "summary.json").read_text())
    cases = {c["case"]: c for c in summary["cases"]}
    assert set(cases) == {"curl", "given"}
    curl = cases["curl"]
    assert not curl["success"] and curl["target_success"]
    assert curl["message"].startswith("routing failed: the body is too thin for the inset min_inset_fraction asks")
    assert "no finer mesh helps" in curl["message"] and "too coarse" not in curl["message"]
    assert "min_inset_fraction at most 0.0" in curl["message"]
    assert cases["given"]["success"] and cases["given"]["n_muscles"] == 1
    # its diagnostic routing could not be made either: said in its notes, not only stored in the setup
    assert any(n.startswith("routing (a diagnostic beside the given muscles) not made: the body is too thin")
               for n in cases["given"]["notes"])
    table = (out / "summary.md").read_text()
    assert "| FAILED (routing failed: the body is too thin for the inset min_inset_fraction asks) |" in table
    assert "FAILED slender/curl: routing failed: the body is too thin" in text.out


def test_the_message_names_a_min_inset_fraction_that_works_and_the_body_routes_with_it(tentacle):
    mesh, target = tentacle
    D = body_size(mesh)
    with pytest.raises(LayoutError) as exc:
        route_for_design(mesh, target, fabrication=Fabrication(**SIZES))
    msg = str(exc.value)
    assert isinstance(exc.value, ValueError)  # Python callers still get a ValueError
    assert msg.startswith("the body is too thin for the inset min_inset_fraction asks: every rope node must lie "
                          f"at least {MIN_INSET_FRACTION * D:.4g} inside")
    assert "no finer mesh helps" in msg and "mesh is too coarse" not in msg
    # the body's depth, checked with shapely's largest inscribed circle on the polygon it was meshed from
    depth = shapely.maximum_inscribed_circle(Polygon(OUTLINE), 1e-4).length
    said = float(msg.split("the body is only ")[1].split()[0])
    assert depth < MIN_INSET_FRACTION * D and said == pytest.approx(depth, rel=0.01)
    # the deepest edge it quotes, checked with shapely: each mesh edge's distance from the outline
    P, edge = mesh.points, Polygon(OUTLINE).exterior
    deepest = max(edge.distance(LineString(P[list(e)])) for e in mesh.edges)
    assert float(msg.split("its deepest edge lies ")[1].split()[0]) == pytest.approx(deepest, rel=1e-3)
    quoted = float(msg.split("min_inset_fraction at most ")[1].split()[0].rstrip(";,"))
    assert quoted * D <= deepest < (quoted + 1e-4) * D  # the largest fraction (to 3 digits) this mesh holds
    assert 0.5 * SIZES["channel_diameter"] + SIZES["wall"] < quoted * D < depth
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RoutingWarning)
        route_muscles(mesh, target, fabrication=Fabrication(**SIZES, min_inset_fraction=quoted))  # no LayoutError


@pytest.mark.parametrize("fraction", [0.005, 0.0])
def test_a_slender_body_routes_with_a_smaller_min_inset_fraction_every_rope_node_that_far_inside(tentacle, fraction):
    mesh, target = tentacle
    fab = Fabrication(**SIZES, min_inset_fraction=fraction)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RoutingWarning)
        rr = route_for_design(mesh, target, fabrication=fab)
    assert len(rr) >= 1
    assert rr.fabrication.min_inset_fraction == fraction
    need = max(0.5 * SIZES["channel_diameter"] + SIZES["wall"], fraction * body_size(mesh))
    edge = Polygon(OUTLINE).exterior
    P = mesh.points
    for m in rr:
        nodes = list(m.nodes)
        inset = min(edge.distance(Point(P[k])) for k in nodes)
        assert inset >= need - 1e-9, (m.name, inset, need)
        assert edge.distance(LineString(P[nodes])) >= need - 1e-9  # the segments between the nodes too


def test_the_2_percent_floor_stays_the_default():
    mesh = Mesh.rectangle(100.0, 60.0, 20, 12)
    D = body_size(mesh)
    assert Fabrication().min_inset_fraction is None
    assert Fabrication().for_body(mesh).min_inset_fraction == MIN_INSET_FRACTION == 0.02
    assert Fabrication(channel_diameter=0.2, wall=0.2).clearance(mesh) == pytest.approx(0.02 * D)
    assert Fabrication(channel_diameter=0.2, wall=0.2, min_inset_fraction=0.0).clearance(mesh) == pytest.approx(0.3)
    assert Fabrication(min_inset_fraction=0.03).to_dict()["min_inset_fraction"] == 0.03


@pytest.mark.parametrize("value, error, words", [
    (0.5, ValueError, "min_inset_fraction must be below 0.5"),
    (0.9, ValueError, "min_inset_fraction must be below 0.5"),
    (-0.01, ValueError, "min_inset_fraction must be a finite fraction >= 0"),
    (float("nan"), ValueError, "min_inset_fraction must be a finite fraction >= 0"),
    (True, TypeError, "min_inset_fraction must be a fraction"),
    ("0.01", TypeError, "min_inset_fraction must be a fraction"),
])
def test_a_bad_min_inset_fraction_is_refused_at_the_door(value, error, words):
    with pytest.raises(error, match=words):
        Fabrication(min_inset_fraction=value)


@pytest.mark.parametrize("value, words", [("0.5", "below 0.5"), ("-0.1", ">= 0"), ('"small"', "expected a number")])
def test_a_bad_min_inset_fraction_in_a_scene_file_is_exit_2_with_nothing_run(tmp_path, capsys, value, words):
    scene = tmp_path / "slender.toml"
    scene.write_text(SCENE % f"min_inset_fraction = {value}")
    with pytest.raises((ValueError, TypeError), match="min_inset_fraction") as exc:
        load_scene(scene)
    assert words in str(exc.value)
    out = tmp_path / "out"
    assert main(["run", str(scene), "--out", str(out), "--serial", "--no-photos", "--no-figures"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "min_inset_fraction" in err and not out.exists()


def test_a_scene_file_sets_min_inset_fraction_and_the_routed_case_gets_ropes(tmp_path, capsys):
    scene = tmp_path / "slender.toml"
    scene.write_text(SCENE % "min_inset_fraction = 0.005")
    sc = load_scene(scene)
    assert sc.routing_options["fabrication"]["min_inset_fraction"] == 0.005
    out = tmp_path / "out"
    main(["run", str(scene), "--out", str(out), "--case", "curl", "--serial", "--no-photos", "--no-figures",
          "--no-animations", "--no-prototype"])
    curl = json.loads((out / "summary.json").read_text())["cases"][0]
    assert curl["n_muscles"] >= 1 and not curl["message"].startswith("routing")


def test_the_author_page_takes_and_checks_min_inset_fraction():
    from mdsr_opt.author.server import load_body

    s = load_body({"kind": "outline", "outline": OUTLINE, "resolution": 150})
    assert s.fabrication_shown()["min_inset_fraction"] == MIN_INSET_FRACTION
    assert s.check_fabrication_fields({"min_inset_fraction": 0.005}) == {"min_inset_fraction": 0.005}
    with pytest.raises(ValueError, match="min_inset_fraction must be below 0.5"):
        s.check_fabrication_fields({"min_inset_fraction": 0.5})
    with pytest.raises(ValueError, match="min_inset_fraction must be a finite fraction >= 0"):
        s.check_fabrication_fields({"min_inset_fraction": -1})


def test_a_mesh_too_coarse_for_a_deep_enough_body_is_told_a_finer_mesh_and_the_fraction_that_fits_here():
    mesh = Mesh.rectangle(100.0, 10.0, 16, 3)  # 5 deep; the rows at 3.33: the deepest edge 3.33 inside
    target = mesh.points * [0.8, 1.0]
    fab = Fabrication(channel_diameter=1.0, wall=0.5, min_inset_fraction=0.04)  # 4 % of 100.5: 4.02 > 3.33
    with pytest.raises(LayoutError) as exc:
        route_muscles(mesh, target, fabrication=fab)
    msg = str(exc.value)
    assert msg.startswith("the mesh is too coarse to hold a rope at its inset")
    assert "Would work: a finer mesh, mean edge length at most 0.49" in msg  # (5 - 4.02) / 2
    assert "min_inset_fraction at most 0.0331" in msg  # 3.333 / 100.5, rounded down
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RoutingWarning)
        route_muscles(mesh, target, fabrication=Fabrication(channel_diameter=1.0, wall=0.5, min_inset_fraction=0.0331))
        fine = Mesh.rectangle(100.0, 10.0, 250, 26)
        assert fine.edge_lengths.mean() <= 0.49
        route_muscles(fine, fine.points * [0.8, 1.0], fabrication=fab)


def test_a_layout_the_body_cannot_hold_is_a_layout_error_from_routing():
    strip = Mesh.rectangle(4.0, 1.0, 16, 4)
    with pytest.raises(LayoutError, match="does not fit in the body"):
        route_muscles(strip, strip.points * [0.8, 1.0], fabrication=Fabrication(channel_diameter=0.8, wall=0.2))
    with pytest.raises(LayoutError, match="at least half the body's size"):
        route_muscles(strip, strip.points * [0.8, 1.0], fabrication=Fabrication(fixture_radius=3.0))
    bent = strip.points.copy()
    bent[:, 0] *= np.where(strip.points[:, 1] > 0.5, 0.8, 1.0)  # only the upper half shortens: no mirror image
    with pytest.raises(LayoutError, match="symmetry=True but"):
        route_muscles(strip, bent, symmetry=True, fabrication=False)


def test_a_deeper_fallback_the_body_cannot_hold_leaves_the_routing_before_it():
    """route_for_design routes again deeper inside (the smallest fixture plus its wall) when ropes lost their
    fixtures; on a mesh with no edge that deep that second routing has no band: the first one's answer (every
    rope dropped for its fixtures, said in a RoutingWarning) stands, not a LayoutError."""
    strip = Mesh.rectangle(4.0, 1.0, 32, 5)  # rows at 0.2 and 0.4: no node 0.49 inside
    fab = Fabrication(fixture_radius=0.45, min_fixture_radius=0.45, wall=0.04)
    with pytest.warns(RoutingWarning, match="no routed rope keeps room for its end fixtures"):
        rr = route_for_design(strip, strip.points * [0.8, 1.0], fabrication=fab)
    assert len(rr) == 0


def test_the_coarse_strip_is_told_that_a_finer_mesh_gives_its_contracted_edges_room(tmp_path):
    """Trial 10's b12: a 41-node 4 x 1 strip, channel 0.3 and wall 0.2 (0.35 inside): its contracted edges
    lie outside the band, and the message now says a finer mesh gives them edges inside it; that mesh does."""
    from mdsr_opt.scenes.cases import prepare_case

    text = ('name = "b12"\n[body]\noutline = [[0, 0], [4, 0], [4, 1], [0, 1]]\nresolution = %d\n'
            '[regions]\nbase = { box = [-1, -1, 0, 2] }\ntip = { box = [3.9, -1, 5, 2] }\n'
            '[fabrication]\nchannel_diameter = 0.3\nwall = 0.2\n'
            '[[cases]]\nname = "c"\nanchors = "base"\ndrags = [{ nodes = "tip", rotate = 40, about = [0, 0.5] }]\n')
    f = tmp_path / "b12.toml"
    f.write_text(text % 40)
    setup = prepare_case(load_scene(f), "c")
    assert not setup.muscles
    why = "; ".join(setup.warnings)
    assert "lie outside the buildable band" in why
    assert "reach within an edge of the band: a finer mesh (mean edge length at most 0.075, now 0.4" in why
    assert "gives them edges inside it" in why  # (0.5 - 0.35) / 2: the strip is 0.5 deep, the band 0.35 inside
    fine = load_scene(f, resolution=1500).mesh
    assert fine.edge_lengths.mean() <= 0.075
    f.write_text(text % 1500)
    assert len(prepare_case(load_scene(f), "c").muscles) >= 1
