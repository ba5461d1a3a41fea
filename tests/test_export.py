"""Fabrication files (mdsr_opt.export): SVG and DXF at true scale, the muscle CSV, units."""

from __future__ import annotations

import csv
import xml.etree.ElementTree as ET
from types import SimpleNamespace

import ezdxf
import numpy as np
import pytest

from mdsr_opt import Mesh, Muscle
from mdsr_opt.synthesis.export import UNITS, check_units, export_fabrication

SVG = "{http://www.w3.org/2000/svg}"


def body():
    """A 40 x 10 plate with a square hole, in mm, and three muscles (one turning a corner)."""
    outer = np.array([[0, 0], [40, 0], [40, 10], [0, 10]], float)
    hole = np.array([[18, 4], [22, 4], [22, 6], [18, 6]], float)
    from mdsr_opt.scenes.select import edge_path
    from mdsr_opt.scenes.scene import mesh_polygon

    mesh = mesh_polygon(outer, holes=[hole], resolution=300)
    mus = [edge_path(mesh, [(1, 1), (39, 1)], name="bottom"), edge_path(mesh, [(1, 9), (39, 9)], name="top"),
           edge_path(mesh, [(5, 2), (12, 8), (30, 8)], name="diag")]
    return mesh, mus


def design_of(mus, mesh, a):
    """A stand-in DesignResult: contractions only (stroke = a L0, no tension)."""
    return SimpleNamespace(contractions=np.asarray(a, float))


def test_svg_dxf_csv_at_true_scale(tmp_path):
    mesh, mus = body()
    d = {"up": design_of(mus, mesh, [0.1, 0.0, 0.2]), "down": design_of(mus, mesh, [0.0, 0.15, 0.05])}
    files = export_fabrication(mesh, d, tmp_path, muscles=mus, units="mm", name="plate")
    L0 = np.array([m.rest_length(mesh) for m in mus])
    # SVG: parses; one muscle polyline per muscle with its rest length; physical size in mm
    root = ET.parse(files["svg"]).getroot()
    assert root.get("width").endswith("mm") and root.get("height").endswith("mm")
    vb = [float(v) for v in root.get("viewBox").split()]
    assert float(root.get("width")[:-2]) == pytest.approx(vb[2])          # 1 user unit = 1 mm
    lines = [e for e in root.iter(SVG + "polyline") if e.get("class") == "muscle"]
    assert [e.get("id") for e in lines] == ["bottom", "top", "diag"]
    for e, L in zip(lines, L0):
        P = np.array([[float(c) for c in p.split(",")] for p in e.get("points").split()])
        assert np.linalg.norm(np.diff(P, axis=0), axis=1).sum() == pytest.approx(L, rel=1e-6)
    assert len([e for e in root.iter(SVG + "circle") if e.get("class") == "end"]) == 2 * len(mus)
    assert [e.text for e in root.iter(SVG + "text") if e.get("class") == "label"] == ["bottom", "top", "diag"]
    assert len([e for e in root.iter(SVG + "polygon")]) == 2                # outline + hole
    # DXF: reads back; same number of muscle polylines, lengths at true scale; unit mm
    doc = ezdxf.readfile(files["dxf"])
    assert doc.header["$INSUNITS"] == 4
    msp = doc.modelspace()
    polys = msp.query('LWPOLYLINE[layer=="MUSCLES"]')
    assert len(polys) == len(mus)
    for pl, L in zip(polys, L0):
        P = np.array([(p[0], p[1]) for p in pl.get_points()])
        assert np.linalg.norm(np.diff(P, axis=0), axis=1).sum() == pytest.approx(L, rel=1e-6)
    assert len(msp.query('LWPOLYLINE[layer=="BODY"]')) == 1 and len(msp.query('LWPOLYLINE[layer=="HOLES"]')) == 1
    assert len(msp.query('CIRCLE[layer=="ENDS"]')) == 2 * len(mus)
    assert sorted(t.dxf.text for t in msp.query("TEXT")) == ["bottom", "diag", "top"]
    outline = np.array([(p[0], p[1]) for p in msp.query('LWPOLYLINE[layer=="BODY"]')[0].get_points()])
    assert np.ptp(outline, axis=0) == pytest.approx([40, 10])
    # CSV: units in every header with a length; strokes a * L0
    rows = list(csv.reader(open(files["csv"])))
    head = rows[0]
    assert head[2] == "rest length [mm]" and "stroke up [mm]" in head and "tension down [E*t*mm]" in head
    assert [r[0] for r in rows[1:]] == ["bottom", "top", "diag"]
    col = head.index("stroke up [mm]")
    np.testing.assert_allclose([float(r[col]) for r in rows[1:]], np.array([0.1, 0.0, 0.2]) * L0, rtol=1e-8)
    np.testing.assert_allclose([float(r[2]) for r in rows[1:]], L0, rtol=1e-8)


def test_units_go_into_every_file(tmp_path):
    mesh, mus = body()
    files = export_fabrication(mesh, None, tmp_path, muscles=mus, units="cm", name="p")
    root = ET.parse(files["svg"]).getroot()
    assert root.get("width").endswith("cm")
    assert ezdxf.readfile(files["dxf"]).header["$INSUNITS"] == 5
    assert open(files["csv"]).readline().split(",")[2] == "rest length [cm]"
    files = export_fabrication(mesh, None, tmp_path / "m", muscles=mus, units="m", name="p")
    root = ET.parse(files["svg"]).getroot()   # metres: the physical size is written in mm
    assert float(root.get("width")[:-2]) == pytest.approx(1000 * float(root.get("viewBox").split()[2]))


def test_names_with_markup_characters_stay_valid_svg(tmp_path):
    """A muscle's name goes into an attribute (its id) and a label: quotes, <, > and & are escaped."""
    mesh, mus = body()
    odd = 'top "left" <a> & b\'s'
    mus = [Muscle(mus[0].nodes, name=odd), *mus[1:]]
    files = export_fabrication(mesh, None, tmp_path, muscles=mus, units="mm", name="p")
    root = ET.parse(files["svg"]).getroot()  # parses: the file is well-formed XML
    assert odd in [e.get("id") for e in root.iter(f"{SVG}polyline")]
    assert odd in ["".join(e.itertext()) for e in root.iter(f"{SVG}text")]


def test_a_real_design_exports_its_strokes_and_tensions(tmp_path):
    from mdsr_opt import NeoHookean, solve_internal
    from mdsr_opt.synthesis.contractions import design_contractions

    mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    m = Muscle(range(1, 16), name="M0")
    target = solve_internal(mesh, NeoHookean(1.0, 0.3), [m], [0.2]).x
    res = design_contractions(mesh, NeoHookean(1.0, 0.3), [m], target)
    files = export_fabrication(mesh, res, tmp_path, muscles=[m], units="mm")
    rows = list(csv.DictReader(open(files["csv"])))
    stroke = getattr(res, "stroke", None)
    expect = float(stroke[0]) if stroke is not None else 0.2 * m.rest_length(mesh)
    assert float(rows[0]["stroke design [mm]"]) == pytest.approx(expect, rel=1e-8)
    assert float(rows[0]["stroke design [mm]"]) == pytest.approx(0.2 * 3.5, rel=1e-4)   # 14 edges of 0.25
    if getattr(res, "tension", None) is not None:
        assert float(rows[0]["tension design [E*t*mm]"]) > 0


@pytest.mark.parametrize("kw, kind, words", [
    (dict(units="furlong"), ValueError, "unknown units 'furlong'"),
    (dict(units=3), TypeError, "units must be a string"),
    (dict(muscles=None), ValueError, "give the muscles"),
    (dict(name="../x"), ValueError, "plain file stem"),
    (dict(channel_width=-1.0), ValueError, "channel_width"),
    (dict(design=[1, 2]), TypeError, "design must be"),
])
def test_bad_input_writes_nothing(tmp_path, kw, kind, words):
    mesh, mus = body()
    args = dict(muscles=mus, units="mm", name="p", design=None)
    args.update(kw)
    design = args.pop("design")
    out = tmp_path / "out"
    with pytest.raises(kind, match=words):
        export_fabrication(mesh, design, out, **args)
    assert not out.exists()


def test_known_units():
    assert set(UNITS) >= {"mm", "cm", "m", "in"} and check_units("in") == "in"
