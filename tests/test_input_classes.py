"""Inconsistent and silent inputs (issue 31, item 8), each class at every entry point: a result paired with
another mesh, names that are not text, node indices in every form, impossible targets, deep scene files."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from types import SimpleNamespace

import ezdxf
from ezdxf.lldxf.encoding import decode_dxf_unicode
import numpy as np
import pytest

from mdsr_opt import Mesh, Muscle, NeoHookean, solve_external, solve_internal
from mdsr_opt.body.fingerprint import check_same_mesh, mesh_fingerprint
from mdsr_opt.core.checks import check_label, check_stem, node_indices
from mdsr_opt.mechanics.drags import RigidDrag, drag_path
from mdsr_opt.scenes.reader import SceneFileError
from mdsr_opt.scenes.scene import Case
from mdsr_opt.scenes.scenefile import load_scene
from mdsr_opt.synthesis.contractions import design_contractions
from mdsr_opt.synthesis.export import escape, export_fabrication
from mdsr_opt.synthesis.results import DesignResult
from mdsr_opt.synthesis.verify import verify_design

MAT = NeoHookean(1.0, 0.3)
SVG = "{http://www.w3.org/2000/svg}"


def strip() -> Mesh:
    return Mesh.rectangle(4.0, 1.0, 16, 4)


def bend(mesh, s):
    X = mesh.points
    R, phi = 3.0, (X[:, 0] - 2.0) / 3.0
    r = R - s * (X[:, 1] - 0.5)
    return np.column_stack([r * np.sin(phi), s * (R - r * np.cos(phi))])


@pytest.fixture(scope="module")
def made():
    """A design of one muscle on the 4 x 1 strip (size sqrt(17) = 4.12311)."""
    mesh = strip()
    mus = [Muscle(range(1, 16), name="M0")]
    target = solve_internal(mesh, MAT, mus, [0.2]).x
    return mesh, mus, target, design_contractions(mesh, MAT, mus, target)


def others(mesh):
    """(label, mesh, words of the refusal) for bodies that are not ``mesh``: scaled, moved, a node shifted,
    other triangles on the same nodes, another node count."""
    moved_node = mesh.points.copy()
    moved_node[20] += [0.05, 0.02]   # an interior node, a fifth of an edge
    T = mesh.triangles.copy()
    assert T[:2].tolist() == [[0, 1, 18], [0, 18, 17]]
    T[:2] = [[0, 1, 17], [1, 18, 17]]  # the first cell's diagonal flipped: same nodes, another connectivity
    return [("scaled", Mesh(mesh.points * 2.0, mesh.triangles), r"size 4\.12311 .*size 8\.24621 \(2 times as large\)"),
            ("translated", Mesh(mesh.points + [1.0, -0.5], mesh.triangles), r"moved by \(1, -0\.5\)"),
            ("moved node", Mesh(moved_node, mesh.triangles), "other node positions"),
            ("topology", Mesh(mesh.points, T), "other triangles"),
            ("node count", Mesh.rectangle(4.0, 1.0, 8, 2), "27 nodes"),
            ("pattern", Mesh.rectangle(4.0, 1.0, 16, 4, pattern="right"), "other triangles")]


# ---------------------------------------------------------------------------------------------- 1. result + mesh
def test_the_fingerprint_tells_the_same_body_from_every_other():
    mesh = strip()
    fp = mesh_fingerprint(mesh)
    check_same_mesh(Mesh(mesh.points.copy(), mesh.triangles.copy()), fp)            # a copy: the same body
    check_same_mesh(Mesh(mesh.points * (1 + 1e-12), mesh.triangles), fp)            # file round-off: the same
    T = np.roll(mesh.triangles[::-1], 1, axis=1)                                   # listed in another order
    check_same_mesh(Mesh(mesh.points, T), fp)
    for label, other, words in others(mesh):
        with pytest.raises(ValueError, match=words):
            check_same_mesh(other, fp, "the design")
    assert json.loads(json.dumps(fp)) == fp                                        # JSON-ready as it is


def test_export_refuses_a_design_on_another_mesh_and_writes_nothing(made, tmp_path):
    mesh, mus, _, res = made
    assert res.rest_mesh == mesh_fingerprint(mesh)
    for label, other, words in others(mesh):
        out = tmp_path / label.replace(" ", "_")
        with pytest.raises(ValueError, match=words):
            export_fabrication(other, res, out, muscles=mus)
        assert not out.exists()
    files = export_fabrication(Mesh(mesh.points.copy(), mesh.triangles), res, tmp_path / "ok", muscles=mus)
    # a rope along the outline: the NOT MOULDABLE comment line comes first, then the header
    rows = [r for r in open(files["csv"], encoding="utf-8").read().splitlines() if not r.startswith("#")]
    rest, stroke = float(rows[1].split(",")[2]), float(rows[1].split(",")[7])
    assert rest == pytest.approx(mus[0].rest_length(mesh)) and stroke == pytest.approx(0.2 * rest, rel=1e-4)


def test_recorded_rest_lengths_catch_another_mesh_or_layout_without_a_fingerprint(made, tmp_path):
    """A result without a fingerprint (saved by an older version, or a stand-in) is still held to its
    recorded rest lengths: a 2x mesh, or another muscle of the same count, is refused."""
    mesh, mus, _, res = made
    old = DesignResult(**{**res.__dict__, "rest_mesh": None})
    with pytest.raises(ValueError, match=r"muscle 'M0' of rest length 3\.5; .* it is 7"):
        export_fabrication(Mesh(mesh.points * 2.0, mesh.triangles), old, tmp_path / "a", muscles=mus)
    with pytest.raises(ValueError, match="rest length"):
        export_fabrication(mesh, old, tmp_path / "b", muscles=[Muscle(range(18, 30), name="other")])
    stand_in = SimpleNamespace(contractions=np.array([0.1]), rest_lengths=np.array([1.0]))
    with pytest.raises(ValueError, match="rest length 1"):
        export_fabrication(mesh, stand_in, tmp_path / "c", muscles=mus)
    assert not any((tmp_path / k).exists() for k in "abc")


def test_every_function_taking_a_design_and_a_mesh_refuses_another_mesh(made):
    from mdsr_opt.plot.design import plot_design

    mesh, mus, target, res = made
    big = Mesh(mesh.points * 2.0, mesh.triangles)
    with pytest.raises(ValueError, match="2 times as large"):
        verify_design(big, MAT, mus, res, target * 2.0)
    with pytest.raises(ValueError, match="2 times as large"):
        plot_design(big, res, target * 2.0, mus)


def test_saved_and_loaded_results_keep_their_mesh(made, tmp_path):
    mesh, mus, _, res = made
    back = DesignResult.load(res.save(tmp_path / "d.npz"))
    assert back.rest_mesh == res.rest_mesh
    assert DesignResult.from_dict(json.loads(json.dumps(res.to_dict()))).rest_mesh == res.rest_mesh
    with pytest.raises(ValueError, match="2 times as large"):
        export_fabrication(Mesh(mesh.points * 2.0, mesh.triangles), back, tmp_path / "x", muscles=mus)


def test_pipeline_result_keeps_its_mesh_and_refuses_a_foreign_one(tmp_path):
    from mdsr_opt.body.io import write_mesh
    from mdsr_opt.synthesis.pipeline import PipelineResult, design_pipeline

    mesh = strip()
    left = np.flatnonzero(mesh.points[:, 0] == 0.0)
    right = np.flatnonzero(mesh.points[:, 0] == 4.0)
    out = design_pipeline(mesh, MAT, left, {int(i): mesh.points[i] + [-0.3, -0.4] for i in right})
    out.save(tmp_path / "run")
    back = PipelineResult.load(tmp_path / "run")
    assert back.design.rest_mesh == out.design.rest_mesh == mesh_fingerprint(mesh)
    check_same_mesh(back.mesh, back.design.rest_mesh)                # the mesh read back is the design's
    # the saved mesh replaced by a scaled one: the folder no longer holds the design's body
    write_mesh(tmp_path / "run" / json.load(open(tmp_path / "run" / "design.json"))["meshes"]["target"],
               Mesh(mesh.points * 2.0, mesh.triangles), x=out.target * 2.0)
    with pytest.raises(ValueError, match="2 times as large"):
        PipelineResult.load(tmp_path / "run")


def test_layouts_and_schedules_refuse_another_mesh_and_keep_it_on_disk(tmp_path):
    from mdsr_opt.synthesis.gait import GaitSchedule, gait_schedule, save_gait_animation
    from mdsr_opt.synthesis.poses import design_poses
    from mdsr_opt.synthesis.poses_result import PosesResult

    mesh = strip()
    lay = design_poses(mesh, MAT, {"left": bend(mesh, 1), "right": bend(mesh, -1)}, compare=False)
    back = PosesResult.load(lay.save(tmp_path / "layout.json"))
    assert back.rest_mesh == lay.rest_mesh == mesh_fingerprint(mesh)
    sch = gait_schedule(mesh, MAT, back, ["left"], frames_per_step=1)
    sch_back = GaitSchedule.load(sch.save(tmp_path / "s.npz"))
    assert sch_back.rest_mesh == mesh_fingerprint(mesh)
    for label, other, words in others(mesh):
        if other.n_nodes != mesh.n_nodes:
            words = "nodes"
        with pytest.raises(ValueError, match=words):
            gait_schedule(other, MAT, back, ["left"], frames_per_step=1)
        with pytest.raises(ValueError, match=words):
            export_fabrication(other, back, tmp_path / "f")
        with pytest.raises(ValueError, match=words):
            save_gait_animation(other, sch_back, back.muscles, tmp_path / "g.gif")
    assert not (tmp_path / "f").exists() and not (tmp_path / "g.gif").exists()
    # a pose's separate design made on another mesh is refused before any routing
    big = Mesh(mesh.points * 2.0, mesh.triangles)
    with pytest.raises(ValueError, match="separate design of pose 'left'.*2 times as large"):
        design_poses(big, MAT, {"left": 2.0 * bend(mesh, 1)}, separate={"left": (lay.muscles[:1],
                                                                                  lay.designs["left"])})


# ---------------------------------------------------------------------------------------------- 2. names
@pytest.mark.parametrize("bad", ["a\x00b", "esc\x1b[31m", "two\nlines", "tab\there", "cr\r", "del\x7f",
                                 "sep\u2028", "lone\ud800"])
def test_control_characters_are_refused_in_names_at_every_door(bad, tmp_path):
    with pytest.raises(ValueError, match="control character"):
        Muscle([0, 1, 2], name=bad)
    with pytest.raises(ValueError, match="control character"):
        check_stem(bad)
    mesh = strip()
    with pytest.raises(ValueError, match="control character"):
        export_fabrication(mesh, None, tmp_path / "out", muscles=[Muscle([0, 1, 2], name="ok")], name=bad)
    assert not (tmp_path / "out").exists()
    from mdsr_opt.synthesis.poses import design_poses

    with pytest.raises(ValueError, match="pose name .*control character"):
        design_poses(mesh, MAT, {bad: bend(mesh, 1)})
    # a scene file: the field is named
    scene = {"name": "s", "body": {"outline": [[0, 0], [4, 0], [4, 1], [0, 1]], "resolution": 60},
             "muscles": [{"name": bad, "path": [[0.2, 0.0], [3.8, 0.0]]}],
             "cases": [{"name": "c", "contractions": [0.1]}]}
    path = tmp_path / "s.json"
    path.write_text(json.dumps(scene))
    with pytest.raises(SceneFileError, match=r"s\.json: muscles\[0\]\.name: .*control character"):
        load_scene(path)


def test_names_that_are_not_strings_and_stems_that_are_paths_are_refused():
    with pytest.raises(TypeError, match="muscle name must be a string"):
        Muscle([0, 1], name=3)
    for stem, words in [("a/b", "holds '/'"), ("..\\x", "holds"), ("c:x", "holds ':'"), ("", "is empty"),
                        (".hidden", "starts with a dot"), ("a<b", "holds '<'")]:
        with pytest.raises(ValueError, match=words):
            check_stem(stem)
    assert check_stem("gecko v2_final") == "gecko v2_final" and check_label("M<1> & 'b'", "x") == "M<1> & 'b'"


def test_markup_and_any_text_survive_svg_and_dxf(tmp_path):
    mesh = strip()
    names = ["<b>bold</b>", "a & b", 'say "hi"', "it's", "]]> <!-- x -->", "m\u00fcscle \u03bb \U0001F600"]
    mus = [Muscle([i, i + 1, i + 2], name=n) for i, n in zip(range(0, 12, 2), names)]
    files = export_fabrication(mesh, None, tmp_path, muscles=mus, name="r&d")
    root = ET.parse(files["svg"]).getroot()  # well-formed XML: parses
    assert [e.get("id") for e in root.iter(f"{SVG}polyline") if e.get("class") == "muscle"] == names
    assert [e.text for e in root.iter(f"{SVG}text") if e.get("class") == "label"] == names
    assert "r&d" in root.find(f"{SVG}title").text
    doc = ezdxf.readfile(files["dxf"])
    texts = [decode_dxf_unicode(t.plain_text()) for t in doc.modelspace().query("TEXT")]
    assert texts == names[:-1] + ["m\u00fcscle \u03bb ?"]  # beyond U+FFFF: "?" (R12 has no escape for it)
    # the escape itself keeps any string parseable, even characters that never pass the name check
    for raw in ["\x00\x1b<&>\"'", "\ud800\ufffe"]:
        assert ET.fromstring(f'<a b="{escape(raw)}">{escape(raw)}</a>').tag == "a"


# ---------------------------------------------------------------------------------------------- 3. node indices
@pytest.mark.parametrize("value, err, words", [
    ([16.9, 33.5], TypeError, "16.9 is not an integer"),
    ([16.0, 33.0], TypeError, r"16\.0 is not an integer \(a float"),
    (np.array([3.0, 4.0]), TypeError, "3.0 is not an integer"),
    ([3, float("nan")], TypeError, "nan is not an integer"),
    ([True, 3], TypeError, "boolean"),
    (np.array([True, False]), TypeError, "boolean"),
    (["3"], TypeError, "integer"),
    ([3, 3], ValueError, "node 3 is repeated"),
    ([0, 999], ValueError, "out of range"),
    ([[1, 2]], ValueError, "shape"),
])
def test_one_validator_for_node_indices_in_every_form(value, err, words):
    mesh = strip()
    left = [0, 17, 34]
    with pytest.raises(err, match=words):
        node_indices(value, "nodes", n=mesh.n_nodes)
    with pytest.raises(err, match=words):          # anchors of external driving
        solve_external(mesh, MAT, value, {50: (4.0, 0.0)})
    with pytest.raises(err, match=words):          # the (indices, positions) form of drags
        drag_path((value, np.zeros((len(value), 2))), mesh)
    with pytest.raises(err, match=words):          # a rigid drag (16.9 used to become node 16)
        drag_path(RigidDrag(value, 0.1, (0.0, 0.0)), mesh)
    if "range" not in words:                       # a scene case built in Python (the scene checks the range)
        with pytest.raises(err, match=words):
            Case("c", anchors=value, drag_nodes=left, drag_positions=mesh.points[left])


def test_muscle_paths_take_the_same_integers():
    """A muscle's path is checked by the same integer rule (its own message for a repeated node: a path)."""
    for nodes, words in [([16.9, 17.2], "must hold integer"), ([16.0, 17.0], "must hold integers"),
                         ([True, 1], "boolean"), ([1, float("nan")], "must hold integer")]:
        with pytest.raises(TypeError, match=words):
            Muscle(nodes)
    with pytest.raises(ValueError, match="repeats node 1"):
        Muscle([0, 1, 2, 1])
    assert Muscle(np.array([0, 1, 2], dtype=np.int32)).nodes == (0, 1, 2)


def test_a_node_dragged_twice_is_refused_in_every_form_even_to_the_same_place():
    mesh = strip()
    p, q = (4.0, 0.0), (5.0, 0.0)
    with pytest.raises(ValueError, match="node 16 is repeated"):
        drag_path(([16, 16], [p, q]), mesh)                       # last-wins before
    with pytest.raises(ValueError, match="node 16 is repeated"):
        drag_path(([16, 16], [p, p]), mesh)
    with pytest.raises(ValueError, match=r"node 16 more than once \(to \(4, 0\) and to \(5, 0\)\)"):
        drag_path([{16: p}, {16: q}], mesh)
    with pytest.raises(ValueError, match=r"node 16 more than once \(to the same place\)"):
        drag_path([{16: p}, {16: p}], mesh)
    with pytest.raises(ValueError, match="more than once"):
        drag_path([RigidDrag([16, 33], 0.2, (4.0, 0.0)), {33: q}], mesh)
    with pytest.raises(ValueError, match="node 33 is repeated"):
        RigidDrag([16, 33, 33], 0.2, (4.0, 0.0))
    with pytest.raises(TypeError, match="integer node indices"):
        drag_path({16.0: p}, mesh)                                # dict keys: integers only, as before
    with pytest.raises(ValueError, match="both anchored and dragged"):
        solve_external(mesh, MAT, [0, 16], {16: p})


def test_scene_files_take_integer_node_indices_only(tmp_path):
    base = {"name": "s", "body": {"outline": [[0, 0], [4, 0], [4, 1], [0, 1]], "resolution": 60}}
    cases = [([{"name": "c", "anchors": [0, 1.0], "drags": [{"nodes": [2], "by": [0.1, 0]}]}],
              TypeError, r"cases\[0\]\.anchors\[1\]: expected a node index"),
             ([{"name": "c", "anchors": [0, True], "drags": [{"nodes": [2], "by": [0.1, 0]}]}],
              TypeError, "boolean"),
             ([{"name": "c", "anchors": [0], "drags": [{"nodes": [2], "by": [0.1, 0]},
                                                       {"nodes": [2], "by": [0.2, 0]}]}],
              SceneFileError, "node 2 is dragged twice")]
    for k, (case, err, words) in enumerate(cases):
        path = tmp_path / f"s{k}.json"
        path.write_text(json.dumps({**base, "cases": case}))
        with pytest.raises(err, match=words):
            load_scene(path)


def test_the_pipeline_takes_rigid_drags():
    """design_pipeline() parsed its drags by node count only, so a RigidDrag failed after the external solve."""
    from mdsr_opt.synthesis.pipeline import design_pipeline

    mesh = strip()
    left = np.flatnonzero(mesh.points[:, 0] == 0.0)
    right = np.flatnonzero(mesh.points[:, 0] == 4.0)
    rd = RigidDrag(right, 0.4, (4.0, 0.0), shift=(-0.6, 0.0))
    out = design_pipeline(mesh, MAT, left, rd, verify=False)
    np.testing.assert_array_equal(out.drag_nodes, right)
    np.testing.assert_allclose(out.drag_positions, drag_path(rd, mesh).final, atol=1e-12)
    np.testing.assert_allclose(out.target[right], out.drag_positions, atol=1e-9)


# ---------------------------------------------------------------------------------------------- 4. targets
def impossible_targets(mesh, good):
    inv = good.copy()
    inv[20] += [0.0, -0.6]                   # an interior node pulled through its lower neighbours
    flat = good.copy()
    flat[:, 1] = 0.0
    return [("inverted", inv, r"target has \d+ inverted triangle\(s\) \(det F <= 0\), first: triangle"),
            ("mirrored", good * [-1.0, 1.0], "inverts every triangle .* mirror image"),
            ("flat", flat, "flattens every triangle"),
            ("nan", np.where(np.arange(good.size).reshape(good.shape) == 7, np.nan, good), "NaN or inf"),
            ("inf", good + np.where(np.arange(good.size).reshape(good.shape) == 3, np.inf, 0.0), "NaN or inf"),
            ("shape", good[:-1], r"shape .*\(85, 2\)")]


@pytest.mark.parametrize("method", ["flattened", "nested", "derivative-free"])
def test_every_design_method_refuses_impossible_targets(made, method):
    mesh, mus, target, _ = made
    for label, t, words in impossible_targets(mesh, target):
        with pytest.raises(ValueError, match=words):
            design_contractions(mesh, MAT, mus, t, method=method)


def test_routing_poses_and_designs_give_the_same_message(made):
    from mdsr_opt.synthesis.poses import design_poses
    from mdsr_opt.synthesis.routing import route_muscles

    mesh, mus, target, res = made
    for label, t, words in impossible_targets(mesh, target):
        msgs = []
        for call in (lambda: design_contractions(mesh, MAT, mus, t), lambda: route_muscles(mesh, t),
                     lambda: design_poses(mesh, MAT, {"p": t}),
                     lambda: design_poses(mesh, MAT, {"p": t}, separate={"p": (tuple(mus), res)})):
            with pytest.raises(ValueError, match=words) as info:
                call()
            msgs.append(str(info.value).replace("pose 'p': ", "").replace("pose 'p' ", ""))
        if label != "shape":  # design_poses says the poses' shapes apart
            assert len(set(msgs)) == 1, msgs


# ---------------------------------------------------------------------------------------------- 5. deep files
@pytest.mark.parametrize("suffix, text", [
    (".json", '{"name": "x", "expected": ' + "[" * 10_000 + "]" * 10_000 + "}"),
    (".json", '{"name": "x", "expected": ' + '{"a": ' * 100 + "1" + "}" * 100 + "}"),
    (".toml", "name = 'x'\nexpected = " + "[" * 5_000 + "]" * 5_000 + "\n"),
    (".toml", "name = 'x'\nexpected = " + "[" * 80 + "]" * 80 + "\n"),
])
def test_deeply_nested_scene_files_are_a_clear_error(tmp_path, suffix, text):
    path = tmp_path / f"deep{suffix}"
    path.write_text(text)
    with pytest.raises(SceneFileError, match=rf"deep\{suffix}: tables and lists are nested more than 64 deep"):
        load_scene(path)


def test_an_oversized_scene_file_is_refused_before_it_is_read(tmp_path, monkeypatch):
    import mdsr_opt.scenes.reader as reader

    path = tmp_path / "big.toml"
    path.write_text("name = 'x'\n" + "# padding\n" * 200)
    monkeypatch.setattr(reader, "MAX_BYTES", 1000)
    with pytest.raises(SceneFileError, match=r"big\.toml: the scene file is .* MB, more than"):
        load_scene(path)


def test_deeply_nested_result_files_are_a_clear_error(tmp_path):
    from mdsr_opt.synthesis.poses_result import PosesResult

    path = tmp_path / "layout.json"
    path.write_text('{"format": "mdsr_opt.poses/1", "names": ' + "[" * 10_000 + "]" * 10_000 + "}")
    with pytest.raises(ValueError, match=r"layout\.json.*nested too deeply"):
        PosesResult.load(path)
