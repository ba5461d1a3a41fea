"""Validation at the door: scene-file option values, solver options, waypoints, output names, a folder as
scene file, damaged design results, and the demo's and study's arguments -- each before any work."""

from __future__ import annotations

import copy
import json
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

from mdsr_opt import Mesh, Muscle, NeoHookean, solve_external
from mdsr_opt.mechanics.backends import check_options
from mdsr_opt.cli.main import main
from mdsr_opt.synthesis.pipeline import PipelineResult, design_pipeline
from mdsr_opt.scenes.scene import Case, Scene
from mdsr_opt.scenes.reader import SceneFileError
from mdsr_opt.scenes.select import boundary_path, edge_path
from mdsr_opt.scenes.names import check_output_names
from mdsr_opt.scenes.library import get_problem
from mdsr_opt.scenes.scenefile import load_scene

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

DATA = Path(__file__).parent / "data"
FINGER = DATA / "finger.toml"
BASE = tomllib.loads(FINGER.read_text())


def _scene_file(tmp_path, mutate) -> Path:
    d = copy.deepcopy(BASE)
    mutate(d)
    p = tmp_path / "scene.json"
    p.write_text(json.dumps(d))
    return p


def _set(section, key, value):
    return lambda d: d.setdefault(section, {}).__setitem__(key, value)


# ---------------------------------------------------------------------------------------------- scene options
OPTION_CASES = [
    (_set("design", "a_max", 1.5), SceneFileError, r"design\.a_max: must lie in \(0, 1\) .*got 1\.5"),
    (_set("design", "method", "magic"), SceneFileError,
     r"design\.method: must be one of 'flattened', 'nested', 'derivative-free', got 'magic'"),
    (_set("routing", "max_muscles", -2), SceneFileError, r"routing\.max_muscles: must be an integer >= 1, got -2"),
    (_set("design", "tol", "tight"), TypeError, r"design\.tol: expected a number, got str"),
    (_set("design", "stiffness", 0), SceneFileError, r"design\.stiffness: must be > 0, got 0"),
    (_set("design", "max_iter", 2.5), TypeError, r"design\.max_iter: expected an integer, got 2\.5"),
    (_set("design", "verify", "yes"), TypeError, r"design\.verify: expected true or false"),
    (_set("design", "muscle_model", "rope"), SceneFileError, r"design\.muscle_model: must be one of 'springs'"),
    (_set("design", "interior_weight", 0.9), SceneFileError, r"design\.interior_weight: must lie in \[0\.3, 0\.7\]"),
    (_set("routing", "K_a", -1), SceneFileError, r"routing\.K_a: must be >= 0, got -1"),
    (_set("routing", "n_seeds", 0), SceneFileError, r"routing\.n_seeds: must be an integer >= 1, got 0"),
    (_set("routing", "min_contraction", 1.0), SceneFileError, r"routing\.min_contraction: must lie in \[0, 1\)"),
    (_set("design", "options", {"mu_strategy": "magic"}), SceneFileError,
     r"design\.options\.mu_strategy: invalid value 'magic' for ipopt option 'mu_strategy': Setting: \"magic\" is "
     r"not a valid setting"),
    (_set("design", "options", {"tolerance": 1e-6}), SceneFileError,
     r"design\.options\.tolerance: unknown ipopt option 'tolerance'"),
    (_set("design", "options", 3), TypeError, r"design\.options: expected a table of solver options"),
    (lambda d: d["design"].update(method="nested", options={"xatol": 1e-3}), SceneFileError,
     r"design\.options\.xatol: unknown scipy L-BFGS-B option 'xatol'"),
    (lambda d: d["cases"][0].update(name="summary"), SceneFileError, r"cases\[0\]\.name: the case name 'summary' is "
     r"reserved"),
    (lambda d: d["cases"][0].update(name="rest.png"), SceneFileError, r"cases\[0\]\.name: the case name 'rest\.png' "
     r"is reserved"),
    (lambda d: d["cases"][0].update(name="summary.json"), SceneFileError, r"cases\[0\]\.name: .*reserved"),
    (lambda d: d["animations"][0].update(name="summary"), SceneFileError,
     r"animations\[0\]\.name: the animation name 'summary' is reserved"),
    (lambda d: d["animations"][0].update(name="summary.md"), SceneFileError, r"animations\[0\]\.name: .*reserved"),
    (lambda d: d["cases"][0].update(name="curl.gif"), SceneFileError,
     r"animations\[0\]\.name: the animation 'curl' would write 'curl\.gif', which is written by the case 'curl\.gif'"),
    (lambda d: d["muscles"][0].update(path=[[0, 1], [2, 1], [3.5, 2.5]]),
     SceneFileError, r"muscles\[0\]\.path: waypoint 2 \[3\.5, 2\.5\] lies 1\.5 from the nearest node, more than "
     r"0\.\d+ \(one mean edge length\)"),
    (lambda d: d["muscles"][0].pop("path") and d["muscles"][0].update(boundary={"from": [0, 1], "to": [2, 2]}),
     SceneFileError,
     r"muscles\[0\]\.boundary: end \[2\.0, 2\.0\] lies 1 from the nearest boundary node"),
]


@pytest.mark.parametrize("mutate, err, match", OPTION_CASES, ids=[c[2][:40] for c in OPTION_CASES])
def test_scene_file_values_are_checked_at_load(tmp_path, mutate, err, match):
    with pytest.raises(err, match=r"scene\.json: " + match):
        load_scene(_scene_file(tmp_path, mutate))


def test_good_option_values_pass_and_keep_their_types(tmp_path):
    scene = load_scene(_scene_file(tmp_path, lambda d: d["design"].update(
        tol=1e-9, max_iter=100, options={"mu_strategy": "adaptive"}, hessian="gauss-newton", verify=True)))
    assert scene.design_options == {"a_max": 0.6, "tol": 1e-9, "max_iter": 100, "hessian": "gauss-newton",
                                    "verify": True, "options": {"mu_strategy": "adaptive"}}


def test_scene_file_errors_stop_mdsr_run_before_any_file(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["run", str(_scene_file(tmp_path, _set("design", "a_max", 1.5))), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "scene.json: design.a_max: must lie in (0, 1)" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_python_scenes_check_their_options_and_names():
    mesh = Mesh.rectangle(2.0, 1.0, 4, 2)
    case = Case("pull", anchors=[0, 5], drag_nodes=[4], drag_positions=[[2.2, 0.0]])
    with pytest.raises(SceneFileError, match=r"scene 'box': design\.a_max: must lie in \(0, 1\)"):
        Scene("box", mesh, NeoHookean(1.0, 0.3), (case,), design_options={"a_max": 2})
    with pytest.raises(SceneFileError, match=r"scene 'box': routing\.max_muscle: unknown field"):
        Scene("box", mesh, NeoHookean(1.0, 0.3), (case,), routing_options={"max_muscle": 2})
    with pytest.raises(SceneFileError, match=r"scene 'box': case 'Summary': the case name 'Summary' is reserved"):
        Scene("box", mesh, NeoHookean(1.0, 0.3), (Case("Summary", anchors=[0, 5]),))
    with pytest.raises(SceneFileError, match=r"animation 'pull' would write 'pull\.json'"):
        check_output_names(["pull.json"], ["pull"])
    check_output_names(["bend", "curl"], ["wave"])  # no collision: no error


# ---------------------------------------------------------------------------------------------- solver options
@pytest.mark.parametrize("backend, options, words", [
    ("ipopt", {"ipopt.tolerance": 1e-6}, "unknown ipopt option 'ipopt.tolerance'"),
    ("ipopt", {"tol": 1e-6}, "unknown ipopt option 'tol' (IPOPT's own options are written 'ipopt.NAME')"),
    ("ipopt", {"ipopt.max_iter": "many"}, "invalid value 'many' for ipopt option 'ipopt.max_iter'"),
    ("ipopt", {"ipopt.tol": -1}, "Setting: \"-1\" is not a valid setting for Option: tol."),
    ("sqpmethod", {"max_iter": "x"}, "invalid value 'x' for sqpmethod option 'max_iter'"),
    ("scipy", {"gtol": 1e-3}, "backend 'scipy' takes no options"),
    ("scipy:L-BFGS-B", {"xatol": 1}, "unknown scipy L-BFGS-B option 'xatol'"),
])
def test_check_options_names_the_bad_option(backend, options, words):
    with pytest.raises(ValueError) as info:
        check_options(backend, options)
    assert words in str(info.value)


def test_check_options_accepts_known_options_and_types_are_checked():
    assert check_options("ipopt", {"ipopt.print_level": 0, "ipopt.mu_strategy": "adaptive"}) == \
        {"ipopt.print_level": 0, "ipopt.mu_strategy": "adaptive"}
    assert check_options("scipy:Nelder-Mead", {"xatol": 1e-4}) == {"xatol": 1e-4}
    assert check_options("newton", None) == {}
    with pytest.raises(TypeError, match="options must be a dict"):
        check_options("ipopt", [("ipopt.tol", 1)])
    with pytest.raises(ValueError, match="unknown backend 'ipop'"):
        check_options("ipop", {})


def test_unknown_ipopt_option_in_a_solve_is_a_value_error():
    mesh = Mesh.rectangle(2.0, 1.0, 4, 2)
    left = np.flatnonzero(mesh.points[:, 0] == 0)
    right = np.flatnonzero(mesh.points[:, 0] == 2)
    with pytest.raises(ValueError, match="unknown ipopt option 'ipopt.magic_speed'"):
        solve_external(mesh, NeoHookean(1.0, 0.3), anchors=left,
                       drags=(right, mesh.points[right] + [0.1, 0]), options={"ipopt.magic_speed": 2})


@pytest.mark.parametrize("method, options, err, match", [
    ("flattened", {"bogus_opt": 1}, ValueError, r"unknown ipopt option 'bogus_opt'"),
    ("flattened", {"tol": "tight"}, ValueError, r"invalid value 'tight' for ipopt option 'tol'"),
    ("flattened", [("tol", 1e-3)], TypeError, r"options must be a dict"),
    ("nested", {"xatol": 1e-3}, ValueError, r"unknown scipy L-BFGS-B option 'xatol'"),
    ("derivative-free", {"ftol": 1e-3}, ValueError, r"unknown scipy Nelder-Mead option 'ftol'"),
])
def test_design_solver_options_are_checked_at_the_door(method, options, err, match, monkeypatch):
    """design_contractions(options=...) is checked before any model is built (never a CasADi error)."""
    import mdsr_opt.synthesis.contractions as contractions

    mesh = Mesh.rectangle(4.0, 1.0, 8, 2)
    mus = [Muscle(np.flatnonzero(mesh.points[:, 1] == 1.0)[1:-1])]

    def no_work(*args, **kwargs):
        raise AssertionError("a design problem was built before the options were checked")

    monkeypatch.setattr(contractions, "DesignProblem", no_work)
    with pytest.raises(err, match=match):
        contractions.design_contractions(mesh, NeoHookean(1.0, 0.3), mus, mesh.points, method=method,
                                         options=options)


# ---------------------------------------------------------------------------------------------- waypoints
def test_far_waypoints_are_refused_with_the_distance():
    mesh = Mesh.rectangle(4.0, 1.0, 16, 4)                   # mean edge length about 0.26
    m = edge_path(mesh, [[0, 0], [4, 0.1]])
    assert m.nodes[0] == 0 and len(m.nodes) == 17
    with pytest.raises(ValueError, match=r"waypoint 1 \[4\.0, 2\.0\] lies 1 from the nearest node, more than "
                                         r"0\.2\d+ \(one mean edge length\): is it on the body\?"):
        edge_path(mesh, [[0, 0], [4, 2.0]])
    with pytest.raises(ValueError, match=r"start \[-1\.0, 0\.0\] lies 1 from the nearest boundary node"):
        boundary_path(mesh, [-1, 0], [4, 0])
    assert len(edge_path(mesh, [[0, 0], [4, 2.0]], tol=2.0).nodes) > 2        # a looser tolerance on request


# ---------------------------------------------------------------------------------------------- files
def test_a_folder_as_scene_file(tmp_path, capsys):
    (tmp_path / "scene.toml").mkdir()
    with pytest.raises(SceneFileError, match=r"scene\.toml is a folder, not a scene file"):
        load_scene(tmp_path / "scene.toml")
    with pytest.raises(ValueError, match=r"is a folder, not a scene"):
        get_problem(str(tmp_path))
    assert main(["run", str(tmp_path / "scene.toml"), "--out", str(tmp_path / "o")]) == 2
    assert "scene.toml is a folder, not a scene" in capsys.readouterr().err


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    mesh = Mesh.rectangle(4.0, 1.0, 8, 2)
    left = [i for i, (x, y) in enumerate(mesh.points) if x == 0.0]
    right = {i: (x - 0.3, y - 0.5) for i, (x, y) in enumerate(mesh.points) if x == 4.0}
    d = tmp_path_factory.mktemp("saved") / "result"
    design_pipeline(mesh, NeoHookean(1.0, 0.3), left, right, muscles=[Muscle(range(1, 8))]).save(d)
    return d


def _damaged(saved, tmp_path, edit):
    d = tmp_path / "r"
    shutil.copytree(saved, d)
    edit(d)
    return d


@pytest.mark.parametrize("edit, err, words", [
    (lambda d: (d / "design.json").write_text('{"format": "mdsr_opt.design/1", "mat'), ValueError,
     "design.json is damaged: not valid JSON"),
    (lambda d: (d / "design.json").write_text(json.dumps({k: v for k, v in json.loads(
        (d / "design.json").read_text()).items() if k != "muscles"})), ValueError,
     "design.json is damaged: field 'muscles' is missing"),
    (lambda d: (d / "design.json").write_text(json.dumps({**json.loads((d / "design.json").read_text()),
                                                          "material": {"kind": "rubber"}})), ValueError,
     "design.json is damaged (material): unknown material kind 'rubber'"),
    (lambda d: (d / "target.vtu").unlink(), FileNotFoundError, "the target mesh"),
    (lambda d: (d / "design.json").write_text("[1, 2]"), ValueError, "is not a mdsr_opt design result"),
])
def test_damaged_design_results_are_named(saved, tmp_path, edit, err, words):
    assert PipelineResult.load(saved).muscles                      # the intact copy loads
    with pytest.raises(err) as info:
        PipelineResult.load(_damaged(saved, tmp_path, edit))
    assert words in str(info.value)


def test_design_result_folder_missing_or_a_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="no such design result folder"):
        PipelineResult.load(tmp_path / "nowhere")
    (tmp_path / "f").write_text("x")
    with pytest.raises(ValueError, match="is a file; PipelineResult.load takes the folder"):
        PipelineResult.load(tmp_path / "f")


# ---------------------------------------------------------------------------------------------- arguments
@pytest.mark.parametrize("args, words", [
    (["--contraction", "1.5"], "contraction 1.5 is outside [0, 1)"),
    (["--contraction", "nan"], "contraction must be finite"),
    (["--max-area", "-0.1"], "max_area must be > 0"),
    (["--out", ""], "--out is empty"),
])
def test_demo_arguments_fail_before_meshing(tmp_path, capsys, monkeypatch, args, words):
    monkeypatch.setattr("mdsr_opt.body.mesh.Mesh.from_polygon", lambda *a, **k: pytest.fail("meshing started"))
    monkeypatch.chdir(tmp_path)
    assert main(["demo", "--out", "d", *args]) == 2
    assert words in capsys.readouterr().err
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("args, words", [
    (["--resolutions", "100,many"], "--resolutions: expected comma-separated integers, got 'many'"),
    (["--workers", "0"], "--workers must be at least 1"),
    (["--timeout", "-1"], "--timeout must be a positive number"),
])
def test_study_arguments_are_named(tmp_path, capsys, args, words):
    assert main(["study", "quick", "--out", str(tmp_path / "s"), *args]) == 2
    assert words in capsys.readouterr().err
    assert not (tmp_path / "s").exists()


def test_an_anchor_radius_of_half_the_body_is_refused_at_every_door():
    from mdsr_opt import check_minimum, design_contractions, solve_internal

    mesh = Mesh.rectangle(4.0, 1.0, 8, 2)  # body size (diameter) sqrt(17) = 4.12
    mus = [Muscle(np.flatnonzero(mesh.points[:, 1] == 1.0)[1:-1])]
    mat = NeoHookean(1.0, 0.3)
    for call in (lambda: solve_internal(mesh, mat, mus, [0.1], anchor_radius=2.1),
                 lambda: design_contractions(mesh, mat, mus, mesh.points, anchor_radius=1e9),
                 lambda: check_minimum(mesh, mat, mus, [0.1], mesh.points, anchor_radius=2.1)):
        with pytest.raises(ValueError, match=r"anchor_radius .* is at least half the body's size \(4\.12\)"):
            call()
    assert solve_internal(mesh, mat, mus, [0.1], anchor_radius=2.0).success  # just below the limit
