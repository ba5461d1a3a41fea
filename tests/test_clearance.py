"""Clearance between ropes, fixtures and the outline in the fabrication export, and the export's door checks."""

from __future__ import annotations

import re
import warnings
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from mdsr_opt import Mesh
from mdsr_opt.scenes.select import edge_path
from mdsr_opt.synthesis.export import export_fabrication
from mdsr_opt.synthesis.fabrication import Fabrication, FabricationWarning, rope_conflicts

SVG = "{http://www.w3.org/2000/svg}"


def plate(scale=1.0):
    """A 10 x 4 plate (node spacing 0.25), times ``scale``."""
    m = Mesh.rectangle(10.0, 4.0, 40, 16)
    return Mesh(m.points * scale, m.triangles)


def rope(mesh, pts, name, scale=1.0):
    return edge_path(mesh, [tuple(scale * np.asarray(p, float)) for p in pts], name=name)


def fab(scale=1.0):
    return Fabrication(channel_diameter=0.2 * scale, wall=0.1 * scale, fixture_radius=0.2 * scale)


def export_warnings(mesh, mus, tmp_path, **kw):
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        files = export_fabrication(mesh, None, tmp_path, muscles=mus, name="p", **kw)
    return files, [str(x.message) for x in w if issubclass(x.category, FabricationWarning)]


@pytest.mark.parametrize("scale", [1e-3, 1.0, 250.0])
def test_ropes_apart_export_without_warning(tmp_path, scale):
    mesh = plate(scale)
    mus = [rope(mesh, [(2, 1.5), (8, 1.5)], "a", scale), rope(mesh, [(2, 2.5), (8, 2.5)], "b", scale)]
    assert rope_conflicts(mesh, mus, fab(scale)) == []
    files, msgs = export_warnings(mesh, mus, tmp_path, fabrication=fab(scale))
    assert msgs == []
    assert "conflict" not in open(files["svg"]).read()


@pytest.mark.parametrize("scale", [1e-3, 1.0, 250.0])
def test_channels_of_two_muscles_closer_than_channel_plus_wall_are_reported(tmp_path, scale):
    mesh = plate(scale)
    mus = [rope(mesh, [(2, 1.5), (8, 1.5)], "a", scale), rope(mesh, [(3, 1.75), (7, 1.75)], "b", scale)]
    found = rope_conflicts(mesh, mus, fab(scale))
    ropes = [c for c in found if c.kind == "ropes"]
    assert len(ropes) == 1 and ropes[0].muscles == (0, 1)
    assert ropes[0].distance == pytest.approx(0.25 * scale, rel=1e-9)
    assert ropes[0].required == pytest.approx(0.3 * scale, rel=1e-12)
    files, msgs = export_warnings(mesh, mus, tmp_path, fabrication=fab(scale))
    assert len(msgs) == 1
    assert re.search(r"muscles a and b: their channels overlap: centre lines \S+ apart", msgs[0])
    assert f"need {0.3 * scale:.4g}" in msgs[0]
    # the fixture of b lies on a's channel too (0.25 from it; radius 0.2 + half channel 0.1 + wall 0.1)
    assert "the end fixture of b" in msgs[0] and f"need {0.4 * scale:.4g}" in msgs[0]
    rings = ET.parse(files["svg"]).getroot().findall(f".//{SVG}g[@id='conflicts']/{SVG}circle")
    assert {r.get("class") for r in rings} == {"conflict ropes", "conflict fixture-channel"}
    assert all(set(r.get("data-muscles").split()) == {"a", "b"} for r in rings)


def test_crossing_ropes_are_reported(tmp_path):
    mesh = plate()
    mus = [rope(mesh, [(2, 2), (8, 2)], "flat"), rope(mesh, [(4, 0.75), (5, 3.25)], "steep")]
    found = rope_conflicts(mesh, mus, fab())
    assert [c.kind for c in found if c.kind == "crossing"] == ["crossing"]
    _, msgs = export_warnings(mesh, mus, tmp_path, fabrication=fab())
    assert "muscles flat and steep cross or touch" in msgs[0] and "cannot be moulded in one layer" in msgs[0]


def test_overlapping_fixtures_of_two_muscles_are_reported(tmp_path):
    mesh = plate()
    # end to end along one line: b starts 0.25 after a ends (fixtures of radius 0.2 + a wall 0.1 need 0.5)
    mus = [rope(mesh, [(1, 2), (4.5, 2)], "a"), rope(mesh, [(4.75, 2), (9, 2)], "b")]
    found = rope_conflicts(mesh, mus, fab())
    fx = [c for c in found if c.kind == "fixtures"]
    assert len(fx) == 1 and fx[0].distance == pytest.approx(0.25) and fx[0].required == pytest.approx(0.5)
    _, msgs = export_warnings(mesh, mus, tmp_path, fabrication=fab())
    assert "muscles a and b: their end fixtures overlap: centres 0.25 apart" in msgs[0]


@pytest.mark.parametrize("scale", [1e-2, 1.0, 40.0])
def test_a_user_rope_on_the_outline_is_marked_not_mouldable(tmp_path, scale):
    mesh = plate(scale)
    mus = [rope(mesh, [(0, 0), (10, 0)], "lower", scale)]
    files, msgs = export_warnings(mesh, mus, tmp_path, fabrication=fab(scale))
    assert len(msgs) == 1
    need = max(0.2, 0.02 * np.hypot(10, 4)) * scale
    assert (f"muscle lower: its channel is not mouldable: its smallest inset from the outline or a hole is 0 "
            f"(it runs on the outline), a channel {0.2 * scale:.4g} wide with a wall {0.1 * scale:.4g} needs "
            f"{need:.4g}") in msgs[0]
    assert f"a fixture of radius {0.2 * scale:.4g} with a wall {0.1 * scale:.4g} needs {0.3 * scale:.4g}" in msgs[0]
    assert 'class="conflict inset"' in open(files["svg"]).read()
    assert "NOT MOULDABLE as laid out (2 place(s), red rings)" in " ".join(caption_lines(files["svg"])[-1])


def caption_lines(svg_path):
    root = ET.parse(svg_path).getroot()
    W, H = map(float, root.get("viewBox").split()[2:])
    cap = root.find(f"{SVG}text[@class='caption']")
    fc = float(cap.get("font-size"))
    return W, H, fc, float(cap.get("x")), float(cap.get("y")), [t.text for t in cap.findall(f"{SVG}tspan")]


@pytest.mark.parametrize("width", [1.0, 11.5, 400.0])
def test_the_caption_is_wrapped_to_the_drawing(tmp_path, width):
    m = Mesh.rectangle(width, 0.4 * width, 40, 16)
    mus = [edge_path(m, [(0.2 * width, 0.2 * width), (0.8 * width, 0.2 * width)], name="a rope with a long name")]
    files = export_fabrication(m, None, tmp_path, muscles=mus, name="a_drawing_with_a_rather_long_name")
    W, H, fc, x, y, lines = caption_lines(files["svg"])
    assert len(lines) >= 2
    # a sans-serif character is narrower than 0.6 em: every line ends inside the drawing
    assert all(x + 0.6 * fc * len(t) <= W * (1 + 1e-9) for t in lines)
    assert y + 1.25 * fc * (len(lines) - 1) <= H * (1 + 1e-9)   # the last line is on the page
    assert " ".join(lines).startswith("a_drawing_with_a_rather_long_name: 1 muscle channel(s)")


def test_out_naming_a_file_is_a_value_error(tmp_path):
    mesh = plate()
    f = tmp_path / "afile"
    f.write_text("x")
    with pytest.raises(ValueError, match=r"out '.*afile' is an existing file, not a folder"):
        export_fabrication(mesh, None, f, muscles=[rope(mesh, [(2, 2), (8, 2)], "a")])
    assert f.read_text() == "x"


@pytest.mark.parametrize("design, words", [
    (None, r"design is None and no muscles are given: design must be a PosesResult \(design_poses\), a "
           r"PipelineResult"),
    ({"a": 1}, r"design is a mapping whose value for 'a' is a int, not a DesignResult: design must be"),
    (3.5, r"design must be a PosesResult .* got float"),
])
def test_a_design_of_the_wrong_type_is_a_type_error_naming_design(tmp_path, design, words):
    with pytest.raises(TypeError, match=words):
        export_fabrication(plate(), design, tmp_path / "o")
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("scale", [1e-3, 1.0, 1e3])
@pytest.mark.parametrize("kw, words", [
    (dict(channel_width=5.0), r"channel_width \S+ with walls of .* does not fit in the body: the body is "
                              r"\S+ x \S+ and \S+ deep .*channel_width at most"),
    (dict(fabrication=dict(wall=1.5)), r"does not fit in the body"),
    (dict(fabrication=dict(fixture_radius=1.9)), r"the end fixtures \(radius \S+\) with their wall \S+ do not fit"),
])
def test_sizes_larger_than_the_body_are_refused_at_the_door(tmp_path, scale, kw, words):
    m = Mesh.rectangle(4.0, 1.0, 16, 4)
    mesh = Mesh(m.points * scale, m.triangles)
    mus = [edge_path(mesh, [(0.5 * scale, 0.5 * scale), (3.5 * scale, 0.5 * scale)], name="a")]
    kw = {k: (v * scale if k == "channel_width" else {f: x * scale for f, x in v.items()}) for k, v in kw.items()}
    with pytest.raises(ValueError, match=words) as e:
        export_fabrication(mesh, None, tmp_path / "o", muscles=mus, **kw)
    assert f"{0.5 * scale:.4g} deep" in str(e.value)
    assert not (tmp_path / "o").exists()
