"""Trial 3 defects at the doors (2, 3, 5, 8): a channel wider than the body refused at load, routing's failure
message naming the filter that removed the contracted edges, the virtual prototype's fixtures those of the
design, and a scene's muscle on the outline warned about under ``mdsr run`` as in the Python API."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from mdsr_opt import Mesh, NeoHookean
from mdsr_opt.cli.main import main
from mdsr_opt.scenes.scenefile import load_scene
from mdsr_opt.synthesis.fabrication import Fabrication, check_channel_fits

QUIET_RUN = ("--serial", "--no-photos", "--no-figures", "--no-animations", "--no-prototype")

BODY = """name = "b"
units = "{units}"
[body]
outline = [[0, 0], [{L}, 0], [{L}, {H}], [0, {H}]]
resolution = "coarse"
[regions]
base = {{ box = [{m}, {m}, {e}, {h1}] }}
tip = {{ box = [{l0}, {m}, {l1}, {h1}] }}
"""
BEND = """[[cases]]
name = "bend"
anchors = "base"
drags = [{{ nodes = "tip", by = [{dx}, {dy}] }}]
"""


def _scene_text(s: float, units: str = "mm", extra: str = "") -> str:
    """A 40 x 10 strip (times ``s``) bent by its tip, with ``extra`` tables."""
    return (BODY.format(units=units, L=40 * s, H=10 * s, m=-s, e=0.5 * s, h1=11 * s, l0=39.5 * s, l1=41 * s)
            + extra + BEND.format(dx=-5 * s, dy=15 * s))


def _strip(s: float = 1.0) -> tuple[Mesh, list, dict]:
    mesh = Mesh.rectangle(40.0 * s, 10.0 * s, 16, 4)
    P = mesh.points
    anchors = [i for i, (x, y) in enumerate(P) if x == 0.0]
    drags = {i: (x - 5 * s, y + 15 * s) for i, (x, y) in enumerate(P) if x == 40.0 * s}
    return mesh, anchors, drags


# ---------------------------------------------------------------------------------------------- 2: channel > body
@pytest.mark.parametrize("s, units", [(1.0, "mm"), (0.001, "m")])
def test_a_channel_wider_than_the_body_is_refused_when_the_scene_loads(tmp_path, s, units):
    f = tmp_path / "huge.toml"
    f.write_text(_scene_text(s, units, f"[fabrication]\nchannel_diameter = {30 * s}\n"))
    with pytest.raises(ValueError) as e:
        load_scene(f)
    msg = str(e.value)
    assert f"channel_diameter {30 * s:.4g} with a wall" in msg and "does not fit in the body" in msg
    # the largest channel the body admits: 2 (depth - wall), the depth of a 40 x 10 strip being 5
    wall = 0.01 * np.hypot(40, 10) * s
    assert f"admits with this wall is {2 * (5 * s - wall):.4g}" in msg
    assert "too coarse" not in msg


def test_mdsr_run_refuses_a_channel_wider_than_the_body_in_one_line_with_nothing_written(tmp_path, capsys):
    f = tmp_path / "huge.toml"
    f.write_text(_scene_text(1.0, "mm", "[fabrication]\nchannel_diameter = 30\n"))
    out = tmp_path / "o"
    assert main(["run", str(f), "--out", str(out), *QUIET_RUN]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err and "bug" not in err, err
    assert "channel_diameter 30" in err and "does not fit in the body" in err
    assert not out.exists()


def test_a_wall_alone_deeper_than_a_holed_body_is_refused_naming_it():
    """The depth is the body's largest inscribed circle: a ring 2 thick is 1 deep whatever its size."""
    t = np.linspace(0, 2 * np.pi, 48, endpoint=False)
    ring = np.column_stack([np.cos(t), np.sin(t)])
    from mdsr_opt.scenes.scene import mesh_polygon

    mesh = mesh_polygon(30 * ring, [28 * ring[::-1]], "coarse")
    with pytest.raises(ValueError, match=r"channel_diameter 0\.5 with a wall 1\.2 .* only 0\.99\d* deep .* no channel "
                                         r"fits with this wall: the wall must be below 0\.99"):
        check_channel_fits(mesh, {"channel_diameter": 0.5, "wall": 1.2})
    check_channel_fits(mesh, {"channel_diameter": 0.5, "wall": 0.5})  # 0.75 <= 1: fits


def test_design_pipeline_refuses_the_channel_before_the_external_solve(monkeypatch):
    mesh, anchors, drags = _strip()

    def no_solve(*a, **k):
        raise AssertionError("the external solve ran before the channel was checked")

    monkeypatch.setattr("mdsr_opt.synthesis.pipeline._target", no_solve)
    monkeypatch.setattr("mdsr_opt.mechanics.equilibrium.solve_external", no_solve)
    from mdsr_opt.synthesis.pipeline import design_pipeline

    with pytest.raises(ValueError, match=r"channel_diameter 30 with a wall .* does not fit in the body"):
        design_pipeline(mesh, NeoHookean(1.0, 0.3), anchors, drags, fabrication=Fabrication(channel_diameter=30.0))


def test_route_muscles_and_design_poses_refuse_the_channel_at_the_door():
    from mdsr_opt.synthesis.poses import design_poses
    from mdsr_opt.synthesis.routing import route_muscles

    mesh, _, _ = _strip()
    target = mesh.points * [0.8, 1.0]
    with pytest.raises(ValueError, match="does not fit in the body"):
        route_muscles(mesh, target, fabrication={"channel_diameter": 12.0, "wall": 0.0})
    with pytest.raises(ValueError, match="does not fit in the body"):
        design_poses(mesh, NeoHookean(1.0, 0.3), {"a": target}, routing_options={"fabrication": {"wall": 5.5}})


def test_a_body_wide_enough_on_a_coarse_mesh_still_says_the_mesh_is_too_coarse():
    from mdsr_opt.synthesis.routing import route_muscles

    mesh = Mesh.rectangle(40.0, 10.0, 16, 3)  # 5 deep, but no node deeper than 3.33
    check_channel_fits(mesh, {"channel_diameter": 7.0, "wall": 1.0})  # 4.5 <= 5: fits the body
    with pytest.raises(ValueError, match="the mesh is too coarse"):
        route_muscles(mesh, mesh.points * [0.8, 1.0], fabrication={"channel_diameter": 7.0, "wall": 1.0})


def test_given_muscles_are_checked_against_stated_sizes_only():
    """Muscles the user lays are designed as given: the default channel (a fraction of the diameter) does not
    refuse a body thinner than it, a stated one does; the routing checks both."""
    mesh = Mesh.rectangle(100.0, 1.0, 100, 2)  # 0.5 deep; the default channel / 2 + wall is 1.5
    check_channel_fits(mesh, None, routed=False)
    with pytest.raises(ValueError, match="channel_diameter the default 1%"):
        check_channel_fits(mesh, None)
    with pytest.raises(ValueError, match="does not fit"):
        check_channel_fits(mesh, {"channel_diameter": 2.0}, routed=False)


# ---------------------------------------------------------------------------------------------- 3: why no seed
TEE = """name = "tee"
units = "mm"
[body]
outline = [[30, 0], [50, 0], [50, 60], [80, 60], [80, 80], [0, 80], [0, 60], [30, 60]]
holes = [[[45.000, 25.000], [44.619, 26.913], [43.536, 28.536], [41.913, 29.619], [40.000, 30.000],
          [38.087, 29.619], [36.464, 28.536], [35.381, 26.913], [35.000, 25.000], [35.381, 23.087],
          [36.464, 21.464], [38.087, 20.381], [40.000, 20.000], [41.913, 20.381], [43.536, 21.464],
          [44.619, 23.087]]]
resolution = "coarse"
[material]
silicone = "dragon-skin-30"
thickness = 5
[regions]
foot = { box = [29, -1, 51, 50] }
left = { box = [-1, 59, 0.5, 81] }
[routing]
max_muscles = 4
[[cases]]
name = "left_up"
anchors = "foot"
drags = [{ nodes = "left", rotate = -35, about = [30, 70] }]
"""


@pytest.fixture(scope="module")
def tee_left_up(tmp_path_factory):
    from mdsr_opt.mechanics.equilibrium import solve_external

    f = tmp_path_factory.mktemp("tee") / "tee.toml"
    f.write_text(TEE)
    scene = load_scene(f)
    case = scene.case("left_up")
    res = solve_external(scene.mesh, scene.material, case.anchors, case.drags)
    assert res.success
    return scene, res.x


def _route_warning(mesh, x, **kw) -> tuple:
    from mdsr_opt.synthesis.routing import RoutingWarning, route_muscles

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        rr = route_muscles(mesh, x, **kw)
    return rr, [str(w.message) for w in caught if issubclass(w.category, RoutingWarning)]


def test_no_seed_names_the_compression_filter_and_a_ratio_that_routes(tee_left_up):
    """The trial's T: left_up contracts 8 edges by more than 5 %, all on the outline; the 11 strong edges inside
    the band are all removed by compression_ratio=1. The message says so and the ratio it suggests routes."""
    scene, x = tee_left_up
    rr, msgs = _route_warning(scene.mesh, x, max_muscles=4)
    assert len(rr) == 0 and len(msgs) == 1
    msg = msgs[0]
    assert "does the target shorten any edge" not in msg
    assert "8 by more than 5 %" in msg
    assert "lie outside the buildable band" in msg and "8 of those contracting by more than 5 %" in msg
    assert "the compression_ratio filter (1) removed all 11 of the 11" in msg
    import re

    ratio = float(re.search(r"try compression_ratio=([0-9.]+)", msg).group(1))
    assert 0.5 <= ratio < 1.0
    from mdsr_opt.synthesis.routing import route_for_design

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert len(route_for_design(scene.mesh, x, max_muscles=4, compression_ratio=ratio)) >= 1


def test_no_seed_on_a_poisson_response_names_the_compression_filter():
    """Another body and target: a strip pulled along its length narrows across it; the narrowing edges contract,
    but only as the sideways response of the stretch, which the compression filter removes."""
    mesh = Mesh.rectangle(4.0, 1.0, 16, 8)
    x = mesh.points * [1.2, 0.94] + [0.0, 0.03]
    rr, msgs = _route_warning(mesh, x, fabrication=False)
    assert len(rr) == 0 and len(msgs) == 1
    assert "the compression_ratio filter (1) removed all" in msgs[0]
    # 6 % across, 20 % along: a ratio below 0.3 keeps them (on the grid of 0.05)
    assert "try compression_ratio=0.25 or lower (it keeps 136 of them)" in msgs[0]


def test_design_pipeline_says_why_routing_found_no_muscle():
    """The pipeline's error carries the routing's reason, not a guess: a strip pulled at its end only narrows."""
    from mdsr_opt.synthesis.pipeline import design_pipeline

    mesh = Mesh.rectangle(4.0, 1.0, 16, 8)
    left = [i for i, (px, py) in enumerate(mesh.points) if px == 0.0]
    right = {i: (1.2 * px, py) for i, (px, py) in enumerate(mesh.points) if px == 4.0}
    with pytest.raises(ValueError, match=r"routing found no muscle on the target \(no muscle unit could be "
                                         r"seeded: .* compression_ratio filter \(1\) removed"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            design_pipeline(mesh, NeoHookean(1.0, 0.3), left, right, fabrication=False)


# ---------------------------------------------------------------------------------------------- 8: scene muscles
def _muscle_scene(tmp_path, s: float, frm, to, units="mm"):
    text = (BODY.format(units=units, L=40 * s, H=10 * s, m=-s, e=0.5 * s, h1=11 * s, l0=39.5 * s, l1=41 * s)
            + f"[[muscles]]\nname = \"m\"\nboundary = {{ from = [{frm[0] * s}, {frm[1] * s}], "
              f"to = [{to[0] * s}, {to[1] * s}] }}\n"
            + "[[cases]]\nname = \"c\"\ncontractions = [0.2]\n")
    f = tmp_path / f"m{s}.toml"
    f.write_text(text)
    return f


@pytest.mark.parametrize("s, units", [(1.0, "mm"), (0.001, "m")])
def test_a_scene_muscle_on_the_outline_warns_in_the_run_its_log_and_its_table(tmp_path, s, units):
    from mdsr_opt.scenes.cases import prepare_case
    from mdsr_opt.scenes.runner import run_case
    from mdsr_opt.scenes.scenereport import SceneReport
    from mdsr_opt.synthesis.fabrication import FabricationWarning, rope_conflicts

    scene = load_scene(_muscle_scene(tmp_path, s, (0, 0), (40, 0), units))
    with pytest.warns(FabricationWarning, match=r"muscle m: its channel is not mouldable: .*runs on the outline"):
        prepare_case(scene, "c")
    said = []
    with warnings.catch_warnings():
        warnings.simplefilter("error", FabricationWarning)  # the run reports it in its log and report instead
        run = run_case(scene, "c", photo=False, bands=False, log=said.append)
    rep = run.report
    assert rep.success and len(rep.fabrication) == 1
    # the same check as the Python API's (rope_conflicts), word for word
    expected = [c.message for c in rope_conflicts(scene.mesh, scene.muscles, Fabrication())]
    assert all(m in rep.fabrication[0] for m in expected) and expected
    assert any(line.startswith("FabricationWarning: ") and "runs on the outline" in line for line in said)
    table = SceneReport(scene="b", title="", n_nodes=scene.mesh.n_nodes, cases=[rep]).table()
    assert "ok (not mouldable as laid out)" in table
    assert "runs on the outline" in str(rep.to_dict()["fabrication"])


def test_a_mouldable_scene_muscle_gives_no_fabrication_warning(tmp_path):
    from mdsr_opt.scenes.cases import given_muscle_conflicts

    scene = load_scene(_muscle_scene(tmp_path, 1.0, (0, 0), (40, 0)))
    import networkx as nx

    from mdsr_opt import Muscle
    from mdsr_opt.synthesis.fabrication import boundary_distance

    mesh = scene.mesh
    P, deep = mesh.points, boundary_distance(mesh) >= 2.5
    g = nx.Graph([(int(a), int(b), {"l": float(np.linalg.norm(P[a] - P[b]))}) for a, b in mesh.edges
                  if deep[a] and deep[b]])
    a, b = (min(g.nodes, key=lambda i: np.linalg.norm(P[i] - q)) for q in ((10.0, 5.0), (30.0, 5.0)))
    path = nx.shortest_path(g, a, b, weight="l")
    assert len(path) >= 3
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert given_muscle_conflicts(scene, scene.cases[0], (Muscle(path, name="inside"),)) == []


# ---------------------------------------------------------------------------------------------- 5: prototype fixtures
class _Shot:
    success, status = False, "not solved (a stand-in prototype)"


class _Prototype:
    """validate_case's view of a VirtualPrototype: its default fixtures and what it was asked to build."""

    def __init__(self, radius, mesh):
        self.fixture_radius, self.design_mesh, self.asked = radius, mesh, []

    def describe(self):
        return {"fixture_radius": self.fixture_radius}

    def drive(self, scene, case, guess=None):
        return _Shot()

    def internal(self, muscles, contractions, photo=True, guess=None, fixture_radius=None):
        self.asked.append(fixture_radius)
        return _Shot()


@pytest.mark.parametrize("designed, used", [(2.61, 2.61), (float("nan"), 3.77), (0.0, 3.77)])
def test_the_prototype_builds_the_designs_fixtures_and_records_them(designed, used):
    """The routing shrank the fixtures (3.77 -> 2.61 on the trial's T): the design and the fabrication files use
    2.61, so the prototype is built with 2.61 and the case's record says so (a design without a radius, NaN
    before this fix, or with point ends: the prototype's own)."""
    from types import SimpleNamespace

    from mdsr_opt.scenes.prototype import validate_case

    mesh = Mesh.rectangle(4.0, 1.0, 8, 2)
    proto = _Prototype(3.77, mesh)
    setup = SimpleNamespace(case=SimpleNamespace(kind="external", name="c"), scene=None, target=mesh.points,
                            muscles=())
    design = SimpleNamespace(anchor_radius=designed, contractions=np.array([0.1]), x=mesh.points)
    said = []
    out, _ = validate_case(proto, setup, design, log=said.append)
    assert proto.asked == [used]
    assert out["design"]["fixture_radius"] == used and out["prototype"]["fixture_radius"] == used
    assert "fixture_radius" not in out["driving"]  # anchors and drags: no ropes, no fixtures
    assert f"fixtures of radius {used:.3g}" in said[-1]


def test_no_seed_message_when_nothing_contracts_names_it_without_failing():
    from mdsr_opt.synthesis.routing_why import no_seed_message

    mesh = Mesh.rectangle(4.0, 1.0, 8, 2)
    w = -0.1 * np.ones(len(mesh.edges))  # every edge stretched
    msg = no_seed_message(mesh, mesh.points * 1.1, w, w > 0.001, None, 0.05, None, min_contraction=0.001,
                          seed_threshold=0.5, compression_ratio=1.0, clearance=None)
    assert msg.startswith("no muscle unit could be seeded: 0 edge(s) contract") and msg.endswith("no muscles routed")
