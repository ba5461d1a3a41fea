"""Issue 36: the command line does what the README says (-v logger names, -vv debug messages), the progress
bar counts every stage that takes time, and results work together (export, sub-results, saved scenes)."""

import re
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import outline_finger

ROOT = Path(__file__).resolve().parents[1]
FINGER = ROOT / "tests" / "data" / "finger.toml"


def _mdsr(tmp_path, *flags):
    cmd = [sys.executable, "-m", "mdsr_opt", *flags, "run", str(outline_finger(tmp_path)), "--out", str(tmp_path / "out"),
           "--resolution", "coarse", "--no-figures", "--no-animations", "--no-prototype", "--case", "contract"]
    env = {**__import__("os").environ, "OPENBLAS_NUM_THREADS": "1", "PYTHONPATH": str(ROOT)}
    done = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, env=env, timeout=120)
    assert done.returncode == 0, done.stderr
    return done.stdout.splitlines(), done.stderr.splitlines()


def test_verbosity_flags_add_logger_names_then_debug_lines(tmp_path):
    plain_out, plain_err = _mdsr(tmp_path / "a")
    v_out, v_err = _mdsr(tmp_path / "b", "-v")
    vv_out, vv_err = _mdsr(tmp_path / "c", "-vv")
    said = [line for line in plain_out if line.startswith("[finger")]
    assert said and not any(line.startswith("INFO ") for line in plain_out)
    # -v: the same messages, each led by its level and the module that said it
    named = [line for line in v_out if line.startswith(("INFO mdsr_opt.scenes.runner: [finger",
                                                       "INFO mdsr_opt.scenes.runscene: [finger",
                                                       "WARNING mdsr_opt.scenes.runner: [finger"))]
    assert len(named) == len(said)
    # a warning is led by WARNING (this finger's muscle runs on the outline)
    assert [line for line in named if line.startswith("WARNING")] == [
        "WARNING mdsr_opt.scenes.runner: " + line for line in said if "FabricationWarning" in line] != []
    assert not any(line.startswith("DEBUG") for line in plain_err + v_err)
    # -vv: debug records of the library too (one per equilibrium solve, the case's stage times)
    debug = [line for line in vv_err if line.startswith("DEBUG mdsr_opt.")]
    assert any("mechanics.loadsteps: internal solve on" in line and "iteration(s)" in line for line in debug)
    assert any("scenes.runner: [finger 1/1 contract] stage times: target" in line for line in debug)
    assert len([line for line in vv_out if line.startswith(("INFO mdsr_opt.", "WARNING mdsr_opt."))]) == \
        len([line for line in v_out if line.startswith(("INFO mdsr_opt.", "WARNING mdsr_opt."))]) == len(plain_out) - len(
            [line for line in plain_out if not line.startswith(("[finger", "finger: "))])


@pytest.mark.parametrize("photos, figures", [(True, True), (False, True), (True, False)])
def test_progress_total_counts_every_stage_that_ran(tmp_path, photos, figures):
    from mdsr_opt.core.progress import Progress
    from mdsr_opt.scenes.runscene import n_units, run_scene
    from mdsr_opt.scenes.scenefile import load_scene

    scene = load_scene(FINGER, resolution="coarse")
    done = []

    class Counting(Progress):
        def advance(self, n=1):
            done.append(n)
            super().advance(n)

    total = n_units(scene, None, True, photos=photos, figures=figures)
    # two cases (solves, photograph, figures each) and one animation
    assert total == 2 * (1 + photos + figures) + 1
    with Counting(total, "finger", enabled=False, stream=None) as log:
        rep = run_scene(scene, tmp_path / "out", photos=photos, figures=figures, prototype=False,
                        background=False, log=log)
        assert rep.success
        assert log.n == log.total == total == sum(done)  # never past 100 %, and 100 % only at the end


@pytest.fixture(scope="module")
def pipeline_result():
    from mdsr_opt import Mesh, NeoHookean, design_pipeline

    mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    left = [i for i, (x, y) in enumerate(mesh.points) if x == 0.0]
    right = {i: (x - 0.3, y - 0.5) for i, (x, y) in enumerate(mesh.points) if x == 4.0}
    return design_pipeline(mesh, NeoHookean(1.0, 0.3), left, right, routing_options={"max_muscles": 2})


def test_export_fabrication_takes_a_pipeline_result(pipeline_result, tmp_path):
    from mdsr_opt import export_fabrication

    res = pipeline_result
    files = export_fabrication(res.mesh, res, tmp_path / "fab", units="cm", name="strip")
    assert sorted(Path(f).name for f in files.values()) == ["strip.dxf", "strip.svg", "strip_muscles.csv"]
    rows = Path(files["csv"]).read_text().splitlines()
    assert len(rows) == 1 + len(res.muscles)  # a header, one row per muscle of the pipeline's layout
    # the same files as with the design and its muscles given apart
    apart = export_fabrication(res.mesh, res.design, tmp_path / "apart", muscles=res.muscles, units="cm",
                               name="strip")
    assert Path(apart["csv"]).read_text() == Path(files["csv"]).read_text()
    with pytest.raises(ValueError, match=r"a DesignResult or a mapping of them does not record its muscles"):
        export_fabrication(res.mesh, res.design, tmp_path / "none")
    assert not (tmp_path / "none").exists()


def test_pipeline_sub_results_are_result_objects_and_round_trip(pipeline_result, tmp_path):
    import json

    from mdsr_opt.mechanics.result import EquilibriumResult
    from mdsr_opt.synthesis.pipeline import PipelineResult
    from mdsr_opt.synthesis.routing_result import RoutingResult

    res = pipeline_result
    assert isinstance(res.routing, RoutingResult) and isinstance(res.external, EquilibriumResult)
    table = res.routing.table().splitlines()
    assert len(table) == 1 + len(res.muscles) and table[0].startswith("muscle")
    assert repr(res.routing).startswith(f"RoutingResult({len(res.muscles)} muscle(s)")
    assert repr(res.external).startswith("EquilibriumResult(mode='external'")
    assert res.external.x is not None and res.external.success
    data = json.loads(json.dumps(res.to_dict(), allow_nan=False))  # JSON-ready
    assert data["routing"]["n_units"] == res.routing.n_units and data["external"]["status"] == res.external.status
    back = PipelineResult.load(Path(res.save(tmp_path / "r")).parent)
    assert isinstance(back.routing, RoutingResult) and back.routing.table() == res.routing.table()
    assert back.routing.to_dict() == res.routing.to_dict()
    assert back.routing.graph.number_of_edges() == res.routing.graph.number_of_edges()
    assert isinstance(back.external, EquilibriumResult)
    assert {k: v for k, v in back.external.to_dict().items() if k != "x"} == \
        {k: v for k, v in res.external.to_dict().items() if k != "x"}
    assert back.external.x is not back.target and abs(back.external.x - res.target).max() < 1e-12


def _strings(value):
    if isinstance(value, dict):
        for v in value.values():
            yield from _strings(v)
    elif isinstance(value, list):
        for v in value:
            yield from _strings(v)
    elif isinstance(value, str):
        yield value


@pytest.mark.parametrize("origin", ["problem", "scene file"])
def test_a_saved_scene_holds_no_path_of_the_machine(origin, tmp_path):
    import json
    import re
    import shutil

    pytest.importorskip("starlette")
    from mdsr_opt import get_problem, load_scene
    from mdsr_opt.author.export import save_scene
    from mdsr_opt.author.session import Session

    if origin == "problem":
        scene = get_problem("tentacle", resolution="coarse")  # its source: the script's absolute path
    else:
        shutil.copy(FINGER, tmp_path / "finger.toml")
        scene = load_scene(tmp_path / "finger.toml", resolution="coarse")
    assert Path(scene.source).is_absolute()
    s = Session.from_scene(scene)
    s.settle()
    files = save_scene(s, tmp_path / "saved", "authored")
    data = json.loads(Path(files[0]).read_text())
    text = list(_strings(data))
    assert not [t for t in text if re.match(r"^(/|[A-Za-z]:[\\/]|\\\\)", t)]
    assert not [t for t in text if str(tmp_path) in t or sys.prefix in t or str(ROOT) in t]
    assert data["description"].endswith(f"from {Path(scene.source).name}.")
    assert [c.name for c in load_scene(files[0]).cases] == [c.name for c in scene.cases]  # a scene mdsr run reproduces


def test_the_page_save_box_starts_empty():
    html = (ROOT / "mdsr_opt" / "author" / "static" / "index.html").read_text()
    js = (ROOT / "mdsr_opt" / "author" / "static" / "author.js").read_text()
    box = re.search(r'<input id="save-name"[^>]*>', html).group(0)
    assert "value=" not in box and "placeholder=" in box
    # the page shows the body's name as the placeholder, never as the box's text (typing would append to it)
    assert re.findall(r'\$\("save-name"\)\.value = ([^;]+);', js) == ['""']
    assert '$("save-name").placeholder = m.name' in js


def test_the_scene_format_is_documented_once_with_every_key(tmp_path):
    import textwrap

    from mdsr_opt.scenes import scenefile
    from mdsr_opt.scenes.scenefile import load_scene

    doc = load_scene.__doc__
    example = textwrap.dedent(doc.split("::\n", 1)[1].split("\n\n    Node references")[0])
    (tmp_path / "doc.toml").write_text(example)
    scene = load_scene(tmp_path / "doc.toml")  # the documented example is itself a valid scene file
    assert scene.units == "mm" and scene.gait is not None and scene.gait.name == "walk"
    assert scene.gait.sequence == ("bend", "rest", "contract") and scene.expected == {"n_muscles": 2}
    # every key the reader accepts is named in the example
    keys = [k for name in dir(scenefile) if name.endswith("_KEYS") for k in getattr(scenefile, name)]
    assert len(keys) > 40
    assert [k for k in keys if not re.search(rf"\b{k}\b", example)] == []
    readme = (ROOT / "README.md").read_text()
    assert "Every section is in the docstring of `mdsr_opt.scenes.scenefile.load_scene`" in readme


def test_the_scene_format_documents_the_keys_of_the_nested_tables_too(tmp_path):
    """Keys the reader checks outside the ``*_KEYS`` tuples: a muscle's ``boundary`` (``via``), the
    ``[fabrication]`` fields and the ``[acceptance]`` keys are named in load_scene's docstring as well."""
    from dataclasses import fields

    from mdsr_opt.scenes.scene import check_acceptance
    from mdsr_opt.scenes.scenefile import load_scene
    from mdsr_opt.synthesis.fabrication import Fabrication

    doc = load_scene.__doc__
    keys = ["from", "to", "via"] + [f.name for f in fields(Fabrication)] + list(check_acceptance({}))
    assert len(keys) > 9
    assert [k for k in keys if not re.search(rf"\b{k}\b", doc)] == []
    # the reader's own list for a boundary muscle: exactly those documented
    scene = {"name": "s", "body": {"outline": [[0, 0], [4, 0], [4, 1], [0, 1]], "resolution": 60},
             "muscles": [{"boundary": {"from": [0, 0], "to": [4, 0], "qqq": 1}}],
             "cases": [{"name": "c", "contractions": [0.1]}]}
    (tmp_path / "s.json").write_text(__import__("json").dumps(scene))
    with pytest.raises(ValueError, match=r"boundary\.qqq: unknown field \(allowed: from, to, via\)"):
        load_scene(tmp_path / "s.json")


def test_every_sub_result_of_a_pipeline_result_is_an_object_with_manners(pipeline_result):
    """Walk the PipelineResult's fields (and theirs): every result object in it has its own repr and a
    JSON-ready to_dict, and those with rows (routing, design, bands) a table()."""
    import dataclasses
    import json

    seen = {}

    def walk(obj, where, depth=0):
        if depth > 3 or id(obj) in seen:
            return
        if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
            seen[id(obj)] = (where, obj)
            for f in dataclasses.fields(obj):
                if f.name not in ("mesh", "material"):
                    walk(getattr(obj, f.name), f"{where}.{f.name}", depth + 1)
        elif isinstance(obj, (list, tuple)):
            for i, v in enumerate(obj[:3]):
                walk(v, f"{where}[{i}]", depth + 1)
        elif isinstance(obj, dict):
            for k, v in list(obj.items())[:10]:
                walk(v, f"{where}[{k!r}]", depth + 1)

    walk(pipeline_result, "result")
    names = {type(o).__name__ for _, o in seen.values()}
    assert {"PipelineResult", "RoutingResult", "EquilibriumResult", "DesignResult", "Verification",
            "MuscleStats"} <= names, names
    for where, obj in seen.values():
        if type(obj).__name__ in ("Muscle", "Fabrication"):  # inputs carried along, with their own to_dict
            continue
        r = repr(obj)
        assert r.startswith(type(obj).__name__ + "(") and len(r) < 2000, where
        json.dumps(obj.to_dict(), allow_nan=False, default=str)
    for sub in (pipeline_result, pipeline_result.routing, pipeline_result.design):
        assert len(sub.table().splitlines()) >= 2
