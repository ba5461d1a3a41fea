"""Scenes: the registry, the helpers that draw scenes, the scene-file loader and the ``mdsr`` command."""

from __future__ import annotations

import copy
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from mdsr_opt import Mesh, Muscle, NeoHookean
from mdsr_opt.cli.main import main
from mdsr_opt.body.io import write_mesh
from mdsr_opt.scenes.scene import Animation, Case, Scene, UnknownName, mesh_polygon, resolve_resolution
from mdsr_opt.scenes.reader import SceneFileError
from mdsr_opt.scenes.shapes import arc_map, arc_rigid
from mdsr_opt.scenes.select import boundary_path, edge_path
from mdsr_opt.scenes.library import get_problem, list_problems, problems_dir, remeshable_source
from mdsr_opt.scenes.scenefile import load_scene, remeshable

DATA = Path(__file__).parent / "data"
FINGER = DATA / "finger.toml"

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


# ---------------------------------------------------------------------------------------------- registry
def test_registry_finds_the_repository_problems():
    assert problems_dir() == Path(__file__).resolve().parents[1] / "problems"
    assert "gecko" in list_problems() and "__init__" not in list_problems()


def test_unknown_problem_names_the_library():
    with pytest.raises(UnknownName, match=r"unknown problem 'geko' \(did you mean 'gecko'\?\); the library has: .*gecko"):
        get_problem("geko")
    assert issubclass(UnknownName, KeyError) and issubclass(UnknownName, ValueError)


def test_problems_folder_from_the_environment(tmp_path, monkeypatch):
    (tmp_path / "square.py").write_text(
        "from mdsr_opt import NeoHookean\n"
        "from mdsr_opt.scenes.scene import Case, Scene, mesh_polygon; from mdsr_opt.scenes.select import nodes_in_box\n"
        "def build(resolution='medium'):\n"
        "    m = mesh_polygon([[0, 0], [1, 0], [1, 1], [0, 1]], resolution=resolution)\n"
        "    c = Case('push', anchors=nodes_in_box(m, xmax=0), drag_nodes=nodes_in_box(m, xmin=1),\n"
        "             drag_positions=m.points[nodes_in_box(m, xmin=1)] - [0.2, 0])\n"
        "    return Scene('square', m, NeoHookean(1.0, 0.3), (c,))\n")
    (tmp_path / "_helper.py").write_text("x = 1\n")
    monkeypatch.setenv("MDSR_PROBLEMS", str(tmp_path))
    assert list_problems() == ["square"]
    scene = get_problem("square", resolution=60)
    assert scene.source.endswith("square.py") and 48 <= scene.mesh.n_nodes <= 72
    monkeypatch.setenv("MDSR_PROBLEMS", str(tmp_path / "missing"))
    with pytest.raises(FileNotFoundError, match="MDSR_PROBLEMS"):
        list_problems()


def test_problem_script_by_path():
    scene = get_problem(str(Path(__file__).resolve().parents[1] / "problems" / "gripper.py"), resolution="coarse")
    assert scene.name == "gripper" and scene.case_names == ("close",)


@pytest.mark.parametrize("bad, err, match", [("tiny", ValueError, "resolution must be one of"),
                                             (5, ValueError, "at least 20 nodes"),
                                             (99999999, ValueError, "at most 200000 nodes .a solve's memory"),
                                             (2.5, TypeError, "integer node count")])
def test_resolution_is_checked(bad, err, match):
    with pytest.raises(err, match=match):
        resolve_resolution(bad)


@pytest.mark.parametrize("want", [100, 400, 1500])
def test_mesh_polygon_meets_the_node_count(want):
    L = [[0, 0], [3, 0], [3, 0.5], [1, 0.5], [1, 2], [0, 2]]
    mesh = mesh_polygon(L, resolution=want)
    assert abs(mesh.n_nodes - want) <= 0.15 * want


# ---------------------------------------------------------------------------------------------- helpers
def test_arc_map_keeps_lengths_along_the_centre_line():
    s = np.linspace(0.0, 4.0, 9)
    line = np.column_stack([s, np.zeros_like(s)])
    bent = arc_map(line, (0.0, 0.0), (1.0, 0.0), 4.0, np.pi / 2)
    R = 4.0 / (np.pi / 2)
    assert np.allclose(np.linalg.norm(bent - [0.0, R], axis=1), R)        # on the circle about (0, R)
    assert np.allclose(bent[-1], [R, R])                                   # a quarter turn
    # points off the line keep their distance to it (normal offset)
    off = arc_map(line + [0.0, 0.3], (0.0, 0.0), (1.0, 0.0), 4.0, np.pi / 2)
    assert np.allclose(np.linalg.norm(off - [0.0, R], axis=1), R - 0.3)


def test_arc_rigid_moves_a_group_rigidly():
    rng = np.random.default_rng(1)
    pts = rng.uniform([3.5, -0.3], [4.0, 0.3], size=(20, 2))
    moved = arc_rigid(pts, (3.5, 0.0), (0.0, 0.0), (1.0, 0.0), 3.5, 1.0)
    d0 = np.linalg.norm(pts[:, None] - pts[None], axis=2)
    d1 = np.linalg.norm(moved[:, None] - moved[None], axis=2)
    assert np.allclose(d0, d1)
    root = arc_map(np.array([[3.5, 0.0]]), (0.0, 0.0), (1.0, 0.0), 3.5, 1.0)[0]
    assert np.allclose(arc_rigid(np.array([[3.5, 0.0]]), (3.5, 0.0), (0.0, 0.0), (1.0, 0.0), 3.5, 1.0)[0], root)


def test_boundary_and_edge_paths_follow_mesh_edges():
    mesh = mesh_polygon([[0, 0], [4, 0], [4, 1], [0, 1]], resolution=200)
    m = boundary_path(mesh, (0, 0), (4, 0), via=(2, 0), name="lower")
    P = mesh.points
    assert np.all(np.abs(P[list(m.nodes), 1]) < 1e-9)                      # along the lower side
    assert m.rest_length(mesh) == pytest.approx(4.0)
    m.check_on(mesh)
    e = edge_path(mesh, [(0.2, 0.5), (2.0, 0.5), (3.8, 0.5)])
    e.check_on(mesh)
    assert e.rest_length(mesh) < 1.25 * 3.6


# ---------------------------------------------------------------------------------------------- data model
def test_scene_checks_its_cases():
    mesh = Mesh.rectangle(2.0, 1.0, 4, 2)
    mat = NeoHookean(1.0, 0.3)
    with pytest.raises(ValueError, match="an internal case needs the scene's muscles"):
        Scene("s", mesh, mat, (Case("c", contractions=[0.2]),))
    with pytest.raises(ValueError, match="2 contraction"):
        Scene("s", mesh, mat, (Case("c", contractions=[0.2, 0.3]),), muscles=(Muscle([0, 1, 2]),))
    ext = Case("e", anchors=[0, 5], drag_nodes=[4], drag_positions=[[2.5, 0.0]])
    with pytest.raises(ValueError, match="case name 'e' is used twice"):
        Scene("s", mesh, mat, (ext, ext))
    with pytest.raises(ValueError, match="unknown case 'x'"):
        Scene("s", mesh, mat, (ext,), animations=(Animation("a", (("rest", 0), ("x", 1))),))
    with pytest.raises(ValueError, match="at least two fixed nodes"):
        Case("one", anchors=[0])
    with pytest.raises(ValueError, match="may hold only letters"):
        Case("a/b", anchors=[0, 1])
    with pytest.raises(UnknownName, match="has no case 'f'"):
        Scene("s", mesh, mat, (ext,)).case("f")


# ---------------------------------------------------------------------------------------------- scene files
def finger_dict() -> dict:
    return tomllib.loads(FINGER.read_text())


def write_json(tmp_path, data, name="scene.json") -> Path:
    p = tmp_path / name
    p.write_text(json.dumps(data))
    return p


def test_toml_and_json_scene_files_agree(tmp_path):
    a = load_scene(FINGER)
    b = load_scene(write_json(tmp_path, finger_dict()))
    assert a.name == b.name == "finger"
    assert np.array_equal(a.mesh.points, b.mesh.points)
    assert [c.name for c in a.cases] == ["bend", "contract"]
    assert a.cases[0].kind == "external" and a.cases[1].kind == "internal"
    assert np.array_equal(a.cases[0].drag_nodes, b.cases[0].drag_nodes)
    assert np.allclose(a.cases[0].drag_positions, b.cases[0].drag_positions)
    assert a.muscles == b.muscles and len(a.muscles) == 1
    assert a.design_options == {"a_max": 0.6} and a.routing_options == {"max_muscles": 2}
    # the drag is a 60 degree turn of the tip about (0, 0.5): distances to the pivot are kept
    c = a.cases[0]
    P = a.mesh.points[c.drag_nodes]
    assert np.allclose(np.linalg.norm(c.drag_positions - [0, 0.5], axis=1), np.linalg.norm(P - [0, 0.5], axis=1))
    ang = np.arctan2(*(c.drag_positions - [0, 0.5])[:, ::-1].T) - np.arctan2(*(P - [0, 0.5])[:, ::-1].T)
    assert np.allclose(ang, np.radians(60))
    # the muscle runs in a channel along y = 0.7 (its waypoints), clear of the outline
    xy = a.mesh.points[list(a.muscles[0].nodes)]
    assert np.all(np.abs(xy[:, 1] - 0.7) < 0.2) and xy[:, 0].min() < 0.5 and xy[:, 0].max() > 3.1


def test_scene_file_with_a_mesh_file(tmp_path):
    mesh = Mesh.rectangle(4.0, 1.0, 8, 2)
    write_mesh(tmp_path / "body.vtu", mesh)
    d = finger_dict()
    d["body"] = {"mesh": "body.vtu"}
    d["regions"]["tip"] = {"box": [3.9, -1, 5, 2]}
    d["muscles"][0] = {"name": "upper", "boundary": {"from": [0, 1], "to": [4, 1]}}
    path = write_json(tmp_path, d)
    scene = load_scene(path)
    assert scene.mesh.n_nodes == mesh.n_nodes and np.allclose(scene.mesh.points, mesh.points)
    assert set(scene.regions["tip"].tolist()) == set(np.flatnonzero(mesh.points[:, 0] == 4.0).tolist())
    # its nodes are given: a resolution asked for is refused, not silently ignored (a mesh study would
    # repeat one mesh), at every door that takes one
    assert not remeshable(path) and not remeshable_source(path) and remeshable(FINGER)
    with pytest.raises(SceneFileError, match=r"body\.mesh: the body is a mesh file .* resolution 'coarse' cannot"):
        load_scene(path, resolution="coarse")
    with pytest.raises(SceneFileError, match="cannot re-mesh"):
        get_problem(path, resolution=2000)


def test_a_resolution_asked_for_re_meshes_a_max_area_body(tmp_path, capsys):
    """``max_area`` is the file's own mesh density; a resolution given (``mdsr run --resolution``, a study)
    meshes the outline at that node count instead of being ignored."""
    d = finger_dict()
    del d["body"]["resolution"]
    d["body"]["max_area"] = 0.01
    path = write_json(tmp_path, d)
    own = load_scene(path).mesh.n_nodes
    sizes = {r: load_scene(path, resolution=r).mesh.n_nodes for r in ("coarse", 1200)}
    assert sizes["coarse"] < 0.7 * own < 1.3 * own < sizes[1200]
    assert abs(sizes[1200] - 1200) < 0.15 * 1200 and get_problem(path, resolution=1200).mesh.n_nodes == sizes[1200]
    d["body"] = {"mesh": "body.vtu"}
    write_mesh(tmp_path / "body.vtu", Mesh.rectangle(4.0, 1.0, 8, 2))
    d["regions"]["tip"] = {"box": [3.9, -1, 5, 2]}
    d["muscles"][0] = {"name": "upper", "boundary": {"from": [0, 1], "to": [4, 1]}}
    mesh_path = write_json(tmp_path, d, "mesh_body.json")
    code = main(["run", str(mesh_path), "--out", str(tmp_path / "out"), "--resolution", "coarse"])
    assert code == 2 and "cannot re-mesh it" in capsys.readouterr().err and not (tmp_path / "out").exists()


def _set(path, value):
    def f(d):
        keys = path.split("/")
        cur = d
        for k in keys[:-1]:
            cur = cur[int(k)] if isinstance(cur, list) else cur[k]
        last = keys[-1]
        if value is _DELETE:
            del cur[int(last) if isinstance(cur, list) else last]
        elif isinstance(cur, list):
            cur[int(last)] = value
        else:
            cur[last] = value
    return f


_DELETE = object()

MALFORMED = [
    ("missing name", _set("name", _DELETE), SceneFileError, r"name: missing \(required\)"),
    ("unknown field", _set("case", []), SceneFileError, r"case: unknown field \(did you mean 'cases'\?\)"),
    ("bad name", _set("name", "my finger"), SceneFileError, r"name: .*only letters"),
    ("outline and mesh", _set("body/mesh", "x.vtu"), SceneFileError, r"body: give exactly one of outline"),
    ("short outline", _set("body/outline", [[0, 0], [1, 0]]), SceneFileError, r"body\.outline: needs at least 3"),
    ("3d point", _set("body/outline/1", [3.5, 0, 0]), SceneFileError, r"body\.outline\[1\]: expected a point"),
    ("crossing outline", _set("body/outline", [[0, 0], [1, 1], [1, 0], [0, 1]]), SceneFileError,
     r"body\.outline: .*intersect"),
    ("text coordinate", _set("body/outline/0/0", "zero"), TypeError, r"body\.outline\[0\]\[0\]: expected a number"),
    ("resolution", _set("body/resolution", "tiny"), SceneFileError, r"body\.resolution: resolution must be one"),
    ("missing mesh", lambda d: d.update(body={"mesh": "nowhere.vtu"}), FileNotFoundError,
     r"body\.mesh: no such mesh file"),
    ("nu", _set("material/nu", 0.5), SceneFileError, r"material\.nu: nu \(Poisson's ratio\) must lie in"),
    ("material model", _set("material/model", "mooney"), SceneFileError, r"material\.model: unknown material"),
    ("E text", _set("material/E", "soft"), TypeError, r"material\.E: expected a number"),
    ("region field", _set("regions/tip/radiuss", 0.3), SceneFileError,
     r"regions\.tip\.radiuss: unknown field \(did you mean 'radius'\?\)"),
    ("empty region", _set("regions/tip", {"near": [10, 10], "radius": 0.1}), SceneFileError,
     r"regions\.tip: selects no node"),
    ("region no radius", _set("regions/tip", {"near": [4, 0.5]}), SceneFileError, r"regions\.tip\.radius: missing"),
    ("unknown region", _set("cases/0/anchors", "bas"), SceneFileError,
     r"cases\[0\]\.anchors\[0\]: unknown region 'bas' \(regions: base, tip\)"),
    ("index range", _set("cases/0/anchors", [0, 99999]), SceneFileError,
     r"cases\[0\]\.anchors\[1\]: node index 99999 out of range"),
    ("off the body", _set("cases/0/drags", [{"at": [9, 9], "to": [1, 1]}]), SceneFileError,
     r"cases\[0\]\.drags\[0\]\.at\[0\]: no node within"),
    ("no destination", _set("cases/0/drags", [{"nodes": "tip"}]), SceneFileError,
     r"cases\[0\]\.drags\[0\]: say where the nodes go"),
    ("to and by", _set("cases/0/drags", [{"nodes": "tip", "to": [1, 1], "by": [0, 1]}]), SceneFileError,
     r"cases\[0\]\.drags\[0\]\.by: cannot be combined with to"),
    ("by length", _set("cases/0/drags", [{"nodes": "tip", "by": [1]}]), SceneFileError,
     r"cases\[0\]\.drags\[0\]\.by: expected a point \[x, y\], got \[1\]"),
    ("anchored and dragged", _set("cases/0/anchors", "tip"), SceneFileError,
     r"cases\[0\]: node \d+ is both anchored and dragged"),
    ("one fixed node", lambda d: d["cases"][0].pop("drags") and d["cases"][0].update(anchors=[[0, 0]]),
     SceneFileError, r"cases\[0\]: an external case needs at least two fixed nodes"),
    ("contraction count", _set("cases/1/contractions", [0.3, 0.2]), SceneFileError,
     r"cases\[1\]\.contractions: needs one value per muscle \(1\), got 2"),
    ("contraction range", _set("cases/1/contractions", [1.2]), SceneFileError,
     r"cases\[1\]\.contractions\[0\]: must lie in \[0, 1\)"),
    ("no muscles", lambda d: d.pop("muscles"), SceneFileError,
     r"cases\[1\]\.contractions: an internal case needs muscles"),
    ("duplicate case", _set("cases/1/name", "bend"), SceneFileError,
     r"cases\[1\]\.name: 'bend' is used by an earlier case"),
    ("internal with anchors", _set("cases/1/anchors", "base"), SceneFileError,
     r"cases\[1\]\.anchors: an internal case \(with contractions\) has no anchors"),
    ("no cases", _set("cases", []), SceneFileError, r"cases: expected a non-empty list"),
    ("routing option", _set("routing/max_muscle", 2), SceneFileError,
     r"routing\.max_muscle: unknown field \(did you mean 'max_muscles'\?\)"),
    ("design option", _set("design/amax", 0.5), SceneFileError, r"design\.amax: unknown field \(did you mean 'a_max'"),
    ("muscle two ways", _set("muscles/0/nodes", [1, 2]), SceneFileError, r"muscles\[0\]: give exactly one of"),
    ("muscle off the mesh", lambda d: d["muscles"][0].pop("path") and d["muscles"][0].update(nodes=[0, 99999]),
     SceneFileError, r"muscles\[0\]\.nodes: muscle 'upper' has node 99999 out of range"),
    ("animation case", _set("animations/0/keyframes/1", ["contrct", 1]), SceneFileError,
     r"animations\[0\]\.keyframes\[1\]: unknown case 'contrct'"),
    ("animation fraction", _set("animations/0/keyframes/1", ["contract", 2]), SceneFileError,
     r"animations\[0\]: .*outside \[0, 1\]"),
    ("anchor radius sign", _set("design/anchor_radius", -1), SceneFileError, r"design\.anchor_radius: must be >= 0"),
    ("anchor radius text", _set("design/anchor_radius", "big"), TypeError, r"design\.anchor_radius: expected a number"),
    ("anchor radius size", _set("design/anchor_radius", 1e9), SceneFileError,
     r".*design\.anchor_radius 1e\+09 is at least half the body's size"),
    ("max turn", _set("routing/max_turn", 200), SceneFileError, r"routing\.max_turn: must lie in \[0, 180\]"),
    ("seed threshold", _set("routing/seed_threshold", 2), SceneFileError,
     r"routing\.seed_threshold: must lie in \(0, 1\]"),
    ("compression ratio", _set("routing/compression_ratio", 0), SceneFileError,
     r"routing\.compression_ratio: must lie in \(0, 1\]"),
    ("symmetry", _set("routing/symmetry", "yes"), SceneFileError, r"routing\.symmetry: must be 'auto', true or false"),
    ("warm start", _set("design/warm_start", "target-ish"), SceneFileError,
     r"design\.warm_start: must be 'target', 'rest', true or false"),
    ("huge drag", _set("cases/0/drags", [{"nodes": "tip", "by": [1e300, 0]}]), SceneFileError,
     r".*case 'bend': a drag moves a node by 1e\+300, more than 10"),
    ("gait named like a case", lambda d: d.update(gait={"name": "bend", "poses": ["bend", "rest"]}), SceneFileError,
     r".*gait 'bend': the gait 'bend' would write 'bend', which is written by the case 'bend'"),
    ("gait named summary", lambda d: d.update(gait={"name": "summary", "poses": ["bend", "rest"]}), SceneFileError,
     r".*gait 'summary': the gait name 'summary' is reserved"),
]


def test_every_scene_option_keyword_has_a_check():
    """A keyword added to route_muscles or design_contractions must get its scene-file check (else a scene
    file's value would only fail mid-run)."""
    import inspect

    from mdsr_opt.scenes.reader import scene_options, Reader
    from mdsr_opt.synthesis.contractions import design_contractions
    from mdsr_opt.synthesis.routing import route_muscles

    for kind, fn in (("routing", route_muscles), ("design", design_contractions)):
        for p in inspect.signature(fn).parameters.values():
            if p.kind != p.KEYWORD_ONLY or p.name in ("initial_guess", "weights"):
                continue
            # a value of the wrong type is refused by the keyword's check (an unchecked keyword would pass)
            with pytest.raises((SceneFileError, TypeError), match=rf"{kind}\.{p.name}: "):
                scene_options(Reader("scene.toml"), {p.name: object()}, kind)


@pytest.mark.parametrize("label, mutate, err, match", MALFORMED, ids=[m[0] for m in MALFORMED])
def test_malformed_scene_file_names_the_field(tmp_path, label, mutate, err, match):
    d = copy.deepcopy(finger_dict())
    mutate(d)
    path = write_json(tmp_path, d)
    with pytest.raises(err, match=r"scene\.json: " + match):
        load_scene(path)


@pytest.mark.parametrize("name, text, match", [
    ("bad.toml", "name = 'x'\n[body\n", r"bad\.toml: not valid TOML"),
    ("bad.json", "{\"name\": \"x\",", r"bad\.json: not valid JSON"),
    ("list.json", "[1, 2]", r"list\.json: the top level must be a table"),
    ("scene.yaml", "name: x", r"scene\.yaml: a scene file ends in \.toml or \.json"),
])
def test_unreadable_scene_files(tmp_path, name, text, match):
    p = tmp_path / name
    p.write_text(text)
    with pytest.raises(SceneFileError, match=match):
        load_scene(p)


def test_missing_scene_file():
    with pytest.raises(FileNotFoundError, match="no such scene file"):
        get_problem("nowhere/scene.toml")


# ---------------------------------------------------------------------------------------------- mdsr command
def test_mdsr_list(capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    for name in ("gecko", "starfish", "face", "humanoid", "one_muscle", "two_muscles", "four_muscles"):
        assert f"  {name} " in out


def test_mdsr_run_unknown_name(capsys, tmp_path):
    assert main(["run", "geko", "--out", str(tmp_path)]) == 2
    assert "unknown problem 'geko'" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())     # nothing written


def test_mdsr_run_scene_file_writes_everything(tmp_path, capsys):
    out = tmp_path / "finger"
    assert main(["run", str(FINGER), "--out", str(out), "--resolution", "coarse", "--photo-size", "300x300"]) == 0
    text = capsys.readouterr().out
    assert "[finger 2/2 contract] design" in text                  # progress
    assert "| finger | contract | internal |" in text and "2/2 case(s) succeeded" in text
    files = sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file())
    per_case = ["design.png", "driven.vtu", "graph.png", "muscles.png", "overlay.png", "photo.json", "photo.png",
                "target.png", "target.vtu"] + [f"prototype_{k}.{e}" for k in ("design", "driving") for e in ("json", "png")]
    assert files == sorted([f"{c}/{f}" for c in ("bend", "contract") for f in per_case]
                           + [".mdsr-run.json", "curl.gif", "curl.json", "rest.png", "summary.json",
                              "summary.md", "validation.md"])
    manifest = json.loads((out / ".mdsr-run.json").read_text())
    assert manifest["status"] == "complete" and "bend" in manifest["claims"]
    assert manifest["files"] == [f for f in files if not f.startswith(".mdsr")]  # every file it wrote, by name
    s = json.loads((out / "summary.json").read_text())
    assert s["success"] is True and s["photographs"].startswith("SYNTHETIC")
    contract = s["cases"][1]
    assert contract["contraction_error"] < 1e-6 and contract["known_contractions"] == [0.3]
    assert contract["photo"]["image_size"] == [300, 300]
    assert contract["photo"]["self"]["mean_px"] < 1.0               # the measuring floor at 300 px
    bend = s["cases"][0]
    assert bend["n_muscles"] == 1 and bend["difference"] <= bend["initial_difference"]
    gif = json.loads((out / "curl.json").read_text())
    assert gif["success"] is True and gif["n_frames"] == 9 and max(max(f) for f in gif["contractions"]) == \
        pytest.approx(contract["contractions"][0])


def test_mdsr_run_reports_a_failed_case(tmp_path, capsys):
    # a strip pulled by its end, without lateral contraction (nu = 0): every edge stretches or keeps its
    # length, the exact equilibrium is the uniform stretch, and a cable cannot push: no muscle to route
    d = {"name": "strip", "body": {"outline": [[0, 0], [4, 0], [4, 1], [0, 1]], "resolution": 100},
         "material": {"nu": 0.0},
         "regions": {"base": {"box": [-1, -1, 0, 2]}, "end": {"box": [4, -1, 5, 2]}},
         "cases": [{"name": "stretch", "anchors": "base", "drags": [{"nodes": "end", "by": [0.5, 0]}]}]}
    path = write_json(tmp_path, d)
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out), "--no-figures", "--no-photos"]) == 1
    text = capsys.readouterr().out
    assert "FAILED strip/stretch: routing found no muscle" in text and "cable cannot push" in text
    s = json.loads((out / "summary.json").read_text())
    assert s["success"] is False and s["cases"][0]["target_success"] is True
    assert sorted(p.name for p in out.iterdir()) == [".mdsr-run.json", "summary.json", "summary.md"]


def test_a_scene_file_may_choose_where_the_design_warm_start_starts():
    from mdsr_opt.scenes.reader import scene_options, Reader

    for v in ("target", "rest", True, False):
        assert scene_options(Reader("scene.toml"), {"warm_start": v}, "design")["warm_start"] == v
