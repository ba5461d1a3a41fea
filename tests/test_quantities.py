"""Units on strokes and tensions wherever a user reads them (issue 36): tables, the run's log and
summary.json, the fabrication files; a material states its stress unit (the silicone presets: Pa), and a
body whose length unit is not known is in "body units", never an invented mm."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from mdsr_opt import Mesh, Muscle, NeoHookean, solve_internal
from mdsr_opt.body.material import Yeoh, material_dict, material_from_dict
from mdsr_opt.body.silicone import silicone
from mdsr_opt.cli.main import main
from mdsr_opt.core.quantities import tension_unit
from mdsr_opt.synthesis.contractions import design_contractions
from mdsr_opt.synthesis.export import export_fabrication
from mdsr_opt.synthesis.pipeline import design_pipeline

ROOT = Path(__file__).resolve().parents[1]
FINGER = ROOT / "tests" / "data" / "finger.toml"


def strip_mm():
    """A 40 x 10 mm strip, its lower muscle contracted: the target."""
    mesh = Mesh.rectangle(40.0, 10.0, 16, 4)
    return mesh, Muscle(range(1, 16))


def pipeline(mesh, mat, mus, units):
    left = [i for i, (x, y) in enumerate(mesh.points) if x == 0.0]
    bent = solve_internal(mesh, mat, [mus], [0.1]).x
    right = {i: tuple(bent[i]) for i, (x, y) in enumerate(mesh.points) if x == 40.0}
    return design_pipeline(mesh, mat, left, right, muscles=[mus], units=units)


def test_materials_state_their_stress_unit():
    assert silicone("dragon-skin-30").stress_unit == "Pa" and silicone("sylgard-184", law="neo-hookean").stress_unit == "Pa"
    assert NeoHookean(1.0, 0.3).stress_unit is None and Yeoh(1.0).stress_unit is None
    m = silicone("ecoflex-00-30", 2.0)
    assert material_from_dict(material_dict(m)).stress_unit == "Pa"
    with pytest.raises(ValueError, match="unknown stress_unit 'psi'"):
        NeoHookean(1.0, 0.3, stress_unit="psi")
    assert tension_unit("Pa", "mm") == ("N", pytest.approx(1e-6)) and tension_unit("kPa", "cm")[1] == pytest.approx(0.1)
    assert tension_unit(None, "mm") == ("units of E*t*mm", 1.0) and tension_unit("Pa", None)[0] == "units of E*t*length"


def test_a_silicone_in_mm_gives_strokes_in_mm_and_tensions_in_newtons(tmp_path):
    mesh, mus = strip_mm()
    mat = silicone("dragon-skin-30", thickness=2.0)
    out = pipeline(mesh, mat, mus, "mm")
    d = out.design
    assert out.success and d.units == "mm" and d.tension_unit == "N"
    head, row = out.table().splitlines()[:2]
    assert "stroke (mm)" in head and "tension (N)" in head
    t_row = float(row.split()[4])
    assert t_row == pytest.approx(1e-6 * d.tension[0], rel=1e-3) and 1e-3 < t_row < 10  # newtons, not Pa mm^2
    assert d.summary()["units"] == {"stroke": "mm", "tension": "N"}
    assert d.summary()["tension"][0] == pytest.approx(1e-6 * d.tension[0])
    # the fabrication files default to the design's units and give tensions in N
    files = export_fabrication(mesh, out, tmp_path / "f")
    rows = list(csv.DictReader(ln for ln in open(files["csv"]) if not ln.startswith("#")))  # NOT MOULDABLE first
    assert float(rows[0]["tension design [N]"]) == pytest.approx(1e-6 * d.tension[0], rel=1e-8)
    assert float(rows[0]["stroke design [mm]"]) == pytest.approx(d.stroke[0])
    with pytest.raises(ValueError, match="made in mm"):
        export_fabrication(mesh, out, tmp_path / "g", units="cm")
    assert not (tmp_path / "g").exists()


def test_a_dimensionless_body_is_in_body_units_everywhere(tmp_path):
    import ezdxf

    mesh, mus = strip_mm()
    mat = NeoHookean(1.0, 0.3)
    target = solve_internal(mesh, mat, [mus], [0.1]).x
    d = design_contractions(mesh, mat, [mus], target)
    head = d.table().splitlines()[0]
    assert "stroke (body units)" in head and "tension (units of E*t*length)" in head
    files = export_fabrication(mesh, d, tmp_path, muscles=[mus])  # no units known: never mm
    text = next(ln for ln in open(files["csv"]).read().splitlines() if not ln.startswith("#"))  # the header
    assert "rest length [body units]" in text and "tension design [units of E*t*length]" in text and "mm" not in text
    svg = open(files["svg"]).read()
    assert "units: body units" in svg and 'mm"' not in svg and "true scale" not in svg
    assert ezdxf.readfile(files["dxf"]).header["$INSUNITS"] == 0
    # with a dimensionless material and known units: tensions in E*t*mm, strokes in mm
    d.units = "mm"
    assert "stroke (mm)" in d.table() and "tension (units of E*t*mm)" in d.table()


def test_mdsr_run_logs_and_summarises_strokes_and_tensions_with_units(tmp_path, capsys):
    out, finger = tmp_path / "o", tmp_path / "finger_mm.toml"
    finger.write_text(FINGER.read_text().replace('name = "finger"\n', 'name = "finger"\nunits = "mm"\n'))
    assert main(["run", str(finger), "--out", str(out), "--case", "contract", "--serial", "--no-photos",
                 "--no-figures", "--no-animations", "--no-prototype"]) == 0
    log = capsys.readouterr().out
    line = next(s for s in log.splitlines() if "strokes [" in s)
    assert "] mm, tensions [" in line and "] units of E*t*mm" in line
    case = json.loads((out / "summary.json").read_text())["cases"][0]
    assert case["units"] == {"stroke": "mm", "tension": "units of E*t*mm"} and len(case["tension"]) == len(case["stroke"])
    lines = [ln for ln in (out / "summary.md").read_text().splitlines() if ln.startswith("| ")]
    head, row = ([c.strip() for c in ln.strip("|").split("|")] for ln in (lines[0], lines[2]))
    assert row[head.index("strokes")].endswith(" mm")  # every stroke cell carries the unit


def test_a_scene_file_states_its_stress_unit(tmp_path):
    from mdsr_opt.scenes.reader import SceneFileError
    from mdsr_opt.scenes.scenefile import load_scene, material_table

    src = FINGER.read_text()
    path = tmp_path / "f.toml"
    path.write_text(src.replace("nu = 0.4\n", 'nu = 0.4\nstress_unit = "kPa"\n'))
    scene = load_scene(path)
    assert scene.material.stress_unit == "kPa" and scene.units is None  # no unit given: body units
    assert material_table(scene.material)["stress_unit"] == "kPa"
    assert material_table(silicone("dragon-skin-30"))["stress_unit"] == "Pa"
    path.write_text(src.replace("nu = 0.4\n", 'nu = 0.4\nstress_unit = "psi"\n'))
    with pytest.raises(SceneFileError, match="material.stress_unit: unknown stress_unit 'psi'"):
        load_scene(path)


def test_export_takes_the_material_for_a_design_that_records_no_stress_unit(tmp_path):
    mesh, mus = strip_mm()
    target = solve_internal(mesh, NeoHookean(1.0, 0.3), [mus], [0.1]).x
    d = design_contractions(mesh, NeoHookean(1.0, 0.3), [mus], target)
    d.stress_unit = None  # as a PosesResult: no stress unit of its own
    files = export_fabrication(mesh, {"bend": d}, tmp_path, muscles=[mus], units="mm",
                               material=NeoHookean(1.0, 0.3, stress_unit="MPa"))
    rows = list(csv.DictReader(ln for ln in open(files["csv"]) if not ln.startswith("#")))  # NOT MOULDABLE first
    assert float(rows[0]["tension bend [N]"]) == pytest.approx(d.tension[0], rel=1e-8)  # MPa x mm^2 = N


def test_a_scene_without_units_is_in_body_units_everywhere(tmp_path, capsys):
    """No unit invented (new-user trial: a scene file without `units` reported mm): the scene, the log, the
    summary and the gait's schedule say body units."""
    from mdsr_opt.scenes.scenefile import load_scene
    from mdsr_opt.scenes.scene import Scene

    assert load_scene(FINGER).units is None
    assert Scene.__dataclass_fields__["units"].default is None
    out = tmp_path / "o"
    assert main(["run", str(FINGER), "--out", str(out), "--case", "contract", "--serial", "--no-photos",
                 "--no-figures", "--no-animations", "--no-prototype"]) == 0
    line = next(s for s in capsys.readouterr().out.splitlines() if "strokes [" in s)
    assert "] body units, tensions [" in line and " mm" not in line
    case = json.loads((out / "summary.json").read_text())["cases"][0]
    assert case["units"]["stroke"] == "body units"
