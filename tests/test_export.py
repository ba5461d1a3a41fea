"""Fabrication files (mdsr_opt.synthesis.export): SVG and DXF at true scale, the muscle CSV, units."""

from __future__ import annotations

import csv
import re
import xml.etree.ElementTree as ET
from types import SimpleNamespace

import ezdxf
from ezdxf.lldxf.encoding import decode_dxf_unicode
import numpy as np
import pytest

from mdsr_opt import Mesh, Muscle
from mdsr_opt.synthesis.export import UNITS, check_units, export_fabrication
from mdsr_opt.synthesis.fabrication import Fabrication

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
    # DXF (R12, read by ezdxf, an independent reader): no audit errors; same number of muscle polylines,
    # lengths at true scale, the channel width; closed outline and hole; unit mm
    doc = ezdxf.readfile(files["dxf"])
    assert doc.dxfversion == "AC1009" and doc.header["$INSUNITS"] == 4 and doc.header["$MEASUREMENT"] == 1
    assert not doc.audit().has_errors
    colors = {ly.dxf.name: ly.dxf.color for ly in doc.layers}  # (the reader adds its own, e.g. Defpoints)
    assert {k: colors.get(k) for k in ("BODY", "HOLES", "MUSCLES", "ENDS", "LABELS")} == \
        {"BODY": 7, "HOLES": 7, "MUSCLES": 1, "ENDS": 5, "LABELS": 3}
    msp = doc.modelspace()
    polys = msp.query('POLYLINE[layer=="MUSCLES"]')
    assert len(polys) == len(mus)
    fd_width = None
    for pl, L, mu in zip(polys, L0, mus):
        P = np.array([(p[0], p[1]) for p in pl.points()])
        np.testing.assert_allclose(P, mesh.points[list(mu.nodes)], atol=1e-9)   # the nodes at rest
        assert np.linalg.norm(np.diff(P, axis=0), axis=1).sum() == pytest.approx(L, rel=1e-9)
        assert not pl.is_closed and pl.dxf.default_start_width == pl.dxf.default_end_width > 0
        fd_width = pl.dxf.default_start_width
    channels = [e for e in root.iter(SVG + "polyline") if e.get("class") == "channel"]
    assert float(channels[0].get("stroke-width")) == pytest.approx(fd_width)   # as wide as the SVG's
    body_, holes = msp.query('POLYLINE[layer=="BODY"]'), msp.query('POLYLINE[layer=="HOLES"]')
    assert len(body_) == 1 and len(holes) == 1 and body_[0].is_closed and holes[0].is_closed
    ends = msp.query('CIRCLE[layer=="ENDS"]')
    assert len(ends) == 2 * len(mus)
    np.testing.assert_allclose([tuple(c.dxf.center)[:2] for c in ends[:2]],
                               mesh.points[[mus[0].nodes[0], mus[0].nodes[-1]]], atol=1e-9)
    assert sorted(t.dxf.text for t in msp.query("TEXT")) == ["bottom", "diag", "top"]
    outline = np.array([(p[0], p[1]) for p in body_[0].points()])
    assert np.ptp(outline, axis=0) == pytest.approx([40, 10])
    hole = np.array([(p[0], p[1]) for p in holes[0].points()])
    assert np.ptp(hole, axis=0) == pytest.approx([4, 2])
    # CSV: units in every header with a length; strokes a * L0
    lines = open(files["csv"]).read().splitlines()
    # this layout cannot be moulded (its top rope's channel is 0.79 mm inside the hole's edge): the CSV's first
    # line says so, as the SVG and DXF do
    assert lines[0].startswith("# NOT MOULDABLE as laid out (")
    rows = list(csv.reader(line for line in lines if not line.startswith("#")))
    head = rows[0]
    assert head[2] == "rest length [mm]" and "stroke up [mm]" in head and "tension down [units of E*t*mm]" in head
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
    head = next(line for line in open(files["csv"]) if not line.startswith("#"))  # after the NOT MOULDABLE line
    assert head.split(",")[2] == "rest length [cm]"
    files = export_fabrication(mesh, None, tmp_path / "m", muscles=mus, units="m", name="p")
    root = ET.parse(files["svg"]).getroot()   # metres: the physical size is written in mm
    assert float(root.get("width")[:-2]) == pytest.approx(1000 * float(root.get("viewBox").split()[2]))


def test_svg_in_body_units_has_a_drawable_size(tmp_path):
    """trial9: a body-units SVG had width="5.75" (px), a few pixels in a browser. Its longer side is now
    SVG_SIDE_PX px, width and height in the viewBox's proportion, and the caption states the scale."""
    from mdsr_opt.synthesis.export import SVG_SIDE_PX

    mesh, mus = body()
    for scale in (1.0, 0.01):  # a body 40 or 0.4 units long (wider than tall): the same drawn size
        m = Mesh(mesh.points * scale, mesh.triangles)
        files = export_fabrication(m, None, tmp_path / str(scale), muscles=mus, name="p")
        root = ET.parse(files["svg"]).getroot()
        w, h = root.get("width"), root.get("height")
        assert w.endswith("px") and h.endswith("px")
        vb = [float(v) for v in root.get("viewBox").split()]
        w, h = float(w[:-2]), float(h[:-2])
        assert w / h == pytest.approx(vb[2] / vb[3])  # one scale for both sides
        assert w == pytest.approx(SVG_SIDE_PX) and 0.2 * SVG_SIDE_PX < h < w  # the caption's lines below
        caption = " ".join(t.text or "" for t in root.iter(SVG + "tspan"))
        said = re.search(r"drawn at ([\d.e+-]+) px per body unit", " ".join(caption.split()))
        assert said and float(said.group(1)) == pytest.approx(w / vb[2], rel=1e-3), caption
        assert "true scale" not in root.find(SVG + "title").text
    # a known unit keeps its true scale (1 user unit = 1 mm), no px and no such note
    root = ET.parse(export_fabrication(mesh, None, tmp_path / "mm", muscles=mus, units="mm", name="p")["svg"]).getroot()
    assert root.get("width").endswith("mm") and "px per body unit" not in ET.tostring(root, encoding="unicode")


def test_dxf_labels_keep_any_name_on_one_line(tmp_path):
    """A name goes into a DXF TEXT as one ASCII line: other characters as \\U+ escapes (decoded by the
    reader), the control-code starters backslash and percent escaped too, a character beyond U+FFFF as ?.
    (A line break never reaches it: a muscle name may hold no control character, tests/test_input_classes.py.)"""
    mesh, mus = body()
    names = ["m\u00fcscle \u00e9t\u00e9 \u03bb", "50%%u off \\P", "two lines \U0001F600"]
    mus = [Muscle(m.nodes, name=n) for m, n in zip(mus, names)]
    files = export_fabrication(mesh, None, tmp_path, muscles=mus, units="mm", name="p")
    raw = open(files["dxf"], "rb").read()
    assert raw.isascii()
    lines = raw.decode("ascii").split("\n")
    assert lines[-1] == "" and lines[-2] == "EOF" and len(lines) % 2 == 1   # code/value pairs
    # as a reader shows them: TEXT control codes (%%%) interpreted, then the \\U+ escapes decoded
    texts = [decode_dxf_unicode(t.plain_text()) for t in ezdxf.readfile(files["dxf"]).modelspace().query("TEXT")]
    assert texts == ["m\u00fcscle \u00e9t\u00e9 \u03bb", "50%%u off \\P", "two lines ?"]


def test_dxf_carets_long_names_and_every_unit(tmp_path):
    """Carets are escaped (``^J`` would be a line feed); a name is cut to R12's 255 characters on a whole
    character; every unit gets its $INSUNITS code and inches $MEASUREMENT 0."""
    mesh, mus = body()
    names = ["a^Jb", "x^ y", "\u00e9" * 100]
    mus = [Muscle(m.nodes, name=n) for m, n in zip(mus, names)]
    files = export_fabrication(mesh, None, tmp_path, muscles=mus, units="mm", name="p")
    texts = [decode_dxf_unicode(t.plain_text()) for t in ezdxf.readfile(files["dxf"]).modelspace().query("TEXT")]
    assert texts[:2] == ["a^Jb", "x^ y"]
    assert texts[2] == "\u00e9" * 36  # 36 escapes of 7 characters: 252 <= 255
    codes = {"in": (1, 0), "mm": (4, 1), "cm": (5, 1), "m": (6, 1), "um": (13, 1)}
    assert set(codes) == set(UNITS)
    for unit, (code, metric) in codes.items():
        doc = ezdxf.readfile(export_fabrication(mesh, None, tmp_path / unit, muscles=mus, units=unit)["dxf"])
        assert (doc.header["$INSUNITS"], doc.header["$MEASUREMENT"]) == (code, metric)


@pytest.mark.parametrize("scale", [1e-8, 1e6])
def test_dxf_numbers_keep_their_digits_at_any_scale_and_the_extents_hold_everything(tmp_path, scale):
    """No exponent and no digit lost, for a body in nanometres as in kilometres: the muscles' lengths read
    back to 1e-9; $EXTMIN/$EXTMAX hold every circle and channel. A design's NaN anchor radius (none) gives
    the default circles."""
    mesh, mus = body()
    mesh = Mesh(mesh.points * scale, mesh.triangles)
    d = SimpleNamespace(contractions=np.zeros(len(mus)), anchor_radius=float("nan"))
    files = export_fabrication(mesh, d, tmp_path, muscles=mus, units="m", name="p")
    values = open(files["dxf"]).read().split("\n")[1::2]

    def number(v):
        try:
            return float(v)
        except ValueError:
            return None

    nums = [v for v in values if number(v) is not None]
    assert len(nums) > 100 and all("e" not in v.lower() and np.isfinite(number(v)) for v in nums)
    doc = ezdxf.readfile(files["dxf"])
    assert not doc.audit().has_errors
    msp = doc.modelspace()
    for pl, mu in zip(msp.query('POLYLINE[layer=="MUSCLES"]'), mus):
        P = np.array([(p[0], p[1]) for p in pl.points()])
        assert np.linalg.norm(np.diff(P, axis=0), axis=1).sum() == pytest.approx(mu.rest_length(mesh), rel=1e-9)
    ends = msp.query('CIRCLE[layer=="ENDS"]')
    r = ends[0].dxf.radius
    assert r == pytest.approx(Fabrication().for_body(mesh).fixture_radius, rel=1e-9)  # the default fixture
    lo, hi = np.array(doc.header["$EXTMIN"])[:2], np.array(doc.header["$EXTMAX"])[:2]
    for c in ends:
        ctr = np.array(tuple(c.dxf.center)[:2])
        assert np.all(ctr - r >= lo - 1e-12 * scale) and np.all(ctr + r <= hi + 1e-12 * scale)
    assert np.all(lo <= mesh.points.min(axis=0)) and np.all(hi >= mesh.points.max(axis=0))


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
    # the rope runs on the outline (the bottom row of nodes): a NOT MOULDABLE comment line, then the table
    rows = list(csv.DictReader(line for line in open(files["csv"]) if not line.startswith("#")))
    stroke = getattr(res, "stroke", None)
    expect = float(stroke[0]) if stroke is not None else 0.2 * m.rest_length(mesh)
    assert float(rows[0]["stroke design [mm]"]) == pytest.approx(expect, rel=1e-8)
    assert float(rows[0]["stroke design [mm]"]) == pytest.approx(0.2 * 3.5, rel=1e-4)   # 14 edges of 0.25
    if getattr(res, "tension", None) is not None:
        assert float(rows[0]["tension design [units of E*t*mm]"]) > 0


@pytest.mark.parametrize("kw, kind, words", [
    (dict(units="furlong"), ValueError, "unknown units 'furlong'"),
    (dict(units=3), TypeError, "units must be a string"),
    (dict(muscles=None), TypeError, "design is None and no muscles are given: design must be a PosesResult"),
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
